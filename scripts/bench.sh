#!/usr/bin/env bash
# `motorid fit --model sindyc` end to end against pysindy's STLSQ fit on the same 10^6 samples
# (scripts/bench_peers.py: one run, ratio peer/ours, time per sample at each size), then the
# building blocks' criterion benches beside numpy when `--blocks` is given.
# Installs numpy and pysindy 2.x into a venv under target/ when missing; builds the release
# binary. The table goes to docs/performance-sindyc.md. Arguments after the options go to bench_peers.py (e.g. `--sizes 1e5,1e6,1e7`).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --bin motorid
if [ "${1:-}" = "--blocks" ]; then
    shift
    cargo bench -p motorid --bench ident
fi
VENV=target/bench-venv
if ! "$VENV/bin/python" -c "import numpy, pysindy" 2>/dev/null; then
    if ! python3 -m venv "$VENV" 2>/dev/null; then
        echo "installing python3-venv (Debian) for the peers' virtual environment" >&2
        apt-get update -qq && apt-get install -y -qq python3-venv
        python3 -m venv "$VENV"
    fi
    "$VENV/bin/pip" install -q numpy "pysindy>=2,<3"
fi
"$VENV/bin/python" scripts/bench_peers.py "$@"
