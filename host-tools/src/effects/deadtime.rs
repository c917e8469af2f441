//! `deadtime`: the inverter's voltage loss, with the sign of the current.
use super::*;

const KEYS: &[Key] = &[k(
    "vd",
    "V",
    0.3,
    "inverter voltage loss, sign of the current",
)];

pub static D: Descriptor = Descriptor {
    kind: EffectKind::Deadtime,
    meaning: "voltage the inverter loses to its dead time, with the sign of the current",
    keys: KEYS,
    help: None,
    check: no_check,
    to_effect: |s| Effect::Deadtime { vd: s.get("vd") },
    values: |e| match *e {
        Effect::Deadtime { vd } => vec![("vd", vd)],
        _ => vec![],
    },
    fit_keys: |_| vec![("vd", -5.0, 5.0)],
    scale: |e, f| {
        if let Effect::Deadtime { vd } = e {
            *vd *= f
        }
    },
    harmonic: not_periodic,
    weak_torque: WeakTorque::None,
    voltage: Some(Voltage {
        column: VoltageColumn::SignOfCurrent,
        key: "vd",
        value: |x, _| x,
        residual_floor: 0.0,
    }),
    on_residual: false,
    sindy: |_| terms(&[(Term::SgnI, IN_CURRENT)]),
    diagnose: Diagnose {
        variants: |s| match column(s) {
            Some(c) => vec![Variant::new(
                EffectKind::Deadtime,
                Equation::Electrical,
                vec![],
                vec![c],
            )],
            None => vec![],
        },
        present: |_, s| {
            column(s)
                .map(|c| (Equation::Electrical, c))
                .into_iter()
                .collect()
        },
        keys: |b, _, v| put(v, "vd", b[0]),
        column_names: &[],
        torque_unit: "N·m",
        plausible: |s| s.get("vd") > 0.0,
        explain: |s| {
            format!(
                "the inverter loses {:.3} V with the sign of the current (dead time)",
                s.get("vd")
            )
        },
    },
};

/// `diagnose`'s column, `sgn(I)` smoothed, on a voltage plant with a measured current.
fn column(s: &Signals) -> Option<Vec<f64>> {
    use control::effects::{smooth_sign, CURRENT_EPS};
    let i = s.current()?;
    Some(i.iter().map(|c| smooth_sign(*c, CURRENT_EPS)).collect())
}

pub(super) fn key_mut<'a, D>(e: &'a mut Effect<D>, key: &str) -> Option<&'a mut D> {
    match (e, key) {
        (Effect::Deadtime { vd }, "vd") => Some(vd),
        _ => None,
    }
}
