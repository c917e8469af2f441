//! Weak-form (integrated) equations: derivatives of measured signals without differentiating
//! them.
//!
//! Multiplying an equation such as `J·θ̈ = K_t·I − F` by a smooth bump `φ(t − t_c)` that
//! vanishes with its derivatives at both ends and integrating moves every derivative onto the
//! bump: `∫φ·θ̈ dt = ∫φ''·θ dt`, `∫φ·ω dt = −∫φ'·θ dt`. The Hall-quantised angle is then only
//! ever *averaged*, never differentiated. One row per window centre; windows overlap by half.
//!
//! The bump is `φ(s) = (1 − s²)⁴` on `s ∈ [−1, 1]`, `s = (t − t_c)/T`: its value and first two
//! derivatives vanish at `s = ±1`, which is what the integrations by parts need.
//!
//! # Discrete integration by parts ([`WeakForm::new`])
//! The derivative weights are the bump's central differences, not its sampled analytic
//! derivatives: for a sequence φ that vanishes at the window's ends
//! `Σφ_k·(x_{k+1} − x_{k−1})/2 = −Σ x_k·(φ_{k+1} − φ_{k−1})/2` and
//! `Σφ_k·(x_{k+1} − 2x_k + x_{k−1}) = Σ x_k·(φ_{k+1} − 2φ_k + φ_{k−1})` hold exactly, so the
//! weak derivatives annihilate constants (and the second one linear ramps) to the last bit and
//! the absolute angle never leaks into the torque equation. Their relative error on a signal
//! of frequency f is `(2π·f·dt)²/12`. Why: docs/decisions/0003-exact-discrete-weights.md.

/// Default half-width of a window in samples: 8 × 12 ms ≈ 0.1 s, short against the
/// excitations (≤ 1 Hz) and long against the Hall quantisation (one step per 12 ms at 8 rad/s).
pub const HALF_WIDTH: usize = 8;
/// The same half-width in seconds (8 × 12 ms), used for logs at other sample rates.
pub const HALF_WIDTH_S: f64 = 0.096;

/// Weak-form operator on a uniformly sampled log.
#[derive(Debug, Clone)]
pub struct WeakForm {
    /// Sample index of each window centre.
    pub centres: Vec<usize>,
    /// Half-width of a window [samples].
    pub half: usize,
    /// `φ` and its central first and second differences (standing for `φ'`, `φ''`) at
    /// offsets `−half..=half`, times `dt` (quadrature weights).
    w0: Vec<f64>,
    w1: Vec<f64>,
    w2: Vec<f64>,
}

