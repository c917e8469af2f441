//! `cogging`: the magnets' pull toward the stator teeth, periodic in angle.
use super::*;
use std::f64::consts::PI;

#[rustfmt::skip]
const KEYS: &[Key] = &[
    k("harmonic", "1/rev", 7.0, "periods per revolution (2 or more)"),
    k("amp", "N·m", 0.03, "torque amplitude"),
    k("phase", "rad", 0.0, "phase"),
];

/// The harmonic is a whole number of 2 or more: one period per revolution is
/// `position_load`.
fn check(s: &EffectSpec) -> Result<()> {
    if let Some(h) = s.values.get("harmonic") {
        if *h < 2.0 || h.fract() != 0.0 || *h > 1000.0 {
            anyhow::bail!(
                "effect 'cogging': harmonic must be a whole number of 2 or more (got {}); \
                 one period per revolution is 'position_load'",
                crate::validate::show(*h)
            );
        }
    }
    Ok(())
}

pub static D: Descriptor = Descriptor {
    kind: EffectKind::Cogging,
    meaning: "torque ripple periodic in angle, several periods per revolution",
    keys: KEYS,
    help: None,
    check,
    to_effect: |s| Effect::Cogging {
        harmonic: s.get("harmonic").round().clamp(2.0, 1000.0) as u16,
        amp: s.get("amp"),
        phase: s.get("phase"),
    },
    values: |e| match *e {
        Effect::Cogging {
            harmonic,
            amp,
            phase,
        } => vec![
            ("harmonic", harmonic as f64),
            ("amp", amp),
            ("phase", phase),
        ],
        _ => vec![],
    },
    fit_keys: |_| vec![("amp", -10.0, 10.0), ("phase", -4.0 * PI, 4.0 * PI)],
    scale: |e, f| {
        if let Effect::Cogging { amp, .. } = e {
            *amp *= f
        }
    },
    harmonic: |e| match *e {
        Effect::Cogging { harmonic, .. } => Some(f64::from(harmonic)),
        _ => None,
    },
    weak_torque: WeakTorque::Periodic,
    voltage: None,
    on_residual: true,
    sindy: |s| {
        let h = s.get("harmonic").round().clamp(1.0, u16::MAX as f64) as u16;
        terms(&[(Term::SinTheta(h), IN_ACCEL), (Term::CosTheta(h), IN_ACCEL)])
    },
    diagnose: Diagnose {
        variants: |s| {
            let hmax = crate::diagnose::harmonics::resolvable(s.hall_resolution);
            (2..=hmax)
                .map(|h| {
                    let [a, b] = s.angle_pair(h);
                    let fixed = vec![("harmonic", h as f64)];
                    Variant::new(EffectKind::Cogging, Equation::Mechanical, fixed, vec![a, b])
                })
                .collect()
        },
        present: |e, s| {
            let Effect::Cogging { harmonic, .. } = *e else {
                return vec![];
            };
            let [a, b] = s.angle_pair(harmonic as u32);
            vec![(Equation::Mechanical, a), (Equation::Mechanical, b)]
        },
        keys: amp_phase,
        column_names: &[],
        torque_unit: "N·m",
        plausible: always_plausible,
        explain: |s| {
            format!(
                "a torque of {:.3} N·m repeats {} times per revolution (cogging between magnets and stator teeth)",
                s.get("amp"),
                s.get("harmonic")
            )
        },
    },
};

/// [`Diagnose::keys`] of a sine and a cosine column of an angle harmonic: amplitude and phase.
pub(super) fn amp_phase(b: &[f64], _: Units, v: &mut BTreeMap<String, f64>) {
    let (amp, phase) = crate::diagnose::harmonics::amp_phase(b[0], b[1]);
    put(v, "amp", amp);
    put(v, "phase", phase);
}

pub(super) fn key_mut<'a, D>(e: &'a mut Effect<D>, key: &str) -> Option<&'a mut D> {
    match (e, key) {
        (Effect::Cogging { amp, .. }, "amp") => Some(amp),
        (Effect::Cogging { phase, .. }, "phase") => Some(phase),
        _ => None,
    }
}
