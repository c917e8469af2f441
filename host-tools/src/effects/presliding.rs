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
};

pub(super) fn key_mut<'a, D>(e: &'a mut Effect<D>, key: &str) -> Option<&'a mut D> {
    match (e, key) {
        (Effect::Presliding { sigma0, .. }, "sigma0") => Some(sigma0),
        (Effect::Presliding { sigma1, .. }, "sigma1") => Some(sigma1),
        _ => None,
    }
}
