//! Simulation-error refinement: move a model's free parameters to minimise the free-run
//! error against the logs (the paper's grey-box estimation), with [`super::nlsq`].
//!
//! Residuals per sample: velocity (the model's angle through the firmware's moving average,
//! without quantisation so the cost stays smooth in the parameters, against the measured
//! velocity), current, and the angle with a small weight; each normalised by the spread of
//! the measured signal so that the three are comparable.
use super::free_params::{parameter_rows, Free, Slot};
use super::freerun::{RunParams, SubstepRoots};
use super::tangent::{RunScalar, Tangent, PARAM_LANES};
use super::{freerun, nlsq, progress, sensor_chain};
use crate::log::MotorLog;
use crate::model::{Model, ModelKind, Parameter};
use anyhow::{bail, Result};
use rayon::prelude::*;

/// Weight of the angle residual relative to velocity and current: the free-run angle drifts
/// (it integrates every velocity error), so it only steers the low frequencies.
const ANGLE_WEIGHT: f64 = 0.3;

/// Standard deviation of a signal (at least 1e-12): the scale each residual is divided by.
pub(crate) fn spread(v: &[f64]) -> f64 {
    let n = v.len().max(1) as f64;
    let mean = v.iter().sum::<f64>() / n;
    (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n)
        .sqrt()
        .max(1e-12)
}

/// Precomputed measured signals of one log.
struct Target<'a> {
    log: &'a MotorLog,
    omega: Vec<f64>,
    s_omega: f64,
    s_i: f64,
    s_theta: f64,
    /// What a multiple-shooting segment takes from this log at its start.
    restart: Restart,
}

/// What a multiple-shooting segment takes from the log at its start (the first segment of a
/// log always starts from the measured state).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Restart {
    /// The measured angle; the velocity, current and bristle deflection continue where the
    /// run before left them.
    Angle,
    /// The measured state: angle, velocity, current, and the bristles on the Stribeck curve.
    State,
}

impl Restart {
    /// The restart a log's sensors allow. The angle is the one state that integrates the
    /// model's errors instead of forgetting them, so it is always taken from the log. The
    /// velocity is taken too when the log measures it without delay: without a velocity
    /// column it is the angle's slope over ±5 samples, centred (an encoder's angle, as on
    /// a linear axis, gives it to well below the model's error). A velocity column is the
    /// firmware's moving average, which delays the velocity by half its window (≈ 60 ms at
    /// 10 samples of 12 ms): restarting from it, and from bristles put on the Stribeck
    /// curve at that velocity, makes a model that forgets its initial state faster cost
    /// less, which biases the inertia and the bristle stiffness σ0 low. Those logs come
    /// from Hall sensors, whose angle's centred slope is off by up to a Hall step per 10
    /// samples, so the velocity there continues from the run before instead.
    ///
    /// A load behind a coupling (`compliance`, `backlash`) is never measured. With
    /// [`Restart::Angle`] its deflection from the rotor and its speed continue from the run
    /// before (the deflection, not its angle: the segment's rotor angle jumps to the
    /// measurement, and the load moves with it, so the coupling's torque carries over
    /// unchanged); with [`Restart::State`] it starts moving with the rotor, undeflected
    /// (`freerun::run_range_from`), as the velocity and bristles start from the measurement.
    pub fn for_log(log: &MotorLog) -> Restart {
        match log.omega {
            Some(_) => Restart::Angle,
            None => Restart::State,
        }
    }
}

/// The residual vector of `model` on `logs`.
pub struct Residuals<'a> {
    targets: Vec<Target<'a>>,
    window: usize,
    /// Multiple shooting: segment length [samples], each segment simulated from the state
    /// its log's [`Restart`] takes at its start; `None`: one free run per log.
    segment: Option<usize>,
    /// Samples between the checks of a free run against a bound ([`Self::cost_below`]):
    /// [`SEGMENT_S`], as often as multiple shooting checks.
    free_run_check: usize,
}

/// Segment length of the multiple-shooting residual [s]. A free run's angle drifts by the
/// integral of every velocity error, and a position-dependent torque (cogging, an
/// unbalanced load) evaluated at a drifted angle is noise: the cost then has a local minimum
/// per period of the effect. Restarting from the measured angle every 2 s keeps the drift
/// well below a cogging period (2π/7 ≈ 0.9 rad) while a segment still spans many mechanical
/// time constants (J·R/(K_t·K_b) ≈ 13 ms) and Hall steps.
pub const SEGMENT_S: f64 = 2.0;

