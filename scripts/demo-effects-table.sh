#!/usr/bin/env bash
# The loop on every effect `motorid demo --random` can draw: hides each at its default size
# (seed 1), runs `motorid demo --effect NAME`, and prints the Markdown table of docs/results.md
# ("Every effect --random can draw"): what was found, and the test fits (a fresh draw of
# signal b no choice was made on) of the angle x and the current i at step 0 and at the end.
#
# Usage: scripts/demo-effects-table.sh [EFFECT ...]   (default: all eight)
# Env: MOTORID (default: build and use target/release/motorid), OUT (work dir, default a temp dir).
set -euo pipefail
cd "$(dirname "$0")/.."
if [ -z "${MOTORID:-}" ]; then
  cargo build -q --release --bin motorid
  MOTORID=target/release/motorid
fi
out=${OUT:-$(mktemp -d)}
mkdir -p "$out"
effects=("$@")
[ ${#effects[@]} -gt 0 ] || effects=(offset asymmetry position_load deadtime cogging current_offset load_friction thermal)

echo "| hidden (default) | verdict: found | x: step 0 → end | i: step 0 → end |"
echo "|---|---|---|---|"
for e in "${effects[@]}"; do
  log="$out/demo-$e.txt"
  "$MOTORID" demo --quiet --effect "$e" --seed 1 --report "$out/report-$e" >"$log" 2>&1
  awk -v name="$e" '
    /^step [0-9]+:/ {
      for (i = 1; i <= NF; i++) {
        if ($i == "x") x = $(i + 1); if ($i == "i") c = $(i + 1)
      }
      if (first == "") { x0 = x; i0 = c; first = 1 }
    }
    /^hidden effect:/ { hidden = $3 }
    $1 == name ":" {
      line = $0; sub(/^ *[a-z_]+: /, "", line); verdict = line
    }
    END {
      printf "| %s | %s | %s → %s | %s → %s |\n", hidden, verdict, x0, x, i0, c
    }' "$log"
done
echo "(demo outputs are in $out)" >&2
