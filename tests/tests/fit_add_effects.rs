//! The product's loop ([`motorid::workflow::run`]) on emulated data, effect by effect: hide one
//! effect (its default spec) in the emulated motor, let the loop fit the base model, diagnose
//! it and refit once with what it found, and check that the loop added the hidden effect by
//! name, kept the refit, and that the refit closes at least half of the gap between the base
//! model and the emulator's own model on a test log no choice was made on.
//!
//! The selection log (signal b) decides whether the refit is kept; the scores are on a second
//! draw of signal b. The test fit is the free-run velocity against the emulator's *true*
//! velocity, so the emulator's own model scores ~100 %. Against the measured,
//! Hall-quantised velocity through the sensor chain (also printed), only a model that tracks
//! the angle to a fraction of a Hall step reproduces the quantisation pattern: the true
//! model gains ~1 point over any fitted one from that alone (3 % of inertia costs half a
//! point), which would hide what the added effect brings.
//!
//! Coulomb and Stribeck are part of the LuGre law, so they are added to a linear base; the
//! Stribeck row's base has Coulomb friction too, so that only the hidden effect is missing
//! (a linear base also lacks the emulator's Coulomb friction, which then explains most of the
//! residual and is rightly named first).
//!
//! The look-alike pairs the first round reported are printed beside each row; a row passes
//! only when the hidden effect itself was added.
//! Prints the table of before / after / truth fits (`cargo test -p e2e --test
//! fit_add_effects -- --nocapture`; the ignored full table takes `FIT_ADD_EFFECTS=cogging,deadtime`
//! to run only some rows, and `FIT_ADD_EFFECTS_SEED=2` another draw of the emulator).
use control::effects::EffectKind;
use motorid::diagnose;
use motorid::effect_spec::EffectSpec;
use motorid::emulator::{simulate_signal, EmulatorConfig, SignalKind};
use motorid::ident::{self, free_params::Constraints};
use motorid::log::{MotorLog, Plant};
use motorid::model::{Model, ModelKind};
use motorid::workflow;

/// Fitting, selection and test signal lengths [s]: long enough for several slow cycles of
/// the paper's multisines, short enough to keep the test's runtime modest.
const FIT_SECONDS: f64 = 50.0;
const VALIDATE_SECONDS: f64 = 40.0;
const STEADY_SECONDS: f64 = 40.0;
/// Voltage steps (signal d) [s] for the effects that act only when the drive brakes the rotor
/// or the current is high (load friction, saturation): the multisine and the steady speeds
/// never brake hard and stay near 6 A, where neither shows. The entry test needs about this
/// much of them to see load friction (docs/decisions/0011-robust-wald-verdict.md, its cost).
const STEPS_SECONDS: f64 = 180.0;

fn log(cfg: &EmulatorConfig, kind: SignalKind, seconds: f64, name: &str) -> (MotorLog, Vec<f64>) {
    let r = simulate_signal(cfg, kind, seconds).unwrap();
    let mut l = r.log;
    l.source = name.into();
    (l, r.truth.omega)
}

/// Fit % of a model's free-run velocity against the true velocity, and through the sensor
/// chain against the measurement; −∞ when the model diverges.
fn scores(m: &Model, val: &MotorLog, omega_true: &[f64]) -> (f64, f64) {
    let Ok(p) = ident::freerun::simulate(m, val) else {
        return (f64::NEG_INFINITY, f64::NEG_INFINITY);
    };
    let vs_truth = ident::fitpct::fit_percent(omega_true, &p.omega).unwrap_or(f64::NEG_INFINITY);
    let sensor = ident::score_prediction(m, val, &p)
        .map(|s| s.fit_sensor.xdot)
        .unwrap_or(f64::NEG_INFINITY);
    (vs_truth, sensor)
}

struct Row {
    effect: &'static str,
    /// What the loop's refit added, and whether the refit was kept.
    added: Option<(String, bool)>,
    /// The added effect's spec as diagnosed → as refitted.
    refitted: String,
    /// Share of the gap closed on the selection log (which chose the refit), for comparison;
    /// None without a refit.
    closed_on_selection: Option<f64>,
    base: (f64, f64),
    /// None when the loop added nothing.
    refit: Option<(f64, f64)>,
    truth: (f64, f64),
    /// Look-alike pairs the first round's diagnoses reported.
    look_alikes: Vec<[String; 2]>,
    /// Why the loop stopped.
    stop: workflow::Stop,
}

/// The emulator's seed from `FIT_ADD_EFFECTS_SEED` (the signals' and the current noise's
/// draw), to measure the table over several draws; unset: the emulator's default.
fn emulator_seed() -> Option<u64> {
    std::env::var("FIT_ADD_EFFECTS_SEED").ok()?.parse().ok()
}

fn case(effect: EffectKind) -> Row {
    case_with_seed(effect, emulator_seed())
}

