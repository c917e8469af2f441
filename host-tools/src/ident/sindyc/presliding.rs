//! `fit --model sindyc --add presliding`: the friction's sign carried by a bristle state
//! instead of a sign function of the velocity (docs/decisions/0015-sindyc-bristle.md).
//!
//! With `w = z` the bristle deflection normalised by its sliding value `z_ss`,
//!
//! ```text
//! dw/dt  = (ẋ − |ẋ|·w) / z_ss          [1/s]   (bristle)
//! dẋ/dt  = … + c_C·w − d·(ẋ − |ẋ|·w)   [rad/s²] (friction)
//! ```
//!
//! `c_C·w` is the Coulomb friction (in sliding `w = sgn ẋ`), and `d·z_ss·dw/dt` the
//! bristle's damping, which holds the rotor for a moment at every reversal while the
//! bristle turns over: the current then follows the held voltage without back-EMF. Both
//! equations are sums of library terms (`xdot`, `z`, `|xdot|*z`), so the model stays a
//! SINDYc model: the free run, the model file and the evaluator need nothing else.
//!
//! The deflection is far below a Hall step, so the angle cannot show it and no regression
//! can: the two bristle numbers (`1/z_ss`, `d`) start from a grid and are refined with
//! every other coefficient of the acceleration and bristle equations on the free-run
//! simulation error (velocity, current and angle: the current is what shows the dwell).
use super::refine::{self, SimResiduals};
use anyhow::{bail, Result};
use control::sindy::{SindyModel, SparseEq, Term};

/// Starts of the bristle's sliding deflection `z_ss` as fractions of the Hall step, half a
/// decade apart: the deflection is below what the sensor resolves (else it would be a
/// visible spring, the emulator's geared-axis `presliding` effect), so the grid spans
/// 10^-3 to 10^-0.5 of it.
const Z_SS_DECADES: (i32, i32) = (-6, -1);

/// Starts of the bristle damping `d` [1/s] (the damping torque over the inertia), half a
/// decade apart: from a damping that stops the rotor in a tenth of a second (10 1/s) to one
/// that holds it for a whole 12 ms sample per milliradian of turnover (1e6 1/s).
const DAMPING_DECADES: (i32, i32) = (2, 12);

/// `10^(k/2)` for the half-decades `k` of `range` (inclusive).
fn half_decades(range: (i32, i32)) -> impl Iterator<Item = f64> {
    (range.0..=range.1).map(|k| 10f64.powf(f64::from(k) / 2.0))
}

/// The cost the refinement minimises.
fn cost(res: &SimResiduals, m: &SindyModel<f64>, weight: f64) -> Option<f64> {
    let r = res.eval(m, weight).ok()?;
    let c: f64 = r.iter().map(|v| v * v).sum();
    c.is_finite().then_some(c)
}

/// The model with its friction sign carried by the bristle state: every sign-like velocity
/// term of the acceleration equation (`tanh(a*xdot)`, `sgn(xdot)`) becomes the Coulomb term
/// `z` with the same coefficient, the bristle damping `d` is added, and the `z` equation is
/// the bristle equation with the deflection `z_ss` [rad] (`damping` `d` in 1/s). The extracted `z` of the other equations is
/// dropped (the bristle takes its place). Errors when the model has no Coulomb term.
pub fn with_bristle(m: &SindyModel<f64>, z_ss: f64, damping: f64) -> Result<SindyModel<f64>> {
    let coulomb: f64 = m
        .accel
        .terms
        .iter()
        .filter(|(t, _)| matches!(t, Term::TanhXdot | Term::SgnXdot))
        .map(|(_, c)| c)
        .sum();
    if coulomb == 0.0 {
        bail!(
            "--add presliding: the SINDYc model has no Coulomb friction term (tanh(a*xdot) \
             or sgn(xdot)) for the bristle to carry"
        );
    }
    let keep = |eq: &SparseEq<f64>| -> Vec<(Term, f64)> {
        eq.terms
            .iter()
            .filter(|(t, _)| !t.has_z() && !matches!(t, Term::TanhXdot | Term::SgnXdot))
            .copied()
            .collect()
    };
    let mut accel = keep(&m.accel);
    match accel.iter_mut().find(|(t, _)| *t == Term::Xdot) {
        Some((_, c)) => *c -= damping,
        None => accel.push((Term::Xdot, -damping)),
    }
    accel.push((Term::Z, coulomb));
    accel.push((Term::AbsXdotZ, damping));
    let k = 1.0 / z_ss;
    let eq = |v: &[(Term, f64)]| {
        SparseEq::from_slice(v).ok_or_else(|| {
            anyhow::anyhow!("--add presliding: the SINDYc equation has too many terms")
        })
    };
    let mut out = m.clone();
    out.accel = eq(&accel)?;
    out.zdot = eq(&[(Term::Xdot, k), (Term::AbsXdotZ, -k)])?;
    out.idot = eq(&keep(&m.idot))?;
    out.z_max = 1.0;
    Ok(out)
}

