//! The weak form: derivatives of measured signals without differentiating them, once for
//! fitting and diagnosis.
//!
//! Multiplying an equation such as `J·θ̈ = K_t·I − F` by a smooth bump `φ(t)` that vanishes
//! with its derivatives at both ends of a window and integrating moves every derivative onto
//! the bump: `∫φ·θ̈ dt = ∫φ''·θ dt`, `∫φ·ω dt = −∫φ'·θ dt`. The Hall-quantised angle is then
//! only ever *averaged*, never differentiated. One regression row per window.
//!
//! The bump is `φ(s) = (1 − s²)⁴` on `s ∈ [−1, 1]`, mapped onto the window's first and last
//! sample times: its value and first two derivatives vanish at `s = ±1`.
//!
//! # Discrete integration by parts
//! The derivative weights are the bump's own differences, not its sampled analytic
//! derivatives. For any sequence φ that vanishes at the window's ends, with steps
//! `h_k = t_{k+1} − t_k` (uniform or not), summation by parts gives exactly
//! `Σφ_k·(x_{k+1} − x_{k−1})/2 = −Σx_k·(φ_{k+1} − φ_{k−1})/2` and
//! `Σφ_k·((x_{k+1} − x_k)/h_k − (x_k − x_{k−1})/h_{k−1}) = Σx_k·((φ_{k+1} − φ_k)/h_k − (φ_k − φ_{k−1})/h_{k−1})`,
//! so the weak derivatives annihilate constants (and the second one linear ramps) to the last
//! bit: the absolute angle never leaks into the torque equation. Their relative error on a
//! signal of frequency f is `(2π·f·h)²/12`. Sampled analytic derivatives do leak: on a 40-sample
//! window at 12 ms, `Σ w_k·φ''(t_k)` is −1.7·10⁻³ s⁻² of `∫φ dt` instead of 0, so an angle of
//! 1000 rad reads as a torque of `J·1.7 rad/s²` (docs/decisions/0003-exact-discrete-weights.md).
//!
//! # The interval form ([`WeakForm::held`])
//! A log knows the angle and the current at the sample instants and the input over each
//! interval `[t_j, t_{j+1})`. What it knows *exactly* is, per interval, the angle increment
//! `∫ω dt = θ_{j+1} − θ_j`, the current increment `∫İ dt` and the held input; and, for the
//! test function linear between the samples, the acceleration term
//! `∫φ_lin·ω̇ dt = Σφ_k·(θ_{k+1} − 2θ_k + θ_{k−1})/dt` (each second difference is the
//! acceleration integrated against a hat). An equation integrated over the intervals (the
//! torque balance under a held input) takes every other term against the test function that
//! is constant over each interval, `ψ_j = (φ_j + φ_{j+1})/2`: [`WeakForm::derivative`] is
//! `Σψ_j·Δx_j`, [`WeakForm::integral_zoh`] `Σψ_j·x_j·dt`, and a signal known only at the
//! samples is the trapezoid over each interval, `Σψ_j·(x_j + x_{j+1})/2·dt`. (An equation
//! that holds at the sample instants, the voltage balance with the current sampled at `t_k`,
//! keeps point weights `φ_k·dt`: [`WeakForm::new`].)
//!
//! Between ψ and φ_lin there is a first-order gap wherever the velocity does not follow a
//! straight line over an interval. Under a held voltage it does not: after each step the
//! velocity settles with the motor's own step response `y(s)` (normalised deficit, `y(0) = 1`,
//! two poles from `J·L·s² + (J·R + L·b)·s + R·b + K_t·K_b`), and for a rotor whose mechanical
//! time constant is about one sample the trapezoid misses a tenth of each step. Matching the
//! first moment of the step response closes the gap: with
//! `κ = Σ'_k y(k·dt) − ∫y ds/dt` (the trapezoid sum of the deficit, endpoint halved, minus its
//! integral, in samples; [`held_step_lag`]) the interval weights become
//! `ψ̂_j = ψ_j − κ·(φ_{j+1} − φ_j)`, and `Σψ̂_j·Δω_j = ∫φ_lin·ω̇` holds for every step that
//! the model's own dynamics answer (`κ = 0` for a torque input, whose velocity ramps linearly
//! over an interval).
//!
//! Two forms of the same operator: [`Window`]s over any time axis (the fits' regression rows)
//! and [`WeakForm`], the same weights as one kernel convolved over a uniformly sampled log
//! (what `diagnose` runs, many columns at a time).
use crate::log::MotorLog;

