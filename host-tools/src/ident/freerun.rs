//! Free-run simulation of a model with a log's input.
//!
//! The model starts from the log's first samples (angle, velocity, current) and then runs on
//! the log's input alone, `u` held constant between samples (zero-order hold), as the board
//! applies it. The plant is stiff at the 12 ms sample period (L/R ≈ 1.4 ms, LuGre σ0 ≈ 300
//! N·m/rad; the paper's σ1 = 22 N·m·s/rad damps the rotor in presliding with J/σ1 ≈ 14 µs).
//! Each sample is split into [`SUBSTEPS`] sub-steps of backward Euler for (θ, ω, I) with the
//! bristle state updated *exactly* for the new velocity (`control::lugre::z_step`) — the
//! scheme of the emulator (`emulator::plant`), L-stable at any step and exact at equilibria
//! (stiction). The unknown of a sub-step is the new velocity: the residual
//! `J·(ω' − ω)/h − K_t·I'(ω') + F_f(ω') + loads(ω')` increases with ω', so the emulator's
//! bracketing scalar solver finds it. (An exponential Rosenbrock scheme was tried first: it
//! diverges at LuGre breakaway, where the bilinear |ω|·z term changes within a step.)
//!
//! SINDYc models are simulated by `ident::sindyc` (the equations live there).
use crate::emulator::scalar_root::find_root;
use crate::log::{MotorLog, Plant};
use crate::model::{Model, ModelKind};
use anyhow::{bail, Result};
use control::effects::{self, EffectInputs};
use control::lugre::z_step;

/// A free-run prediction, one value per log sample.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Prediction {
    pub t: Vec<f64>,
    /// Rotor angle [rad] (the model's true state, not quantised).
    pub theta: Vec<f64>,
    /// Velocity [rad/s] (true state).
    pub omega: Vec<f64>,
    /// Current as the sensor would measure it [A] (with any `current_offset`); None for
    /// `--plant torque`.
    pub i: Option<Vec<f64>>,
    /// Bristle deflection [rad] (LuGre models).
    pub z: Option<Vec<f64>>,
}

/// Number of backward-Euler sub-steps per sample: 1 ms at 12 ms. Against the emulator's
/// 0.2 ms steps the velocity fit of the true model stays within ~1 point (tests), at 1/5 of
/// the cost, which the parameter search needs.
pub const SUBSTEPS: usize = 12;

/// States: θ, ω, I, z.
const NX: usize = 4;

/// The continuous-time right-hand side of a (non-SINDYc) model.
pub struct Dynamics<'a> {
    pub model: &'a Model,
}