impl<'a> Residuals<'a> {
    pub fn new(logs: &'a [MotorLog], window: usize) -> Residuals<'a> {
        let targets = logs
            .iter()
            .map(|log| {
                let omega = sensor_chain::measured_velocity(log, window);
                Target {
                    s_omega: spread(&omega),
                    s_i: log.i.as_deref().map(spread).unwrap_or(1.0),
                    s_theta: spread(&log.theta),
                    restart: Restart::for_log(log),
                    omega,
                    log,
                }
            })
            .collect();
        let dt = logs.first().map(|l| l.sample_period()).unwrap_or(0.012);
        Residuals {
            targets,
            window,
            segment: None,
            free_run_check: ((SEGMENT_S / dt.max(1e-6)).round() as usize).max(4 * window.max(1)),
        }
    }

    /// Multiple-shooting residuals: segments of [`SEGMENT_S`] seconds.
    pub fn segmented(logs: &'a [MotorLog], window: usize) -> Residuals<'a> {
        let mut r = Residuals::new(logs, window);
        r.segment = Some(r.free_run_check);
        r
    }

    /// Residuals of a model (errors if its simulation diverges).
    pub fn eval(&self, model: &Model) -> Result<Vec<f64>> {
        if model.kind == ModelKind::Sindyc {
            return self.eval_sindyc(model);
        }
        let p = RunParams::<f64>::of(model);
        let r = self.residuals(&p, &p, &mut SubstepRoots::Solve, None)?;
        Ok(r.unwrap_or_default())
    }

    /// `Σ r²` of a (non-SINDYc) model, or `None` as soon as the residuals run so far are
    /// known to sum to more than `bound()` (read after every segment, and every
    /// [`SEGMENT_S`] of a free run; it may fall while the run goes on): the rest of the run
    /// is then not simulated. The sum is the one [`cost`] gives, term by term in the same
    /// order, so a model that is not given up costs the same to the bit, and one given up
    /// costs more than a bound it was given.
    pub fn cost_below(&self, model: &Model, bound: &dyn Fn() -> f64) -> Result<Option<f64>> {
        if model.kind == ModelKind::Sindyc {
            return Ok(Some(self.eval_sindyc(model)?.iter().map(|v| v * v).sum()));
        }
        let p = RunParams::<f64>::of(model);
        let r = self.residuals(&p, &p, &mut SubstepRoots::Solve, Some(bound))?;
        Ok(r.map(|r| r.iter().fold(0.0, |acc, v| acc + v * v)))
    }

    /// [`Self::eval`] of a (non-SINDYc) model, with the tape of its sub-steps' roots for
    /// [`Self::eval_with_jacobian`] at the same model.
    pub fn eval_recording(&self, model: &Model) -> Result<(Vec<f64>, Vec<f64>)> {
        let p = RunParams::<f64>::of(model);
        let samples: usize = self.targets.iter().map(|t| t.log.len()).sum();
        let mut tape = Vec::with_capacity(samples * freerun::SUBSTEPS);
        let r = self.residuals(&p, &p, &mut SubstepRoots::Record(&mut tape), None)?;
        Ok((r.unwrap_or_default(), tape))
    }

    /// [`Self::eval_recording`], or `None` as soon as the residuals run so far are known to
    /// have `Σ r²` above `bound` (as [`Self::cost_below`]; the rest of the run is then not
    /// simulated): a trial point that cannot be accepted against a cost of `bound / 2`.
    pub fn eval_recording_below(
        &self,
        model: &Model,
        bound: f64,
    ) -> Result<Option<(Vec<f64>, Vec<f64>)>> {
        let p = RunParams::<f64>::of(model);
        let samples: usize = self.targets.iter().map(|t| t.log.len()).sum();
        let mut tape = Vec::with_capacity(samples * freerun::SUBSTEPS);
        let roots = &mut SubstepRoots::Record(&mut tape);
        let r = self.residuals(&p, &p, roots, Some(&|| bound))?;
        Ok(r.map(|r| (r, tape)))
    }

    /// The residuals and their Jacobian with respect to the free parameters `free` of
    /// `model` (one column per parameter): forward sensitivities of the free run in dual
    /// numbers ([`super::tangent`]), [`PARAM_LANES`] columns per run, the runs on rayon's
    /// threads. `roots`: the tape of [`Self::eval_recording`] at the same model, which
    /// spares the runs the sub-steps' root search. Not for SINDYc models.
    pub fn eval_with_jacobian(
        &self,
        model: &Model,
        free: &[Free],
        roots: Option<&[f64]>,
    ) -> Result<(Vec<f64>, Vec<Vec<f64>>)> {
        let re = RunParams::<f64>::of(model);
        let tape = || match roots {
            Some(t) => SubstepRoots::Replay(t, 0),
            None => SubstepRoots::Solve,
        };
        if free.is_empty() {
            let r = self.residuals(&re, &re, &mut tape(), None)?;
            return Ok((r.unwrap_or_default(), Vec::new()));
        }
        let chunks: Vec<&[Free]> = free.chunks(PARAM_LANES).collect();
        let runs: Vec<Result<Vec<Tangent>>> = chunks
            .par_iter()
            .map(|chunk| {
                let mut p = RunParams::<Tangent>::of(model);
                for (lane, fr) in chunk.iter().enumerate() {
                    seed(&mut p, &fr.slot, lane);
                }
                let r = self.residuals(&p, &re, &mut tape(), None)?;
                Ok(r.unwrap_or_default())
            })
            .collect();
        let mut values = Vec::new();
        let mut cols = Vec::with_capacity(free.len());
        for (chunk, run) in chunks.iter().zip(runs) {
            let run = run?;
            if values.is_empty() {
                values = run.iter().map(|v| v.re).collect();
            }
            for lane in 0..chunk.len() {
                cols.push(run.iter().map(|v| v.eps[lane]).collect());
            }
        }
        Ok((values, cols))
    }

    /// The residuals of the model `p` (values `re`) in its number type: per log (or per
    /// segment), the velocity through the firmware's estimator, the current, the angle; the
    /// sub-steps' roots of all its runs in one tape. With a `bound`, the run stops (the
    /// answer is `None`) once `Σ r²` of the residuals so far is above `bound()`: checked after
    /// each segment and, within a free run, every [`SEGMENT_S`] seconds of samples on the
    /// current and angle residuals run so far (part of the sum, so a lower bound of it).
    fn residuals<D: RunScalar>(
        &self,
        p: &RunParams<D>,
        re: &RunParams<f64>,
        roots: &mut SubstepRoots,
        bound: Option<&dyn Fn() -> f64>,
    ) -> Result<Option<Vec<D>>> {
        let c = D::constant;
        let mut r = Vec::new();
        // Σ r² of `r`, in its order.
        let mut total = 0.0;
        let terms: usize = self
            .targets
            .iter()
            .map(|t| t.log.len() * (2 + usize::from(t.log.i.is_some())))
            .sum();
        for tg in &self.targets {
            let n = tg.log.len();
            if n == 0 {
                bail!(
                    "{}: the log has no samples",
                    crate::log::echo_path(&tg.log.source)
                );
            }
            // Segments start every `seg` samples; each is simulated from `window` samples
            // before its start (so that the velocity estimator has its history) and scored
            // on its own samples only. The free run is one segment from the first sample.
            let seg = self.segment.unwrap_or(n);
            let mut s = 0;
            let mut prev: Option<(usize, freerun::Run<D>)> = None;
            while s < n {
                let e = (s + seg).min(n);
                let a = match self.segment {
                    Some(_) => s.saturating_sub(self.window),
                    None => s,
                };
                let carried = match (tg.restart, &prev) {
                    (Restart::Angle, Some((pa, run))) if a >= *pa && a - *pa < run.theta.len() => {
                        Some(run.carried(p, a - pa))
                    }
                    _ => None,
                };
                // Within a free run, every `SEGMENT_S` of samples: the sum so far and the
                // new samples' current and angle terms against the bound. Those terms are
                // the ones of the full sum, added in another order: rounding makes them at
                // most `terms·ε` relative apart, so a partial sum above the bound by more
                // is above it in the full sum too.
                let every = self.free_run_check;
                let slack = 1.0 - 2.0 * terms as f64 * f64::EPSILON;
                let (mut partial, mut upto) = (total, 0);
                let mut check = |run: &freerun::Run<D>| {
                    let k = run.theta.len();
                    let Some(bound) = bound else { return false };
                    if k < upto + every {
                        return false;
                    }
                    let sq = |v: D| v.re() * v.re();
                    if let (Some(im), Some(ip)) = (&tg.log.i, &run.i) {
                        partial = im[s + upto..s + k]
                            .iter()
                            .zip(&ip[upto..k])
                            .fold(partial, |acc, (a, b)| acc + sq((*b - c(*a)) / c(tg.s_i)));
                    }
                    partial = run.theta[upto..k]
                        .iter()
                        .zip(&tg.log.theta[s + upto..s + k])
                        .fold(partial, |acc, (a, b)| {
                            acc + sq(c(ANGLE_WEIGHT) * (*a - c(*b)) / c(tg.s_theta))
                        });
                    upto = k;
                    partial * slack > bound()
                };
                let give_up: Option<freerun::GiveUp<D>> = match (self.segment, bound) {
                    (None, Some(_)) => Some(&mut check),
                    _ => None,
                };
                let from = freerun::RunFrom {
                    substeps: freerun::SUBSTEPS,
                    carried,
                    give_up,
                };
                let Some(run) = freerun::run_range_from(p, re, tg.log, a..e, from, roots)? else {
                    return Ok(None);
                };
                let w = sensor_chain::velocity_estimate(&tg.log.t[a..e], &run.theta, self.window);
                let off = s - a;
                let before = r.len();
                r.extend(
                    w[off..]
                        .iter()
                        .zip(&tg.omega[s..e])
                        .map(|(a, b)| (*a - c(*b)) / c(tg.s_omega)),
                );
                if let (Some(im), Some(ip)) = (&tg.log.i, &run.i) {
                    r.extend(
                        im[s..e]
                            .iter()
                            .zip(&ip[off..])
                            .map(|(a, b)| (*b - c(*a)) / c(tg.s_i)),
                    );
                }
                r.extend(
                    run.theta[off..]
                        .iter()
                        .zip(&tg.log.theta[s..e])
                        .map(|(a, b)| c(ANGLE_WEIGHT) * (*a - c(*b)) / c(tg.s_theta)),
                );
                prev = Some((a, run));
                s = e;
                if let Some(bound) = bound {
                    total = r[before..]
                        .iter()
                        .fold(total, |acc, v| acc + v.re() * v.re());
                    if total > bound() {
                        return Ok(None);
                    }
                }
            }
        }
        Ok(Some(r))
    }

    /// Free-run residuals of a SINDYc model (simulated by `ident::sindyc`).
    fn eval_sindyc(&self, model: &Model) -> Result<Vec<f64>> {
        let mut r = Vec::new();
        for tg in &self.targets {
            let p = freerun::simulate(model, tg.log)?;
            let w = sensor_chain::velocity_estimate(&p.t, &p.theta, self.window);
            r.extend(w.iter().zip(&tg.omega).map(|(a, b)| (a - b) / tg.s_omega));
            if let (Some(im), Some(ip)) = (&tg.log.i, &p.i) {
                r.extend(im.iter().zip(ip).map(|(a, b)| (b - a) / tg.s_i));
            }
            r.extend(
                p.theta
                    .iter()
                    .zip(&tg.log.theta)
                    .map(|(a, b)| ANGLE_WEIGHT * (a - b) / tg.s_theta),
            );
        }
        Ok(r)
    }
}

/// Seed the derivative lane `lane` of the number behind `slot` (K_b's lane also seeds K_t,
/// which it sets).
fn seed(p: &mut RunParams<Tangent>, slot: &Slot, lane: usize) {
    let one = |v: &mut Tangent| v.eps[lane] = 1.0;
    match slot {
        Slot::R => one(&mut p.motor.r),
        Slot::L => one(&mut p.motor.l),
        Slot::Kb => {
            one(&mut p.motor.kb);
            one(&mut p.motor.kt);
        }
        Slot::J => one(&mut p.motor.j),
        Slot::Viscous => one(&mut p.viscous),
        Slot::Lugre(f) => {
            if let Some(l) = p.lugre.as_mut() {
                one(match *f {
                    "alpha0" => &mut l.alpha0,
                    "alpha1" => &mut l.alpha1,
                    "alpha2" => &mut l.alpha2,
                    "v0" => &mut l.v0,
                    "sigma0" => &mut l.sigma0,
                    _ => &mut l.sigma1,
                });
            }
        }
        Slot::Effect(i, k) => {
            if let Some(v) = p
                .effects
                .get_mut(*i)
                .and_then(|e| crate::effects::key_mut(e, k))
            {
                one(v);
            }
        }
    }
}

/// `Σ r²` of a model, ∞ when it diverges.
pub fn cost(res: &Residuals, model: &Model) -> f64 {
    res.eval(model)
        .map(|r| r.iter().map(|v| v * v).sum())
        .unwrap_or(f64::INFINITY)
}

/// The costs ([`cost`]) of the models `model(k)`, `k < count`, evaluated side by side on
/// rayon's threads, taken up in the order `order` (a permutation of `0..count`; the likely
/// cheapest first). A model's run stops once its segments so far cost more than `bound` or
/// the lowest cost of the models already evaluated, and its cost is then ∞ (as for a model
/// that diverges): the lowest cost, and the first model in `0..count` with it, are those
/// the full costs give, to the bit, whatever the threads' timing; the others may be ∞.
pub fn lowest_costs(
    res: &Residuals,
    order: &[usize],
    bound: f64,
    model: impl Fn(usize) -> Model + Sync,
) -> Vec<f64> {
    use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering::Relaxed};
    // Costs are ≥ 0, where the order of f64 bit patterns is the order of the values.
    let lowest = AtomicU64::new(bound.max(0.0).to_bits());
    let next = AtomicUsize::new(0);
    let costs: Vec<AtomicU64> = (0..order.len())
        .map(|_| AtomicU64::new(f64::INFINITY.to_bits()))
        .collect();
    (0..rayon::current_num_threads().max(1))
        .into_par_iter()
        .for_each(|_| {
            while let Some(&k) = order.get(next.fetch_add(1, Relaxed)) {
                let below = || f64::from_bits(lowest.load(Relaxed));
                if let Ok(Some(c)) = res.cost_below(&model(k), &below) {
                    if c.is_finite() {
                        lowest.fetch_min(c.to_bits(), Relaxed);
                        if let Some(slot) = costs.get(k) {
                            slot.store(c.to_bits(), Relaxed);
                        }
                    }
                }
            }
        });
    costs
        .iter()
        .map(|c| f64::from_bits(c.load(Relaxed)))
        .collect()
}

/// The effects of `model` with their magnitudes multiplied by `f` (keys other than the
/// magnitude, such as a phase or a time constant, kept); `f = 0` is the model without them.
pub fn scale_effect_magnitudes(model: &Model, f: f64) -> Model {
    let mut m = model.clone();
    for e in &mut m.effects {
        (crate::effects::of(e.kind()).scale)(e, f);
    }
    m
}

/// Grid search around the weak-form estimate of the effects: start from the magnitude factor
/// (0, ¼, ½, ¾, 1, 1¼) and, for the angle-periodic effects (cogging, position load), the
/// phase shift with the lowest simulation error on `res` (one simulation each, side by side
/// on rayon's threads). The weak form evaluates sin(h·θ) at the Hall-quantised angle, so
/// its magnitudes can be off, and its phases by up to h times half a Hall step (the
/// quantised angle lags the true one by half a step on average): the shifts are
/// h·(0, ±¼, ±½) Hall steps. Factor 0 ("without the effect") is a candidate, so adding an
/// effect never starts worse than not adding it. A load behind a coupling (`compliance`,
/// `backlash`) is also tried with its inertia taken out of the rotor's, and a coupling's
/// resonance at other frequencies (below).
pub fn better_effect_start(model: &mut Model, res: &Residuals) {
    if model.effects.is_empty() {
        return;
    }
    let step = model.sensor.hall_resolution_rad;
    let periodic = model
        .effects
        .iter()
        .any(|e| (crate::effects::of(e.kind()).harmonic)(e).is_some());
    let shifts: &[f64] = if periodic && step > 0.0 {
        &[0.0, -0.25, 0.25, -0.5, 0.5]
    } else {
        &[0.0]
    };
    let factors = [0.0, 0.25, 0.5, 0.75, 1.0, 1.25];
    let load_inertia: f64 = model
        .effects
        .iter()
        .map(|e| match *e {
            control::effects::Effect::Compliance { j2, .. }
            | control::effects::Effect::Backlash { j2, .. } => j2.max(0.0),
            _ => 0.0,
        })
        .sum();
    // A structure fitted without a load carries its inertia in J (the pair moves as one
    // below the coupling's resonance): a load is also tried with its inertia taken out of J,
    // where that leaves the rotor at least a tenth of it.
    let moves: &[bool] = if load_inertia > 0.0 {
        &[false, true]
    } else {
        &[false]
    };
    // A coupling's resonance is tried a factor 2 and 4 either side (its stiffness scaled by
    // the square, the damper so that the damping ratio stays): off by more than half its
    // width, a resonance leaves the simulation error flat in the coupling's parameters.
    let has_spring = model
        .effects
        .iter()
        .any(|e| matches!(e, control::effects::Effect::Compliance { .. }));
    let stiffness: &[f64] = if has_spring {
        &[1.0, 0.25, 4.0, 1.0 / 16.0, 16.0]
    } else {
        &[1.0]
    };
    let starts: Vec<Start> = factors
        .iter()
        .flat_map(|&f| shifts.iter().map(move |&d| (f, d)))
        .flat_map(|(f, d)| moves.iter().map(move |&mv| (f, d, mv)))
        .flat_map(|(f, d, mv)| stiffness.iter().map(move |&kf| (f, d, mv, kf)))
        .filter(|&(f, d, mv, kf)| f > 0.0 || (d == 0.0 && !mv && kf == 1.0))
        .filter(|&(f, _, mv, _)| !mv || model.motor.j - f * load_inertia >= 0.1 * model.motor.j)
        .collect();
    let trial = |&(f, d, mv, kf): &Start| {
        let mut m = shift_phases(&scale_effect_magnitudes(model, f), d * step);
        if mv {
            m.motor.j -= f * load_inertia;
        }
        if kf != 1.0 {
            for e in &mut m.effects {
                if let control::effects::Effect::Compliance { k, c, .. } = e {
                    *k *= kf;
                    *c *= kf.sqrt();
                }
            }
        }
        m
    };
    // The phase first, at the weak-form magnitude: the phase that fits an angle-periodic
    // torque best is the same at every magnitude (the misfit of a·sin(hθ + φ') against
    // A·sin(hθ + φ) is a² + A² − 2aA·cos(φ' − φ), least at φ' = φ whatever a > 0), while
    // the magnitude that fits best at a wrong phase is shrunk by the cosine of its error.
    // Then the magnitudes (and the loads' moves and stiffness) at that phase.
    let mut best = (f64::INFINITY, (1.0, 0.0, false, 1.0));
    let starts = if shifts.len() > 1 {
        let phases: Vec<Start> = shifts.iter().map(|&d| (1.0, d, false, 1.0)).collect();
        best = lowest_start(res, &phases, f64::INFINITY, &trial, &model.effects, best);
        let phase = best.1 .1;
        starts
            .into_iter()
            .filter(|&(f, d, mv, kf)| {
                (d == phase || f == 0.0) && (f, d, mv, kf) != (1.0, phase, false, 1.0)
            })
            .collect()
    } else {
        starts
    };
    best = lowest_start(res, &starts, best.0, &trial, &model.effects, best);
    *model = trial(&best.1);
}

/// The lowest cost among `starts` (made into models by `trial`) and `best` (the cost and
/// start found so far; it stays unless a start costs less): runs given up above the lowest
/// so far, nearest the weak-form estimate first (its cost is the first bound the others
/// meet).
fn lowest_start(
    res: &Residuals,
    starts: &[Start],
    bound: f64,
    trial: &(dyn Fn(&Start) -> Model + Sync),
    effects: &[control::effects::Effect<f64>],
    mut best: (f64, Start),
) -> (f64, Start) {
    let mut order: Vec<usize> = (0..starts.len()).collect();
    order.sort_by(|&a, &b| {
        let off = |(f, d, mv, kf): Start| {
            (f - 1.0).abs() + d.abs() + f64::from(u8::from(mv)) + kf.ln().abs()
        };
        off(starts[a]).total_cmp(&off(starts[b]))
    });
    let costs = lowest_costs(res, &order, bound, |k| trial(&starts[k]));
    for (st, &c) in starts.iter().zip(&costs) {
        tracing::debug!(
            "effects {effects:?}, start (factor, shift in Hall steps, load inertia out of J, \
             stiffness factor) {st:?}: cost {c:.4e} (∞: above the lowest)"
        );
        if c < best.0 {
            best = (c, *st);
        }
    }
    best
}

/// A start of [`better_effect_start`]: magnitude factor, phase shift [Hall steps], whether the
/// loads' inertia is taken out of J, stiffness factor of a coupling.
type Start = (f64, f64, bool, f64);

/// `model` with the phase of each angle-periodic effect moved as the angle would be moved by
/// `dtheta` [rad]: `h·dtheta` for a cogging torque of harmonic h, `dtheta` for a position load.
fn shift_phases(model: &Model, dtheta: f64) -> Model {
    let mut m = model.clone();
    for e in &mut m.effects {
        if let Some(h) = (crate::effects::of(e.kind()).harmonic)(e) {
            if let Some(phase) = crate::effects::key_mut(e, "phase") {
                *phase += h * dtheta;
            }
        }
    }
    m
}

/// Refine the free parameters of `model` on `logs` (free-run residuals). Returns the
/// parameter rows with standard errors. `progress(iteration, cost)` reports progress.
pub fn refine(
    model: &mut Model,
    free: &[Free],
    logs: &[MotorLog],
    jacobian: Jacobian,
    opts: nlsq::Options,
    progress: &mut dyn FnMut(usize, f64),
) -> Result<Vec<Parameter>> {
    let res = Residuals::new(logs, model.sensor.velocity_window);
    refine_on(model, free, &res, jacobian, opts, progress)
}

/// How a refinement computes the Jacobian of the simulation error.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Jacobian {
    /// Forward sensitivities of the free run ([`Residuals::eval_with_jacobian`]): exact,
    /// about three times cheaper than finite differences over ten parameters.
    Sensitivities,
    /// Forward differences, one free run per parameter on rayon's threads (SINDYc models
    /// always).
    FiniteDifferences,
}

