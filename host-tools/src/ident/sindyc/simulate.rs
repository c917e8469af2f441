//! Free run of a SINDYc model: states `(x, ẋ, z, I)`, `u` held between samples (zero-order
//! hold, as the board applies it). Steps are exponential Rosenbrock–Euler (exact for the
//! linear part, stable however stiff the current or `z` equation), [`SUBSTEPS`] sub-steps per
//! sample; `z` is clamped to `±z_max` after each step as the firmware's observer does. A
//! non-finite state or a velocity/current beyond [`Limits`] is a divergence: an error, never
//! a NaN.
use super::step::{Stepper, MAX_SPLITS};
use crate::ident::freerun::{self, Prediction};
use crate::ident::{fitpct, sensor_chain};
use crate::log::{MotorLog, Plant};
use anyhow::{anyhow, bail, Result};
use control::sindy::SindyModel;

/// Sub-steps per sample of the free run. The exponential Rosenbrock–Euler step is exact for
/// the linear part of the equations, so one step a sample leaves only the frozen-Jacobian
/// error of the nonlinear terms. On the emulated paper motor (fit on signal a) two sub-steps
/// change the validation fit on ẋ by less than 0.3 points and the current's on the voltage
/// steps of signal d by about 4 (the current follows the velocity within a sample), at
/// twice the cost of every free run; docs/performance-sindyc.md has the figures.
pub const SUBSTEPS: usize = 1;

/// Limits beyond which a free run counts as divergent.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    pub omega: f64,
    pub current: f64,
}

impl Default for Limits {
    /// Limits for scoring a finished model: only a runaway (1e7) is a divergence.
    fn default() -> Self {
        Limits {
            omega: 1e7,
            current: 1e7,
        }
    }
}

/// Free-run simulation of a SINDYc model with the input of `log` from its first samples.
/// Errors when the model diverges (never returns non-finite values).
pub fn simulate(
    model: &SindyModel<f64>,
    plant: Plant,
    log: &MotorLog,
    limits: Limits,
) -> Result<Prediction> {
    simulate_substeps(model, plant, log, limits, SUBSTEPS)
}

/// [`simulate`] with `sub` sub-steps per sample.
pub fn simulate_substeps(
    model: &SindyModel<f64>,
    plant: Plant,
    log: &MotorLog,
    limits: Limits,
    sub: usize,
) -> Result<Prediction> {
    let sub = sub.max(1);
    let n = log.len();
    if n == 0 {
        bail!(
            "{}: the log has no samples",
            crate::log::echo_path(&log.source)
        );
    }
    let voltage = plant == Plant::Voltage;
    let i0 = match (&log.i, voltage) {
        (Some(i), true) => i[0],
        _ => 0.0,
    };
    let start = [log.theta[0], freerun::initial_omega(log), 0.0, i0];
    let stepper = Stepper::new(model, voltage);
    // The state after sample k from the one at k. With `incs`, the angle enters at -0 and
    // the increments of a halved step's parts but the last are pushed on `incs` (see
    // `advance`; one sub-step a sample): the angle's entry of the result is the last part's
    // increment, exactly (`-0 + x = x`). A run whose steps do not depend on the angle gives
    // the same other states either way.
    let step = |k: usize, s: &[f64; 4], mut incs: Option<&mut Vec<f64>>| -> Result<[f64; 4]> {
        let u = log.u[k];
        let dt = (log.t[k + 1] - log.t[k]) / sub as f64;
        let mut r = *s;
        if incs.is_some() {
            r[0] = -0.0;
        }
        for _ in 0..sub {
            let mut splits = MAX_SPLITS;
            r = stepper
                .advance(&r, u, dt, &mut splits, incs.as_deref_mut(), None)
                .ok_or_else(|| {
                    anyhow!(
                        "{}: time step {} s before sample {} is too long for the SINDYc model, or \
                     the model's coefficients too large (its matrix exponential is out of \
                     range)",
                        crate::log::echo_path(&log.source),
                        log.t[k + 1] - log.t[k],
                        k + 2
                    )
                })?;
        }
        if !r.iter().all(|v| v.is_finite())
            || r[1].abs() > limits.omega
            || r[3].abs() > limits.current
        {
            bail!(
                "{}: the SINDYc model diverged in free run at t = {} s (sample {})",
                crate::log::echo_path(&log.source),
                log.t[k + 1],
                k + 2
            );
        }
        Ok(r)
    };
    let states = if stepper.uses_angle() || sub > 1 || n < 2 * super::pieces::MIN_PIECE {
        let mut states = Vec::with_capacity(n);
        states.push(start);
        for k in 0..n - 1 {
            let next = step(k, &states[k], None)?;
            states.push(next);
        }
        states
    } else {
        // In pieces, a step returns the angle's increment, and NaN in its place when the
        // step was halved: the increments of its parts, which are added to the angle one
        // after the other (each sum rounded), are kept by sample (a re-run's after the
        // guessed run's). The angles are then summed in order.
        let parts = std::sync::Mutex::new(Vec::<(usize, Vec<f64>)>::new());
        let inc = |k: usize, s: &[f64; 4]| -> Result<[f64; 4]> {
            let mut incs = Vec::new();
            let mut r = step(k, s, Some(&mut incs))?;
            if !incs.is_empty() {
                incs.push(r[0]);
                r[0] = f64::NAN;
                parts
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner)
                    .push((k, incs));
            }
            Ok(r)
        };
        let mut states = run_in_pieces(log, voltage, start, &inc)?;
        let parts: std::collections::HashMap<usize, Vec<f64>> = parts
            .into_inner()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .into_iter()
            .collect();
        for k in 1..n {
            let mut theta = states[k - 1][0];
            match parts.get(&(k - 1)).filter(|_| states[k][0].is_nan()) {
                Some(incs) => incs.iter().for_each(|d| theta += d),
                None => theta += states[k][0],
            }
            if !theta.is_finite() {
                bail!(
                    "{}: the SINDYc model diverged in free run at t = {} s (sample {})",
                    crate::log::echo_path(&log.source),
                    log.t[k],
                    k + 1
                );
            }
            states[k][0] = theta;
        }
        states
    };
    Ok(Prediction {
        t: log.t.clone(),
        theta: states.iter().map(|s| s[0]).collect(),
        omega: states.iter().map(|s| s[1]).collect(),
        i: voltage.then(|| states.iter().map(|s| s[3]).collect()),
        z: Some(states.iter().map(|s| s[2]).collect()),
    })
}

