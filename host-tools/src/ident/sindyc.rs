//! SINDYc identification as in the reference paper (§4.3–4.4, eqs. 43–46): hidden state `z`
//! from the time-delay embedding of the velocity ([`super::hankel`]), the candidate library
//! ([`super::library`]), sparse regression ([`super::stlsq`]), then the paper's one-by-one
//! hard thresholding judged by the free-run validation fit, with divergent candidates
//! rejected. The identified equations are a [`control::sindy::SindyModel`], exactly what the
//! firmware evaluates.
//!
//! # Pipeline
//! 1. **Signals.** `x` = the log's angle; `ẋ` = centred slope of the angle over ±5 samples
//!    (the same 10-sample span as the firmware's moving average, but centred, so it is not
//!    54 ms late; a Hall-quantised angle allows no sharper estimate); `I`, `u` from the log.
//! 2. **Hidden state.** `z` = the Hankel embedding (60 delays, energy < 0.001: the paper's
//!    settings; the lower half of the spectrum when nothing is below 0.001) of `ẋ`, fitted
//!    on all fitting logs, scaled to unit RMS (the paper normalises `z` too; its scale is
//!    arbitrary and absorbed by the coefficients). Every STLSQ start is also tried without
//!    the z terms: on emulated LuGre data the extracted z is nearly uncorrelated with the
//!    bristle state (r ≈ 0.05, see the test `hankel_state_on_lugre_data`: the LuGre z is
//!    almost a static function of ẋ, so it lives in the high-energy part the paper's method
//!    discards) and the z-free model wins (`paper-table`, signal a: STLSQ with z 96.7–96.8 %,
//!    without z 97.4 %, refined without z 98.3 %). The paper's method stays the default and
//!    is reported as measured; the z terms only enter a model when they predict better.
//! 3. **Weak form.** No derivative of quantised data is taken: each equation is multiplied
//!    by the shared smooth test functions ([`super::weak_form`], 40-sample windows, hop 20)
//!    and integrated by parts: `∫φ·dẋ/dt = ∫φ''·x`, `∫φ·dz/dt = −∫φ'·z`,
//!    `∫φ·dI/dt = −∫φ'·I`; the library columns become `∫φ·θ_j`.
//!    Uniformly sampled logs take a fast path ([`weak_rows_uniform`]: each library value
//!    computed once, windows assembled from hop-long segments).
//! 4. **STLSQ** on the normal equations of those rows for several thresholds; the start is
//!    the candidate with the best validation fit that does not diverge. The validation fit
//!    is [`validation_fit`]: the free run's angle through the board's sensor chain (Hall
//!    quantisation, moving-average velocity), against the measured velocity, as `compare`'s
//!    `fit_sensor`.
//! 5. **One-by-one thresholding** (the paper's): try removing terms from the smallest
//!    contribution up, refitting that equation on its support and simulating the validation
//!    logs in free run; keep the first removal whose validation fit on `ẋ` stays within
//!    `tolerance` points of the best seen; stop when no removal qualifies. Every step is a
//!    row of the Pareto table (number of terms vs validation fit).
//! 6. **Refinement on the simulation error** (as the LuGre model's dynamic step): the
//!    nonzero coefficients and the tanh gain `a` of the thresholded model, and of the STLSQ
//!    start, are refined by bounded Levenberg–Marquardt ([`super::nlsq`]) on the free-run
//!    error of the fitting logs (velocity, current, angle); a refined model replaces the
//!    result only if its validation fit is higher. Effect on the emulated paper motor
//!    (`paper-table`, fitted on a, fit_sensor x/ẋ on b): 91.6/96.1 % before, 97.5/97.8 %
//!    after; the emulator's own model scores 99.98/99.53 %, LuGre 99.94/98.83 %.
//!
//! # Free run
//! States `(x, ẋ, z, I)`, `u` held between samples. Steps are exponential Rosenbrock–Euler
//! (the free-run scheme of [`super::freerun`]: exact for the linear part, stable however stiff the
//! current or `z` equation), [`SUBSTEPS`] sub-steps per sample; `z` is clamped to `±z_max` after each
//! step as the firmware's observer does. A non-finite state or a velocity/current beyond ten
//! times the data's range is a divergence: such a candidate is never returned.
use super::freerun::{self, Prediction};
use super::hankel::{HankelEmbedding, Selection, DEFAULT_DELAYS, DEFAULT_ENERGY};
use super::library::{Library, Signals, ACCEL, EQUATION_NAMES, IDOT, ZDOT};
use super::stlsq::{Normal, StlsqOptions};
use super::{fitpct, nlsq, sensor_chain, weak_form};
use crate::effect_spec::EffectSpec;
use crate::log::{MotorLog, Plant};
use anyhow::{anyhow, bail, Context, Result};
use control::sindy::{SindyModel, SparseEq, Term, TermInputs, MAX_TERMS};
use faer::Mat;
use std::fmt::Write as _;

/// Default tanh gain `a` [s/rad] of `tanh(a·ẋ)`: the paper only asks for "a close
/// approximation of the unit step"; 5 s/rad makes the step complete (tanh > 0.99) at
/// 0.5 rad/s, below the 0.79 rad/s velocity resolution of the paper's sensor. With `z`
/// normalised to unit RMS, `tanh(a·z)` is then a sign of `z` too.
pub const DEFAULT_A: f64 = 5.0;
/// Half-width [samples] of the centred velocity estimate (10-sample span as the paper's).
pub const VELOCITY_HALF: usize = 5;
/// Multipliers of the base STLSQ threshold tried for the starting model.
const THRESHOLD_LADDER: [f64; 5] = [1.0, 3.0, 10.0, 30.0, 100.0];
/// Sub-steps per sample of the free run: 2 keeps the frozen-Jacobian error of the
/// exponential Rosenbrock–Euler step small at the mechanical time constant (~13 ms for the
/// paper's motor, about one 12 ms sample).
pub const SUBSTEPS: usize = 2;
/// Bound on the free-run simulations one identification may spend.
const MAX_SIMULATIONS: usize = 400;

/// Settings of [`identify`].
#[derive(Debug, Clone, PartialEq)]
pub struct SindycOptions {
    pub plant: Plant,
    /// Number of delays of the Hankel embedding (paper: 60).
    pub delays: usize,
    /// Which singular components make `z` (paper: energy below 0.001).
    pub selection: Selection,
    /// tanh gain `a`.
    pub a: f64,
    /// Base STLSQ settings (the threshold ladder multiplies its threshold).
    pub stlsq: StlsqOptions,
    /// Allowed drop of the validation fit [points] when removing a term. Default 0.5: below
    /// the run-to-run spread of fits on Hall-quantised data.
    pub tolerance: f64,
    /// Velocity-estimator window of the measured `omega` used for scoring (paper: 10).
    pub velocity_window: usize,
}

impl Default for SindycOptions {
    fn default() -> Self {
        SindycOptions {
            plant: Plant::Voltage,
            delays: DEFAULT_DELAYS,
            selection: Selection::EnergyBelow(DEFAULT_ENERGY),
            a: DEFAULT_A,
            stlsq: StlsqOptions::default(),
            tolerance: 0.5,
            velocity_window: 10,
        }
    }
}

