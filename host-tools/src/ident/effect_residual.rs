//! Weak-form estimate of added effects on the residual of a fitted model (`fit --add`).
//!
//! Once the base model (motor constants and friction law) is known, the linear parameters of
//! the added effects are regressed on what that model leaves unexplained in the equation each
//! effect acts in, window by window (see [`crate::numerics::weak_form`]):
//!
//! - electrical (voltage plant): `∫φ·u − R·∫φ·I − L·(−∫φ'·I) − K_b·(−∫φ'·θ)` on
//!   `v_d·∫φ·sgn(I − i0)` (deadtime) and `−R·i0·∫φ` (current offset: `i_meas = i + i0`);
//! - mechanical: `K_t·∫φ·(I − i0) − J·∫φ''·θ − ∫φ·F(ω)`, with F the model's steady friction
//!   (LuGre Stribeck curve + α2·ω, or viscous b·ω), on `∫φ·sin(kθ)`, `∫φ·cos(kθ)` (cogging,
//!   position_load) and `∫φ` (offset).
//!
//! Only the added effects' magnitudes change; the base model's parameters are kept.
use crate::ident::linear;
use crate::log::{MotorLog, Plant};
use crate::model::Model;
use crate::numerics::differentiation::smooth_velocity;
use crate::numerics::least_squares::lstsq;
use crate::numerics::weak_form;
use control::effects::Effect;

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
    // Columns: L, R, K_b, then the effects. The base fit's R and K_b have absorbed part of
    // the effects, so they are estimated jointly with them.
    let Some(x) = linear::electrical_rows(logs, &extra, i0).solve() else {
        return;
    };
    tracing::debug!("electrical residual regression: {x:?} (was R {r}, L {l}, Kb {kb})");
    if x.iter().any(|v| !v.is_finite()) || x[1] <= 0.0 || x[2] <= 0.0 {
        return;
    }
    let r = x[1];
    m.motor.r = r;
    // L stays as fitted: windows of 0.48 s barely resolve the electrical time constant L/R
    // (about 1 ms), so their estimate of L is far noisier than the free-run fit's.
    // The L column stays in the regression so that it does not bias R, K_b and the effects.
    // K_t = K_b (SI units): the mechanical equation scales as a whole with K_t, so every
    // mechanical torque parameter scales with it and the motion stays the same.
    let c = x[2] / kb;
    m.motor.kb = x[2];
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
    for (c, &(k, _)) in extra.iter().enumerate() {
        let c = 3 + c;
        m.effects[k] = match m.effects[k] {
            Effect::Deadtime { .. } => Effect::Deadtime { vd: x[c].max(0.0) },
            // The column ∫φ carries −R·i0.
            _ if r > 0.0 => Effect::CurrentOffset { i0: -x[c] / r },
            e => e,
        };
    }
}

fn mechanical(m: &mut Model, logs: &[MotorLog]) {
    let idx: Vec<usize> = (0..m.effects.len())
        .filter(|&k| {
            matches!(
                m.effects[k],
                Effect::Cogging { .. } | Effect::PositionLoad { .. } | Effect::Offset { .. }
            )
        })
        .collect();
    if idx.is_empty() {
        return;
    }
    let voltage = m.plant == Plant::Voltage;
    let i0 = control::effects::total_sensor_offset(&m.effects);
    let mut ncols = 0;
    for &k in &idx {
        ncols += if matches!(m.effects[k], Effect::Offset { .. }) {
            1
        } else {
            2
        };
    }
    let mut cols: Vec<Vec<f64>> = vec![Vec::new(); ncols];
    let mut y = Vec::new();
    for log in logs {
        let cur: Vec<f64> = match (voltage, &log.i) {
            (true, Some(i)) => i.iter().map(|c| c - i0).collect(),
            (true, None) => continue,
            (false, _) => log.u.clone(),
        };
        let ws = smooth_velocity(log);
        let fric: Vec<f64> = ws
            .iter()
            .map(|&w| match &m.lugre {
                Some(l) => l.steady_friction(w),
                None => m.viscous * w,
            })
            .collect();
        let mut g: Vec<Vec<f64>> = Vec::new();
        for &k in &idx {
            match m.effects[k] {
                Effect::Cogging { harmonic, .. } => {
                    let h = harmonic as f64;
                    g.push(log.theta.iter().map(|t| (h * t).sin()).collect());
                    g.push(log.theta.iter().map(|t| (h * t).cos()).collect());
                }
                Effect::PositionLoad { .. } => {
                    g.push(log.theta.iter().map(|t| t.sin()).collect());
                    g.push(log.theta.iter().map(|t| t.cos()).collect());
                }
                _ => g.push(vec![1.0; log.len()]),
            }
        }
        for w in weak_form::log_windows(log) {
            let drive = if voltage {
                m.motor.kt * w.int(&cur)
            } else {
                w.int_zoh(&cur)
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
        m.effects[k] = match m.effects[k] {
            Effect::Cogging { harmonic, .. } => {
                let (a, b) = (x[c], x[c + 1]);
                c += 2;
                Effect::Cogging {
                    harmonic,
                    amp: a.hypot(b),
                    phase: b.atan2(a),
                }
            }
            Effect::PositionLoad { .. } => {
                let (a, b) = (x[c], x[c + 1]);
                c += 2;
                Effect::PositionLoad {
                    amp: a.hypot(b),
                    phase: b.atan2(a),
                }
            }
            _ => {
                c += 1;
                Effect::Offset { t0: x[c - 1] }
            }
        };
    }
}
