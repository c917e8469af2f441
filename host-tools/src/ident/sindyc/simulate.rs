//! Free run of a SINDYc model: states `(x, ẋ, z, I)`, `u` held between samples (zero-order
//! hold, as the board applies it). Steps are exponential Rosenbrock–Euler (exact for the
//! linear part, stable however stiff the current or `z` equation), [`SUBSTEPS`] sub-steps per
//! sample; `z` is clamped to `±z_max` after each step as the firmware's observer does. A
//! non-finite state or a velocity/current beyond [`Limits`] is a divergence: an error, never
//! a NaN.
use crate::ident::freerun::{self, Prediction};
use crate::ident::{fitpct, sensor_chain};
use crate::log::{MotorLog, Plant};
use anyhow::{anyhow, bail, Result};
use control::sindy::{SindyModel, TermInputs};

/// Sub-steps per sample of the free run: 2 keeps the frozen-Jacobian error of the
/// exponential Rosenbrock–Euler step small at the mechanical time constant (~13 ms for the
/// paper's motor, about one 12 ms sample).
pub const SUBSTEPS: usize = 2;

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
    let n = log.len();
    if n == 0 {
        bail!("{}: the log has no samples", log.source.display());
    }
    let voltage = plant == Plant::Voltage;
    let i0 = match (&log.i, voltage) {
        (Some(i), true) => i[0],
        _ => 0.0,
    };
    let mut s = [log.theta[0], freerun::initial_omega(log), 0.0, i0];
    let zb = model.z_bound();
    let rhs = |s: &[f64; 4], u: f64| -> [f64; 4] {
        let p = TermInputs {
            x: s[0],
            xdot: s[1],
            z: s[2],
            i: s[3],
            u,
        };
        let di = if voltage { model.idot_rhs(&p) } else { 0.0 };
        [s[1], model.accel_rhs(&p), model.zdot_rhs(&p), di]
    };
    let mut out = Prediction {
        t: log.t.clone(),
        theta: Vec::with_capacity(n),
        omega: Vec::with_capacity(n),
        i: voltage.then(|| Vec::with_capacity(n)),
        z: Some(Vec::with_capacity(n)),
    };
    let sub = SUBSTEPS;
    for k in 0..n {
        out.theta.push(s[0]);
        out.omega.push(s[1]);
        if let Some(i) = &mut out.i {
            i.push(s[3]);
        }
        if let Some(z) = &mut out.z {
            z.push(s[2]);
        }
        if k + 1 == n {
            break;
        }
        let u = log.u[k];
        let dt = (log.t[k + 1] - log.t[k]) / sub as f64;
        for _ in 0..sub {
            s = rosenbrock_step(&rhs, &s, u, dt).ok_or_else(|| {
                anyhow!(
                    "{}: time step {} s before sample {} is too long to simulate the SINDYc \
                     model (its matrix exponential is out of range)",
                    log.source.display(),
                    log.t[k + 1] - log.t[k],
                    k + 2
                )
            })?;
            s[2] = s[2].clamp(-zb, zb);
        }
        if !s.iter().all(|v| v.is_finite())
            || s[1].abs() > limits.omega
            || s[3].abs() > limits.current
        {
            bail!(
                "{}: the SINDYc model diverged in free run at t = {} s (sample {})",
                log.source.display(),
                log.t[k + 1],
                k + 2
            );
        }
    }
    Ok(out)
}

/// One exponential Rosenbrock–Euler step `s⁺ = s + h·φ1(h·A)·f(s)` (A: central-difference
/// Jacobian, forward differences), through [`super::freerun`]'s augmented-matrix exponential.
fn rosenbrock_step(
    rhs: &impl Fn(&[f64; 4], f64) -> [f64; 4],
    s: &[f64; 4],
    u: f64,
    dt: f64,
) -> Option<[f64; 4]> {
    let f0 = rhs(s, u);
    let mut m = [[0.0; 5]; 5];
    for j in 0..4 {
        // Forward differences: the Jacobian only shapes the step's stability and its
        // O(dt²) error, so 1e-7 relative accuracy is plenty.
        let d = 1e-7 * s[j].abs().max(1e-2);
        let mut sp = *s;
        sp[j] += d;
        let fp = rhs(&sp, u);
        for i in 0..4 {
            m[i][j] = (fp[i] - f0[i]) / d * dt;
        }
    }
    for i in 0..4 {
        m[i][4] = f0[i] * dt;
    }
    let e = freerun::expm(&m)?;
    let mut out = *s;
    for i in 0..4 {
        out[i] += e[i][4];
    }
    Some(out)
}

/// Mean validation fit on ẋ of a model's free run **through the sensor chain** (the
/// `fit_sensor` of `compare`: the model's angle Hall-quantised with the log's resolution and
/// differentiated by the firmware's moving average, against the measured velocity
/// `omegas[k]` of `logs[k]`); `None` when the model diverges on any log.
pub fn validation_fit(
    m: &SindyModel<f64>,
    plant: Plant,
    logs: &[MotorLog],
    omegas: &[Vec<f64>],
    window: usize,
    limits: Limits,
) -> Option<f64> {
    let mut total = 0.0;
    for (log, w) in logs.iter().zip(omegas) {
        let pred = simulate(m, plant, log, limits).ok()?;
        let res = sensor_chain::hall_resolution(log);
        let (_, wq) = sensor_chain::through_sensor(&pred.t, &pred.theta, res, window);
        total += fitpct::fit_percent(w, &wq).ok()?;
    }
    Some(total / logs.len().max(1) as f64)
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
        assert!(z.iter().all(|z| z.abs() <= 2.0 + 1e-12));
        assert!(z.iter().any(|z| z.abs() > 1.9));
        assert!(p.i.is_none());
    }
}