/// How `z` was made (stored with the model).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HankelSettings {
    pub delays: usize,
    /// Kept components, 1-based inclusive.
    pub components: (usize, usize),
    /// `z` = Hankel reconstruction / `z_scale`.
    pub z_scale: f64,
}

/// One row of the Pareto table.
#[derive(Debug, Clone, PartialEq)]
pub struct ParetoRow {
    /// Number of terms over all equations.
    pub terms: usize,
    /// Mean validation fit on ẋ [%]; `None` when the candidate diverged (or, for a model
    /// too large to refine, was not evaluated).
    pub fit: Option<f64>,
    /// What produced it.
    pub step: String,
    /// Whether it was kept on the path.
    pub accepted: bool,
}

/// The result of [`identify`].
#[derive(Debug, Clone)]
pub struct SindycResult {
    pub model: SindyModel<f64>,
    pub hankel: HankelSettings,
    pub pareto: Vec<ParetoRow>,
    /// The equations with named terms.
    pub equations_text: String,
    /// The Pareto table as text.
    pub pareto_text: String,
    /// Validation fit on ẋ of the returned model [%].
    pub validation_fit: f64,
    /// Correlation of the extracted z with the true z when the fitting logs have `z_true`.
    pub z_correlation: Option<f64>,
}

/// Centred velocity estimate: slope of the angle over ±`half` samples (one-sided at the
/// ends).
pub fn centred_velocity(t: &[f64], theta: &[f64], half: usize) -> Vec<f64> {
    let n = theta.len();
    (0..n)
        .map(|k| {
            let a = k.saturating_sub(half);
            let b = (k + half).min(n.saturating_sub(1));
            if b > a && t[b] > t[a] {
                (theta[b] - theta[a]) / (t[b] - t[a])
            } else {
                0.0
            }
        })
        .collect()
}

/// Pearson correlation of two equally long series (0 when one is constant).
pub fn correlation(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len()) as f64;
    if n < 2.0 {
        return 0.0;
    }
    let ma = a.iter().sum::<f64>() / n;
    let mb = b.iter().sum::<f64>() / n;
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma) * (x - ma);
        sbb += (y - mb) * (y - mb);
    }
    if saa <= 0.0 || sbb <= 0.0 {
        0.0
    } else {
        sab / (saa * sbb).sqrt()
    }
}

/// The regression rows of the weak form for one log: library integrals `∫φ·θ_j`
/// (`rows × p`), targets (`rows × 3`: `∫φ·dẋ/dt`, `∫φ·dz/dt`, `∫φ·u`) and the column
/// `∫φ·dI/dt` (`rows × 1`, zero without a current) of the current equation's inverse form.
///
/// Uniformly sampled logs (every log the board or the emulator writes) take the fast path
/// [`weak_rows_uniform`]; others the window-by-window [`weak_rows_generic`]. Both give the
/// same rows (to rounding; a test checks 1e-10 relative).
pub fn weak_rows(lib: &Library, t: &[f64], s: &Signals) -> (Mat<f64>, Mat<f64>, Mat<f64>) {
    if is_uniform(t) && weak_form::WINDOW.is_multiple_of(weak_form::HOP) {
        weak_rows_uniform(lib, t, s)
    } else {
        weak_rows_generic(lib, t, s)
    }
}

/// True when the sample period is constant (to 1e-9 relative).
fn is_uniform(t: &[f64]) -> bool {
    if t.len() < 2 {
        return false;
    }
    let h = t[1] - t[0];
    h > 0.0 && t.windows(2).all(|w| ((w[1] - w[0]) - h).abs() <= 1e-9 * h)
}

/// [`weak_rows`] for a uniformly sampled log. With a constant sample period every window
/// has the same test-function weights, and a window of `WINDOW = q·HOP` samples is `q`
/// consecutive hop-long segments. So each library column is evaluated once per sample (not
/// once per window it belongs to, twice at half overlap), blockwise into a cache-sized
/// buffer, and each segment's `q` partial integrals (one per piece of the test function) are
/// computed once; a window's integral is the sum of its segments' pieces.
pub fn weak_rows_uniform(lib: &Library, t: &[f64], s: &Signals) -> (Mat<f64>, Mat<f64>, Mat<f64>) {
    const LEN: usize = weak_form::WINDOW;
    const HOP: usize = weak_form::HOP;
    const Q: usize = LEN / HOP;
    let n = s.len().min(t.len());
    let p = lib.len();
    if n < LEN {
        return (Mat::zeros(0, p), Mat::zeros(0, 3), Mat::zeros(0, 1));
    }
    let rows = (n - LEN) / HOP + 1;
    // Segments used by the windows: rows + Q − 1.
    let segs = rows + Q - 1;
    // The kernels of the first window (all windows share them): φ·w, φ'·w, φ''·w.
    let w0 = &weak_form::windows(&t[..LEN], LEN, HOP)[0];
    let kern = |f: &[f64]| -> Vec<f64> { f.iter().zip(&w0.w).map(|(a, b)| a * b).collect() };
    let (k0, k1, k2) = (kern(&w0.phi), kern(&w0.dphi), kern(&w0.ddphi));
    // Partial integrals of one signal: part[g·Q + q] = Σ_i k[q·HOP + i]·v[g·HOP + i].
    let pieces = |k: &[f64], v: &[f64], out: &mut [f64]| {
        for (g, chunk) in v.chunks_exact(HOP).enumerate() {
            for q in 0..Q {
                out[g * Q + q] = dot(&k[q * HOP..(q + 1) * HOP], chunk);
            }
        }
    };
    // A window's integral from the pieces of its Q segments.
    let assemble = |part: &[f64], r: usize| -> f64 { (0..Q).map(|q| part[(r + q) * Q + q]).sum() };

    let mut a = Mat::<f64>::zeros(rows, p);
    // Library, blockwise: BLOCK samples = whole segments, about 0.5 MB of 17 columns.
    const BLOCK_SEGS: usize = 200;
    let mut buf = Mat::<f64>::zeros(BLOCK_SEGS * HOP, p);
    let mut part = vec![0.0; segs * Q];
    let mut col_parts: Vec<Vec<f64>> = vec![vec![0.0; segs * Q]; p];
    let mut g0 = 0;
    while g0 < segs {
        let g1 = (g0 + BLOCK_SEGS).min(segs);
        let (start, end) = (g0 * HOP, g1 * HOP);
        lib.matrix_into(&s.slice(start, end), &mut buf);
        for (j, cp) in col_parts.iter_mut().enumerate() {
            let col = &buf.col_as_slice(j)[..end - start];
            pieces(&k0, col, &mut cp[g0 * Q..g1 * Q]);
        }
        g0 = g1;
    }
    for (j, cp) in col_parts.iter().enumerate() {
        for r in 0..rows {
            a[(r, j)] = assemble(cp, r);
        }
    }
    let mut y = Mat::<f64>::zeros(rows, 3);
    let end = segs * HOP;
    pieces(&k2, &s.x[..end], &mut part);
    for r in 0..rows {
        y[(r, ACCEL)] = assemble(&part, r);
    }
    pieces(&k1, &s.z[..end], &mut part);
    for r in 0..rows {
        y[(r, ZDOT)] = -assemble(&part, r);
    }
    pieces(&k0, &s.u[..end], &mut part);
    for r in 0..rows {
        y[(r, IDOT)] = assemble(&part, r);
    }
    let mut d = Mat::<f64>::zeros(rows, 1);
    if let Some(i) = s.i {
        pieces(&k1, &i[..end], &mut part);
        for r in 0..rows {
            d[(r, 0)] = -assemble(&part, r);
        }
    }
    (a, y, d)
}

