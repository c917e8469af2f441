//! DC-equivalent motor constants, the paper's eqs. (1)-(2):
//! `J·dω/dt = K_t·I − F_f − T_load`, `L·dI/dt = −R·I − K_b·ω + V`.
use num_traits::Float;
use serde::{Deserialize, Serialize};

/// Electrical and mechanical constants of the motor, SI units.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MotorParams<F> {
    /// Winding resistance R [Ω].
    pub r: F,
    /// Winding inductance L [H].
    pub l: F,
    /// Torque constant K_t [N·m/A].
    pub kt: F,
    /// Back-EMF constant K_b [V·s/rad].
    pub kb: F,
    /// Rotor inertia J [kg·m²].
    pub j: F,
}

impl<F: Float> MotorParams<F> {
    /// The reference paper's Maxon BLDC motor (Table 1: 24 V, stall current 111 A,
    /// stall torque 7.91 N·m). R = 24 V / 111 A, K_t = 7.91 N·m / 111 A, K_b = K_t (SI).
    /// L and J are not in the paper: assumed from Maxon's EC 90 flat data sheet class
    /// (L ≈ 0.3 mH, J ≈ 3.0e-4 kg·m²).
    pub fn paper() -> Self {
        let c = |x: f64| F::from(x).unwrap();
        MotorParams {
            r: c(24.0 / 111.0),
            l: c(0.3e-3),
            kt: c(7.91 / 111.0),
            kb: c(7.91 / 111.0),
            j: c(3.0e-4),
        }
    }
}