/// [`refine`] on given residuals (free run or multiple shooting). The bounds of `free` are
/// widened to the logs' scales and the model's `--fix`/`--bound` constraints
/// (`model.data.fixed`, `model.data.bounds`) applied ([`super::free_params::constrain`]).
pub fn refine_on(
    model: &mut Model,
    free: &[Free],
    res: &Residuals,
    jacobian: Jacobian,
    opts: nlsq::Options,
    progress: &mut dyn FnMut(usize, f64),
) -> Result<Vec<Parameter>> {
    let (v, d) = data_scales(model, res.targets.iter().map(|t| t.log));
    let user = model.data.constraints();
    let (free, fixed_rows) = super::free_params::constrain(model, free, &user, v, d);
    let free = &free[..];
    let x0: Vec<f64> = free.iter().map(|f| f.slot.get(model)).collect();
    let lo: Vec<f64> = free.iter().map(|f| f.lo).collect();
    let hi: Vec<f64> = free.iter().map(|f| f.hi).collect();
    let scale: Vec<f64> = free
        .iter()
        .zip(&x0)
        .map(|(f, x)| x.abs().max(1e-3 * (f.hi - f.lo).abs().min(1.0)).max(1e-9))
        .collect();
    let base = model.clone();
    let model_at = |x: &[f64]| {
        let mut m = base.clone();
        for (fr, v) in free.iter().zip(x) {
            fr.slot.set(&mut m, *v);
        }
        m
    };
    let sol = if base.kind == ModelKind::Sindyc || jacobian == Jacobian::FiniteDifferences {
        let f = |x: &[f64]| res.eval(&model_at(x));
        nlsq::solve_parallel(&f, &x0, &lo, &hi, &scale, opts, progress)?
    } else {
        // Levenberg–Marquardt asks for the Jacobian at the cheapest point evaluated so far:
        // its sub-steps' roots are kept from that evaluation.
        let cheapest: std::sync::Mutex<Option<CheapestPoint>> = Default::default();
        // A trial point is rejected when it costs more than the current point (bound: the
        // current cost): its run stops once the segments so far cost more.
        let f_below = |x: &[f64], current: f64| {
            let Some((r, tape)) = res.eval_recording_below(&model_at(x), 2.0 * current)? else {
                return Ok(None);
            };
            let c: f64 = r.iter().map(|v| v * v).sum();
            if let Ok(mut kept) = cheapest.lock() {
                if kept.as_ref().is_none_or(|k| c < k.1) {
                    *kept = Some((x.to_vec(), c, tape));
                }
            }
            Ok(Some(r))
        };
        let f = |x: &[f64]| Ok(f_below(x, f64::INFINITY)?.unwrap_or_default());
        // Exact Jacobian by forward sensitivities of the free run; without the
        // finite differences' noise the iterations may stop on significance.
        let jac = |x: &[f64]| {
            let roots: Option<Vec<f64>> = cheapest
                .lock()
                .ok()
                .and_then(|k| k.as_ref().filter(|k| k.0 == x).map(|k| k.2.clone()));
            Ok(res
                .eval_with_jacobian(&model_at(x), free, roots.as_deref())?
                .1)
        };
        let opts = nlsq::Options {
            noise_stop: true,
            gain_ratio_damping: true,
            ..opts
        };
        let problem = nlsq::WithJacobian {
            f: &f,
            jac: &jac,
            f_below: Some(&f_below),
        };
        nlsq::solve_with_jacobian(problem, &x0, &lo, &hi, &scale, opts, progress)?
    };
    tracing::debug!(
        "refined {} parameters: {} iterations, {} evaluations, cost {:.4e}",
        free.len(),
        sol.iterations,
        sol.evaluations,
        sol.cost
    );
    for (fr, v) in free.iter().zip(&sol.x) {
        fr.slot.set(model, *v);
    }
    let se: Vec<Option<f64>> = sol.std_err.iter().map(|v| Some(*v)).collect();
    // Identifiability is judged on the curvature of the cost (the white-noise errors);
    // the errors printed carry the residual's autocorrelation.
    let mut rows = parameter_rows(model, free, &se);
    let factor = res
        .eval(model)
        .map(|r| autocorrelation_factor(&r))
        .unwrap_or(1.0);
    for row in &mut rows {
        row.std_err = row.std_err.map(|e| e * factor);
    }
    model.data.std_err_factor = Some(factor);
    for (row, f) in rows.iter_mut().zip(free) {
        if let Some((lo, hi)) = user.bounds.get(&row.name) {
            let sep = if row.note.is_empty() { "" } else { "; " };
            row.note = format!(
                "{}{sep}bounded by --bound {}..{}",
                row.note,
                crate::validate::show(*lo),
                crate::validate::show(*hi)
            );
            debug_assert_eq!((f.lo, f.hi), (*lo, *hi));
        }
    }
    rows.extend(fixed_rows);
    Ok(rows)
}

