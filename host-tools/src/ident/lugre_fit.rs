//! LuGre model fitting (paper eqs. 12–14), following the paper's procedure:
//!
//! 1. motor constants and a first Coulomb/viscous estimate by weak-form regression
//!    ([`super::linear::weak_estimate`]);
//! 2. static parameters α0, α1, α2, v0 from steady-state points (velocity, friction torque):
//!    the second half of every run of constant input (the emulator's `steady` experiment,
//!    the paper's 0.4–0.6 V steps), or, without such runs, quasi-steady windows of any log
//!    (friction = K_t·I − J·dω/dt averaged over the window); the Stribeck curve is fitted to
//!    them by bounded nonlinear least squares;
//! 3. from there, the whole LuGre law (α0, α1, α2, v0, σ0, σ1) with the motor constants and
//!    added effects by bounded nonlinear least squares on the free-run simulation error (the
//!    paper's grey-box step, here joint: the steady points' friction carries the first
//!    estimate's K_t and J errors).
//!    The paper's σ0 acts below one Hall step (the bristle deflection s/σ0 is ~0.3 mrad
//!    against 95 mrad): when the data cannot pin it down the parameter table says so. A soft
//!    bristle (a geared axis's compliance seen at the rotor, `presliding`'s default σ0 = 0.4,
//!    a deflection of 2.6 Hall steps) is visible and identified (0.41 on 60 s of signal a).
use super::free_params::{Free, Slot};
use super::linear::{fixed_rows, motor_free, skeleton, weak_estimate};
use super::{nlsq, sim_error, FitRequest};
use crate::log::{MotorLog, Plant};
use crate::model::{LugreParams, Model, ModelKind};
use anyhow::{bail, Result};
use control::effects::{smooth_sign, VELOCITY_EPS};

/// Shortest run of constant input used as a steady-state point [s]: about 1 s (80 samples
/// at 12 ms).
const MIN_RUN_S: f64 = 0.96;
/// Time skipped at the start of a constant-input run (transient) [s]: many mechanical time
/// constants (J·R/(K_t·K_b) ≈ 13 ms) and presliding creeps (σ1/σ0 ≈ 70 ms).
const SETTLE_S: f64 = 0.48;
/// Quasi-steady window for logs without constant-input runs [s].
const QS_WINDOW_S: f64 = 0.6;

/// A duration [s] as a whole number of sample periods of `log`, at least `min` and at most
/// one more than the log's length (longer than any run or window of the log).
fn in_samples(log: &MotorLog, seconds: f64, min: usize) -> usize {
    let period = log.sample_period();
    let n = if period > 0.0 && period.is_finite() {
        // `as` saturates (and maps NaN to 0).
        (seconds / period).round() as usize
    } else {
        0
    };
    n.min(log.len() + 1).max(min)
}

/// Starting grid of the bristle stiffness σ0 [N·m/rad], over decades: from a geared axis's
/// compliance seen at the rotor (0.3: breakaway deflection of about 3 Hall steps at the
/// paper's friction) to stiffer than the paper's 317.
pub const SIGMA0_GRID: [f64; 5] = [0.3, 3.0, 30.0, 300.0, 3000.0];
/// Lower bound of σ0 [N·m/rad]: 0.01, a breakaway deflection of 10 rad at the paper's
/// friction (s(0)/σ0), more than a turn of the rotor: softer is no longer a bristle, and a
/// bound any stiffer would stop soft bristles of real motors (0.4 N·m/rad has been fitted).
pub const SIGMA0_MIN: f64 = 0.01;
/// A soft bristle start (σ0 < 30) is taken only when its simulation cost is below this
/// fraction of the best stiff start's.
pub const SOFT_START_RATIO: f64 = 0.7;

/// A steady-state point: velocity [rad/s], friction torque [N·m].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SteadyPoint {
    pub omega: f64,
    pub friction: f64,
}

/// Steady-state points of the logs: constant-input runs if there are at least 6 over all
/// logs, else quasi-steady windows.
pub fn all_steady_points(m: &Model, logs: &[MotorLog]) -> Vec<SteadyPoint> {
    let runs: Vec<SteadyPoint> = logs
        .iter()
        .flat_map(|l| steady_points(m, l, false))
        .collect();
    if runs.len() >= 6 {
        return runs;
    }
    logs.iter()
        .flat_map(|l| steady_points(m, l, true))
        .collect()
}

