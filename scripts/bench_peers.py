#!/usr/bin/env python3
"""`motorid fit --model sindyc` end to end against pysindy's STLSQ fit, on the same data.

1. Data: a log of the paper's fitting signal (a) at 12 ms from the emulator
   (`motorid simulate`, chunks of 1,000 s with successive seeds joined end to end, the
   time and the angle made continuous), 10^6 samples; larger sizes repeat it. Written once
   to target/bench-data/sindyc_a_<n>.csv.
2. Ours: wall and CPU time (user + sys) of the release binary `motorid fit --model sindyc
   -q -o MODEL.toml DATA.csv`, from the CSV to the model file, for every size (default 10^5 and 10^6;
   `--sizes 1e5,1e6,1e7` adds 10^7): time per sample shows whether it is linear in n.
3. Peer: pysindy 2.x STLSQ (normalize_columns=True) fitted on the paper's 17-term library
   of the same 10^6 samples (x = theta, xdot = centred slope of theta over +-5 samples as
   ours, z = the low-energy Hankel reconstruction of xdot, i, u), three targets (np.gradient
   of xdot, z, i): the fit call alone is timed, not the reading nor the library.
Both run in this one process, one after the other, so they see the same machine load; the
ratio peer/ours is what counts.

If the criterion benches of the building blocks ran (`cargo bench -p motorid --bench
ident`, which writes target/bench-data/ident_1e6.f64), their table follows (numpy Hankel
SVD and library vs ours).

Needs numpy and pysindy>=2; scripts/bench.sh installs them in a venv under target/ and
builds the release binary.
"""
import json
import os
import resource
import subprocess
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DATA_DIR = os.path.join(ROOT, "target", "bench-data")
MOTORID = os.path.join(
    os.environ.get("CARGO_TARGET_DIR", os.path.join(ROOT, "target")), "release", "motorid"
)
BLOCKS = os.path.join(DATA_DIR, "ident_1e6.f64")
CRITERION = os.path.join(ROOT, "target", "criterion", "ident_1e6")
TS = 0.012
CHUNK_S = 1000.0  # seconds of emulated log per `motorid simulate` call (its limit is 10^4)
PEER_N = 1_000_000
M = 60  # delays (paper)
A = 5.0  # tanh gain (motorid's default)


def arg(name, default):
    if name in sys.argv:
        return sys.argv[sys.argv.index(name) + 1]
    return default


def load(path, usecols=(0, 1, 2, 3)):
    """The columns t, u, i, theta of a motorid CSV (its `#` lines and header skipped)."""
    with open(path) as f:
        skip = 1
        for line in f:
            if not line.startswith("#"):
                break
            skip += 1
    return np.loadtxt(path, delimiter=",", skiprows=skip, usecols=usecols)


def write_log(path, t, u, i, theta):
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        f.write(f"# sample_period={TS}\n# hall_resolution_rad=0.09519977738150888\n")
        f.write("t,u,i,theta\n")
        np.savetxt(f, np.column_stack([t, u, i, theta]), delimiter=",", fmt="%.9g")
    os.replace(tmp, path)


def base_log():
    """10^6 samples of signal a, chunk after chunk."""
    path = os.path.join(DATA_DIR, f"sindyc_a_{PEER_N}.csv")
    if os.path.exists(path):
        return path
    os.makedirs(DATA_DIR, exist_ok=True)
    per_chunk = int(round(CHUNK_S / TS))
    parts = []
    k = 0
    while sum(len(p[0]) for p in parts) < PEER_N:
        out = os.path.join(DATA_DIR, f"chunk_{k}.csv")
        subprocess.run([MOTORID, "simulate", "--signal", "a", "--duration", str(CHUNK_S),
                        "--seed", str(k + 1), "-o", out], check=True, stdout=subprocess.DEVNULL)
        d = load(out)
        os.remove(out)
        parts.append((d[:per_chunk, 1], d[:per_chunk, 2], d[:per_chunk, 3]))
        k += 1
    u = np.concatenate([p[0] for p in parts])[:PEER_N]
    i = np.concatenate([p[1] for p in parts])[:PEER_N]
    theta = join_angles([p[2] for p in parts])[:PEER_N]
    write_log(path, np.arange(PEER_N) * TS, u, i, theta)
    return path


def join_angles(pieces):
    """Angles of consecutive pieces made continuous (each piece starts where the last ended)."""
    out = []
    offset = 0.0
    for p in pieces:
        out.append(p - p[0] + offset)
        offset = out[-1][-1]
    return np.concatenate(out)