/// The states of a free run whose steps do not depend on the angle (see [`simulate`]),
/// computed in parallel pieces ([`super::pieces`]) when the log is long: the same states to
/// the bit as one run from the start. A piece starts from the log's measured velocity
/// (centred slope of the angle over ±5 samples, or its `omega` column) and current.
fn run_in_pieces(
    log: &MotorLog,
    voltage: bool,
    start: [f64; 4],
    step: &(impl Fn(usize, &[f64; 4]) -> Result<[f64; 4]> + Sync),
) -> Result<Vec<[f64; 4]>> {
    let n = log.len();
    let guess = |k: usize| {
        let w = match &log.omega {
            Some(w) => w[k],
            None => {
                let (a, b) = (k.saturating_sub(5), (k + 5).min(n - 1));
                (log.theta[b] - log.theta[a]) / (log.t[b] - log.t[a])
            }
        };
        let i = match (&log.i, voltage) {
            (Some(i), true) => i[k],
            _ => 0.0,
        };
        [0.0, w, 0.0, i]
    };
    super::pieces::run(n, start, step, &guess, 2 * rayon::current_num_threads())
}

/// Duration [s] of log a set of free runs that judges candidate models may hold (the
/// structure search's validation runs, the refinement's fitting runs): 8192 samples at
/// 12 ms, more than the paper's 90 s signals, which are therefore used whole. A
/// computational budget, not a physical constant: it bounds the cost of every model
/// evaluation whatever the length of the logs, so that identification is linear in the data
/// (one pass for the embedding and the weak form) plus a fixed cost for the search.
pub const EVALUATION_SECONDS: f64 = 98.304;
/// Most samples [`evaluation_budget`] gives, whatever the sample rate (eight times the
/// budget at 12 ms): a fast log is judged on a shorter stretch of time rather than at a
/// cost that grows with its rate.
pub const EVALUATION_MAX_SAMPLES: usize = 65_536;

/// Samples of `logs` a set of free runs that judges candidate models may hold:
/// [`EVALUATION_SECONDS`] at the first log's sample period, at most
/// [`EVALUATION_MAX_SAMPLES`].
pub fn evaluation_budget(logs: &[MotorLog]) -> usize {
    let total: usize = logs.iter().map(MotorLog::len).sum();
    let dt = logs.first().map_or(0.0, MotorLog::sample_period);
    crate::scales::samples_for(EVALUATION_SECONDS, dt, total).min(EVALUATION_MAX_SAMPLES)
}
/// Number of segments [`bounded_segments`] spreads its budget over.
const EVALUATION_SEGMENTS: usize = 4;

