//! `compliance`: a second inertia on a spring-damper coupling.
use super::*;

/// Default: a load twice the paper rotor's inertia on a coupling that resonates near 5 Hz,
/// lightly damped (ζ ≈ 0.05), as a flexible coupling or a long shaft.
#[rustfmt::skip]
const KEYS: &[Key] = &[
    k("j2", "kg·m²", 6e-4, "inertia of the load behind the coupling"),
    // A spring or damper of negative sign would give energy back: the coupled free run and
    // the plant would be unstable, and the implicit step's divisor j2/h + k·h + c could vanish.
    k0("k", "N·m/rad", 0.2, "stiffness of the coupling"),
    k0("c", "N·m·s/rad", 6e-4, "damping of the coupling"),
];

pub static D: Descriptor = Descriptor {
    kind: EffectKind::Compliance,
    meaning: "a load inertia behind a spring-damper coupling (a resonance)",
    keys: KEYS,
    help: None,
    check: no_check,
    to_effect: |s| Effect::Compliance {
        j2: s.get("j2"),
        k: s.get("k"),
        c: s.get("c"),
    },
    values: |e| match *e {
        Effect::Compliance { j2, k, c } => vec![("j2", j2), ("k", k), ("c", c)],
        _ => vec![],
    },
    // A load from a hundredth to a hundred times a small rotor, couplings from 0.5 Hz up.
    fit_keys: |_| vec![("j2", 1e-6, 1.0), ("k", 1e-4, 1e4), ("c", 0.0, 10.0)],
    scale: |e, f| {
        if let Effect::Compliance { j2, .. } = e {
            *j2 *= f
        }
    },
    harmonic: not_periodic,
    weak_torque: WeakTorque::None,
    voltage: None,
    on_residual: false,
    sindy: |_| {
        anyhow::bail!(
            "--add compliance: a SINDYc library has no load state for a second inertia; fit --model lugre --add compliance"
        )
    },
    diagnose: Diagnose {
        // A load on a coupling, over natural frequencies from a few periods per log to the
        // sample rate's reach ([`grid`]), each lightly or well damped ([`ZETA`]).
        variants: |s| {
            grid(s)
                .into_iter()
                .flat_map(|f| ZETA.iter().map(move |&z| (f, z)))
                .map(|(f, z)| {
                    let columns = vec![s.load_acceleration(f, z)];
                    let fixed = vec![("fn", f), ("zeta", z)];
                    Variant::new(EffectKind::Compliance, Equation::Mechanical, fixed, columns)
                })
                .collect()
        },
        present: |e, s| match *e {
            Effect::Compliance { j2, k, c } if j2 > 0.0 && k > 0.0 => {
                let wn = (k / j2).sqrt();
                let f = wn / (2.0 * std::f64::consts::PI);
                let z = c / (2.0 * (k * j2).sqrt());
                vec![(Equation::Mechanical, s.load_acceleration(f, z))]
            }
            _ => vec![],
        },
        // The coefficient is j2; the grid's natural frequency and damping ratio give k and c.
        keys: |b, _, values| {
            let f = values.remove("fn").unwrap_or(0.0);
            let z = values.remove("zeta").unwrap_or(0.0);
            let wn = 2.0 * std::f64::consts::PI * f;
            values.insert("j2".into(), b[0]);
            values.insert("k".into(), b[0] * wn * wn);
            values.insert("c".into(), 2.0 * z * wn * b[0]);
        },
        column_names: &[],
        torque_unit: "kg·m²",
        plausible: |s| s.get("j2") > 0.0,
        explain: |s| {
            format!(
                "a second inertia of {:.2e} kg·m² follows the rotor through a compliant coupling resonating near {:.2} Hz against a fixed rotor (a flexible coupling, a long shaft, a belt)",
                s.get("j2"),
                (s.get("k") / s.get("j2")).sqrt() / (2.0 * std::f64::consts::PI)
            )
        },
    },
};

/// Damping ratios of a missing compliance: a lightly damped coupling (a flexible coupling,
/// a long shaft: ζ ≈ 0.05) and a well damped one (an elastomer coupling, a belt: ζ ≈ 0.3).
pub const ZETA: [f64; 2] = [0.05, 0.3];

/// Natural frequencies [Hz] of a missing compliance, a factor 1.4 apart (the resonance's
/// half-power width at ζ = 0.3): from 8 periods per log up to ten times the input's RMS
/// frequency ([`crate::diagnose::carriers::rms_frequency`]), the weak-form window's reach
/// (1.5/half-width) and 0.45 of the sample rate, whichever is lowest. A coupling far above
/// the excitation's band moves with the rotor: its column differs from the inertia's by
/// (f/f_n)², and fitting that difference would fit the sensor chain's lag instead.
pub fn grid(s: &Signals) -> Vec<f64> {
    let span = s.t.last().copied().unwrap_or(0.0) - s.t.first().copied().unwrap_or(0.0);
    if span <= 0.0 || s.dt <= 0.0 {
        return vec![];
    }
    let half_s = crate::numerics::weak_form::HALF_WIDTH_S.max(2.0 * s.dt);
    let f_u = crate::diagnose::carriers::rms_frequency(&s.raw_u, s.dt);
    let lo = 8.0 / span;
    let hi =
        (0.45 / s.dt)
            .min(1.5 / half_s)
            .min(if f_u > 0.0 { 10.0 * f_u } else { f64::INFINITY });
    let mut v = Vec::new();
    let mut f = lo;
    while f <= hi && v.len() < 40 {
        v.push(f);
        f *= 1.4;
    }
    v
}

pub(super) fn key_mut<'a, D>(e: &'a mut Effect<D>, key: &str) -> Option<&'a mut D> {
    match (e, key) {
        (Effect::Compliance { j2, .. }, "j2") => Some(j2),
        (Effect::Compliance { k, .. }, "k") => Some(k),
        (Effect::Compliance { c, .. }, "c") => Some(c),
        _ => None,
    }
}
