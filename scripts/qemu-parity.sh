#!/usr/bin/env bash
# QEMU parity: run the board logic with its control step (crate qemu-parity, built for
# thumbv7em-none-eabihf) on an emulated Cortex-M4F (QEMU mps2-an386, semihosting) over the
# recorded input trace qemu-parity/trace/closed_loop.qpt, run the same code on the host, and
# compare the f32 outputs bit for bit. Then count the instructions each 12 ms period of the
# board logic (limits, faults, telemetry and the control step) takes, per observer
# (none / LuGre / SINDYc / SINDYc in experiment mode on signal a / LuGre with all eight effect
# slots used), from QEMU's per-instruction exec log, each held to the budget of
# docs/decisions/0036-step-budget-counts-the-fullest-blob.md.
#
# Installs qemu-system-arm (Debian) and the thumbv7em-none-eabihf target when missing.
# Builds in $CARGO_TARGET_DIR, by default <repo>/target/qemu (a separate directory, so that it
# does not wait for the lock of a concurrent host build and never rebuilds the firmware).
# Env: QEMU_PARITY_ULP (default 0) = allowed difference in ulp; QEMU_PARITY_COUNT=0 skips counting.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)

as_root() { if [ "$(id -u)" = 0 ]; then "$@"; else sudo "$@"; fi; }
if ! command -v qemu-system-arm >/dev/null 2>&1; then
  echo "==> installing qemu-system-arm (Debian)"
  as_root apt-get update -qq
  as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends qemu-system-arm >/dev/null
fi
if ! rustup target list --installed | grep -qx thumbv7em-none-eabihf; then
  rustup target add thumbv7em-none-eabihf
fi

export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$root/target/qemu}"
echo "==> building qemu-parity for thumbv7em-none-eabihf and for the host (in $CARGO_TARGET_DIR)"
cargo build -q --release -p qemu-parity --target thumbv7em-none-eabihf
cargo build -q --release -p qemu-parity
elf="$CARGO_TARGET_DIR/thumbv7em-none-eabihf/release/qemu-parity"
host="$CARGO_TARGET_DIR/release/qemu-parity"

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
qemu=(qemu-system-arm -machine mps2-an386 -cpu cortex-m4 -nographic -monitor none -serial none
      -semihosting-config enable=on,target=native -kernel "$elf")

echo "==> running the control step on QEMU mps2-an386 (Cortex-M4F)"
if ! timeout 300 "${qemu[@]}" >"$work/qemu.out" 2>"$work/qemu.err"; then
  echo "error: the QEMU run failed:" >&2
  cat "$work/qemu.err" >&2
  tail -5 "$work/qemu.out" >&2
  exit 1
fi
"$host" compare "$work/qemu.out" --ulp "${QEMU_PARITY_ULP:-0}"

if [ "${QEMU_PARITY_COUNT:-1}" != 0 ]; then
  echo "==> counting instructions per control step (one instruction per translation block)"
  # QEMU >= 8.1 replaced -singlestep with -accel tcg,one-insn-per-tb=on.
  ver=$(qemu-system-arm --version | sed -n 's/^QEMU emulator version \([0-9]*\)\.\([0-9]*\).*/\1 \2/p')
  read -r major minor <<<"$ver" || true
  major=${major:-0}; minor=${minor:-0}
  if [ "$major" -gt 8 ] || { [ "$major" -eq 8 ] && [ "$minor" -ge 1 ]; }; then
    one=(-accel tcg,one-insn-per-tb=on)
  else
    one=(-singlestep)
  fi
  timeout 900 "${qemu[@]}" "${one[@]}" -d exec,nochain -D /dev/stderr 2>&1 >/dev/null \
    | "$host" count "$work/qemu.out"
fi
