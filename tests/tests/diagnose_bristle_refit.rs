//! The parameter check of `diagnose` on a model whose bristles are off: the refit's move of
//! the presliding column is put back into the model as bristle parameters, so the free run
//! of the refitted model judges it as it judges the other parameters, instead of the Wald
//! test's rejection standing for want of a run.
use control::effects::Effect;
use motorid::diagnose::{diagnose, Options, Structure};
use motorid::emulator::{simulate_signal, EmulatorConfig, SignalKind};

/// Bristle stiffness [N·m/rad] of the emulated plant: `presliding`'s documented default (a
/// geared axis seen at the rotor), soft enough for its deflection to span Hall steps.
const SIGMA0: f64 = 0.4;

/// The emulator with visible bristles (σ1 critically damping the rotor on them) and its own
/// model with both bristle parameters scaled by `factor`.
fn bristles_off(seed: u64, factor: f64) -> (motorid::log::MotorLog, Structure) {
    let mut cfg = EmulatorConfig::paper();
    cfg.seed = seed;
    cfg.lugre.sigma0 = SIGMA0;
    cfg.lugre.sigma1 = 2.0 * (SIGMA0 * cfg.motor.j).sqrt();
    let log = simulate_signal(&cfg, SignalKind::A, 60.0).unwrap().log;
    let mut st = Structure::from_model(&cfg.truth_model());
    for e in st.effects.iter_mut() {
        if let Effect::Presliding { sigma0, sigma1 } = e {
            *sigma0 *= factor;
            *sigma1 *= factor;
        }
    }
    (log, st)
}

/// Bristles 4 and 16 times too stiff: the torque equation's check rejects, the refit names
/// the bristle stiffness with a value between the model's and the truth (in ratio), and the
/// detail is the free run's judgement, not "a parameter a free run cannot take".
#[test]
fn stiff_bristles_are_judged_by_a_free_run() {
    for factor in [4.0, 16.0] {
        let (log, st) = bristles_off(1, factor);
        let d = diagnose(&log, &st, &Options::default());
        let summary = format!("{:?} {:#?}", d.verdict.refit, d.verdict.checks);
        let check = d
            .verdict
            .checks
            .iter()
            .find(|c| c.name == "parameters" && c.detail.starts_with("torque"))
            .unwrap_or_else(|| panic!("no torque parameter check: {summary}"));
        assert!(
            check.detail.contains("the refit's free run") && !check.detail.contains("cannot take"),
            "{summary}"
        );
        let sigma0 = d
            .verdict
            .refit
            .iter()
            .find(|r| r.0.starts_with("sigma0"))
            .unwrap_or_else(|| panic!("no refitted bristle stiffness: {summary}"))
            .1;
        let given = factor * SIGMA0;
        assert!(
            sigma0 < given && sigma0 > SIGMA0 / factor,
            "refitted σ0 {sigma0} (model {given}, truth {SIGMA0}): {summary}"
        );
    }
}
