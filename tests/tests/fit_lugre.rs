//! `motorid fit` on emulated data from the plain paper motor (LuGre friction): the LuGre fit
//! recovers the static friction curve, validates within a few points of the emulator's own
//! model (scored by the same function), and the linear model is clearly worse.
use e2e::motorid;
use std::path::Path;

fn run_ok(dir: &Path, args: &[&str]) -> String {
    let out = motorid(dir, args);
    assert!(
        out.status.success(),
        "motorid {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

/// A number from `[section]` of a TOML text (`key = value`).
fn toml_number(text: &str, section: &str, key: &str) -> f64 {
    let mut inside = false;
    for line in text.lines() {
        let l = line.trim();
        if l.starts_with('[') {
            inside = l == format!("[{section}]");
            continue;
        }
        if inside {
            if let Some((k, v)) = l.split_once('=') {
                if k.trim() == key {
                    return v.trim().parse().unwrap();
                }
            }
        }
    }
    panic!("no {section}.{key} in\n{text}");
}

fn xdot_sensor(dir: &Path, model: &str, data: &str) -> f64 {
    let out = run_ok(dir, &["compare", model, data, "--json"]);
    let v: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    v["fit_sensor"]["xdot"].as_f64().unwrap()
}

/// The paper's fitting signal (a) and validation signal (b), 60 s each, as a.csv and b.csv.
fn simulate_a_and_b(dir: &Path) {
    run_ok(
        dir,
        &[
            "simulate",
            "--signal",
            "a",
            "--duration",
            "60",
            "-o",
            "a.csv",
        ],
    );
    run_ok(
        dir,
        &[
            "simulate",
            "--signal",
            "b",
            "--duration",
            "60",
            "--seed",
            "2",
            "-o",
            "b.csv",
        ],
    );
}

/// The emulator's own model (paper motor, paper LuGre), as MODEL.toml.
const TRUTH: &str = r#"kind = "lugre"
plant = "voltage"
sample_period = 0.012

[motor]
r = 0.21621621621621623
l = 0.0003
kt = 0.07126126126126126
kb = 0.07126126126126126
j = 0.0003

[lugre]
alpha0 = 0.08
alpha1 = 0.0175
alpha2 = 0.0016
v0 = 3.676
sigma0 = 317.225
sigma1 = 22.2464

[sensor]
hall_resolution_rad = 0.09519977738150888
velocity_window = 10
"#;

/// The fitted motor constants of `model` (MODEL.toml text) against the emulator's
/// ([`TRUTH`]). R and K_b are fixed by every sample of the winding's equation: within 2 %
/// and 1 %. The inertia: within 6 %, the free run's backward-Euler sub-steps of h = 1 ms
/// slowing the mechanical time constant τ_m = J·R/(K_t·K_b) ≈ 13 ms by h/2 (a J about 3.8 %
/// low; at 48 sub-steps the fit lands within 0.5 %) plus a few standard errors (0.1 % each).
/// L/R = 1.4 ms is a tenth of the 12 ms period, so the samples see L only through the torque
/// impulse of every voltage step: within 15 %, or marked not identifiable.
fn assert_motor_constants(model: &str) {
    let close = |key: &str, truth: f64, tol: f64| {
        let v = toml_number(model, "motor", key);
        assert!(
            (v - truth).abs() <= tol * truth,
            "{key} = {v}, truth {truth} (more than {} % off)",
            100.0 * tol
        );
    };
    close("r", 0.21621621621621623, 0.02);
    close("kb", 0.07126126126126126, 0.01);
    close("j", 3.0e-4, 0.06);
    let l = toml_number(model, "motor", "l");
    let flagged = model
        .split("[[parameters]]")
        .find(|p| p.contains("name = \"L\""))
        .is_some_and(|p| p.contains("identifiable = false"));
    assert!(
        flagged || (l - 3.0e-4).abs() <= 0.15 * 3.0e-4,
        "L = {l} H, truth 0.3 mH, neither within 15 % nor marked not identifiable"
    );
}

/// A constant load torque hidden in the motor (offset, 0.03 N·m, more than a third of the
/// Coulomb friction) and added to the fit: the motor constants and the offset come out as
/// on the plain motor. (Refined without a Stribeck excess, the inductance and inertia would
/// mimic it: L about twice the truth, J 15 % low.)
#[test]
fn lugre_fit_with_an_added_offset_recovers_the_motor_constants() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (signal, seed, out) in [("a", "1", "a.csv"), ("b", "2", "b.csv")] {
        let args = [
            "simulate",
            "--signal",
            signal,
            "--duration",
            "60",
            "--seed",
            seed,
            "--effect",
            "offset",
            "-o",
            out,
        ];
        run_ok(d, &args);
    }
    let args = [
        "fit",
        "-q",
        "--model",
        "lugre",
        "--add",
        "offset",
        "--validate",
        "b.csv",
        "-o",
        "offset.toml",
        "a.csv",
    ];
    run_ok(d, &args);
    let model = std::fs::read_to_string(d.join("offset.toml")).unwrap();
    assert_motor_constants(&model);
    let t0 = model
        .split("[[effects]]")
        .nth(1)
        .and_then(|e| e.lines().find_map(|l| l.trim().strip_prefix("t0 =")))
        .map(|v| v.trim().parse::<f64>().unwrap())
        .expect("the offset in the model");
    // 10 %, about a hundred of the fit's standard errors (0.02 mN·m): not noise, but an
    // offset partly taken up by the other terms, as described above.
    assert!((t0 - 0.03).abs() < 0.003, "offset t0 = {t0}, truth 0.03");
}

#[test]
fn lugre_fit_recovers_the_static_curve_and_validates_like_the_truth() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    simulate_a_and_b(d);
    run_ok(d, &["simulate", "--signal", "steady", "-o", "steady.csv"]);
    std::fs::write(d.join("truth.toml"), TRUTH).unwrap();
    let text = run_ok(
        d,
        &[
            "fit",
            "--model",
            "lugre",
            "-o",
            "lugre.toml",
            "a.csv",
            "steady.csv",
        ],
    );
    assert!(text.contains("alpha0") && text.contains("N·m"), "{text}");
    let model = std::fs::read_to_string(d.join("lugre.toml")).unwrap();
    // 10 %: about ten of the fit's standard errors of the least certain value (v0, 1 %; the
    // others 0.2-1 %), so the test fails on a biased static curve, not on noise.
    for (key, truth) in [
        ("alpha0", 0.08),
        ("alpha1", 0.0175),
        ("alpha2", 0.0016),
        ("v0", 3.676),
    ] {
        let v = toml_number(&model, "lugre", key);
        assert!(
            (v - truth).abs() <= 0.10 * truth,
            "{key} = {v}, truth {truth} (more than 10 % off)"
        );
    }
    assert_motor_constants(&model);
    run_ok(
        d,
        &["fit", "--model", "linear", "-o", "linear.toml", "a.csv"],
    );
    let truth = xdot_sensor(d, "truth.toml", "b.csv");
    let lugre = xdot_sensor(d, "lugre.toml", "b.csv");
    let linear = xdot_sensor(d, "linear.toml", "b.csv");
    eprintln!(
        "validation on b, fit_sensor xdot: truth {truth:.2}, lugre {lugre:.2}, linear {linear:.2}"
    );
    // The emulator's own model through its own sensor chain scores about 99.5: below 90 the
    // scoring, not the fit, is broken. Three points: three times the spread of one model's
    // fit between fresh draws of the noise (about a point, decision 0010), so "like the
    // truth" and "clearly below" are not decided by the draw.
    assert!(truth > 90.0, "the emulator's own model scores only {truth}");
    assert!(
        (lugre - truth).abs() < 3.0,
        "lugre {lugre} vs truth {truth}"
    );
    assert!(
        linear < lugre - 3.0,
        "linear {linear} is not clearly below lugre {lugre}"
    );
}

