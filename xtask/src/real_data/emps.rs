//! The EMPS benchmark (Janot, Gautier, Brunot 2019): a ball-screw prismatic axis driven by a
//! DC motor under a position loop, 1 kHz. Input `vir` [V] (force = gτ·vir [N]), output `qm` [m].
//!
//! What is here:
//! - reading the benchmark CSV through the generic motor-log reader (`--map`, `--plant torque`);
//! - the authors' IDIM-LS identification of the rigid model
//!   `gτ·vir = M·q̈ + Fv·q̇ + Fc·sign(q̇) + OF` (and its direction-asymmetric variant);
//! - the benchmark's open-loop free-run test (`vir` → `qm`, 20 samples to initialise the
//!   state, RMSE in mm) and the authors' closed-loop reference simulation (`qg` → `qm` with
//!   the P/PI loop of the description).
//!
//! Constants come from the benchmark's `.mat` files and EMPS_Description.pdf, as quoted in
//! `../shared/data/README.md`.
use super::butterworth::LowPass;
use super::static_curve::sgn;
use anyhow::{bail, Result};
use motorid::log::{ColumnMap, MotorLog, Plant};
use motorid::numerics::differentiation::smoothed_derivative;
use motorid::numerics::least_squares::{ols, Ols};
use std::path::Path;

/// Force per volt of `vir`, gτ [N/V] (scalar `gtau` in both .mat files).
pub const GTAU: f64 = 35.15065188248547;
/// Position-loop gain kp [1/s] (EMPS_Description.pdf).
pub const KP: f64 = 160.18;
/// Velocity-loop gain kv [V/(m/s)] (EMPS_Description.pdf).
pub const KV: f64 = 243.45;
/// Saturation of `vir` in the reference simulation [V] (`viradm = 10`).
pub const VIR_MAX: f64 = 10.0;
/// Samples used to initialise the state in the benchmark's free-run test
/// (`state_initialization_window_length` of the nonlinear_benchmarks loader).
pub const INIT_WINDOW: usize = 20;
/// The `--map` that reads the benchmark CSV as a motor log.
pub const MAP: &str = "t=t_s,u=vir_V,theta=qm_m";
/// The authors' IDIM-LS estimates (EMPS_Description.pdf): M [kg], Fv [N·s/m], Fc [N], OF [N].
pub const REFERENCE: [(&str, f64, f64); 4] = [
    ("M", 95.1089, 0.1085),
    ("Fv", 203.5034, 1.1460),
    ("Fc", 20.3935, 0.1012),
    ("OF", -3.1648, 0.0444),
];
/// The authors' asymmetric-friction estimates (doc §4.2): M, Fv+, Fc+, Fv−, Fc−.
pub const REFERENCE_ASYM: [(&str, f64); 5] = [
    ("M", 95.1540),
    ("Fv+", 166.7061),
    ("Fc+", 20.1440),
    ("Fv-", 240.4236),
    ("Fc-", 20.6277),
];
/// Open-loop test RMSE on DATA_EMPS_PULSES [mm] of other model classes, as tabulated by
/// Champneys et al. 2024 (quoted in ../shared/data/README.md, unchecked transcription).
pub const PUBLISHED_TEST_RMSE_MM: [(&str, f64); 6] = [
    ("LTI state space", 5.53),
    ("ARX", 12.6),
    ("pNARX", 5.17),
    ("LSTM", 74.1),
    ("GP-NARX", 1690.0),
    ("dynoNet (best reported)", 0.452),
];

/// Read an EMPS CSV (`DATA_EMPS.csv` or `DATA_EMPS_PULSES.csv`) with the generic reader.
pub fn read(path: &Path) -> Result<MotorLog> {
    MotorLog::read(path, &ColumnMap::parse(MAP)?, Plant::Torque)
}

/// The rigid axis: mass and friction. Friction force opposing motion:
/// symmetric `Fv·v + Fc·sign(v) + OF`, or, when `asym` is set,
/// `Fv+·v + Fc+` for v > 0 and `Fv−·v − Fc−` for v < 0 (plus `OF`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigidAxis {
    /// Moving mass seen on the load side [kg].
    pub m: f64,
    /// Viscous coefficient [N·s/m] (positive direction when asymmetric).
    pub fv: f64,
    /// Coulomb force [N] (positive direction when asymmetric).
    pub fc: f64,
    /// Constant offset force [N].
    pub offset: f64,
    /// Negative-direction (Fv−, Fc−) when the friction is asymmetric.
    pub asym: Option<(f64, f64)>,
}

impl RigidAxis {
    fn negative(&self) -> (f64, f64) {
        self.asym.unwrap_or((self.fv, self.fc))
    }

