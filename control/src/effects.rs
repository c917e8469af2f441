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
    Backlash,
    Table,
}

impl EffectKind {
    /// Every effect, in the documented order.
    pub const ALL: [EffectKind; 16] = [
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
        EffectKind::Backlash,
        EffectKind::Table,
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
            EffectKind::Backlash => "backlash",
            EffectKind::Table => "table",
        }
    }

    /// Parse an effect's name.
    pub fn from_name(name: &str) -> Option<EffectKind> {
        EffectKind::ALL.iter().copied().find(|k| k.name() == name)
    }

    /// Where the effect acts.
    pub fn site(self) -> Site {
        match self {
            EffectKind::Presliding | EffectKind::Compliance | EffectKind::Backlash => Site::State,
            EffectKind::Deadtime => Site::Voltage,
            EffectKind::CurrentOffset => Site::Sensor,
            EffectKind::Thermal => Site::Resistance,
            _ => Site::Torque,
        }
    }
}

/// Most bins a [`Effect::Table`] holds.
pub const TABLE_MAX_BINS: usize = 16;

/// The variable a [`Effect::Table`] looks its torque up by.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum TableVar {
    /// Rotor angle θ [rad]: the table spans one revolution and wraps around, or, with a
    /// range `lo < hi`, that stretch of θ (the stroke of a linear axis), clamped at its ends.
    Theta,
    /// Rotor velocity ω [rad/s], clamped to the table's range.
    Omega,
    /// Winding current I [A], clamped to the table's range.
    Current,
}

impl TableVar {
    /// Every variable, in the order of its code in a spec (`var` = 0, 1, 2).
    pub const ALL: [TableVar; 3] = [TableVar::Theta, TableVar::Omega, TableVar::Current];

    /// The variable's name in a spec (`theta`, `omega`, `current`).
    pub fn name(self) -> &'static str {
        match self {
            TableVar::Theta => "theta",
            TableVar::Omega => "omega",
            TableVar::Current => "current",
        }
    }

    /// Parse a variable's name.
    pub fn from_name(name: &str) -> Option<TableVar> {
        TableVar::ALL.iter().copied().find(|v| v.name() == name)
    }
}

