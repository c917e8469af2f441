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
    diagnose: Diagnose {
        // One variant per gap of [`gaps`], the column [`Signals::backlash_acceleration`] (its
        // coefficient is the load's inertia j2).
        variants: |s| {
            gaps(s)
                .into_iter()
                .map(|gap| {
                    let columns = vec![s.backlash_acceleration(gap)];
                    let fixed = vec![("gap", gap)];
                    Variant::new(EffectKind::Backlash, Equation::Mechanical, fixed, columns)
                })
                .collect()
        },
        present: |e, s| match *e {
            Effect::Backlash { j2, gap } if j2 > 0.0 => {
                vec![(Equation::Mechanical, s.backlash_acceleration(gap))]
            }
            _ => vec![],
        },
        keys: |b, _, v| put(v, "j2", b[0]),
        column_names: &[],
        torque_unit: "kg·m²",
        plausible: |s| s.get("j2") > 0.0,
        explain: |s| {
            format!(
                "a load of {:.2e} kg·m² is dragged along only after the rotor has turned {:.3} rad alone past each reversal (backlash in a gear or coupling)",
                s.get("j2"),
                s.get("gap")
            )
        },
    },
};

/// Gaps [rad] a backlash is tested at, a factor 1.6 apart (the gap is then estimated within
/// a factor of about 1.26): from two angle quantisation steps (a gap of one step hides in
/// the quantisation of the angle) up to the median angle the rotor travels between two
/// reversals ([`Signals::median_swing`]; a gap wider than most swings is closed only on the
/// longest ones, and its column rests on those few), at most 12 gaps. None when the log has
/// fewer than two reversals: the load then parts from the rotor only where it slows down,
/// and a gap cannot be told from the load's own inertia.
pub fn gaps(s: &Signals) -> Vec<f64> {
    let step = s.angle_step();
    if !(step.is_finite() && step > 0.0) {
        return vec![];
    }
    let Some(top) = s.median_swing() else {
        return vec![];
    };
    (0..12)
        .map(|k| 2.0 * step * 1.6f64.powi(k))
        .take_while(|g| *g <= top)
        .collect()
}

pub(super) fn key_mut<'a, D>(e: &'a mut Effect<D>, key: &str) -> Option<&'a mut D> {
    match (e, key) {
        (Effect::Backlash { j2, .. }, "j2") => Some(j2),
        (Effect::Backlash { gap, .. }, "gap") => Some(gap),
        _ => None,
    }
}
