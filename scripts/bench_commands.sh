#!/usr/bin/env bash
# Wall and CPU time of the commands a user waits for, end to end from the CSV files: on
# emulated logs of 90 s at 12 ms (signal a to fit, signal b to validate, a constant load
# torque hidden), `fit --model lugre`, `fit --add offset`, `diagnose` and `demo`; on the same
# signals with a cogging torque hidden, `fit --add cogging`.
# Prints a markdown table (docs/performance.md has the measured figures). CPU above wall
# means the work ran on several cores; wall far above CPU means the machine was busy.
# Usage: scripts/bench_commands.sh [--no-demo]
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --bin motorid
bin="${CARGO_TARGET_DIR:-target}/release/motorid"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
"$bin" simulate --signal a --duration 90 --seed 1 --effect offset -o "$work/a.csv" >/dev/null
"$bin" simulate --signal b --duration 90 --seed 2 --effect offset -o "$work/b.csv" >/dev/null
"$bin" simulate --signal a --duration 90 --seed 1 --effect cogging -o "$work/a_cog.csv" >/dev/null
"$bin" simulate --signal b --duration 90 --seed 2 --effect cogging -o "$work/b_cog.csv" >/dev/null

rows=()
# run NAME COMMAND...: time one command (output discarded), append a table row.
run() {
    local name=$1
    shift
    local TIMEFORMAT='%R %U %S' t
    t=$( { time "$@" >/dev/null 2>&1; } 2>&1 )
    read -r wall user sys <<<"$t"
    rows+=("| \`$name\` | $wall | $(awk -v a="$user" -v b="$sys" 'BEGIN { printf "%.2f", a + b }') |")
}

run "fit --model lugre" "$bin" fit -q --model lugre -o "$work/lugre.toml" "$work/a.csv"
run "fit --model lugre --add offset --validate b" "$bin" fit -q --model lugre --add offset \
    --validate "$work/b.csv" -o "$work/offset.toml" "$work/a.csv"
run "fit --model lugre --add cogging --validate b" "$bin" fit -q --model lugre --add cogging \
    --validate "$work/b_cog.csv" -o "$work/cogging.toml" "$work/a_cog.csv"
run "diagnose" "$bin" diagnose "$work/lugre.toml" "$work/a.csv"
if [[ "${1:-}" != "--no-demo" ]]; then
    run "demo" "$bin" demo -q --report "$work/demo-report"
fi

echo
echo "90 s logs at 12 ms (7,500 samples), $(nproc) cores, load average $(cut -d' ' -f1 /proc/loadavg)"
echo
echo "| command | wall [s] | CPU [s] |"
echo "|---|---:|---:|"
printf '%s\n' "${rows[@]}"
