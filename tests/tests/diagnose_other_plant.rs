//! The named effects hidden in a plant our emulator did not make (`e2e::other_plant`: RK4,
//! Karnopp stick-slip friction, its own noise, and each effect written its own way), judged
//! by `motorid diagnose --json` as a user runs it: the plant's log as a CSV, and as
//! MODEL.toml the plant's own constants without the hidden physics.
//!
//! What the product promises, asserted per effect: the model is never called adequate while
//! an effect is hidden, and the effect's name is reported (a finding, or one of a look-alike
//! pair) on at least 2 of 3 seeds. Not 3 of 3: the findings are tests at a stated level
//! whose power at a real effect's size is below 1, so a miss on one seed is what a sound
//! test does now and then; a miss on two of three is a defect. The verdict itself is a union
//! of checks (residual whiteness, the input, the parameters, findings, carriers) and is held
//! to every seed. What fails today is `#[ignore]`d with its reason;
//! `cargo test --release -p e2e --test diagnose_other_plant -- --ignored write_table`
//! regenerates docs/other-plant.md, the table of every case.
use control::effects::Effect;
use control::motor::MotorParams;
use e2e::other_plant::{Extra, OtherPlant, PreslidingPlant};
use e2e::plant_cases::{case, Case, NAMES};
use motorid::emulator::{signal, SignalKind};
use motorid::log::{MotorLog, Plant};
use motorid::model::{Model, ModelKind};
use serde_json::Value;

const TS: f64 = 0.012;
const SECONDS: f64 = 60.0;
const SEEDS: [u64; 3] = [1, 2, 3];
/// Seeds of 3 on which the name must be reported (see the file's doc).
const NAMED_AT_LEAST: usize = 2;

/// What `diagnose --json` said on one log.
struct Outcome {
    signal: SignalKind,
    seed: u64,
    adequate: bool,
    /// Findings: name and share of the residual.
    effects: Vec<(String, f64)>,
    /// Look-alike pairs (findings or carriers).
    look_alikes: Vec<[String; 2]>,
    /// Carriers: variable and share.
    carriers: Vec<(String, f64)>,
    /// Checks that failed in either equation, by name ("cannot judge" when a check could not
    /// decide).
    failed: Vec<String>,
    /// Constants the parameter check refitted, by name.
    refit: Vec<String>,
}

impl Outcome {
    /// Not adequate because something decided so: a finding, a carrier or a check that
    /// decided (not only checks that cannot judge this log).
    fn claims(&self) -> bool {
        !self.effects.is_empty()
            || !self.carriers.is_empty()
            || self.failed.iter().any(|f| !f.ends_with("(cannot judge)"))
    }

    /// The effect `name` is reported: a finding, or one of a look-alike pair. Viscous
    /// friction is part of every model `diagnose` reads (a model without it states b = 0),
    /// so it is never a missing effect: it is reported by the parameter check's refit.
    fn names(&self, name: &str) -> bool {
        self.effects.iter().any(|(n, _)| n == name)
            || self.look_alikes.iter().any(|l| l.iter().any(|n| n == name))
            || (name == "viscous" && self.refit.iter().any(|n| n.contains(name)))
    }
}

/// MODEL.toml of the plant's own constants: Coulomb friction as an effect, viscous friction
/// where asked, the rigid inertia, and the plant's Hall step.
fn given_model(p: &OtherPlant, viscous: bool) -> Model {
    let mut m = Model::new(ModelKind::Linear, Plant::Voltage, TS);
    m.motor = MotorParams {
        r: p.r,
        l: p.l,
        kt: p.kt,
        kb: p.kt,
        j: p.j,
    };
    m.viscous = if viscous { p.b } else { 0.0 };
    m.effects = vec![Effect::Coulomb { fc: p.fc }];
    m.sensor.hall_resolution_rad = p.hall;
    m
}

/// Run the plant on `kind` with `seed`, write its log and the given model, and read what
/// `motorid diagnose --json` says.
fn diagnose(c: &Case, kind: SignalKind, seed: u64) -> Outcome {
    let p = OtherPlant::new(c.extra);
    let log = p.run(&signal(kind, SECONDS, seed), TS, seed);
    judge(log, &given_model(&p, c.viscous_in_model), kind, seed)
}

/// Coulomb friction hidden: the plant's own (Karnopp: it holds the rotor at rest up to its
/// level and opposes the sliding motion with it), judged with a linear model of the plant's
/// constants and viscous friction alone.
fn without_coulomb(p: &OtherPlant) -> Model {
    let mut m = given_model(p, true);
    m.effects.clear();
    m
}

