//! The whole loop as an engineer runs it on their own motor — fit a LuGre model, diagnose
//! it, add what the diagnosis names, refit, until it is adequate or nothing more helps —
//! on the independent plant (`e2e::other_plant`, not our emulator's equations) with each
//! case of `e2e::plant_cases` hidden, and how much of the model's error the additions take
//! away on data no choice was made on.
//!
//! The loop is `motorid demo`'s (`workflow::run`, up to `demo::MAX_ROUNDS` rounds) on the
//! demo's logs: 90 s of the fitting multisine a and 30 s of the voltage steps d to fit and
//! diagnose, 90 s of signal b to choose (the keep-or-not test), and a fresh 90 s of signal b
//! to score: the fit percentage of the final model's free-run velocity against the plant's
//! true velocity. "Error removed" is the share of the base model's error (100 % less its
//! fit) that the final model no longer makes; a model cannot reach 100 % on it (the Hall
//! sensor's rounding and the plant's own noise), so the figure understates what a perfect
//! addition would show.
//!
//! `cargo test --release -p e2e --test loop_table -- --ignored --nocapture` regenerates
//! docs/loop-table.md and its summary in README.md (about 45 loops, ten minutes on two
//! cores).
use e2e::other_plant::{Extra, OtherPlant};
use e2e::plant_cases::{case, verdict_cases, NAMES};
use motorid::cmd::demo::MAX_ROUNDS;
use motorid::diagnose::Diagnosis;
use motorid::emulator::{signal, SignalKind};
use motorid::ident::{self, free_params::Constraints};
use motorid::log::{MotorLog, Plant};
use motorid::model::{Model, ModelKind};
use motorid::workflow;

const TS: f64 = 0.012;
const SEEDS: [u64; 3] = [1, 2, 3];
/// The demo's lengths [s]: the multisines, and the steps.
const SECONDS: f64 = 90.0;
const STEP_SECONDS: f64 = 30.0;

/// Every case of the table: what is hidden and the plant that hides it.
fn cases() -> Vec<(String, Extra)> {
    let mut out = vec![("nothing (correct structure)".to_string(), Extra::None)];
    // `viscous` is the plant without extra physics: a fitted LuGre model has viscous
    // friction, so that case is the row above.
    out.extend(
        NAMES
            .iter()
            .filter(|n| **n != "viscous")
            .map(|n| (n.to_string(), case(n).extra)),
    );
    out.push((
        "asymmetry (Coulomb level 0.02 N·m higher one way)".into(),
        Extra::Directional { dfc: 0.02, db: 0.0 },
    ));
    for (label, extra, _) in verdict_cases() {
        if extra != Extra::None && !out.iter().any(|(_, e)| *e == extra) {
            out.push((label.to_string(), extra));
        }
    }
    out.push((
        "sawtooth load over a revolution (no formula in the list)".into(),
        Extra::SawtoothLoad { amp: 0.08 },
    ));
    out
}

/// One loop on one seed.
struct Row {
    seed: u64,
    /// What the first diagnosis (of the first fitted model, on each fitting log) said.
    first: String,
    /// Whether that diagnosis called the model adequate on the multisine a (on the steps d
    /// the whiteness and carrier checks cannot judge, whatever the model).
    adequate: bool,
    /// Each addition tried: its spec, whether the keep-or-not test kept it, and that test's
    /// p-value and the share of the selection residual it explained.
    added: Vec<(String, bool, f64, f64)>,
    stop: workflow::Stop,
    base: f64,
    last: f64,
}

impl Row {
    fn removed(&self) -> f64 {
        (self.last - self.base) / (100.0 - self.base)
    }
}

fn said(d: &Diagnosis) -> String {
    if d.verdict.adequate {
        return "adequate".into();
    }
    let mut parts: Vec<String> = d.effects.iter().map(|f| f.name.clone()).collect();
    parts.extend(
        d.verdict
            .unexplained
            .iter()
            .map(|u| format!("carried by {}", u.variable)),
    );
    parts.extend(
        d.verdict
            .checks
            .iter()
            .filter(|c| !c.passed && !c.p_value.is_nan())
            .map(|c| format!("failed {}", c.name)),
    );
    parts.dedup();
    let verdict = if d.verdict.judged {
        "not adequate"
    } else {
        "cannot judge"
    };
    if parts.is_empty() {
        verdict.to_string()
    } else {
        format!("{verdict}: {}", parts.join(", "))
    }
}

fn one_loop(extra: Extra, seed: u64) -> Row {
    let p = OtherPlant::new(extra);
    let centre = 0.5 * p.hall;
    let run = |kind: SignalKind, seconds: f64, s: u64, name: &str| {
        let (mut log, omega) = p.run_with_velocity(&signal(kind, seconds, s), TS, s, centre);
        log.source = name.into();
        (log, omega)
    };
    let fit_logs: Vec<MotorLog> = vec![
        run(SignalKind::A, SECONDS, seed, "a.csv").0,
        run(SignalKind::D, STEP_SECONDS, seed + 2000, "d.csv").0,
    ];
    let select = [run(SignalKind::B, SECONDS, seed + 1000, "b.csv").0];
    let (test, omega) = run(SignalKind::B, SECONDS, seed + 3000, "b-test.csv");
    let out = workflow::run(
        &workflow::Config {
            kind: ModelKind::Lugre,
            plant: Plant::Voltage,
            fit_logs: &fit_logs,
            select_logs: &select,
            start: Vec::new(),
            constraints: &Constraints::NONE,
            max_rounds: MAX_ROUNDS,
            diagnose: motorid::diagnose::Options::default(),
        },
        &mut |req| Ok(ident::fit(req)?.model),
        &mut |_| {},
    )
    .unwrap();
    let score = |m: &Model| {
        ident::freerun::simulate(m, &test)
            .ok()
            .and_then(|pr| ident::fitpct::fit_percent(&omega, &pr.omega).ok())
            .unwrap_or(f64::NEG_INFINITY)
    };
    Row {
        seed,
        first: out.rounds[0]
            .diagnoses
            .iter()
            .zip(["a", "d"])
            .map(|(d, log)| format!("{log}: {}", said(d)))
            .collect::<Vec<_>>()
            .join("; "),
        added: out.rounds[1..]
            .iter()
            .map(|r| {
                let spec = r.adds.last().map_or(String::new(), |s| s.to_string());
                let (p, share) = r
                    .selection_test
                    .as_ref()
                    .map_or((f64::NAN, f64::NAN), |t| (t.p_value, t.explained));
                (spec, r.kept, p, share)
            })
            .collect(),
        adequate: out.rounds[0]
            .diagnoses
            .first()
            .is_some_and(|d| d.verdict.adequate),
        stop: out.stop,
        base: score(&out.rounds[0].model),
        last: score(out.final_model()),
    }
}

