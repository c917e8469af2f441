//! A load behind a coupling: a second inertia `j2` [kg·m²] that the rotor drives through a
//! spring-damper (`compliance`) or across a gap (`backlash`), and its implicit step.
//!
//! ```text
//! j2·dω2/dt = τ_c(x, v),   dθ2/dt = ω2,   x = θ1 − θ2,   v = ω1 − ω2
//! spring: τ_c = k·x + c·v
//! gap:    τ_c = max(0, k_c·(x − g/2) + c_c·v)   for x >  g/2
//!         τ_c = min(0, k_c·(x + g/2) + c_c·v)   for x < −g/2,   0 inside
//! ```
//!
//! The rotor feels `−τ_c`; angles are on the rotor's side of any gear. The gap's faces are a
//! stiff, critically damped contact that pushes and never pulls: `k_c = μ·(N/h)²`,
//! `c_c = 2·μ·N/h` with `N` = [`CONTACT_FREQUENCY_STEPS`] and `μ` the pair's reduced inertia
//! (`j2` itself when the rotor's motion is given, an infinitely heavy rotor), so the contact
//! rings at `N/h` rad/s and the backward Euler step below settles it in a step or two: an
//! inelastic impact, the momenta merged. Inside the gap the load coasts.
//!
//! # Step
//! Over a step `h` with the rotor's state at its end (θ1', ω1') given, backward Euler:
//! `j2·(ω2' − ω2)/h = τ_c(θ1' − θ2 − h·ω2', ω1' − ω2')`, `θ2' = θ2 + h·ω2'`. The coupling's
//! torque never rises with ω2' (it never falls with the deflection or its rate), so the
//! difference of the two sides increases with ω2' and its root is unique; and the torque is
//! piecewise linear, so the root is exact in closed form. When no torque acts at ω2' = ω2,
//! the root is ω2 (the load coasts). Otherwise it lies where the torque has the sign it has
//! there, on the linear law of the face that pushes (or the spring's), whose root is
//! `(j2·ω2/h + k·(θ1' − θ2 − e) + c·ω1') / (j2/h + k·h + c)` with `e` the face's offset
//! (`±g/2`; 0 for the spring), as long as that speed leaves the load beyond the face. The
//! damper's torque drops to zero as the load crosses the face, so the difference may jump
//! over zero there instead: then the step ends with the load at the face,
//! `ω2' = (θ1' − θ2 − e)/h`. The step is stable for any stiffness and never adds energy.
use num_traits::Float;

/// Frequency of a gap's contact times the step: the critically damped contact rings at
/// `CONTACT_FREQUENCY_STEPS / h` rad/s, settled by backward Euler in one or two steps.
pub const CONTACT_FREQUENCY_STEPS: f64 = 10.0;

/// Angle [rad] and speed [rad/s] of a load behind a coupling.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LoadState<F> {
    pub theta: F,
    pub omega: F,
}

/// How the load is coupled to the rotor, with the constants of one step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Coupling<F> {
    /// Spring `k` [N·m/rad] and damper `c` [N·m·s/rad].
    Spring { k: F, c: F },
    /// Free across `±half` [rad], then a contact `kc` [N·m/rad], `cc` [N·m·s/rad].
    Gap { half: F, kc: F, cc: F },
}

impl<F: Float> Coupling<F> {
    /// A gap of width `gap` [rad] whose contact is critically damped at
    /// [`CONTACT_FREQUENCY_STEPS`]`/h` on the reduced inertia `mu` [kg·m²].
    pub fn gap(gap: F, mu: F, h: F) -> Coupling<F> {
        let wc = F::from(CONTACT_FREQUENCY_STEPS).unwrap() / h;
        let two = F::one() + F::one();
        Coupling::Gap {
            half: gap / two,
            kc: mu * wc * wc,
            cc: two * mu * wc,
        }
    }

    /// Torque [N·m] the coupling passes to the load at deflection `x` = θ1 − θ2 [rad] and
    /// rate `v` = ω1 − ω2 [rad/s].
    pub fn torque(&self, x: F, v: F) -> F {
        match *self {
            Coupling::Spring { k, c } => k * x + c * v,
            Coupling::Gap { half, kc, cc } => {
                if x > half {
                    (kc * (x - half) + cc * v).max(F::zero())
                } else if x < -half {
                    (kc * (x + half) + cc * v).min(F::zero())
                } else {
                    F::zero()
                }
            }
        }
    }

