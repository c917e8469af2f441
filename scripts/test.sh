#!/usr/bin/env bash
# The project's test command (README "Quick start", second line; .ci/run calls it).
# Installs what a fresh machine lacks, builds the firmware and prints its flash/RAM use,
# runs clippy and rustfmt checks, every host test, and the QEMU parity run.
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

step "Installing what is missing (thumbv7em target, qemu-system-arm, chromium, arm binutils)"
rustup target list --installed | grep -qx thumbv7em-none-eabihf || rustup target add thumbv7em-none-eabihf
apt_install qemu-system-arm qemu-system-arm
apt_install chromium chromium
apt_install arm-none-eabi-size binutils-arm-none-eabi

step "Building the firmware for the B-G431B-ESC1 (thumbv7em-none-eabihf)"
cargo build --release -p firmware --target thumbv7em-none-eabihf
if [ -x scripts/firmware-size.sh ]; then bash scripts/firmware-size.sh; fi

step "Formatting and lints"
cargo fmt --all -- --check
cargo clippy --all-targets -- -D warnings

step "Host tests (control core, motorid, end-to-end)"
cargo test --no-fail-fast

if [ -x scripts/qemu-parity.sh ]; then
  step "QEMU parity: the control step on an emulated Cortex-M4F equals the host run"
  bash scripts/qemu-parity.sh
fi
