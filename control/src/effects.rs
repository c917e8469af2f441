//! The physical effects `motorid` names, as equations.
//!
//! One place defines what each effect *is*: the emulator adds them to the plant, the host
//! models add them when the user says `fit --add NAME`, and the firmware evaluates them for
//! compensation. Each effect acts at one [`Site`]: a torque on the rotor, a voltage loss in
//! the inverter, an offset in the current sensor, a change of the winding resistance, or a
//! hidden friction state (presliding, handled by [`crate::lugre`]).
//!
//! Sign conventions: a *torque* here is a load torque opposing motion, so the mechanics read
//! `J·dω/dt = K_t·I − F_f − Σ torque(effect)`. A *voltage loss* is subtracted from the
//! commanded voltage: `L·dI/dt = −R·I − K_b·ω + V − Σ voltage_loss(effect)`.
use num_traits::Float;
use serde::{Deserialize, Serialize};

/// Velocity scale [rad/s] of the smooth sign `tanh(ω/ε)` used for every Coulomb-like term,
/// so that the terms are continuous at standstill (below one Hall step per 12 ms sample,
/// 0.0952 rad / 0.012 s ≈ 8 rad/s, the data cannot resolve a sharper edge anyway).
pub const VELOCITY_EPS: f64 = 0.05;
/// Current scale [A] of the smooth sign of the current used by the dead-time term.
pub const CURRENT_EPS: f64 = 0.05;

/// Smooth sign: `tanh(x/eps)`.
pub fn smooth_sign<F: Float>(x: F, eps: F) -> F {
    (x / eps).tanh()
}

/// Where an effect acts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Site {
    /// A torque opposing the motion, in N·m.
    Torque,
    /// A voltage lost between the commanded and the applied voltage, in V.
    Voltage,
    /// An additive offset of the measured current, in A.
    Sensor,
    /// A relative change of the winding resistance (ΔR/R), driven by a heat state.
    Resistance,
    /// A hidden friction state (bristle deflection), see [`crate::lugre`].
    State,
}

/// The effect names, without parameters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EffectKind {
    Coulomb,
    Viscous,
    Stribeck,
    Presliding,
    Cogging,
    PositionLoad,
    Offset,
    Asymmetry,
    Deadtime,
    CurrentOffset,
    Thermal,
    LoadFriction,
    Saturation,
    Compliance,
}

impl EffectKind {
    /// Every effect, in the documented order.
    pub const ALL: [EffectKind; 14] = [
        EffectKind::Coulomb,
        EffectKind::Viscous,
        EffectKind::Stribeck,
        EffectKind::Presliding,
        EffectKind::Cogging,
        EffectKind::PositionLoad,
        EffectKind::Offset,
        EffectKind::Asymmetry,
        EffectKind::Deadtime,
        EffectKind::CurrentOffset,
        EffectKind::Thermal,
        EffectKind::LoadFriction,
        EffectKind::Saturation,
        EffectKind::Compliance,
    ];

    /// The effect's name on the command line (`position_load`, ...).
    pub fn name(self) -> &'static str {
        match self {
            EffectKind::Coulomb => "coulomb",
            EffectKind::Viscous => "viscous",
            EffectKind::Stribeck => "stribeck",
            EffectKind::Presliding => "presliding",
            EffectKind::Cogging => "cogging",
            EffectKind::PositionLoad => "position_load",
            EffectKind::Offset => "offset",
            EffectKind::Asymmetry => "asymmetry",
            EffectKind::Deadtime => "deadtime",
            EffectKind::CurrentOffset => "current_offset",
            EffectKind::Thermal => "thermal",
            EffectKind::LoadFriction => "load_friction",
            EffectKind::Saturation => "saturation",
            EffectKind::Compliance => "compliance",
        }
    }

    /// Parse an effect's name.
    pub fn from_name(name: &str) -> Option<EffectKind> {
        EffectKind::ALL.iter().copied().find(|k| k.name() == name)
    }

    /// Where the effect acts.
    pub fn site(self) -> Site {
        match self {
            EffectKind::Presliding | EffectKind::Compliance => Site::State,
            EffectKind::Deadtime => Site::Voltage,
            EffectKind::CurrentOffset => Site::Sensor,
            EffectKind::Thermal => Site::Resistance,
            _ => Site::Torque,
        }
    }
}

/// What an effect term may depend on at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EffectInputs<F> {
    /// Rotor angle θ [rad] (mechanical).
    pub theta: F,
    /// Rotor velocity ω [rad/s].
    pub omega: F,
    /// Winding current I [A] (true current, not the measured one).
    pub current: F,
    /// Torque constant K_t [N·m/A] (for load-dependent friction).
    pub kt: F,
}

