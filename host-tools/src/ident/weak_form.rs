//! Weak-form (integral) regression features.
//!
//! Derivatives of Hall-quantised angles are noise, so the motor equations are never fitted on
//! finite differences. Instead each equation is multiplied by a smooth test function φ with
//! compact support on a window and integrated; integration by parts moves every derivative
//! onto φ: `∫φ·ω̇ dt = ∫φ''·θ dt`, `∫φ·ω dt = −∫φ'·θ dt`, `∫φ·İ dt = −∫φ'·I dt`. One window
//! gives one regression row whose columns are integrals of measured signals only.
//!
//! φ(s) = s⁴(1 − s)⁴ on s ∈ [0, 1] (smooth enough that φ, φ' vanish at both ends).
use crate::log::MotorLog;

/// Window length [s] of the grey-box regressions ([`log_windows`]): several Hall steps at
/// moderate speed, short against the 1 Hz upper frequency of the paper's signals.
pub const WINDOW_S: f64 = 0.48;
/// Window length [samples] at the paper's 12 ms ([`WINDOW_S`]): the SINDYc rows, whose
/// fast path builds its windows in fixed-size blocks.
pub const WINDOW: usize = 40;
/// Hop between windows [samples] (half overlap).
pub const HOP: usize = 20;
/// Fewest samples in a window: φ'' of the bump needs a few points to integrate.
const MIN_WINDOW: usize = 8;

/// Half-width [s] of [`smooth_velocity_of`]: ±5 samples at the paper's 12 ms, about one Hall
/// step at 1.6 rad/s.
pub const VELOCITY_HALF_S: f64 = 0.06;

/// The windows of [`WINDOW_S`] (half overlap) covering a log, in samples at its own period.
pub fn log_windows(log: &MotorLog) -> Vec<Window> {
    let n = log.len();
    let len = crate::scales::samples_for(WINDOW_S, log.sample_period(), n)
        .max(MIN_WINDOW)
        .min(n);
    windows(&log.t, len, (len / 2).max(1))
}

/// [`smooth_velocity`] over ±[`VELOCITY_HALF_S`] at the log's own period.
pub fn smooth_velocity_of(log: &MotorLog) -> Vec<f64> {
    let half = crate::scales::samples_for(VELOCITY_HALF_S, log.sample_period(), log.len());
    smooth_velocity(log, half)
}

/// φ, φ', φ'' (derivatives with respect to s) at s.
fn phi(s: f64) -> (f64, f64, f64) {
    let a = s;
    let b = 1.0 - s;
    let p = a.powi(4) * b.powi(4);
    let dp = 4.0 * a.powi(3) * b.powi(4) - 4.0 * a.powi(4) * b.powi(3);
    let ddp =
        12.0 * a.powi(2) * b.powi(4) - 32.0 * a.powi(3) * b.powi(3) + 12.0 * a.powi(4) * b.powi(2);
    (p, dp, ddp)
}

/// One window: sample range and the test function's values in time units.
#[derive(Debug, Clone)]
pub struct Window {
    pub start: usize,
    pub end: usize,
    /// φ(t_k), φ'(t_k), φ''(t_k) for k in start..end (derivatives in 1/s, 1/s²).
    pub phi: Vec<f64>,
    pub dphi: Vec<f64>,
    pub ddphi: Vec<f64>,
    /// Trapezoid weights ∫ g dt ≈ Σ w_k g_k.
    pub w: Vec<f64>,
}

impl Window {
    /// `∫ φ·g dt` over the window (g sampled).
    pub fn int(&self, g: &[f64]) -> f64 {
        self.sum(&self.phi, g)
    }

    /// `∫ φ'·g dt`.
    pub fn int_d(&self, g: &[f64]) -> f64 {
        self.sum(&self.dphi, g)
    }

    /// `∫ φ''·g dt`.
    pub fn int_dd(&self, g: &[f64]) -> f64 {
        self.sum(&self.ddphi, g)
    }

    /// `∫ φ·u dt` for an input held constant between samples (zero-order hold).
    pub fn int_zoh(&self, t: &[f64], u: &[f64]) -> f64 {
        let mut s = 0.0;
        for k in self.start..self.end - 1 {
            let j = k - self.start;
            s += u[k] * 0.5 * (self.phi[j] + self.phi[j + 1]) * (t[k + 1] - t[k]);
        }
        s
    }

