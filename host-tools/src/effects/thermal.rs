//! `thermal`: the winding resistance rising as the motor heats.
use super::*;

/// Defaults: copper's resistance rises 0.393 %/K; k = 0.02/A² is +8 % (≈ +20 K of winding)
/// at 2 A steady and +2 % at 1 A, what a small BLDC motor with a few K/W winding-to-ambient
/// reaches at the paper's currents (a tenth of it, +0.8 %, is too small to see in a 60–90 s
/// log). tau = 30 s: a small motor's winding thermal time constant (the case takes minutes).
#[rustfmt::skip]
const KEYS: &[Key] = &[
    k("k", "1/A²", 0.02, "relative resistance rise per A² of steady current"),
    k("tau", "s", 30.0, "thermal time constant"),
];

pub static D: Descriptor = Descriptor {
    kind: EffectKind::Thermal,
    meaning: "winding resistance rising as the current heats the motor",
    keys: KEYS,
    help: None,
    check: no_check,
    to_effect: |s| Effect::Thermal {
        k: s.get("k"),
        tau: s.get("tau"),
    },
    values: |e| match *e {
        Effect::Thermal { k, tau } => vec![("k", k), ("tau", tau)],
        _ => vec![],
    },
    fit_keys: |_| vec![("k", 0.0, 1.0), ("tau", 0.5, 1e4)],
    scale: |e, f| {
        if let Effect::Thermal { k, .. } = e {
            *k *= f
        }
    },
    harmonic: not_periodic,
    weak_torque: WeakTorque::None,
    voltage: None,
    on_residual: false,
    // The library's term inputs carry no heat state: the instantaneous I² stands in for
    // the running mean of I² that heats the winding (the proxy at thermal equilibrium).
    sindy: |_| terms(&[(Term::ISquared, IN_CURRENT)]),
    diagnose: Diagnose {
        variants: |s| {
            if s.current().is_none() {
                return vec![];
            }
            let duration = s.t.last().copied().unwrap_or(0.0) - s.t.first().copied().unwrap_or(0.0);
            GRID.iter()
                .filter(|&&tau| tau <= 2.0 * duration.max(5.0))
                .map(|&tau| {
                    let columns = vec![s.thermal_column(tau)];
                    let fixed = vec![("tau", tau)];
                    Variant::new(EffectKind::Thermal, Equation::Electrical, fixed, columns)
                })
                .collect()
        },
        present: |e, s| match *e {
            Effect::Thermal { tau, .. } if s.current().is_some() => {
                vec![(Equation::Electrical, s.thermal_column(tau.max(0.1)))]
            }
            _ => vec![],
        },
        keys: |b, units, v| put(v, "k", b[0] / units.r),
        column_names: &[],
        torque_unit: "N·m",
        plausible: |s| s.get("k") > 0.0,
        explain: |s| {
            format!(
                "the winding resistance rises as the current heats the motor ({:.1e} per A², time constant {} s)",
                s.get("k"),
                s.get("tau")
            )
        },
    },
};

/// Grid of thermal time constants [s] `diagnose` tries, doubling from a small motor's
/// winding (10 s: tens of grams of copper, a few J/K, on a few K/W to the stator) to its case
/// (10 min: the frame's heat capacity on its path to ambient). A log shows a time constant up
/// to about twice its own length; beyond that the heat state rises along the log as
/// `∫I²·dt/τ` whatever `τ`, one column shape, so longer values add no variant.
pub const GRID: [f64; 7] = [10.0, 20.0, 40.0, 80.0, 160.0, 320.0, 640.0];

pub(super) fn key_mut<'a, D>(e: &'a mut Effect<D>, key: &str) -> Option<&'a mut D> {
    match (e, key) {
        (Effect::Thermal { k, .. }, "k") => Some(k),
        (Effect::Thermal { tau, .. }, "tau") => Some(tau),
        _ => None,
    }
}
