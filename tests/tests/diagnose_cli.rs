//! The whole loop through the command line: simulate, fit, diagnose --json, fit --add
//! the printed spec, compare --report.
use e2e::motorid;

fn ok(out: &std::process::Output) -> String {
    assert!(
        out.status.success(),
        "stdout: {}\nstderr: {}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn diagnose_json_spec_is_accepted_by_fit_add_and_compare_reports() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(&motorid(
        d,
        &[
            "simulate",
            "--signal",
            "a",
            "--duration",
            "45",
            "--effect",
            "offset:t0=0.03",
            "-o",
            "a.csv",
        ],
    ));
    ok(&motorid(
        d,
        &["fit", "--model", "lugre", "-o", "m0.toml", "a.csv"],
    ));
    let js = ok(&motorid(d, &["diagnose", "m0.toml", "a.csv", "--json"]));
    let v: serde_json::Value = serde_json::from_str(js.trim()).expect("one JSON object");
    let effects = v["effects"].as_array().expect("effects list");
    assert_eq!(effects[0]["name"], "offset", "{js}");
    assert!(effects[0]["score"].as_f64().unwrap() > 0.0);
    assert!(!effects[0]["explanation"].as_str().unwrap().is_empty());
    let spec = effects[0]["spec"].as_str().unwrap().to_string();
    ok(&motorid(
        d,
        &[
            "fit", "--model", "lugre", "--add", &spec, "-o", "m1.toml", "a.csv",
        ],
    ));
    let js = ok(&motorid(d, &["diagnose", "m1.toml", "a.csv", "--json"]));
    let v: serde_json::Value = serde_json::from_str(js.trim()).unwrap();
    assert!(
        v["effects"]
            .as_array()
            .unwrap()
            .iter()
            .all(|e| e["name"] != "offset"),
        "offset still reported after adding it: {js}"
    );
    let out = motorid(d, &["compare", "m1.toml", "a.csv", "--report", "rep"]);
    ok(&out);
    let html = std::fs::read_to_string(d.join("rep").join("index.html")).unwrap();
    assert!(html.matches("<svg").count() >= 4 && html.contains("<table"));
    // The terminal names the error's worst regions (or says it is even).
    assert!(String::from_utf8_lossy(&out.stderr).contains("velocity error"));
    // Bad input: one error line naming the file.
    let bad = motorid(d, &["diagnose", "m1.toml", "missing.csv"]);
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(
        err.starts_with("error:") && err.contains("missing.csv"),
        "{err}"
    );
}
