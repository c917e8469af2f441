//! Speed of the SINDYc building blocks on 10^6 samples:
//! Hankel state extraction (target ≤ 0.25 s) and one SINDYc regression with the paper's
//! 17-term library and STLSQ (target ≤ 0.2 s), on a 2-core machine.
//!
//! Benchmarks (group `ident_1e6`): `hankel_extract` (Gram matrix + eigen-decomposition +
//! FIR extraction of z, m = 60), `sindyc_library` (the 17 columns), `sindyc_regression`
//! (library + normal equations + STLSQ for 3 pointwise targets: the problem pysindy solves),
//! `sindyc_weak_regression` (library + weak-form integrals + STLSQ: what `fit` does; the
//! uniform-sampling fast path), `sindyc_weak_regression_generic` (the same rows window by
//! window, the path of non-uniformly sampled logs).
//!
//! The data is a deterministic motor-like record (multisine voltage, first-order velocity
//! with tanh friction, Hall-quantised angle, current from the quasi-static electrical
//! equation plus pseudo-noise). It is also written to `target/bench-data/ident_1e6.f64`
//! so that `scripts/bench_peers.py` runs pysindy and numpy on the SAME numbers:
//! little-endian f64, `n` then the columns x, xdot, z, i, u, dxdot, dz, di (each `n` long);
//! the last three are `numpy.gradient`-style central differences (the pointwise targets
//! pysindy would use).
use control::sindy::Term;
use criterion::{criterion_group, criterion_main, Criterion};
use faer::Mat;
use motorid::ident::hankel::{HankelEmbedding, Selection, DEFAULT_DELAYS};
use motorid::ident::library::{Library, Signals};
use motorid::ident::sindyc::{weak_rows, weak_rows_generic};
use motorid::ident::stlsq::StlsqOptions;
use motorid::log::Plant;
use motorid::numerics::least_squares::NormalEquations;
use std::hint::black_box;
use std::path::PathBuf;

const N: usize = 1_000_000;
const DT: f64 = 0.012;

struct Data {
    t: Vec<f64>,
    x: Vec<f64>,
    xdot: Vec<f64>,
    z: Vec<f64>,
    i: Vec<f64>,
    u: Vec<f64>,
}

/// `numpy.gradient` with uniform spacing.
fn gradient(f: &[f64], dt: f64) -> Vec<f64> {
    let n = f.len();
    (0..n)
        .map(|k| match k {
            0 => (f[1] - f[0]) / dt,
            k if k == n - 1 => (f[n - 1] - f[n - 2]) / dt,
            k => (f[k + 1] - f[k - 1]) / (2.0 * dt),
        })
        .collect()
}

fn data() -> Data {
    let mut s = 0x2545F4914F6CDD1Du64;
    let mut noise = || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((s >> 11) as f64 / (1u64 << 53) as f64) - 0.5
    };
    let tau = std::f64::consts::TAU;
    let (r, kb, hall) = (0.216, 0.0713, 0.0952);
    let mut t = Vec::with_capacity(N);
    let mut u = Vec::with_capacity(N);
    let mut x = Vec::with_capacity(N);
    let mut i = Vec::with_capacity(N);
    let (mut w, mut th) = (0.0f64, 0.0f64);
    let mut wtrue = Vec::with_capacity(N);
    for k in 0..N {
        let tk = k as f64 * DT;
        let uk = 6.0 * (tau * 0.3 * tk).sin()
            + 3.0 * (tau * 0.77 * tk + 1.0).sin()
            + 2.0 * (tau * 0.11 * tk).sin();
        t.push(tk);
        u.push(uk);
        x.push((th / hall).floor() * hall);
        i.push((uk - kb * w) / r + 0.02 * noise());
        wtrue.push(w);
        // Semi-implicit step of ω' = −78ω + 84u − 30·tanh(5ω) (stable at 12 ms).
        w = (w + DT * (84.0 * uk - 30.0 * (5.0 * w).tanh())) / (1.0 + 78.0 * DT);
        th += w * DT;
    }
    let half = motorid::scales::samples_for(motorid::ident::sindyc::VELOCITY_HALF_S, DT, t.len());
    let xdot = motorid::ident::sindyc::centred_velocity(&t, &x, half);
    let emb = HankelEmbedding::fit(&xdot, DEFAULT_DELAYS, Selection::Range(31, 60)).unwrap();
    let z = emb.extract(&xdot).unwrap();
    Data {
        t,
        x,
        xdot,
        z,
        i,
        u,
    }
}

