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
    half: usize,
    /// `φ`, `φ'`, `φ''` at offsets `−half..=half`, times `dt` (quadrature weights).
    w0: Vec<f64>,
    w1: Vec<f64>,
    w2: Vec<f64>,
}

impl WeakForm {
    /// Windows of half-width `half` samples over `n` samples of period `dt`, one every `stride`.
    pub fn new(n: usize, dt: f64, half: usize, stride: usize) -> WeakForm {
        let half = half.max(2);
        let big_t = half as f64 * dt;
        let mut w0 = Vec::with_capacity(2 * half + 1);
        let mut w1 = Vec::with_capacity(2 * half + 1);
        let mut w2 = Vec::with_capacity(2 * half + 1);
        for k in -(half as isize)..=(half as isize) {
            let s = k as f64 / half as f64;
            let q = 1.0 - s * s;
            w0.push(q.powi(4) * dt);
            w1.push(-8.0 * s * q.powi(3) / big_t * dt);
            w2.push((-8.0 * q.powi(3) + 48.0 * s * s * q.powi(2)) / (big_t * big_t) * dt);
        }
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
        // The weak second derivative carries a quadrature scale error (17 points for φ''),
        // the same on every row: a fitted inertia absorbs it. Check that it is a pure scale.
        let scale = c.iter().zip(&d).map(|(x, y)| x * y).sum::<f64>()
            / d.iter().map(|y| y * y).sum::<f64>();
        assert!((scale - 1.0).abs() < 0.3, "scale {scale}");
        for r in 0..wf.rows() {
            assert!(
                (a[r] - b[r]).abs() < 1e-4 * (1.0 + b[r].abs()),
                "{} {}",
                a[r],
                b[r]
            );
            let e = (c[r] - scale * d[r]).abs();
            assert!(e < 1e-3 * (1.0 + d[r].abs()), "{} {}", c[r], d[r]);
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
}
