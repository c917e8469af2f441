//! Butterworth low-pass filters as cascades of biquads (bilinear transform with pre-warping),
//! and zero-phase forward-backward filtering (`filtfilt`), as the EMPS IDIM-LS scripts use
//! them (4th order, 100 Hz at 1 kHz).
//!
//! Edges are handled like scipy's `filtfilt`: odd reflection at both ends (3·(order+1)
//! samples or three cut-off periods, whichever is longer) and each section started in its steady state for the first padded value.

/// One second-order section in transposed direct form II (a0 = 1).
#[derive(Debug, Clone, Copy)]
struct Biquad {
    b: [f64; 3],
    a: [f64; 2],
}

/// A Butterworth low-pass filter of even order.
#[derive(Debug, Clone)]
pub struct LowPass {
    sections: Vec<Biquad>,
    /// Samples of padding for `filtfilt`.
    pad: usize,
}

impl LowPass {
    /// Design an order-`order` (even, ≥ 2) low-pass with cut-off `fc` Hz at sample rate `fs` Hz.
    pub fn new(order: usize, fc: f64, fs: f64) -> LowPass {
        assert!(
            order >= 2 && order.is_multiple_of(2),
            "Butterworth order must be even"
        );
        assert!(fc > 0.0 && fc < fs / 2.0, "cut-off must lie below Nyquist");
        let k = (std::f64::consts::PI * fc / fs).tan();
        let sections = (0..order / 2)
            .map(|s| {
                // Pole pair s of the analog prototype: Q = 1 / (2 sin((2s+1)π / (2N))).
                let q = 1.0
                    / (2.0
                        * ((2 * s + 1) as f64 * std::f64::consts::PI / (2 * order) as f64).sin());
                let norm = 1.0 / (1.0 + k / q + k * k);
                let b0 = k * k * norm;
                Biquad {
                    b: [b0, 2.0 * b0, b0],
                    a: [2.0 * (k * k - 1.0) * norm, (1.0 - k / q + k * k) * norm],
                }
            })
            .collect();
        // scipy pads 3·(order+1) samples; a few periods of the cut-off more let the start
        // transient of a sloped signal die out before the data begin.
        let pad = (3 * (order + 1)).max((3.0 * fs / fc).ceil() as usize);
        LowPass { sections, pad }
    }

    /// Causal filtering, every section started at rest at the level of `x[0]` (steady state).
    pub fn filter(&self, x: &[f64]) -> Vec<f64> {
        let mut y = x.to_vec();
        for s in &self.sections {
            let x0 = y.first().copied().unwrap_or(0.0);
            // Steady state for a constant input x0 with unit DC gain: y = x0.
            let mut z1 = (1.0 - s.b[0]) * x0;
            let mut z2 = (s.b[2] - s.a[1]) * x0;
            for v in y.iter_mut() {
                let xin = *v;
                let out = s.b[0] * xin + z1;
                z1 = s.b[1] * xin - s.a[0] * out + z2;
                z2 = s.b[2] * xin - s.a[1] * out;
                *v = out;
            }
        }
        y
    }

    /// Zero-phase filtering: forward, then backward, with odd reflection padding.
    pub fn filtfilt(&self, x: &[f64]) -> Vec<f64> {
        let n = x.len();
        if n == 0 {
            return Vec::new();
        }
        let pad = self.pad.min(n - 1);
        let mut ext = Vec::with_capacity(n + 2 * pad);
        for k in (1..=pad).rev() {
            ext.push(2.0 * x[0] - x[k]);
        }
        ext.extend_from_slice(x);
        for k in 1..=pad {
            ext.push(2.0 * x[n - 1] - x[n - 1 - k]);
        }
        let mut y = self.filter(&ext);
        y.reverse();
        let mut y = self.filter(&y);
        y.reverse();
        y[pad..pad + n].to_vec()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gain(f: &LowPass, freq: f64, fs: f64) -> f64 {
        let n = 20_000;
        let x: Vec<f64> = (0..n)
            .map(|k| (2.0 * std::f64::consts::PI * freq * k as f64 / fs).sin())
            .collect();
        let y = f.filter(&x);
        let tail = &y[n / 2..];
        (2.0 * tail.iter().map(|v| v * v).sum::<f64>() / tail.len() as f64).sqrt()
    }

    #[test]
    fn butterworth_gain_is_minus_3db_at_cutoff_and_flat_below() {
        let f = LowPass::new(4, 100.0, 1000.0);
        assert!((gain(&f, 100.0, 1000.0) - std::f64::consts::FRAC_1_SQRT_2).abs() < 0.01);
        assert!((gain(&f, 10.0, 1000.0) - 1.0).abs() < 0.01);
        assert!(gain(&f, 300.0, 1000.0) < 0.02);
    }

    #[test]
    fn filtfilt_keeps_a_slow_ramp_without_lag() {
        let f = LowPass::new(4, 100.0, 1000.0);
        let x: Vec<f64> = (0..1000).map(|k| 0.5 + 0.01 * k as f64).collect();
        let y = f.filtfilt(&x);
        for (k, (a, b)) in x.iter().zip(&y).enumerate() {
            // Exact inside, small start-up error within the filter's memory of the ends.
            let tol = if (100..900).contains(&k) { 1e-9 } else { 1e-4 };
            assert!((a - b).abs() < tol, "sample {k}: {a} vs {b}");
        }
    }
}