/// What `motorid diagnose --json` says of `log` (the plant run on `kind` with `seed`) with
/// `model` given.
fn judge(log: MotorLog, model: &Model, kind: SignalKind, seed: u64) -> Outcome {
    let dir = tempfile::tempdir().unwrap();
    log.write(&dir.path().join("log.csv")).unwrap();
    model.save(&dir.path().join("model.toml")).unwrap();
    let out = e2e::stdout_of_success(e2e::motorid(
        dir.path(),
        &["diagnose", "model.toml", "log.csv", "--json"],
    ));
    let v: Value = serde_json::from_str(out.trim()).expect("one JSON object");
    let list = |key: &str| v[key].as_array().cloned().unwrap_or_default();
    let pair = |e: &Value, a: &str, b: &str| {
        (
            e[a].as_str().unwrap_or("?").to_string(),
            e[b].as_f64().unwrap_or(f64::NAN),
        )
    };
    Outcome {
        signal: kind,
        seed,
        adequate: v["adequate"].as_bool().expect("adequate"),
        effects: list("effects")
            .iter()
            .map(|e| pair(e, "name", "score"))
            .collect(),
        look_alikes: list("look_alikes")
            .iter()
            .map(|l| {
                let n = |k: usize| l["names"][k].as_str().unwrap_or("?").to_string();
                [n(0), n(1)]
            })
            .collect(),
        carriers: list("unexplained")
            .iter()
            .map(|u| pair(u, "variable", "share"))
            .collect(),
        failed: list("checks")
            .iter()
            .filter(|c| c["passed"] == false)
            .map(|c| {
                let name = c["name"].as_str().unwrap_or("?");
                if c["p_value"].is_null() {
                    format!("{name} (cannot judge)")
                } else {
                    name.to_string()
                }
            })
            .fold(Vec::new(), |mut v: Vec<String>, c| {
                if !v.contains(&c) {
                    v.push(c);
                }
                v
            }),
        refit: list("refit")
            .iter()
            .map(|r| r["name"].as_str().unwrap_or("?").to_string())
            .collect(),
    }
}

fn describe(o: &Outcome) -> String {
    format!(
        "{} seed {}: adequate {} effects {:?} look-alikes {:?} carriers {:?} failed {:?} \
         refit {:?}",
        o.signal.name(),
        o.seed,
        o.adequate,
        o.effects,
        o.look_alikes,
        o.carriers,
        o.failed,
        o.refit
    )
}

/// The promise on one effect and one signal: never adequate, named on at least 2 of 3 seeds.
fn check(name: &str, kind: SignalKind) {
    let c = case(name);
    assert!(c.signals.contains(&kind));
    let runs: Vec<Outcome> = SEEDS.iter().map(|&s| diagnose(&c, kind, s)).collect();
    hold_to_the_promise(name, &runs);
}

/// The signals the friction law's own effects (Coulomb, presliding) are judged on: the
/// multisine a, and the voltage steps d (braking to rest and holding there, where
/// stick-slip and presliding show most).
const FRICTION_SIGNALS: [SignalKind; 2] = [SignalKind::A, SignalKind::D];

/// [`diagnose`] of the plant with nothing added, judged without its Coulomb friction.
fn diagnose_coulomb(kind: SignalKind, seed: u64) -> Outcome {
    let p = OtherPlant::new(Extra::None);
    let log = p.run(&signal(kind, SECONDS, seed), TS, seed);
    judge(log, &without_coulomb(&p), kind, seed)
}

/// Travel after a reversal over which the presliding plant's friction builds up [rad]: the
/// wind-up of a geared axis seen at the rotor, sized as `presliding`'s own default (a
/// harmonic drive's compliance through its ratio, a breakaway deflection of a few Hall
/// steps): 0.4 rad, whose first stiffness (fc/0.4 times the elements' harmonic sum, 0.44
/// N·m/rad) is that default's σ0.
const PRESLIDING_BREAKAWAY: f64 = 0.4;

/// Presliding hidden: the plant's friction deflects before it slides (a Maxwell-slip model,
/// [`PreslidingPlant`]), judged with the plant's constants, Coulomb and viscous friction.
fn diagnose_presliding(kind: SignalKind, seed: u64) -> Outcome {
    let p = PreslidingPlant {
        base: OtherPlant::new(Extra::None),
        breakaway: PRESLIDING_BREAKAWAY,
    };
    let log = p.run(&signal(kind, SECONDS, seed), TS, seed);
    judge(log, &given_model(&p.base, true), kind, seed)
}

