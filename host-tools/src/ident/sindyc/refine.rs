//! The refinement stage: the coefficients of a sparse structure (and the tanh gain `a`)
//! refined by bounded Levenberg–Marquardt ([`crate::ident::nlsq`]) on the free-run
//! simulation error, as the LuGre model's dynamic step does. The weak form gets the structure
//! and a start; the simulation error then corrects what the weak form cannot see (the lag of
//! a quasi-static current, the bias of the sign-like terms on Hall-quantised data). The
//! current equation keeps the coefficients of its held-voltage regression
//! ([`super::rows::held_current_normal`]): it is the sampled current's own law, and moving
//! it to help the velocity fit trades a right equation for a wrong one (and one free run per
//! coefficient per iteration).
use super::simulate::{simulate, Limits};
use super::ParetoRow;
use crate::ident::library::IDOT;
use crate::ident::{nlsq, sensor_chain, sim_error};
use crate::log::{MotorLog, Plant};
use anyhow::Result;
use control::sindy::{SindyModel, Term};

/// Weight of the angle residual of the refinement relative to velocity and current (as the
/// grey-box refinement's, `sim_error.rs`: the free-run angle integrates every velocity error,
/// so it only steers the low frequencies).
const REFINE_ANGLE_WEIGHT: f64 = 0.3;
/// Weight of the current residual of the refinement relative to velocity. The current
/// equation itself is not refined (its coefficients come from the held-voltage regression),
/// so the current residual only steers the mechanical equations. At 12 ms the current is
/// `(u − K_b·ẋ)/R` within a sample, and most of its free-run error sits in the few samples
/// after each velocity reversal, where presliding (the bristles of a LuGre law turning
/// round under a damping far above the viscous one) holds the rotor for several
/// milliseconds: no sign-like or Stribeck term reproduces that, and at the velocity's weight
/// those samples bias the inertia and the friction level to imitate it. A tenth keeps the
/// current as a check on the velocity's level without that bias; on the emulated paper
/// motor it is what brings the validation fit of the current closest to the true model's on
/// both fitting seeds tried (docs/performance-sindyc.md).
const REFINE_CURRENT_WEIGHT: f64 = 0.1;
/// Iteration limit of the refinement (one Jacobian = one free run per coefficient each).
const REFINE_ITER: usize = 25;
/// Largest model (terms over all equations) the refinement takes on: each iteration costs
/// one free run per coefficient, and the sparse models the thresholding returns have 5–10.
const REFINE_MAX_TERMS: usize = 16;
/// Range of the tanh gain `a` [s/rad] the refinement may move to: from a soft sign
/// (0.5 s/rad, step complete at 5 rad/s) to one sharper than a sample of the paper's
/// velocity resolution can resolve (100 s/rad).
const REFINE_A_RANGE: (f64, f64) = (0.5, 100.0);
/// Range of the Stribeck velocity `vs` the refinement may move to, relative to its start:
/// a decade either side.
const REFINE_VS_FACTOR: f64 = 10.0;

/// Free-run residuals of a SINDYc model on the fitting logs, defined as the grey-box
/// refinement's (`sim_error.rs`): velocity (the model's angle through the firmware's moving
/// average, not quantised so the cost stays smooth in the coefficients), current and angle
/// (weights [`REFINE_CURRENT_WEIGHT`], [`REFINE_ANGLE_WEIGHT`]), each normalised by the spread of the measured signal.
pub struct SimResiduals<'a> {
    logs: &'a [MotorLog],
    omega: Vec<Vec<f64>>,
    spreads: Vec<(f64, f64, f64)>,
    plant: Plant,
    window: usize,
    limits: Limits,
}

impl<'a> SimResiduals<'a> {
    pub fn new(logs: &'a [MotorLog], plant: Plant, window: usize, limits: Limits) -> Self {
        let omega: Vec<Vec<f64>> = logs
            .iter()
            .map(|l| sensor_chain::measured_velocity(l, window))
            .collect();
        let spreads = logs
            .iter()
            .zip(&omega)
            .map(|(l, w)| {
                (
                    sim_error::spread(w),
                    l.i.as_deref().map(sim_error::spread).unwrap_or(1.0),
                    sim_error::spread(&l.theta),
                )
            })
            .collect();
        SimResiduals {
            logs,
            omega,
            spreads,
            plant,
            window,
            limits,
        }
    }

    fn eval(&self, m: &SindyModel<f64>) -> Result<Vec<f64>> {
        use rayon::prelude::*;
        let runs: Vec<Vec<f64>> = self
            .logs
            .par_iter()
            .zip(&self.omega)
            .zip(&self.spreads)
            .map(|((log, w), &(sw, si, sx))| -> Result<Vec<f64>> {
                let p = simulate(m, self.plant, log, self.limits)?;
                let wp = sensor_chain::velocity_estimate(&p.t, &p.theta, self.window);
                let mut r: Vec<f64> = wp.iter().zip(w).map(|(a, b)| (a - b) / sw).collect();
                if let (Some(im), Some(ip)) = (&log.i, &p.i) {
                    r.extend(
                        ip.iter()
                            .zip(im)
                            .map(|(a, b)| REFINE_CURRENT_WEIGHT * (a - b) / si),
                    );
                }
                r.extend(
                    p.theta
                        .iter()
                        .zip(&log.theta)
                        .map(|(a, b)| REFINE_ANGLE_WEIGHT * (a - b) / sx),
                );
                Ok(r)
            })
            .collect::<Result<_>>()?;
        Ok(runs.concat())
    }
}