/// The cheapest point a refinement evaluated: parameters, `Σ r²`, and the tape of its
/// sub-steps' roots.
type CheapestPoint = (Vec<f64>, f64, Vec<f64>);

/// Factor by which white-noise standard errors σ²·(JᵀJ)⁻¹ understate the spread of the
/// estimates when the residual `r` is autocorrelated: `√τ`, τ the residual's integrated
/// autocorrelation time ([`crate::numerics::statistics::correlation_time`]). For a least-squares
/// estimate `β̂ = (JᵀJ)⁻¹Jᵀr`, `Var(β̂) = (JᵀJ)⁻¹·JᵀΣJ·(JᵀJ)⁻¹` with Σ the residual's
/// covariance; where the sensitivities in J vary slowly against the residual's correlation
/// time (a free run's do), `JᵀΣJ ≈ σ²·τ·JᵀJ`, the variance of a mean of n correlated samples
/// (n/τ independent ones): the errors grow by `√τ`. Where a sensitivity varies faster, the
/// factor overstates its error, so the corrected errors are conservative. At least 1.
pub fn autocorrelation_factor(r: &[f64]) -> f64 {
    crate::numerics::statistics::correlation_time(r)
        .sqrt()
        .max(1.0)
}

/// The velocity and drive scales of `logs` for the bounds of a fit of `model`
/// ([`super::free_params::widen_to_data`]): the velocity scale its smooth-sign width was set
/// from, and [`crate::scales::drive_scale`] of the torque command or of `K_t·I`.
pub fn data_scales<'a>(model: &Model, logs: impl Iterator<Item = &'a MotorLog>) -> (f64, f64) {
    let v = (model.sign_width / control::effects::VELOCITY_EPS).clamp(1e-12, 1.0);
    let drive: Vec<f64> = logs
        .flat_map(|l| match (model.plant, &l.i) {
            (crate::log::Plant::Voltage, Some(i)) => {
                i.iter().map(|c| model.motor.kt * c).collect::<Vec<_>>()
            }
            _ => l.u.clone(),
        })
        .collect();
    (v, crate::scales::drive_scale(&drive))
}

