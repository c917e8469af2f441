//! Helpers for the end-to-end tests: find (and build once) the `motorid` and `xtask`
//! binaries, run them, and locate `../shared/data`.
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

/// Folder of the `motorid` and `xtask` binaries, both built once (one nested `cargo build`)
/// in the dev profile, which this workspace optimises (`opt-level = 2`, dependencies at 3),
/// whatever profile the tests themselves were built in.
///
/// `MOTORID_BUILD_ARGS` (space-separated) replaces the default target selection
/// `--bin motorid --bin xtask` of that nested `cargo build`. scripts/test.sh sets it to
/// `-p motorid -p xtask --bin motorid --bin xtask --tests` after the workspace-wide `cargo
/// test` build: with resolver 2 the dev-dependencies' features (proptest, criterion:
/// `either/use_std`, `getrandom/std`, `zerocopy/derive`, ...) are unified only when a test
/// target is part of the build, so bare `--bin` targets would compile rand, rayon, faer and
/// their dependents a second time (about 3 minutes on 2 cores). The default suits `cargo test
/// -p e2e ...`, which resolves without dev-dependencies too.
fn bin_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let target = std::env::var_os("CARGO_TARGET_DIR")
            .map(PathBuf::from)
            .unwrap_or_else(|| root().join("target"));
        let select = std::env::var("MOTORID_BUILD_ARGS")
            .unwrap_or_else(|_| "--bin motorid --bin xtask".to_string());
        let status = Command::new(env!("CARGO"))
            .args(["build", "-q"])
            .args(select.split_whitespace())
            .current_dir(root())
            .status()
            .expect("cannot run cargo to build motorid and xtask");
        assert!(status.success(), "cargo build {select} failed");
        target.join("debug")
    })
}

/// Path of the `motorid` binary (the product).
pub fn motorid_bin() -> PathBuf {
    bin_dir().join("motorid")
}

/// Run `motorid ARGS...` in `dir`.
pub fn motorid(dir: &Path, args: &[&str]) -> Output {
    Command::new(motorid_bin())
        .args(args)
        .current_dir(dir)
        .output()
        .expect("cannot start motorid")
}

/// The stdout of a command that must succeed; its stderr is the failure's message.
pub fn stdout_of_success(out: Output) -> String {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).expect("stdout is UTF-8")
}

/// Run `xtask ARGS...` (the project automation: `cargo xtask ARGS...`) in `dir`.
pub fn xtask(dir: &Path, args: &[&str]) -> Output {
    Command::new(bin_dir().join("xtask"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("cannot start xtask")
}

/// `../shared/data` if present. Where it is absent the test is skipped with a printed reason
/// (`None`), except in CI (environment variable `CI` set), where the data must be present and
/// its absence fails the test.
pub fn shared_data(test: &str) -> Option<PathBuf> {
    let d = root().join("..").join("shared").join("data");
    if d.is_dir() {
        return Some(d);
    }
    let reason = format!("{test}: ../shared/data is not present next to the repository");
    if std::env::var_os("CI").is_some_and(|v| !v.is_empty()) {
        panic!("{reason}, and CI (environment variable CI is set) must have it");
    }
    // Written to the process's stderr, not through `eprintln!`, which the test harness
    // captures and shows only for a failing test: a skip must be seen when the test passes.
    use std::io::Write;
    let _ = writeln!(std::io::stderr(), "SKIPPED {reason}");
    None
}

/// The paper's motor with the paper's LuGre friction as a MODEL.toml text (voltage plant,
/// 12 ms sample period; numbers from the paper's parameter tables), for tests to append
/// `[[effects]]` or `[sensor]` sections to.
pub const PAPER_LUGRE_MODEL: &str = r#"
kind = "lugre"
plant = "voltage"
sample_period = 0.012

[motor]
r = 0.2162
l = 0.0003
kt = 0.07126
kb = 0.07126
j = 0.0003

[lugre]
alpha0 = 0.08
alpha1 = 0.0175
alpha2 = 0.0016
v0 = 3.676
sigma0 = 317.225
sigma1 = 22.2464
"#;
pub mod false_alarms;
pub mod other_plant;
pub mod plant_cases;