/// Up to `budget` samples of `logs` to simulate candidate models on: the logs themselves
/// when they hold no more, else [`EVALUATION_SEGMENTS`] segments of `budget /
/// EVALUATION_SEGMENTS` samples spread evenly over the logs (first and last samples
/// included), each a free run of its own from the measured state at its start (as the
/// segments of a multiple-shooting fit). A log shorter than a segment is taken whole.
pub fn bounded_segments(logs: &[MotorLog], budget: usize) -> Vec<MotorLog> {
    let total: usize = logs.iter().map(MotorLog::len).sum();
    if total <= budget {
        return logs.to_vec();
    }
    let seg = (budget / EVALUATION_SEGMENTS).max(1);
    let mut picked: Vec<(usize, usize, usize)> = Vec::new();
    for k in 0..EVALUATION_SEGMENTS {
        let global = k * (total - seg) / (EVALUATION_SEGMENTS - 1);
        // The log holding sample `global` of the concatenation, and the offset in it.
        let (mut idx, mut offset) = (0, global);
        while offset >= logs[idx].len() {
            offset -= logs[idx].len();
            idx += 1;
        }
        let len = logs[idx].len();
        let range = if len <= seg {
            (idx, 0, len)
        } else {
            let start = offset.min(len - seg);
            (idx, start, start + seg)
        };
        if !picked.contains(&range) {
            picked.push(range);
        }
    }
    picked
        .into_iter()
        .map(|(idx, start, end)| sub_log(&logs[idx], start, end))
        .collect()
}

/// Samples `start..end` of a log as a log of its own (metadata kept, extra columns dropped).
fn sub_log(log: &MotorLog, start: usize, end: usize) -> MotorLog {
    MotorLog {
        source: format!("{} (samples {}..{})", log.source.display(), start + 1, end).into(),
        meta: log.meta.clone(),
        t: log.t[start..end].to_vec(),
        u: log.u[start..end].to_vec(),
        i: log.i.as_ref().map(|v| v[start..end].to_vec()),
        theta: log.theta[start..end].to_vec(),
        omega: log.omega.as_ref().map(|v| v[start..end].to_vec()),
        extra: Vec::new(),
        units: log.units.clone(),
    }
}

