#!/usr/bin/env bash
# A checksum of what `motorid` writes for every named effect, to show that a refactor leaves
# the product's outputs as they were: run it before and after, then `diff` the two files.
#
# For each effect NAME: `simulate --effect NAME` (signal a, 90 s, seed 1), then on that log
# `fit --model linear|lugre|sindyc --add NAME` (the model file, or the error text when the
# model refuses the effect), `diagnose --json` of the LuGre fit, and `export` of it as a
# blob, JSON and C header with `inspect --json` of the blob. Each line of the manifest is
# `sha256  NAME/what`. Takes about five minutes on two free cores (48 fits).
#
# Usage: scripts/outputs-manifest.sh MANIFEST.txt [NAME ...]
set -euo pipefail
out=${1:?usage: scripts/outputs-manifest.sh MANIFEST.txt [NAME ...]}
out=$(realpath -m "$out")
cd "$(dirname "$0")/.."
shift
names=("$@")
if [[ ${#names[@]} -eq 0 ]]; then
    names=(coulomb viscous stribeck presliding cogging position_load offset asymmetry deadtime
        current_offset thermal load_friction saturation compliance backlash table:var=omega,bins=4)
fi
cargo build -q --release --bin motorid
bin="${CARGO_TARGET_DIR:-target}/release/motorid"
bin=$(realpath "$bin")
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
# Relative paths inside one folder: the model files record where their data came from.
cd "$work"

# capture FILE COMMAND...: the command's output file, or its stderr when it fails.
capture() {
    local file=$1
    shift
    if "$@" >/dev/null 2>"$file.err"; then
        rm "$file.err"
    else
        mv "$file.err" "$file"
    fi
}

: >"$out.tmp"
for name in "${names[@]}"; do
    dir="${name%%:*}"
    mkdir -p "$dir"
    capture "$dir/log.csv" "$bin" simulate --signal a --duration 90 --seed 1 --effect "$name" \
        -o "$dir/log.csv"
    for model in linear lugre sindyc; do
        capture "$dir/$model.toml" "$bin" fit -q --model "$model" --add "${name%%:*}" \
            -o "$dir/$model.toml" "$dir/log.csv"
    done
    if grep -q '^kind' "$dir/lugre.toml"; then
        "$bin" diagnose --json "$dir/lugre.toml" "$dir/log.csv" >"$dir/diagnose.json" 2>&1 || true
        for format in blob json c-header; do
            capture "$dir/export.$format" "$bin" export --format "$format" \
                -o "$dir/export.$format" "$dir/lugre.toml"
        done
        "$bin" inspect --json "$dir/export.blob" >"$dir/inspect.json" 2>&1 || true
    fi
    sha256sum "$dir"/* >>"$out.tmp"
done
mv "$out.tmp" "$out"
echo "wrote $out ($(wc -l <"$out") outputs)"