/// A case judged on a signal with a seed.
type Judged = fn(SignalKind, u64) -> Outcome;

fn check_presliding(kind: SignalKind) {
    let runs: Vec<Outcome> = SEEDS
        .iter()
        .map(|&s| diagnose_presliding(kind, s))
        .collect();
    hold_to_the_promise("presliding", &runs);
}

fn check_coulomb(kind: SignalKind) {
    let runs: Vec<Outcome> = SEEDS.iter().map(|&s| diagnose_coulomb(kind, s)).collect();
    hold_to_the_promise("coulomb", &runs);
}

/// Never adequate on any seed, and `name` reported on at least [`NAMED_AT_LEAST`] of them.
fn hold_to_the_promise(name: &str, runs: &[Outcome]) {
    let all: Vec<String> = runs.iter().map(describe).collect();
    let all = all.join("\n");
    assert!(
        runs.iter().all(|o| !o.adequate),
        "{name} hidden, called adequate:\n{all}"
    );
    let named = runs.iter().filter(|o| o.names(name)).count();
    assert!(named >= NAMED_AT_LEAST, "{name} named on {named}/3:\n{all}");
}

#[test]
fn cogging_on_a() {
    check("cogging", SignalKind::A);
}

/// The identification loop on the plant with its slot cogging hidden, as
/// `tests/tests/fit_add_effects.rs` runs it on the emulator: a LuGre fit on the multisine a
/// and the steady runs, diagnosed, refitted once with what the diagnosis named, the refit
/// kept or not on a selection draw of signal b; scored on a second draw of b no choice was
/// made on, as the free run's velocity against the plant's true velocity.
///
/// The true model is the plant's constants with both cogging harmonics, their phases in the
/// log's angle: the plant's Hall reading is the floor of its angle, the product's the
/// nearest step, so the log's angle is the plant's less half a step. A free run starts from
/// the log's first angle, which puts the rotor anywhere in its Hall band; the test draw is
/// run from [`LOOP_STARTS`] starts across the band and each model scored by its mean fit,
/// so that no model gains from where one start happens to fall.
struct CoggingLoop {
    seed: u64,
    /// The added spec as `diagnose` printed it and as refitted; whether the refit was kept.
    added: Option<(String, String, bool)>,
    base: f64,
    refit: Option<f64>,
    truth: f64,
    /// The true model with the slot harmonic alone (what one cogging term can reach).
    truth_one: f64,
}

impl CoggingLoop {
    /// Share of the gap from the base fit to the true model the refit closes.
    fn closed(&self) -> f64 {
        self.refit
            .map_or(0.0, |r| (r - self.base) / (self.truth - self.base))
    }
}

/// Fitting, selection and test lengths [s], those of `fit_add_effects.rs`.
const LOOP_FIT_SECONDS: f64 = 50.0;
const LOOP_STEADY_SECONDS: f64 = 40.0;
const LOOP_SELECT_SECONDS: f64 = 40.0;
/// Starts of the test draw within the first Hall band, evenly spread.
const LOOP_STARTS: usize = 5;

