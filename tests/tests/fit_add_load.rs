//! A load behind a coupling (`compliance`, `backlash`) through the user's commands: simulate
//! the emulated motor with the load, fit the plain LuGre model and the same with `fit --add
//! SPEC` (a spec off the truth, as a first guess or `diagnose` would give one), and check the
//! load's parameters come back and the free-run fit on a fresh signal-b log rises.
//!
//! `compare` scores each model on the fresh log; neither fit saw it (no `--validate`, so no
//! choice was made on it either).
use e2e::{motorid, stdout_of_success as ok};
use motorid::model::Model;
use std::path::Path;

/// Simulate `signal` for 90 s with `effect` into `name`.
fn simulate(d: &Path, signal: &str, seed: &str, effect: &str, name: &str) {
    ok(motorid(
        d,
        &[
            "simulate",
            "--signal",
            signal,
            "--duration",
            "90",
            "--seed",
            seed,
            "--effect",
            effect,
            "-o",
            name,
        ],
    ));
}

/// `compare`'s free-run fit [%] of `model` on `log`: the velocity through the sensor chain
/// (Hall-quantised angle, the firmware's estimator: without the quantisation every model
/// scores about 90 % against the measured velocity, the quantisation's own share), and the
/// current.
fn held_out(d: &Path, model: &str, log: &str) -> (f64, f64) {
    let out = ok(motorid(d, &["compare", model, log, "--json"]));
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    (
        v["fit_sensor"]["xdot"].as_f64().unwrap(),
        v["fit"]["i"].as_f64().unwrap(),
    )
}

/// The value of the added load's key `key` in a fitted MODEL.toml.
fn key(d: &Path, model: &str, key: &str) -> f64 {
    let m = Model::load(&d.join(model)).unwrap();
    let spec = m
        .effect_specs()
        .into_iter()
        .next()
        .expect("an added effect");
    spec.get(key)
}

/// Fits the plain LuGre model and LuGre `--add spec` on a 90 s signal-a log of the motor
/// with `truth`, and returns the held-out scores (velocity, current) of both on a fresh
/// signal-b log, and the directory with `added.toml`.
fn fit_both(truth: &str, spec: &str) -> (tempfile::TempDir, (f64, f64), (f64, f64)) {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    simulate(d, "a", "3", truth, "a.csv");
    simulate(d, "b", "4", truth, "b.csv");
    ok(motorid(
        d,
        &["fit", "--model", "lugre", "-o", "plain.toml", "a.csv"],
    ));
    ok(motorid(
        d,
        &[
            "fit",
            "--model",
            "lugre",
            "--add",
            spec,
            "-o",
            "added.toml",
            "a.csv",
        ],
    ));
    let plain = held_out(d, "plain.toml", "b.csv");
    let added = held_out(d, "added.toml", "b.csv");
    eprintln!("{truth} (fit --add {spec}): held-out velocity, current fit: plain {plain:?}, added {added:?}");
    (dir, plain, added)
}

#[test]
fn fit_add_compliance_recovers_the_load_and_the_spring() {
    // The emulator's default coupling: j2 = 6e-4 kg·m², k = 0.2 N·m/rad (2.9 Hz against a
    // fixed rotor), c = 6e-4; the start resonates at 11 Hz, a third of the load's inertia.
    let (dir, plain, added) = fit_both("compliance", "compliance:j2=2e-4,k=1,c=1e-3");
    let d = dir.path();
    let (j2, k) = (key(d, "added.toml", "j2"), key(d, "added.toml", "k"));
    eprintln!("compliance: j2 = {j2:.4e} (true 6e-4), k = {k:.4e} (true 0.2)");
    // Within 10 %: the fit's 1 ms sub-steps lower the coupled frequency by (ω_c·h)²/3 against
    // the emulator's 0.2 ms (far below 1 % at 5 Hz), and the Hall-quantised angle and 12 ms
    // samples pin a 5 Hz resonance to a few percent. The damper c is not checked: backward
    // Euler damps the mode by ζ ≈ ω_c·h/2 (0.016 at 1 ms, 0.003 at 0.2 ms), which the fit
    // takes out of c (a quarter of the default's ζ = 0.05).
    assert!((j2 / 6e-4 - 1.0).abs() < 0.1, "j2 = {j2}");
    assert!((k / 0.2 - 1.0).abs() < 0.1, "k = {k}");
    // The board compensates no load inertia: export carries the load and says so.
    let out = motorid(d, &["export", "added.toml", "-o", "c.bin"]);
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(
        out.status.success() && err.contains("no load state"),
        "{err}"
    );
    let shown = ok(motorid(d, &["inspect", "c.bin"]));
    assert!(
        shown.contains("compliance:") && shown.contains("not compensated"),
        "{shown}"
    );
    // The velocity through the sensor chain is held to the Hall steps' rounding (0.2 to 1
    // point measured): it must rise. The current, which no quantisation limits, rose by 5-8
    // points: 3 is beyond what a refit of the same structure moves on a fresh draw.
    assert!(added.0 > plain.0, "velocity: {plain:?} -> {added:?}");
    assert!(added.1 > plain.1 + 3.0, "current: {plain:?} -> {added:?}");
}

#[test]
fn fit_add_backlash_recovers_the_load_and_the_gap() {
    // The emulator's default: j2 = 6e-4 kg·m² behind a gap of 0.19 rad.
    let (dir, plain, added) = fit_both("backlash", "backlash:j2=4e-4,gap=0.12");
    let d = dir.path();
    let (j2, gap) = (key(d, "added.toml", "j2"), key(d, "added.toml", "gap"));
    eprintln!("backlash: j2 = {j2:.4e} (true 6e-4), gap = {gap:.4} (true 0.19)");
    // Within 10 %: the gap is seen through a Hall-quantised angle (0.095 rad steps, half a
    // gap), so only the timing of the contacts pins it; the fit's contact is as stiff per
    // sub-step as the emulator's but its sub-step five times longer.
    assert!((j2 / 6e-4 - 1.0).abs() < 0.1, "j2 = {j2}");
    assert!((gap / 0.19 - 1.0).abs() < 0.1, "gap = {gap}");
    // The velocity through the sensor chain is held to the Hall steps' rounding (0.2 to 1
    // point measured): it must rise. The current, which no quantisation limits, rose by 5-8
    // points: 3 is beyond what a refit of the same structure moves on a fresh draw.
    assert!(added.0 > plain.0, "velocity: {plain:?} -> {added:?}");
    assert!(added.1 > plain.1 + 3.0, "current: {plain:?} -> {added:?}");
}
