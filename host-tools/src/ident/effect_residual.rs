//! Weak-form estimate of added effects on the residual of a fitted model (`fit --add`).
//!
//! Once the base model (motor constants and friction law) is known, the linear parameters of
//! the added effects are regressed on what that model leaves unexplained in the equation each
//! effect acts in, window by window (see [`crate::numerics::weak_form`]):
//!
//! - electrical (voltage plant): the sample-level winding equation of
//!   [`crate::ident::linear`] at the fitted L/R, R and K_b re-estimated jointly with
//!   `v_d·∫ψ·sgn(Ĩ − i0)` (deadtime) and `−R·i0·∫ψ` (current offset: `i_meas = i + i0`);
//! - mechanical: `K_t·∫φ·(I − i0) − J·∫φ''·θ − ∫φ·F(ω)`, with F the model's steady friction
//!   (LuGre Stribeck curve + α2·ω, or viscous b·ω), on `∫φ·sin(kθ)`, `∫φ·cos(kθ)` (cogging,
//!   position_load) and `∫φ` (offset).
//!
//! Only the added effects' magnitudes change; the base model's parameters are kept.
use crate::effects::{self, TorqueSignals, WeakTorque};
use crate::ident::free_params::Slot;
use crate::ident::linear;
use crate::log::{MotorLog, Plant};
use crate::model::Model;
use crate::numerics::differentiation::smooth_velocity;
use crate::numerics::least_squares::lstsq;
use crate::numerics::weak_form;
use control::effects::{smooth_sign, Effect};

/// `base` with the effects of `with` (structure) re-estimated on `base`'s residuals in `logs`.
/// Effects this regression does not cover keep the values they have in `with`.
pub fn estimate(base: &Model, with: &Model, logs: &[MotorLog]) -> Model {
    let mut m = base.clone();
    m.effects = with.effects.clone();
    if m.plant == Plant::Voltage {
        // Two passes: the sign of the current depends on the offset estimate.
        for _ in 0..2 {
            electrical(&mut m, logs);
        }
    }
    mechanical(&mut m, logs);
    m
}

fn electrical(m: &mut Model, logs: &[MotorLog]) {
    let extra = linear::electrical_effects(m);
    if extra.is_empty() {
        return;
    }
    let i0 = control::effects::total_sensor_offset(&m.effects);
    let (r, l, kb) = (m.motor.r, m.motor.l, m.motor.kb);
    // Columns: R, K_b, then the effects, at the fitted winding's time constant L/R. The base
    // fit's R and K_b have absorbed part of the effects, so they are estimated jointly with
    // them; the time constant is kept (the free run resolves it, the windows barely do), and
    // L with it.
    let tau = l / r;
    let Some(x) = linear::electrical_rows(logs, &extra, i0, tau).solve() else {
        return;
    };
    tracing::debug!("electrical residual regression: {x:?} (was R {r}, L {l}, Kb {kb})");
    if x.iter().any(|v| !v.is_finite()) || x[0] <= 0.0 || x[1] <= 0.0 {
        return;
    }
    let r = x[0];
    m.motor.r = r;
    m.motor.l = tau * r;
    // K_t = K_b (SI units): the mechanical equation scales as a whole with K_t, so every
    // mechanical torque parameter scales with it and the motion stays the same.
    let c = x[1] / kb;
    m.motor.kb = x[1];
    m.motor.kt *= c;
    m.motor.j *= c;
    m.viscous *= c;
    if let Some(lg) = m.lugre.as_mut() {
        lg.alpha0 *= c;
        lg.alpha1 *= c;
        lg.alpha2 *= c;
        lg.sigma0 *= c;
        lg.sigma1 *= c;
    }
    for (c, &(k, v)) in extra.iter().enumerate() {
        let value = (v.value)(x[2 + c], r).max(v.residual_floor);
        Slot::Effect(k, v.key).set(m, value);
    }
}

/// The signals of one log the torque regressors are made of: smoothed velocity, its smooth
/// sign, the current less the sensor offset (the command on a torque plant).
struct Signals {
    ws: Vec<f64>,
    sgn: Vec<f64>,
    cur: Vec<f64>,
}