fn cogging_loop(seed: u64) -> CoggingLoop {
    use motorid::ident::{self, free_params::Constraints};
    use motorid::workflow;
    let c = case("cogging");
    let p = OtherPlant::new(c.extra);
    // The fitting and selection logs from the centre of the first band.
    let run = |kind: SignalKind, seconds: f64, s: u64, name: &str, theta0: f64| {
        let (mut log, omega) = p.run_with_velocity(&signal(kind, seconds, s), TS, s, theta0);
        log.source = name.into();
        (log, omega)
    };
    let centre = 0.5 * p.hall;
    let fit_logs = vec![
        run(SignalKind::A, LOOP_FIT_SECONDS, seed, "a.csv", centre).0,
        run(
            SignalKind::Steady,
            LOOP_STEADY_SECONDS,
            seed,
            "steady.csv",
            centre,
        )
        .0,
    ];
    let select = [run(
        SignalKind::B,
        LOOP_SELECT_SECONDS,
        seed + 1000,
        "b.csv",
        centre,
    )
    .0];
    let tests: Vec<(MotorLog, Vec<f64>)> = (0..LOOP_STARTS)
        .map(|k| {
            let theta0 = (k as f64 + 0.5) / LOOP_STARTS as f64 * p.hall;
            run(
                SignalKind::B,
                LOOP_SELECT_SECONDS,
                seed + 3000,
                "b-test.csv",
                theta0,
            )
        })
        .collect();
    let out = workflow::run(
        &workflow::Config {
            kind: ModelKind::Lugre,
            plant: Plant::Voltage,
            fit_logs: &fit_logs,
            select_logs: &select,
            start: Vec::new(),
            constraints: &Constraints::NONE,
            max_rounds: 1,
            diagnose: motorid::diagnose::Options::default(),
        },
        &mut |req| Ok(ident::fit(req)?.model),
        &mut |_| {},
    )
    .unwrap();
    let score = |m: &Model| {
        let fits = tests.iter().map(|(log, omega)| {
            ident::freerun::simulate(m, log)
                .ok()
                .and_then(|pr| ident::fitpct::fit_percent(omega, &pr.omega).ok())
                .unwrap_or(f64::NEG_INFINITY)
        });
        fits.sum::<f64>() / LOOP_STARTS as f64
    };
    let mut truth = given_model(&p, true);
    if let Extra::SlotCogging {
        slots,
        a1,
        p1,
        a2,
        p2,
    } = c.extra
    {
        // Each harmonic's phase in the log's angle (the plant's less half a step).
        let h = f64::from(slots);
        truth.effects.push(Effect::Cogging {
            harmonic: slots,
            amp: a1,
            phase: p1 + h * centre,
        });
        truth.effects.push(Effect::Cogging {
            harmonic: 2 * slots,
            amp: a2,
            phase: p2 + 2.0 * h * centre,
        });
    }
    let mut truth_one = truth.clone();
    truth_one.effects.pop();
    let refit = out.rounds.get(1);
    CoggingLoop {
        seed,
        added: refit.map(|r| {
            let spec = r.adds.last().unwrap();
            let fitted = r
                .model
                .effects
                .iter()
                .rev()
                .find(|e| e.kind() == spec.kind)
                .map_or(String::new(), |e| {
                    motorid::effect_spec::EffectSpec::from_effect(e).to_string()
                });
            (spec.to_string(), fitted, r.kept)
        }),
        base: score(&out.rounds[0].model),
        refit: refit.map(|r| score(&r.model)),
        truth: score(&truth),
        truth_one: score(&truth_one),
    }
}

/// The loop's rows for `COGGING_SEEDS` (comma-separated; default [`SEEDS`]), the loops side
/// by side, printed.
fn cogging_rows() -> Vec<CoggingLoop> {
    let seeds: Vec<u64> = std::env::var("COGGING_SEEDS")
        .ok()
        .map(|v| v.split(',').filter_map(|s| s.parse().ok()).collect())
        .unwrap_or(SEEDS.to_vec());
    let rows: Vec<CoggingLoop> = std::thread::scope(|scope| {
        let loops: Vec<_> = seeds
            .iter()
            .map(|&s| scope.spawn(move || cogging_loop(s)))
            .collect();
        loops.into_iter().map(|h| h.join().unwrap()).collect()
    });
    for r in &rows {
        eprintln!(
            "seed {}: base {:.2} refit {} truth {:.2} (slot harmonic alone {:.2}) closed {:.0} %; \
             added {:?}",
            r.seed,
            r.base,
            r.refit.map_or("none".into(), |x| format!("{x:.2}")),
            r.truth,
            r.truth_one,
            100.0 * r.closed(),
            r.added
        );
    }
    rows
}

/// The hidden cogging was added by name and its refit kept.
fn cogging_added(r: &CoggingLoop) -> bool {
    r.added
        .as_ref()
        .is_some_and(|(spec, _, kept)| *kept && spec.starts_with("cogging"))
}

/// Cogging found by name on this plant: on every seed the loop adds it and keeps the refit,
/// and on at least 2 of 3 (the rule of this file's names, [`NAMED_AT_LEAST`]) the refit
/// closes at least half of the gap between the base fit and the true model on fresh data.
/// Every seed is held to it by the ignored test below; the gap is under a point of fit, and
/// the seed that falls short misses by the selection log's choice of cogging estimate
/// (docs/limits.md).
#[test]
fn cogging_found_by_name_closes_half_the_gap_on_most_seeds() {
    let rows = cogging_rows();
    assert!(
        rows.iter().all(cogging_added),
        "cogging not added and kept on every seed"
    );
    let closed = rows.iter().filter(|r| r.closed() >= 0.5).count();
    assert!(
        closed >= NAMED_AT_LEAST * rows.len() / SEEDS.len(),
        "half the gap closed on {closed} of {} seeds",
        rows.len()
    );
}