/// Steady-state points of a log (see the module doc), with the motor constants of `m`:
/// constant-input runs, or with `quasi` quasi-steady windows.
pub fn steady_points(m: &Model, log: &MotorLog, quasi: bool) -> Vec<SteadyPoint> {
    let res = super::sensor_chain::hall_resolution(log).max(m.sensor.hall_resolution_rad);
    let offset = control::effects::total_sensor_offset(&m.effects);
    // Motor torque minus the load torque of the model's other effects (offset, cogging...,
    // at their current estimates): what is left is the friction.
    let ws = crate::numerics::differentiation::smooth_velocity(log);
    let torque = |k: usize| -> Option<f64> {
        let cur = match (m.plant, &log.i) {
            (Plant::Voltage, Some(i)) => i[k] - offset,
            (Plant::Voltage, None) => return None,
            (Plant::Torque, _) => log.u[k],
        };
        let x = control::effects::EffectInputs {
            theta: log.theta[k],
            omega: ws[k],
            current: cur,
            kt: m.motor.kt,
        };
        Some(m.motor.kt * cur - control::effects::total_torque(&m.effects, &x))
    };
    let mut pts = Vec::new();
    let n = log.len();
    let min_run = in_samples(log, MIN_RUN_S, 3);
    let settle = in_samples(log, SETTLE_S, 0);
    let qs_window = in_samples(log, QS_WINDOW_S, 4);
    // Runs of constant input.
    let mut a = 0;
    while a < n && !quasi {
        let mut b = a + 1;
        while b < n && log.u[b] == log.u[a] {
            b += 1;
        }
        if b - a >= min_run {
            // Skip the transient (the first SETTLE_S seconds or a third of the run), then the
            // velocity is the least-squares slope of the angle: it averages the Hall steps.
            let s = a + settle.min((b - a) / 3);
            let e = b - 1;
            let moved = (log.theta[e] - log.theta[s]).abs();
            // Moving by less than two Hall steps: stuck (or unresolvable), not sliding.
            if moved > 2.0 * res.max(1e-9) {
                let w = slope(&log.t[s..=e], &log.theta[s..=e]);
                let tq: Option<Vec<f64>> = (s..=e).map(torque).collect();
                if let Some(tq) = tq {
                    pts.push(SteadyPoint {
                        omega: w,
                        friction: tq.iter().sum::<f64>() / tq.len() as f64,
                    });
                }
            }
        }
        a = b;
    }
    if !quasi {
        return pts;
    }
    // Quasi-steady windows: velocity from the angle over each half, inertia corrected.
    let mut s = 0;
    while s + qs_window < n {
        let e = s + qs_window;
        let mid = s + qs_window / 2;
        let w1 = (log.theta[mid] - log.theta[s]) / (log.t[mid] - log.t[s]);
        let w2 = (log.theta[e] - log.theta[mid]) / (log.t[e] - log.t[mid]);
        let wbar = (log.theta[e] - log.theta[s]) / (log.t[e] - log.t[s]);
        let acc = (w2 - w1) / (0.5 * (log.t[e] - log.t[s]));
        let moved = (log.theta[e] - log.theta[s]).abs() > 4.0 * res.max(1e-9);
        let steady = (w2 - w1).abs() < 0.1 * wbar.abs() && w1 * w2 > 0.0;
        if moved && steady {
            let tq: Option<Vec<f64>> = (s..=e).map(torque).collect();
            if let Some(tq) = tq {
                pts.push(SteadyPoint {
                    omega: wbar,
                    friction: tq.iter().sum::<f64>() / tq.len() as f64 - m.motor.j * acc,
                });
            }
        }
        s += qs_window / 2;
    }
    pts
}

/// Least-squares slope of y over t.
fn slope(t: &[f64], y: &[f64]) -> f64 {
    let n = t.len() as f64;
    let tm = t.iter().sum::<f64>() / n;
    let ym = y.iter().sum::<f64>() / n;
    let num: f64 = t.iter().zip(y).map(|(a, b)| (a - tm) * (b - ym)).sum();
    let den: f64 = t.iter().map(|a| (a - tm).powi(2)).sum();
    if den > 0.0 {
        num / den
    } else {
        0.0
    }
}