/// Half-width of a diagnosis window in samples: 8 × 12 ms ≈ 0.1 s, short against the
/// excitations (≤ 1 Hz) and long against the Hall quantisation (one step per 12 ms at 8 rad/s).
pub const HALF_WIDTH: usize = 8;
/// The same half-width in seconds (8 × 12 ms), used for logs at other sample rates.
pub const HALF_WIDTH_S: f64 = 0.096;

/// Length of a fitting window [s] ([`log_windows`]): several Hall steps at moderate speed,
/// short against the 1 Hz upper frequency of the paper's signals.
pub const WINDOW_S: f64 = 0.48;
/// Length of a fitting window [samples] at the paper's 12 ms ([`WINDOW_S`]): the SINDYc rows,
/// whose fast path builds its windows in fixed-size blocks.
pub const WINDOW: usize = 40;
/// Hop between fitting windows [samples] (half overlap).
pub const HOP: usize = 20;
/// Fewest samples in a fitting window: φ'' of the bump needs a few points to integrate.
const MIN_WINDOW: usize = 8;

/// The bump `(1 − s²)⁴` on `|s| < 1`, zero outside.
fn bump(s: f64) -> f64 {
    let q = 1.0 - s * s;
    if q > 0.0 {
        q.powi(4)
    } else {
        0.0
    }
}

/// Quadrature weights of one window over the sample times `t` (at least three):
/// `(w0, w1, w2, wz)` with `Σ w0·g ≈ ∫φ·g dt` (trapezoid), `Σ w1·g ≈ ∫φ'·g dt` and
/// `Σ w2·g ≈ ∫φ''·g dt` (the exact discrete differences of the module doc), and
/// `Σ wz_k·u_k ≈ ∫φ·u dt` for `u` held over `[t_k, t_{k+1})` (`len − 1` intervals, each
/// against the interval's mean of φ, `ψ_k = (φ_k + φ_{k+1})/2`, as [`WeakForm::integral_zoh`]).
fn kernel(t: &[f64]) -> [Vec<f64>; 4] {
    let n = t.len();
    let (t0, span) = (t[0], t[n - 1] - t[0]);
    let s_of = |tk: f64| 2.0 * (tk - t0) / span - 1.0;
    let phi: Vec<f64> = t.iter().map(|&tk| bump(s_of(tk))).collect();
    let at = |k: isize| -> f64 {
        if k < 0 || k as usize >= n {
            0.0
        } else {
            phi[k as usize]
        }
    };
    let h = |k: isize| -> f64 {
        // Step after sample k; outside the window φ is zero on both sides, any step will do.
        let k = k.clamp(0, n as isize - 2) as usize;
        t[k + 1] - t[k]
    };
    let mut w = [vec![0.0; n], vec![0.0; n], vec![0.0; n], vec![0.0; n - 1]];
    for k in 0..n as isize {
        let j = k as usize;
        let left = if j > 0 { t[j] - t[j - 1] } else { 0.0 };
        let right = if j + 1 < n { t[j + 1] - t[j] } else { 0.0 };
        w[0][j] = phi[j] * 0.5 * (left + right);
        w[1][j] = 0.5 * (at(k + 1) - at(k - 1));
        w[2][j] = (at(k + 1) - at(k)) / h(k) - (at(k) - at(k - 1)) / h(k - 1);
    }
    for j in 0..n - 1 {
        w[3][j] = 0.5 * (phi[j] + phi[j + 1]) * (t[j + 1] - t[j]);
    }
    w
}

/// One window of the weak form over samples `start..end` of a log.
#[derive(Debug, Clone)]
pub struct Window {
    pub start: usize,
    pub end: usize,
    /// `∫φ·g dt` weights.
    pub w0: Vec<f64>,
    /// `∫φ'·g dt` weights.
    pub w1: Vec<f64>,
    /// `∫φ''·g dt` weights.
    pub w2: Vec<f64>,
    /// `∫φ·u dt` weights for an input held between samples (one per interval).
    pub wz: Vec<f64>,
}

