#!/usr/bin/env python3
"""Peers of motorid's SINDYc building blocks, timed on the SAME data as our criterion benches.

Reads target/bench-data/ident_1e6.f64, written by `cargo bench -p host-tools --bench ident`
(10^6 samples; little-endian f64: n, then the columns x, xdot, z, i, u, dxdot, dz, di), and
times:
  * numpy: SVD of the 60-row Hankel matrix of the velocity, then the first row of the
    low-energy reconstruction U Σ̂ Vᵀ (components 31..60, the paper's), i.e. the paper's
    hidden-state extraction done the direct way;
  * pysindy 2.x: STLSQ (normalize_columns=True) on the paper's 17-term library evaluated
    with numpy on the same signals, 3 targets (dxdot, dz, di);
  * numpy: building that 17-column library alone.
Each is the best of REPEATS runs. If our criterion results exist (target/criterion/ident_1e6),
prints ours vs peers with ratios as a markdown table; `--json` prints the numbers.

Needs numpy and pysindy>=2; scripts/bench.sh installs them in a venv under target/.
"""
import json
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DATA = os.path.join(ROOT, "target", "bench-data", "ident_1e6.f64")
CRITERION = os.path.join(ROOT, "target", "criterion", "ident_1e6")
REPEATS = 3
M = 60  # delays (paper)
A = 5.0  # tanh gain (motorid's default)


def best_of(fn, repeats=REPEATS):
    best = float("inf")
    out = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def load():
    if not os.path.exists(DATA):
        sys.exit(
            f"error: {DATA} is missing; run `cargo bench -p host-tools --bench ident` first "
            "(it writes the data), or scripts/bench.sh"
        )
    raw = np.fromfile(DATA, dtype="<f8")
    n = int(raw[0])
    cols = raw[1:].reshape(8, n)
    names = ["x", "xdot", "z", "i", "u", "dxdot", "dz", "di"]
    return {k: cols[j] for j, k in enumerate(names)}


def hankel_svd(w):
    n = w.size - M + 1
    h = np.lib.stride_tricks.sliding_window_view(w, n)  # M x n view, H[k, j] = w[j + k]
    h = np.ascontiguousarray(h)
    u, s, vt = np.linalg.svd(h, full_matrices=False)
    lo, hi = 30, 60  # components 31..60
    return (u[0, lo:hi] * s[lo:hi]) @ vt[lo:hi, :]


def library(d):
    x, v, z, i, u = d["x"], d["xdot"], d["z"], d["i"], d["u"]
    av = np.abs(v)
    az = np.abs(z)
    return np.column_stack(
        [
            x, v, z, i, np.tanh(A * v), np.tanh(A * z), av * v, av * v * v, az * z,
            az * z * z, z * v, z * z * v, z * v * v, u, z * u, z * z * u, z * u * u,
        ]
    )


def ours():
    """Mean times [s] of our criterion benches, if they ran."""
    out = {}
    for name in ["hankel_extract", "sindyc_library", "sindyc_regression", "sindyc_weak_regression"]:
        p = os.path.join(CRITERION, name, "new", "estimates.json")
        try:
            with open(p) as f:
                out[name] = json.load(f)["mean"]["point_estimate"] * 1e-9
        except OSError:
            pass
    return out


def main():
    d = load()
    res = {"samples": int(d["x"].size)}
    t_svd, z_np = best_of(lambda: hankel_svd(d["xdot"]), repeats=1 if "--quick" in sys.argv else REPEATS)
    res["numpy_hankel_svd"] = t_svd
    t_lib, theta = best_of(lambda: library(d))
    res["numpy_library"] = t_lib
    try:
        import pysindy as ps

        y = np.column_stack([d["dxdot"], d["dz"], d["di"]])

        def stlsq():
            opt = ps.STLSQ(threshold=0.002, normalize_columns=True, max_iter=20)
            opt.fit(theta, y)
            return opt.coef_

        t_st, _ = best_of(stlsq)
        res["pysindy_stlsq"] = t_st
        res["pysindy_version"] = ps.__version__ if hasattr(ps, "__version__") else "?"
    except ImportError:
        print("pysindy is not installed: skipping its STLSQ (scripts/bench.sh installs it)", file=sys.stderr)
    mine = ours()
    res["ours"] = mine
    if "--json" in sys.argv:
        print(json.dumps(res, indent=1))
        return
    rows = [("Hankel hidden state, m = 60", "hankel_extract", "numpy SVD of the 60-row Hankel + reconstruction", t_svd)]
    if "pysindy_stlsq" in res:
        rows.append(
            ("SINDYc regression, 17 terms, STLSQ, 3 targets", "sindyc_regression",
             "pysindy STLSQ on a numpy-built library (library + fit)", t_lib + res["pysindy_stlsq"])
        )
        rows.append(("  of which: STLSQ only", None, "pysindy STLSQ (fit only)", res["pysindy_stlsq"]))
    rows.append(("  of which: 17-term library", "sindyc_library", "numpy library", t_lib))
    print(f"10^6 samples, {os.cpu_count()} cores\n")
    print("| task | motorid | peer | peer time | ratio (peer/ours) |")
    print("|---|---|---|---|---|")
    for task, key, peer, tp in rows:
        to = mine.get(key) if key else None
        ours_s = f"{to:.3f} s" if to else "-"
        ratio = f"{tp / to:.1f}×" if to else "-"
        print(f"| {task} | {ours_s} | {peer} | {tp:.3f} s | {ratio} |")
    if "sindyc_weak_regression" in mine:
        print(f"| SINDYc weak-form regression (what `fit` runs) | {mine['sindyc_weak_regression']:.3f} s | - | - | - |")


if __name__ == "__main__":
    main()
