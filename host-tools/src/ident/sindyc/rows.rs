//! The regression-rows stage: each equation multiplied by the shared smooth test functions
//! ([`crate::numerics::weak_form`], 40-sample windows, hop 20) and integrated by parts, so no
//! derivative of quantised data is taken: `∫φ·dẋ/dt = ∫φ''·x`, `∫φ·dz/dt = −∫φ'·z`,
//! `∫φ·dI/dt = −∫φ'·I`; the library columns become `∫φ·θ_j`. The rows of every fitting log
//! are stacked into one set of normal equations per state equation.
use super::embedding::HiddenState;
use crate::ident::library::{Library, Signals, ACCEL, IDOT, ZDOT};
use crate::log::{MotorLog, Plant};
use crate::numerics::least_squares::NormalEquations;
use crate::numerics::weak_form;
use anyhow::{bail, Result};
use faer::Mat;

/// The normal equations of the acceleration, `z` and (voltage plant) current equations over
/// the stacked weak-form rows of every fitting log.
///
/// Acceleration and `z`: `∫φ·dẋ/dt`, `∫φ·dz/dt` on the library. Current: the inverse form
/// `∫φ·u = L·∫φ·dI/dt + Σ c_k·∫φ·θ_k` (its last column is `∫φ·dI/dt`), because at 12 ms the
/// current is quasi-static (L/R ≈ 1.4 ms): `∫φ·dI/dt` is tiny and noisy, so regressing it on
/// the library would shrink every coefficient (errors in variables), while `u` is known
/// exactly.
pub fn normal_equations(
    lib: &Library,
    logs: &[MotorLog],
    hidden: &HiddenState,
    plant: Plant,
) -> Result<Vec<NormalEquations>> {
    let voltage = plant == Plant::Voltage;
    let mut blocks = Vec::new();
    for ((log, xdot), z) in logs.iter().zip(&hidden.xdot).zip(&hidden.z) {
        let s = Signals {
            x: &log.theta,
            xdot,
            z,
            i: if voltage { log.i.as_deref() } else { None },
            u: &log.u,
        };
        blocks.push(weak_rows(lib, &log.t, &s));
    }
    let rows: usize = blocks.iter().map(|(a, _, _)| a.nrows()).sum();
    if rows < lib.len() + 1 {
        bail!(
            "SINDYc: the logs are too short for {} library terms",
            lib.len()
        );
    }
    let mut a = Mat::<f64>::zeros(rows, lib.len());
    let mut y = Mat::<f64>::zeros(rows, 3);
    let mut d = Mat::<f64>::zeros(rows, 1);
    let mut r0 = 0;
    for (ba, by, bd) in &blocks {
        d.as_mut().submatrix_mut(r0, 0, bd.nrows(), 1).copy_from(bd);
        a.as_mut()
            .submatrix_mut(r0, 0, ba.nrows(), ba.ncols())
            .copy_from(ba);
        y.as_mut().submatrix_mut(r0, 0, by.nrows(), 3).copy_from(by);
        r0 += ba.nrows();
    }
    let mut nes = vec![
        NormalEquations::new(a.as_ref(), y.as_ref().subcols(ACCEL, 1)),
        NormalEquations::new(a.as_ref(), y.as_ref().subcols(ZDOT, 1)),
    ];
    if voltage {
        let mut ad = Mat::<f64>::zeros(rows, lib.len() + 1);
        ad.as_mut().subcols_mut(0, lib.len()).copy_from(&a);
        ad.as_mut().subcols_mut(lib.len(), 1).copy_from(&d);
        nes.push(NormalEquations::new(
            ad.as_ref(),
            y.as_ref().subcols(IDOT, 1),
        ));
    }
    Ok(nes)
}