/// One physical effect with its parameters (SI units).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum Effect<F> {
    /// Coulomb friction `fc·sgn(ω)` [N·m].
    Coulomb { fc: F },
    /// Viscous friction `b·ω`, b in N·m·s/rad.
    Viscous { b: F },
    /// Stribeck (breakaway) friction above Coulomb: `fs·exp(−(ω/vs)²)·sgn(ω)`,
    /// fs in N·m, vs in rad/s.
    Stribeck { fs: F, vs: F },
    /// Bristle deflection (the LuGre state): stiffness σ0 [N·m/rad] and damping σ1
    /// [N·m·s/rad]; evaluated by [`crate::lugre`], its torque here is zero.
    Presliding { sigma0: F, sigma1: F },
    /// Cogging: `amp·sin(harmonic·θ + phase)`, `harmonic` ≥ 2 periods per revolution.
    Cogging { harmonic: u16, amp: F, phase: F },
    /// Position-dependent load with one period per revolution (gravity on an arm, an
    /// unbalanced load): `amp·sin(θ + phase)`.
    PositionLoad { amp: F, phase: F },
    /// Constant load torque `t0` [N·m].
    Offset { t0: F },
    /// Friction that differs by direction: `dv·|ω| + dc·|sgn(ω)|`, so that viscous friction is
    /// `b ± dv` and Coulomb friction `fc ± dc` for positive/negative motion.
    Asymmetry { dv: F, dc: F },
    /// Inverter dead time: a voltage loss `vd·sgn(I)` [V].
    Deadtime { vd: F },
    /// Current-sensor offset: the measured current is `I + i0` [A].
    CurrentOffset { i0: F },
    /// Winding heating: resistance `R·(1 + h)` with heat state `dh/dt = (k·I² − h)/tau`,
    /// k in 1/A², tau in s.
    Thermal { k: F, tau: F },
    /// Friction growing with transmitted torque: `mu·|K_t·I|·sgn(ω)` (gears, screws).
    LoadFriction { mu: F },
    /// Magnetic saturation: the torque constant falls with the current,
    /// `K_t(I) = K_t/(1 + k·I²)`, k in 1/A²; as a load torque, the torque the motor no longer
    /// makes, `K_t·I·k·I²/(1 + k·I²)`.
    Saturation { k: F },
    /// A second inertia `j2` [kg·m²] on a spring `k` [N·m/rad] and damper `c` [N·m·s/rad]
    /// (a compliant coupling or shaft; the angle is measured on the motor side). Its state,
    /// the load's angle and speed, is integrated by the plant; its torque here is zero.
    Compliance { j2: F, k: F, c: F },
}

impl<F: Float> Effect<F> {
    /// The effect's kind (name without parameters).
    pub fn kind(&self) -> EffectKind {
        match self {
            Effect::Coulomb { .. } => EffectKind::Coulomb,
            Effect::Viscous { .. } => EffectKind::Viscous,
            Effect::Stribeck { .. } => EffectKind::Stribeck,
            Effect::Presliding { .. } => EffectKind::Presliding,
            Effect::Cogging { .. } => EffectKind::Cogging,
            Effect::PositionLoad { .. } => EffectKind::PositionLoad,
            Effect::Offset { .. } => EffectKind::Offset,
            Effect::Asymmetry { .. } => EffectKind::Asymmetry,
            Effect::Deadtime { .. } => EffectKind::Deadtime,
            Effect::CurrentOffset { .. } => EffectKind::CurrentOffset,
            Effect::Thermal { .. } => EffectKind::Thermal,
            Effect::LoadFriction { .. } => EffectKind::LoadFriction,
            Effect::Saturation { .. } => EffectKind::Saturation,
            Effect::Compliance { .. } => EffectKind::Compliance,
        }
    }

    /// Load torque [N·m] opposing motion; zero for effects that act elsewhere.
    pub fn torque(&self, x: &EffectInputs<F>) -> F {
        let veps = F::from(VELOCITY_EPS).unwrap();
        let sgn = smooth_sign(x.omega, veps);
        match *self {
            Effect::Coulomb { fc } => fc * sgn,
            Effect::Viscous { b } => b * x.omega,
            Effect::Stribeck { fs, vs } => {
                let r = x.omega / vs;
                fs * (-(r * r)).exp() * sgn
            }
            Effect::Cogging {
                harmonic,
                amp,
                phase,
            } => amp * (F::from(harmonic).unwrap() * x.theta + phase).sin(),
            Effect::PositionLoad { amp, phase } => amp * (x.theta + phase).sin(),
            Effect::Offset { t0 } => t0,
            Effect::Asymmetry { dv, dc } => dv * x.omega.abs() + dc * sgn.abs(),
            Effect::LoadFriction { mu } => mu * (x.kt * x.current).abs() * sgn,
            Effect::Saturation { k } => {
                let q = k * x.current * x.current;
                x.kt * x.current * q / (F::one() + q)
            }
            Effect::Presliding { .. }
            | Effect::Compliance { .. }
            | Effect::Deadtime { .. }
            | Effect::CurrentOffset { .. }
            | Effect::Thermal { .. } => F::zero(),
        }
    }

    /// Voltage [V] lost between the commanded and the applied voltage.
    pub fn voltage_loss(&self, current: F) -> F {
        match *self {
            Effect::Deadtime { vd } => vd * smooth_sign(current, F::from(CURRENT_EPS).unwrap()),
            _ => F::zero(),
        }
    }

