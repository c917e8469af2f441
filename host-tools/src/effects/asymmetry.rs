//! `asymmetry`: friction that differs by direction.
use super::*;

#[rustfmt::skip]
const KEYS: &[Key] = &[
    k("dv", "N·m·s/rad", 0.0008, "viscous friction difference (b ± dv by direction)"),
    k("dc", "N·m", 0.0, "Coulomb friction difference (fc ± dc by direction)"),
];

pub static D: Descriptor = Descriptor {
    kind: EffectKind::Asymmetry,
    meaning: "friction larger in one direction than in the other",
    keys: KEYS,
    help: None,
    check: no_check,
    to_effect: |s| Effect::Asymmetry {
        dv: s.get("dv"),
        dc: s.get("dc"),
    },
    values: |e| match *e {
        Effect::Asymmetry { dv, dc } => vec![("dv", dv), ("dc", dc)],
        _ => vec![],
    },
    fit_keys: |_| vec![("dv", -10.0, 10.0), ("dc", -10.0, 10.0)],
    scale: |e, f| {
        if let Effect::Asymmetry { dv, dc } = e {
            *dv *= f;
            *dc *= f
        }
    },
    harmonic: not_periodic,
    weak_torque: WeakTorque::PerKey(&[
        ("dv", |s| s.ws.iter().map(|w| w.abs()).collect()),
        ("dc", |s| s.sgn.iter().map(|g| g.abs()).collect()),
    ]),
    voltage: None,
    on_residual: false,
    sindy: |_| terms(&[(Term::AbsXdot, IN_ACCEL), (Term::AbsSgnXdot, IN_ACCEL)]),
    diagnose: Diagnose {
        variants: |s| {
            let columns = vec![s.omega.iter().map(|w| w.abs()).collect()];
            vec![Variant::new(
                EffectKind::Asymmetry,
                Equation::Mechanical,
                vec![],
                columns,
            )]
        },
        present: |_, s| {
            vec![(
                Equation::Mechanical,
                s.omega.iter().map(|w| w.abs()).collect(),
            )]
        },
        keys: |b, _, v| {
            put(v, "dv", b[0]);
            put(v, "dc", 0.0)
        },
        column_names: &[],
        torque_unit: "N·m·s/rad",
        plausible: always_plausible,
        explain: |s| {
            format!(
                "friction differs by direction: viscous friction {:+.2e} N·m per rad/s going forward against backward",
                2.0 * s.get("dv")
            )
        },
    },
};

pub(super) fn key_mut<'a, D>(e: &'a mut Effect<D>, key: &str) -> Option<&'a mut D> {
    match (e, key) {
        (Effect::Asymmetry { dv, .. }, "dv") => Some(dv),
        (Effect::Asymmetry { dc, .. }, "dc") => Some(dc),
        _ => None,
    }
}