impl Dynamics<'_> {
    /// Friction and load torque [N·m] at state x (heat state h does not enter torques).
    pub fn load_torque(&self, x: &[f64; NX]) -> f64 {
        let m = self.model;
        let (theta, omega, cur, z) = (x[0], x[1], x[2], x[3]);
        let friction = match (&m.lugre, m.kind) {
            (Some(l), ModelKind::Lugre) => crate::model::lugre_friction(l, omega, z),
            _ => m.viscous * omega,
        };
        let inputs = EffectInputs {
            theta,
            omega,
            current: cur,
            kt: m.motor.kt,
        };
        friction + effects::total_torque_with_width(&m.effects, &inputs, m.sign_width)
    }

    /// dx/dt at state x with input u and heat state h.
    pub fn rhs(&self, x: &[f64; NX], u: f64, h: f64) -> [f64; NX] {
        let m = self.model;
        let p = &m.motor;
        let (omega, cur, z) = (x[1], x[2], x[3]);
        let torque = self.load_torque(x);
        let domega = (p.kt * cur - torque) / p.j;
        let dcur = match m.plant {
            Plant::Voltage => {
                let v = u - effects::total_voltage_loss(&m.effects, cur);
                (-p.r * (1.0 + h) * cur - p.kb * omega + v) / p.l
            }
            Plant::Torque => 0.0,
        };
        let dz = match (&m.lugre, m.kind) {
            (Some(l), ModelKind::Lugre) => crate::model::lugre_z_rate(l, omega, z),
            _ => 0.0,
        };
        [omega, domega, dcur, dz]
    }

    /// One backward-Euler sub-step of length `h` (z exact), from state x with input u and
    /// heat state h_th. Returns the new state.
    pub fn implicit_step(
        &self,
        x: &[f64; NX],
        u: f64,
        h_th: f64,
        h: f64,
        w_guess: f64,
    ) -> [f64; NX] {
        let m = self.model;
        let p = &m.motor;
        let lugre = match (&m.lugre, m.kind) {
            (Some(l), ModelKind::Lugre) => Some(l),
            _ => None,
        };
        let r = p.r * (1.0 + h_th);
        let vloss_max: f64 = m.effects.iter().map(|e| e.voltage_loss(1e9).abs()).sum();
        let current_for = |w: f64| -> f64 {
            match m.plant {
                Plant::Torque => u,
                Plant::Voltage => {
                    let a = p.l / h + r;
                    let rhs = p.l / h * x[2] + u - p.kb * w;
                    if vloss_max == 0.0 {
                        rhs / a
                    } else {
                        find_root(
                            |i| a * i + effects::total_voltage_loss(&m.effects, i) - rhs,
                            rhs / a,
                            vloss_max / a + 1e-12,
                            1e-12 * (1.0 + (rhs / a).abs()),
                        )
                    }
                }
            }
        };
        let eval = |w: f64| {
            let i = current_for(w);
            let (z, fric) = match lugre {
                Some(l) => {
                    let (z, zdot) = z_step(l, x[3], w, h);
                    (z, l.friction_at(w, z, zdot))
                }
                None => (x[3], m.viscous * w),
            };
            let theta = x[0] + h * w;
            let inputs = EffectInputs {
                theta,
                omega: w,
                current: i,
                kt: p.kt,
            };
            let load = effects::total_torque_with_width(&m.effects, &inputs, m.sign_width);
            let resid = p.j * (w - x[1]) / h - p.kt * i + fric + load;
            (resid, [theta, w, i, z])
        };
        let g0 = eval(w_guess).0;
        let step0 = g0.abs() * h / p.j + 1e-9;
        let w = find_root(|w| eval(w).0, w_guess, step0, 1e-11 * (1.0 + x[1].abs()));
        eval(w).1
    }
}

/// Matrix exponential of a small dense matrix: scaling and squaring with a degree-12 Taylor
/// polynomial after scaling the norm below 1/2 (truncation error < 1e-16 relative). Used by
/// the SINDYc simulator for its linear part. `None` when the matrix is not finite or its norm
/// is beyond [`EXPM_MAX_NORM`] (a time step far too long for the dynamics): the number of
/// squarings is bounded, never ~2³¹.
pub fn expm<const N: usize>(a: &[[f64; N]; N]) -> Option<[[f64; N]; N]> {
    let norm = a
        .iter()
        .map(|r| r.iter().map(|v| v.abs()).sum::<f64>())
        .fold(0.0, f64::max);
    if !(norm.is_finite() && norm <= EXPM_MAX_NORM) {
        return None;
    }
    let s = if norm > 0.5 {
        (norm / 0.5).log2().ceil() as i32
    } else {
        0
    };
    let scale = 0.5f64.powi(s);
    let mut b = *a;
    for r in b.iter_mut() {
        for v in r.iter_mut() {
            *v *= scale;
        }
    }
    // Horner: E = I + B(I + B/2(I + B/3(...))).
    let mut e = [[0.0; N]; N];
    for (i, r) in e.iter_mut().enumerate() {
        r[i] = 1.0;
    }
    for k in (1..=12).rev() {
        let mut t = matmul(&b, &e);
        for (i, r) in t.iter_mut().enumerate() {
            for v in r.iter_mut() {
                *v /= k as f64;
            }
            r[i] += 1.0;
        }
        e = t;
    }
    for _ in 0..s {
        e = matmul(&e, &e);
    }
    Some(e)
}

/// Largest norm of `h·A` [`expm`] accepts (at most 62 squarings); a physical model at a
/// physical sample period is many orders of magnitude below.
pub const EXPM_MAX_NORM: f64 = 1e18;