    /// The load's state after a step `h` [s] from `s` when the rotor ends it at angle
    /// `theta1` [rad] and speed `omega1` [rad/s] (backward Euler, exact root; module doc).
    /// A load of no inertia (`j2 ≤ 0`) or a step `h ≤ 0` keeps its state.
    pub fn step(&self, j2: F, s: LoadState<F>, theta1: F, omega1: F, h: F) -> LoadState<F> {
        if !(j2 > F::zero() && h > F::zero()) {
            return s;
        }
        // `side`: the face the load presses on (+1 or −1), 0 on a spring without a gap. It
        // is kept apart from the face's offset, which is ±0 for a gap of zero width.
        let (k, c, offset, side) = match *self {
            Coupling::Spring { k, c } => (k, c, F::zero(), 0),
            Coupling::Gap { half, kc, cc } => {
                let at_rest = self.torque(theta1 - s.theta - h * s.omega, omega1 - s.omega);
                if at_rest == F::zero() {
                    return LoadState {
                        theta: s.theta + h * s.omega,
                        omega: s.omega,
                    };
                }
                if at_rest > F::zero() {
                    (kc, cc, half, 1)
                } else {
                    (kc, cc, -half, -1)
                }
            }
        };
        let mut omega = (j2 * s.omega / h + k * (theta1 - s.theta - offset) + c * omega1)
            / (j2 / h + k * h + c);
        // The face's law reaches inside the gap, where no torque acts: a root there is none,
        // and the residual changes sign where the load reaches the face.
        let x = theta1 - s.theta - h * omega;
        if (side > 0 && x < offset) || (side < 0 && x > offset) {
            omega = (theta1 - s.theta - offset) / h;
        }
        LoadState {
            theta: s.theta + h * omega,
            omega,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The step's speed is where the backward Euler equation's residual changes sign, on the
    /// spring, on both faces and inside the gap.
    #[test]
    fn the_step_solves_the_implicit_equation() {
        let h = 2e-4;
        let j2 = 6e-4;
        let couplings = [
            Coupling::Spring { k: 0.6, c: 0.002 },
            Coupling::gap(0.5, 2e-4, h),
            Coupling::gap(0.0, 2e-4, h),
        ];
        let mut seed = 7u64;
        let mut draw = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        for cpl in couplings {
            for _ in 0..2000 {
                let s = LoadState {
                    theta: draw(),
                    omega: 20.0 * draw(),
                };
                let (t1, w1) = (s.theta + 0.4 * draw(), 20.0 * draw());
                let n = cpl.step(j2, s, t1, w1, h);
                // The residual of the implicit equation changes sign at the step's speed.
                let r = |w: f64| j2 * (w - s.omega) / h - cpl.torque(t1 - s.theta - h * w, w1 - w);
                let eps = 1e-9 * (1.0 + n.omega.abs());
                assert!(
                    r(n.omega - eps) <= 0.0 && r(n.omega + eps) >= 0.0,
                    "{cpl:?} {s:?} {t1} {w1} {n:?}"
                );
            }
        }
    }

    /// Driven into a face at a steady speed, the load is caught and then moves with the
    /// rotor: an inelastic impact (an elastic one would send it off at twice the rotor's
    /// speed), of which at most 1 % of the impact speed comes back.
    #[test]
    fn a_caught_load_moves_with_the_rotor() {
        let h = 1e-3;
        let cpl = Coupling::gap(0.2, 1.0, h);
        let mut s = LoadState::default();
        for k in 1..=400 {
            let t = k as f64 * h;
            s = cpl.step(1.0, s, 2.0 * t, 2.0, h);
        }
        assert!((s.omega - 2.0).abs() < 0.02, "{s:?}");
        // Within the gap, at the face it was caught by or drifting off it at that 1 %.
        assert!(s.theta > 0.7 - 1e-4 && s.theta < 0.7 + 0.02 * 0.35, "{s:?}");
    }
}
