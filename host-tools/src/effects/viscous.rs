//! `viscous`: a friction torque proportional to the velocity.
use super::*;

const KEYS: &[Key] = &[k("b", "N·m·s/rad", 0.001, "viscous friction coefficient")];

pub static D: Descriptor = Descriptor {
    kind: EffectKind::Viscous,
    meaning: "friction proportional to the velocity",
    keys: KEYS,
    help: None,
    check: no_check,
    to_effect: |s| Effect::Viscous { b: s.get("b") },
    values: |e| match *e {
        Effect::Viscous { b } => vec![("b", b)],
        _ => vec![],
    },
    fit_keys: |_| vec![("b", 0.0, 10.0)],
    scale: |e, f| {
        if let Effect::Viscous { b } = e {
            *b *= f
        }
    },
    harmonic: not_periodic,
    weak_torque: WeakTorque::PerKey(&[("b", |s| s.ws.to_vec())]),
    voltage: None,
    on_residual: false,
    // ẋ is already in the library.
    sindy: in_paper_library,
    diagnose: Diagnose {
        variants: |s| {
            let columns = vec![s.omega.clone()];
            vec![Variant::new(
                EffectKind::Viscous,
                Equation::Mechanical,
                vec![],
                columns,
            )]
        },
        present: |_, s| vec![(Equation::Mechanical, s.omega.clone())],
        keys: |b, _, v| put(v, "b", b[0]),
        column_names: &["b (viscous)"],
        torque_unit: "N·m·s/rad",
        plausible: |s| s.get("b") > 0.0,
        explain: |s| {
            format!(
                "friction grows in proportion to speed, {:.2e} N·m per rad/s (viscous)",
                s.get("b")
            )
        },
    },
};

pub(super) fn key_mut<'a, D>(e: &'a mut Effect<D>, key: &str) -> Option<&'a mut D> {
    match (e, key) {
        (Effect::Viscous { b }, "b") => Some(b),
        _ => None,
    }
}