/// Fit the Stribeck curve `s(ω)·sgn(ω) + α2·ω` to steady points. Returns the parameters
/// (σ0, σ1 untouched) and the std errors of (α0, α1, α2, v0).
/// With `fix_alpha2` the viscous coefficient stays at `init.alpha2` (steady points over a
/// narrow velocity range cannot separate it from α0).
pub fn fit_static(
    pts: &[SteadyPoint],
    init: LugreParams,
    fix_alpha2: bool,
) -> Result<(LugreParams, Vec<f64>)> {
    if pts.len() < 5 {
        bail!(
            "only {} steady-state points: the static LuGre curve needs constant-input runs of \
             at least {MIN_RUN_S} s or slowly varying segments (record `motorid simulate \
             --signal steady` or the board's steady experiment and fit on it too)",
            pts.len()
        );
    }
    let mut f = |x: &[f64]| -> Result<Vec<f64>> {
        let l = LugreParams {
            alpha0: x[0],
            alpha1: x[1],
            alpha2: x[2],
            v0: x[3],
            ..init
        };
        Ok(pts
            .iter()
            .map(|p| {
                let sgn = smooth_sign(p.omega, VELOCITY_EPS);
                l.s(p.omega) * sgn + l.alpha2 * p.omega - p.friction
            })
            .collect())
    };
    let x0 = [init.alpha0, init.alpha1, init.alpha2, init.v0];
    let mut lo = [0.0, -10.0, 0.0, 0.05];
    let mut hi = [10.0, 10.0, 10.0, 500.0];
    if fix_alpha2 {
        lo[2] = init.alpha2;
        hi[2] = init.alpha2;
    }
    let scale = [
        init.alpha0.abs().max(1e-3),
        init.alpha1.abs().max(1e-3),
        init.alpha2.abs().max(1e-5),
        init.v0.abs().max(0.1),
    ];
    let opts = nlsq::Options {
        max_iter: 100,
        ..Default::default()
    };
    // Several starting Stribeck velocities: the curve is not convex in v0.
    let mut best: Option<nlsq::Solution> = None;
    for v0 in [init.v0, 1.0, 3.0, 10.0, 30.0] {
        let mut start = x0;
        start[3] = v0;
        if let Ok(sol) = nlsq::solve(&mut f, &start, &lo, &hi, &scale, opts, &mut |_, _| {}) {
            if best.as_ref().is_none_or(|b| sol.cost < b.cost) {
                best = Some(sol);
            }
        }
    }
    let sol = best.ok_or_else(|| anyhow::anyhow!("the static LuGre fit failed"))?;
    Ok((
        LugreParams {
            alpha0: sol.x[0],
            alpha1: sol.x[1],
            alpha2: sol.x[2],
            v0: sol.x[3],
            ..init
        },
        sol.std_err,
    ))
}

/// Starts of the Stribeck excess α1 (as a fraction of α0) and velocity v0 [rad/s, times the
/// logs' velocity scale] tried after a refinement.
const STRIBECK_RESTARTS: ([f64; 3], [f64; 4]) = ([0.1, 0.25, 0.5], [1.0, 3.0, 10.0, 30.0]);

