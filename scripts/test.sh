#!/usr/bin/env bash
# The project's test command (README "Quick start", second line; .ci/run calls it).
# Installs what a fresh machine lacks, builds the firmware and prints its flash/RAM use,
# runs rustfmt and clippy checks, the commit messages' check, every host test, and the QEMU
# parity run.
set -euo pipefail
cd "$(dirname "$0")/.."

step() { printf '\n==> %s\n' "$*"; }
as_root() { if [ "$(id -u)" = 0 ]; then "$@"; else sudo "$@"; fi; }
apt_updated=0
apt_install() {
  # apt_install CMD PACKAGE: install PACKAGE from Debian when CMD is missing.
  if ! command -v "$1" >/dev/null 2>&1; then
    if [ "$apt_updated" = 0 ]; then as_root apt-get update -qq; apt_updated=1; fi
    as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "$2" >/dev/null
  fi
}

# Property tests draw new cases on every local run (they keep exploring); under CI they draw
# from one fixed seed so that a red run can be reproduced exactly (failures found locally go
# into the checked-in *.proptest-regressions files, which every run replays first).
if [ -n "${CI:-}" ]; then export PROPTEST_RNG_SEED="${PROPTEST_RNG_SEED:-20261124}"; fi

step "Installing what is missing (thumbv7em target, qemu-system-arm, chromium, arm binutils)"
rustup target list --installed | grep -qx thumbv7em-none-eabihf || rustup target add thumbv7em-none-eabihf
apt_install qemu-system-arm qemu-system-arm
apt_install chromium chromium
apt_install arm-none-eabi-size binutils-arm-none-eabi

step "Building the firmware for the B-G431B-ESC1 (thumbv7em-none-eabihf)"
cargo build --release -p firmware --target thumbv7em-none-eabihf
if [ -x scripts/firmware-size.sh ]; then bash scripts/firmware-size.sh; fi

# `motorid flash` (the debug-probe path of docs/bring-up.md) is behind the `probe` feature,
# which no other build here turns on: type-check it so that it cannot rot. `check` does no
# code generation, so probe-rs and its USB stack cost about 1.5 CPU-minutes, not a build.
step "Checking that motorid compiles with --features probe (motorid flash)"
cargo check -q -p motorid --features probe --lib

step "Formatting"
cargo fmt --all -- --check

# Lints in the same pass as the test build. `cargo clippy --all-targets -- -D warnings` is
# `cargo check --all-targets` with clippy-driver as RUSTC_WORKSPACE_WRAPPER: it type-checks
# every dependency a second time (about 4 minutes on 2 cores) only to throw the result away.
# clippy-driver is a drop-in rustc, so with the same wrapper and lint flags cargo's real build
# runs the same lints on the same workspace targets (lib, bins, unit and integration tests,
# benches, examples) while dependencies, which clippy never lints, are built once. Set
# CI_SEPARATE_CLIPPY=1 to run plain `cargo clippy` instead.
step "Lints (clippy -D warnings) while building every target, then the host tests"
if [ "${CI_SEPARATE_CLIPPY:-0}" = 1 ] || ! clippy_driver=$(rustup which clippy-driver 2>/dev/null); then
  cargo clippy --all-targets -- -D warnings
else
  export RUSTC_WORKSPACE_WRAPPER="$clippy_driver"
  export CLIPPY_ARGS="-D__CLIPPY_HACKERY__warnings__CLIPPY_HACKERY__" # = `-- -D warnings`
fi
# Lib, bins, unit/integration tests, benches and examples (benches compile in the test profile).
cargo test --no-run --all-targets
# The non-test `motorid` and `xtask` binaries for the end-to-end tests. The tests' helper runs
# the same `cargo build $MOTORID_BUILD_ARGS` (it inherits these variables, the clippy wrapper
# included) and finds them fresh. `--tests` makes cargo resolve features with the dev-dependencies, as the
# workspace `cargo test` does; bare `--bin` targets would compile faer & co. a second time.
export MOTORID_BUILD_ARGS="-p motorid -p xtask --bin motorid --bin xtask --tests"
# shellcheck disable=SC2086
cargo build $MOTORID_BUILD_ARGS

# Commit messages (`cargo xtask commits`, with the binary just built: `cargo run` would resolve
# other features and compile the dependencies again). A clean checkout of main knows no branch
# point, so the range starts after COMMITS_BASE, the last commit whose message broke the rule:
# the history before it is left as it is, every commit since is held to the rule. COMMITS_RANGE
# overrides it (a branch before its merge: `main..HEAD`).
COMMITS_BASE=764c6ad6f37296bb529d393a5c014764f279a791
commits_range=${COMMITS_RANGE:-$COMMITS_BASE..HEAD}
commits_rc=0
step "Commit messages: subject of at most 72 characters, blank line, body ($commits_range)"
if ! git rev-parse -q --verify "${commits_range%%..*}^{commit}" >/dev/null 2>&1; then
  echo "SKIPPED commit messages: ${commits_range%%..*} is not in this checkout (no git history, or a shallow clone)"
else
  "${CARGO_TARGET_DIR:-target}/debug/xtask" commits "$commits_range" || commits_rc=$?
fi
# Cargo runs test binaries one after another, and most are one long single-threaded fit: the
# longest (fit_add_effects: the position load, and cogging on five draws) runs beside all the
# others so that both cores work (a name filter: both `the_loop_adds_` tests).
slow_test=the_loop_adds_
# (The same arguments as the build above, so nothing is rebuilt: `-p e2e` alone would resolve
# other features and compile the dependencies again.)
slow_bin=$(cargo test --no-run --all-targets --message-format=json 2>/dev/null \
  | sed -n 's/.*"executable":"\([^"]*\/fit_add_effects-[^"]*\)".*/\1/p' | tail -1)
slow_log=$(mktemp)
if [ -n "$slow_bin" ]; then
  (cd tests && "$slow_bin" "$slow_test" >"$slow_log" 2>&1; echo "rc=$?" >>"$slow_log") &
  slow_pid=$!
  skip=(-- --skip "$slow_test")
else
  skip=()
fi
tests_rc=0
cargo test --no-fail-fast "${skip[@]}" || tests_rc=$?
if [ -n "$slow_bin" ]; then
  wait "$slow_pid" || true
  printf '\n     Running %s (beside the others)\n' "$slow_bin"
  cat "$slow_log"
  grep -qx 'rc=0' "$slow_log" || { echo "error: $slow_test failed" >&2; tests_rc=1; }
fi
rm -f "$slow_log"
[ "$tests_rc" = 0 ] || exit "$tests_rc"
[ "$commits_rc" = 0 ] || { echo "error: commit messages in $commits_range break the rule" >&2; exit "$commits_rc"; }
unset RUSTC_WORKSPACE_WRAPPER CLIPPY_ARGS MOTORID_BUILD_ARGS

if [ -x scripts/qemu-parity.sh ]; then
  step "QEMU parity: the control step on an emulated Cortex-M4F equals the host run"
  bash scripts/qemu-parity.sh
fi