/// Which numbers of a model the refinement moves: every coefficient of the acceleration and
/// `z` equations (equation, position in its term list), and the shape parameters its terms
/// use: the tanh gain `a` and the Stribeck velocity `vs`.
struct Slots {
    coef: Vec<(usize, usize)>,
    a: bool,
    vs: bool,
}

fn refine_slots(m: &SindyModel<f64>) -> Slots {
    let mut slots = Slots {
        coef: Vec::new(),
        a: false,
        vs: false,
    };
    for (e, eq) in [&m.accel, &m.zdot, &m.idot].into_iter().enumerate() {
        for (k, (t, _)) in eq.terms.iter().enumerate() {
            if e != IDOT {
                slots.coef.push((e, k));
            }
            slots.a |= matches!(t, Term::TanhXdot | Term::TanhZ);
            slots.vs |= *t == Term::StribeckXdot;
        }
    }
    slots
}

fn with_values(base: &SindyModel<f64>, slots: &Slots, x: &[f64]) -> SindyModel<f64> {
    let mut m = base.clone();
    for (&(e, k), v) in slots.coef.iter().zip(x) {
        let eq = match e {
            0 => &mut m.accel,
            1 => &mut m.zdot,
            _ => &mut m.idot,
        };
        eq.terms[k].1 = *v;
    }
    let mut rest = x[slots.coef.len()..].iter();
    if slots.a {
        m.a = *rest.next().expect("a slot for a");
    }
    if slots.vs {
        m.vs = *rest.next().expect("a slot for vs");
    }
    m
}

/// Refine the coefficients of a model's sparse structure (and the tanh gain) by bounded
/// Levenberg–Marquardt ([`nlsq`]) on the free-run simulation error of the fitting
/// logs, as the LuGre model's dynamic step does. The weak form gets the structure and a
/// start; the simulation error then corrects what the weak form cannot see (the lag of a
/// quasi-static current, the bias of the sign-like terms on Hall-quantised data). Each
/// coefficient may move within ±10 times its magnitude around the start (so it can change
/// sign but cannot run off); a trial that diverges is rejected like one that raises the
/// cost. Errors when the start itself diverges on the fitting logs.
fn refine_model(
    m: &SindyModel<f64>,
    res: &SimResiduals,
    max_iter: usize,
) -> Result<SindyModel<f64>> {
    let slots = refine_slots(m);
    let eqs = [&m.accel, &m.zdot, &m.idot];
    let mut x0: Vec<f64> = slots.coef.iter().map(|&(e, k)| eqs[e].terms[k].1).collect();
    let mut lo: Vec<f64> = x0.iter().map(|c| c - 10.0 * c.abs()).collect();
    let mut hi: Vec<f64> = x0.iter().map(|c| c + 10.0 * c.abs()).collect();
    let mut scale: Vec<f64> = x0.iter().map(|c| c.abs().max(1e-12)).collect();
    if slots.a {
        x0.push(m.a.clamp(REFINE_A_RANGE.0, REFINE_A_RANGE.1));
        lo.push(REFINE_A_RANGE.0);
        hi.push(REFINE_A_RANGE.1);
        scale.push(m.a.abs().max(1.0));
    }
    if slots.vs {
        x0.push(m.vs);
        lo.push(m.vs / REFINE_VS_FACTOR);
        hi.push(m.vs * REFINE_VS_FACTOR);
        scale.push(m.vs);
    }
    if x0.is_empty() {
        return Ok(m.clone());
    }
    let mut f = |x: &[f64]| res.eval(&with_values(m, &slots, x));
    let opts = nlsq::Options {
        max_iter,
        ..nlsq::Options::default()
    };
    let sol = nlsq::solve(&mut f, &x0, &lo, &hi, &scale, opts, &mut |it, cost| {
        tracing::debug!("SINDYc refinement: iteration {it}, cost {cost:.6e}");
    })?;
    Ok(with_values(m, &slots, &sol.x))
}