    /// `∫φ·I dt` for a winding current `i` sampled at the sample times while the voltage `u`
    /// is held over `[t_k, t_k+1)` (zero-order hold), for a winding of resistance `r` and
    /// inductance `l`.
    ///
    /// The current reaches its new quasi-static value within `τ = L/R` (1.4 ms for the paper's
    /// motor) of each voltage step, so over an interval it is nearly flat at the value sampled
    /// at its *end*; the trapezoid rule instead ramps it from the old value. Adding each
    /// step's share `φ(t_k)·(Δt/2 − τ)·(u_k − u_k−1)/R` makes the integral exact for that
    /// first-order response. Measured on the emulator (`examples/weakform_truth.rs`, signal
    /// a, windows where the rotor moves): the plain trapezoid of the true current misses
    /// `K_t·∫φI` by 0.0100 N·m rms; with the correction, 0.0006 N·m.
    pub fn int_current(&self, t: &[f64], i: &[f64], u: &[f64], r: f64, l: f64) -> f64 {
        let mut s = self.int(i);
        if !(r > 0.0 && l >= 0.0) {
            return s;
        }
        let tau = l / r;
        for k in self.start.max(1)..self.end - 1 {
            let j = k - self.start;
            let half = 0.5 * (t[k + 1] - t[k]);
            s += self.phi[j] * (half - tau) * (u[k] - u[k - 1]) / r;
        }
        s
    }

    fn sum(&self, f: &[f64], g: &[f64]) -> f64 {
        f.iter()
            .zip(&self.w)
            .zip(&g[self.start..self.end])
            .map(|((a, b), c)| a * b * c)
            .sum()
    }
}

/// The windows covering a log.
pub fn windows(t: &[f64], len: usize, hop: usize) -> Vec<Window> {
    let n = t.len();
    let mut out = Vec::new();
    let mut start = 0;
    while start + len <= n {
        let end = start + len;
        let t0 = t[start];
        let span = t[end - 1] - t0;
        let mut ph = Vec::with_capacity(len);
        let mut dph = Vec::with_capacity(len);
        let mut ddph = Vec::with_capacity(len);
        let mut w = Vec::with_capacity(len);
        for k in start..end {
            let (p, dp, ddp) = phi((t[k] - t0) / span);
            ph.push(p);
            dph.push(dp / span);
            ddph.push(ddp / (span * span));
            let left = if k > start { t[k] - t[k - 1] } else { 0.0 };
            let right = if k + 1 < end { t[k + 1] - t[k] } else { 0.0 };
            w.push(0.5 * (left + right));
        }
        out.push(Window {
            start,
            end,
            phi: ph,
            dphi: dph,
            ddphi: ddph,
            w,
        });
        start += hop;
    }
    out
}

/// A smooth velocity estimate for evaluating nonlinear regressors (sign of ω, |ω|): the
/// central slope of θ over ±`half` samples. Not used as a regression target.
pub fn smooth_velocity(log: &MotorLog, half: usize) -> Vec<f64> {
    let n = log.len();
    (0..n)
        .map(|k| {
            let a = k.saturating_sub(half);
            let b = (k + half).min(n - 1);
            if b > a {
                (log.theta[b] - log.theta[a]) / (log.t[b] - log.t[a])
            } else {
                0.0
            }
        })
        .collect()
}

