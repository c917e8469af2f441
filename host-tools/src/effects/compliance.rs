//! `compliance`: a second inertia on a spring-damper coupling.
use super::*;

/// Default: a load twice the paper rotor's inertia on a coupling that resonates near 5 Hz,
/// lightly damped (ζ ≈ 0.05), as a flexible coupling or a long shaft.
#[rustfmt::skip]
const KEYS: &[Key] = &[
    k("j2", "kg·m²", 6e-4, "inertia of the load behind the coupling"),
    // A spring or damper of negative sign would give energy back: the coupled free run and
    // the plant would be unstable, and the implicit step's divisor j2/h + k·h + c could vanish.
    k0("k", "N·m/rad", 0.2, "stiffness of the coupling"),
    k0("c", "N·m·s/rad", 6e-4, "damping of the coupling"),
];

pub static D: Descriptor = Descriptor {
    kind: EffectKind::Compliance,
    meaning: "a load inertia behind a spring-damper coupling (a resonance)",
    keys: KEYS,
    help: None,
    check: no_check,
    to_effect: |s| Effect::Compliance {
        j2: s.get("j2"),
        k: s.get("k"),
        c: s.get("c"),
    },
    values: |e| match *e {
        Effect::Compliance { j2, k, c } => vec![("j2", j2), ("k", k), ("c", c)],
        _ => vec![],
    },
    // A load from a hundredth to a hundred times a small rotor, couplings from 0.5 Hz up.
    fit_keys: |_| vec![("j2", 1e-6, 1.0), ("k", 1e-4, 1e4), ("c", 0.0, 10.0)],
    scale: |e, f| {
        if let Effect::Compliance { j2, .. } = e {
            *j2 *= f
        }
    },
    harmonic: not_periodic,
    weak_torque: WeakTorque::None,
    voltage: None,
    on_residual: false,
    sindy: |_| {
        anyhow::bail!(
            "--add compliance: a SINDYc library has no load state for a second inertia; fit --model lugre --add compliance"
        )
    },
};

pub(super) fn key_mut<'a, D>(e: &'a mut Effect<D>, key: &str) -> Option<&'a mut D> {
    match (e, key) {
        (Effect::Compliance { j2, .. }, "j2") => Some(j2),
        (Effect::Compliance { k, .. }, "k") => Some(k),
        (Effect::Compliance { c, .. }, "c") => Some(c),
        _ => None,
    }
}
