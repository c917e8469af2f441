//! `offset`: a constant load torque.
use super::*;

const KEYS: &[Key] = &[k("t0", "N·m", 0.03, "constant load torque")];

pub static D: Descriptor = Descriptor {
    kind: EffectKind::Offset,
    meaning: "constant load torque, the same in both directions (gravity on an arm at rest)",
    keys: KEYS,
    help: None,
    check: no_check,
    to_effect: |s| Effect::Offset { t0: s.get("t0") },
    values: |e| match *e {
        Effect::Offset { t0 } => vec![("t0", t0)],
        _ => vec![],
    },
    fit_keys: |_| vec![("t0", -10.0, 10.0)],
    scale: |e, f| {
        if let Effect::Offset { t0 } = e {
            *t0 *= f
        }
    },
    harmonic: not_periodic,
    weak_torque: WeakTorque::PerKey(&[("t0", |s| vec![1.0; s.theta.len()])]),
    voltage: None,
    on_residual: true,
    sindy: |_| terms(&[(Term::One, IN_ACCEL)]),
    diagnose: Diagnose {
        variants: |s| {
            let columns = vec![vec![1.0; s.len()]];
            vec![Variant::new(
                EffectKind::Offset,
                Equation::Mechanical,
                vec![],
                columns,
            )]
        },
        present: |_, s| vec![(Equation::Mechanical, vec![1.0; s.len()])],
        keys: |b, _, v| put(v, "t0", b[0]),
        column_names: &[],
        torque_unit: "N·m",
        plausible: always_plausible,
        explain: |s| {
            format!(
                "a constant load torque of {:.3} N·m pulls in one direction",
                s.get("t0")
            )
        },
    },
};

pub(super) fn key_mut<'a, D>(e: &'a mut Effect<D>, key: &str) -> Option<&'a mut D> {
    match (e, key) {
        (Effect::Offset { t0 }, "t0") => Some(t0),
        _ => None,
    }
}