/// The normal equations of the current equation as it is sampled. With `L/R` far below the
/// sample period (1.4 ms against 12 ms for the paper's motor) the current settles within a
/// sample: the `I_j` measured at `t_j` is the current of the whole interval
/// `[t_{j−1}, t_j]`, driven by the voltage `u_{j−1}` held over it. Integrating
/// `u = R·I + L·dI/dt + Σ c_k·θ_k` over the `W` intervals around `t_k` (a box test function
/// of the centred velocity's span, `W` = 2·[`super::velocity_half`]) gives exactly, for the
/// linear terms: mean of `u_{j−1}` = `R`·mean of `I_j` + `K_b`·(centred slope of θ) + the
/// negligible `L·ΔI/(W·h)`. So every signal is averaged over the same `W` intervals (the
/// angle's mean slope is the centred velocity; nonlinear terms are evaluated on the averaged
/// signals) and the target is the averaged held voltage: one row per sample, `u` never in a
/// support. A regression on `dI/dt` instead sees almost nothing of a current that has
/// settled, and the weak form's smooth test functions treat the held `u` as if it were
/// interpolated, half a sample early. `None` when a log has no current.
pub fn held_current_normal(
    lib: &Library,
    logs: &[MotorLog],
    hidden: &HiddenState,
) -> Option<NormalEquations> {
    let n: usize = logs
        .iter()
        .map(|l| l.len().saturating_sub(2 * super::velocity_half(l)))
        .sum();
    let mut cols: [Vec<f64>; 5] = std::array::from_fn(|_| Vec::with_capacity(n));
    for (log, z) in logs.iter().zip(&hidden.z) {
        let i = log.i.as_ref()?;
        let m = log.len();
        let w = 2 * super::velocity_half(log);
        if m <= w {
            continue;
        }
        // Interval j = 1..m: [t_{j−1}, t_j]; its mean velocity, held voltage, current.
        let slope: Vec<f64> = (1..m)
            .map(|j| (log.theta[j] - log.theta[j - 1]) / (log.t[j] - log.t[j - 1]))
            .collect();
        let series: [&[f64]; 5] = [&log.theta[1..], &slope, &z[1..m], &i[1..], &log.u[..m - 1]];
        for (col, v) in cols.iter_mut().zip(series) {
            box_mean_into(v, w, col);
        }
    }
    let [x, xdot, z, i, u] = &cols;
    let s = Signals {
        x,
        xdot,
        z,
        i: Some(i),
        u,
    };
    Some(lib.normal(&s, &[u]))
}

/// Append the means of every `w` consecutive values of `v` (a running sum).
fn box_mean_into(v: &[f64], w: usize, out: &mut Vec<f64>) {
    if v.len() < w {
        return;
    }
    let mut sum: f64 = v[..w].iter().sum();
    out.push(sum / w as f64);
    for k in w..v.len() {
        sum += v[k] - v[k - w];
        out.push(sum / w as f64);
    }
}

/// The regression rows of the weak form for one log: library integrals `∫φ·θ_j`
/// (`rows × p`), targets (`rows × 3`: `∫φ·dẋ/dt`, `∫φ·dz/dt`, `∫φ·u`) and the column
/// `∫φ·dI/dt` (`rows × 1`, zero without a current) of the current equation's inverse form.
///
/// Uniformly sampled logs (every log the board or the emulator writes) take the fast path
/// [`weak_rows_uniform`]; others the window-by-window [`weak_rows_generic`]. Both give the
/// same rows (to rounding; a test checks 1e-10 relative).
pub fn weak_rows(lib: &Library, t: &[f64], s: &Signals) -> (Mat<f64>, Mat<f64>, Mat<f64>) {
    if is_uniform(t) && weak_form::WINDOW.is_multiple_of(weak_form::HOP) {
        weak_rows_uniform(lib, t, s)
    } else {
        weak_rows_generic(lib, t, s)
    }
}

/// True when the sample period is constant (to 1e-9 relative).
fn is_uniform(t: &[f64]) -> bool {
    if t.len() < 2 {
        return false;
    }
    let h = t[1] - t[0];
    h > 0.0 && t.windows(2).all(|w| ((w[1] - w[0]) - h).abs() <= 1e-9 * h)
}

