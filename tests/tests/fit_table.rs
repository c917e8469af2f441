//! `fit --add table:var=theta,bins=N` on data from a plant our emulator did not make
//! (`e2e::other_plant`): a load torque shaped like a sawtooth over each revolution, which no
//! named effect matches (position_load is its first harmonic only). The table's node torques
//! are estimated with the model (the spec as `diagnose` offers it), written to MODEL.toml, and the free-run fit on a held-out log
//! (another excitation and seed) rises; `compare` and `diagnose` take the model, and it
//! exports to the board's blob, which `inspect` decodes with the table.
use e2e::motorid;
use e2e::other_plant::{Extra, OtherPlant};
use motorid::emulator::{signal, SignalKind};
use serde_json::Value;
use std::path::Path;

const TS: f64 = 0.012;
/// Sawtooth load amplitude [N·m], about the plant's Coulomb friction.
const AMP: f64 = 0.08;

fn write_log(dir: &Path, name: &str, kind: SignalKind, seconds: f64, seed: u64) {
    let p = OtherPlant::new(Extra::SawtoothLoad { amp: AMP });
    let u = signal(kind, seconds, seed);
    let log = p.run(&u, TS, seed);
    std::fs::write(dir.join(name), log.to_csv()).unwrap();
}

fn run_ok(dir: &Path, args: &[&str]) -> String {
    let out = motorid(dir, args);
    assert!(
        out.status.success(),
        "motorid {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// The angle fit and the velocity fit through the sensor chain of `compare MODEL
/// held_out.csv --json`. (The velocity as it is, against the estimator applied to the Hall
/// angle, is dominated by the estimator's quantisation ripple on this log: about 90 % for
/// any model that tracks the angle.)
fn fits(dir: &Path, model: &str) -> (f64, f64) {
    let v: Value =
        serde_json::from_str(&run_ok(dir, &["compare", model, "held_out.csv", "--json"])).unwrap();
    (
        v["fit"]["x"].as_f64().unwrap(),
        v["fit_sensor"]["xdot"].as_f64().unwrap(),
    )
}

#[test]
fn a_theta_table_raises_the_held_out_fit_of_a_sawtooth_load() {
    let dir = tempfile::tempdir().unwrap();
    let keep = std::env::var_os("FIT_TABLE_DIR").map(std::path::PathBuf::from);
    let d = keep.as_deref().unwrap_or(dir.path());
    write_log(d, "fit.csv", SignalKind::A, 60.0, 1);
    write_log(d, "held_out.csv", SignalKind::B, 40.0, 2);
    run_ok(
        d,
        &["fit", "--model", "lugre", "-o", "base.toml", "fit.csv"],
    );
    // `diagnose` offers the table where the angle carries what no effect explains.
    let v: Value =
        serde_json::from_str(&run_ok(d, &["diagnose", "base.toml", "fit.csv", "--json"])).unwrap();
    let theta = v["unexplained"]
        .as_array()
        .unwrap()
        .iter()
        .find(|u| u["variable"] == "theta")
        .unwrap_or_else(|| panic!("no theta carrier: {v}"));
    for key in ["variable", "share", "explanation", "spec"] {
        assert!(theta.get(key).is_some(), "{key}: {theta}");
    }
    let spec = theta["spec"].as_str().unwrap();
    assert!(spec.starts_with("table:var=theta,bins="), "{spec}");
    assert!(theta["explanation"].as_str().unwrap().contains(spec));
    let add = ["fit", "--model", "lugre", "--add", spec, "-o", "table.toml"];
    run_ok(d, &[&add[..], &["fit.csv"]].concat());
    let text = std::fs::read_to_string(d.join("table.toml")).unwrap();
    assert!(text.contains("name = \"table\""), "{text}");
    assert!(text.contains("var = \"theta\""), "{text}");
    assert!(text.contains("b1 = "), "{text}");
    let (bx, bv) = fits(d, "base.toml");
    let (tx, tv) = fits(d, "table.toml");
    eprintln!("held-out fit: base x {bx:.1} xdot {bv:.1}; table x {tx:.1} xdot {tv:.1}");
    // A point of fit: a load the size of the Coulomb friction costs a model without it far
    // more, and a refit of the same structure moves less.
    assert!(tx > bx + 1.0, "x: base {bx:.1}, table {tx:.1}");
    assert!(tv > bv + 1.0, "xdot: base {bv:.1}, table {tv:.1}");

    // The other commands take a model with a table.
    let diag = motorid(d, &["diagnose", "table.toml", "held_out.csv", "--json"]);
    assert!(
        serde_json::from_slice::<Value>(&diag.stdout).is_ok(),
        "{}",
        String::from_utf8_lossy(&diag.stderr)
    );
    // The board takes the table: it exports, and `inspect` decodes it with its nodes.
    run_ok(d, &["export", "table.toml", "-o", "coeffs.bin"]);
    let v: Value = serde_json::from_str(&run_ok(d, &["inspect", "coeffs.bin", "--json"])).unwrap();
    assert!(v.to_string().contains("Table"), "{v}");
}

#[test]
fn simulate_refuses_a_table_without_node_torques() {
    let dir = tempfile::tempdir().unwrap();
    let out = motorid(
        dir.path(),
        &[
            "simulate",
            "--signal",
            "c",
            "--duration",
            "2",
            "--effect",
            "table:var=theta,bins=12",
            "-o",
            "sim.csv",
        ],
    );
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.starts_with("error:") && err.contains("b0 to b11"),
        "{err}"
    );
    assert!(!dir.path().join("sim.csv").exists());
    // With node torques the emulator runs it.
    let out = motorid(
        dir.path(),
        &[
            "simulate",
            "--signal",
            "c",
            "--duration",
            "2",
            "--effect",
            "table:var=theta,bins=4,b0=0.02,b1=-0.01",
            "-o",
            "sim.csv",
        ],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The blob whose step cost `scripts/qemu-parity.sh` counts (LuGre with all eight effect slots
/// used, a 16-node speed table and saturation among them) is what `motorid export` writes for
/// its model, byte for byte.
#[test]
fn the_counted_table_blob_is_the_export_of_its_model() {
    let dir = tempfile::tempdir().unwrap();
    let trace = e2e::root().join("qemu-parity").join("trace");
    let model = trace.join("lugre-table.toml");
    let args = [
        "export",
        model.to_str().unwrap(),
        "--edge-timing",
        "0.1",
        "-o",
        "blob.bin",
    ];
    run_ok(dir.path(), &args);
    let ours = std::fs::read(dir.path().join("blob.bin")).unwrap();
    let counted = std::fs::read(trace.join("lugre-table.bin")).unwrap();
    assert!(
        ours == counted,
        "qemu-parity/trace/lugre-table.bin is stale"
    );
    let v: Value =
        serde_json::from_str(&run_ok(dir.path(), &["inspect", "blob.bin", "--json"])).unwrap();
    let effects = &v["coefficients"]["effects"];
    assert_eq!(
        effects.as_array().map(Vec::len),
        Some(control::blob::MAX_EFFECTS),
        "{effects}"
    );
    let effects = effects.to_string();
    assert!(
        effects.contains("\"bins\":16") && effects.contains("Saturation"),
        "{effects}"
    );
}
