//! `presliding`: the LuGre bristles, a spring before the surfaces slide.
use super::*;

/// Defaults: the compliance of a geared axis as seen at the rotor, where presliding becomes
/// visible. A size-14 harmonic drive winds up about 1 mrad at its output under its rated
/// torque (torsional stiffness of a few 10³ N·m/rad); with ratio 100 the rotor sees that
/// stiffness divided by 100², about 0.4 N·m/rad. With the paper's static friction
/// s(0) = α0 + α1 = 0.0975 N·m the breakaway deflection s(0)/σ0 is then 0.24 rad at the
/// rotor, 2.6 Hall steps (0.095 rad) of the paper's board. (The paper's own bristles,
/// σ0 = 317, deflect 0.3 mrad: far inside one Hall step, invisible.) σ1 = 0.022: critical
/// damping of the rotor inertia J = 3e-4 kg·m² on that spring, 2·√(σ0·J).
#[rustfmt::skip]
const KEYS: &[Key] = &[
    k("sigma0", "N·m/rad", 0.4, "bristle stiffness"),
    k("sigma1", "N·m·s/rad", 0.022, "bristle damping"),
];

pub static D: Descriptor = Descriptor {
    kind: EffectKind::Presliding,
    meaning: "elastic deflection of the contact (LuGre bristles) before it slides",
    keys: KEYS,
    help: None,
    check: no_check,
    to_effect: |s| Effect::Presliding {
        sigma0: s.get("sigma0"),
        sigma1: s.get("sigma1"),
    },
    values: |e| match *e {
        Effect::Presliding { sigma0, sigma1 } => vec![("sigma0", sigma0), ("sigma1", sigma1)],
        _ => vec![],
    },
    fit_keys: |_| vec![("sigma0", 1.0, 1e5), ("sigma1", 0.0, 1e3)],
    scale: |_, _| {},
    harmonic: not_periodic,
    weak_torque: WeakTorque::None,
    voltage: None,
    on_residual: false,
    // The z terms are already in the library.
    sindy: in_paper_library,
    // Its columns depend on the model's static friction law and the refitted inertia:
    // `diagnose` builds them itself with [`variants`], on every window.
    diagnose: Diagnose {
        variants: no_variants,
        present: |e, s| {
            let Effect::Presliding { sigma0, sigma1 } = *e else {
                return vec![];
            };
            let tau = if sigma0 > 0.0 && sigma1 > 0.0 {
                sigma1 / sigma0
            } else {
                0.07
            };
            vec![(Equation::Mechanical, s.breakaway_column(tau))]
        },
        keys: no_keys,
        column_names: &[],
        torque_unit: "N·m",
        plausible: always_plausible,
        explain: |s| {
            format!(
                "friction builds up over a deflection after each reversal and breakaway instead of switching at once (presliding, the LuGre bristle state, stiffness about {:.3} N·m/rad: `fit --model lugre` has it)",
                s.get("sigma0")
            )
        },
    },
};

/// Grid of breakaway deflections `s(0)/σ0` of a missing presliding, in angle steps (Hall
/// steps): from two steps to 8, a factor of 2 apart (the estimated σ0 is then within a factor
/// √2 of the best grid point). Where a sharp friction switch falls between two Hall edges is
/// uncertain by up to a full step of travel (the quantisation error spans ±½ step), so a
/// bristle that deflects one step cannot be told from ordinary stick-slip friction seen
/// through the sensor: on a plant with Karnopp stick-slip friction and no bristles at all,
/// a one-step variant was named on most seeds (`tests/tests/diagnose_verdict.rs`).
pub const DEFLECTION_GRID: [f64; 3] = [2.0, 4.0, 8.0];
/// Breakaway deflection [angle steps] of the nuisance term in the presliding test's base.
pub const NUISANCE_STEPS: f64 = 0.5;
/// Grid of breakaway time constants σ1/σ0 [s] for the breakaway column of a model that has
/// presliding: the paper's 22.2/317 = 70 ms, and a factor of about 2.5 either way.
pub const BREAKAWAY_GRID: [f64; 3] = [0.03, 0.07, 0.18];

/// Variants of a missing presliding on top of a static friction law `law` (its α0, α1, v0,
/// α2; σ0 and σ1 are set here): one per breakaway deflection of `grid` (in angle steps,
/// [`DEFLECTION_GRID`]), σ0 = s(0)/deflection, σ1 = 2·√(σ0·J) (critical damping of the rotor
/// inertia `inertia` on the bristle spring). The column is [`Signals::presliding_column`]:
/// the friction the bristles take away from (or add to) the static law after each reversal
/// and breakaway.
pub fn variants(
    s: &Signals,
    law: &control::lugre::LugreParams<f64>,
    inertia: f64,
    grid: &[f64],
) -> Vec<Variant> {
    let s0 = law.s(0.0);
    if !(s0 > 0.0 && s0.is_finite()) {
        return vec![];
    }
    let step = s.angle_step();
    grid.iter()
        .map(|&d| {
            let sigma0 = s0 / (d * step);
            let sigma1 = 2.0 * (sigma0 * inertia.max(0.0)).sqrt();
            let p = control::lugre::LugreParams {
                sigma0,
                sigma1,
                ..*law
            };
            let fixed = vec![("sigma0", sigma0), ("sigma1", sigma1)];
            let columns = vec![s.presliding_column(&p)];
            Variant::new(EffectKind::Presliding, Equation::Mechanical, fixed, columns)
        })
        .collect()
}

pub(super) fn key_mut<'a, D>(e: &'a mut Effect<D>, key: &str) -> Option<&'a mut D> {
    match (e, key) {
        (Effect::Presliding { sigma0, .. }, "sigma0") => Some(sigma0),
        (Effect::Presliding { sigma1, .. }, "sigma1") => Some(sigma1),
        _ => None,
    }
}