    /// One step of length `dt` with the force `f` held: backward Euler in the velocity with the
    /// set-valued Coulomb law (sticks exactly at zero when the force cannot break away), so the
    /// step is stable for any `dt`. Returns the new velocity.
    pub fn velocity_step(&self, v: f64, f: f64, dt: f64) -> f64 {
        let (fvm, fcm) = self.negative();
        let mom = self.m * v + dt * (f - self.offset);
        let vp = (mom - dt * self.fc) / (self.m + dt * self.fv);
        if vp > 0.0 {
            return vp;
        }
        let vn = (mom + dt * fcm) / (self.m + dt * fvm);
        if vn < 0.0 {
            return vn;
        }
        0.0
    }
}

/// The identified rigid model with its least-squares statistics.
#[derive(Debug, Clone)]
pub struct Idim {
    /// Parameter names in column order.
    pub names: Vec<&'static str>,
    /// The fit.
    pub ols: Ols,
    /// The same numbers as an axis model.
    pub axis: RigidAxis,
}

/// Position, velocity and acceleration as the IDIM-LS scripts prepare them: 4th-order
/// Butterworth at 100 Hz (filtfilt), then central differences.
pub fn filtered_states(q: &[f64], dt: f64) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let qf = LowPass::new(4, 100.0, 1.0 / dt).filtfilt(q);
    let d = |x: &[f64]| smoothed_derivative(x, dt, 1);
    let dq = d(&qf);
    let ddq = d(&dq);
    (qf, dq, ddq)
}

/// Decimation factor of the IDIM-LS scripts: round(0.8·(fs/2)/40) = 10 at 1 kHz.
fn decimation(fs: f64) -> usize {
    ((0.8 * fs / 2.0 / 40.0).round() as usize).max(1)
}

/// The IDIM-LS observation matrix and force: columns (q̈, q̇, sign q̇, 1), or the asymmetric
/// columns (q̈, q̇⁺, 1(q̇>0), q̇⁻, −1(q̇<0)). Parallel decimation: every column and the force
/// low-passed at 0.8·Nyquist/r (4th-order Butterworth, zero phase; the scripts use MATLAB's
/// `decimate`), then every r-th sample; the first 49 decimated samples and the last 5 are
/// dropped (filter and difference edges).
pub fn observation(log: &MotorLog, gain: f64, asym: bool) -> (Vec<Vec<f64>>, Vec<f64>) {
    let dt = log.sample_period();
    let (_, dq, ddq) = filtered_states(&log.theta, dt);
    let force: Vec<f64> = log.u.iter().map(|u| gain * u).collect();
    let mut cols: Vec<Vec<f64>> = vec![ddq.clone()];
    if asym {
        cols.push(dq.iter().map(|&v| v.max(0.0)).collect());
        cols.push(
            dq.iter()
                .map(|&v| if v > 0.0 { 1.0 } else { 0.0 })
                .collect(),
        );
        cols.push(dq.iter().map(|&v| v.min(0.0)).collect());
        cols.push(
            dq.iter()
                .map(|&v| if v < 0.0 { -1.0 } else { 0.0 })
                .collect(),
        );
    } else {
        cols.push(dq.clone());
        cols.push(dq.iter().copied().map(sgn).collect());
        cols.push(vec![1.0; dq.len()]);
    }
    let fs = 1.0 / dt;
    let r = decimation(fs);
    let lp = LowPass::new(4, 0.8 * fs / 2.0 / r as f64, fs);
    let pick = |x: &[f64]| -> Vec<f64> {
        let f = lp.filtfilt(x);
        let n = f.len();
        (0..n)
            .step_by(r)
            .skip(49)
            .take_while(|&k| k + 5 * r < n)
            .map(|k| f[k])
            .collect()
    };
    (cols.iter().map(|c| pick(c)).collect(), pick(&force))
}

/// IDIM-LS on one EMPS log. `gain` converts `u` to force (gτ for `vir`, 1 for a force column).
pub fn idim_ls(log: &MotorLog, gain: f64, asym: bool) -> Result<Idim> {
    if log.len() < 2000 {
        bail!(
            "{}: only {} samples; IDIM-LS needs a few seconds of data",
            log.source.display(),
            log.len()
        );
    }
    let (cols, y) = observation(log, gain, asym);
    let fit = ols(&cols, &y)?;
    let th = &fit.theta;
    let (names, axis) = if asym {
        (
            vec!["M", "Fv+", "Fc+", "Fv-", "Fc-"],
            RigidAxis {
                m: th[0],
                fv: th[1],
                fc: th[2],
                offset: 0.0,
                asym: Some((th[3], th[4])),
            },
        )
    } else {
        (
            vec!["M", "Fv", "Fc", "OF"],
            RigidAxis {
                m: th[0],
                fv: th[1],
                fc: th[2],
                offset: th[3],
                asym: None,
            },
        )
    };
    Ok(Idim {
        names,
        ols: fit,
        axis,
    })
}

