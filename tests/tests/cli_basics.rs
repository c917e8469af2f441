//! The command line as a user first meets it.
use e2e::motorid;

#[test]
fn every_subcommand_has_help() {
    let dir = tempfile::tempdir().unwrap();
    let out = motorid(dir.path(), &["--help"]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    for sub in [
        "simulate", "fit", "compare", "diagnose", "export", "inspect",
    ] {
        assert!(text.contains(sub), "--help does not list {sub}");
        let o = motorid(dir.path(), &[sub, "--help"]);
        assert!(o.status.success(), "{sub} --help failed");
    }
}

#[test]
fn unknown_file_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let out = motorid(dir.path(), &["compare", "nope.toml", "nope.csv"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.starts_with("error:"), "stderr was: {err}");
}

/// A log `fit` chose among candidate models on is printed, scored and written as a
/// selection log, not as validation; a log nothing was chosen on stays a validation log.
#[test]
fn a_log_the_fit_chose_on_is_labelled_a_selection_log() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (signal, name, seed) in [("a", "a.csv", "1"), ("b", "b.csv", "2")] {
        let sim = [
            "simulate",
            "--signal",
            signal,
            "--duration",
            "20",
            "--seed",
            seed,
            "--effect",
            "offset",
            "-o",
            name,
        ];
        assert!(motorid(d, &sim).status.success());
    }
    let run = |args: &[&str]| -> String {
        let out = motorid(d, args);
        assert!(
            out.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let chose = run(&[
        "fit",
        "--model",
        "linear",
        "--add",
        "offset",
        "--validate",
        "b.csv",
        "-o",
        "m1.toml",
        "a.csv",
    ]);
    let line = chose
        .lines()
        .find(|l| l.contains("b.csv"))
        .unwrap_or_else(|| panic!("no line for b.csv: {chose}"));
    let n: usize = line
        .strip_prefix("selection log (chose among ")
        .and_then(|r| r.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("not a selection line: {line}"));
    assert!(n >= 2, "{line}");
    assert!(
        !chose.lines().any(|l| l.starts_with("validation")),
        "{chose}"
    );
    let toml = std::fs::read_to_string(d.join("m1.toml")).unwrap();
    assert!(toml.contains("selection log (chose among"), "{toml}");
    let js = run(&[
        "fit",
        "--model",
        "linear",
        "--add",
        "offset",
        "--validate",
        "b.csv",
        "-o",
        "m2.toml",
        "a.csv",
        "--json",
    ]);
    assert!(js.contains("\"role\":\"selection log (chose among"), "{js}");
    // Nothing to choose: the log validates.
    let plain = run(&[
        "fit",
        "--model",
        "linear",
        "--validate",
        "b.csv",
        "-o",
        "m3.toml",
        "a.csv",
    ]);
    assert!(
        plain
            .lines()
            .any(|l| l.starts_with("validation ") && l.contains("b.csv")),
        "{plain}"
    );
    assert!(!plain.contains("selection log"), "{plain}");
    // diagnose --help names the entry test it runs.
    let help = run(&["diagnose", "--help"]);
    assert!(
        !help.contains("nested F-test") && help.contains("cluster-robust Wald"),
        "{help}"
    );
}