/// After the refinement of `m`, try the [`STRIBECK_RESTARTS`] grid of (α1, v0) (one
/// simulation each, on rayon's threads, on the residuals the refinement ended on) and
/// refine again from the best start (exact Jacobian) if it costs less there; the refined
/// model replaces `m` only when it costs less. Returns the new parameter rows when it does.
///
/// A refinement can end in a corner where the inductance and inertia mimic a Stribeck bump
/// the friction law does not carry: with α1 at its bound 0, v0 has no effect on the cost
/// and the pair cannot leave; with added effects (the grid is then always tried), the
/// refinement from the base structure can also end with a small α1 and L and J compensating
/// (the case is measured in decision 0026). A grid that finds nothing cheaper costs twelve
/// simulations.
fn restart_stribeck(
    m: &mut Model,
    base_free: &[Free],
    logs: &[MotorLog],
) -> Result<Option<Vec<crate::model::Parameter>>> {
    let Some(l) = m.lugre else { return Ok(None) };
    // Without added effects only the corner at α1 = 0 is left by restarts.
    let at_zero = l.alpha1 <= 1e-9 * l.alpha0.abs().max(1e-12);
    if l.alpha0 <= 0.0 || (m.effects.is_empty() && !at_zero) {
        return Ok(None);
    }
    super::progress::report("other Stribeck starts", 0, f64::NAN);
    let window = m.sensor.velocity_window;
    let res = if m.effects.is_empty() {
        sim_error::Residuals::new(logs, window)
    } else {
        sim_error::Residuals::segmented(logs, window)
    };
    let vscale = (m.sign_width / control::effects::VELOCITY_EPS).clamp(1e-12, 1.0);
    let (fractions, speeds) = STRIBECK_RESTARTS;
    let starts: Vec<(f64, f64)> = fractions
        .iter()
        .flat_map(|&f| speeds.iter().map(move |&v| (f * l.alpha0, v * vscale)))
        .collect();
    let with = |a1: f64, v0: f64| {
        let mut t = m.clone();
        if let Some(tl) = t.lugre.as_mut() {
            tl.alpha1 = a1;
            tl.v0 = v0;
        }
        t
    };
    // Only a start cheaper than where the refinement ended is of use: the others' runs
    // stop once their segments so far cost more (∞).
    let ended_cost = sim_error::cost(&res, m);
    let order: Vec<usize> = (0..starts.len()).collect();
    let costs =
        sim_error::lowest_costs(&res, &order, ended_cost, |k| with(starts[k].0, starts[k].1));
    let Some((&(a1, v0), &best)) = starts.iter().zip(&costs).min_by(|a, b| a.1.total_cmp(b.1))
    else {
        return Ok(None);
    };
    tracing::debug!(
        "Stribeck restarts: cost {ended_cost:.4e}; best restart {best:.4e} at α1 {a1}, v0 {v0}"
    );
    if best >= ended_cost {
        return Ok(None);
    }
    let mut again = with(a1, v0);
    let mut free = base_free.to_vec();
    free.extend(super::linear::effect_free(&again));
    let report =
        |it: usize, c: f64| super::progress::report("refining from the new Stribeck start", it, c);
    // A restart that fails (a trial model that diverges throughout) keeps the first result.
    let Ok(rows) = sim_error::refine_on(
        &mut again,
        &free,
        &res,
        sim_error::Jacobian::Sensitivities,
        nlsq::Options::default(),
        &mut { report },
    ) else {
        return Ok(None);
    };
    let refined = sim_error::cost(&res, &again);
    tracing::debug!("Stribeck restart refined: cost {refined:.4e}");
    if refined < ended_cost {
        *m = again;
        return Ok(Some(rows));
    }
    Ok(None)
}