/// Inverse-model (cross-)validation: relative error `100·‖τ − Wθ‖/‖τ‖` [%] of an axis model on
/// another log, with the same observation matrix as [`idim_ls`].
pub fn idim_relative_error(axis: &RigidAxis, log: &MotorLog, gain: f64) -> f64 {
    let asym = axis.asym.is_some();
    let (cols, y) = observation(log, gain, asym);
    let theta: Vec<f64> = match axis.asym {
        Some((fvm, fcm)) => vec![axis.m, axis.fv, axis.fc, fvm, fcm],
        None => vec![axis.m, axis.fv, axis.fc, axis.offset],
    };
    let (mut e2, mut y2) = (0.0, 0.0);
    for (k, yk) in y.iter().enumerate() {
        let p: f64 = cols.iter().zip(&theta).map(|(c, t)| c[k] * t).sum();
        e2 += (yk - p).powi(2);
        y2 += yk * yk;
    }
    100.0 * (e2 / y2).sqrt()
}

/// The force an axis model leaves unexplained, by position along the stroke: the inverse
/// model's residual `gain·u − (M·q̈ + friction)` on the filtered states of [`filtered_states`]
/// (samples at rest left out), averaged in `bins` equal bins of position from `lo` to `hi`
/// [m], in each direction of motion, then the two directions averaged. The part of the
/// residual that depends on the position and not on the direction [N]; NaN for a bin the
/// axis does not cross both ways.
pub fn residual_by_position(
    axis: &RigidAxis,
    gain: f64,
    log: &MotorLog,
    bins: usize,
    (lo, hi): (f64, f64),
) -> Vec<f64> {
    if bins == 0 || hi.partial_cmp(&lo) != Some(std::cmp::Ordering::Greater) {
        return vec![f64::NAN; bins];
    }
    let (qf, dq, ddq) = filtered_states(&log.theta, log.sample_period());
    let (fvm, fcm) = axis.negative();
    let mut sums = vec![[0.0f64; 4]; bins];
    // At rest: below a thousandth of the stroke per second.
    let v_rest = 1e-3 * (hi - lo);
    // The first and last 50 samples carry the filter's edges.
    for k in 50..log.len().saturating_sub(50) {
        let v = dq[k];
        if v.abs() < v_rest {
            continue;
        }
        let friction = if v > 0.0 {
            axis.fv * v + axis.fc
        } else {
            fvm * v - fcm
        };
        let e = gain * log.u[k] - (axis.m * ddq[k] + friction + axis.offset);
        let b = (((qf[k] - lo) / (hi - lo) * bins as f64).floor().max(0.0) as usize).min(bins - 1);
        let d = if v > 0.0 { 0 } else { 2 };
        sums[b][d] += e;
        sums[b][d + 1] += 1.0;
    }
    sums.iter()
        .map(|s| 0.5 * (s[0] / s[1] + s[2] / s[3]))
        .collect()
}

/// Open-loop free run: position driven by the force `gain·u`, starting from (q0, v0) at the
/// first sample. Sample k+1 is the state after holding `u[k]` for `dt`.
pub fn simulate_open_loop(
    axis: &RigidAxis,
    gain: f64,
    u: &[f64],
    dt: f64,
    q0: f64,
    v0: f64,
) -> Vec<f64> {
    let mut q = Vec::with_capacity(u.len());
    let (mut x, mut v) = (q0, v0);
    for &uk in u {
        q.push(x);
        v = axis.velocity_step(v, gain * uk, dt);
        x += dt * v;
    }
    q
}

/// The state at the end of the initialisation window: a straight line fitted to the first
/// `n` measured positions gives the position at sample n−1 and the velocity.
pub fn initial_state(q: &[f64], dt: f64, n: usize) -> (f64, f64) {
    let n = n.min(q.len()).max(2);
    let tm = (n - 1) as f64 / 2.0;
    let qm = q[..n].iter().sum::<f64>() / n as f64;
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for (k, qk) in q[..n].iter().enumerate() {
        sxy += (k as f64 - tm) * (qk - qm);
        sxx += (k as f64 - tm).powi(2);
    }
    let slope = sxy / sxx;
    (qm + slope * ((n - 1) as f64 - tm), slope / dt)
}