/// `Σ a_i·b_i` with four independent partial sums (a strict left-to-right sum is one long
/// dependency chain the compiler may not reorder; four lanes let it vectorise).
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut acc = [0.0; 4];
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let rest: f64 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(x, y)| x * y)
        .sum();
    for (x, y) in ca.zip(cb) {
        for ((s, p), q) in acc.iter_mut().zip(x).zip(y) {
            *s += p * q;
        }
    }
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + rest
}

/// [`weak_rows`] window by window (any sampling).
pub fn weak_rows_generic(lib: &Library, t: &[f64], s: &Signals) -> (Mat<f64>, Mat<f64>, Mat<f64>) {
    let wins = weak_form::windows(t, weak_form::WINDOW, weak_form::HOP);
    let p = lib.len();
    // The library is evaluated window by window into a small reused buffer (never the
    // whole N × p matrix: at 10^6 samples that allocation alone costs more than the fit).
    let mut a = Mat::<f64>::zeros(wins.len(), p);
    let mut buf = Mat::<f64>::zeros(weak_form::WINDOW, p);
    for (r, w) in wins.iter().enumerate() {
        if buf.nrows() < w.end - w.start {
            buf = Mat::<f64>::zeros(w.end - w.start, p);
        }
        lib.matrix_into(&s.slice(w.start, w.end), &mut buf);
        for j in 0..p {
            let col = &buf.col_as_slice(j)[..w.end - w.start];
            a[(r, j)] = w
                .phi
                .iter()
                .zip(&w.w)
                .zip(col)
                .map(|((f, q), v)| f * q * v)
                .sum();
        }
    }
    let y = Mat::<f64>::from_fn(wins.len(), 3, |r, e| match e {
        ACCEL => wins[r].int_dd(s.x),
        ZDOT => -wins[r].int_d(s.z),
        _ => wins[r].int(s.u),
    });
    let d = Mat::<f64>::from_fn(wins.len(), 1, |r, _| s.i.map_or(0.0, |i| -wins[r].int_d(i)));
    (a, y, d)
}

/// Limits beyond which a free run counts as divergent.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    pub omega: f64,
    pub current: f64,
}

impl Default for Limits {
    /// The hub's limits for scoring (runaway to 1e7).
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

/// Weight of the angle residual of the refinement relative to velocity and current (as the
/// grey-box refinement's, `sim_error.rs`: the free-run angle integrates every velocity error,
/// so it only steers the low frequencies).
const REFINE_ANGLE_WEIGHT: f64 = 0.3;
/// Weight of the current residual of the refinement relative to velocity. Lower than the
/// grey-box refinement's 1: the models are judged on x and ẋ, and at 12 ms the current is
/// quasi-static (it follows `u` within a sample), so at full weight the current's fit pulls
/// the electrical coefficients against the velocity fit. Measured on the emulated paper
/// motor (`paper-table`, fitted on signal a, scored on b, fit_sensor x/ẋ): weight 1 gives
/// 91.6/96.1 (the refinement was rejected), 0.3 gives 97.5/97.8, 0 gives 96.6/97.8.
const REFINE_CURRENT_WEIGHT: f64 = 0.3;
/// Iteration limit of the refinement (one Jacobian = one free run per coefficient each).
const REFINE_ITER: usize = 25;
/// Largest model (terms over all equations) the refinement takes on: each iteration costs
/// one free run per coefficient, and the sparse models the thresholding returns have 5–10.
const REFINE_MAX_TERMS: usize = 16;
/// Range of the tanh gain `a` [s/rad] the refinement may move to: from a soft sign
/// (0.5 s/rad, step complete at 5 rad/s) to one sharper than a sample of the paper's
/// velocity resolution can resolve (100 s/rad).
const REFINE_A_RANGE: (f64, f64) = (0.5, 100.0);

/// Free-run residuals of a SINDYc model on the fitting logs, defined as the grey-box
/// refinement's (`sim_error.rs`): velocity (the model's angle through the firmware's moving
/// average, not quantised so the cost stays smooth in the coefficients), current and angle
/// (weights [`REFINE_CURRENT_WEIGHT`], [`REFINE_ANGLE_WEIGHT`]), each normalised by the spread of the measured signal.
struct SimResiduals<'a> {
    logs: &'a [MotorLog],
    omega: Vec<Vec<f64>>,
    spreads: Vec<(f64, f64, f64)>,
    plant: Plant,
    window: usize,
    limits: Limits,
}

impl<'a> SimResiduals<'a> {
    fn new(logs: &'a [MotorLog], plant: Plant, window: usize, limits: Limits) -> Self {
        let omega: Vec<Vec<f64>> = logs
            .iter()
            .map(|l| sensor_chain::measured_velocity(l, window))
            .collect();
        let spreads = logs
            .iter()
            .zip(&omega)
            .map(|(l, w)| {
                (
                    super::sim_error::spread(w),
                    l.i.as_deref().map(super::sim_error::spread).unwrap_or(1.0),
                    super::sim_error::spread(&l.theta),
                )
            })
            .collect();
        SimResiduals {
            logs,
            omega,
            spreads,
            plant,
            window,
            limits,
        }
    }

    fn eval(&self, m: &SindyModel<f64>) -> Result<Vec<f64>> {
        let mut r = Vec::new();
        for ((log, w), (sw, si, sx)) in self.logs.iter().zip(&self.omega).zip(&self.spreads) {
            let p = simulate(m, self.plant, log, self.limits)?;
            let wp = sensor_chain::velocity_estimate(&p.t, &p.theta, self.window);
            r.extend(wp.iter().zip(w).map(|(a, b)| (a - b) / sw));
            if let (Some(im), Some(ip)) = (&log.i, &p.i) {
                r.extend(
                    ip.iter()
                        .zip(im)
                        .map(|(a, b)| REFINE_CURRENT_WEIGHT * (a - b) / si),
                );
            }
            r.extend(
                p.theta
                    .iter()
                    .zip(&log.theta)
                    .map(|(a, b)| REFINE_ANGLE_WEIGHT * (a - b) / sx),
            );
        }
        Ok(r)
    }
}

/// Which numbers of a model the refinement moves: every coefficient (equation, position in
/// its term list) and, when a term uses it, the tanh gain `a`.
fn refine_slots(m: &SindyModel<f64>) -> (Vec<(usize, usize)>, bool) {
    let mut slots = Vec::new();
    let mut uses_a = false;
    for (e, eq) in [&m.accel, &m.zdot, &m.idot].into_iter().enumerate() {
        for (k, (t, _)) in eq.terms.iter().enumerate() {
            slots.push((e, k));
            uses_a |= matches!(t, Term::TanhXdot | Term::TanhZ);
        }
    }
    (slots, uses_a)
}

