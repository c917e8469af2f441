//! `stribeck`: the breakaway friction above Coulomb's that fades with speed.
use super::*;

#[rustfmt::skip]
const KEYS: &[Key] = &[
    k("fs", "N·m", 0.04, "breakaway torque above Coulomb"),
    k("vs", "rad/s", 5.0, "Stribeck velocity"),
];

/// The torque per N·m of `fs`: `exp(−(ω/vs)²)·sgn(ω)`.
fn per_fs(s: &TorqueSignals) -> Vec<f64> {
    let Effect::Stribeck { vs, .. } = *s.effect else {
        return vec![0.0; s.ws.len()];
    };
    s.ws.iter()
        .zip(s.sgn)
        .map(|(w, g)| (-(w / vs).powi(2)).exp() * g)
        .collect()
}

pub static D: Descriptor = Descriptor {
    kind: EffectKind::Stribeck,
    meaning: "extra friction at breakaway that fades above the Stribeck velocity",
    keys: KEYS,
    help: None,
    check: no_check,
    to_effect: |s| Effect::Stribeck {
        fs: s.get("fs"),
        vs: s.get("vs"),
    },
    values: |e| match *e {
        Effect::Stribeck { fs, vs } => vec![("fs", fs), ("vs", vs)],
        _ => vec![],
    },
    fit_keys: |_| vec![("fs", 0.0, 10.0), ("vs", 0.05, 500.0)],
    scale: |e, f| {
        if let Effect::Stribeck { fs, .. } = e {
            *fs *= f
        }
    },
    harmonic: not_periodic,
    weak_torque: WeakTorque::PerKey(&[("fs", per_fs)]),
    voltage: None,
    on_residual: false,
    sindy: |s| {
        Ok(SindyTerms {
            terms: vec![(Term::StribeckXdot, IN_ACCEL)],
            vs: Some(s.get("vs")),
        })
    },
};

pub(super) fn key_mut<'a, D>(e: &'a mut Effect<D>, key: &str) -> Option<&'a mut D> {
    match (e, key) {
        (Effect::Stribeck { fs, .. }, "fs") => Some(fs),
        (Effect::Stribeck { vs, .. }, "vs") => Some(vs),
        _ => None,
    }
}