fn matmul<const N: usize>(a: &[[f64; N]; N], b: &[[f64; N]; N]) -> [[f64; N]; N] {
    let mut c = [[0.0; N]; N];
    for i in 0..N {
        for k in 0..N {
            let aik = a[i][k];
            for j in 0..N {
                c[i][j] += aik * b[k][j];
            }
        }
    }
    c
}

/// Initial velocity from the data: the `omega` column, else the slope of θ over the first
/// few samples (a Hall-quantised angle gives no better).
pub fn initial_omega(log: &MotorLog) -> f64 {
    if let Some(w) = &log.omega {
        return w[0];
    }
    let n = log.len().min(10);
    if n < 2 {
        return 0.0;
    }
    (log.theta[n - 1] - log.theta[0]) / (log.t[n - 1] - log.t[0])
}

/// Free-run simulation of `model` with the input of `log`, starting from the log's first
/// samples. Errors (never NaN) when the model diverges.
pub fn simulate(model: &Model, log: &MotorLog) -> Result<Prediction> {
    simulate_with(model, log, SUBSTEPS)
}

/// [`simulate`] with a chosen number of sub-steps per sample.
pub fn simulate_with(model: &Model, log: &MotorLog, substeps: usize) -> Result<Prediction> {
    if model.kind == ModelKind::Sindyc {
        return super::sindyc_simulate(model, log);
    }
    if log.is_empty() {
        bail!("{}: the log has no samples", log.source.display());
    }
    simulate_range(model, log, 0, log.len(), substeps)
}

/// Velocity at sample `k` from the data alone: the `omega` column, else the slope of θ over
/// ±5 samples (the first samples: over the next 10, as [`initial_omega`]).
fn omega_at(log: &MotorLog, k: usize) -> f64 {
    if let Some(w) = &log.omega {
        return w[k];
    }
    if k == 0 {
        return initial_omega(log);
    }
    let a = k.saturating_sub(5);
    let b = (k + 5).min(log.len() - 1);
    if b > a {
        (log.theta[b] - log.theta[a]) / (log.t[b] - log.t[a])
    } else {
        0.0
    }
}

/// The heat state of the model's thermal effects at sample `k`, from the measured current
/// (the winding heats with the current it carries, whatever the model predicts).
fn heat_at(model: &Model, log: &MotorLog, k: usize) -> f64 {
    let offset = effects::total_sensor_offset(&model.effects);
    let mut h = 0.0;
    if !model
        .effects
        .iter()
        .any(|e| matches!(e, effects::Effect::Thermal { .. }))
    {
        return h;
    }
    let Some(i) = &log.i else { return h };
    for (j, &c) in i.iter().enumerate().take(k) {
        for e in &model.effects {
            h = e.heat_step(h, c - offset, log.t[j + 1] - log.t[j]);
        }
    }
    h
}