fn with_values(
    base: &SindyModel<f64>,
    slots: &[(usize, usize)],
    uses_a: bool,
    x: &[f64],
) -> SindyModel<f64> {
    let mut m = base.clone();
    for (&(e, k), v) in slots.iter().zip(x) {
        let eq = match e {
            0 => &mut m.accel,
            1 => &mut m.zdot,
            _ => &mut m.idot,
        };
        eq.terms[k].1 = *v;
    }
    if uses_a {
        m.a = x[slots.len()];
    }
    m
}

/// Refine the coefficients of a model's sparse structure (and the tanh gain) by bounded
/// Levenberg–Marquardt ([`super::nlsq`]) on the free-run simulation error of the fitting
/// logs, as the LuGre model's dynamic step does. The weak form gets the structure and a
/// start; the simulation error then corrects what the weak form cannot see (the lag of a
/// quasi-static current, the bias of the sign-like terms on Hall-quantised data). Each
/// coefficient may move within ±10 times its magnitude around the start (so it can change
/// sign but cannot run off); a trial that diverges is rejected like one that raises the
/// cost. Errors when the start itself diverges on the fitting logs.
fn refine_model(
    m: &SindyModel<f64>,
    res: &SimResiduals,
    max_iter: usize,
) -> Result<SindyModel<f64>> {
    let (slots, uses_a) = refine_slots(m);
    let eqs = [&m.accel, &m.zdot, &m.idot];
    let mut x0: Vec<f64> = slots.iter().map(|&(e, k)| eqs[e].terms[k].1).collect();
    let mut lo: Vec<f64> = x0.iter().map(|c| c - 10.0 * c.abs()).collect();
    let mut hi: Vec<f64> = x0.iter().map(|c| c + 10.0 * c.abs()).collect();
    let mut scale: Vec<f64> = x0.iter().map(|c| c.abs().max(1e-12)).collect();
    if uses_a {
        x0.push(m.a.clamp(REFINE_A_RANGE.0, REFINE_A_RANGE.1));
        lo.push(REFINE_A_RANGE.0);
        hi.push(REFINE_A_RANGE.1);
        scale.push(m.a.abs().max(1.0));
    }
    if x0.is_empty() {
        return Ok(m.clone());
    }
    let mut f = |x: &[f64]| res.eval(&with_values(m, &slots, uses_a, x));
    let opts = nlsq::Options {
        max_iter,
        ..nlsq::Options::default()
    };
    let sol = nlsq::solve(&mut f, &x0, &lo, &hi, &scale, opts, &mut |it, cost| {
        if std::env::var_os("MOTORID_DEBUG").is_some() {
            eprintln!("SINDYc refinement: iteration {it}, cost {cost:.6e}");
        }
    })?;
    Ok(with_values(m, &slots, uses_a, &sol.x))
}

/// Prepared signals of one log.
struct Prepared {
    xdot: Vec<f64>,
    z: Vec<f64>,
}

/// Sparse coefficients of the three equations (normalised, one vector per equation).
#[derive(Clone)]
struct Candidate {
    xn: [Vec<f64>; 3],
}

impl Candidate {
    fn terms(&self) -> usize {
        self.xn
            .iter()
            .map(|x| x.iter().filter(|v| **v != 0.0).count())
            .sum()
    }
}

struct Search<'a> {
    lib: &'a Library,
    /// Normal equations per equation. The current equation is fitted in its inverse form
    /// `u = L·dI/dt + Σ c_k·θ_k` (see [`identify`]); its last column is `dI/dt`.
    nes: Vec<Normal>,
    /// Sample period (for the fallback inductance).
    dt: f64,
    plant: Plant,
    val: &'a [MotorLog],
    val_omega: Vec<Vec<f64>>,
    /// Velocity-estimator window of the sensor chain.
    window: usize,
    limits: Limits,
    z_max: f64,
    sims: usize,
}

impl Search<'_> {
    fn equations(&self) -> usize {
        if self.plant == Plant::Voltage {
            3
        } else {
            2
        }
    }

    fn model(&self, c: &Candidate) -> SindyModel<f64> {
        let mut m = SindyModel::empty(self.lib.a, self.lib.vs, 0.0);
        m.z_max = self.z_max;
        for e in 0..self.equations() {
            let mut coef = self.nes[e].denormalise(&c.xn[e]);
            if e == IDOT {
                coef = self.current_equation(&coef);
            }
            let mut eq = SparseEq::new();
            for (j, v) in coef.iter().enumerate().take(self.lib.len()) {
                if *v != 0.0 {
                    let _ = eq.push(self.lib.candidates[j].term, *v);
                }
            }
            match e {
                ACCEL => m.accel = eq,
                ZDOT => m.zdot = eq,
                _ => m.idot = eq,
            }
        }
        m
    }

    /// From the inverse form `u = L·dI/dt + Σ c_k·θ_k` to
    /// `dI/dt = u/L − Σ (c_k/L)·θ_k`. When the fitted `L` is not positive (the current
    /// settles within a sample, so 12 ms data cannot resolve it) `L` is set so that the
    /// time constant `L/R` is a tenth of the sample period, `R` being the fitted
    /// coefficient of `I`.
    fn current_equation(&self, coef: &[f64]) -> Vec<f64> {
        let p = self.lib.len();
        let r = self
            .lib
            .candidates
            .iter()
            .position(|c| c.term == Term::I)
            .map_or(0.0, |j| coef[j]);
        let mut l = coef[p];
        if !(l.is_finite() && l > 0.0) {
            l = r.abs().max(1e-6) * self.dt / 10.0;
        }
        let mut out: Vec<f64> = coef[..p].iter().map(|c| -c / l).collect();
        if let Some(j) = self.lib.candidates.iter().position(|c| c.term == Term::U) {
            out[j] = 1.0 / l;
        }
        out
    }

    /// Mean validation fit on ẋ, None when the model diverges on any log.
    fn score(&mut self, c: &Candidate) -> Option<f64> {
        let m = self.model(c);
        self.score_model(&m)
    }

    /// [`Search::score`] of a model.
    fn score_model(&mut self, m: &SindyModel<f64>) -> Option<f64> {
        self.sims += 1;
        validation_fit(
            m,
            self.plant,
            self.val,
            &self.val_omega,
            self.window,
            self.limits,
        )
    }

    /// Remove term `j` from equation `e` and refit that equation.
    fn without(&self, c: &Candidate, e: usize, j: usize) -> Candidate {
        let mut sup: Vec<bool> = c.xn[e].iter().map(|v| *v != 0.0).collect();
        sup[j] = false;
        let mut next = c.clone();
        next.xn[e] = self.nes[e].solve_normalised(0, &sup);
        // Keep the support exact (a refit may produce an exact zero only by accident).
        for (k, s) in sup.iter().enumerate() {
            if !s {
                next.xn[e][k] = 0.0;
            }
        }
        next
    }
}

