//! Bad input to `fit` and `compare`: one `error:` line naming the file and the line or field,
//! a non-zero exit, and no output file.
use e2e::motorid;
use std::path::Path;

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
    assert!(!err.contains("panicked"), "{err}");
}

fn ramp_log(n: usize, u: impl Fn(usize) -> f64) -> String {
    let mut s = String::from("# sample_period=0.012\nt,u,i,theta\n");
    for k in 0..n {
        s.push_str(&format!(
            "{},{},{},{}\n",
            k as f64 * 0.012,
            u(k),
            0.1 * (k % 7) as f64,
            0.01 * k as f64
        ));
    }
    s
}

#[test]
fn bad_logs_and_models_are_one_clear_error_and_no_output() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("text.csv"), "t,u,i,theta\n0,1,2,3\n0.012,one,2,3\n").unwrap();
    fails_with(
        d,
        &["fit", "--model", "linear", "-o", "m.toml", "text.csv"],
        &["text.csv:3", "'u'"],
    );
    std::fs::write(d.join("nocol.csv"), "t,u,theta\n0,1,3\n0.012,1,3\n").unwrap();
    fails_with(
        d,
        &["fit", "--model", "lugre", "-o", "m.toml", "nocol.csv"],
        &["nocol.csv:1", "'i'"],
    );
    std::fs::write(d.join("nan.csv"), "t,u,i,theta\n0,1,2,3\n0.012,1,NaN,3\n").unwrap();
    fails_with(
        d,
        &["fit", "--model", "linear", "-o", "m.toml", "nan.csv"],
        &["nan.csv:3", "'i'"],
    );
    std::fs::write(
        d.join("time.csv"),
        "t,u,i,theta\n0,1,2,3\n0.012,1,2,3\n0.012,1,2,3\n",
    )
    .unwrap();
    fails_with(
        d,
        &["fit", "--model", "linear", "-o", "m.toml", "time.csv"],
        &["time.csv:4", "'t'"],
    );
    std::fs::write(d.join("short.csv"), ramp_log(10, |k| k as f64)).unwrap();
    fails_with(
        d,
        &["fit", "--model", "linear", "-o", "m.toml", "short.csv"],
        &["short.csv", "10 samples"],
    );
    std::fs::write(d.join("flat.csv"), ramp_log(200, |_| 1.0)).unwrap();
    fails_with(
        d,
        &["fit", "--model", "linear", "-o", "m.toml", "flat.csv"],
        &["flat.csv", "'u'", "constant"],
    );
    // Presliding is the LuGre model's state: a linear model is told where to find it.
    std::fs::write(d.join("ok.csv"), ramp_log(200, |k| (k as f64 * 0.1).sin())).unwrap();
    fails_with(
        d,
        &[
            "fit",
            "--model",
            "linear",
            "--add",
            "presliding",
            "-o",
            "m.toml",
            "ok.csv",
        ],
        &["--add presliding", "--model lugre"],
    );
    assert!(!d.join("m.toml").exists(), "an output file was written");
    // A broken model: the line and the field are named.
    std::fs::write(
        d.join("good.csv"),
        ramp_log(200, |k| (k as f64 * 0.1).sin()),
    )
    .unwrap();
    std::fs::write(
        d.join("bad.toml"),
        "kind = \"linear\"\nplant = \"voltage\"\nsample_period = \"fast\"\n",
    )
    .unwrap();
    fails_with(
        d,
        &["compare", "bad.toml", "good.csv"],
        &["bad.toml:3", "sample_period"],
    );
    std::fs::write(
        d.join("neg.toml"),
        "kind = \"linear\"\nplant = \"voltage\"\nsample_period = 0.012\n[motor]\nr = 0.2\nl = 0.0003\nkt = 0.07\nkb = 0.07\nj = -1.0\n",
    )
    .unwrap();
    fails_with(
        d,
        &["compare", "neg.toml", "good.csv"],
        &["neg.toml", "motor.j"],
    );
}
