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