/// Identify a SINDYc model. `val_logs` judge the thresholding (the fitting logs are used
/// when none are given).
pub fn identify(
    fit_logs: &[MotorLog],
    val_logs: &[MotorLog],
    adds: &[EffectSpec],
    opts: &SindycOptions,
) -> Result<SindycResult> {
    if fit_logs.is_empty() {
        bail!("SINDYc: no data to fit");
    }
    let voltage = opts.plant == Plant::Voltage;
    for log in fit_logs.iter().chain(val_logs) {
        if voltage && log.i.is_none() {
            bail!(
                "{}: column 'i': SINDYc with --plant voltage needs the measured current",
                log.source.display()
            );
        }
        if log.len() < 2 * opts.delays.max(weak_form::WINDOW) {
            bail!(
                "{}: {} samples are too few for SINDYc (the delay embedding needs at least {})",
                log.source.display(),
                log.len(),
                2 * opts.delays.max(weak_form::WINDOW)
            );
        }
    }
    // 1-2: velocities, Hankel embedding on all fitting logs, z normalised to unit RMS.
    let vel: Vec<Vec<f64>> = fit_logs
        .iter()
        .map(|l| centred_velocity(&l.t, &l.theta, VELOCITY_HALF))
        .collect();
    let all: Vec<f64> = vel.iter().flatten().copied().collect();
    // When no component is below the energy threshold (a noisy velocity has a flat tail),
    // fall back to the paper's split: the lower half of the spectrum (its k = 31..60).
    let emb = match HankelEmbedding::fit(&all, opts.delays, opts.selection) {
        Err(_) if matches!(opts.selection, Selection::EnergyBelow(_)) => HankelEmbedding::fit(
            &all,
            opts.delays,
            Selection::Range(opts.delays / 2 + 1, opts.delays),
        ),
        r => r,
    }
    .with_context(|| format!("{}: column 'theta'", fit_logs[0].source.display()))?;
    let mut prepared = Vec::new();
    let mut ss = 0.0;
    let mut count = 0usize;
    for v in vel {
        let z = emb.extract(&v)?;
        ss += z.iter().map(|x| x * x).sum::<f64>();
        count += z.len();
        prepared.push(Prepared { xdot: v, z });
    }
    let z_scale = (ss / count as f64).sqrt();
    if !(z_scale.is_finite() && z_scale > 0.0) {
        bail!("SINDYc: the extracted hidden state is zero; the velocity has no low-energy content");
    }
    let mut z_peak: f64 = 0.0;
    for p in &mut prepared {
        for z in &mut p.z {
            *z /= z_scale;
            z_peak = z_peak.max(z.abs());
        }
    }
    let z_correlation = fit_logs[0]
        .extra("z_true")
        .map(|zt| correlation(zt, &prepared[0].z));

    // 3: weak-form rows of every fitting log, stacked.
    let lib = Library::with_effects(opts.plant, opts.a, 1.0, adds)?;
    let mut blocks = Vec::new();
    for (log, p) in fit_logs.iter().zip(&prepared) {
        let s = Signals {
            x: &log.theta,
            xdot: &p.xdot,
            z: &p.z,
            i: if voltage { log.i.as_deref() } else { None },
            u: &log.u,
        };
        blocks.push(weak_rows(&lib, &log.t, &s));
    }
    let rows: usize = blocks.iter().map(|(a, _, _)| a.nrows()).sum();
    if rows < lib.len() + 1 {
        bail!(
            "SINDYc: the logs are too short for {} library terms",
            lib.len()
        );
    }
    let mut a = Mat::<f64>::zeros(rows, lib.len());
    let mut y = Mat::<f64>::zeros(rows, 3);
    let mut d = Mat::<f64>::zeros(rows, 1);
    let mut r0 = 0;
    for (ba, by, bd) in &blocks {
        d.as_mut().submatrix_mut(r0, 0, bd.nrows(), 1).copy_from(bd);
        a.as_mut()
            .submatrix_mut(r0, 0, ba.nrows(), ba.ncols())
            .copy_from(ba);
        y.as_mut().submatrix_mut(r0, 0, by.nrows(), 3).copy_from(by);
        r0 += ba.nrows();
    }
    // Acceleration and z: `∫φ·dẋ/dt`, `∫φ·dz/dt` on the library. Current: the inverse form
    // `∫φ·u = L·∫φ·dI/dt + Σ c_k·∫φ·θ_k`, because at 12 ms the current is quasi-static
    // (L/R ≈ 1.4 ms): `∫φ·dI/dt` is tiny and noisy, so regressing it on the library would
    // shrink every coefficient (errors in variables), while `u` is known exactly.
    let mut nes = vec![
        Normal::new(a.as_ref(), y.as_ref().subcols(0, 1)),
        Normal::new(a.as_ref(), y.as_ref().subcols(1, 1)),
    ];
    if voltage {
        let mut ad = Mat::<f64>::zeros(rows, lib.len() + 1);
        ad.as_mut().subcols_mut(0, lib.len()).copy_from(&a);
        ad.as_mut().subcols_mut(lib.len(), 1).copy_from(&d);
        nes.push(Normal::new(ad.as_ref(), y.as_ref().subcols(2, 1)));
    }

    // Validation logs and divergence limits.
    let val: &[MotorLog] = if val_logs.is_empty() {
        fit_logs
    } else {
        val_logs
    };
    let val_omega: Vec<Vec<f64>> = val
        .iter()
        .map(|l| sensor_chain::measured_velocity(l, opts.velocity_window))
        .collect();
    let wmax = val_omega
        .iter()
        .chain(prepared.iter().map(|p| &p.xdot))
        .flatten()
        .fold(0.0f64, |m, v| m.max(v.abs()));
    let imax = fit_logs
        .iter()
        .chain(val)
        .filter_map(|l| l.i.as_ref())
        .flatten()
        .fold(0.0f64, |m, v| m.max(v.abs()));
    let mut search = Search {
        lib: &lib,
        nes,
        dt: fit_logs[0].sample_period(),
        plant: opts.plant,
        val,
        val_omega,
        window: opts.velocity_window,
        limits: Limits {
            omega: 10.0 * wmax + 10.0,
            current: 10.0 * imax + 10.0,
        },
        // Observer clamp: 1.5× the largest |z| of the training data.
        z_max: 1.5 * z_peak.max(1e-9),
        sims: 0,
    };
    let neq = search.equations();
    // With a measured current, `u ≈ R·I + K_b·ẋ` at 12 ms: `u` terms in the acceleration
    // equation would make the split between `I` and `u` arbitrary and break the friction
    // rule of eq. 47, so they are left to the current equation (with a torque plant `u` is
    // the torque and stays). In the current equation's inverse form `u` is the target.
    let allowed = |e: usize| -> Vec<bool> {
        let usable = search.nes[e].usable();
        let mut v: Vec<bool> = lib
            .candidates
            .iter()
            .zip(&usable)
            .map(|(c, u)| {
                *u && c.allowed[e]
                    && !(voltage && e == ACCEL && c.term.has_voltage())
                    && !(e == IDOT && c.term == Term::U)
            })
            .collect();
        if e == IDOT {
            v.push(usable[lib.len()]);
        }
        v
    };
    let allowed: Vec<Vec<bool>> = (0..neq).map(allowed).collect();

    // 4: STLSQ ladder → starting candidate.
    let mut pareto = Vec::new();
    let mut best: Option<(Candidate, Option<f64>)> = None;
    // Each threshold is tried with the whole library and without the z terms (then z stays
    // 0): the extracted z only earns its terms if it predicts better.
    let ladder = THRESHOLD_LADDER
        .iter()
        .flat_map(|m| [(*m, false), (*m, true)]);
    for (mult, z_free) in ladder {
        let o = StlsqOptions {
            threshold: opts.stlsq.threshold * mult,
            ..opts.stlsq
        };
        let mut c = Candidate {
            xn: [
                vec![0.0; lib.len()],
                vec![0.0; lib.len()],
                vec![0.0; lib.len() + 1],
            ],
        };
        for (e, allowed_e) in allowed.iter().enumerate() {
            if z_free && e == ZDOT {
                continue;
            }
            let mut sup = allowed_e.clone();
            if z_free {
                for (k, c) in lib.candidates.iter().enumerate() {
                    sup[k] &= !c.term.has_z();
                }
            }
            let mut xn = search.nes[e].stlsq_normalised(0, &sup, &o);
            // The firmware holds at most MAX_TERMS terms per equation: drop the smallest.
            while xn.iter().filter(|v| **v != 0.0).count() > MAX_TERMS {
                let j = smallest(&xn);
                let mut sup: Vec<bool> = xn.iter().map(|v| *v != 0.0).collect();
                sup[j] = false;
                xn = search.nes[e].solve_normalised(0, &sup);
                for (k, s) in sup.iter().enumerate() {
                    if !s {
                        xn[k] = 0.0;
                    }
                }
            }
            c.xn[e] = xn;
        }
        let fit = search.score(&c);
        pareto.push(ParetoRow {
            terms: c.terms(),
            fit,
            step: format!(
                "STLSQ, threshold {:.3}{}",
                o.threshold,
                if z_free { ", without z" } else { "" }
            ),
            accepted: false,
        });
        let better = match &best {
            None => true,
            Some((_, bf)) => fit.unwrap_or(f64::NEG_INFINITY) > bf.unwrap_or(f64::NEG_INFINITY),
        };
        if better {
            best = Some((c, fit));
        }
    }
    let (mut cur, mut cur_fit) = best.expect("the ladder is not empty");
    let start = cur.clone();
    if let Some(row) = pareto
        .iter_mut()
        .find(|r| r.fit == cur_fit && r.terms == cur.terms())
    {
        row.accepted = true;
    }
    let mut best_fit = cur_fit.unwrap_or(f64::NEG_INFINITY);

    // 5: one-by-one hard thresholding judged by the validation fit.
    loop {
        if search.sims >= MAX_SIMULATIONS || cur.terms() <= 1 {
            break;
        }
        let mut order: Vec<(f64, usize, usize)> = Vec::new();
        for e in 0..neq {
            let yn = search.nes[e].target_norm(0).max(f64::MIN_POSITIVE);
            for (j, v) in cur.xn[e].iter().enumerate() {
                // The inductance column and the current's R·I stay: they make the equation.
                let keep = e == IDOT && (j == lib.len() || lib.candidates[j].term == Term::I);
                if *v != 0.0 && !keep {
                    order.push((v.abs() / yn, e, j));
                }
            }
        }
        order.sort_by(|a, b| a.0.total_cmp(&b.0));
        if order.is_empty() {
            break;
        }
        // Try the terms from the smallest contribution up; keep the first removal whose
        // validation fit stays within the tolerance of the best seen (or, while the current
        // model diverges, the first that does not diverge).
        let mut accepted = false;
        let mut first_rejected: Option<ParetoRow> = None;
        for &(_, e, j) in &order {
            if search.sims >= MAX_SIMULATIONS {
                break;
            }
            let c = search.without(&cur, e, j);
            let fit = search.score(&c);
            let step = format!("removed {}: {}", EQUATION_NAMES[e], lib.candidates[j].term);
            match fit {
                Some(f) if cur_fit.is_none() || f >= best_fit - opts.tolerance => {
                    pareto.push(ParetoRow {
                        terms: c.terms(),
                        fit: Some(f),
                        step,
                        accepted: true,
                    });
                    best_fit = if cur_fit.is_none() {
                        f
                    } else {
                        best_fit.max(f)
                    };
                    cur = c;
                    cur_fit = Some(f);
                    accepted = true;
                    break;
                }
                _ => {
                    if first_rejected.is_none() {
                        first_rejected = Some(ParetoRow {
                            terms: c.terms(),
                            fit,
                            step: format!("{step} (rejected)"),
                            accepted: false,
                        });
                    }
                }
            }
        }
        if !accepted {
            pareto.extend(first_rejected);
            if cur_fit.is_some() || search.sims >= MAX_SIMULATIONS {
                break;
            }
            // Every removal diverges too: drop the smallest term and go on.
            let (_, e, j) = order[0];
            cur = search.without(&cur, e, j);
        }
    }
    let Some(validation_fit) = cur_fit else {
        bail!(
            "SINDYc: every candidate model diverges in free run on the validation data; \
             try more data, other --add effects, or the lugre model"
        );
    };
    // 6: refinement on the simulation error of the fitting logs, from the thresholded model
    // and from the STLSQ start (more terms, more freedom); kept only when the validation
    // fit improves, so it can never make the result worse.
    let mut model = search.model(&cur);
    let mut validation_fit = validation_fit;
    let res = SimResiduals::new(fit_logs, opts.plant, opts.velocity_window, search.limits);
    let mut starts = vec![("the thresholded model", model.clone())];
    if start.terms() != cur.terms() {
        starts.push(("the STLSQ start", search.model(&start)));
    }
    for (name, m0) in starts {
        let terms = m0.accel.terms.len() + m0.zdot.terms.len() + m0.idot.terms.len();
        if terms > REFINE_MAX_TERMS {
            pareto.push(ParetoRow {
                terms,
                fit: None,
                step: format!(
                    "{name} not refined: more than {REFINE_MAX_TERMS} terms would cost \
                     {} free runs per iteration",
                    terms + 2
                ),
                accepted: false,
            });
            continue;
        }
        let refined = refine_model(&m0, &res, REFINE_ITER);
        let fit = refined.as_ref().ok().and_then(|r| search.score_model(r));
        let better = fit.is_some_and(|f| f > validation_fit);
        pareto.push(ParetoRow {
            terms,
            fit,
            step: format!("{name} refined on the free-run simulation error"),
            accepted: better,
        });
        if let (true, Ok(r), Some(f)) = (better, refined, fit) {
            model = r;
            validation_fit = f;
        }
    }
    let equations_text = equations_text(&model, opts.plant);
    let pareto_text = pareto_text(&pareto);
    Ok(SindycResult {
        model,
        hankel: HankelSettings {
            delays: emb.delays(),
            components: emb.selected(),
            z_scale,
        },
        pareto,
        equations_text,
        pareto_text,
        validation_fit,
        z_correlation,
    })
}

