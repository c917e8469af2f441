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

/// A load torque outside the effect list (a sawtooth over each revolution, from a plant
/// written apart from the emulator): every variable that carries what no effect explains
/// comes with its fitted function, as x and y arrays in `--json`, as a line of text, and as
/// one chart in the report beside the verdict's checks.
#[test]
fn what_carries_the_rest_is_drawn_in_json_text_and_report() {
    use e2e::other_plant::{Extra, OtherPlant};
    use motorid::emulator::{signal, SignalKind};
    let dir = tempfile::tempdir().unwrap();
    let keep = std::env::var_os("DIAGNOSE_CLI_DIR").map(std::path::PathBuf::from);
    let d = keep.as_deref().unwrap_or(dir.path());
    let amp = 0.08;
    let u = signal(SignalKind::A, 60.0, 1);
    let log = OtherPlant::new(Extra::SawtoothLoad { amp }).run(&u, 0.012, 1);
    std::fs::write(d.join("a.csv"), log.to_csv()).unwrap();
    ok(&motorid(
        d,
        &["fit", "--model", "linear", "-o", "m0.toml", "a.csv"],
    ));
    let js = ok(&motorid(d, &["diagnose", "m0.toml", "a.csv", "--json"]));
    let v: serde_json::Value = serde_json::from_str(js.trim()).expect("one JSON object");
    assert_eq!(v["adequate"], false, "{js}");
    let carriers = v["unexplained"].as_array().expect("unexplained list");
    assert!(!carriers.is_empty(), "nothing carries the sawtooth: {js}");
    let numbers = |x: &serde_json::Value| -> Vec<f64> {
        x.as_array()
            .unwrap_or_else(|| panic!("not an array: {x}"))
            .iter()
            .map(|n| n.as_f64().expect("a number"))
            .collect()
    };
    for c in carriers {
        for key in ["variable", "share", "explanation"] {
            assert!(c.get(key).is_some(), "{key}: {c}");
        }
        let shape = &c["shape"];
        let (x, y) = (numbers(&shape["x"]), numbers(&shape["y"]));
        assert!(x.len() >= 2 && x.len() == y.len(), "{c}");
        assert!(x.windows(2).all(|w| w[1] > w[0]), "x not ascending: {c}");
        assert!(
            y.iter().any(|v| (v - y[0]).abs() > 0.0),
            "a flat shape: {c}"
        );
        for key in ["x_unit", "y_unit"] {
            assert!(!shape[key].as_str().unwrap_or("").is_empty(), "{key}: {c}");
        }
    }
    // The angle carries it, over one revolution, in newton-metres. What the findings (the
    // sine of one period per revolution and others) leave of a sawtooth is its jump: the
    // function is largest in magnitude near θ = 0, high just before the jump and low after.
    let theta = carriers
        .iter()
        .find(|c| c["variable"] == "theta")
        .unwrap_or_else(|| panic!("no theta carrier: {js}"));
    let (x, y) = (numbers(&theta["shape"]["x"]), numbers(&theta["shape"]["y"]));
    assert_eq!(theta["shape"]["y_unit"], "N·m", "{theta}");
    let tau = std::f64::consts::TAU;
    // The grid spans exactly one revolution: rounding only.
    assert!(x[0].abs() < 1e-9 && (x[x.len() - 1] - tau).abs() < 1e-9);
    let (k, _) = y
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
        .unwrap();
    // A six-harmonic series of a sawtooth peaks about π/7 ≈ 0.45 rad from its jump.
    assert!(x[k].min(tau - x[k]) < 0.6, "largest at {}: {theta}", x[k]);
    let near = |lo: f64, hi: f64| -> f64 {
        let v: Vec<f64> = x
            .iter()
            .zip(&y)
            .filter(|(a, _)| **a >= lo && **a <= hi)
            .map(|(_, b)| *b)
            .collect();
        v.iter().sum::<f64>() / v.len() as f64
    };
    let (before, after) = (near(tau - 0.5, tau), near(0.0, 0.5));
    assert!(
        before > 0.0 && after < 0.0,
        "before {before}, after {after}"
    );

    // The text prints one shape line per carrier.
    let text = ok(&motorid(d, &["diagnose", "m0.toml", "a.csv"]));
    assert_eq!(
        text.matches("      shape").count(),
        carriers.len(),
        "{text}"
    );
    // The report: the verdict's checks with p-values, and one chart per carrier.
    ok(&motorid(
        d,
        &["diagnose", "m0.toml", "a.csv", "--report", "rep"],
    ));
    let html = std::fs::read_to_string(d.join("rep").join("index.html")).unwrap();
    assert!(html.contains("Verdict on the model as given") && html.contains("p-value"));
    for c in carriers {
        let title = format!("What carries the rest: {}", c["variable"].as_str().unwrap());
        let at = html
            .find(&title)
            .unwrap_or_else(|| panic!("no chart {title}"));
        let svg_start = html[..at]
            .rfind("<svg")
            .expect("chart title inside an <svg>");
        assert!(html[svg_start..at].find("</svg>").is_none(), "{title}");
    }
    assert_eq!(
        html.matches("What carries the rest: ").count(),
        carriers.len()
    );
}