/// The presliding model from a fitted SINDYc model `m`: the grid start ([`Z_SS_DECADES`]
/// of `hall` [rad] × [`DAMPING_DECADES`]) with the lowest free-run cost on the fitting runs
/// of `res`, refined by Levenberg–Marquardt on the same cost. Errors when `m` has no
/// Coulomb term or every start diverges.
pub fn fit(m: &SindyModel<f64>, hall: f64, res: &SimResiduals) -> Result<SindyModel<f64>> {
    let hall = if hall.is_finite() && hall > 0.0 {
        hall
    } else {
        crate::emulator::sensors::hall_resolution(crate::emulator::DEFAULT_POLE_PAIRS)
    };
    let weight = res.current_weight(m)?;
    let mut best: Option<(f64, SindyModel<f64>)> = None;
    for f in half_decades(Z_SS_DECADES) {
        for d in half_decades(DAMPING_DECADES) {
            let cand = with_bristle(m, f * hall, d)?;
            let Some(c) = cost(res, &cand, weight) else {
                continue;
            };
            if best.as_ref().is_none_or(|(b, _)| c < *b) {
                best = Some((c, cand));
            }
        }
    }
    let Some((_, start)) = best else {
        bail!("--add presliding: every start of the bristle diverges in free run");
    };
    refine::refine_model(&start, res, refine::REFINE_ITER)
}

#[cfg(test)]
mod tests {
    use super::*;
    use control::sindy::TermInputs;

    fn plain() -> SindyModel<f64> {
        let mut m = SindyModel::empty(100.0, 4.0, 3e-4);
        m.accel = SparseEq::from_slice(&[
            (Term::Xdot, -5.0),
            (Term::I, 230.0),
            (Term::TanhXdot, -260.0),
            (Term::Z, 3.0),
        ])
        .unwrap();
        m.zdot = SparseEq::from_slice(&[(Term::Z, -2.0)]).unwrap();
        m.idot =
            SparseEq::from_slice(&[(Term::Xdot, -240.0), (Term::I, -700.0), (Term::U, 3300.0)])
                .unwrap();
        m
    }

    #[test]
    fn in_sliding_the_bristle_model_has_the_friction_of_the_sign_model() {
        let m = plain();
        let b = with_bristle(&m, 1e-3, 5e4).unwrap();
        assert_eq!(b.z_max, 1.0);
        assert_eq!(b.idot, m.idot);
        for v in [-40.0, -2.0, 0.5, 30.0] {
            // The sliding bristle: w = sgn(ẋ), where the bristle equation is at rest.
            let w = f64::signum(v);
            let p = TermInputs {
                xdot: v,
                z: w,
                i: 2.0,
                ..Default::default()
            };
            assert_eq!(b.zdot_rhs(&p), 0.0);
            let plain_p = TermInputs { z: 0.0, ..p };
            let want = m.accel_rhs(&plain_p);
            let got = b.accel_rhs(&p);
            // tanh(100·v) is ±1 to 1e-40 at these speeds; the damping cancels exactly.
            assert!(
                (got - want).abs() <= 1e-9 * want.abs(),
                "{v}: {got} vs {want}"
            );
        }
    }

    #[test]
    fn a_model_without_a_coulomb_term_is_refused() {
        let mut m = plain();
        m.accel = SparseEq::from_slice(&[(Term::Xdot, -5.0), (Term::I, 230.0)]).unwrap();
        let e = with_bristle(&m, 1e-3, 5e4).unwrap_err().to_string();
        assert!(e.contains("Coulomb"), "{e}");
    }
}