/// SINDYc's bar: fitted on signal a alone (the one-by-one thresholding
/// and the simulation-error refinement judged on a), its validation fit on signal b through
/// the sensor chain is within 3 points of the emulator's own model scored by the same
/// function, and the linear model is clearly below.
#[test]
fn sindyc_fit_validates_like_the_truth() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    simulate_a_and_b(d);
    std::fs::write(d.join("truth.toml"), TRUTH).unwrap();
    run_ok(
        d,
        &["fit", "--model", "sindyc", "-o", "sindyc.toml", "a.csv"],
    );
    run_ok(
        d,
        &["fit", "--model", "linear", "-o", "linear.toml", "a.csv"],
    );
    let truth = xdot_sensor(d, "truth.toml", "b.csv");
    let sindyc = xdot_sensor(d, "sindyc.toml", "b.csv");
    let linear = xdot_sensor(d, "linear.toml", "b.csv");
    eprintln!(
        "validation on b, fit_sensor xdot: truth {truth:.2}, sindyc {sindyc:.2}, linear {linear:.2}"
    );
    assert!(truth > 90.0, "the emulator's own model scores only {truth}");
    assert!(
        (sindyc - truth).abs() < 3.0,
        "sindyc {sindyc} vs truth {truth}"
    );
    assert!(
        linear < sindyc - 3.0,
        "linear {linear} is not clearly below sindyc {sindyc}"
    );
}

/// A compliant bristle (the `presliding` default: σ0 = 0.4 N·m/rad, a breakaway deflection of
/// 2.6 Hall steps, as a geared axis shows at the rotor) is visible in Hall-quantised data, and
/// the LuGre fit identifies it: σ0 within 30 % (the tolerance covers the spread over noise
/// draws). A stiff start that ends in a local minimum near 10 N·m/rad fails it.
#[test]
fn lugre_fit_identifies_a_compliant_bristle() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    run_ok(
        d,
        &[
            "simulate",
            "--signal",
            "a",
            "--duration",
            "60",
            "--effect",
            "presliding",
            "-o",
            "a.csv",
        ],
    );
    run_ok(d, &["fit", "--model", "lugre", "-o", "m.toml", "a.csv"]);
    let model = std::fs::read_to_string(d.join("m.toml")).unwrap();
    let sigma0 = toml_number(&model, "lugre", "sigma0");
    assert!(
        (sigma0 - 0.4).abs() <= 0.3 * 0.4,
        "sigma0 = {sigma0} N·m/rad, truth 0.4"
    );
}