/// Fit the LuGre model.
pub fn fit(req: &FitRequest) -> Result<Model> {
    let mut m = skeleton(req, ModelKind::Lugre);
    let weak = weak_estimate(&mut m, req.logs, true);
    let (b, fc) = (weak.viscous, weak.coulomb);
    // Initial bristles: deflection of 1 mrad at breakaway, critically damped with the rotor
    // (σ1 = 2·sqrt(σ0·J)), the usual LuGre starting point (Canudas de Wit et al. 1995).
    let s_guess = fc.max(1e-4);
    let sigma0 = s_guess / 1e-3;
    let init = LugreParams {
        alpha0: fc,
        alpha1: 0.2 * fc,
        alpha2: b,
        v0: 3.0,
        sigma0,
        sigma1: 2.0 * (sigma0 * m.motor.j).sqrt(),
    };
    super::progress::report("static friction curve", 0, f64::NAN);
    let pts: Vec<SteadyPoint> = all_steady_points(&m, req.logs);
    // A fit with added effects refines from its own two starts (the weak form's and the
    // base structure's, itself fitted from two bristle starts).
    let other_start = start_dynamics(
        &mut m,
        req.logs,
        &pts,
        init,
        weak.creep,
        req.adds.is_empty(),
    )?;
    let free = free_parameters(req.plant);
    let mut dyn_rows = refine_from_starts(&mut m, other_start, &free, req)?;
    // The refinement can end where the inductance and inertia mimic a Stribeck bump (L
    // about twice and J 15 % below the emulator's, the current fit 4 points down): the
    // steady points seldom fix v0 (few of them below a few rad/s), so other (α1, v0) starts.
    if let Some(rows) = restart_stribeck(&mut m, &free, req.logs)? {
        dyn_rows = rows;
    }
    let lugre = m.lugre.unwrap_or(init);
    let static_note = |r: &mut crate::model::Parameter| {
        r.note = format!(
            "started from the static curve on {} steady-state points, refined on the \
             free-run simulation error{}",
            pts.len(),
            if r.note.is_empty() {
                String::new()
            } else {
                format!("; {}", r.note)
            }
        );
    };
    for r in &mut dyn_rows {
        if matches!(r.name.as_str(), "alpha0" | "alpha1" | "alpha2" | "v0") {
            static_note(r);
        }
    }
    if let Some(unseen) = bristle_scale_unseen(&m, req.logs) {
        let what = if unseen.ratio_seen {
            format!(
                "only the creep time σ1/σ0 = {:.3e} s is identified",
                lugre.sigma1 / lugre.sigma0.max(1e-300)
            )
        } else {
            "neither the bristles' scale nor their creep time is identified".to_string()
        };
        for r in &mut dyn_rows {
            if matches!(r.name.as_str(), "sigma0" | "sigma1") {
                r.identifiable = false;
                r.std_err = None;
                r.note = format!(
                    "{what}: {}; no standard error (the cost's curvature in the scale is the \
                     free run's sub-step's)",
                    unseen.why
                );
            }
        }
    }
    let res = m.sensor.hall_resolution_rad;
    for r in &mut dyn_rows {
        if r.name == "sigma0" && !r.identifiable && r.std_err.is_some() {
            r.note = format!(
                "{}; the bristle deflection s/σ0 = {:.2e} rad is far below one Hall step \
                 ({res:.3} rad)",
                r.note,
                lugre.s(0.0) / r.value.max(1e-300)
            );
        }
    }
    let mut rows = dyn_rows;
    rows.extend(fixed_rows(&m));
    m.parameters = rows;
    m.data.sample_period = m.sample_period;
    m.data.method = "weak-form regression (motor constants), Stribeck curve on steady-state \
                     points (start of alpha0, alpha1, alpha2, v0), then bounded \
                     Levenberg–Marquardt on the free-run simulation error (the whole LuGre \
                     law, motor constants, effects)"
        .into();
    Ok(m)
}

/// Refine `m` from its bristle start and, on another thread, from `other` (σ0, σ1) when
/// given; keep the refinement whose free run ends cheaper. A start's cost ranks starts,
/// not the minima a refinement reaches from them: a stiff, lightly damped bristle can cost
/// least at the start and lead, with a winding start the weak form misread on voltage steps,
/// to a minimum with the inductance several times too large.
fn refine_from_starts(
    m: &mut Model,
    other: Option<(f64, f64)>,
    free: &[Free],
    req: &FitRequest,
) -> Result<Vec<crate::model::Parameter>> {
    let Some((sigma0, sigma1)) = other else {
        return super::refine_free_run(m, free, req);
    };
    let mut second = m.clone();
    if let Some(l) = second.lugre.as_mut() {
        (l.sigma0, l.sigma1) = (sigma0, sigma1);
    }
    // The first on this thread (its progress is the one shown), the second beside it.
    let (first_rows, second_rows) = std::thread::scope(|s| {
        let other = s.spawn(|| super::refine_free_run(&mut second, free, req));
        let first = super::refine_free_run(m, free, req);
        let other = other
            .join()
            .unwrap_or_else(|_| Err(anyhow::anyhow!("the second refinement panicked")));
        (first, other)
    });
    let res = sim_error::Residuals::new(req.logs, m.sensor.velocity_window);
    let second_cost = |rows: &Result<_>| match rows {
        Ok(_) => sim_error::cost(&res, &second),
        Err(_) => f64::INFINITY,
    };
    let take_second = match &first_rows {
        Ok(_) => second_cost(&second_rows) < sim_error::cost(&res, m),
        Err(_) => second_rows.is_ok(),
    };
    if take_second {
        tracing::debug!("the second bristle start ends cheaper: σ0 {sigma0}, σ1 {sigma1}");
        *m = second;
        return second_rows;
    }
    first_rows
}

