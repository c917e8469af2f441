//! `motorid compare --json` prints exactly the documented object, and the fit percentages
//! behave (the true model scores higher than a detuned one).
use e2e::motorid;

#[test]
fn json_has_exactly_the_documented_shape() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    assert!(motorid(
        d,
        &[
            "simulate",
            "--signal",
            "d",
            "--duration",
            "20",
            "-o",
            "d.csv"
        ]
    )
    .status
    .success());
    let fit = motorid(d, &["fit", "--model", "linear", "-o", "m.toml", "d.csv"]);
    assert!(
        fit.status.success(),
        "{}",
        String::from_utf8_lossy(&fit.stderr)
    );
    let out = motorid(d, &["compare", "m.toml", "d.csv", "--json"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    assert_eq!(text.trim().lines().count(), 1, "one line of JSON: {text}");
    let v: serde_json::Value = serde_json::from_str(text.trim()).unwrap();
    let obj = v.as_object().unwrap();
    let mut keys: Vec<&str> = obj.keys().map(String::as_str).collect();
    keys.sort();
    assert_eq!(keys, ["fit", "fit_sensor", "samples"]);
    assert_eq!(v["samples"].as_u64(), Some(1667));
    for part in ["fit", "fit_sensor"] {
        let f = v[part].as_object().unwrap();
        let mut k: Vec<&str> = f.keys().map(String::as_str).collect();
        k.sort();
        assert_eq!(k, ["i", "x", "xdot"], "{part}");
        for key in ["x", "xdot", "i"] {
            let x = f[key]
                .as_f64()
                .unwrap_or_else(|| panic!("{part}.{key} is not a number"));
            assert!(x <= 100.0 && x > 50.0, "{part}.{key} = {x}");
        }
    }
    // Human-readable table by default.
    let out = motorid(d, &["compare", "m.toml", "d.csv"]);
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(
        text.contains("fit_sensor") && text.contains("xdot"),
        "{text}"
    );
}