    /// Additive offset [A] of the measured current.
    pub fn sensor_offset(&self) -> F {
        match *self {
            Effect::CurrentOffset { i0 } => i0,
            _ => F::zero(),
        }
    }

    /// Exact update of the heat state `h` over `dt` with the current held constant
    /// (`dh/dt = (k·I² − h)/tau`); returns `h` unchanged for other effects.
    pub fn heat_step(&self, h: F, current: F, dt: F) -> F {
        match *self {
            Effect::Thermal { k, tau } if tau > F::zero() => {
                let target = k * current * current;
                target + (h - target) * (-dt / tau).exp()
            }
            _ => h,
        }
    }
}

/// Sum of the load torques of a list of effects.
pub fn total_torque<F: Float>(effects: &[Effect<F>], x: &EffectInputs<F>) -> F {
    effects.iter().fold(F::zero(), |acc, e| acc + e.torque(x))
}

/// Sum of the voltage losses of a list of effects.
pub fn total_voltage_loss<F: Float>(effects: &[Effect<F>], current: F) -> F {
    effects
        .iter()
        .fold(F::zero(), |acc, e| acc + e.voltage_loss(current))
}

/// Sum of the current-sensor offsets of a list of effects.
pub fn total_sensor_offset<F: Float>(effects: &[Effect<F>]) -> F {
    effects
        .iter()
        .fold(F::zero(), |acc, e| acc + e.sensor_offset())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(theta: f64, omega: f64, current: f64) -> EffectInputs<f64> {
        EffectInputs {
            theta,
            omega,
            current,
            kt: 0.07,
        }
    }

    #[test]
    fn saturation_takes_the_torque_a_falling_kt_no_longer_makes() {
        let e = Effect::Saturation { k: 2e-4 };
        for i in [-40.0, -5.0, 0.0, 10.0, 40.0] {
            // K_t·I − torque = K_t(I)·I with K_t(I) = K_t/(1 + k·I²).
            let made = 0.07 * i - e.torque(&at(0.0, 3.0, i));
            let expected = 0.07 / (1.0 + 2e-4 * i * i) * i;
            assert!((made - expected).abs() < 1e-12, "I = {i}");
        }
        // Odd in the current, independent of the motion.
        assert_eq!(
            e.torque(&at(1.0, -3.0, 20.0)),
            -e.torque(&at(0.0, 3.0, -20.0))
        );
    }

    #[test]
    fn names_round_trip() {
        for k in EffectKind::ALL {
            assert_eq!(EffectKind::from_name(k.name()), Some(k));
        }
        assert_eq!(EffectKind::from_name("friction"), None);
    }

    #[test]
    fn coulomb_and_viscous_oppose_motion() {
        let c = Effect::Coulomb { fc: 0.08 };
        assert!((c.torque(&at(0.0, 10.0, 0.0)) - 0.08).abs() < 1e-9);
        assert!((c.torque(&at(0.0, -10.0, 0.0)) + 0.08).abs() < 1e-9);
        assert_eq!(c.torque(&at(0.0, 0.0, 0.0)), 0.0);
        let v = Effect::Viscous { b: 0.002 };
        assert!((v.torque(&at(0.0, -5.0, 0.0)) + 0.01).abs() < 1e-12);
    }

    #[test]
    fn cogging_has_its_period() {
        let e = Effect::Cogging {
            harmonic: 7,
            amp: 0.02,
            phase: 0.3,
        };
        let p = 2.0 * core::f64::consts::PI / 7.0;
        for th in [0.0, 0.4, 1.7, 5.0] {
            let a = e.torque(&at(th, 1.0, 0.0));
            let b = e.torque(&at(th + p, 1.0, 0.0));
            assert!((a - b).abs() < 1e-12);
        }
    }

    #[test]
    fn asymmetry_differs_by_direction() {
        let e = Effect::Asymmetry { dv: 0.001, dc: 0.0 };
        let fwd = e.torque(&at(0.0, 20.0, 0.0));
        let back = e.torque(&at(0.0, -20.0, 0.0));
        // +dv·|ω| raises friction going forward (b + dv) and lowers it going backward (b − dv).
        assert!((fwd - 0.02).abs() < 1e-12 && (back - 0.02).abs() < 1e-12);
    }

    #[test]
    fn deadtime_follows_current_sign() {
        let e = Effect::Deadtime { vd: 0.5 };
        assert!((e.voltage_loss(3.0) - 0.5).abs() < 1e-9);
        assert!((e.voltage_loss(-3.0) + 0.5).abs() < 1e-9);
    }

    #[test]
    fn heat_state_relaxes_to_its_target() {
        let e = Effect::Thermal { k: 0.01, tau: 10.0 };
        let mut h = 0.0;
        for _ in 0..10_000 {
            h = e.heat_step(h, 2.0, 0.1);
        }
        assert!((h - 0.04).abs() < 1e-9);
    }
}
