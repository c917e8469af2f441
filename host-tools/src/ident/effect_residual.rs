//! Weak-form estimate of added effects on the residual of a fitted model (`fit --add`).
//!
//! Once the base model (motor constants and friction law) is known, the linear parameters of
//! the added effects are regressed on what that model leaves unexplained in the equation each
//! effect acts in, window by window (see [`crate::numerics::weak_form`]):
//!
//! - electrical (voltage plant): the sample-level winding equation of
//!   [`crate::ident::linear`] at the fitted L/R, R and K_b re-estimated jointly with
//!   `v_d·∫ψ·sgn(Ĩ − i0)` (deadtime) and `−R·i0·∫ψ` (current offset: `i_meas = i + i0`);
//! - mechanical: the drive's torque of the same sample-level winding (K_t times the current's
//!   exact mean over each interval, [`linear::drive_torques`]) less `J·∫φ''·θ + ∫φ·F(ω)`,
//!   with F the model's steady friction (LuGre Stribeck curve + α2·ω, or viscous b·ω), on the
//!   regressors the linear fit uses for the same effects: `∫φ·sin(kθ)`, `∫φ·cos(kθ)`
//!   (cogging, position_load) and `∫φ` (offset), each kept within its key's bounds.
//!
//! Only the added effects' magnitudes change; the base model's parameters are kept.
use crate::effects;
use crate::ident::free_params::Slot;
use crate::ident::linear::{self, EffCols, MechanicalSignals, WeakRows};
use crate::log::{MotorLog, Plant};
use crate::model::Model;
use crate::numerics::weak_form;

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

fn mechanical(m: &mut Model, logs: &[MotorLog]) {
    let map: Vec<EffCols> = linear::mechanical_effects(m)
        .into_iter()
        .filter(|c| effects::of(m.effects[c.effect()].kind()).on_residual)
        .collect();
    if map.is_empty() {
        return;
    }
    let mut rows = WeakRows::new(map.iter().map(EffCols::width).sum());
    for log in logs {
        let Some(s) = MechanicalSignals::of(m, log) else {
            continue;
        };
        let fric: Vec<f64> =
            s.ws.iter()
                .map(|&w| match &m.lugre {
                    Some(l) => l.steady_friction(w),
                    None => m.viscous * w,
                })
                .collect();
        let g = linear::effect_regressors(m, &map, log, &s);
        let windows = weak_form::log_windows(log);
        let drive = linear::drive_torques(m, log, &s, &windows);
        for (w, d) in windows.iter().zip(drive) {
            rows.y
                .push(d - m.motor.j * w.int_dd(&log.theta) - w.int(&fric));
            for (c, gv) in g.iter().enumerate() {
                rows.cols[c].push(w.int(gv));
            }
        }
    }
    let Some(x) = rows.solve() else {
        return;
    };
    tracing::debug!("mechanical residual regression: {x:?}");
    if x.iter().any(|v| !v.is_finite()) {
        return;
    }
    linear::set_mechanical_effects(m, &map, &x);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effect_spec::EffectSpec;
    use crate::emulator::{simulate_signal, EmulatorConfig, SignalKind};

    /// The emulator's own model with its load torque hidden: the residual regression reads
    /// the load back from what the model leaves, in the torque equation the linear fit uses.
    #[test]
    fn a_hidden_load_is_read_back_on_the_true_model() {
        for t0 in [0.03, -0.05] {
            let spec = EffectSpec::parse(&format!("offset:t0={t0}")).unwrap();
            let cfg = EmulatorConfig::paper().with_effects(vec![spec.to_effect()]);
            let log = simulate_signal(&cfg, SignalKind::A, 60.0).unwrap().log;
            let truth = cfg.truth_model();
            let mut base = truth.clone();
            base.effects.clear();
            let mut with = truth.clone();
            Slot::Effect(0, "t0").set(&mut with, 0.0);
            let m = estimate(&base, &with, std::slice::from_ref(&log));
            let read = Slot::Effect(0, "t0").get(&m);
            assert!(
                (read / t0 - 1.0).abs() < 0.05,
                "hidden load {t0} N·m read as {read}"
            );
        }
    }
}