/// The start of the base structure's refinement: the static curve fitted to the steady
/// points `pts` from `init`, then the bristles from a grid (below). Returns, when
/// `second` asks for it, a second start (σ0, σ1) of another stiffness: the cheapest stiff
/// start with another σ0 than the one taken.
fn start_dynamics(
    m: &mut Model,
    logs: &[MotorLog],
    pts: &[SteadyPoint],
    init: LugreParams,
    creep: Option<f64>,
    second: bool,
) -> Result<Option<(f64, f64)>> {
    let (lugre, _static_se) = fit_static(pts, init, false)?;
    m.lugre = Some(lugre);
    let sigma0 = init.sigma0;
    // Dynamic step. The simulation error has local minima in (σ0, σ1) (σ1 → 0 with a
    // too-slow winding, for one): start from the best of a coarse grid over decades. The
    // soft end (0.3 and 3 N·m/rad; 0.3 is a breakaway deflection of 0.3 rad, 3 Hall steps,
    // at the paper's friction) is a geared axis's compliance seen at the rotor
    // (`presliding`'s default); soft bristles are tried critically damped with the rotor,
    // σ1 = 2·√(σ0·J) (0.02 at σ0 = 0.4, which the decade grid of σ1 misses), and at 0.1 and
    // 1. A stiff grid alone can leave a soft bristle in the local minimum near σ0 ≈ 10.
    {
        super::progress::report("bristle start grid", 0, f64::NAN);
        let res = sim_error::Residuals::new(logs, m.sensor.velocity_window);
        // Best start among the stiff (≥ 30) and among the soft grid points, separately.
        let mut best = (f64::INFINITY, sigma0, init.sigma1);
        let mut best_soft = (f64::INFINITY, sigma0, init.sigma1);
        let starts: Vec<(f64, f64)> = SIGMA0_GRID
            .iter()
            .flat_map(|&s0| {
                let soft = vec![2.0 * (s0 * m.motor.j.max(0.0)).sqrt(), 0.1, 1.0];
                let mut stiff = vec![0.1, 1.0, 10.0, 30.0];
                stiff.extend(creep.map(|c| c * s0));
                let s1s = if s0 < 30.0 { soft } else { stiff };
                s1s.into_iter().map(move |s1| (s0, s1))
            })
            .collect();
        let trial = |k: usize| {
            let mut trial = sim_error::scale_effect_magnitudes(m, 0.0);
            if let Some(l) = trial.lugre.as_mut() {
                (l.sigma0, l.sigma1) = starts[k];
            }
            trial
        };
        // The starts' free runs side by side on rayon's threads, each given up once it
        // cannot be the one taken: the stiff starts above the lowest stiff cost; then the
        // soft starts above the lowest soft cost or the ratio of the stiff one they must
        // beat. The lowest costs are the full runs' (`sim_error::lowest_costs`).
        let (soft, stiff): (Vec<usize>, Vec<usize>) =
            (0..starts.len()).partition(|&k| starts[k].0 < 30.0);
        let in_order = |v: &[usize]| (0..v.len()).collect::<Vec<usize>>();
        let stiff_costs =
            sim_error::lowest_costs(&res, &in_order(&stiff), f64::INFINITY, |k| trial(stiff[k]));
        for (&k, &c) in stiff.iter().zip(&stiff_costs) {
            if c < best.0 {
                best = (c, starts[k].0, starts[k].1);
            }
        }
        let bound = SOFT_START_RATIO * best.0;
        let soft_costs = sim_error::lowest_costs(&res, &in_order(&soft), bound, |k| trial(soft[k]));
        for (&k, &c) in soft.iter().zip(&soft_costs) {
            if c < best_soft.0 {
                best_soft = (c, starts[k].0, starts[k].1);
            }
        }
        // A soft start only when it is clearly better: with stiff bristles in the data a
        // soft start that costs a little less at the grid can lead the refinement to a
        // worse local minimum; a soft bristle the data really shows costs far less.
        tracing::debug!("bristle start (cost, sigma0, sigma1): stiff {best:?}, soft {best_soft:?}");
        if best_soft.0 < SOFT_START_RATIO * best.0 {
            best = best_soft;
        }
        // The cheapest stiff start of another σ0: its own runs, given up above the lowest
        // among them (the first pass gave up most of them above the taken one's cost).
        let others: Vec<usize> = stiff
            .iter()
            .copied()
            .filter(|&k| second && starts[k].0 != best.1)
            .collect();
        let other_costs = sim_error::lowest_costs(&res, &in_order(&others), f64::INFINITY, |k| {
            trial(others[k])
        });
        let other = others
            .iter()
            .zip(&other_costs)
            .filter(|(_, c)| c.is_finite())
            .min_by(|a, b| a.1.total_cmp(b.1))
            .map(|(&k, _)| starts[k]);
        if let Some(l) = m.lugre.as_mut() {
            l.sigma0 = best.1;
            l.sigma1 = best.2;
        }
        tracing::debug!("second bristle start (sigma0, sigma1): {other:?}");
        Ok(other)
    }
}