/// Simulation of samples `start..end` of `log` from the measured state at `start` (angle,
/// velocity, current, the heat the measured current has put into the winding): one
/// segment of a multiple-shooting fit. `start = 0, end = len` is the free run.
pub fn simulate_range(
    model: &Model,
    log: &MotorLog,
    start: usize,
    end: usize,
    substeps: usize,
) -> Result<Prediction> {
    let end = end.min(log.len());
    if start >= end {
        bail!(
            "{}: empty sample range {start}..{end}",
            log.source.display()
        );
    }
    let n = end - start;
    let dyn_ = Dynamics { model };
    let offset = effects::total_sensor_offset(&model.effects);
    let omega0 = omega_at(log, start);
    let i0 = match (model.plant, &log.i) {
        (Plant::Voltage, Some(i)) => i[start] - offset,
        (Plant::Voltage, None) => 0.0,
        (Plant::Torque, _) => log.u[start],
    };
    let z0 = match (&model.lugre, model.kind) {
        // Sliding: the bristles sit on the Stribeck curve; at rest: no deflection known.
        (Some(l), ModelKind::Lugre) if l.sigma0 > 0.0 && omega0.abs() > 1e-9 => {
            l.s(omega0) * omega0.signum() / l.sigma0
        }
        _ => 0.0,
    };
    let mut x = [log.theta[start], omega0, i0, z0];
    let mut h = heat_at(model, log, start);
    let mut w_prev = omega0;
    let mut out = Prediction {
        t: log.t[start..end].to_vec(),
        theta: Vec::with_capacity(n),
        omega: Vec::with_capacity(n),
        i: (model.plant == Plant::Voltage).then(|| Vec::with_capacity(n)),
        z: (model.kind == ModelKind::Lugre).then(|| Vec::with_capacity(n)),
    };
    let sub = substeps.max(1);
    for k in 0..n {
        out.theta.push(x[0]);
        out.omega.push(x[1]);
        if let Some(i) = &mut out.i {
            i.push(x[2] + offset);
        }
        if let Some(z) = &mut out.z {
            z.push(x[3]);
        }
        if k + 1 == n {
            break;
        }
        let k = start + k;
        let u = log.u[k];
        if model.plant == Plant::Torque {
            x[2] = u;
        }
        let dt = (log.t[k + 1] - log.t[k]) / sub as f64;
        for _ in 0..sub {
            let guess = x[1] + (x[1] - w_prev);
            w_prev = x[1];
            x = dyn_.implicit_step(&x, u, h, dt, guess);
            for e in &model.effects {
                h = e.heat_step(h, x[2], dt);
            }
        }
        if !x.iter().all(|v| v.is_finite()) || x[1].abs() > 1e7 || x[2].abs() > 1e7 {
            bail!(
                "{}: the model diverged in free run at t = {} s (sample {}); its parameters \
                 are not physical",
                log.source.display(),
                log.t[k + 1],
                k + 2
            );
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::LugreParams;

    fn log_with(u: Vec<f64>, dt: f64) -> MotorLog {
        let n = u.len();
        MotorLog {
            t: (0..n).map(|k| k as f64 * dt).collect(),
            u,
            i: Some(vec![0.0; n]),
            theta: vec![0.0; n],
            ..Default::default()
        }
    }

    #[test]
    fn expm_matches_a_rotation() {
        let e = expm(&[[0.0, -3.0], [3.0, 0.0]]).unwrap();
        assert!((e[0][0] - 3f64.cos()).abs() < 1e-13);
        assert!((e[1][0] - 3f64.sin()).abs() < 1e-13);
    }

    #[test]
    fn linear_model_reaches_its_steady_state() {
        let mut m = Model::new(ModelKind::Linear, Plant::Voltage, 0.012);
        m.viscous = 0.001;
        let p = m.motor;
        let log = log_with(vec![6.0; 400], 0.012);
        let pr = simulate(&m, &log).unwrap();
        // ω_ss from K_t·I = b·ω, R·I + K_b·ω = V.
        let w_ss = 6.0 * p.kt / (p.r * m.viscous + p.kt * p.kb);
        assert!(
            (pr.omega[399] - w_ss).abs() < 1e-6 * w_ss,
            "{}",
            pr.omega[399]
        );
    }

    #[test]
    fn lugre_sticks_below_breakaway_and_substeps_agree() {
        let mut m = Model::new(ModelKind::Lugre, Plant::Voltage, 0.012);
        m.lugre = Some(LugreParams::paper());
        // Below breakaway: K_t·V/R < α0 + α1 → the rotor only deflects the bristles.
        let v_small = 0.5 * (0.08 * m.motor.r / m.motor.kt);
        let pr = simulate(&m, &log_with(vec![v_small; 300], 0.012)).unwrap();
        assert!(pr.theta[299].abs() < 1e-3, "{}", pr.theta[299]);
        // Signal a through the emulator (0.2 ms steps) and through this free run (1 ms): the
        // same physics, so the velocity agrees with the emulator's true velocity.
        let cfg = crate::emulator::EmulatorConfig::paper();
        let res =
            crate::emulator::simulate_signal(&cfg, crate::emulator::SignalKind::A, 30.0).unwrap();
        let mut m = Model::new(ModelKind::Lugre, Plant::Voltage, 0.012);
        m.lugre = Some(cfg.lugre);
        m.motor = cfg.motor;
        let mut log = res.log.clone();
        log.omega = Some(res.truth.omega.clone());
        log.i = Some(res.truth.i.clone());
        let pr = simulate(&m, &log).unwrap();
        let fit = crate::ident::fitpct::fit_percent(&res.truth.omega, &pr.omega).unwrap();
        assert!(fit > 97.0, "fit {fit}");
    }
}
