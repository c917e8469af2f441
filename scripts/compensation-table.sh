#!/usr/bin/env bash
# The reference paper's friction-compensation experiment on the emulated board: simulate the
# fitting signal (a) on the built-in motor emulator, fit a LuGre and a SINDYc model to it, then
# run closed-loop PI speed control (same gains everywhere) with no, LuGre and SINDYc
# compensation on a sine and a stepped speed reference, and print the Markdown table of docs/results.md
# (RMS tracking error overall and at |ω_ref| below the Stribeck velocity).
#
# Usage: scripts/compensation-table.sh [extra `motorid emulate` options, e.g. --edge-timing 0.1]
# Env: MOTORID (default: build and use target/release/motorid), OUT (work dir, default a temp dir).
set -euo pipefail
cd "$(dirname "$0")/.."
if [ -z "${MOTORID:-}" ]; then
  cargo build -q --release --bin motorid
  MOTORID=target/release/motorid
fi
out=${OUT:-$(mktemp -d)}
mkdir -p "$out"
"$MOTORID" simulate --signal a --duration 60 --seed 1 -o "$out/a.csv" >&2
"$MOTORID" fit --model lugre -o "$out/lugre.toml" "$out/a.csv" >"$out/fit-lugre.log" 2>&1
"$MOTORID" fit --model sindyc -o "$out/sindyc.toml" "$out/a.csv" >"$out/fit-sindyc.log" 2>&1
"$MOTORID" emulate --table --model "$out/lugre.toml" --model "$out/sindyc.toml" \
  --svg "$out/compensation-sine.svg" "$@"
echo "(models, logs and the chart are in $out)" >&2