/// Why the logs show the bristles' ratio σ1/σ0 and not their scale, or None when they may
/// show the scale. The stiffness shows either as a deflection the angle sensor resolves or
/// as a mode the samples resolve. At breakaway the bristles stretch `s(0)/σ0`; the rotor on
/// its bristles, `J·ẍ + c·ẋ + σ0·x` with `c = σ1 + α2 + K_t·K_b/R`, has poles whose product
/// is `σ0/J` and sum `c/J`. When the deflection is below one Hall step and the fast pole
/// settles within a sample (`|p|·h > 1`) while the slow one, about `σ0/c`, does not, all the
/// logs show is the creep time `c/σ0`, which σ1/σ0 sets when σ1 dominates c.
fn bristle_scale_unseen(m: &Model, logs: &[MotorLog]) -> Option<BristleScale> {
    let l = m.lugre?;
    let hall = m.sensor.hall_resolution_rad;
    let h = logs
        .iter()
        .map(|g| g.sample_period())
        .filter(|p| p.is_finite() && *p > 0.0)
        .min_by(f64::total_cmp)?;
    let j = m.motor.j;
    if !(l.sigma0 > 0.0 && j > 0.0 && hall > 0.0) {
        return None;
    }
    let deflection = l.s(0.0) / l.sigma0;
    let electrical = if m.plant == Plant::Voltage && m.motor.r > 0.0 {
        m.motor.kt * m.motor.kb / m.motor.r
    } else {
        0.0
    };
    let c = l.sigma1 + l.alpha2 + electrical;
    let disc = c * c - 4.0 * j * l.sigma0;
    if disc <= 0.0 {
        // An oscillating bristle mode: its frequency `√(σ0/J)` carries the scale, unless
        // it lies above the samples' Nyquist frequency and its envelope (`c/2J`) dies
        // within a sample; then the creep time `c/σ0` (at most two samples here) is gone
        // with it, and the logs show neither.
        let (wn, decay) = ((l.sigma0 / j).sqrt(), c / (2.0 * j));
        return (deflection < hall && wn * h > std::f64::consts::PI && decay * h > 1.0).then(
            || BristleScale {
                ratio_seen: false,
                why: format!(
                    "the bristles stretch {deflection:.2e} rad at breakaway, below one Hall \
                     step ({hall:.3} rad), and their mode ({:.0} Hz) lies above the samples' \
                     Nyquist frequency and dies within a sample ({h} s)",
                    wn / (2.0 * std::f64::consts::PI)
                ),
            },
        );
    }
    let (fast, slow) = ((c + disc.sqrt()) / (2.0 * j), (c - disc.sqrt()) / (2.0 * j));
    (deflection < hall && fast * h > 1.0 && slow * h < 1.0).then(|| BristleScale {
        ratio_seen: true,
        why: format!(
            "the bristles stretch {deflection:.2e} rad at breakaway, below one Hall step \
             ({hall:.3} rad), and the rotor's fast presliding pole ({:.1e} s) settles \
             within a sample ({h} s)",
            1.0 / fast
        ),
    })
}

