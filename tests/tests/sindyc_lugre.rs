//! SINDYc end to end on the emulated LuGre motor: `simulate` the paper's fitting signal (a)
//! and validation signal (b), `fit --model sindyc --validate b.csv`, `compare`.
//! The validation fit on the velocity must be within a few points of what the emulator's
//! true states score against the same measurement, and above the linear model's; the
//! returned model never diverges, not even on the other signals (c, d).
use e2e::motorid;
use std::path::Path;

fn run(dir: &Path, args: &[&str]) -> String {
    let out = motorid(dir, args);
    assert!(
        out.status.success(),
        "motorid {args:?} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// A column of a motor log CSV.
fn column(path: &Path, name: &str) -> Vec<f64> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let k = header.iter().position(|h| *h == name).unwrap();
    lines
        .map(|l| l.split(',').nth(k).unwrap().parse().unwrap())
        .collect()
}

/// The paper's fit percentage (eq. 48).
fn fit_percent(y: &[f64], yhat: &[f64]) -> f64 {
    let mean = y.iter().sum::<f64>() / y.len() as f64;
    let num: f64 = y.iter().zip(yhat).map(|(a, b)| (a - b).powi(2)).sum();
    let den: f64 = y.iter().map(|a| (a - mean).powi(2)).sum();
    100.0 * (1.0 - (num / den).sqrt())
}

fn xdot_fit(dir: &Path, model: &str, data: &str) -> f64 {
    let out = run(dir, &["compare", model, data, "--json"]);
    let v: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    v["fit"]["xdot"].as_f64().unwrap()
}

#[test]
fn sindyc_on_emulated_lugre_motor() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    for (sig, seed) in [("a", "1"), ("b", "2"), ("c", "3"), ("d", "4")] {
        let out = format!("{sig}.csv");
        run(
            dir,
            &[
                "simulate", "--signal", sig, "--seed", seed, "--truth", "-o", &out,
            ],
        );
    }
    run(
        dir,
        &[
            "fit",
            "--model",
            "sindyc",
            "--validate",
            "b.csv",
            "-o",
            "sindyc.toml",
            "a.csv",
        ],
    );
    run(
        dir,
        &["fit", "--model", "linear", "-o", "linear.toml", "a.csv"],
    );
    let toml = std::fs::read_to_string(dir.join("sindyc.toml")).unwrap();
    // Where the data came from is recorded as for the other kinds: the log's sample period
    // and Hall step, not zeros.
    for key in ["sample_period", "hall_resolution_rad"] {
        let values: Vec<f64> = toml
            .lines()
            .filter_map(|l| l.strip_prefix(key)?.trim_start().strip_prefix('='))
            .map(|v| v.trim().parse().unwrap())
            .collect();
        assert!(
            !values.is_empty() && values.iter().all(|v| *v > 0.0),
            "{key}: {toml}"
        );
    }
    assert!(
        toml.contains("kind = \"sindyc\"") && toml.contains("[sindy.accel]"),
        "{toml}"
    );

    let sindyc = xdot_fit(dir, "sindyc.toml", "b.csv");
    let linear = xdot_fit(dir, "linear.toml", "b.csv");
    let b = dir.join("b.csv");
    let truth = fit_percent(&column(&b, "omega"), &column(&b, "omega_true"));
    eprintln!("validation b, fit on xdot: SINDYc {sindyc:.2} %, linear {linear:.2} %, true states {truth:.2} %");
    // 5 points, as sindyc_current.rs's GAP: the requirement itself (a library model of the
    // friction may trail the true law by its approximation), not a margin measured here.
    assert!(
        sindyc > truth - 5.0,
        "SINDYc {sindyc} vs true states {truth}"
    );
    assert!(sindyc > linear, "SINDYc {sindyc} vs linear {linear}");
    // Never divergent: compare must simulate the other signals to the end.
    for data in ["c.csv", "d.csv"] {
        let f = xdot_fit(dir, "sindyc.toml", data);
        assert!(f.is_finite(), "{data}: {f}");
    }
}