/// The columns of effect `e` in the mechanical residual regression: a sine and a cosine
/// of h·θ for an angle-periodic torque, else one per key of its weak-form torque.
fn columns(e: &Effect<f64>, kt: f64, log: &MotorLog, s: &Signals) -> Vec<Vec<f64>> {
    let d = effects::of(e.kind());
    match (d.weak_torque, (d.harmonic)(e)) {
        (WeakTorque::Periodic, Some(h)) => vec![
            log.theta.iter().map(|t| (h * t).sin()).collect(),
            log.theta.iter().map(|t| (h * t).cos()).collect(),
        ],
        (WeakTorque::PerKey(keys), _) => {
            let s = TorqueSignals {
                effect: e,
                kt,
                theta: &log.theta,
                ws: &s.ws,
                sgn: &s.sgn,
                cur: &s.cur,
            };
            keys.iter().map(|(_, g)| g(&s)).collect()
        }
        _ => vec![],
    }
}

/// The keys [`columns`] estimates, in its order.
fn column_keys(e: &Effect<f64>) -> Vec<&'static str> {
    match effects::of(e.kind()).weak_torque {
        WeakTorque::Periodic => vec!["amp", "phase"],
        WeakTorque::PerKey(keys) => keys.iter().map(|(k, _)| *k).collect(),
        _ => vec![],
    }
}

fn mechanical(m: &mut Model, logs: &[MotorLog]) {
    let idx: Vec<usize> = (0..m.effects.len())
        .filter(|&k| effects::of(m.effects[k].kind()).on_residual)
        .collect();
    if idx.is_empty() {
        return;
    }
    let voltage = m.plant == Plant::Voltage;
    let i0 = control::effects::total_sensor_offset(&m.effects);
    let ncols: usize = idx.iter().map(|&k| column_keys(&m.effects[k]).len()).sum();
    let mut cols: Vec<Vec<f64>> = vec![Vec::new(); ncols];
    let mut y = Vec::new();
    for log in logs {
        let cur: Vec<f64> = match (voltage, &log.i) {
            (true, Some(i)) => i.iter().map(|c| c - i0).collect(),
            (true, None) => continue,
            (false, _) => log.u.clone(),
        };
        let ws = smooth_velocity(log);
        let sgn = ws.iter().map(|&w| smooth_sign(w, m.sign_width)).collect();
        let fric: Vec<f64> = ws
            .iter()
            .map(|&w| match &m.lugre {
                Some(l) => l.steady_friction(w),
                None => m.viscous * w,
            })
            .collect();
        let sig = Signals { ws, sgn, cur };
        let cur = &sig.cur;
        let g: Vec<Vec<f64>> = idx
            .iter()
            .flat_map(|&k| columns(&m.effects[k], m.motor.kt, log, &sig))
            .collect();
        for w in weak_form::log_windows(log) {
            let drive = if voltage {
                m.motor.kt * w.int(cur)
            } else {
                w.int_zoh(cur)
            };
            y.push(drive - m.motor.j * w.int_dd(&log.theta) - w.int(&fric));
            for (c, gv) in g.iter().enumerate() {
                cols[c].push(w.int(gv));
            }
        }
    }
    if y.len() <= cols.len() {
        return;
    }
    let refs: Vec<&[f64]> = cols.iter().map(|c| c.as_slice()).collect();
    let x = lstsq(&refs, &y).beta;
    tracing::debug!("mechanical residual regression: {x:?}");
    if x.iter().any(|v| !v.is_finite()) {
        return;
    }
    let mut c = 0;
    for &k in &idx {
        let keys = column_keys(&m.effects[k]);
        if keys == ["amp", "phase"] {
            let (a, b) = (x[c], x[c + 1]);
            Slot::Effect(k, "amp").set(m, a.hypot(b));
            Slot::Effect(k, "phase").set(m, b.atan2(a));
        } else {
            for (j, key) in keys.into_iter().enumerate() {
                Slot::Effect(k, key).set(m, x[c + j]);
            }
        }
        c += column_keys(&m.effects[k]).len();
    }
}
