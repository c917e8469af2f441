//! `backlash`: a load inertia engaged across a gap.
use super::*;
use std::f64::consts::PI;

/// Default: a load twice the paper rotor's inertia behind a gap of two Hall steps of the
/// paper's board (0.19 rad), a worn gear stage seen at the rotor.
#[rustfmt::skip]
const KEYS: &[Key] = &[
    k("j2", "kg·m²", 6e-4, "inertia of the load behind the gap"),
    // A gap is a width.
    k0("gap", "rad", 0.19, "angle the rotor turns alone after a reversal"),
];

pub static D: Descriptor = Descriptor {
    kind: EffectKind::Backlash,
    meaning: "a load inertia the rotor engages only after crossing a gap (worn gears)",
    keys: KEYS,
    help: None,
    check: no_check,
    to_effect: |s| Effect::Backlash {
        j2: s.get("j2"),
        gap: s.get("gap"),
    },
    values: |e| match *e {
        Effect::Backlash { j2, gap } => vec![("j2", j2), ("gap", gap)],
        _ => vec![],
    },
    // A gap from none up to a quarter revolution of the rotor.
    fit_keys: |_| vec![("j2", 1e-6, 1.0), ("gap", 0.0, 0.5 * PI)],
    scale: |e, f| {
        if let Effect::Backlash { j2, .. } = e {
            *j2 *= f
        }
    },
    harmonic: not_periodic,
    weak_torque: WeakTorque::None,
    voltage: None,
    on_residual: false,
    sindy: no_sindy_term,
};

pub(super) fn key_mut<'a, D>(e: &'a mut Effect<D>, key: &str) -> Option<&'a mut D> {
    match (e, key) {
        (Effect::Backlash { j2, .. }, "j2") => Some(j2),
        (Effect::Backlash { gap, .. }, "gap") => Some(gap),
        _ => None,
    }
}
