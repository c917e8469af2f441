//! The cases hidden in the independent plant ([`crate::other_plant`]) that the diagnosis
//! tables and the loop table run: each named effect sized as a real motor of the plant's
//! class shows it, and physics the effect list has no formula for.
use crate::other_plant::Extra;
use motorid::emulator::SignalKind;

/// One hidden effect: the plant's physics, whether the given model keeps the plant's
/// viscous friction, and the signals it is judged on.
pub struct Case {
    pub extra: Extra,
    pub viscous_in_model: bool,
    pub signals: &'static [SignalKind],
}

/// The multisine a for all; the voltage steps d (braking from speed, held voltages) where
/// the effect shows in braking, at rest or in heat.
const A: &[SignalKind] = &[SignalKind::A];
const AD: &[SignalKind] = &[SignalKind::A, SignalKind::D];

/// The cases, with the sizes a real motor of this plant's class (R 0.22 Ω, K_t 0.071 N·m/A,
/// J 3.1e-4 kg·m², Coulomb 0.085 N·m; rated torque about 0.4 N·m, a 24 V bridge) shows.
pub fn case(name: &str) -> Case {
    let (extra, viscous_in_model, signals) = match name {
        // A slotted motor's cogging is 1-5 % of its rated torque: 10 mN·m (2.5 %) at the
        // slot frequency of a 6-slot stator, its second harmonic 4 mN·m.
        "cogging" => (
            Extra::SlotCogging {
                slots: 6,
                a1: 0.010,
                p1: 0.7,
                a2: 0.004,
                p2: 2.1,
            },
            true,
            A,
        ),
        // 0.5 µs dead time per edge at 20 kHz on a 24 V bus loses 24·0.5e-6·20e3 = 0.24 V;
        // the sign of the current passes through zero across the PWM ripple, ±0.3 A.
        "deadtime" => (
            Extra::DeadTime {
                vd: 0.24,
                band: 0.3,
            },
            true,
            AD,
        ),
        // A small motor's winding: about 16 g of copper (6 J/K) and 10 K/W to still air
        // without a heatsink (a one-minute time constant); copper's 0.393 %/K.
        "thermal" => (
            Extra::Heating {
                r_th: 10.0,
                c_th: 6.0,
            },
            true,
            AD,
        ),
        // Three counts of a 12-bit ADC on a 3 mΩ shunt with gain 9 (29 mA a count) left by
        // an offset calibration done cold.
        "current_offset" => (Extra::SensorOffset { i0: 0.09 }, true, AD),
        // A constant load of a quarter of the Coulomb friction: a spring's preload, a
        // vertical axis not quite balanced.
        "offset" => (Extra::ConstantLoad { t0: 0.02 }, true, AD),
        // 50 g out of balance at 4 cm under gravity (0.0196 N·m) and a second harmonic of a
        // quarter of it from the mount's eccentricity.
        "position_load" => (
            Extra::Unbalance {
                a1: 0.0196,
                p1: 1.1,
                a2: 0.005,
                p2: -0.4,
            },
            true,
            A,
        ),
        // A two-stage planetary gearhead passes 75 % of the torque it transmits (catalogue
        // efficiencies of 70-80 %); the gearhead and its load are two thirds of the inertia.
        "load_friction" => (
            Extra::GearFriction {
                mu: 0.25,
                j_load: 2.0e-4,
            },
            true,
            AD,
        ),
        // Static friction 30 % above Coulomb (lubricated contacts: 1.1-1.5 times), falling
        // by half at 2.5 rad/s.
        "stribeck" => (Extra::Breakaway { fs: 0.025, vs: 2.5 }, true, AD),
        // The plant's own viscous friction (1.5e-3 N·m·s/rad), left out of the model.
        "viscous" => (Extra::None, false, A),
        _ => unreachable!("no case {name}"),
    };
    Case {
        extra,
        viscous_in_model,
        signals,
    }
}

/// Every hidden effect, in the order of the table.
pub const NAMES: [&str; 9] = [
    "cogging",
    "deadtime",
    "thermal",
    "current_offset",
    "offset",
    "position_load",
    "load_friction",
    "stribeck",
    "viscous",
];

/// The cases of the verdict table: a name, the plant's extra physics and the signal.
pub fn verdict_cases() -> [(&'static str, Extra, SignalKind); 7] {
    [
        ("correct model", Extra::None, SignalKind::A),
        ("correct model", Extra::None, SignalKind::D),
        (
            "compliant coupling (5 Hz two-mass resonance), load 2× rotor",
            Extra::Coupling {
                j2: 6e-4,
                k: 0.2,
                c: 6e-4,
            },
            SignalKind::A,
        ),
        (
            "gap 0.5 rad, load 2× rotor",
            Extra::Gap { j2: 6e-4, gap: 0.5 },
            SignalKind::A,
        ),
        (
            "K_t falling with current (table)",
            Extra::FallingKt,
            SignalKind::D,
        ),
        (
            "K_t falling with current (table)",
            Extra::FallingKt,
            SignalKind::A,
        ),
        (
            "Coulomb friction +100 %/min",
            Extra::CreepingCoulomb { per_minute: 1.0 },
            SignalKind::A,
        ),
    ]
}
