//! The refinement stage: the coefficients of a sparse structure (and the tanh gain `a`)
//! refined by bounded Levenberg–Marquardt ([`crate::ident::nlsq`]) on the free-run
//! simulation error, as the LuGre model's dynamic step does. The weak form gets the structure
//! and a start; the simulation error then corrects what the weak form cannot see (the lag of
//! a quasi-static current, the bias of the sign-like terms on Hall-quantised data). The
//! current equation keeps the coefficients of its held-voltage regression
//! ([`super::rows::held_current_normal`]): it is the sampled current's own law, and moving
//! it to help the velocity fit trades a right equation for a wrong one (and one free run per
//! coefficient per iteration). The current residual still steers the mechanical equations,
//! weighted against the velocity's by maximum likelihood: each output divided by its own
//! residual scale on the fitting logs ([`SimResiduals::current_weight`]).
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
/// Iteration limit of the refinement (one Jacobian = one free run per coefficient each).
pub(crate) const REFINE_ITER: usize = 25;
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
/// average, not quantised so the cost stays smooth in the coefficients), current and angle,
/// each normalised by the spread of the measured signal. The angle has the weight
/// [`REFINE_ANGLE_WEIGHT`] relative to the velocity; the current's weight is an argument,
/// the maximum-likelihood one of [`SimResiduals::current_weight`].
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

    /// Free-run residuals of `m` on each fitting log, normalised by the spread of the
    /// measured signal and not yet weighted: (velocity, current, angle); the current is
    /// empty without a measured or simulated current.
    fn outputs(&self, m: &SindyModel<f64>) -> Result<Vec<[Vec<f64>; 3]>> {
        use rayon::prelude::*;
        self.logs
            .par_iter()
            .zip(&self.omega)
            .zip(&self.spreads)
            .map(|((log, w), &(sw, si, sx))| -> Result<[Vec<f64>; 3]> {
                let p = simulate(m, self.plant, log, self.limits)?;
                let wp = sensor_chain::velocity_estimate(&p.t, &p.theta, self.window);
                let rw = wp.iter().zip(w).map(|(a, b)| (a - b) / sw).collect();
                let ri = match (&log.i, &p.i) {
                    (Some(im), Some(ip)) => ip.iter().zip(im).map(|(a, b)| (a - b) / si).collect(),
                    _ => Vec::new(),
                };
                let rx = p
                    .theta
                    .iter()
                    .zip(&log.theta)
                    .map(|(a, b)| (a - b) / sx)
                    .collect();
                Ok([rw, ri, rx])
            })
            .collect()
    }

    /// Weight of the current residual relative to the velocity's for a refinement that
    /// starts at `m`: the ratio of the two outputs' residual scales, `σ_ẋ/σ_i`, each the RMS
    /// of its normalised free-run residual over all fitting logs. Dividing each output's
    /// residual by its own scale is the maximum-likelihood weighting of an output-error
    /// problem with independent Gaussian errors of unknown variance per output (the
    /// estimate minimises `Σ_k N_k·ln σ_k²`, whose normal equations are least squares
    /// weighted by `1/σ_k²` at the optimum's own residual variances), so neither output
    /// dominates by its units or by the size of its model error. The angle, the measurement
    /// the velocity is estimated from rather than an independent output, keeps its fixed
    /// weight relative to the velocity. 1 when either scale is zero or not finite (an exact output: nothing to
    /// weigh against). Errors when `m` diverges on the fitting logs.
    pub fn current_weight(&self, m: &SindyModel<f64>) -> Result<f64> {
        let runs = self.outputs(m)?;
        let scale = |k: usize| {
            let all: Vec<f64> = runs.iter().flat_map(|r| r[k].iter().copied()).collect();
            crate::numerics::statistics::rms(&all)
        };
        let ratio = scale(0) / scale(1);
        Ok(if ratio.is_finite() && ratio > 0.0 {
            ratio
        } else {
            1.0
        })
    }

    /// The residual vector the refinement minimises: velocity, current times
    /// `current_weight`, angle times [`REFINE_ANGLE_WEIGHT`], log after log.
    pub(crate) fn eval(&self, m: &SindyModel<f64>, current_weight: f64) -> Result<Vec<f64>> {
        let runs = self.outputs(m)?;
        let mut r = Vec::with_capacity(
            runs.iter()
                .map(|o| o.iter().map(Vec::len).sum::<usize>())
                .sum(),
        );
        for [rw, ri, rx] in runs {
            r.extend(rw);
            r.extend(ri.iter().map(|v| current_weight * v));
            r.extend(rx.iter().map(|v| REFINE_ANGLE_WEIGHT * v));
        }
        Ok(r)
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
/// cost. The current residual has the maximum-likelihood weight of the start
/// ([`SimResiduals::current_weight`]), estimated once from the free run of the regression
/// stage's model and held through the iterations. Errors when the start itself diverges on
/// the fitting logs.
pub(crate) fn refine_model(
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
    let weight = res.current_weight(&with_values(m, &slots, &x0))?;
    tracing::debug!("SINDYc refinement: current weight {weight:.4} (maximum likelihood)");
    let mut f = |x: &[f64]| res.eval(&with_values(m, &slots, x), weight);
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

    /// A model of both equations near the paper motor's: viscous and tanh friction, the
    /// winding's resistance, back-EMF and input gain.
    fn two_equation_truth() -> SindyModel<f64> {
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
        truth
    }

    #[test]
    fn refinement_moves_perturbed_coefficients_back_to_the_data() {
        let truth = two_equation_truth();
        let log = log_of(&truth);
        let logs = std::slice::from_ref(&log);
        let res = SimResiduals::new(logs, Plant::Voltage, 10, Limits::default());
        let mut start = truth.clone();
        start.accel.terms[1].1 *= 1.1;
        start.accel.terms[2].1 *= 0.8;
        let cost =
            |m: &SindyModel<f64>| res.eval(m, 1.0).unwrap().iter().map(|r| r * r).sum::<f64>();
        let refined = refine_model(&start, &res, 15).unwrap();
        // The log is the truth's own noiseless free run, so the minimum is the truth: the
        // refinement must remove nearly all (99 %) of the cost the 10 % and 20 %
        // perturbations cause, and bring each value back to within a quarter of its
        // perturbation or less (2 % after 10 % on the current's gain; 5 % after 20 % on the
        // flatter tanh term, active only near reversals) in its 15 iterations.
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
    fn the_current_weight_equalises_the_outputs_and_falls_with_current_noise() {
        let truth = two_equation_truth();
        let mut start = truth.clone();
        start.accel.terms[1].1 *= 1.1;
        start.idot.terms[2].1 *= 0.95;
        let log = log_of(&truth);
        let logs = std::slice::from_ref(&log);
        let res = SimResiduals::new(logs, Plant::Voltage, 10, Limits::default());
        let w = res.current_weight(&start).unwrap();
        assert!(w.is_finite() && w > 0.0, "{w}");
        // Weighted, the velocity and current residuals have the same RMS: neither output
        // dominates the cost.
        let r = res.eval(&start, w).unwrap();
        let n = log.len();
        let rms = crate::numerics::statistics::rms;
        let (rw, ri) = (rms(&r[..n]), rms(&r[n..2 * n]));
        // Equal by the weight's definition: rounding only.
        assert!((rw / ri - 1.0).abs() < 1e-9, "{rw} vs {ri}");
        // A noisier current measurement weighs less.
        let mut noisy = log.clone();
        let spread = sim_error::spread(noisy.i.as_ref().unwrap());
        let noise = crate::numerics::statistics::white_noise(n, 7);
        for (i, e) in noisy.i.as_mut().unwrap().iter_mut().zip(noise) {
            *i += 0.2 * spread * e;
        }
        let noisy_logs = std::slice::from_ref(&noisy);
        let res = SimResiduals::new(noisy_logs, Plant::Voltage, 10, Limits::default());
        let w_noisy = res.current_weight(&start).unwrap();
        // Noise of a fifth of the current's spread adds an RMS of 0.2 to its normalised
        // residual, so the weight falls below 0.7 whenever the model error's own current
        // residual is under 0.19 (a 5 % input gain leaves much less).
        assert!(w_noisy < 0.7 * w, "{w_noisy} vs {w}");
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