/// Ordinary least squares `min ‖A·x − y‖` via faer's thin SVD (pseudo-inverse, rank
/// tolerance 1e-10 relative). Columns are scaled to unit norm first. Returns the solution and
/// the standard errors σ²·(AᵀA)⁻¹ of each coefficient (None when rank deficient).
pub fn least_squares(a: &[Vec<f64>], y: &[f64]) -> (Vec<f64>, Vec<Option<f64>>) {
    let m = y.len();
    let n = a.len();
    if n == 0 || m == 0 {
        return (vec![0.0; n], vec![None; n]);
    }
    let scale: Vec<f64> = a
        .iter()
        .map(|c| {
            let s = c.iter().map(|v| v * v).sum::<f64>().sqrt();
            if s > 0.0 {
                s
            } else {
                1.0
            }
        })
        .collect();
    let am = faer::Mat::<f64>::from_fn(m, n, |i, j| a[j][i] / scale[j]);
    let Ok(svd) = am.thin_svd() else {
        return (vec![0.0; n], vec![None; n]);
    };
    let s = svd.S().column_vector();
    let smax = (0..n).map(|i| s[i]).fold(0.0, f64::max);
    let u = svd.U();
    let v = svd.V();
    let mut x = vec![0.0; n];
    let mut var = vec![0.0; n];
    let mut deficient = false;
    for k in 0..n {
        let sk = s[k];
        if sk <= 1e-10 * smax {
            deficient = true;
            continue;
        }
        let uy: f64 = (0..m).map(|i| u[(i, k)] * y[i]).sum();
        for j in 0..n {
            x[j] += v[(j, k)] * uy / sk;
            var[j] += (v[(j, k)] / sk).powi(2);
        }
    }
    let resid: f64 = (0..m)
        .map(|i| {
            let p: f64 = (0..n).map(|j| am[(i, j)] * x[j]).sum();
            (y[i] - p).powi(2)
        })
        .sum();
    let dof = (m as f64 - n as f64).max(1.0);
    let s2 = resid / dof;
    let x: Vec<f64> = x.iter().zip(&scale).map(|(v, s)| v / s).collect();
    let se = var
        .iter()
        .zip(&scale)
        .map(|(v, s)| (!deficient).then(|| (s2 * v).sqrt() / s))
        .collect();
    (x, se)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integration_by_parts_holds() {
        // θ = sin(t): ∫φ''θ = ∫φ·θ'' = −∫φ·sin.
        let t: Vec<f64> = (0..2000).map(|k| k as f64 * 0.001).collect();
        let th: Vec<f64> = t.iter().map(|t| t.sin()).collect();
        let w = &windows(&t, 1000, 500)[1];
        let lhs = w.int_dd(&th);
        let rhs = -w.int(&th);
        assert!(
            (lhs - rhs).abs() < 1e-6 * rhs.abs().max(1e-3),
            "{lhs} {rhs}"
        );
        let cos: Vec<f64> = t.iter().map(|t| t.cos()).collect();
        assert!((w.int(&cos) + w.int_d(&th)).abs() < 1e-7);
    }

    #[test]
    fn least_squares_recovers_coefficients() {
        let x1: Vec<f64> = (0..50).map(|k| k as f64).collect();
        let x2: Vec<f64> = (0..50).map(|k| ((k * 7) % 11) as f64 * 1e-3).collect();
        let y: Vec<f64> = x1
            .iter()
            .zip(&x2)
            .map(|(a, b)| 2.0 * a - 300.0 * b)
            .collect();
        let (c, se) = least_squares(&[x1, x2], &y);
        assert!(
            (c[0] - 2.0).abs() < 1e-9 && (c[1] + 300.0).abs() < 1e-6,
            "{c:?}"
        );
        assert!(se[0].unwrap() < 1e-6);
    }

    /// A winding current sampled under a held voltage (steps settle within L/R ≪ Δt):
    /// `int_current` matches the exact `∫φ·I`, the plain trapezoid does not.
    #[test]
    fn int_current_integrates_a_settling_winding_current() {
        let (r, l, dt) = (0.216, 0.3e-3, 0.012);
        let tau = l / r;
        let n = 120;
        let u: Vec<f64> = (0..n).map(|k| 4.0 * ((k * 37 % 11) as f64 - 5.0)).collect();
        let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
        // Sampled current: I(t_k) with u[k−1] held before t_k, from rest.
        let mut i = vec![0.0; n];
        for k in 1..n {
            let ss = u[k - 1] / r;
            i[k] = ss + (i[k - 1] - ss) * (-dt / tau).exp();
        }
        let w = &windows(&t, WINDOW, HOP)[2];
        // Exact ∫φ·I by a fine sum over each interval's exponential response.
        let span = t[w.end - 1] - t[w.start];
        let fine = 2000;
        let mut exact = 0.0;
        for k in w.start..w.end - 1 {
            let ss = u[k] / r;
            for m in 0..fine {
                let tt = (m as f64 + 0.5) * dt / fine as f64;
                let cur = ss + (i[k] - ss) * (-tt / tau).exp();
                exact += phi((t[k] + tt - t[w.start]) / span).0 * cur * dt / fine as f64;
            }
        }
        let trapezoid = w.int(&i);
        let corrected = w.int_current(&t, &i, &u, r, l);
        let scale = w.int(&i.iter().map(|c| c.abs()).collect::<Vec<_>>());
        assert!(
            (corrected - exact).abs() < 1e-3 * scale,
            "corrected {corrected} exact {exact}"
        );
        assert!(
            (trapezoid - exact).abs() > 10.0 * (corrected - exact).abs(),
            "trapezoid {trapezoid} corrected {corrected} exact {exact}"
        );
    }
}
