//! `load_friction`: friction growing with the torque the drive transmits.
use super::*;

/// Default μ = 0.2: high-ratio transmissions (worm and harmonic gears, lead screws) lose
/// 10–30 % of the torque they transmit; spur gears and ball screws 2–10 %. Smaller values
/// differ from a lower K_t only while the drive brakes and are not visible on the paper
/// motor (docs/limits.md).
const KEYS: &[Key] = &[k("mu", "1", 0.2, "friction per N·m of transmitted torque")];

pub static D: Descriptor = Descriptor {
    kind: EffectKind::LoadFriction,
    meaning: "friction growing with the torque a transmission carries (gears, screws)",
    keys: KEYS,
    help: None,
    check: no_check,
    to_effect: |s| Effect::LoadFriction { mu: s.get("mu") },
    values: |e| match *e {
        Effect::LoadFriction { mu } => vec![("mu", mu)],
        _ => vec![],
    },
    fit_keys: |_| vec![("mu", 0.0, 2.0)],
    scale: |e, f| {
        if let Effect::LoadFriction { mu } = e {
            *mu *= f
        }
    },
    harmonic: not_periodic,
    weak_torque: WeakTorque::PerKey(&[("mu", |s| {
        s.cur
            .iter()
            .zip(s.sgn)
            .map(|(c, g)| (s.kt * c).abs() * g)
            .collect()
    })]),
    voltage: None,
    on_residual: false,
    sindy: |_| terms(&[(Term::AbsISgnXdot, IN_ACCEL)]),
    diagnose: Diagnose {
        variants: |s| {
            let columns = vec![s.load_friction_column()];
            let kind = EffectKind::LoadFriction;
            vec![Variant {
                torque: Some(s.load_friction_torque()),
                ..Variant::new(kind, Equation::Mechanical, vec![], columns)
            }]
        },
        // Its column needs the fitted K_b and R: `diagnose` adds it to the torque equation's
        // base itself (`Signals::load_friction_intervals`).
        present: no_columns,
        // The braking column's coefficient is μ/(1 − μ): the motoring part μ·drive of the
        // friction scales the whole base by 1/(1 − μ) (a lower K_t), the braking part then
        // enters with μ/(1 − μ).
        keys: |b, _, v| put(v, "mu", b[0] / (1.0 + b[0])),
        column_names: &[],
        torque_unit: "N·m",
        plausible: |s| (0.0..=crate::diagnose::MAX_LOAD_FRICTION).contains(&s.get("mu")),
        explain: |s| {
            format!(
                "friction grows with the transmitted torque, {:.3} N·m per N·m (gears, screws)",
                s.get("mu")
            )
        },
    },
};

pub(super) fn key_mut<'a, D>(e: &'a mut Effect<D>, key: &str) -> Option<&'a mut D> {
    match (e, key) {
        (Effect::LoadFriction { mu }, "mu") => Some(mu),
        _ => None,
    }
}
