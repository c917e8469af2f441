//! `coulomb`: a constant friction torque opposing the motion.
use super::*;

const KEYS: &[Key] = &[k("fc", "N·m", 0.05, "Coulomb friction torque")];

pub static D: Descriptor = Descriptor {
    kind: EffectKind::Coulomb,
    meaning: "friction of constant size opposing the motion",
    keys: KEYS,
    help: None,
    check: no_check,
    to_effect: |s| Effect::Coulomb { fc: s.get("fc") },
    values: |e| match *e {
        Effect::Coulomb { fc } => vec![("fc", fc)],
        _ => vec![],
    },
    fit_keys: |_| vec![("fc", 0.0, 10.0)],
    scale: |e, f| {
        if let Effect::Coulomb { fc } = e {
            *fc *= f
        }
    },
    harmonic: not_periodic,
    weak_torque: WeakTorque::PerKey(&[("fc", sign_of_velocity)]),
    voltage: None,
    on_residual: false,
    sindy: |_| terms(&[(Term::SgnXdot, IN_ACCEL)]),
    diagnose: Diagnose {
        variants: |s| {
            let columns = vec![s.sgn_omega(), s.stick_column()];
            vec![Variant::new(
                EffectKind::Coulomb,
                Equation::Mechanical,
                vec![],
                columns,
            )]
        },
        present: |_, s| {
            let mech = Equation::Mechanical;
            vec![(mech, s.sgn_omega()), (mech, s.stick_column())]
        },
        keys: |b, _, v| put(v, "fc", b[0]),
        column_names: &["fc (Coulomb)", "Coulomb at standstill"],
        torque_unit: "N·m",
        plausible: |s| s.get("fc") > 0.0,
        explain: |s| {
            format!(
                "a constant friction of {:.3} N·m opposes the motion in either direction (Coulomb)",
                s.get("fc")
            )
        },
    },
};

pub(super) fn key_mut<'a, D>(e: &'a mut Effect<D>, key: &str) -> Option<&'a mut D> {
    match (e, key) {
        (Effect::Coulomb { fc }, "fc") => Some(fc),
        _ => None,
    }
}
