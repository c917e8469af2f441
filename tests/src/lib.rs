//! Helpers for the end-to-end tests: find (and build once) the `motorid` binary, run it,
//! and locate `../shared/data`.
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

/// The workspace root.
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

/// Path of the `motorid` binary, built once with the same (optimised) profile as the tests.
pub fn motorid_bin() -> &'static Path {
    static BIN: OnceLock<PathBuf> = OnceLock::new();
    BIN.get_or_init(|| {
        let target = std::env::var_os("CARGO_TARGET_DIR")
            .map(PathBuf::from)
            .unwrap_or_else(|| root().join("target"));
        let status = Command::new(env!("CARGO"))
            .args(["build", "-q", "--bin", "motorid"])
            .current_dir(root())
            .status()
            .expect("cannot run cargo to build motorid");
        assert!(status.success(), "cargo build --bin motorid failed");
        target.join("debug").join("motorid")
    })
}

/// Run `motorid ARGS...` in `dir`.
pub fn motorid(dir: &Path, args: &[&str]) -> Output {
    Command::new(motorid_bin())
        .args(args)
        .current_dir(dir)
        .output()
        .expect("cannot start motorid")
}

/// `../shared/data` if present; `None` (and a line saying the test skipped) otherwise.
pub fn shared_data(test: &str) -> Option<PathBuf> {
    let d = root().join("..").join("shared").join("data");
    if d.is_dir() {
        Some(d)
    } else {
        eprintln!("SKIPPED {test}: ../shared/data is not present next to the repository");
        None
    }
}