/// Why the logs do not show the bristles' scale ([`bristle_scale_unseen`]), and whether
/// they show the creep time σ1/σ0.
struct BristleScale {
    ratio_seen: bool,
    why: String,
}

/// The parameters the LuGre refinement moves, with bounds: the whole LuGre law and the
/// motor constants.
fn free_parameters(plant: Plant) -> Vec<Free> {
    // The static curve is only the starting point: the whole LuGre law is refined jointly
    // with the motor constants on the simulation error. Refining only (α2, σ0, σ1, motor)
    // left the static curve biased by the steady points' K_t and J, and the validation
    // velocity fit 1.2 points below the emulator's own model; jointly, 0.45 points
    // (emulated paper motor, signal a + steady, validated on b).
    let mut free: Vec<Free> = [
        ("alpha0", 0.0, 10.0),
        // α1 = F_s − F_c, the Stribeck excess of static over Coulomb friction: physically
        // ≥ 0. With it free to go negative, a hidden cogging is mimicked by a friction dip
        // at low speed (α1 < 0 with v0 at its lower bound), from which `fit --add cogging`
        // cannot get back (tests/tests/fit_add_effects.rs).
        ("alpha1", 0.0, 10.0),
        ("alpha2", 0.0, 10.0),
        ("v0", 0.05, 500.0),
        ("sigma0", SIGMA0_MIN, 1e6),
        ("sigma1", 0.0, 1e3),
    ]
    .into_iter()
    .map(|(f, lo, hi)| Free {
        slot: Slot::Lugre(f),
        lo,
        hi,
    })
    .collect();
    free.extend(motor_free(plant));
    free
}

#[cfg(test)]
mod tests {
    use super::*;

    fn log_at(period: f64, n: usize) -> MotorLog {
        MotorLog {
            t: (0..n).map(|k| k as f64 * period).collect(),
            u: vec![0.0; n],
            theta: vec![0.0; n],
            ..Default::default()
        }
    }

    #[test]
    fn steady_windows_are_durations() {
        // At 12 ms the windows are the sample counts the fit was tuned with.
        let l = log_at(0.012, 10_000);
        assert_eq!(in_samples(&l, MIN_RUN_S, 3), 80);
        assert_eq!(in_samples(&l, SETTLE_S, 0), 40);
        assert_eq!(in_samples(&l, QS_WINDOW_S, 4), 50);
        // Ten times the rate, ten times the samples.
        let l = log_at(0.0012, 10_000);
        assert_eq!(in_samples(&l, QS_WINDOW_S, 4), 500);
        // Longer than the log: one more than its length; no period: the minimum.
        assert_eq!(in_samples(&log_at(1e-9, 100), QS_WINDOW_S, 4), 101);
        assert_eq!(in_samples(&log_at(0.0, 100), QS_WINDOW_S, 4), 4);
    }

    /// The paper motor's bristles at a stiffness `sigma0` and damping `sigma1` on 12 ms logs.
    fn paper_with(sigma0: f64, sigma1: f64) -> Option<BristleScale> {
        let mut m = Model::new(ModelKind::Lugre, Plant::Voltage, 0.012);
        m.motor = control::motor::MotorParams::<f64>::paper();
        m.sensor.hall_resolution_rad = 0.0952;
        let mut l = LugreParams::paper();
        (l.sigma0, l.sigma1) = (sigma0, sigma1);
        m.lugre = Some(l);
        bristle_scale_unseen(&m, &[log_at(0.012, 100)])
    }

    #[test]
    fn bristle_scale_seen_only_where_a_deflection_or_a_mode_shows_it() {
        // The paper's overdamped bristles: the creep time alone.
        assert!(paper_with(317.0, 22.0).is_some_and(|b| b.ratio_seen));
        // Stiff, lightly damped: a 500 Hz mode far above the 42 Hz Nyquist frequency that
        // dies within a sample: neither shows.
        assert!(paper_with(3000.0, 0.1).is_some_and(|b| !b.ratio_seen));
        // A soft bristle stretching several Hall steps shows its scale.
        assert!(paper_with(0.4, 0.05).is_none());
    }
}