/// [`weak_rows`] for a uniformly sampled log. With a constant sample period every window
/// has the same test-function weights, and a window of `WINDOW = q·HOP` samples is `q`
/// consecutive hop-long segments. So each library column is evaluated once per sample (not
/// once per window it belongs to, twice at half overlap), blockwise into a cache-sized
/// buffer, and each segment's `q` partial integrals (one per piece of the test function) are
/// computed once; a window's integral is the sum of its segments' pieces.
pub fn weak_rows_uniform(lib: &Library, t: &[f64], s: &Signals) -> (Mat<f64>, Mat<f64>, Mat<f64>) {
    const LEN: usize = weak_form::WINDOW;
    const HOP: usize = weak_form::HOP;
    const Q: usize = LEN / HOP;
    let n = s.len().min(t.len());
    let p = lib.len();
    if n < LEN {
        return (Mat::zeros(0, p), Mat::zeros(0, 3), Mat::zeros(0, 1));
    }
    let rows = (n - LEN) / HOP + 1;
    // Segments used by the windows: rows + Q − 1.
    let segs = rows + Q - 1;
    // The kernels of the first window (all windows share them): φ·w, φ'·w, φ''·w.
    let w0 = &weak_form::windows(&t[..LEN], LEN, HOP)[0];
    let (k0, k1, k2) = (&w0.w0, &w0.w1, &w0.w2);
    // Partial integrals of one signal: part[g·Q + q] = Σ_i k[q·HOP + i]·v[g·HOP + i].
    let pieces = |k: &[f64], v: &[f64], out: &mut [f64]| {
        for (g, chunk) in v.chunks_exact(HOP).enumerate() {
            for q in 0..Q {
                out[g * Q + q] = dot(&k[q * HOP..(q + 1) * HOP], chunk);
            }
        }
    };
    // A window's integral from the pieces of its Q segments.
    let assemble = |part: &[f64], r: usize| -> f64 { (0..Q).map(|q| part[(r + q) * Q + q]).sum() };

    let mut a = Mat::<f64>::zeros(rows, p);
    // Library, blockwise: BLOCK samples = whole segments, about 0.5 MB of 17 columns. The
    // blocks are independent (each gives the pieces of its own segments), so they are
    // evaluated in parallel, each into a buffer of its thread.
    const BLOCK_SEGS: usize = 200;
    let mut part = vec![0.0; segs * Q];
    let mut col_parts: Vec<Vec<f64>> = vec![vec![0.0; segs * Q]; p];
    {
        use rayon::prelude::*;
        // Per block, its pieces column after column: block_parts[b][j·len + i].
        let blocks: Vec<Vec<f64>> = (0..segs.div_ceil(BLOCK_SEGS))
            .into_par_iter()
            .map_init(
                || Mat::<f64>::zeros(BLOCK_SEGS * HOP, p),
                |buf, b| {
                    let g0 = b * BLOCK_SEGS;
                    let g1 = (g0 + BLOCK_SEGS).min(segs);
                    let (start, end) = (g0 * HOP, g1 * HOP);
                    lib.matrix_into(&s.slice(start, end), buf);
                    let len = (g1 - g0) * Q;
                    let mut out = vec![0.0; p * len];
                    for (j, o) in out.chunks_exact_mut(len).enumerate() {
                        pieces(k0, &buf.col_as_slice(j)[..end - start], o);
                    }
                    out
                },
            )
            .collect();
        for (b, out) in blocks.iter().enumerate() {
            let g0 = b * BLOCK_SEGS;
            let len = out.len() / p.max(1);
            for (cp, o) in col_parts.iter_mut().zip(out.chunks_exact(len.max(1))) {
                cp[g0 * Q..g0 * Q + len].copy_from_slice(o);
            }
        }
    }
    for (j, cp) in col_parts.iter().enumerate() {
        for r in 0..rows {
            a[(r, j)] = assemble(cp, r);
        }
    }
    let mut y = Mat::<f64>::zeros(rows, 3);
    let end = segs * HOP;
    pieces(k2, &s.x[..end], &mut part);
    for r in 0..rows {
        y[(r, ACCEL)] = assemble(&part, r);
    }
    pieces(k1, &s.z[..end], &mut part);
    for r in 0..rows {
        y[(r, ZDOT)] = -assemble(&part, r);
    }
    pieces(k0, &s.u[..end], &mut part);
    for r in 0..rows {
        y[(r, IDOT)] = assemble(&part, r);
    }
    let mut d = Mat::<f64>::zeros(rows, 1);
    if let Some(i) = s.i {
        pieces(k1, &i[..end], &mut part);
        for r in 0..rows {
            d[(r, 0)] = -assemble(&part, r);
        }
    }
    (a, y, d)
}

/// `Σ a_i·b_i` with four independent partial sums (a strict left-to-right sum is one long
/// dependency chain the compiler may not reorder; four lanes let it vectorise).
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut acc = [0.0; 4];
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let rest: f64 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(x, y)| x * y)
        .sum();
    for (x, y) in ca.zip(cb) {
        for ((s, p), q) in acc.iter_mut().zip(x).zip(y) {
            *s += p * q;
        }
    }
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + rest
}

