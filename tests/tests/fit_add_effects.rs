//! The product's loop on emulated data, effect by effect: hide one effect (its default spec)
//! in the emulated motor, fit the base model without it, then `fit --add` its spec, and check
//! the validation fit (signal b, velocity through the sensor chain) closes at least half of
//! the gap between the base model and the emulator's own model (scored by the same function).
//!
//! Coulomb and Stribeck are part of the LuGre law, so they are added to a linear base.
//! Prints the table of before / after / truth fits (`cargo test -p tests --test
//! fit_add_effects -- --nocapture`).
use control::effects::EffectKind;
use motorid::effect_spec::EffectSpec;
use motorid::emulator::{simulate_signal, EmulatorConfig, SignalKind};
use motorid::ident::{self, FitRequest};
use motorid::log::{MotorLog, Plant};
use motorid::model::{Model, ModelKind};

/// Fitting and validation signal lengths [s]: long enough for several slow cycles of the
/// paper's multisines, short enough to keep the test's runtime modest.
const FIT_SECONDS: f64 = 50.0;
const VALIDATE_SECONDS: f64 = 40.0;
const STEADY_SECONDS: f64 = 40.0;

/// The emulator's own model as a [`Model`] (the truth the fits are measured against).
fn truth_model(cfg: &EmulatorConfig) -> Model {
    let mut m = Model::new(ModelKind::Lugre, Plant::Voltage, 0.012);
    m.motor = cfg.motor;
    m.lugre = Some(cfg.effective_lugre());
    m.effects = cfg.effects.clone();
    m.sensor.hall_resolution_rad = cfg.hall_resolution();
    m
}

fn log(cfg: &EmulatorConfig, kind: SignalKind, seconds: f64, name: &str) -> MotorLog {
    let mut l = simulate_signal(cfg, kind, seconds).unwrap().log;
    l.source = name.into();
    l
}

struct Row {
    effect: &'static str,
    base: f64,
    added: f64,
    truth: f64,
}

fn case(effect: EffectKind) -> Row {
    let spec = EffectSpec::bare(effect);
    let cfg = EmulatorConfig::paper().with_effects(vec![spec.to_effect()]);
    let mut fit_logs = vec![log(&cfg, SignalKind::A, FIT_SECONDS, "a.csv")];
    let base_kind = match effect {
        EffectKind::Coulomb | EffectKind::Stribeck => ModelKind::Linear,
        _ => {
            fit_logs.push(log(&cfg, SignalKind::Steady, STEADY_SECONDS, "steady.csv"));
            ModelKind::Lugre
        }
    };
    let val = vec![log(&cfg, SignalKind::B, VALIDATE_SECONDS, "b.csv")];
    let fit = |adds: &[EffectSpec]| -> f64 {
        let rep = ident::fit(&FitRequest {
            kind: base_kind,
            logs: &fit_logs,
            validate: &val,
            adds,
            plant: Plant::Voltage,
        })
        .unwrap();
        ident::score(&rep.model, &val[0])
            .map(|s| s.fit_sensor.xdot)
            .unwrap_or(f64::NEG_INFINITY)
    };
    let base = fit(&[]);
    let added = fit(std::slice::from_ref(&spec));
    let truth = ident::score(&truth_model(&cfg), &val[0])
        .unwrap()
        .fit_sensor
        .xdot;
    Row {
        effect: effect.name(),
        base,
        added,
        truth,
    }
}

#[test]
#[ignore = "slow: about 10 min in release (30 fits); run with `cargo test --release -p tests \
            --test fit_add_effects -- --ignored --nocapture`"]
fn fit_add_closes_half_the_gap_to_the_truth_for_every_effect() {
    // Presliding only moves σ0/σ1 of the LuGre law, and viscous only α2: the base LuGre
    // model already has both terms, so there is no gap to close for them.
    let effects: Vec<EffectKind> = EffectKind::ALL
        .into_iter()
        .filter(|k| !matches!(k, EffectKind::Presliding | EffectKind::Viscous))
        .collect();
    // Two worker threads (the effects are independent fits).
    let queue = std::sync::Mutex::new(effects.clone());
    let rows = std::sync::Mutex::new(Vec::new());
    std::thread::scope(|s| {
        for _ in 0..2 {
            s.spawn(|| loop {
                let Some(k) = queue.lock().unwrap().pop() else {
                    break;
                };
                let r = case(k);
                eprintln!(
                    "{:<14} base {:7.2}  added {:7.2}  truth {:7.2}",
                    r.effect, r.base, r.added, r.truth
                );
                rows.lock().unwrap().push(r);
            });
        }
    });
    let rows = rows.into_inner().unwrap();
    println!("effect          base xdot  +add xdot  truth xdot  gap closed");
    let mut failed = Vec::new();
    for r in &rows {
        let gap = r.truth - r.base;
        let closed = if gap.abs() > 1e-9 {
            (r.added - r.base) / gap
        } else {
            1.0
        };
        println!(
            "{:<14} {:9.2}  {:9.2}  {:10.2}  {:9.0} %",
            r.effect,
            r.base,
            r.added,
            r.truth,
            100.0 * closed
        );
        // A base model already within a point of the truth has nothing to close: the
        // added model must then just not be worse by more than a point.
        let ok = if gap < 1.0 {
            r.added >= r.base.min(r.truth) - 1.0
        } else {
            closed >= 0.5
        };
        if !ok {
            failed.push(r.effect);
        }
    }
    assert!(
        failed.is_empty(),
        "fit --add did not close half the gap for {failed:?}"
    );
}
