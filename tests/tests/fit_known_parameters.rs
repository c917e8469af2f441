//! `fit --fix KEY=VALUE` and `--bound KEY=LO..HI`: a known parameter is held or kept in its
//! range, the model file says so, and a key the fit does not have or an empty range is one
//! clear error. The standard errors carry the residual's autocorrelation.
use e2e::motorid;
use serde_json::Value;
use std::path::Path;

fn ok(dir: &Path, args: &[&str]) -> String {
    let out = motorid(dir, args);
    assert!(
        out.status.success(),
        "motorid {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

fn fails_with(dir: &Path, args: &[&str], want: &[&str]) {
    let out = motorid(dir, args);
    assert!(!out.status.success(), "motorid {args:?} succeeded");
    let err = String::from_utf8_lossy(&out.stderr);
    let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(lines.len(), 1, "one line expected: {err}");
    assert!(lines[0].starts_with("error: "), "{err}");
    for w in want {
        assert!(lines[0].contains(w), "'{w}' missing in: {err}");
    }
    assert!(!dir.join("bad.toml").exists(), "an output was written");
}

fn param(fit: &Value, name: &str) -> Value {
    fit["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["name"] == name)
        .unwrap_or_else(|| panic!("no {name} in {fit}"))
        .clone()
}

/// A 20 s log of the emulated motor under signal d (voltage steps) in `dir`, as `d.csv`.
fn simulated_log(dir: &Path) {
    ok(
        dir,
        &[
            "simulate",
            "--signal",
            "d",
            "--duration",
            "20",
            "-o",
            "d.csv",
        ],
    );
}

/// `motorid fit --json --model linear EXTRA... -o OUT d.csv`, parsed.
fn fit_linear(dir: &Path, extra: &[&str], out: &str) -> Value {
    let mut args = vec!["fit", "--json", "--model", "linear"];
    args.extend_from_slice(extra);
    args.extend_from_slice(&["-o", out, "d.csv"]);
    serde_json::from_str(&ok(dir, &args)).unwrap()
}

/// Equal up to the last digit of a JSON number's round trip.
fn same(v: &Value, want: f64) -> bool {
    (v.as_f64().unwrap() - want).abs() <= 1e-12 * want.abs()
}

#[test]
fn a_fixed_key_is_held_a_bounded_key_kept_in_range_and_both_recorded() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    simulated_log(d);
    let free = fit_linear(d, &[], "free.toml");
    let r_free = param(&free, "R")["value"].as_f64().unwrap();
    let j_free = param(&free, "J")["value"].as_f64().unwrap();
    // The errors are widened for the autocorrelated free-run residual, and say by how much.
    let factor = free["std_error_factor"].as_f64().unwrap();
    assert!(factor > 1.0, "factor {factor}");

    // R held at 1.5 times its estimate, J kept below 80 % of it.
    let (r_fixed, j_hi) = (1.5 * r_free, 0.8 * j_free);
    let fix = format!("R={r_fixed}");
    let bound = format!("J={}..{j_hi}", 0.1 * j_free);
    let held = fit_linear(d, &["--fix", &fix, "--bound", &bound], "held.toml");
    let r = param(&held, "R");
    assert!(same(&r["value"], r_fixed), "{r}");
    assert!(r["note"].as_str().unwrap().contains("--fix"), "{r}");
    let j = param(&held, "J");
    let jv = j["value"].as_f64().unwrap();
    // At the bound up to a JSON round trip's last digit, as in `same`.
    assert!(
        jv <= j_hi * (1.0 + 1e-12),
        "J = {jv} above its bound {j_hi}"
    );
    assert!(j["note"].as_str().unwrap().contains("--bound"), "{j}");
    // The model file records them for a reader.
    let toml = std::fs::read_to_string(d.join("held.toml")).unwrap();
    assert!(
        toml.contains("[data.fixed]") && toml.contains("[data.bounds]"),
        "{toml}"
    );
    assert!(toml.contains(&format!("R = {r_fixed}")), "{toml}");
    assert!(same(&held["fixed"]["R"], r_fixed), "{held}");
}

#[test]
fn kt_is_fixed_through_the_kb_it_is_tied_to() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    simulated_log(d);
    let kt = fit_linear(d, &["--fix", "Kt=0.07"], "kt.toml");
    assert!(same(&param(&kt, "Kb")["value"], 0.07), "{kt}");
}

#[test]
fn an_unknown_key_an_empty_range_or_a_bad_value_is_one_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    simulated_log(d);
    let run = |extra: &[&str], want: &[&str]| {
        let mut a = vec!["fit", "--model", "linear", "-o", "bad.toml"];
        a.extend_from_slice(extra);
        a.push("d.csv");
        fails_with(d, &a, want);
    };
    run(
        &["--fix", "coulomb.fc=0.1"],
        &["--fix coulomb.fc", "R, L, Kb, J, b"],
    );
    run(&["--bound", "J=2..1"], &["--bound J=2..1", "empty"]);
    // A motor constant outside the range every model is held to names the flag.
    run(&["--fix", "J=-1"], &["--fix J=-1", "outside", "inertia"]);
    run(&["--bound", "J=1"], &["--bound J=1", "LO..HI"]);
    run(&["--fix", "R=abc"], &["--fix R=abc", "is not a number"]);
    run(&["--fix", "R=inf"], &["--fix R=inf", "not a finite number"]);
    run(&["--fix", "R=1", "--bound", "R=0..2"], &["R", "give one"]);
}

#[test]
fn an_added_effects_key_can_be_fixed_and_a_validation_log_does_not_undo_it() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    simulated_log(d);
    let extra = [
        "--add",
        "coulomb",
        "--fix",
        "coulomb.fc=0.01",
        "--validate",
        "d.csv",
    ];
    let c = fit_linear(d, &extra, "c.toml");
    assert_eq!(c["effects"][0], "coulomb:fc=0.01", "{c}");
    let toml = std::fs::read_to_string(d.join("c.toml")).unwrap();
    assert!(toml.contains("\"coulomb.fc\" = 0.01"), "{toml}");
}