#[test]
#[ignore = "seed 3 closes 13 % of a gap of 0.4 points: the selection log prefers the cogging estimated by weak form on the base fit (18 % high, 0.14 rad off) to the joint refinement's (within 1 %), by 0.05 points; the true cogging on the same constants would close 51 % (docs/limits.md)"]
fn cogging_found_by_name_closes_half_the_gap() {
    let failed: Vec<u64> = cogging_rows()
        .iter()
        .filter(|r| !(cogging_added(r) && r.closed() >= 0.5))
        .map(|r| r.seed)
        .collect();
    assert!(failed.is_empty(), "seeds {failed:?} below half the gap");
}

#[test]
fn coulomb_on_a() {
    check_coulomb(SignalKind::A);
}

#[test]
fn coulomb_on_d() {
    check_coulomb(SignalKind::D);
}

#[test]
fn presliding_on_a() {
    check_presliding(SignalKind::A);
}

#[test]
#[ignore = "named on 0/3: on the voltage steps the presliding candidate is not significant, and only the checks that cannot judge held steps fail"]
fn presliding_on_d() {
    check_presliding(SignalKind::D);
}

#[test]
fn deadtime_on_a() {
    check("deadtime", SignalKind::A);
}

#[test]
#[ignore = "named on 1/3: on voltage steps the cluster-robust entry test has few held inputs and the parameter check takes the loss as a resistance"]
fn deadtime_on_d() {
    check("deadtime", SignalKind::D);
}

#[test]
#[ignore = "not named: +1-2 % of resistance on the multisine; the thermal candidate misses the Bonferroni level, and the model is not adequate by the voltage equation's parameter drift instead (docs/decisions/0028-significant-means-not-adequate.md)"]
fn thermal_on_a() {
    check("thermal", SignalKind::A);
}

#[test]
fn thermal_on_d() {
    check("thermal", SignalKind::D);
}

#[test]
fn current_offset_on_a() {
    check("current_offset", SignalKind::A);
}

#[test]
fn current_offset_on_d() {
    check("current_offset", SignalKind::D);
}

#[test]
fn offset_on_a() {
    check("offset", SignalKind::A);
}

#[test]
fn offset_on_d() {
    check("offset", SignalKind::D);
}

#[test]
fn position_load_on_a() {
    check("position_load", SignalKind::A);
}

#[test]
#[ignore = "not named: tooth friction on the mostly inertial transmitted torque shows as wrong constants: the parameter check refits J and the friction"]
fn load_friction_on_a() {
    check("load_friction", SignalKind::A);
}

#[test]
#[ignore = "named on 1/3: on voltage steps the cluster-robust entry test has few held inputs"]
fn load_friction_on_d() {
    check("load_friction", SignalKind::D);
}

#[test]
fn stribeck_on_a() {
    check("stribeck", SignalKind::A);
}

#[test]
#[ignore = "named on 1 of 3 seeds only: on the others only the checks that cannot judge voltage steps fail"]
fn stribeck_on_d() {
    check("stribeck", SignalKind::D);
}

#[test]
fn viscous_on_a() {
    check("viscous", SignalKind::A);
}