impl Window {
    /// `∫ φ·g dt` over the window (g sampled).
    pub fn int(&self, g: &[f64]) -> f64 {
        dot(&self.w0, &g[self.start..self.end])
    }

    /// `∫ φ'·g dt` (so `−int_d(x)` is `∫φ·ẋ dt`).
    pub fn int_d(&self, g: &[f64]) -> f64 {
        dot(&self.w1, &g[self.start..self.end])
    }

    /// `∫ φ''·g dt` (so `int_dd(x)` is `∫φ·ẍ dt`).
    pub fn int_dd(&self, g: &[f64]) -> f64 {
        dot(&self.w2, &g[self.start..self.end])
    }

    /// `∫ φ·u dt` for an input held constant between samples (zero-order hold, as the board
    /// applies its voltage).
    pub fn int_zoh(&self, u: &[f64]) -> f64 {
        dot(&self.wz, &u[self.start..self.end - 1])
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// The windows of `len` samples (at least three), one every `hop`, covering a log sampled at
/// the times `t`.
pub fn windows(t: &[f64], len: usize, hop: usize) -> Vec<Window> {
    let len = len.max(3);
    let mut out = Vec::new();
    let mut start = 0;
    while start + len <= t.len() {
        let end = start + len;
        let [w0, w1, w2, wz] = kernel(&t[start..end]);
        out.push(Window {
            start,
            end,
            w0,
            w1,
            w2,
            wz,
        });
        start += hop.max(1);
    }
    out
}

/// The fitting windows of [`WINDOW_S`] (half overlap) covering a log, in samples at its own
/// period.
pub fn log_windows(log: &MotorLog) -> Vec<Window> {
    let n = log.len();
    let len = crate::scales::samples_for(WINDOW_S, log.sample_period(), n)
        .max(MIN_WINDOW)
        .min(n);
    windows(&log.t, len, (len / 2).max(1))
}

/// Weak-form operator on a uniformly sampled log.
#[derive(Debug, Clone)]
pub struct WeakForm {
    /// Sample index of each window centre.
    pub centres: Vec<usize>,
    /// Half-width of a window [samples].
    pub half: usize,
    /// Lag of the held-input step response [samples] the interval weights correct for.
    pub kappa: f64,
    /// Whether sampled signals are integrated as the trapezoid over each interval against
    /// ψ̂ ([`WeakForm::held`]) rather than at their sample instants against φ.
    held: bool,
    dt: f64,
    /// φ at offsets `−half..=half` (zero at both ends).
    phi: Vec<f64>,
    /// Weights at offsets `−half..=half`: sampled signals (trapezoid against ψ̂, times dt),
    /// first differences (`ψ̂_{k−1} − ψ̂_k`) and second differences (`φ_{k+1} − 2φ_k +
    /// φ_{k−1}`, over dt).
    w0: Vec<f64>,
    w1: Vec<f64>,
    w2: Vec<f64>,
    /// Interval weights `ψ̂_j·dt` for intervals `−half..half`.
    wz: Vec<f64>,
}

impl WeakForm {
    /// Windows of half-width `half` samples over `n` samples of period `dt`, one every `stride`,
    /// for an equation that holds at the sample instants (the voltage balance with the
    /// current sampled at `t_k`): sampled signals against φ at the samples, increments
    /// against ψ. Discrete integration by parts holds exactly, constants and ramps are
    /// annihilated (see the module doc). [`WeakForm::held`] gives the interval form.
    pub fn new(n: usize, dt: f64, half: usize, stride: usize) -> WeakForm {
        let half = half.max(2);
        let phi: Vec<f64> = (-(half as isize)..=(half as isize))
            .map(|k| bump(k as f64 / half as f64))
            .collect();
        let centres = if n > 2 * half {
            (half..n - half).step_by(stride.max(1)).collect()
        } else {
            Vec::new()
        };
        let mut wf = WeakForm {
            centres,
            half,
            kappa: 0.0,
            held: false,
            dt,
            phi,
            w0: vec![],
            w1: vec![],
            w2: vec![],
            wz: vec![],
        };
        wf.set_weights();
        wf
    }

    /// The same windows for an equation integrated over the held intervals: every sampled
    /// signal as the trapezoid over each interval, every interval against
    /// `ψ̂_j = ψ_j − κ·(φ_{j+1} − φ_j)`, for a velocity that settles after each input step
    /// with lag `kappa` ([`held_step_lag`]; 0 for a torque input).
    pub fn held(&self, kappa: f64) -> WeakForm {
        let mut wf = self.clone();
        wf.kappa = if kappa.is_finite() { kappa } else { 0.0 };
        wf.held = true;
        wf.set_weights();
        wf
    }

    fn set_weights(&mut self) {
        let h = self.half;
        let dt = self.dt;
        let phi = |k: isize| -> f64 {
            if k.unsigned_abs() > h {
                0.0
            } else {
                self.phi[(k + h as isize) as usize]
            }
        };
        // ψ̂ of interval j (offsets j..j+1), zero outside −h..h−1.
        let psi = |j: isize| -> f64 {
            if j < -(h as isize) || j >= h as isize {
                0.0
            } else {
                0.5 * (phi(j) + phi(j + 1)) - self.kappa * (phi(j + 1) - phi(j))
            }
        };
        let ks = -(h as isize)..=(h as isize);
        self.w0 = ks
            .clone()
            .map(|k| {
                if self.held {
                    0.5 * (psi(k - 1) + psi(k)) * dt
                } else {
                    phi(k) * dt
                }
            })
            .collect();
        self.w1 = ks.clone().map(|k| psi(k - 1) - psi(k)).collect();
        self.w2 = ks
            .map(|k| (phi(k + 1) - 2.0 * phi(k) + phi(k - 1)) / dt)
            .collect();
        self.wz = (-(h as isize)..(h as isize)).map(|j| psi(j) * dt).collect();
    }

    /// Number of rows (windows).
    pub fn rows(&self) -> usize {
        self.centres.len()
    }

    fn conv(&self, w: &[f64], x: &[f64]) -> Vec<f64> {
        self.centres
            .iter()
            .map(|&c| {
                let start = c - self.half;
                w.iter().zip(&x[start..]).map(|(a, b)| a * b).sum()
            })
            .collect()
    }

    /// `∫φ·x dt` per window for a signal known at the samples: `Σφ_k·x_k·dt`, or, in the
    /// interval form ([`WeakForm::held`]), the trapezoid over each interval against ψ̂.
    pub fn integral(&self, x: &[f64]) -> Vec<f64> {
        self.conv(&self.w0, x)
    }

    /// `∫ψ̂·x dt` for a signal held constant over each sample interval `[t_k, t_k+1)` (the
    /// board's voltage, or any per-interval quantity): `Σψ̂_j·x_j·dt`.
    pub fn integral_zoh(&self, x: &[f64]) -> Vec<f64> {
        self.conv(&self.wz, x)
    }

    /// `Σψ̂_j·(x_{j+1} − x_j)`: the weak first derivative `∫φ·ẋ dt`, exact for the angle
    /// (its increments are the velocity's integrals).
    pub fn derivative(&self, x: &[f64]) -> Vec<f64> {
        self.conv(&self.w1, x)
    }

    /// Variance of `a1·derivative(e) + a2·second_derivative(e)` per window for independent
    /// errors `e_k` of variance `var_k` (an angle's quantisation error through the terms of
    /// an equation that take the angle): `Σ_k (a1·w1_k + a2·w2_k)²·var_k`.
    pub fn angle_error_variance(&self, a1: f64, a2: f64, var: &[f64]) -> Vec<f64> {
        let w: Vec<f64> = self
            .w1
            .iter()
            .zip(&self.w2)
            .map(|(b, c)| (a1 * b + a2 * c).powi(2))
            .collect();
        self.conv(&w, var)
    }

    /// `Σφ_k·(x_{k+1} − 2x_k + x_{k−1})/dt = ∫φ_lin·ẍ dt` per window (the weak second
    /// derivative, exact for the angle against the test function linear between samples).
    pub fn second_derivative(&self, x: &[f64]) -> Vec<f64> {
        self.conv(&self.w2, x)
    }
}

/// Lag `κ` [samples] of a motor's velocity step response under a held voltage (module doc):
/// the normalised deficit `y(s)` (`y(0) = 1`, `ẏ(0) = 0`, the current being continuous) of
/// `a2·ÿ + a1·ẏ + a0·y = 0` with `a2 = J·L`, `a1 = J·R + L·b`, `a0 = R·b + K_t·K_b`, summed by
/// the trapezoid rule at the sample instants minus its integral `a1/a0`, over `dt`. `b` is the
/// viscous friction [N·m·s/rad]. Zero when the constants give no settling response.
pub fn held_step_lag(r: f64, l: f64, kt: f64, kb: f64, j: f64, b: f64, dt: f64) -> f64 {
    let (a2, a1, a0) = (j * l.max(0.0), j * r + l.max(0.0) * b, r * b + kt * kb);
    if !(a1 > 0.0 && a0 > 0.0 && dt > 0.0 && a2.is_finite()) {
        return 0.0;
    }
    // y(s) in closed form: one pole, two real poles or a damped oscillation.
    let y: Box<dyn Fn(f64) -> f64> = if a2 <= 1e-12 * a1 * a1 / a0 {
        let tau = a1 / a0;
        Box::new(move |s: f64| (-s / tau).exp())
    } else {
        let disc = a1 * a1 - 4.0 * a2 * a0;
        if disc > 0.0 {
            let q = disc.sqrt();
            let (t1, t2) = (2.0 * a2 / (a1 - q), 2.0 * a2 / (a1 + q));
            Box::new(move |s: f64| (t1 * (-s / t1).exp() - t2 * (-s / t2).exp()) / (t1 - t2))
        } else {
            let (al, be) = (a1 / (2.0 * a2), (-disc).sqrt() / (2.0 * a2));
            Box::new(move |s: f64| {
                if be > 0.0 {
                    (-al * s).exp() * ((be * s).cos() + al / be * (be * s).sin())
                } else {
                    (-al * s).exp() * (1.0 + al * s)
                }
            })
        }
    };
    // Sum until the slowest mode has decayed to 1e-12 (at most a million samples).
    let slow = (a1 / a0).max(2.0 * a2 / a1);
    let steps = ((28.0 * slow / dt).ceil() as usize).clamp(1, 1_000_000);
    let trapezoid = 0.5 + (1..=steps).map(|k| y(k as f64 * dt)).sum::<f64>();
    trapezoid - a1 / a0 / dt
}

#[cfg(test)]
mod tests {
    // Tolerances within a few float ε of the values compared (1e-15 to 1e-9 in f64, 1e-6
    // in f32) are rounding of the same closed form computed another way; wider ones say
    // why beside them.
    use super::*;

    /// A motor without inductance answers a held voltage with one exponential per interval:
    /// the interval form with the step response's lag holds to rounding on the exactly
    /// sampled angle, and without the lag it misses by the trapezoid's gap.
    #[test]
    fn held_form_is_exact_for_a_settling_velocity() {
        let (r, kt, j, b, dt) = (0.22, 0.0712, 3.1e-4, 1.5e-3, 0.012);
        let kb = kt;
        let tau = j / (kt * kb / r + b);
        let h = dt / tau;
        let kappa = held_step_lag(r, 0.0, kt, kb, j, b, dt);
        let closed = 1.0 / (1.0 - (-h).exp()) - 0.5 - 1.0 / h;
        assert!((kappa - closed).abs() < 1e-9, "κ {kappa} vs {closed}");
        // Voltage steps every 7 samples, both signs.
        let n = 400;
        let v: Vec<f64> = (0..n)
            .map(|k| [6.0, -3.0, 9.5, 1.0, -8.0][(k / 7) % 5])
            .collect();
        let mut theta = vec![0.0; n];
        let mut w = 0.0;
        for k in 0..n - 1 {
            let w_ss = (kt * v[k] / r) / (kt * kb / r + b);
            theta[k + 1] = theta[k] + w_ss * dt + (w - w_ss) * tau * (1.0 - (-h).exp());
            w = w_ss + (w - w_ss) * (-h).exp();
        }
        let base = WeakForm::new(n, dt, 8, 8);
        let mut worst = [0.0f64; 2];
        for (slot, lag) in [kappa, 0.0].into_iter().enumerate() {
            let wf = base.held(lag);
            let (zoh, d1, d2) = (
                wf.integral_zoh(&v),
                wf.derivative(&theta),
                wf.second_derivative(&theta),
            );
            for r_ in 0..wf.rows() {
                let res = zoh[r_] - (kb + r * b / kt) * d1[r_] - r * j / kt * d2[r_];
                worst[slot] = worst[slot].max(res.abs() / zoh[r_].abs().max(1e-3));
            }
        }
        assert!(worst[0] < 1e-9, "with the lag: {}", worst[0]);
        assert!(worst[1] > 1e-3, "without the lag: {}", worst[1]);
    }

    /// On a uniform axis a [`Window`] and the [`WeakForm`] row centred on it agree.
    #[test]
    fn windows_and_the_uniform_form_agree() {
        let dt = 0.012;
        let n = 100;
        let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
        let x: Vec<f64> = t.iter().map(|t| (2.0 * t).sin() + 0.3 * t).collect();
        let wf = WeakForm::new(n, dt, 8, 8);
        let w = &windows(&t, 17, 8)[0];
        assert_eq!(wf.centres[0], 8);
        for (a, b) in [
            (wf.integral(&x)[0], w.int(&x)),
            (wf.derivative(&x)[0], -w.int_d(&x)),
            (wf.second_derivative(&x)[0], w.int_dd(&x)),
            (wf.integral_zoh(&x)[0], w.int_zoh(&x)),
        ] {
            assert!((a - b).abs() < 1e-12 * (1.0 + b.abs()), "{a} {b}");
        }
    }

    /// Integration by parts holds on a smooth signal, and exactly for constants and ramps on
    /// a jittered (non-uniform) time axis.
    #[test]
    fn integration_by_parts_holds_on_any_time_axis() {
        // θ = sin(t): ∫φ''θ = ∫φ·θ'' = −∫φ·sin, ∫φ'θ = −∫φ·cos.
        let t: Vec<f64> = (0..2000).map(|k| k as f64 * 0.001).collect();
        let th: Vec<f64> = t.iter().map(|t| t.sin()).collect();
        let cos: Vec<f64> = t.iter().map(|t| t.cos()).collect();
        let w = &windows(&t, 1000, 500)[1];
        assert!((w.int_dd(&th) + w.int(&th)).abs() < 1e-6 * w.int(&th).abs());
        assert!((w.int(&cos) + w.int_d(&th)).abs() < 1e-6 * w.int(&cos).abs());
        let jitter: Vec<f64> = (0..200)
            .map(|k| k as f64 * 0.01 + 0.003 * ((k * 7919 % 13) as f64 / 13.0))
            .collect();
        for w in windows(&jitter, 40, 20) {
            let c = vec![1000.0; jitter.len()];
            let ramp: Vec<f64> = jitter.iter().map(|t| 500.0 + 3.0 * t).collect();
            assert!(w.int_d(&c).abs() < 1e-9 && w.int_dd(&c).abs() < 1e-7);
            assert!(w.int_dd(&ramp).abs() < 1e-7, "{}", w.int_dd(&ramp));
        }
    }

    #[test]
    fn weak_derivatives_match_analytic_ones() {
        let dt = 0.012;
        let n = 400;
        let x: Vec<f64> = (0..n).map(|k| (1.3 * k as f64 * dt).sin()).collect();
        let dx: Vec<f64> = (0..n).map(|k| 1.3 * (1.3 * k as f64 * dt).cos()).collect();
        let ddx: Vec<f64> = x.iter().map(|v| -1.69 * v).collect();
        let wf = WeakForm::new(n, dt, 8, 8);
        assert!(wf.rows() > 40);
        let a = wf.derivative(&x);
        let b = wf.integral(&dx);
        let c = wf.second_derivative(&x);
        let d = wf.integral(&ddx);
        for r in 0..wf.rows() {
            // 1e-3: the discrete weights' quadrature error on the sampled sine, of order
            // (ω·dt)² = 2.4e-4.
            assert!(
                (a[r] - b[r]).abs() < 1e-3 * (1.0 + b[r].abs()),
                "{} {}",
                a[r],
                b[r]
            );
            // No scale error: the weak second derivative matches ∫φ·ẍ to the differences'
            // (2π·f·dt)²/12 relative error.
            assert!(
                (c[r] - d[r]).abs() < 2e-3 * (0.01 + d[r].abs()),
                "{} {}",
                c[r],
                d[r]
            );
        }
    }

    /// The weak derivatives of a constant angle are exactly zero, and of a ramp exactly its
    /// slope times `∫φ`, whatever the angle's size: an absolute angle of hundreds of radians
    /// (a drifting log) must not leak into the torque equation.
    #[test]
    fn weak_derivatives_annihilate_offsets_and_ramps() {
        let dt = 0.012;
        let n = 200;
        let wf = WeakForm::new(n, dt, 8, 8);
        let ones = vec![1.0; n];
        let norm = wf.integral(&ones);
        for (offset, slope) in [(0.0, 0.0), (300.0, 0.0), (-512.25, 3.5), (1e4, -40.0)] {
            let x: Vec<f64> = (0..n).map(|k| offset + slope * k as f64 * dt).collect();
            let d1 = wf.derivative(&x);
            let d2 = wf.second_derivative(&x);
            for r in 0..wf.rows() {
                let tol = 1e-12 * (offset.abs() + slope.abs() * n as f64 * dt + 1.0);
                assert!(
                    (d1[r] - slope * norm[r]).abs() < tol,
                    "{} {}",
                    d1[r],
                    slope * norm[r]
                );
                assert!(
                    d2[r].abs() < tol / dt,
                    "second derivative {} of a ramp",
                    d2[r]
                );
            }
        }
    }

    /// No bias reaches `diagnose`: the torque-equation residual of the correct model (the
    /// emulator's own LuGre structure, refitted) has a mean within two standard errors of zero.
    #[test]
    fn diagnose_residual_of_a_correct_model_has_no_mean() {
        use crate::diagnose::candidates::Equation;
        use crate::diagnose::{diagnose, Options, Structure};
        use crate::emulator::{simulate_signal, EmulatorConfig, SignalKind};
        use crate::log::Plant;
        for seed in [1, 2, 3] {
            let mut cfg = EmulatorConfig::paper();
            cfg.seed = seed;
            let log = simulate_signal(&cfg, SignalKind::A, 60.0).unwrap().log;
            let d = diagnose(
                &log,
                &Structure::lugre_paper(Plant::Voltage),
                &Options::default(),
            );
            let e = d
                .equations
                .iter()
                .find(|e| e.equation == Equation::Mechanical)
                .expect("a torque equation");
            let n = e.base.len() as f64;
            let mean = e.base.iter().sum::<f64>() / n;
            let var = e.base.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / (n - 1.0);
            let se = (var / e.n_eff.max(2.0)).sqrt();
            // Two standard errors: a two-sided 5 % test per seed, on the residual's effective sample
            // size.
            assert!(
                mean.abs() < 2.0 * se,
                "seed {seed}: mean torque residual {mean:.3e} {} is {:.1} standard errors off",
                e.unit,
                mean / se
            );
        }
    }

    fn corr(a: &[f64], b: &[f64]) -> f64 {
        let n = a.len() as f64;
        let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
        let (mut ab, mut aa, mut bb) = (0.0, 0.0, 0.0);
        for (x, y) in a.iter().zip(b) {
            ab += (x - ma) * (y - mb);
            aa += (x - ma) * (x - ma);
            bb += (y - mb) * (y - mb);
        }
        ab / (aa * bb).sqrt().max(1e-300)
    }

    /// The torque equation of the emulator's own motor, in weak form on its emulated log
    /// (Hall angle, measured current, held voltage), with the TRUE constants and the steady
    /// LuGre curve at the smoothed velocity, on windows where the rotor moves: what is left
    /// must be small and carry no systematic part an effect could take for itself (no mean
    /// beyond its standard error, no following of the absolute angle).
    #[test]
    fn true_model_leaves_no_systematic_torque_residual() {
        use crate::emulator::{simulate_signal, EmulatorConfig, SignalKind};
        let cfg = EmulatorConfig::paper();
        let (m, lg) = (cfg.motor, cfg.lugre);
        let log = simulate_signal(&cfg, SignalKind::A, 60.0).unwrap().log;
        let dt = log.sample_period();
        let n = log.len();
        let i = log.i.clone().unwrap();
        let omega = crate::numerics::differentiation::smoothed_derivative(&log.theta, dt, 4);
        let wf = WeakForm::new(n, dt, HALF_WIDTH, HALF_WIDTH);
        let q = m.kt / m.r;
        let (u, w, di) = (
            wf.integral_zoh(&log.u),
            wf.derivative(&log.theta),
            wf.derivative(&i),
        );
        let acc = wf.second_derivative(&log.theta);
        let fric = wf.integral(
            &omega
                .iter()
                .map(|v| lg.steady_friction(*v))
                .collect::<Vec<_>>(),
        );
        let norm = wf.integral(&vec![1.0; n]);
        let sgn: Vec<f64> = omega.iter().map(|v| v.signum()).collect();
        let regs = [
            ("sgn(ω)", wf.integral(&sgn)),
            ("ω", wf.integral(&omega)),
            (
                "|K_t·I|·sgn(ω)",
                wf.integral(
                    &i.iter()
                        .zip(&sgn)
                        .map(|(c, s)| (m.kt * c).abs() * s)
                        .collect::<Vec<_>>(),
                ),
            ),
            ("θ", wf.integral(&log.theta)),
        ];
        let rows: Vec<usize> = (0..wf.rows())
            .filter(|&r| {
                let c = wf.centres[r];
                omega[c - HALF_WIDTH..=c + HALF_WIDTH]
                    .iter()
                    .all(|v| v.abs() >= 1.0)
            })
            .collect();
        assert!(rows.len() > 200, "only {} moving windows", rows.len());
        let res: Vec<f64> = rows
            .iter()
            .map(|&r| (q * (u[r] - m.kb * w[r] - m.l * di[r]) - m.j * acc[r] - fric[r]) / norm[r])
            .collect();
        let nr = res.len() as f64;
        let mean = res.iter().sum::<f64>() / nr;
        let rms = (res.iter().map(|v| v * v).sum::<f64>() / nr).sqrt();
        eprintln!(
            "torque residual of the true model: mean {mean:.5} rms {rms:.5} N·m over {} windows",
            res.len()
        );
        // Scale: the Coulomb friction α0 = 0.08 N·m. The rest (0.009 N·m rms) is noise, not
        // bias: Hall quantisation in the back-EMF and inertia terms (0.005 and 0.0026 N·m rms
        // on 0.19 s windows) and the Stribeck curve at a velocity known to ±0.8 rad/s
        // (0.007 N·m), measured term by term with `xtask/examples/weakform_truth.rs`.
        assert!(mean.abs() < 0.01 * lg.alpha0, "mean residual {mean} N·m");
        for (name, g) in &regs {
            let g: Vec<f64> = rows.iter().map(|&r| g[r] / norm[r]).collect();
            let c = corr(&res, &g);
            eprintln!("  corr with {name}: {c:+.3}");
            // 0.2: a parameter bias would leave the residual along its regressor (|corr| near 1);
            // noise of 0.009 N·m rms keeps chance correlations small.
            assert!(c.abs() < 0.2, "residual correlates with {name}: {c}");
        }
        assert!(rms < 0.15 * lg.alpha0, "rms residual {rms} N·m");
    }

    /// The variance of the weak derivatives of independent errors is what their spread over
    /// many draws shows.
    #[test]
    fn angle_error_variance_matches_the_spread_of_its_weights() {
        let (n, dt) = (200, 0.012);
        let wf = WeakForm::new(n, dt, 8, 8).held(0.1);
        let var: Vec<f64> = (0..n).map(|k| if k < 100 { 1e-3 } else { 4e-3 }).collect();
        let (a1, a2) = (-0.07, -1e-3);
        let predicted = wf.angle_error_variance(a1, a2, &var);
        let mut sum2 = vec![0.0; wf.rows()];
        let draws = 400;
        for d in 0..draws {
            let z = crate::numerics::statistics::white_noise(n, 1000 + d);
            let e: Vec<f64> = z.iter().zip(&var).map(|(z, v)| z * v.sqrt()).collect();
            let (d1, d2) = (wf.derivative(&e), wf.second_derivative(&e));
            for r in 0..wf.rows() {
                sum2[r] += (a1 * d1[r] + a2 * d2[r]).powi(2) / draws as f64;
            }
        }
        for r in 0..wf.rows() {
            let ratio = sum2[r] / predicted[r];
            assert!((0.8..1.25).contains(&ratio), "row {r}: {ratio}");
        }
    }
}