fn smallest(xn: &[f64]) -> usize {
    let mut best = (f64::INFINITY, 0);
    for (j, v) in xn.iter().enumerate() {
        if *v != 0.0 && v.abs() < best.0 {
            best = (v.abs(), j);
        }
    }
    best.1
}

/// The equations with named terms, one line per equation (eq. 43 included).
pub fn equations_text(m: &SindyModel<f64>, plant: Plant) -> String {
    let mut s = String::from("dx/dt = xdot\n");
    let eqs: Vec<(&str, &SparseEq<f64>)> = if plant == Plant::Voltage {
        vec![
            (EQUATION_NAMES[0], &m.accel),
            (EQUATION_NAMES[1], &m.zdot),
            (EQUATION_NAMES[2], &m.idot),
        ]
    } else {
        vec![(EQUATION_NAMES[0], &m.accel), (EQUATION_NAMES[1], &m.zdot)]
    };
    for (name, eq) in eqs {
        let _ = write!(s, "{name} =");
        if eq.terms.is_empty() {
            s.push_str(" 0");
        }
        for (k, (t, c)) in eq.terms.iter().enumerate() {
            let sign = if *c < 0.0 {
                "-"
            } else if k == 0 {
                ""
            } else {
                "+"
            };
            let _ = write!(s, " {sign} {:.6e}*{}", c.abs(), t);
        }
        s.push('\n');
    }
    let _ = writeln!(s, "(a = {}, vs = {}, |z| <= {:.4})", m.a, m.vs, m.z_max);
    s
}