/// [`case`] on the emulator's draw `seed` (None: its default).
fn case_with_seed(effect: EffectKind, seed: Option<u64>) -> Row {
    let spec = EffectSpec::bare(effect);
    let mut cfg = EmulatorConfig::paper().with_effects(vec![spec.to_effect()]);
    if let Some(seed) = seed {
        cfg.seed = seed;
    }
    let mut fit_logs = vec![log(&cfg, SignalKind::A, FIT_SECONDS, "a.csv").0];
    let start = match effect {
        EffectKind::Stribeck => vec![EffectSpec::bare(EffectKind::Coulomb)],
        _ => Vec::new(),
    };
    let base_kind = match effect {
        EffectKind::Coulomb | EffectKind::Stribeck => ModelKind::Linear,
        _ => {
            fit_logs.push(log(&cfg, SignalKind::Steady, STEADY_SECONDS, "steady.csv").0);
            ModelKind::Lugre
        }
    };
    if matches!(effect, EffectKind::LoadFriction | EffectKind::Saturation) {
        fit_logs.push(log(&cfg, SignalKind::D, STEPS_SECONDS, "d.csv").0);
    }
    let draw = |offset: u64, name: &str| {
        let mut c = cfg.clone();
        c.seed = cfg.seed.wrapping_add(offset);
        log(&c, SignalKind::B, VALIDATE_SECONDS, name)
    };
    let (select_log, select_omega) = draw(1000, "b.csv");
    let select = [select_log];
    let (test_log, omega_true) = draw(3000, "b-test.csv");
    let out = workflow::run(
        &workflow::Config {
            kind: base_kind,
            plant: Plant::Voltage,
            fit_logs: &fit_logs,
            select_logs: &select,
            start,
            constraints: &Constraints::NONE,
            max_rounds: 1,
            diagnose: diagnose::Options::default(),
        },
        &mut |req| Ok(ident::fit(req)?.model),
        &mut |_| {},
    )
    .unwrap();
    let refit = out.rounds.get(1);
    Row {
        effect: effect.name(),
        added: refit.map(|r| {
            let a = r.adds.last().unwrap();
            (a.kind.name().to_string(), r.kept)
        }),
        refitted: refit.map_or(String::new(), |r| {
            let m = &r.model;
            format!(
                "{} → {:?}",
                r.adds.last().unwrap(),
                m.effects
                    .last()
                    .map(|e| e.kind())
                    .and_then(|_| m.effects.last())
            )
        }),
        base: scores(&out.rounds[0].model, &test_log, &omega_true),
        refit: refit.map(|r| scores(&r.model, &test_log, &omega_true)),
        truth: scores(&cfg.truth_model(), &test_log, &omega_true),
        closed_on_selection: refit.map(|r| {
            let on = |m: &Model| scores(m, &select[0], &select_omega).0;
            let (b, t) = (on(&out.rounds[0].model), on(&cfg.truth_model()));
            (on(&r.model) - b) / (t - b)
        }),
        look_alikes: out.rounds[0]
            .diagnoses
            .iter()
            .flat_map(|d| d.verdict.look_alikes.iter().map(|l| l.names.clone()))
            .collect(),
        stop: out.stop,
    }
}