impl WeakForm {
    /// Windows of half-width `half` samples over `n` samples of period `dt`, one every `stride`,
    /// with the bump's central differences as derivative weights: discrete integration by
    /// parts holds exactly, constants and ramps are annihilated (see the module doc). What
    /// `diagnose` uses.
    pub fn new(n: usize, dt: f64, half: usize, stride: usize) -> WeakForm {
        let half = half.max(2);
        // φ at offsets −half−1 ..= half+1 (zero at and beyond ±half).
        let phi: Vec<f64> = (-(half as isize) - 1..=(half as isize) + 1)
            .map(|k| {
                let s = k as f64 / half as f64;
                let q = 1.0 - s * s;
                if q > 0.0 {
                    q.powi(4)
                } else {
                    0.0
                }
            })
            .collect();
        // Offset k of the window is phi[k + 1]; see the module doc for why differences.
        let w0: Vec<f64> = (1..=2 * half + 1).map(|j| phi[j] * dt).collect();
        let w1: Vec<f64> = (1..=2 * half + 1)
            .map(|j| (phi[j + 1] - phi[j - 1]) / (2.0 * dt) * dt)
            .collect();
        let w2: Vec<f64> = (1..=2 * half + 1)
            .map(|j| (phi[j + 1] - 2.0 * phi[j] + phi[j - 1]) / (dt * dt) * dt)
            .collect();
        let centres = if n > 2 * half {
            (half..n - half).step_by(stride.max(1)).collect()
        } else {
            Vec::new()
        };
        WeakForm {
            centres,
            half,
            w0,
            w1,
            w2,
        }
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

    /// `∫φ·x dt` per window.
    pub fn integral(&self, x: &[f64]) -> Vec<f64> {
        self.conv(&self.w0, x)
    }

    /// `∫φ·x dt` for a signal held constant over each sample interval `[t_k, t_k+1)`
    /// (zero-order hold, as the board applies its voltage): exact interval weights
    /// `∫φ` over each interval (Simpson's rule, exact for the bump's polynomial to 1e-6).
    pub fn integral_zoh(&self, x: &[f64]) -> Vec<f64> {
        let h = self.half as f64;
        let dt = self.w0[self.half] / 1.0; // φ(0)·dt = dt
        let phi = |s: f64| {
            let q = 1.0 - s * s;
            if q > 0.0 {
                q.powi(4)
            } else {
                0.0
            }
        };
        let w: Vec<f64> = (-(self.half as isize)..(self.half as isize))
            .map(|k| {
                let a = k as f64 / h;
                let b = (k + 1) as f64 / h;
                dt / 6.0 * (phi(a) + 4.0 * phi(0.5 * (a + b)) + phi(b))
            })
            .collect();
        self.centres
            .iter()
            .map(|&c| {
                let start = c - self.half;
                w.iter().zip(&x[start..]).map(|(a, b)| a * b).sum()
            })
            .collect()
    }

    /// `∫φ·ẋ dt = −∫φ'·x dt` per window (the weak first derivative).
    pub fn derivative(&self, x: &[f64]) -> Vec<f64> {
        self.conv(&self.w1, x).into_iter().map(|v| -v).collect()
    }

    /// `∫φ·ẍ dt = ∫φ''·x dt` per window (the weak second derivative).
    pub fn second_derivative(&self, x: &[f64]) -> Vec<f64> {
        self.conv(&self.w2, x)
    }
}

/// Least-squares slope over `±m` samples (Savitzky–Golay, first order): a smoothed derivative
/// of a quantised signal; the window shrinks at the ends.
pub fn smoothed_derivative(x: &[f64], dt: f64, m: usize) -> Vec<f64> {
    let n = x.len();
    (0..n)
        .map(|j| {
            let mm = m.min(j).min(n.saturating_sub(1) - j);
            if mm == 0 {
                return if n < 2 {
                    0.0
                } else if j == 0 {
                    (x[1] - x[0]) / dt
                } else {
                    (x[j] - x[j - 1]) / dt
                };
            }
            let mut num = 0.0;
            let mut den = 0.0;
            for k in 1..=mm {
                num += k as f64 * (x[j + k] - x[j - k]);
                den += 2.0 * (k * k) as f64;
            }
            num / (den * dt)
        })
        .collect()
}

/// Centred moving average over `±m` samples (shrinking at the ends).
pub fn moving_average(x: &[f64], m: usize) -> Vec<f64> {
    let n = x.len();
    (0..n)
        .map(|j| {
            let mm = m.min(j).min(n.saturating_sub(1) - j);
            x[j - mm..=j + mm].iter().sum::<f64>() / (2 * mm + 1) as f64
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

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
            assert!(
                mean.abs() < 2.0 * se,
                "seed {seed}: mean torque residual {mean:.3e} {} is {:.1} standard errors off",
                e.unit,
                mean / se
            );
        }
    }

    #[test]
    fn smoothed_derivative_of_a_ramp() {
        let x: Vec<f64> = (0..50).map(|k| 2.0 * k as f64 * 0.01).collect();
        for v in smoothed_derivative(&x, 0.01, 4) {
            assert!((v - 2.0).abs() < 1e-9);
        }
        let m = moving_average(&x, 2);
        assert!((m[10] - x[10]).abs() < 1e-12);
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
        let omega = smoothed_derivative(&log.theta, dt, 4);
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
        // (0.007 N·m), measured term by term with `examples/weakform_truth.rs`.
        assert!(mean.abs() < 0.01 * lg.alpha0, "mean residual {mean} N·m");
        for (name, g) in &regs {
            let g: Vec<f64> = rows.iter().map(|&r| g[r] / norm[r]).collect();
            let c = corr(&res, &g);
            eprintln!("  corr with {name}: {c:+.3}");
            assert!(c.abs() < 0.2, "residual correlates with {name}: {c}");
        }
        assert!(rms < 0.15 * lg.alpha0, "rms residual {rms} N·m");
    }
}
