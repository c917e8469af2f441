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

/// `Σ r²` of a model, ∞ when it diverges.
pub fn cost(res: &Residuals, model: &Model) -> f64 {
    res.eval(model)
        .map(|r| r.iter().map(|v| v * v).sum())
        .unwrap_or(f64::INFINITY)
}

/// The effects of `model` with their magnitudes multiplied by `f` (keys other than the
/// magnitude, such as a phase or a time constant, kept); `f = 0` is the model without them.
pub fn scale_effect_magnitudes(model: &Model, f: f64) -> Model {
    use control::effects::Effect;
    let mut m = model.clone();
    for e in &mut m.effects {
        match e {
            Effect::Coulomb { fc } => *fc *= f,
            Effect::Viscous { b } => *b *= f,
            Effect::Stribeck { fs, .. } => *fs *= f,
            Effect::Cogging { amp, .. } | Effect::PositionLoad { amp, .. } => *amp *= f,
            Effect::Offset { t0 } => *t0 *= f,
            Effect::Asymmetry { dv, dc } => {
                *dv *= f;
                *dc *= f
            }
            Effect::Deadtime { vd } => *vd *= f,
            Effect::CurrentOffset { i0 } => *i0 *= f,
            Effect::Thermal { k, .. } => *k *= f,
            Effect::LoadFriction { mu } => *mu *= f,
            Effect::Presliding { .. } => {}
        }
    }
    m
}

/// Line search along the weak-form estimate of the effects: start from the magnitude factor
/// (0, ¼, ½, ¾, 1, 1¼) with the lowest simulation error. The weak form gets phases right but
/// its magnitudes can be off (Hall quantisation of θ inside sin(hθ)), and a free run with a
/// wrong position-dependent torque drifts; factor 0 ("without the effect") is a candidate,
/// so adding an effect never starts worse than not adding it.
pub fn better_effect_start(model: &mut Model, logs: &[MotorLog]) {
    if model.effects.is_empty() {
        return;
    }
    let res = Residuals::new(logs, model.sensor.velocity_window);
    let mut best = (f64::INFINITY, 1.0);
    for f in [0.0, 0.25, 0.5, 0.75, 1.0, 1.25] {
        let c = cost(&res, &scale_effect_magnitudes(model, f));
        if std::env::var_os("MOTORID_DEBUG_IDENT").is_some() {
            eprintln!("effects {:?} x {f}: cost {c:.4e}", model.effects);
        }
        if c < best.0 {
            best = (c, f);
        }
    }
    *model = scale_effect_magnitudes(model, best.1);
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

/// Refine in two stages when the model has effects: first the base model (effects at zero
/// magnitude) on `base_free`, then the effects from their weak-form estimate (line search
/// along it, [`better_effect_start`]) with everything free. A position-dependent torque
/// that is slightly wrong makes a free run stick or drift, so the base model must be right
/// before the effects are searched.
pub fn refine_with_effects(
    model: &mut Model,
    base_free: &[Free],
    logs: &[MotorLog],
    opts: nlsq::Options,
) -> Result<Vec<Parameter>> {
    if model.effects.is_empty() {
        return refine(model, base_free, logs, opts, &mut |_, _| {});
    }
    let weak = model.effects.clone();
    let mut base = scale_effect_magnitudes(model, 0.0);
    refine(&mut base, base_free, logs, opts, &mut |_, _| {})?;
    base.effects = weak;
    better_effect_start(&mut base, logs);
    let mut free = base_free.to_vec();
    free.extend(super::linear::effect_free(&base));
    let rows = refine(&mut base, &free, logs, opts, &mut |_, _| {})?;
    *model = base;
    Ok(rows)
}
