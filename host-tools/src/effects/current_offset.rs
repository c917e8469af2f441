//! `current_offset`: an offset of the current sensor.
use super::*;

const KEYS: &[Key] = &[k("i0", "A", 0.2, "current-sensor offset")];

pub static D: Descriptor = Descriptor {
    kind: EffectKind::CurrentOffset,
    meaning: "offset of the current sensor: the measured current is the true one plus i0",
    keys: KEYS,
    help: None,
    check: no_check,
    to_effect: |s| Effect::CurrentOffset { i0: s.get("i0") },
    values: |e| match *e {
        Effect::CurrentOffset { i0 } => vec![("i0", i0)],
        _ => vec![],
    },
    fit_keys: |_| vec![("i0", -50.0, 50.0)],
    scale: |e, f| {
        if let Effect::CurrentOffset { i0 } = e {
            *i0 *= f
        }
    },
    harmonic: not_periodic,
    weak_torque: WeakTorque::None,
    // The column ∫φ carries the voltage −R·i0 of the offset.
    voltage: Some(Voltage {
        column: VoltageColumn::One,
        key: "i0",
        value: |x, r| -x / r,
        residual_floor: f64::NEG_INFINITY,
    }),
    on_residual: false,
    sindy: |_| terms(&[(Term::One, IN_CURRENT)]),
    diagnose: Diagnose {
        variants: |s| match s.current() {
            Some(_) => {
                let columns = vec![vec![1.0; s.len()]];
                let kind = EffectKind::CurrentOffset;
                vec![Variant::new(kind, Equation::Electrical, vec![], columns)]
            }
            None => vec![],
        },
        // A constant in the voltage equation, and `K_t·i0` in the torque equation.
        present: |_, s| match s.current() {
            Some(_) => vec![
                (Equation::Electrical, vec![1.0; s.len()]),
                (Equation::Mechanical, vec![1.0; s.len()]),
            ],
            None => vec![],
        },
        keys: |b, units, v| put(v, "i0", -b[0] / units.r),
        column_names: &[],
        torque_unit: "N·m",
        plausible: always_plausible,
        explain: |s| {
            format!(
                "the current sensor reads {:.3} A too much at zero current (offset)",
                s.get("i0")
            )
        },
    },
};

pub(super) fn key_mut<'a, D>(e: &'a mut Effect<D>, key: &str) -> Option<&'a mut D> {
    match (e, key) {
        (Effect::CurrentOffset { i0 }, "i0") => Some(i0),
        _ => None,
    }
}