/// The benchmark's test: simulate `vir` → `qm` in open loop after a 20-sample initialisation
/// window, return (RMSE in mm over samples 20.., the simulated position for every sample; the
/// first 20 are the measurement).
pub fn benchmark_rmse_mm(axis: &RigidAxis, gain: f64, log: &MotorLog) -> (f64, Vec<f64>) {
    let n0 = INIT_WINDOW;
    let dt = log.sample_period();
    let (q0, v0) = initial_state(&log.theta, dt, n0);
    let mut sim = log.theta[..n0 - 1].to_vec();
    sim.extend(simulate_open_loop(axis, gain, &log.u[n0 - 1..], dt, q0, v0));
    sim.truncate(log.len());
    let rmse = rms_diff(&log.theta[n0..], &sim[n0..]);
    (1000.0 * rmse, sim)
}

/// The authors' closed-loop reference simulation: the axis under the loop
/// `vir = kp·kv·(qg − q) − kv·q̇`, saturated at ±10 V, with q̇ the difference of the
/// half-sum-filtered position (EMPS_Description.pdf). Returns (simulated q, simulated vir).
pub fn simulate_closed_loop(
    axis: &RigidAxis,
    qg: &[f64],
    dt: f64,
    q0: f64,
) -> (Vec<f64>, Vec<f64>) {
    let (mut x, mut v) = (q0, 0.0);
    let (mut x_prev, mut qf_prev) = (q0, q0);
    let mut qs = Vec::with_capacity(qg.len());
    let mut us = Vec::with_capacity(qg.len());
    for &r in qg {
        let qf = 0.5 * x + 0.5 * x_prev;
        let dq = (qf - qf_prev) / dt;
        let u = (KP * KV * (r - x) - KV * dq).clamp(-VIR_MAX, VIR_MAX);
        qs.push(x);
        us.push(u);
        qf_prev = qf;
        x_prev = x;
        v = axis.velocity_step(v, GTAU * u, dt);
        x += dt * v;
    }
    (qs, us)
}

pub use motorid::numerics::statistics::rms_diff;

/// Relative error `100·‖a − b‖/‖a‖` [%] (the description's eq. 11).
pub fn relative_error_pct(a: &[f64], b: &[f64]) -> f64 {
    let e: f64 = a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum();
    let n: f64 = a.iter().map(|x| x * x).sum();
    100.0 * (e / n).sqrt()
}

/// One nested-model test on the IDIM-LS regression.
#[derive(Debug, Clone)]
pub struct TermTest {
    /// Effect name (as `motorid` names it).
    pub name: &'static str,
    /// What the smaller model is.
    pub against: &'static str,
    /// The test, with the effective sample size of the larger model's residual (the statistics
    /// `diagnose` uses: [`motorid::numerics::statistics`]).
    pub test: motorid::numerics::statistics::FTest,
}

/// (name, smaller model, its columns, the larger model's columns).
type Nested = (&'static str, &'static str, Vec<Vec<f64>>, Vec<Vec<f64>>);

/// Is each friction term of the IDIM-LS model needed? Nested F-tests on the decimated
/// observation matrix: Coulomb against (M, Fv); offset against (M, Fv, Fc); asymmetry
/// (one Fv/Fc per direction) against the symmetric model with offset.
pub fn term_tests(log: &MotorLog, gain: f64) -> Result<Vec<TermTest>> {
    use motorid::numerics::statistics::{effective_n, f_test};
    let (sym, y) = observation(log, gain, false);
    let (asym, _) = observation(log, gain, true);
    let resid = |cols: &[Vec<f64>]| -> Result<(f64, Vec<f64>)> {
        let f = ols(cols, &y)?;
        let r: Vec<f64> = (0..y.len())
            .map(|k| {
                y[k] - cols
                    .iter()
                    .zip(&f.theta)
                    .map(|(c, t)| c[k] * t)
                    .sum::<f64>()
            })
            .collect();
        Ok((f.rss, r))
    };
    let steps: [Nested; 3] = [
        ("coulomb", "M, Fv", sym[..2].to_vec(), sym[..3].to_vec()),
        ("offset", "M, Fv, Fc", sym[..3].to_vec(), sym.clone()),
        ("asymmetry", "M, Fv, Fc, OF", sym.clone(), asym.clone()),
    ];
    let mut out = Vec::new();
    for (name, against, small, big) in steps {
        let (rss0, _) = resid(&small)?;
        let (rss1, r1) = resid(&big)?;
        let q = big.len() - small.len();
        out.push(TermTest {
            name,
            against,
            test: f_test(rss0, rss1, q, small.len(), effective_n(&r1)),
        });
    }
    Ok(out)
}
