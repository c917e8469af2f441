#!/usr/bin/env bash
# Speed of motorid's SINDYc building blocks against their peers, on the same 10^6 samples:
# runs our criterion benches (which also write the data to target/bench-data/), then
# scripts/bench_peers.py (numpy SVD of the Hankel matrix, pysindy STLSQ), and prints a
# markdown table of docs/results.md (ours vs peers, ratio).
# Installs numpy and pysindy 2.x into a venv under target/ when missing.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo bench -p host-tools --bench ident
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