/// The Pareto table: terms vs validation fit, one row per candidate examined.
pub fn pareto_text(rows: &[ParetoRow]) -> String {
    let mut s = String::from("  terms  validation fit xdot %  kept  step\n");
    for r in rows {
        let fit = match r.fit {
            Some(f) => format!("{f:8.2}"),
            None if r.step.contains("not refined") => "-".to_string(),
            None => "diverged".to_string(),
        };
        let _ = writeln!(
            s,
            "  {:>5}  {:>22}  {:>4}  {}",
            r.terms,
            fit,
            if r.accepted { "yes" } else { "" },
            r.step
        );
    }
    s
}

/// The `[sindy]` table of MODEL.toml: settings, then each equation as `term name = coef`.
pub fn to_table(m: &SindyModel<f64>, h: &HankelSettings) -> toml::Table {
    use toml::Value;
    let mut t = toml::Table::new();
    t.insert("a".into(), Value::Float(m.a));
    t.insert("vs".into(), Value::Float(m.vs));
    t.insert("j".into(), Value::Float(m.j));
    t.insert("z_max".into(), Value::Float(m.z_max));
    t.insert("hankel_delays".into(), Value::Integer(h.delays as i64));
    t.insert(
        "hankel_components".into(),
        Value::Array(vec![
            Value::Integer(h.components.0 as i64),
            Value::Integer(h.components.1 as i64),
        ]),
    );
    t.insert("z_scale".into(), Value::Float(h.z_scale));
    for (name, eq) in [("accel", &m.accel), ("zdot", &m.zdot), ("idot", &m.idot)] {
        let mut e = toml::Table::new();
        for (term, c) in &eq.terms {
            e.insert(term.name().as_str().to_string(), Value::Float(*c));
        }
        t.insert(name.into(), Value::Table(e));
    }
    t
}

/// Read the `[sindy]` table back (errors name the field).
pub fn from_table(t: &toml::Table) -> Result<(SindyModel<f64>, HankelSettings)> {
    let num = |k: &str| -> Result<f64> {
        match t.get(k) {
            Some(toml::Value::Float(v)) => Ok(*v),
            Some(toml::Value::Integer(v)) => Ok(*v as f64),
            Some(_) => bail!("field 'sindy.{k}': not a number"),
            None => bail!("field 'sindy.{k}': missing"),
        }
    };
    let mut m = SindyModel::empty(num("a")?, num("vs")?, num("j")?);
    m.z_max = num("z_max")?;
    for name in ["accel", "zdot", "idot"] {
        let mut eq = SparseEq::new();
        if let Some(v) = t.get(name) {
            let tab = v.as_table().ok_or_else(|| {
                anyhow!("field 'sindy.{name}': not a table of term = coefficient")
            })?;
            for (k, v) in tab {
                let term = Term::parse(k)
                    .ok_or_else(|| anyhow!("field 'sindy.{name}': unknown term '{k}'"))?;
                let c = v
                    .as_float()
                    .or_else(|| v.as_integer().map(|i| i as f64))
                    .filter(|c| c.is_finite())
                    .ok_or_else(|| anyhow!("field 'sindy.{name}.\"{k}\"': not a number"))?;
                eq.push(term, c)
                    .map_err(|_| anyhow!("field 'sindy.{name}': more than {MAX_TERMS} terms"))?;
            }
        }
        match name {
            "accel" => m.accel = eq,
            "zdot" => m.zdot = eq,
            _ => m.idot = eq,
        }
    }
    let comps = t
        .get("hankel_components")
        .and_then(|v| v.as_array())
        .and_then(|a| Some((a.first()?.as_integer()?, a.get(1)?.as_integer()?)))
        .unwrap_or((0, 0));
    let h = HankelSettings {
        // From the file: bounded, it sizes a Hankel matrix.
        delays: num("hankel_delays").unwrap_or(0.0).clamp(0.0, 1000.0) as usize,
        components: (
            comps.0.clamp(0, 1000) as usize,
            comps.1.clamp(0, 1000) as usize,
        ),
        z_scale: num("z_scale").unwrap_or(1.0),
    };
    Ok((m, h))
}

/// `fit --model sindyc`: identify and wrap as a [`crate::model::Model`] (called from [`super::fit`]).
pub fn fit_model(req: &super::FitRequest) -> Result<crate::model::Model> {
    use crate::model::{Model, ModelKind, Parameter};
    let opts = SindycOptions {
        plant: req.plant,
        ..SindycOptions::default()
    };
    let res = identify(req.logs, req.validate, req.adds, &opts)?;
    eprintln!("SINDYc equations:\n{}", res.equations_text);
    eprintln!(
        "SINDYc Pareto path (terms vs validation fit):\n{}",
        res.pareto_text
    );
    let ts = req.logs[0].sample_period();
    let mut model = Model::new(ModelKind::Sindyc, req.plant, ts);
    let mut sm = res.model;
    // Inertia for eq. 47 (friction torque = −J·Σ friction terms): K_t/b_I for a voltage
    // plant, 1/b_u for a torque plant (u is the torque), else the motor's nominal J.
    let (gain_term, gain) = match req.plant {
        Plant::Voltage => (Term::I, model.motor.kt),
        Plant::Torque => (Term::U, 1.0),
    };
    let b = sm.accel.coef(gain_term);
    if b > 0.0 && (gain / b).is_finite() {
        model.motor.j = gain / b;
    }
    if req.plant == Plant::Torque {
        model.motor.kt = 1.0;
        model.motor.r = 0.0;
        model.motor.l = 0.0;
        model.motor.kb = 0.0;
    }
    sm.j = model.motor.j;
    model.effects = req.adds.iter().map(|s| s.to_effect()).collect();
    model.sindy = Some(to_table(&sm, &res.hankel));
    for (prefix, eq, unit) in [
        ("accel", &sm.accel, "rad/s² per term unit"),
        ("zdot", &sm.zdot, "1/s per term unit"),
        ("idot", &sm.idot, "A/s per term unit"),
    ] {
        for (t, c) in &eq.terms {
            let mut p = Parameter::new(&format!("{prefix}[{t}]"), *c, unit);
            p.note = "SINDYc coefficient".into();
            model.parameters.push(p);
        }
    }
    model.data.method = format!(
        "SINDYc: z from a {}-delay Hankel embedding of the velocity (components {}..{}), \
         weak-form STLSQ, one-by-one thresholding on the validation fit ({:.2} % on xdot)",
        res.hankel.delays, res.hankel.components.0, res.hankel.components.1, res.validation_fit
    );
    Ok(model)
}

