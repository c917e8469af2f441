//! `position_load`: a load torque periodic in angle, one period per revolution.
use super::*;
use std::f64::consts::PI;

#[rustfmt::skip]
const KEYS: &[Key] = &[
    k("amp", "N·m", 0.05, "torque amplitude (one period per revolution)"),
    k("phase", "rad", 0.0, "phase"),
];

pub static D: Descriptor = Descriptor {
    kind: EffectKind::PositionLoad,
    meaning: "load torque periodic in angle, one period per revolution (an unbalance)",
    keys: KEYS,
    help: None,
    check: no_check,
    to_effect: |s| Effect::PositionLoad {
        amp: s.get("amp"),
        phase: s.get("phase"),
    },
    values: |e| match *e {
        Effect::PositionLoad { amp, phase } => vec![("amp", amp), ("phase", phase)],
        _ => vec![],
    },
    fit_keys: |_| vec![("amp", -10.0, 10.0), ("phase", -4.0 * PI, 4.0 * PI)],
    scale: |e, f| {
        if let Effect::PositionLoad { amp, .. } = e {
            *amp *= f
        }
    },
    harmonic: |e| matches!(e, Effect::PositionLoad { .. }).then_some(1.0),
    weak_torque: WeakTorque::Periodic,
    voltage: None,
    on_residual: true,
    sindy: |_| terms(&[(Term::SinTheta(1), IN_ACCEL), (Term::CosTheta(1), IN_ACCEL)]),
    diagnose: Diagnose {
        variants: |s| {
            let [a, b] = s.angle_pair(1);
            let kind = EffectKind::PositionLoad;
            vec![Variant::new(kind, Equation::Mechanical, vec![], vec![a, b])]
        },
        present: |_, s| {
            let [a, b] = s.angle_pair(1);
            vec![(Equation::Mechanical, a), (Equation::Mechanical, b)]
        },
        keys: super::cogging::amp_phase,
        column_names: &[],
        torque_unit: "N·m",
        plausible: always_plausible,
        explain: |s| {
            format!(
                "a torque of {:.3} N·m repeats once per revolution (gravity on an arm or an unbalanced load)",
                s.get("amp")
            )
        },
    },
};

pub(super) fn key_mut<'a, D>(e: &'a mut Effect<D>, key: &str) -> Option<&'a mut D> {
    match (e, key) {
        (Effect::PositionLoad { amp, .. }, "amp") => Some(amp),
        (Effect::PositionLoad { phase, .. }, "phase") => Some(phase),
        _ => None,
    }
}
