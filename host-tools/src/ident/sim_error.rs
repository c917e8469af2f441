//! Simulation-error refinement: move a model's free parameters to minimise the free-run
//! error against the logs (the paper's grey-box estimation), with [`super::nlsq`].
//!
//! Residuals per sample: velocity (the model's angle through the firmware's moving average,
//! without quantisation so the cost stays smooth in the parameters, against the measured
//! velocity), current, and the angle with a small weight; each normalised by the spread of
//! the measured signal so that the three are comparable.
use super::free_params::{parameter_rows, Free};
use super::{freerun, nlsq, sensor_chain};
use crate::log::MotorLog;
use crate::model::{Model, Parameter};
use anyhow::Result;

/// Weight of the angle residual relative to velocity and current: the free-run angle drifts
/// (it integrates every velocity error), so it only steers the low frequencies.
const ANGLE_WEIGHT: f64 = 0.3;

fn spread(v: &[f64]) -> f64 {
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
}

/// The residual vector of `model` on `logs`.
pub struct Residuals<'a> {
    targets: Vec<Target<'a>>,
    window: usize,
}

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
                    omega,
                    log,
                }
            })
            .collect();
        Residuals { targets, window }
    }

    /// Residuals of a model (errors if its simulation diverges).
    pub fn eval(&self, model: &Model) -> Result<Vec<f64>> {
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

/// Refine the free parameters of `model` on `logs`. Returns the parameter rows with
/// standard errors. `progress(iteration, cost)` reports progress.
pub fn refine(
    model: &mut Model,
    free: &[Free],
    logs: &[MotorLog],
    opts: nlsq::Options,
    progress: &mut dyn FnMut(usize, f64),
) -> Result<Vec<Parameter>> {
    let res = Residuals::new(logs, model.sensor.velocity_window);
    let x0: Vec<f64> = free.iter().map(|f| f.slot.get(model)).collect();
    let lo: Vec<f64> = free.iter().map(|f| f.lo).collect();
    let hi: Vec<f64> = free.iter().map(|f| f.hi).collect();
    let scale: Vec<f64> = free
        .iter()
        .zip(&x0)
        .map(|(f, x)| x.abs().max(1e-3 * (f.hi - f.lo).abs().min(1.0)).max(1e-9))
        .collect();
    let base = model.clone();
    let mut f = |x: &[f64]| -> Result<Vec<f64>> {
        let mut m = base.clone();
        for (fr, v) in free.iter().zip(x) {
            fr.slot.set(&mut m, *v);
        }
        res.eval(&m)
    };
    let sol = nlsq::solve(&mut f, &x0, &lo, &hi, &scale, opts, progress)?;
    for (fr, v) in free.iter().zip(&sol.x) {
        fr.slot.set(model, *v);
    }
    let se: Vec<Option<f64>> = sol.std_err.iter().map(|v| Some(*v)).collect();
    Ok(parameter_rows(model, free, &se))
}