#[test]
#[ignore = "slow: about 1 min on 2 cores in release (20 fits); run with `cargo test --release -p e2e \
            --test fit_add_effects -- --ignored --nocapture`"]
fn the_loop_adds_each_effect_and_closes_half_the_gap_to_the_truth() {
    // Presliding only moves σ0/σ1 of the LuGre law, and viscous only α2: the base LuGre
    // model already has both terms, so there is no gap to close for them.
    // FIT_ADD_EFFECTS=cogging,deadtime runs only those rows.
    let only = std::env::var("FIT_ADD_EFFECTS").ok();
    let effects: Vec<EffectKind> = EffectKind::ALL
        .into_iter()
        // Compliance and backlash are fitted by `fit --add` in fit_add_load.rs: on a log with
        // one of them `diagnose` may name the other first or both as a pair (docs/limits.md),
        // which this table's by-name check does not take. Saturation at its default
        // size is named only on minutes of voltage steps at a larger loss (docs/limits.md),
        // not on these logs. A table has no default torques to hide.
        .filter(|k| {
            !matches!(
                k,
                EffectKind::Presliding
                    | EffectKind::Viscous
                    | EffectKind::Compliance
                    | EffectKind::Backlash
                    | EffectKind::Saturation
                    | EffectKind::Table
            )
        })
        .filter(|k| {
            only.as_deref()
                .is_none_or(|o| o.split(',').any(|n| n == k.name()))
        })
        .collect();
    check(effects);
}

/// The part of the table above that the test command runs every time (the whole table takes
/// too long for CI): the position load, refined on multiple-shooting segments.
#[test]
fn the_loop_adds_position_load_and_closes_half_the_gap() {
    check(vec![EffectKind::PositionLoad]);
}

/// Cogging is the hardest row: its refit lands in the narrow basin of its multiple-shooting
/// cost (docs/limits.md), so on some draws the loop's refit loses the amplitude and the
/// guard does not keep it. One draw says little about that; five draws of the emulator
/// (seeds 1-5) must give the named, kept cogging that improves the fresh test draw on at
/// least three.
#[test]
fn the_loop_adds_cogging_on_most_draws() {
    let mut rows = on_two_threads((1..=5u64).collect(), |seed| {
        (seed, case_with_seed(EffectKind::Cogging, Some(seed)))
    });
    rows.sort_by_key(|r| r.0);
    let mut good = 0;
    for (seed, r) in &rows {
        let named = r.added.as_ref().is_some_and(|(n, k)| *k && n == r.effect);
        let refit = r.refit.map_or(f64::NEG_INFINITY, |x| x.0);
        let closed = (refit - r.base.0) / (r.truth.0 - r.base.0);
        println!(
            "seed {seed}: added {:?}, base {:.2}, refit {refit:.2}, truth {:.2}, gap closed {:.0} %",
            r.added,
            r.base.0,
            r.truth.0,
            100.0 * closed
        );
        if named && refit > r.base.0 {
            good += 1;
        }
    }
    assert!(
        good >= 3,
        "cogging named, kept and improving on {good} of 5 draws"
    );
}

/// `f` of every item on two worker threads (the cases are independent fits), in the order
/// they finish.
fn on_two_threads<T: Send, R: Send>(items: Vec<T>, f: impl Fn(T) -> R + Sync) -> Vec<R> {
    let queue = std::sync::Mutex::new(items);
    let rows = std::sync::Mutex::new(Vec::new());
    std::thread::scope(|s| {
        for _ in 0..2 {
            s.spawn(|| loop {
                let Some(item) = queue.lock().unwrap().pop() else {
                    break;
                };
                let r = f(item);
                rows.lock().unwrap().push(r);
            });
        }
    });
    rows.into_inner().unwrap()
}

fn check(effects: Vec<EffectKind>) {
    let rows = on_two_threads(effects, |k| {
        let r = case(k);
        eprintln!(
            "{:<14} base {:7.2}  refit {}  truth {:7.2}  added {:?}, refitted {}; \
             gap closed on the selection log {}; look-alikes {:?}; stop {:?}",
            r.effect,
            r.base.0,
            r.refit
                .map_or("   none".to_string(), |x| format!("{:7.2}", x.0)),
            r.truth.0,
            r.added,
            r.refitted,
            r.closed_on_selection
                .map_or("none".to_string(), |c| format!("{:.0} %", 100.0 * c)),
            r.look_alikes,
            r.stop
        );
        r
    });
    println!(
        "velocity fit % on a test draw of signal b: free run vs the true velocity | through \
         the sensor chain vs the measured one"
    );
    println!(
        "effect         added (kept)          base  refit  truth  gap closed | base  refit  truth"
    );
    let mut failed = Vec::new();
    for r in &rows {
        let gap = r.truth.0 - r.base.0;
        let added = r.added.as_ref().map_or("nothing".to_string(), |(n, k)| {
            format!("{n} ({})", if *k { "kept" } else { "not kept" })
        });
        let dash = |x: Option<f64>| x.map_or("     —".to_string(), |v| format!("{v:6.2}"));
        // Without a refit there is nothing to score: the row says so instead of a number.
        let Some(refit) = r.refit else {
            println!(
                "{:<14} {:<20} {:6.2} {} {:6.2}        — %  | {:6.2} {} {:6.2}   (loop stopped: {:?})",
                r.effect,
                added,
                r.base.0,
                dash(None),
                r.truth.0,
                r.base.1,
                dash(None),
                r.truth.1,
                r.stop
            );
            failed.push(r.effect);
            continue;
        };
        let closed = if gap.abs() > 1e-9 {
            (refit.0 - r.base.0) / gap
        } else {
            1.0
        };
        println!(
            "{:<14} {:<20} {:6.2} {} {:6.2} {:8.0} %  | {:6.2} {} {:6.2}",
            r.effect,
            added,
            r.base.0,
            dash(Some(refit.0)),
            r.truth.0,
            100.0 * closed,
            r.base.1,
            dash(Some(refit.1)),
            r.truth.1
        );
        // The hidden effect by name: a look-alike the loop added instead does not pass (the
        // pairs include ones reported whatever the shares say, and an effect that closes no
        // gap would pass on "not worse" alone).
        let named = r.added.as_ref().is_some_and(|(n, k)| *k && n == r.effect);
        // A base model already within a point of the truth has nothing to close: the
        // refit must then just not be worse by more than a point. Cogging's refit lands in
        // the narrow basin of its multiple-shooting cost (docs/limits.md): on the fresh test
        // draw it closes less than half of the gap, so for it only an improvement is asked.
        let ok = if gap < 1.0 {
            refit.0 >= r.base.0.min(r.truth.0) - 1.0
        } else if r.effect == EffectKind::Cogging.name() {
            closed > 0.0
        } else {
            closed >= 0.5
        };
        if !(named && ok) {
            failed.push(r.effect);
        }
    }
    assert!(
        failed.is_empty(),
        "the loop did not add the hidden effect by name or did not close half the gap for \
         {failed:?}"
    );
}
