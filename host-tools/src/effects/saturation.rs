//! `saturation`: a torque constant falling with current.
use super::*;

/// Default k = 2e-4/A²: K_t down 2 % at 10 A and 24 % at 40 A, the board's peak rating;
/// small BLDC motors lose 10-30 % of K_t at two to three times their continuous current.
const KEYS: &[Key] = &[k(
    "k",
    "1/A²",
    2e-4,
    "torque constant falls as K_t/(1 + k·I²)",
)];

pub static D: Descriptor = Descriptor {
    kind: EffectKind::Saturation,
    meaning: "torque constant falling at high current as the iron saturates",
    keys: KEYS,
    help: None,
    check: no_check,
    to_effect: |s| Effect::Saturation { k: s.get("k") },
    values: |e| match *e {
        Effect::Saturation { k } => vec![("k", k)],
        _ => vec![],
    },
    // Up to K_t halved at 1 A: far beyond any real motor, a bound only against runaway.
    fit_keys: |_| vec![("k", 0.0, 1.0)],
    scale: |e, f| {
        if let Effect::Saturation { k } = e {
            *k *= f
        }
    },
    harmonic: not_periodic,
    // The torque a falling K_t loses, to first order in k: K_t·k·I³.
    weak_torque: WeakTorque::PerKey(&[("k", |s| s.cur.iter().map(|c| s.kt * c * c * c).collect())]),
    voltage: None,
    on_residual: false,
    sindy: |_| terms(&[(Term::ICubed, IN_ACCEL)]),
    // The candidate's column is `K_t·I³` per sample interval of the current the model's own
    // noise-free run draws from the log's input (`Signals::saturation_intervals` on the run),
    // less what the model's own columns make of that run
    // (`diagnose::candidates::saturation_beyond_run`): the measured current is the torque
    // equation's left side over R, and a column built from it fits the model's residual with
    // itself wherever the current's magnitude holds still. `diagnose` puts the run's column in
    // place of this sample column and drops the candidate where there is no run
    // (docs/decisions/0031-thermal-and-saturation-candidates.md). Its present column needs the
    // fitted R: `diagnose` adds it to the torque equation's base itself.
    diagnose: Diagnose {
        variants: |s| match s.current() {
            Some(i) => {
                let column = i.iter().map(|c| s.kt * c * c * c).collect();
                vec![Variant::new(
                    EffectKind::Saturation,
                    Equation::Mechanical,
                    vec![],
                    vec![column],
                )]
            }
            None => vec![],
        },
        present: no_columns,
        keys: |b, _, v| put(v, "k", b[0]),
        column_names: &[],
        torque_unit: "N·m",
        plausible: |s| s.get("k") > 0.0,
        explain: |s| {
            format!(
                "the torque constant falls at high current (magnetic saturation, K_t/(1 + k·I²) with k = {:.2e}/A², {:.0}% lower at 20 A)",
                s.get("k"),
                100.0 * (1.0 - 1.0 / (1.0 + s.get("k") * 400.0))
            )
        },
    },
};

pub(super) fn key_mut<'a, D>(e: &'a mut Effect<D>, key: &str) -> Option<&'a mut D> {
    match (e, key) {
        (Effect::Saturation { k }, "k") => Some(k),
        _ => None,
    }
}