/// Refine a model with added effects on the multiple-shooting residual
/// ([`Residuals::segmented`]), exact Jacobian, everything together (`base_free` and the
/// effects' keys). A base model fitted without a position-dependent torque drifts in angle,
/// and in free run the effect's phase then has a local minimum per period: the segments
/// restart from the measured angle.
///
/// The cost has nearby local minima (the inductance and inertia compensating a misplaced
/// effect: a hidden offset or cogging torque; a Stribeck bump below the speeds the axis
/// holds, with α0 at 0, standing in for Coulomb friction), and which one a refinement
/// reaches depends on its start. Each of `starts` (makers of structures without the effects:
/// the weak-form start and the base structure refined alone), with the effects of `model`
/// (their weak-form estimate) moved to their [`better_effect_start`], is refined, and the
/// refinement that ends cheapest is kept. The cheaper start does not always end cheaper: a
/// base structure refined into such a corner is close to the data at the start and stays in
/// the corner, while the weak-form start leaves it.
///
/// The starts are made and refined side by side, the first on this thread (which reports
/// its progress), the others on threads of their own: a refinement's trial runs are
/// sequential, so one start alone leaves a second core idle between its Jacobians.
pub fn refine_added_effects(
    model: &mut Model,
    starts: &[&StartMaker],
    base_free: &[Free],
    logs: &[MotorLog],
    opts: nlsq::Options,
) -> Result<Vec<Parameter>> {
    let stage = "with the added effects, 2 s segments";
    progress::report(stage, 0, f64::NAN);
    let seg = Residuals::segmented(logs, model.sensor.velocity_window);
    let mut free = base_free.to_vec();
    free.extend(super::linear::effect_free(model));
    let effects = &model.effects;
    let refine_from = |make: &StartMaker, report: &mut dyn FnMut(usize, f64)| {
        let mut m = make()?;
        m.effects = effects.clone();
        better_effect_start(&mut m, &seg);
        let rows = refine_on(&mut m, &free, &seg, Jacobian::Sensitivities, opts, report)?;
        let c = cost(&seg, &m);
        tracing::debug!("added effects refined: cost {c:.4e}");
        Ok((c, m, rows))
    };
    let Some((first, others)) = starts.split_first() else {
        bail!("no start for the added effects");
    };
    let ends: Vec<Result<(f64, Model, Vec<Parameter>)>> = std::thread::scope(|scope| {
        let handles: Vec<_> = others
            .iter()
            .map(|make| scope.spawn(|| refine_from(make, &mut |_, _| {})))
            .collect();
        let mut ends = vec![refine_from(first, &mut |it, c| {
            progress::report(stage, it, c)
        })];
        for h in handles {
            ends.push(match h.join() {
                Ok(end) => end,
                Err(panic) => std::panic::resume_unwind(panic),
            });
        }
        ends
    });
    let mut best: Option<(f64, Model, Vec<Parameter>)> = None;
    let mut first_err = None;
    // In the order of `starts`: the first of equally cheap ends is kept.
    for end in ends {
        match end {
            Ok(end) => {
                if best.as_ref().is_none_or(|b| end.0 < b.0) {
                    best = Some(end);
                }
            }
            Err(e) => {
                first_err.get_or_insert(e);
            }
        }
    }
    match (best, first_err) {
        (Some((_, m, rows)), _) => {
            *model = m;
            Ok(rows)
        }
        (None, Some(e)) => Err(e),
        (None, None) => bail!("no start for the added effects"),
    }
}

