//! Friction compensation: the current and the voltage that cancel the estimated friction.
//!
//! The paper's eqs. 38-40: `I_c = F_f/K_t` and `V_c = L·dI_c/dt + R·I_c`. (The paper's eq. 40
//! prints `V_c = dI_c/dt + R·I_c`, dropping L; it is kept here.) `dI_c/dt` comes from a
//! first-order filtered derivative `s/(τ·s + 1)`: the backward difference of `I_c` low-passed
//! with time constant τ by an exact exponential update, which reproduces the continuous
//! filter's response to a ramp at every sample. The output is saturated to ±V_bus.
use num_traits::Float;
use serde::{Deserialize, Serialize};

use crate::pi::saturate;

/// Compensation parameters.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CompParams<F> {
    /// Torque constant K_t [N·m/A].
    pub kt: F,
    /// Winding resistance R [Ω].
    pub r: F,
    /// Winding inductance L [H].
    pub l: F,
    /// Time constant τ [s] of the derivative filter (0: plain backward difference).
    pub tau_d: F,
}

/// Output of one compensation step.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CompOutput<F> {
    /// Compensation current I_c [A].
    pub i_c: F,
    /// Filtered dI_c/dt [A/s].
    pub di_c: F,
    /// Compensation voltage V_c [V], saturated to ±V_bus.
    pub v_c: F,
}

/// Compensator state (the previous I_c and the filtered derivative).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Compensator<F> {
    pub params: CompParams<F>,
    prev_i: Option<F>,
    deriv: F,
    /// Cached filter gain `1 − exp(−dt/τ)` for `cached_dt` (dt is constant in practice, so
    /// the exponential is computed once).
    cached_dt: F,
    gain: F,
}

impl<F: Float> Compensator<F> {
    pub fn new(params: CompParams<F>) -> Self {
        Compensator {
            params,
            prev_i: None,
            deriv: F::zero(),
            cached_dt: F::zero(),
            gain: F::one(),
        }
    }

    pub fn reset(&mut self) {
        self.prev_i = None;
        self.deriv = F::zero();
    }

    /// One step: friction torque `f_f` [N·m], period `dt` [s], bus voltage `v_bus` [V].
    /// The first step (no previous I_c) takes dI_c/dt = 0. Non-finite friction counts as 0;
    /// K_t ≤ 0 or non-finite gives no compensation.
    pub fn step(&mut self, f_f: F, dt: F, v_bus: F) -> CompOutput<F> {
        let p = self.params;
        let i_c = if p.kt > F::zero() && p.kt.is_finite() && f_f.is_finite() {
            f_f / p.kt
        } else {
            F::zero()
        };
        let valid_dt = dt.is_finite() && dt > F::zero();
        if let (Some(prev), true) = (self.prev_i, valid_dt) {
            let raw = (i_c - prev) / dt;
            if dt != self.cached_dt {
                self.cached_dt = dt;
                self.gain = if p.tau_d > F::zero() {
                    F::one() - (-dt / p.tau_d).exp()
                } else {
                    F::one()
                };
            }
            self.deriv = self.deriv + self.gain * (raw - self.deriv);
        }
        self.prev_i = Some(i_c);
        if !self.deriv.is_finite() {
            self.deriv = F::zero();
        }
        let lim = if v_bus.is_finite() {
            v_bus.abs()
        } else {
            F::zero()
        };
        let v = p.l * self.deriv + p.r * i_c;
        let v_c = if v.is_finite() {
            saturate(v, -lim, lim)
        } else {
            F::zero()
        };
        CompOutput {
            i_c,
            di_c: self.deriv,
            v_c,
        }
    }
}

#[cfg(test)]
mod tests {
    // Tolerances within a few float ε of the values compared (1e-15 to 1e-9 in f64, 1e-6
    // in f32) are rounding of the same closed form computed another way; wider ones say
    // why beside them.
    use super::*;

    fn params(tau_d: f64) -> CompParams<f64> {
        CompParams {
            kt: 0.07,
            r: 0.2,
            l: 3e-4,
            tau_d,
        }
    }

    #[test]
    fn constant_friction_gives_resistive_voltage() {
        let mut c = Compensator::new(params(0.02));
        let mut out = CompOutput::default();
        for _ in 0..100 {
            out = c.step(0.0975, 0.012, 24.0);
        }
        assert!((out.i_c - 0.0975 / 0.07).abs() < 1e-12);
        assert!((out.v_c - 0.2 * 0.0975 / 0.07).abs() < 1e-12);
    }

    #[test]
    fn ramp_matches_continuous_filter() {
        // F_f = k·t → I_c = k·t/K_t; s/(τs+1) of a ramp of slope m is m·(1 − e^{−t/τ}).
        let (k, tau, dt) = (0.5, 0.03, 0.012);
        let mut c = Compensator::new(params(tau));
        let m = k / 0.07;
        c.step(0.0, dt, 24.0);
        for n in 1..50 {
            let t = n as f64 * dt;
            let out = c.step(k * t, dt, 24.0);
            let d = m * (1.0 - (-t / tau).exp());
            assert!(
                (out.di_c - d).abs() < 1e-9 * m,
                "n={n}: {} vs {d}",
                out.di_c
            );
            let v = 3e-4 * d + 0.2 * m * t;
            assert!((out.v_c - v).abs() < 1e-9);
        }
    }

    #[test]
    fn saturates_at_bus_voltage() {
        let mut c = Compensator::new(params(0.0));
        c.step(0.0, 0.012, 12.0);
        // A friction jump of 5 N·m in one step: L·dI/dt + R·I far above 12 V.
        let out = c.step(5.0, 0.012, 12.0);
        assert_eq!(out.v_c, 12.0);
        let out = c.step(-5.0, 0.012, 12.0);
        assert_eq!(out.v_c, -12.0);
        let out = c.step(f64::NAN, 0.012, 12.0);
        assert!(out.v_c.is_finite());
    }
}
