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
    diagnose: Diagnose {
        variants: |s| {
            GRID.iter()
                .map(|&vs0| {
                    let vs = vs0 * s.vscale;
                    let columns = vec![column(s, vs)];
                    let fixed = vec![("vs", vs)];
                    Variant::new(EffectKind::Stribeck, Equation::Mechanical, fixed, columns)
                })
                .collect()
        },
        present: |e, s| {
            let Effect::Stribeck { vs, .. } = *e else {
                return vec![];
            };
            let vs = if vs > 0.0 { vs } else { 3.5 };
            vec![(Equation::Mechanical, column(s, vs))]
        },
        keys: |b, _, v| put(v, "fs", b[0]),
        column_names: &["fs − fc (Stribeck)"],
        torque_unit: "N·m",
        plausible: |s| s.get("fs") > 0.0,
        explain: |s| {
            format!(
                "friction is {:.3} N·m higher at low speed and falls off above about {} rad/s (Stribeck)",
                s.get("fs"),
                s.get("vs")
            )
        },
    },
};

/// Grid of Stribeck velocities [rad/s] `diagnose` tries (times [`Signals::vscale`]): around
/// the paper's v0 = 3.7 rad/s, from the velocity resolution (≈1 rad/s) up to where Stribeck
/// merges with viscous friction.
pub const GRID: [f64; 6] = [1.0, 2.0, 3.5, 5.0, 8.0, 12.0];

/// `diagnose`'s column: `exp(−(ω/vs)²)·sgn(ω)` on the smoothed velocity.
fn column(s: &Signals, vs: f64) -> Vec<f64> {
    let sgn = s.sgn_omega();
    s.omega
        .iter()
        .zip(&sgn)
        .map(|(w, g)| (-(w / vs) * (w / vs)).exp() * g)
        .collect()
}

pub(super) fn key_mut<'a, D>(e: &'a mut Effect<D>, key: &str) -> Option<&'a mut D> {
    match (e, key) {
        (Effect::Stribeck { fs, .. }, "fs") => Some(fs),
        (Effect::Stribeck { vs, .. }, "vs") => Some(vs),
        _ => None,
    }
}