/// A start of [`refine_added_effects`]: makes a structure without the added effects.
pub type StartMaker<'a> = dyn Fn() -> Result<Model> + Sync + 'a;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::emulator::{simulate_signal, EmulatorConfig, SignalKind};
    use crate::log::Plant;
    use control::effects::Effect;

    /// A LuGre model away from the emulator's (so that every residual moves), with effects on
    /// every path of the sub-step: load torque by angle and by current, a voltage loss (the
    /// winding's inner root), a heat state and a sensor offset.
    fn model_and_free(cfg: &EmulatorConfig) -> (Model, Vec<Free>) {
        let mut m = Model::new(ModelKind::Lugre, Plant::Voltage, 0.012);
        m.motor = cfg.motor;
        m.motor.r *= 1.1;
        m.motor.j *= 0.8;
        let mut l = cfg.lugre;
        l.alpha0 *= 1.2;
        l.sigma0 = 30.0;
        l.sigma1 = 1.0;
        m.lugre = Some(l);
        m.effects = vec![
            Effect::Cogging {
                harmonic: 7,
                amp: 0.02,
                phase: 0.3,
            },
            Effect::Offset { t0: 0.01 },
            Effect::LoadFriction { mu: 0.05 },
            Effect::Deadtime { vd: 0.2 },
            Effect::Thermal { k: 0.001, tau: 5.0 },
            Effect::CurrentOffset { i0: 0.05 },
        ];
        let mut free: Vec<Free> = ["alpha0", "alpha1", "alpha2", "v0", "sigma0", "sigma1"]
            .into_iter()
            .map(|f| Free {
                slot: Slot::Lugre(f),
                lo: 0.0,
                hi: 1e6,
            })
            .collect();
        free.extend(super::super::linear::motor_free(Plant::Voltage));
        free.extend(super::super::linear::effect_free(&m));
        (m, free)
    }

    /// Segments of a log with a velocity column (the firmware's delayed estimate) take only
    /// the angle from it: on a log whose angle is the model's own free run, the
    /// multiple-shooting cost is the free run's. Without the column the velocity is the
    /// angle's centred slope and is taken too, so the segments restart from a velocity that
    /// is not the run's own (Hall-quantised), and the costs differ.
    #[test]
    fn segments_restart_the_states_the_log_measures_without_delay() {
        let cfg = EmulatorConfig::paper();
        let mut log = simulate_signal(&cfg, SignalKind::A, 6.0).unwrap().log;
        let model = cfg.truth_model();
        log.theta = freerun::simulate(&model, &log).unwrap().theta;
        let mut without = log.clone();
        without.omega = None;
        assert_eq!(Restart::for_log(&log), Restart::Angle);
        assert_eq!(Restart::for_log(&without), Restart::State);
        let costs = |log: MotorLog| {
            let logs = [log];
            let mut seg = Residuals::segmented(&logs, 10);
            seg.segment = Some(120);
            let free = Residuals::new(&logs, 10);
            (cost(&seg, &model), cost(&free, &model))
        };
        let (c_seg, c_free) = costs(log);
        assert!(c_free > 0.0);
        // Equal to rounding (3e-15 measured); without the column they differ by 1.5e-5.
        assert!(
            (c_seg - c_free).abs() <= 1e-12 * c_free,
            "segments {c_seg:.9e}, free run {c_free:.9e}"
        );
        let (c_seg, c_free) = costs(without);
        // 1e-6: a million times the rounding bound above, so this difference is not rounding.
        assert!(
            (c_seg - c_free).abs() > 1e-6 * c_free,
            "without a velocity column: segments {c_seg:.9e}, free run {c_free:.9e}"
        );
    }

    /// Grid costs given up early keep the lowest cost and its first model to the bit, and
    /// a model's cost that is not given up is [`cost`]'s.
    #[test]
    fn costs_given_up_keep_the_lowest_to_the_bit() {
        let cfg = EmulatorConfig::paper();
        let logs = [simulate_signal(&cfg, SignalKind::A, 12.0).unwrap().log];
        let mut seg = Residuals::segmented(&logs, 10);
        seg.segment = Some(120);
        let (model, _) = model_and_free(&cfg);
        // Inertias around the model's, and the cheapest of them again at the end (a tie).
        let mut factors = vec![1.3, 0.7, 1.1, 0.9, 1.0, 1.2, 0.8];
        let with_j = |f: f64| {
            let mut m = model.clone();
            m.motor.j *= f;
            m
        };
        let seven: Vec<f64> = factors.iter().map(|f| cost(&seg, &with_j(*f))).collect();
        let lowest = seven.iter().copied().fold(f64::INFINITY, f64::min);
        let first = seven.iter().position(|c| *c == lowest).unwrap();
        factors.push(factors[first]);
        let at = |k: usize| with_j(factors[k]);
        let full: Vec<f64> = (0..factors.len()).map(|k| cost(&seg, &at(k))).collect();
        for order in [vec![0, 1, 2, 3, 4, 5, 6, 7], vec![7, 4, 6, 5, 3, 2, 1, 0]] {
            let costs = lowest_costs(&seg, &order, f64::INFINITY, at);
            for (k, (c, f)) in costs.iter().zip(&full).enumerate() {
                assert!(
                    c == f || (c.is_infinite() && f > &lowest),
                    "{k}: {c} vs {f}"
                );
            }
            assert_eq!(costs[first], lowest);
            assert_eq!(costs[7], lowest, "the tie is not given up");
            assert!(costs.iter().all(|c| *c >= lowest));
        }
        // Against a bound below every cost, every model is given up within its first
        // segments; at the lowest cost, only that cost (and its tie) are kept.
        let costs = lowest_costs(&seg, &[0, 1, 2, 3, 4, 5, 6, 7], 0.5 * lowest, at);
        assert!(costs.iter().all(|c| c.is_infinite()), "{costs:?}");
        let costs = lowest_costs(&seg, &[0, 1, 2, 3, 4, 5, 6, 7], lowest, at);
        assert_eq!((costs[first], costs[7]), (lowest, lowest));
        // A free run is checked within its run, on part of its sum: a model is given up
        // there only above its bound, and kept at a bound equal to its full cost.
        let free = Residuals::new(&logs, 10);
        let m = at(0);
        let c = free.cost_below(&m, &|| 0.0).unwrap();
        assert_eq!(c, None);
        let full = cost(&free, &m);
        assert_eq!(free.cost_below(&m, &|| f64::INFINITY).unwrap(), Some(full));
        assert_eq!(free.cost_below(&m, &|| full).unwrap(), Some(full));
        // The free runs' lowest cost is the full runs', also with the runs given up within.
        let free_full: Vec<f64> = (0..factors.len()).map(|k| cost(&free, &at(k))).collect();
        let free_lowest = free_full.iter().copied().fold(f64::INFINITY, f64::min);
        let costs = lowest_costs(&free, &[0, 1, 2, 3, 4, 5, 6, 7], f64::INFINITY, at);
        assert_eq!(
            costs.iter().copied().fold(f64::INFINITY, f64::min),
            free_lowest
        );
        for (c, f) in costs.iter().zip(&free_full) {
            assert!(c == f || c.is_infinite(), "{c} vs {f}");
        }
    }

    #[test]
    fn sensitivities_match_central_differences() {
        let cfg = EmulatorConfig::paper();
        let res_a = simulate_signal(&cfg, SignalKind::A, 6.0).unwrap();
        let (model, free) = model_and_free(&cfg);
        check_sensitivities(&model, &free, &[res_a.log]);
    }

    /// The loads behind a coupling, a spring and a gap at once (their states in the same
    /// sub-step root), on a log of a motor with a compliant load, so that both move: the
    /// dual run's Jacobian in their parameters and the rotor's inertia is the derivative of
    /// the f64 run, and replays its roots bit for bit.
    #[test]
    fn sensitivities_match_central_differences_with_loads() {
        let truth = Effect::Compliance {
            j2: 6e-4,
            k: 0.2,
            c: 6e-4,
        };
        let cfg = EmulatorConfig::paper().with_effects(vec![truth]);
        let res_a = simulate_signal(&cfg, SignalKind::A, 6.0).unwrap();
        let mut m = cfg.truth_model();
        m.effects = vec![
            Effect::Compliance {
                j2: 5e-4,
                k: 0.25,
                c: 1e-3,
            },
            Effect::Backlash {
                j2: 1e-4,
                gap: 0.05,
            },
        ];
        let mut free = vec![Free {
            slot: Slot::J,
            lo: 1e-9,
            hi: 1.0,
        }];
        free.extend(super::super::linear::effect_free(&m));
        let names: Vec<String> = free.iter().map(|f| f.slot.name(&m)).collect();
        assert_eq!(
            names,
            [
                "J",
                "compliance.j2",
                "compliance.k",
                "compliance.c",
                "backlash.j2",
                "backlash.gap"
            ]
        );
        check_sensitivities(&m, &free, &[res_a.log]);
    }

    /// The exact Jacobian of `model`'s residuals on `logs` in the parameters `free`, free
    /// run and 120-sample segments: the dual run's values and a replay of the f64 run's
    /// sub-step roots are the f64 run's to the bit, and each column is the central
    /// differences' within 1e-4 relative.
    fn check_sensitivities(model: &Model, free: &[Free], logs: &[MotorLog]) {
        let model = model.clone();
        for segmented in [false, true] {
            let res = if segmented {
                let mut r = Residuals::segmented(logs, 10);
                r.segment = Some(120);
                r
            } else {
                Residuals::new(logs, 10)
            };
            let (r, jac) = res.eval_with_jacobian(&model, free, None).unwrap();
            // The dual run's values are the f64 run's, to the bit; so are its sub-steps'
            // roots, and with them replayed from the f64 run's tape it gives the same
            // Jacobian.
            let (r64, tape) = res.eval_recording(&model).unwrap();
            assert_eq!(r, res.eval(&model).unwrap());
            assert_eq!(r, r64);
            let steps = (logs[0].len() - 1) * freerun::SUBSTEPS;
            assert!(
                tape.len() >= steps,
                "{} roots for {steps} sub-steps",
                tape.len()
            );
            let replayed = res.eval_with_jacobian(&model, free, Some(&tape)).unwrap();
            assert_eq!((r.clone(), jac.clone()), replayed);
            assert_eq!(jac.len(), free.len());
            for (j, fr) in free.iter().enumerate() {
                let x = fr.slot.get(&model);
                let at = |v: f64| {
                    let mut m = model.clone();
                    fr.slot.set(&mut m, v);
                    res.eval(&m).unwrap()
                };
                let norm = jac[j].iter().map(|v| v * v).sum::<f64>().sqrt();
                let name = fr.slot.name(&model);
                assert!(norm > 0.0, "{name}: the residuals do not depend on it");
                // Central differences err by h² (truncation) for large steps and by the
                // residual's rounding (the sub-step's root tolerance) over h for small
                // ones: the best of a few steps is compared. 1e-4 is well above that floor,
                // and far below the order-one error of a missed or wrong term.
                let best = [1e-3, 1e-4, 1e-5, 1e-6]
                    .into_iter()
                    .map(|rel| {
                        let h = rel * x.abs().max(1e-3);
                        let (rp, rm) = (at(x + h), at(x - h));
                        let diff = rp
                            .iter()
                            .zip(&rm)
                            .zip(&jac[j])
                            .map(|((a, b), d)| ((a - b) / (2.0 * h) - d).powi(2))
                            .sum::<f64>()
                            .sqrt();
                        diff / norm
                    })
                    .fold(f64::INFINITY, f64::min);
                assert!(
                    best < 1e-4,
                    "{name} (segmented {segmented}): |J − central differences|/|J| = {best:.3e}"
                );
            }
        }
    }
}