def sized_log(n):
    path = os.path.join(DATA_DIR, f"sindyc_a_{n}.csv")
    if os.path.exists(path):
        return path
    base = base_log()
    if n == PEER_N:
        return base
    d = load(base)
    reps = -(-n // len(d))
    u = np.tile(d[:, 1], reps)[:n]
    i = np.tile(d[:, 2], reps)[:n]
    theta = join_angles([d[:, 3]] * reps)[:n]
    write_log(path, np.arange(n) * TS, u, i, theta)
    return path


def children_cpu():
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def time_ours(path):
    """Wall and CPU (user + sys) seconds of one `motorid fit --model sindyc`."""
    out = os.path.join(DATA_DIR, "bench_model.toml")
    c0 = children_cpu()
    t0 = time.perf_counter()
    r = subprocess.run([MOTORID, "fit", "--model", "sindyc", "-q", "-o", out, path],
                       stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    dt = time.perf_counter() - t0
    if r.returncode != 0:
        sys.exit(f"error: motorid fit failed on {path}: {r.stderr.strip()}")
    return dt, children_cpu() - c0


def centred_velocity(t, theta, half=5):
    n = theta.size
    k = np.arange(n)
    a = np.maximum(k - half, 0)
    b = np.minimum(k + half, n - 1)
    return (theta[b] - theta[a]) / (t[b] - t[a])


def hankel_z(w):
    """First row of the low-energy (components 31..60) reconstruction of the Hankel matrix."""
    h = np.lib.stride_tricks.sliding_window_view(w, M)  # (n-M+1) x M
    g = h.T @ h
    vals, vecs = np.linalg.eigh(g)  # ascending: the low-energy half is the first 30
    low = vecs[:, : M // 2]
    z = h @ (low @ low[0, :])
    z = np.concatenate([z, np.zeros(M - 1)])
    return z / np.sqrt(np.mean(z * z))


def library(x, v, z, i, u):
    av = np.abs(v)
    az = np.abs(z)
    return np.column_stack(
        [
            x, v, z, i, np.tanh(A * v), np.tanh(A * z), av * v, av * v * v, az * z,
            az * z * z, z * v, z * z * v, z * v * v, u, z * u, z * z * u, z * u * u,
        ]
    )


def time_pysindy(path):
    import pysindy as ps

    d = load(path)
    t, u, i, theta = d[:, 0], d[:, 1], d[:, 2], d[:, 3]
    v = centred_velocity(t, theta)
    z = hankel_z(v)
    theta_lib = library(theta, v, z, i, u)
    y = np.column_stack([np.gradient(v, TS), np.gradient(z, TS), np.gradient(i, TS)])
    opt = ps.STLSQ(threshold=0.002, normalize_columns=True, max_iter=20)
    c0 = time.process_time()
    t0 = time.perf_counter()
    opt.fit(theta_lib, y)
    dt = time.perf_counter() - t0
    return dt, time.process_time() - c0, getattr(ps, "__version__", "?")


def building_blocks():
    """Our criterion means [s] and numpy's times on the criterion data, when it exists."""
    if not os.path.exists(BLOCKS):
        return None
    raw = np.fromfile(BLOCKS, dtype="<f8")
    n = int(raw[0])
    cols = dict(zip(["x", "xdot", "z", "i", "u"], raw[1:].reshape(8, n)[:5]))
    t0 = time.perf_counter()
    library(cols["x"], cols["xdot"], cols["z"], cols["i"], cols["u"])
    t_lib = time.perf_counter() - t0
    t0 = time.perf_counter()
    hankel_z(cols["xdot"])
    t_hankel = time.perf_counter() - t0
    mine = {}
    for name in ["hankel_extract", "sindyc_library", "sindyc_weak_regression"]:
        try:
            with open(os.path.join(CRITERION, name, "new", "estimates.json")) as f:
                mine[name] = json.load(f)["mean"]["point_estimate"] * 1e-9
        except OSError:
            pass
    return [
        ("Hankel hidden state, m = 60", mine.get("hankel_extract"), "numpy Gram + eigh + projection", t_hankel),
        ("17-term library", mine.get("sindyc_library"), "numpy library", t_lib),
    ]


def main():
    if not os.path.exists(MOTORID):
        sys.exit(f"error: {MOTORID} is missing; run `cargo build --release --bin motorid` first")
    sizes = [int(float(s)) for s in arg("--sizes", "1e5,1e6").split(",")]
    paths = {n: sized_log(n) for n in sorted(set(sizes + [PEER_N]))}
    res = {"cores": os.cpu_count(), "ours_s": {}, "ours_cpu_s": {}}
    res["load_average_before"] = os.getloadavg()[0]
    # Peer and ours on the 10^6 samples back to back, then the other sizes.
    t_peer, cpu_peer, version = time_pysindy(paths[PEER_N])
    res["pysindy_stlsq_s"] = t_peer
    res["pysindy_stlsq_cpu_s"] = cpu_peer
    res["pysindy_version"] = version
    for n in [PEER_N] + [s for s in sizes if s != PEER_N]:
        res["ours_s"][n], res["ours_cpu_s"][n] = time_ours(paths[n])
    res["load_average_after"] = os.getloadavg()[0]
    res["ratio_peer_over_ours"] = t_peer / res["ours_s"][PEER_N]
    if "--json" in sys.argv:
        print(json.dumps(res, indent=1))
        return
    print(f"signal a at 12 ms, {os.cpu_count()} cores, pysindy {version}, load average "
          f"{res['load_average_before']:.1f} before, {res['load_average_after']:.1f} after "
          "(the ratio is only meaningful on free cores)\n")
    print("| samples | motorid fit --model sindyc (CSV -> MODEL.toml) | CPU (user + sys) | per sample | pysindy STLSQ fit alone | its CPU | ratio (peer/ours) |")
    print("|---|---|---|---|---|---|---|")
    for n in sorted(res["ours_s"]):
        t, c = res["ours_s"][n], res["ours_cpu_s"][n]
        peer = f"{t_peer:.2f} s" if n == PEER_N else "-"
        peer_cpu = f"{cpu_peer:.2f} s" if n == PEER_N else "-"
        ratio = f"{t_peer / t:.1f}x" if n == PEER_N else "-"
        print(f"| {n:.0e} | {t:.2f} s | {c:.2f} s | {t / n * 1e6:.2f} us | {peer} | {peer_cpu} | {ratio} |")
    blocks = building_blocks()
    if blocks:
        print("\n| building block, 10^6 samples | motorid | peer | peer time | ratio (peer/ours) |")
        print("|---|---|---|---|---|")
        for task, ours, peer, tp in blocks:
            o = f"{ours:.3f} s" if ours else "-"
            r = f"{tp / ours:.1f}x" if ours else "-"
            print(f"| {task} | {o} | {peer} | {tp:.3f} s | {r} |")


if __name__ == "__main__":
    main()