/// [`weak_rows`] window by window (any sampling).
pub fn weak_rows_generic(lib: &Library, t: &[f64], s: &Signals) -> (Mat<f64>, Mat<f64>, Mat<f64>) {
    let wins = weak_form::windows(t, weak_form::WINDOW, weak_form::HOP);
    let p = lib.len();
    // The library is evaluated window by window into a small reused buffer (never the
    // whole N × p matrix: at 10^6 samples that allocation alone costs more than the fit).
    let mut a = Mat::<f64>::zeros(wins.len(), p);
    let mut buf = Mat::<f64>::zeros(weak_form::WINDOW, p);
    for (r, w) in wins.iter().enumerate() {
        if buf.nrows() < w.end - w.start {
            buf = Mat::<f64>::zeros(w.end - w.start, p);
        }
        lib.matrix_into(&s.slice(w.start, w.end), &mut buf);
        for j in 0..p {
            let col = &buf.col_as_slice(j)[..w.end - w.start];
            a[(r, j)] = w.w0.iter().zip(col).map(|(q, v)| q * v).sum();
        }
    }
    let y = Mat::<f64>::from_fn(wins.len(), 3, |r, e| match e {
        ACCEL => wins[r].int_dd(s.x),
        ZDOT => -wins[r].int_d(s.z),
        _ => wins[r].int(s.u),
    });
    let d = Mat::<f64>::from_fn(wins.len(), 1, |r, _| s.i.map_or(0.0, |i| -wins[r].int_d(i)));
    (a, y, d)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::emulator::{simulate_signal, EmulatorConfig, SignalKind};
    use crate::ident::sindyc::{centred_velocity, velocity_half, DEFAULT_A};

    #[test]
    fn uniform_weak_rows_equal_the_window_by_window_rows() {
        let cfg = EmulatorConfig {
            seed: 3,
            ..EmulatorConfig::paper()
        };
        let a = simulate_signal(&cfg, SignalKind::A, 20.0).unwrap().log;
        let v = centred_velocity(&a.t, &a.theta, velocity_half(&a));
        let z: Vec<f64> = v.iter().map(|w| (0.3 * w).sin()).collect();
        let lib = Library::paper(Plant::Voltage, DEFAULT_A, 1.0);
        // 17 extra samples: the last partial hop is not part of any window.
        let n = 1000 + 17;
        let s = Signals {
            x: &a.theta[..n],
            xdot: &v[..n],
            z: &z[..n],
            i: a.i.as_deref().map(|i| &i[..n]),
            u: &a.u[..n],
        };
        assert!(is_uniform(&a.t[..n]));
        let fast = weak_rows_uniform(&lib, &a.t[..n], &s);
        let slow = weak_rows_generic(&lib, &a.t[..n], &s);
        for (f, g) in [(&fast.0, &slow.0), (&fast.1, &slow.1), (&fast.2, &slow.2)] {
            assert_eq!((f.nrows(), f.ncols()), (g.nrows(), g.ncols()));
            for j in 0..g.ncols() {
                let scale = (0..g.nrows())
                    .map(|r| g[(r, j)].abs())
                    .fold(1e-300, f64::max);
                // 1e-10 of the column's scale: the same sums in another order (rounding).
                for r in 0..g.nrows() {
                    assert!(
                        (f[(r, j)] - g[(r, j)]).abs() <= 1e-10 * scale,
                        "row {r} column {j}: {} vs {}",
                        f[(r, j)],
                        g[(r, j)]
                    );
                }
            }
        }
        // A non-uniform time axis takes the generic path.
        let mut t = a.t[..n].to_vec();
        t[500] += 0.003;
        assert!(!is_uniform(&t));
    }

    #[test]
    fn the_weak_rows_of_an_exact_law_recover_its_coefficients() {
        // ẍ = −4·ẋ + 3·u exactly: x = sin(3t) + 0.5·sin(7t), u chosen to make it so.
        let dt = 0.01;
        let n = 4000;
        let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
        let x: Vec<f64> = t
            .iter()
            .map(|t| (3.0 * t).sin() + 0.5 * (7.0 * t).sin())
            .collect();
        let v: Vec<f64> = t
            .iter()
            .map(|t| 3.0 * (3.0 * t).cos() + 3.5 * (7.0 * t).cos())
            .collect();
        let u: Vec<f64> = t
            .iter()
            .zip(&v)
            .map(|(t, v)| (-9.0 * (3.0 * t).sin() - 24.5 * (7.0 * t).sin() + 4.0 * v) / 3.0)
            .collect();
        let z = vec![0.0; n];
        let lib = Library::paper(Plant::Torque, DEFAULT_A, 1.0);
        let s = Signals {
            x: &x,
            xdot: &v,
            z: &z,
            i: None,
            u: &u,
        };
        let (a, y, _) = weak_rows(&lib, &t, &s);
        let ne = NormalEquations::new(a.as_ref(), y.as_ref().subcols(ACCEL, 1));
        let terms = lib.terms();
        let sup: Vec<bool> = terms
            .iter()
            .map(|t| matches!(t, control::sindy::Term::Xdot | control::sindy::Term::U))
            .collect();
        let c = ne.solve(0, &sup);
        let at = |term| c[terms.iter().position(|t| *t == term).unwrap()];
        // The weak form's difference weights are exact for constants and ramps and carry a
        // relative error of (ω·dt)²/12 = 4.1e-4 at the 7 rad/s component.
        let tol = 1.5 * (7.0 * dt).powi(2) / 12.0; // that error, and half again as margin
        assert!(
            (at(control::sindy::Term::Xdot) + 4.0).abs() < 4.0 * tol,
            "{c:?}"
        );
        assert!(
            (at(control::sindy::Term::U) - 3.0).abs() < 3.0 * tol,
            "{c:?}"
        );
    }
}