/// Regenerates docs/other-plant.md: every case, signal and seed, and a summary per effect.
#[test]
#[ignore = "writes docs/other-plant.md (about 57 diagnoses)"]
fn write_table() {
    use std::fmt::Write;
    let mut md = String::from(TABLE_HEAD);
    let mut summary = String::from(SUMMARY_HEAD);
    let mut write = |name: &str, kind: SignalKind, runs: &[Outcome]| {
        for o in runs {
            let pct = |v: &[(String, f64)]| {
                v.iter()
                    .map(|(n, s)| format!("{n} ({:.0} %)", 100.0 * s))
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            let pairs: Vec<String> = o
                .look_alikes
                .iter()
                .map(|l| format!("{} ~ {}", l[0], l[1]))
                .collect();
            let _ = writeln!(
                md,
                "| {name} | {} | {} | {} | {} | {} | {} | {} | {} |",
                kind.name(),
                o.seed,
                o.adequate,
                pct(&o.effects),
                pairs.join(", "),
                pct(&o.carriers),
                o.failed.join(", "),
                o.refit.join(", ")
            );
        }
        let named = runs.iter().filter(|o| o.names(name)).count();
        let flagged = runs.iter().filter(|o| !o.adequate).count();
        let claimed = runs.iter().filter(|o| !o.adequate && o.claims()).count();
        let _ = writeln!(
            summary,
            "| {name} | {} | {named}/3 | {flagged}/3 | {claimed}/3 |",
            kind.name()
        );
    };
    let friction: [(&str, Judged); 2] = [
        ("coulomb", diagnose_coulomb),
        ("presliding", diagnose_presliding),
    ];
    for (name, judged) in friction {
        for kind in FRICTION_SIGNALS {
            let runs: Vec<Outcome> = SEEDS.iter().map(|&s| judged(kind, s)).collect();
            write(name, kind, &runs);
        }
    }
    for name in NAMES {
        let c = case(name);
        for &kind in c.signals {
            let runs: Vec<Outcome> = SEEDS.iter().map(|&s| diagnose(&c, kind, s)).collect();
            write(name, kind, &runs);
        }
    }
    md.push_str(&summary);
    md.push_str(TABLE_TAIL);
    let path = e2e::root().join("docs").join("other-plant.md");
    std::fs::write(&path, md).unwrap();
    eprintln!("wrote {}", path.display());
}

const TABLE_HEAD: &str = "# Eleven named effects hidden in a plant our equations did not make\n\n\
     Generated by `cargo test --release -p e2e --test diagnose_other_plant -- --ignored \
     write_table`. The plant is `tests/src/other_plant.rs` (RK4 on a 50 µs grid, Karnopp \
     stick-slip friction, its own noise), each effect written there its own way and sized as \
     a real motor of its class shows it (the reasons are beside each case in \
     `tests/tests/diagnose_other_plant.rs`); 60 s at 12 ms of the multisine a, and of the \
     voltage steps d where the effect shows in braking, at rest or in heat. The model given to \
     `motorid diagnose --json` is MODEL.toml with the plant's own constants, Coulomb and \
     viscous friction, without the hidden effect (for `viscous`: without viscous friction; \
     for `coulomb`: a linear model with viscous friction alone, on the plant with nothing \
     added, whose Coulomb friction is Karnopp stick-slip; for `presliding`: the plant's \
     friction written as Maxwell-slip elements that deflect up to 0.4 rad before sliding, \
     `PreslidingPlant`). \
     Effects and carriers: name (share of the residual); look-alikes: the pairs `diagnose` \
     reports as explaining about the same.\n\n\
     | effect hidden | signal | seed | adequate | effects | look-alikes | carried by | failed checks | refitted |\n\
     |---|---|---|---|---|---|---|---|---|\n";

const SUMMARY_HEAD: &str = "\n## Summary\n\n\
     Named: the hidden effect is a finding or one of a look-alike pair (viscous friction, \
     which every model `diagnose` reads states, even as b = 0: a refitted viscous \
     coefficient). Not adequate: the verdict did not say the model explains the data; by a \
     claim: with a finding, a carrier or a failed check that decided, not only checks that \
     cannot judge the log.\n\n\
     | effect hidden | signal | named | not adequate | by a claim |\n|---|---|---|---|---|\n";

const TABLE_TAIL: &str = "\nHow to read it. On the voltage steps d a correct model is itself \
     mostly not adequate because the whiteness and carrier checks cannot judge held steps \
     (docs/diagnose-verdict.md): there \"not adequate\" counts only with a finding, a \
     carrier or a failed check that decided. The tests in \
     `tests/tests/diagnose_other_plant.rs` hold each effect to the promise (never adequate, \
     named on at least 2 of 3 seeds) and keep the cases that fall short `#[ignore]`d with \
     their cause. Causes seen here: a winding that warms by up to 5 K over a minute of the \
     multisine raises R by up to 2 %: the thermal candidate misses the Bonferroni level, and \
     the model is not adequate because the voltage equation's parameter check sees its \
     parameters drift along the log, not by a name \
     (docs/decisions/0028-significant-means-not-adequate.md). Gear tooth \
     friction proportional to a transmitted torque that is mostly inertial looks like wrong \
     constants (the refit raises J and the friction). On steps, the cluster-robust entry test \
     has some 30 held inputs and names dead time or load friction on one seed of three. A \
     model without viscous friction fails the parameter check, whose refit gives the viscous \
     coefficient. Presliding written as Maxwell-slip elements is named on the multisine, \
     not on the voltage steps, where only the checks that cannot judge held steps fail.\n";