fn write_peer_file(d: &Data) {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../target/bench-data");
    let _ = std::fs::create_dir_all(&dir);
    let cols = [
        &d.x,
        &d.xdot,
        &d.z,
        &d.i,
        &d.u,
        &gradient(&d.xdot, DT),
        &gradient(&d.z, DT),
        &gradient(&d.i, DT),
    ];
    let mut bytes = Vec::with_capacity(8 * (1 + cols.len() * N));
    bytes.extend_from_slice(&(N as f64).to_le_bytes());
    for c in cols {
        for v in c.iter() {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
    let path = dir.join("ident_1e6.f64");
    if let Err(e) = motorid::atomic::write(&path, &bytes) {
        eprintln!("cannot write {}: {e:#}", path.display());
    }
}

fn benches(c: &mut Criterion) {
    let d = data();
    write_peer_file(&d);
    let sig = Signals {
        x: &d.x,
        xdot: &d.xdot,
        z: &d.z,
        i: Some(&d.i),
        u: &d.u,
    };
    let lib = Library::paper(Plant::Voltage, 5.0, 1.0);
    assert_eq!(lib.terms(), Term::PAPER_LIBRARY.to_vec());
    let mut g = c.benchmark_group("ident_1e6");
    g.sample_size(10);

    g.bench_function("hankel_extract", |b| {
        b.iter(|| {
            let emb =
                HankelEmbedding::fit(black_box(&d.xdot), DEFAULT_DELAYS, Selection::Range(31, 60))
                    .unwrap();
            black_box(emb.extract(&d.xdot).unwrap())
        })
    });

    // The 17 columns into a reused buffer (allocating a fresh 136 MB matrix is not the
    // library's cost, and the regression never materialises it).
    let mut buf = Mat::<f64>::zeros(N, lib.len());
    g.bench_function("sindyc_library", |b| {
        b.iter(|| {
            lib.matrix_into(black_box(&sig), &mut buf);
            black_box(buf[(N - 1, 0)])
        })
    });

    let targets = [
        gradient(&d.xdot, DT),
        gradient(&d.z, DT),
        gradient(&d.i, DT),
    ];
    g.bench_function("sindyc_regression", |b| {
        b.iter(|| {
            let y: Vec<&[f64]> = targets.iter().map(|t| t.as_slice()).collect();
            let ne = lib.normal(&sig, &y);
            let opts = StlsqOptions::default();
            black_box((0..3).map(|k| ne.stlsq(k, &opts)).collect::<Vec<_>>())
        })
    });

    g.bench_function("sindyc_weak_regression", |b| {
        b.iter(|| {
            let (a, y, _) = weak_rows(&lib, &d.t, &sig);
            let ne = NormalEquations::new(a.as_ref(), y.as_ref());
            let opts = StlsqOptions::default();
            black_box((0..3).map(|k| ne.stlsq(k, &opts)).collect::<Vec<_>>())
        })
    });
    // The window-by-window path (taken by non-uniformly sampled logs), for comparison with
    // the uniform fast path above under the same machine load.
    g.bench_function("sindyc_weak_regression_generic", |b| {
        b.iter(|| {
            let (a, y, _) = weak_rows_generic(&lib, &d.t, &sig);
            let ne = NormalEquations::new(a.as_ref(), y.as_ref());
            let opts = StlsqOptions::default();
            black_box((0..3).map(|k| ne.stlsq(k, &opts)).collect::<Vec<_>>())
        })
    });
    g.finish();
}

criterion_group!(ident, benches);
criterion_main!(ident);