/// Free run of a `sindyc` [`crate::model::Model`] (called from [`super::fit`]).
pub fn simulate_model(model: &crate::model::Model, log: &MotorLog) -> Result<Prediction> {
    let table = model
        .sindy
        .as_ref()
        .ok_or_else(|| anyhow!("field 'sindy': a model of kind 'sindyc' needs a [sindy] table"))?;
    let (m, _) = from_table(table)?;
    simulate(&m, model.plant, log, Limits::default())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::emulator::{simulate_signal, EmulatorConfig, SignalKind};

    fn emulated(kind: SignalKind, seed: u64) -> MotorLog {
        let cfg = EmulatorConfig {
            seed,
            ..EmulatorConfig::paper()
        };
        let mut log = simulate_signal(&cfg, kind, 90.0).unwrap().log_with_truth();
        log.source = format!("{}.csv", kind.name()).into();
        log
    }

    #[test]
    fn uniform_weak_rows_equal_the_window_by_window_rows() {
        let a = emulated(SignalKind::A, 3);
        let v = centred_velocity(&a.t, &a.theta, VELOCITY_HALF);
        let z: Vec<f64> = v.iter().map(|w| (0.3 * w).sin()).collect();
        let lib = Library::paper(Plant::Voltage, DEFAULT_A, 1.0);
        // 17 extra samples: the last partial hop is not part of any window.
        let n = 1000 + 17;
        let s = Signals {
            x: &a.theta[..n],
            xdot: &v[..n],
            z: &z[..n],
            i: a.i.as_deref().map(|i| &i[..n]),
            u: &a.u[..n],
        };
        assert!(is_uniform(&a.t[..n]));
        let fast = weak_rows_uniform(&lib, &a.t[..n], &s);
        let slow = weak_rows_generic(&lib, &a.t[..n], &s);
        for (f, g) in [(&fast.0, &slow.0), (&fast.1, &slow.1), (&fast.2, &slow.2)] {
            assert_eq!((f.nrows(), f.ncols()), (g.nrows(), g.ncols()));
            for j in 0..g.ncols() {
                let scale = (0..g.nrows())
                    .map(|r| g[(r, j)].abs())
                    .fold(1e-300, f64::max);
                for r in 0..g.nrows() {
                    assert!(
                        (f[(r, j)] - g[(r, j)]).abs() <= 1e-10 * scale,
                        "row {r} column {j}: {} vs {}",
                        f[(r, j)],
                        g[(r, j)]
                    );
                }
            }
        }
        // A non-uniform time axis takes the generic path.
        let mut t = a.t[..n].to_vec();
        t[500] += 0.003;
        assert!(!is_uniform(&t));
    }

    fn truth_model() -> crate::model::Model {
        use crate::model::{Model, ModelKind};
        let cfg = EmulatorConfig::paper();
        let mut m = Model::new(
            ModelKind::Lugre,
            Plant::Voltage,
            crate::emulator::SAMPLE_PERIOD,
        );
        m.motor = cfg.motor;
        m.lugre = Some(cfg.lugre);
        m.sensor.hall_resolution_rad = cfg.hall_resolution();
        m
    }

    #[test]
    fn lugre_data_gives_a_stable_model_close_to_the_truth() {
        let a = emulated(SignalKind::A, 1);
        let b = emulated(SignalKind::B, 2);
        let res = identify(
            std::slice::from_ref(&a),
            std::slice::from_ref(&b),
            &[],
            &SindycOptions::default(),
        )
        .unwrap();
        eprintln!("{}\n{}", res.equations_text, res.pareto_text);
        eprintln!("z correlation {:?}", res.z_correlation);
        let wb = sensor_chain::measured_velocity(&b, 10);
        // The emulator's own model scored by the same function (through the sensor chain).
        let truth = crate::ident::score(&truth_model(), &b)
            .unwrap()
            .fit_sensor
            .xdot;
        let ours = validation_fit(
            &res.model,
            Plant::Voltage,
            std::slice::from_ref(&b),
            std::slice::from_ref(&wb),
            10,
            Limits::default(),
        )
        .unwrap();
        eprintln!("validation b: SINDYc {ours:.2} %, true model {truth:.2} %");
        assert!((ours - res.validation_fit).abs() < 1e-9);
        assert!(ours > truth - 5.0, "{ours} vs {truth}");
        // Every returned model is finite in free run on the other signals too.
        for (k, kind) in [SignalKind::C, SignalKind::D].into_iter().enumerate() {
            let log = emulated(kind, 10 + k as u64);
            let p = simulate(&res.model, Plant::Voltage, &log, Limits::default()).unwrap();
            assert!(p.omega.iter().all(|w| w.is_finite()));
        }
        // The table round-trips.
        let t = to_table(&res.model, &res.hankel);
        let (back, h) = from_table(&t).unwrap();
        // (TOML tables are sorted by name: compare term by term, a sum has no order.)
        for (a, b) in [
            (&back.accel, &res.model.accel),
            (&back.zdot, &res.model.zdot),
            (&back.idot, &res.model.idot),
        ] {
            assert_eq!(a.terms.len(), b.terms.len());
            for (t, c) in &b.terms {
                assert_eq!(a.coef(*t), *c, "{t}");
            }
        }
        assert_eq!(
            (back.a, back.vs, back.z_max),
            (res.model.a, res.model.vs, res.model.z_max)
        );
        assert_eq!(h, res.hankel);
    }

    /// The paper's hidden state on emulated LuGre data. Finding (reported, not hidden): with
    /// the paper's low-energy selection the extracted z is almost uncorrelated with the
    /// emulator's bristle deflection (|r| ≈ 0.05), because the LuGre z is nearly a static
    /// function of the velocity (r ≈ 0.93 with tanh(ω/0.5)) and lives in the high-energy
    /// subspace the method discards. What the test pins down: the low-energy z carries
    /// almost none of the velocity itself (it is a projection onto the complementary
    /// subspace), and dropping only the dominant component keeps clearly more of z_true.
    #[test]
    fn hankel_state_on_lugre_data() {
        let a = emulated(SignalKind::A, 1);
        let zt = a.extra("z_true").unwrap();
        let v = centred_velocity(&a.t, &a.theta, VELOCITY_HALF);
        let paper = HankelEmbedding::fit(&v, 60, Selection::EnergyBelow(0.001)).unwrap();
        let zp = paper.extract(&v).unwrap();
        let broad = HankelEmbedding::fit(&v, 60, Selection::Range(2, 60)).unwrap();
        let zb = broad.extract(&v).unwrap();
        let r_paper = correlation(zt, &zp);
        let r_broad = correlation(zt, &zb);
        eprintln!(
            "corr(z_true, z): paper selection {:?} {r_paper:.3}, components 2..60 {r_broad:.3}",
            paper.selected()
        );
        assert_eq!(zp.len(), v.len());
        assert!(correlation(&v, &zp).abs() < 0.1);
        assert!(r_broad.abs() > r_paper.abs() + 0.2);
    }
}