/// The two table nodes around `x` and the weight of the second: the value at `x` is
/// `(1 − w)·v[k0] + w·v[k1]` (linear "hat" interpolation, continuous in `x`).
///
/// For [`TableVar::Theta`] without a range (`lo < hi` does not hold) the `bins` nodes sit at
/// `θ_k = 2π·k/bins` and the table wraps around one revolution. Otherwise the nodes sit
/// evenly from `lo` (node 0) to `hi` (node `bins − 1`) and `x` is clamped to that range (for
/// θ: a position-dependent force along the stroke of a linear axis, which does not repeat).
/// `bins` is taken as at least 2 and at most [`TABLE_MAX_BINS`].
pub fn table_nodes<F: Float>(var: TableVar, bins: u8, lo: F, hi: F, x: F) -> (usize, usize, F) {
    let n = (bins as usize).clamp(2, TABLE_MAX_BINS);
    let nf = F::from(n).unwrap();
    if !x.is_finite() {
        return (0, 0, F::zero());
    }
    match var {
        TableVar::Theta if hi.partial_cmp(&lo) != Some(core::cmp::Ordering::Greater) => {
            let two_pi = F::from(core::f64::consts::TAU).unwrap();
            let mut t = (x / two_pi).fract() * nf;
            if t < F::zero() {
                t = t + nf;
            }
            let k0 = t.floor().to_usize().unwrap_or(0).min(n - 1);
            let w = (t - F::from(k0).unwrap()).max(F::zero()).min(F::one());
            (k0, (k0 + 1) % n, w)
        }
        TableVar::Theta | TableVar::Omega | TableVar::Current => {
            let span = hi - lo;
            if span.is_nan() || span <= F::zero() {
                return (0, 0, F::zero());
            }
            let t = ((x - lo) / span).max(F::zero()).min(F::one()) * (nf - F::one());
            let k0 = t.floor().to_usize().unwrap_or(0).min(n - 2);
            let w = (t - F::from(k0).unwrap()).max(F::zero()).min(F::one());
            (k0, k0 + 1, w)
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
#[serde(bound(deserialize = "F: Deserialize<'de> + Copy + Default"))]
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
    /// A load inertia `j2` [kg·m²] engaged across a gap `gap` [rad] (gear or coupling
    /// backlash): after a reversal the motor turns alone until it has travelled `gap`, then
    /// drags the load along. Its state, the angle since the last reversal, is the plant's;
    /// its torque here is zero.
    Backlash { j2: F, gap: F },
    /// A lookup table of load torque [N·m] over one variable, for physics without a name:
    /// `Σ_k values[k]·h_k(x)` with the hat functions `h_k` of [`table_nodes`] (`bins` nodes;
    /// over one revolution and periodic for θ without a range, over `lo..hi` and clamped for
    /// θ [rad] with one, ω [rad/s] or I [A]). Entries from `bins` on are unused.
    Table {
        var: TableVar,
        bins: u8,
        lo: F,
        hi: F,
        #[serde(with = "crate::serde_array")]
        values: [F; TABLE_MAX_BINS],
    },
}

impl<A: Copy> Effect<A> {
    /// The same effect with every number mapped by `c` (`|x| x as f32` for the board's blob,
    /// a constant dual number for a Jacobian); the variant, `harmonic`, `var` and `bins` are
    /// kept.
    pub fn map<B>(&self, c: impl Fn(A) -> B) -> Effect<B> {
        match *self {
            Effect::Coulomb { fc } => Effect::Coulomb { fc: c(fc) },
            Effect::Viscous { b } => Effect::Viscous { b: c(b) },
            Effect::Stribeck { fs, vs } => Effect::Stribeck {
                fs: c(fs),
                vs: c(vs),
            },
            Effect::Presliding { sigma0, sigma1 } => Effect::Presliding {
                sigma0: c(sigma0),
                sigma1: c(sigma1),
            },
            Effect::Cogging {
                harmonic,
                amp,
                phase,
            } => Effect::Cogging {
                harmonic,
                amp: c(amp),
                phase: c(phase),
            },
            Effect::PositionLoad { amp, phase } => Effect::PositionLoad {
                amp: c(amp),
                phase: c(phase),
            },
            Effect::Offset { t0 } => Effect::Offset { t0: c(t0) },
            Effect::Asymmetry { dv, dc } => Effect::Asymmetry {
                dv: c(dv),
                dc: c(dc),
            },
            Effect::Deadtime { vd } => Effect::Deadtime { vd: c(vd) },
            Effect::CurrentOffset { i0 } => Effect::CurrentOffset { i0: c(i0) },
            Effect::Thermal { k, tau } => Effect::Thermal {
                k: c(k),
                tau: c(tau),
            },
            Effect::LoadFriction { mu } => Effect::LoadFriction { mu: c(mu) },
            Effect::Saturation { k } => Effect::Saturation { k: c(k) },
            Effect::Compliance { j2, k, c: d } => Effect::Compliance {
                j2: c(j2),
                k: c(k),
                c: c(d),
            },
            Effect::Backlash { j2, gap } => Effect::Backlash {
                j2: c(j2),
                gap: c(gap),
            },
            Effect::Table {
                var,
                bins,
                lo,
                hi,
                values,
            } => Effect::Table {
                var,
                bins,
                lo: c(lo),
                hi: c(hi),
                values: values.map(&c),
            },
        }
    }
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
            Effect::Backlash { .. } => EffectKind::Backlash,
            Effect::Table { .. } => EffectKind::Table,
        }
    }

    /// Load torque [N·m] opposing motion; zero for effects that act elsewhere. The sign of
    /// the velocity is smoothed over [`VELOCITY_EPS`].
    pub fn torque(&self, x: &EffectInputs<F>) -> F {
        self.torque_with_width(x, F::from(VELOCITY_EPS).unwrap())
    }

    /// [`Self::torque`] with the sign of the velocity smoothed over `veps` [rad/s] instead of
    /// [`VELOCITY_EPS`]: a model identified on a log in other velocity units (m/s of a linear
    /// axis) carries the width that means the same there.
    pub fn torque_with_width(&self, x: &EffectInputs<F>, veps: F) -> F {
        // The smoothed sign only where an effect needs it (a tanh per call otherwise).
        let sgn = || smooth_sign(x.omega, veps);
        match *self {
            Effect::Coulomb { fc } => fc * sgn(),
            Effect::Viscous { b } => b * x.omega,
            Effect::Stribeck { fs, vs } => {
                let r = x.omega / vs;
                fs * (-(r * r)).exp() * sgn()
            }
            Effect::Cogging {
                harmonic,
                amp,
                phase,
            } => amp * crate::trig::sin_of(F::from(harmonic).unwrap() * x.theta + phase),
            Effect::PositionLoad { amp, phase } => amp * crate::trig::sin_of(x.theta + phase),
            Effect::Offset { t0 } => t0,
            Effect::Asymmetry { dv, dc } => dv * x.omega.abs() + dc * sgn().abs(),
            Effect::LoadFriction { mu } => mu * (x.kt * x.current).abs() * sgn(),
            Effect::Saturation { k } => {
                let q = k * x.current * x.current;
                x.kt * x.current * q / (F::one() + q)
            }
            Effect::Table {
                var,
                bins,
                lo,
                hi,
                ref values,
            } => {
                let x = match var {
                    TableVar::Theta => x.theta,
                    TableVar::Omega => x.omega,
                    TableVar::Current => x.current,
                };
                let (k0, k1, w) = table_nodes(var, bins, lo, hi, x);
                values[k0] * (F::one() - w) + values[k1] * w
            }
            Effect::Presliding { .. }
            | Effect::Compliance { .. }
            | Effect::Backlash { .. }
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

/// [`total_torque`] with the sign of the velocity smoothed over `veps` (see
/// [`Effect::torque_with_width`]).
pub fn total_torque_with_width<F: Float>(effects: &[Effect<F>], x: &EffectInputs<F>, veps: F) -> F {
    effects
        .iter()
        .fold(F::zero(), |acc, e| acc + e.torque_with_width(x, veps))
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
    // Tolerances within a few float ε of the values compared (1e-15 to 1e-9 in f64, 1e-6
    // in f32) are rounding of the same closed form computed another way; wider ones say
    // why beside them.
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

    fn table(var: TableVar, bins: u8, lo: f64, hi: f64) -> Effect<f64> {
        let mut values = [0.0; TABLE_MAX_BINS];
        for (k, v) in values.iter_mut().enumerate().take(bins as usize) {
            *v = 0.01 * (k as f64 + 1.0);
        }
        Effect::Table {
            var,
            bins,
            lo,
            hi,
            values,
        }
    }

    #[test]
    fn theta_table_hits_its_nodes_and_wraps_around_one_revolution() {
        let e = table(TableVar::Theta, 8, 0.0, 0.0);
        let tau = core::f64::consts::TAU;
        for k in 0..8 {
            let th = tau * k as f64 / 8.0;
            let want = 0.01 * (k as f64 + 1.0);
            assert!(
                (e.torque(&at(th, 0.0, 0.0)) - want).abs() < 1e-12,
                "node {k}"
            );
            assert!((e.torque(&at(th - 3.0 * tau, 0.0, 0.0)) - want).abs() < 1e-9);
        }
        // Halfway between the last node and the first: the mean of both.
        let mid = e.torque(&at(tau * 7.5 / 8.0, 0.0, 0.0));
        assert!((mid - 0.5 * (0.08 + 0.01)).abs() < 1e-12);
        // Continuous across the wrap.
        let (a, b) = (
            e.torque(&at(tau - 1e-9, 0.0, 0.0)),
            e.torque(&at(0.0, 0.0, 0.0)),
        );
        // 1e-6: the table's slope (about 0.1 N·m/rad) over the 1e-9 rad left of the wrap is
        // 1e-10; a jump at the wrap would be a node difference, 0.07 N·m.
        assert!((a - b).abs() < 1e-6);
    }

    #[test]
    fn theta_table_with_a_range_spans_the_stroke_and_does_not_wrap() {
        // Five nodes over 0..240 (mm of a linear axis): 60 apart.
        let e = table(TableVar::Theta, 5, 0.0, 240.0);
        assert!((e.torque(&at(0.0, 0.0, 0.0)) - 0.01).abs() < 1e-12);
        assert!((e.torque(&at(240.0, 0.0, 0.0)) - 0.05).abs() < 1e-12);
        assert!((e.torque(&at(90.0, 0.0, 0.0)) - 0.025).abs() < 1e-12);
        // Beyond the stroke the end nodes hold; one revolution later is not node 0 again.
        assert!((e.torque(&at(300.0, 0.0, 0.0)) - 0.05).abs() < 1e-12);
        assert!((e.torque(&at(-5.0, 0.0, 0.0)) - 0.01).abs() < 1e-12);
        let tau = core::f64::consts::TAU;
        assert!((e.torque(&at(tau, 0.0, 0.0)) - e.torque(&at(0.0, 0.0, 0.0))).abs() > 1e-4);
    }

    #[test]
    fn omega_table_interpolates_inside_and_clamps_outside_its_range() {
        let e = table(TableVar::Omega, 5, -20.0, 20.0);
        assert!((e.torque(&at(0.0, -20.0, 0.0)) - 0.01).abs() < 1e-12);
        assert!((e.torque(&at(0.0, 20.0, 0.0)) - 0.05).abs() < 1e-12);
        assert!((e.torque(&at(0.0, 5.0, 0.0)) - 0.035).abs() < 1e-12);
        assert!((e.torque(&at(0.0, 1e4, 0.0)) - 0.05).abs() < 1e-12);
        assert!((e.torque(&at(0.0, -1e4, 0.0)) - 0.01).abs() < 1e-12);
        let c = table(TableVar::Current, 2, 0.0, 10.0);
        assert!((c.torque(&at(0.0, 3.0, 5.0)) - 0.015).abs() < 1e-12);
        // A degenerate range or a non-finite input gives the first node, never a panic.
        assert!(table(TableVar::Omega, 4, 1.0, 1.0)
            .torque(&at(0.0, 2.0, 0.0))
            .is_finite());
        assert!(e.torque(&at(0.0, f64::NAN, 0.0)).is_finite());
    }

    #[test]
    fn map_keeps_the_variant_and_maps_every_number() {
        let mut values = [0.0; TABLE_MAX_BINS];
        values[3] = 0.7;
        let every = [
            Effect::Coulomb { fc: 0.1 },
            Effect::Viscous { b: 0.2 },
            Effect::Stribeck { fs: 0.3, vs: 0.4 },
            Effect::Presliding {
                sigma0: 0.5,
                sigma1: 0.6,
            },
            Effect::Cogging {
                harmonic: 7,
                amp: 0.7,
                phase: 0.8,
            },
            Effect::PositionLoad {
                amp: 0.9,
                phase: 1.0,
            },
            Effect::Offset { t0: 1.1 },
            Effect::Asymmetry { dv: 1.2, dc: 1.3 },
            Effect::Deadtime { vd: 1.4 },
            Effect::CurrentOffset { i0: 1.5 },
            Effect::Thermal { k: 1.6, tau: 1.7 },
            Effect::LoadFriction { mu: 1.8 },
            Effect::Saturation { k: 1.9 },
            Effect::Compliance {
                j2: 2.0,
                k: 2.1,
                c: 2.2,
            },
            Effect::Backlash { j2: 2.3, gap: 2.4 },
            Effect::Table {
                var: TableVar::Omega,
                bins: 5,
                lo: 2.5,
                hi: 2.6,
                values,
            },
        ];
        // The numbers each variant holds (a table: lo, hi and all its values).
        let numbers = [
            1,
            1,
            2,
            2,
            2,
            2,
            1,
            2,
            1,
            1,
            2,
            1,
            1,
            3,
            2,
            2 + TABLE_MAX_BINS,
        ];
        for ((e, kind), n) in every.iter().zip(EffectKind::ALL).zip(numbers) {
            assert_eq!(e.kind(), kind);
            let calls = core::cell::Cell::new(0);
            let doubled = e.map(|x| {
                calls.set(calls.get() + 1);
                2.0 * x
            });
            assert_eq!(calls.get(), n, "{kind:?}: every number mapped once");
            assert_eq!(doubled.kind(), kind);
            // Halving undoes doubling exactly: no number is lost or changed otherwise.
            assert_eq!(doubled.map(|x| 0.5 * x), *e);
        }
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