#[test]
#[ignore = "writes docs/loop-table.md (about 45 loops, several minutes)"]
fn write_loop_table() {
    use std::fmt::Write;
    let mut md = String::from(HEAD);
    let mut summary = String::from(SUMMARY_HEAD);
    for (label, extra) in cases() {
        let rows: Vec<Row> = std::thread::scope(|scope| {
            let loops: Vec<_> = SEEDS
                .iter()
                .map(|&s| scope.spawn(move || one_loop(extra, s)))
                .collect();
            loops.into_iter().map(|h| h.join().unwrap()).collect()
        });
        for r in &rows {
            let added: Vec<String> = r
                .added
                .iter()
                .map(|(s, kept, p, share)| {
                    let verdict = if *kept { "kept" } else { "not kept" };
                    format!("`{s}` ({verdict}: p {p:.1e}, {:.0} %)", 100.0 * share)
                })
                .collect();
            let line = format!(
                "| {label} | {} | {} | {} | {:?} | {:.2} | {:.2} | {:.0} % |",
                r.seed,
                r.first,
                added.join(", "),
                r.stop,
                r.base,
                r.last,
                100.0 * r.removed()
            );
            eprintln!("{line}");
            let _ = writeln!(md, "{line}");
        }
        let kept = rows.iter().filter(|r| r.added.iter().any(|a| a.1)).count();
        let mut removed: Vec<f64> = rows.iter().map(Row::removed).collect();
        removed.sort_by(f64::total_cmp);
        let _ = writeln!(
            summary,
            "| {label} | {}/{} | {}/{} | {:.0} % |",
            rows.iter().filter(|r| !r.adequate).count(),
            rows.len(),
            kept,
            rows.len(),
            100.0 * removed[removed.len() / 2]
        );
    }
    md.push_str(&summary);
    let path = e2e::root().join("docs").join("loop-table.md");
    std::fs::write(&path, md).unwrap();
    eprintln!("wrote {}", path.display());
    // The README shows the summary between its two markers.
    let readme = e2e::root().join("README.md");
    let text = std::fs::read_to_string(&readme).unwrap();
    let (begin, end) = ("<!-- loop-table -->\n", "<!-- /loop-table -->");
    let (Some(a), Some(b)) = (text.find(begin), text.find(end)) else {
        panic!("README.md lacks the markers {begin:?} and {end:?}");
    };
    let table = summary
        .split_once("\n| hidden")
        .map_or(String::new(), |(_, t)| t.to_string());
    let new = format!("{}{begin}| hidden{table}{}", &text[..a], &text[b..]);
    std::fs::write(&readme, new).unwrap();
    eprintln!("updated the summary in {}", readme.display());
}

const HEAD: &str = "# The loop on a plant our equations did not make\n\n\
     Generated by `cargo test --release -p e2e --test loop_table -- --ignored --nocapture` \
     (`tests/tests/loop_table.rs`). The plant is `tests/src/other_plant.rs` (RK4 on a 50 µs \
     grid, Karnopp stick-slip friction, its own noise) with one case hidden \
     (`tests/src/plant_cases.rs` gives each case's size and why). The loop is `motorid \
     demo`'s: fit LuGre on 90 s of signal a and 30 s of the steps d, diagnose, add the effect \
     or table the diagnosis names, refit, keep the refit only when it explains 90 s of signal \
     b significantly better (the keep-or-not test's p-value and the share of the selection \
     residual the addition explains are given beside it); scored on a fresh 90 s of signal b, the free run's velocity \
     against the plant's true velocity. First diagnosis: the verdict on the first fitted \
     model, on each fitting log (a, d). Error removed: the share of the first model's error (100 % less \
     its fit) that the final model no longer makes.\n\n\
     | hidden | seed | first diagnosis | added (in order) | stop | first fit % | final fit % | error removed |\n\
     |---|---|---|---|---|---|---|---|\n";

const SUMMARY_HEAD: &str = "\n## Summary\n\n\
     Not adequate on a: the first diagnosis did not call the fitted model adequate on the \
     multisine a (on the steps d its whiteness and carrier checks cannot judge any model; \
     for the correct structure, a false alarm; a fitted LuGre model has a Stribeck dip of \
     its own, so for `stribeck` it is the correct structure too). Kept: an addition passed the keep-or-not test. \
     Error removed: the median over the seeds.\n\n\
     | hidden | not adequate on a | kept an addition | error removed |\n|---|---|---|---|\n";