/// The refinement stage: refine each start (named for the Pareto table) on the
/// simulation error of the fitting logs (`res`) and keep a refined model only when its
/// validation fit (`score`) beats `fit`, so it can never make the result worse. Models of
/// more than [`REFINE_MAX_TERMS`] terms are not refined (a row says so). Returns the best
/// model and its validation fit.
pub fn refine_and_choose(
    model: SindyModel<f64>,
    fit: f64,
    starts: Vec<(&str, SindyModel<f64>)>,
    res: &SimResiduals,
    mut score: impl FnMut(&SindyModel<f64>) -> Option<f64>,
    pareto: &mut Vec<ParetoRow>,
) -> (SindyModel<f64>, f64) {
    let (mut model, mut validation_fit) = (model, fit);
    for (name, m0) in starts {
        let terms = m0.accel.terms.len() + m0.zdot.terms.len() + m0.idot.terms.len();
        if terms > REFINE_MAX_TERMS {
            pareto.push(ParetoRow {
                terms,
                fit: None,
                step: format!(
                    "{name} not refined: more than {REFINE_MAX_TERMS} terms would cost \
                     {} free runs per iteration",
                    terms + 2
                ),
                accepted: false,
            });
            continue;
        }
        let refined = refine_model(&m0, res, REFINE_ITER);
        let fit = refined.as_ref().ok().and_then(&mut score);
        let better = fit.is_some_and(|f| f > validation_fit);
        pareto.push(ParetoRow {
            terms,
            fit,
            step: format!("{name} refined on the free-run simulation error"),
            accepted: better,
        });
        if let (true, Ok(r), Some(f)) = (better, refined, fit) {
            model = r;
            validation_fit = f;
        }
    }
    (model, validation_fit)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::emulator::{simulate_signal, EmulatorConfig, SignalKind};
    use control::sindy::SparseEq;

    /// A log whose measurements are the free run of `m` on the paper's signal a.
    fn log_of(m: &SindyModel<f64>) -> MotorLog {
        let cfg = EmulatorConfig::paper();
        let mut log = simulate_signal(&cfg, SignalKind::A, 15.0).unwrap().log;
        log.omega = None;
        log.theta[0] = 0.0;
        log.i.as_mut().unwrap()[0] = 0.0;
        let p = simulate(m, Plant::Voltage, &log, Limits::default()).unwrap();
        log.theta = p.theta;
        log.i = p.i;
        log
    }

    #[test]
    fn refinement_moves_perturbed_coefficients_back_to_the_data() {
        let mut truth = SindyModel::empty(5.0, 1.0, 1.0);
        truth.accel = SparseEq::from_slice(&[
            (Term::Xdot, -4.0),
            (Term::I, 190.0),
            (Term::TanhXdot, -240.0),
        ])
        .unwrap();
        truth.idot =
            SparseEq::from_slice(&[(Term::Xdot, -240.0), (Term::I, -700.0), (Term::U, 3300.0)])
                .unwrap();
        let log = log_of(&truth);
        let logs = std::slice::from_ref(&log);
        let res = SimResiduals::new(logs, Plant::Voltage, 10, Limits::default());
        let mut start = truth.clone();
        start.accel.terms[1].1 *= 1.1;
        start.accel.terms[2].1 *= 0.8;
        let cost = |m: &SindyModel<f64>| res.eval(m).unwrap().iter().map(|r| r * r).sum::<f64>();
        let refined = refine_model(&start, &res, 15).unwrap();
        assert!(
            cost(&refined) < 0.01 * cost(&start),
            "{} vs {}",
            cost(&refined),
            cost(&start)
        );
        let rel = |a: f64, b: f64| (a - b).abs() / b.abs();
        assert!(
            rel(refined.accel.coef(Term::I), 190.0) < 0.02,
            "{:?}",
            refined.accel
        );
        assert!(
            rel(refined.accel.coef(Term::TanhXdot), -240.0) < 0.05,
            "{:?}",
            refined.accel
        );
        // The structure stays: the refinement moves values, never adds or drops terms.
        assert_eq!(refined.accel.terms.len(), 3);
        assert_eq!(refined.idot.terms.len(), 3);
    }

    #[test]
    fn slots_cover_the_mechanical_coefficients_and_the_shape_parameters_only_when_used() {
        let mut m = SindyModel::empty(5.0, 1.0, 1.0);
        m.accel = SparseEq::from_slice(&[(Term::Xdot, -4.0), (Term::I, 190.0)]).unwrap();
        m.zdot = SparseEq::from_slice(&[(Term::Z, -9.0)]).unwrap();
        m.idot = SparseEq::from_slice(&[(Term::U, 3300.0)]).unwrap();
        let slots = refine_slots(&m);
        // The current equation keeps its held-voltage regression.
        assert_eq!(slots.coef, vec![(0, 0), (0, 1), (1, 0)]);
        assert!(!slots.a && !slots.vs);
        let back = with_values(&m, &slots, &[1.0, 2.0, 3.0]);
        assert_eq!(back.accel.coef(Term::I), 2.0);
        assert_eq!(back.zdot.coef(Term::Z), 3.0);
        assert_eq!(back.idot.coef(Term::U), 3300.0);
        m.zdot = SparseEq::from_slice(&[(Term::TanhZ, 1.0)]).unwrap();
        m.accel = SparseEq::from_slice(&[(Term::StribeckXdot, -50.0)]).unwrap();
        let slots = refine_slots(&m);
        assert!(slots.a && slots.vs);
        // Coefficients first, then a, then vs.
        let back = with_values(&m, &slots, &[-40.0, 2.0, 7.0, 3.5]);
        assert_eq!((back.a, back.vs), (7.0, 3.5));
        assert_eq!(back.accel.coef(Term::StribeckXdot), -40.0);
    }
}