/// Mean validation fit on ẋ of a model's free run **through the sensor chain** (the
/// `fit_sensor` of `compare`: the model's angle Hall-quantised with the log's resolution and
/// differentiated by the firmware's moving average, against the measured velocity
/// `omegas[k]` of `logs[k]`); `None` when the model diverges on any log. The logs (the
/// segments of [`bounded_segments`]) run in parallel.
pub fn validation_fit(
    m: &SindyModel<f64>,
    plant: Plant,
    logs: &[MotorLog],
    omegas: &[Vec<f64>],
    window: usize,
    limits: Limits,
) -> Option<f64> {
    use rayon::prelude::*;
    let fits: Option<Vec<f64>> = logs
        .par_iter()
        .zip(omegas)
        .map(|(log, w)| {
            let pred = simulate(m, plant, log, limits).ok()?;
            let res = sensor_chain::hall_resolution(log);
            let (_, wq) = sensor_chain::through_sensor(&pred.t, &pred.theta, res, window);
            fitpct::fit_percent(w, &wq).ok()
        })
        .collect();
    Some(fits?.iter().sum::<f64>() / logs.len().max(1) as f64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use control::sindy::{SparseEq, Term};

    /// A log of `n` samples at `dt` with input `u(k)` (angle and current zero).
    fn log_with_input(n: usize, dt: f64, u: impl Fn(usize) -> f64) -> MotorLog {
        MotorLog {
            t: (0..n).map(|k| k as f64 * dt).collect(),
            u: (0..n).map(u).collect(),
            theta: vec![0.0; n],
            i: Some(vec![0.0; n]),
            ..MotorLog::default()
        }
    }

    #[test]
    fn a_linear_model_follows_its_exact_step_response() {
        // dẋ/dt = −ẋ/τ + g·u, dI/dt = −I/τe + u/L: both first order, u held at 1.
        let (tau, g, tau_e, l) = (0.013, 80.0, 0.0014, 3e-4);
        let mut m = SindyModel::empty(5.0, 1.0, 1.0);
        m.accel = SparseEq::from_slice(&[(Term::Xdot, -1.0 / tau), (Term::U, g)]).unwrap();
        m.idot = SparseEq::from_slice(&[(Term::I, -1.0 / tau_e), (Term::U, 1.0 / l)]).unwrap();
        let dt = 0.012;
        let log = log_with_input(200, dt, |_| 1.0);
        let p = simulate(&m, Plant::Voltage, &log, Limits::default()).unwrap();
        for k in [1, 5, 50, 199] {
            let t = k as f64 * dt;
            let w = g * tau * (1.0 - (-t / tau).exp());
            let i = tau_e / l * (1.0 - (-t / tau_e).exp());
            // 1e-6 relative: linear equations are stepped by their exact exponential, so
            // only rounding and the step's own solve tolerance remain.
            assert!(
                (p.omega[k] - w).abs() < 1e-6 * w.abs().max(1.0),
                "ω[{k}] {} vs {w}",
                p.omega[k]
            );
            assert!((p.i.as_ref().unwrap()[k] - i).abs() < 1e-6 * i, "I[{k}]");
        }
        // The angle integrates the velocity (second order in the step: within 1 %).
        let t = 199.0 * dt;
        let x = g * tau * (t - tau * (1.0 - (-t / tau).exp()));
        assert!(
            (p.theta[199] - x).abs() < 1e-2 * x,
            "{} vs {x}",
            p.theta[199]
        );
    }

    #[test]
    fn a_start_from_rest_under_a_sign_like_friction_follows_the_exact_response() {
        // dẋ/dt = −ẋ/τ + g·u − c·tanh(a·ẋ), u held at 1 from rest. Beyond a few 1/a the tanh
        // is 1: ẋ(t) = τ·(g − c)·(1 − e^(−t/τ)), up to the microseconds spent crossing its
        // kink. A step that froze the tanh's slope at ẋ = 0 (a·c = 2000 1/s of damping)
        // over the whole first sample would land far below.
        let (tau, g, c, a) = (0.013, 1000.0, 250.0, 8.0);
        let mut m = SindyModel::empty(a, 1.0, 1.0);
        m.accel =
            SparseEq::from_slice(&[(Term::Xdot, -1.0 / tau), (Term::U, g), (Term::TanhXdot, -c)])
                .unwrap();
        let dt = 0.012;
        let log = log_with_input(20, dt, |_| 1.0);
        let p = simulate(&m, Plant::Torque, &log, Limits::default()).unwrap();
        for k in [1, 2, 10] {
            let t = k as f64 * dt;
            let w = tau * (g - c) * (1.0 - (-t / tau).exp());
            // 5e-3 relative: while |ẋ| < 1/a the friction is below c, which adds about
            // c·ln2/(a·g) ≈ 0.02 rad/s, a few 1e-3 of ω at the first sample and less later;
            // a frozen slope misses by tens of %.
            assert!(
                (p.omega[k] - w).abs() < 5e-3 * w,
                "ω[{k}] {} vs {w}",
                p.omega[k]
            );
        }
        assert_eq!(
            super::super::step::sign_kinks(&m, false),
            vec![(1, 1.0 / a)]
        );
    }

    #[test]
    fn the_evaluation_budget_is_a_duration_of_the_log() {
        // 8192 samples at 12 ms; the same 98 s at 24 ms; at 1 ms the cap.
        let budget = |dt: f64, n: usize| evaluation_budget(&[log_with_input(n, dt, |_| 0.0)]);
        assert_eq!(budget(0.012, 100_000), 8192);
        assert_eq!(budget(0.024, 100_000), 4096);
        assert_eq!(budget(0.001, 100_000), EVALUATION_MAX_SAMPLES);
        // Never more than the logs hold.
        assert_eq!(budget(0.012, 500), 500);
    }

    #[test]
    fn a_divergent_model_is_an_error_not_a_nan() {
        let mut m = SindyModel::empty(5.0, 1.0, 1.0);
        m.accel = SparseEq::from_slice(&[(Term::Xdot, 50.0), (Term::U, 1.0)]).unwrap();
        let log = log_with_input(500, 0.012, |_| 1.0);
        let limits = Limits {
            omega: 1e3,
            current: 1e3,
        };
        let e = simulate(&m, Plant::Voltage, &log, limits)
            .unwrap_err()
            .to_string();
        assert!(e.contains("diverged"), "{e}");
        assert!(
            validation_fit(&m, Plant::Voltage, &[log], &[vec![0.0; 500]], 10, limits).is_none()
        );
    }

    #[test]
    fn the_hidden_state_stays_within_its_bound() {
        let mut m = SindyModel::empty(5.0, 1.0, 1.0);
        m.z_max = 2.0;
        m.accel = SparseEq::from_slice(&[(Term::Xdot, -10.0), (Term::U, 10.0)]).unwrap();
        m.zdot = SparseEq::from_slice(&[(Term::Xdot, 100.0)]).unwrap();
        let log = log_with_input(300, 0.012, |k| if k < 150 { 1.0 } else { -1.0 });
        let p = simulate(&m, Plant::Torque, &log, Limits::default()).unwrap();
        let z = p.z.unwrap();
        // The bound holds up to rounding (1e-12), and the state does reach it (within 5 %):
        // the drive saturates it, so a bound never reached would test nothing.
        assert!(z.iter().all(|z| z.abs() <= 2.0 + 1e-12));
        assert!(z.iter().any(|z| z.abs() > 1.9));
        assert!(p.i.is_none());
    }

    #[test]
    fn a_bristle_turns_over_at_a_reversal_within_its_bound() {
        // dẋ/dt = −ẋ/τ + g·u + c·w − d·(ẋ − |ẋ|·w), dw/dt = (ẋ − |ẋ|·w)/z_ss: Coulomb
        // friction carried by the bristle w, whose damping d (a time constant of 5 µs while
        // it turns over) holds the rotor at the reversal. In sliding w = sgn ẋ and
        // ẋ = τ·(g·u + c·w).
        let (tau, g, c, d, zss) = (0.013, 1000.0, -250.0, 1e5, 1e-3);
        let mut m = SindyModel::empty(100.0, 1.0, 1.0);
        m.z_max = 1.0;
        m.accel = SparseEq::from_slice(&[
            (Term::Xdot, -1.0 / tau - d),
            (Term::U, g),
            (Term::Z, c),
            (Term::AbsXdotZ, d),
        ])
        .unwrap();
        m.zdot =
            SparseEq::from_slice(&[(Term::Xdot, 1.0 / zss), (Term::AbsXdotZ, -1.0 / zss)]).unwrap();
        let log = log_with_input(100, 0.012, |k| if k < 50 { 1.0 } else { -1.0 });
        let p = simulate(&m, Plant::Torque, &log, Limits::default()).unwrap();
        let z = p.z.as_ref().unwrap();
        assert!(z.iter().all(|z| z.abs() <= 1.0));
        let slide = tau * (g + c);
        // At the end of each half the bristle is turned over and the rotor slides at the
        // exact sliding speed: after 0.6 s (45 time constants) only rounding (1e-9) and the
        // step's solve tolerance (1e-6 of the speed) remain.
        for (k, sign) in [(49, 1.0), (99, -1.0)] {
            assert!((z[k] - sign).abs() < 1e-9, "w[{k}] = {}", z[k]);
            let w = p.omega[k];
            assert!((w - sign * slide).abs() < 1e-6 * slide, "ẋ[{k}] = {w}");
        }
        // The split steps agree with 32 sub-steps a sample (the convergence of the step,
        // to a hundredth of the sliding speed).
        let fine = simulate_substeps(&m, Plant::Torque, &log, Limits::default(), 32).unwrap();
        for (a, b) in p.omega.iter().zip(&fine.omega) {
            assert!((a - b).abs() < 1e-2 * slide, "{a} vs {b}");
        }
    }

    #[test]
    fn segments_bound_the_samples_and_cover_both_ends() {
        let long = log_with_input(50_000, 0.012, |k| k as f64);
        let short = log_with_input(300, 0.012, |k| -(k as f64));
        // Within the budget: the logs themselves.
        let whole = bounded_segments(std::slice::from_ref(&short), 1000);
        assert_eq!(whole.len(), 1);
        assert_eq!(whole[0].u, short.u);
        let logs = [short.clone(), long.clone()];
        let segs = bounded_segments(&logs, 4000);
        let n: usize = segs.iter().map(MotorLog::len).sum();
        assert!(n <= 4000, "{n}");
        // The short log comes whole; the last segment ends at the last sample.
        assert_eq!(segs[0].u, short.u);
        let last = segs.last().unwrap();
        assert_eq!(last.u.last(), long.u.last());
        assert_eq!(last.len(), 1000);
        // Each segment is a contiguous piece of its log, time included.
        for s in &segs[1..] {
            let k = s.u[0] as usize;
            assert_eq!(s.t[0], long.t[k]);
            assert!(s.u.windows(2).all(|w| w[1] == w[0] + 1.0));
        }
    }
}
