//! The model-error workbench: which physical effect a model is missing, and where it fails.
//!
//! How `diagnose` decides (documented for `motorid diagnose --help` too):
//! 1. The log is turned into two *equation residuals* in weak form ([`crate::numerics::weak_form`]): the
//!    mechanical torque balance and, for a voltage plant, the electrical voltage balance.
//!    The model's own structure (inertia, R, L, K_b and the effects it has) is refitted by
//!    least squares in each equation, so a biased parameter cannot pass for a missing effect.
//! 2. Every effect of the list (`EffectKind::ALL`) that the model lacks brings its regressors
//!    ([`candidates`]), over a grid for its nonlinear parameters (cogging harmonic, Stribeck
//!    velocity, thermal time constant, bristle stiffness). Presliding is tested apart, on
//!    every window of the torque equation (the reversals and standstills where it lives
//!    included), on top of a model with Coulomb or Stribeck friction; see
//!    [`crate::effects::presliding::DEFLECTION_GRID`] and [`PRESLIDING_GAIN`].
//! 3. Forward selection: the candidate that explains most of the residual is tested beyond
//!    the base with the jackknifed cluster-robust Wald test on disjoint windows, clustered by
//!    held input ([`statistics::robust_wald_test`]), so that a few noisy windows or the
//!    shared error of one held input are not taken for evidence.
//!    It is kept when it is **significant** (p below [`FAMILY_ALPHA`] divided by the number of
//!    candidate variants tested, Bonferroni, and a lower BIC) **and relevant** (it explains at
//!    least [`MIN_EXPLAINED`] of the model's own residual sum of squares; a second inertia on
//!    a coupling, whose column shares the angle's reading with the inertia's, also a torque of
//!    at least [`MIN_TORQUE_FRACTION`] of the Coulomb friction); it then joins the base and
//!    the next one is tested, until none passes. A candidate left that passes every rule but
//!    the share is not named, and fails the verdict's `small effects` check: the model
//!    misses something the data show, too small to estimate.
//! 4. Each finding's coefficients become a spec (`cogging:harmonic=7,amp=0.03,phase=0.2`) that
//!    `fit --add` accepts; its score is the fraction of the base residual it explains.
pub mod candidates;
pub mod carriers;
mod equations;
mod forward_select;
pub mod harmonics;
pub mod lookalikes;
pub mod regions;
pub mod verdict;

use crate::effect_spec::EffectSpec;
use crate::effects::presliding;
use crate::log::{MotorLog, Plant};
use crate::numerics::least_squares;
use crate::numerics::statistics;
use crate::numerics::weak_form;
use candidates::{Equation, Signals, Units, Variant};
use control::effects::{Effect, EffectKind};
use control::motor::MotorParams;
use serde::Serialize;

/// Family-wise false-alarm probability of one `diagnose` run: the chance that a correct model
/// gets any finding at all is at most 0.1 % (Bonferroni over every variant tested), where
/// the entry tests' p-values are valid; columns built from the measured angle share its
/// rounding with the residual, and for those the level is not shown (decision 0024).
pub const FAMILY_ALPHA: f64 = 1e-3;
/// Smallest fraction of an equation's residual sum of squares an effect must explain to be
/// reported: 2 %. Below that, adding the effect would not change a fit noticeably, however
/// significant.
pub const MIN_EXPLAINED: f64 = 0.02;
/// Most findings one run reports.
pub const MAX_FINDINGS: usize = 6;

/// What the model already has: the plant, its effects (with their parameter values, which fix
/// the nonlinear parameters of their regressors) and its constants.
#[derive(Debug, Clone)]
pub struct Structure {
    pub plant: Plant,
    /// Effects of the model, including its base friction (`coulomb`, `viscous`, ...).
    pub effects: Vec<Effect<f64>>,
    /// Torque constant K_t [N·m/A] (ignored for a torque plant).
    pub kt: f64,
    /// The model's constants as given, for the verdict on its parameters; `None` when the
    /// model's equations are not a motor with these constants (SINDYc).
    pub motor: Option<MotorParams<f64>>,
}

impl Structure {
    /// A structure with the given effects and the paper motor's K_t.
    pub fn with_effects(plant: Plant, effects: Vec<Effect<f64>>) -> Structure {
        Structure {
            plant,
            effects,
            kt: MotorParams::<f64>::paper().kt,
            motor: Some(MotorParams::paper()),
        }
    }

    /// The effect kinds the model has.
    pub fn kinds(&self) -> Vec<EffectKind> {
        self.effects.iter().map(|e| e.kind()).collect()
    }

    fn has(&self, k: EffectKind) -> bool {
        self.effects.iter().any(|e| e.kind() == k)
    }
}

/// Tuning of a run (defaults: the documented constants).
#[derive(Debug, Clone, Copy)]
pub struct Options {
    pub alpha: f64,
    pub min_explained: f64,
    /// Weak-form window half-width in samples; 0 (the default): [`weak_form::HALF_WIDTH_S`]
    /// seconds in the log's samples (8 samples at the paper's 12 ms).
    pub half_width: usize,
    /// Read the torque equation's angle as the centre line its readings allow on stretches
    /// of steady speed ([`crate::numerics::quantisation`]) and weight that equation's rows by
    /// the variance the remaining quantisation puts into each ([`row_scale`]). Off by
    /// default: it removes the beat of the rounding against the sampling on voltage steps,
    /// but the voltage equation's own error at the steps then decides the verdict there, and
    /// on the multisines it changes nothing a correct model needs.
    pub steady_angle: bool,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            alpha: FAMILY_ALPHA,
            min_explained: MIN_EXPLAINED,
            half_width: 0,
            steady_angle: false,
        }
    }
}

/// One effect the data shows the model is missing.
#[derive(Debug, Clone, Serialize)]
pub struct Finding {
    pub name: String,
    /// Spec with estimated parameters, accepted by `fit --add`.
    pub spec: String,
    /// Fraction of the equation's base residual sum of squares the effect explains (0..1).
    pub score: f64,
    /// One sentence of physics.
    pub explanation: String,
    pub equation: Equation,
    /// p-value of the entry test (the cluster-robust Wald test of the effect's columns
    /// beyond the base, [`forward_select`]).
    pub p_value: f64,
    /// Hotelling's `T²` of that test (NaN when it could not decide).
    pub t2: f64,
    pub delta_bic: f64,
    #[serde(skip)]
    pub kind: Option<EffectKind>,
}

/// One candidate's best test (kept or not), for tables.
#[derive(Debug, Clone, Serialize)]
pub struct Tested {
    pub name: String,
    pub equation: Equation,
    pub spec: String,
    pub explained: f64,
    pub p_value: f64,
    pub kept: bool,
}

/// Residual of one equation.
#[derive(Debug, Clone, Serialize)]
pub struct EquationResidual {
    pub equation: Equation,
    /// Time of each weak-form window centre [s].
    pub t: Vec<f64>,
    /// Sample index of each window centre.
    #[serde(skip)]
    pub centres: Vec<usize>,
    /// Residual of the model's own structure, per window.
    pub base: Vec<f64>,
    /// Residual after the findings were added.
    pub after: Vec<f64>,
    /// Effective sample count of the base residual.
    pub n_eff: f64,
    /// Whiteness of the base residual and its correlation with the input.
    #[serde(skip)]
    pub whiteness: statistics::Whiteness,
    /// Unit of the residual.
    pub unit: &'static str,
}

/// Result of a diagnosis.
#[derive(Debug, Clone, Serialize)]
pub struct Diagnosis {
    /// Significant and relevant missing effects, most important first.
    pub effects: Vec<Finding>,
    /// Every candidate's best test.
    pub tested: Vec<Tested>,
    /// Equation residuals.
    pub equations: Vec<EquationResidual>,
    /// Per-test level after Bonferroni.
    pub alpha_per_test: f64,
    pub min_explained: f64,
    /// The verdict on the model as given.
    pub verdict: Verdict,
}

/// The verdict on the model as given ([`verdict`]).
#[derive(Debug, Clone, Serialize, Default)]
pub struct Verdict {
    /// True only when every check passes, no effect is missing and nothing is unexplained.
    pub adequate: bool,
    /// False when a check could not decide on this log: an equation with too few usable
    /// windows ([`MIN_VERDICT_ROWS`]), too few held inputs for a test, a whiteness check on
    /// held inputs, or a carrier whose test had to leave out too much (its p-value NaN). The
    /// log cannot show whether the model is adequate, and `adequate` is false for that reason
    /// alone when no finding, carrier or other check says otherwise.
    pub judged: bool,
    /// Family-wise level of the checks and the per-test level after Bonferroni.
    pub level: f64,
    pub level_per_test: f64,
    /// Parameter, whiteness and input checks, per equation.
    pub checks: Vec<verdict::Check>,
    /// Variables that carry structure no effect explains, most important first.
    pub unexplained: Vec<carriers::Carrier>,
    /// The refitted constants, when the parameter check failed.
    pub refit: Vec<(String, f64, String)>,
    /// Explanations the data supports about equally, with the experiment that separates them.
    pub look_alikes: Vec<lookalikes::LookAlike>,
}

pub(super) struct EqData {
    pub(super) eq: Equation,
    pub(super) y: Vec<f64>,
    /// The base columns; add them with [`EqData::push_base`] only, which keeps them, their
    /// names and their instruments in one order.
    pub(super) base_cols: Vec<Vec<f64>>,
    /// What each base column's coefficient is ([`Column`]), for the refitted values.
    pub(super) base_names: Vec<Column>,
    /// Each base column computed on the model's own noise-free run ([`simulated_log`]), the
    /// parameter check's instrument for it; `None` where there is no run.
    pub(super) base_inst: Vec<Option<Vec<f64>>>,
    /// Sample-level columns to carry into the other equation's base.
    pub(super) base_sample: Vec<SampleColumn>,
    /// Smallest torque [N·m] (RMS of the effect's term) worth reporting.
    pub(super) min_torque: f64,
    /// Base column of the model's Coulomb friction (`sgn ω`) when the model states no positive
    /// value for it: the threshold then follows the refitted Coulomb friction ([`min_torque`]).
    pub(super) coulomb_col: Option<usize>,
    pub(super) cand: Vec<(Variant, Vec<Vec<f64>>)>,
    /// Held input of each row ([`verdict::hold_clusters`]): rows that may share an error of
    /// the angle's reading, one cluster of the entry test ([`forward_select`]).
    pub(super) cluster: Vec<usize>,
}

impl EqData {
    /// An equation with no columns yet.
    pub(super) fn new(eq: Equation, y: Vec<f64>, cluster: Vec<usize>) -> EqData {
        EqData {
            eq,
            y,
            base_cols: vec![],
            base_names: vec![],
            base_inst: vec![],
            base_sample: vec![],
            min_torque: 0.0,
            coulomb_col: None,
            cand: vec![],
            cluster,
        }
    }

    /// Add one base column with its name and its instrument, so that the three lists keep
    /// one order.
    pub(super) fn push_base(&mut self, name: Column, col: Vec<f64>, inst: Option<Vec<f64>>) {
        self.base_cols.push(col);
        self.base_names.push(name);
        self.base_inst.push(inst);
    }
}

/// A sample-level column on its way into the other equation's base, with its name and its
/// counterpart on the model's own run.
pub(super) struct SampleColumn {
    pub(super) col: Vec<f64>,
    pub(super) inst: Option<Vec<f64>>,
    pub(super) name: Column,
}

/// What the coefficient of one base column is: a parameter's name and unit, whether it is a
/// torque term (written in volts in a voltage plant's torque equation, so that its
/// coefficient times `K_t/R` is the parameter), and whether it is `free`: not a parameter of
/// the model as given (an equation's own approximation, an effect found in the other
/// equation), left free in the parameter check.
#[derive(Debug, Clone)]
pub(super) struct Column {
    pub(super) name: String,
    pub(super) unit: &'static str,
    pub(super) torque: bool,
    pub(super) free: bool,
}

impl Column {
    pub(super) fn new(name: impl Into<String>, unit: &'static str, torque: bool) -> Column {
        Column {
            name: name.into(),
            unit,
            torque,
            free: false,
        }
    }

    /// The same column, free in the parameter check.
    pub(super) fn free(mut self) -> Column {
        self.free = true;
        self
    }

    /// The names of an effect's present columns ([`candidates::present_columns`]), in order.
    pub(super) fn of_effect(e: &Effect<f64>, eq: Equation, k: usize, of: usize) -> Column {
        let kind = e.kind();
        let d = &crate::effects::of(kind).diagnose;
        let name = match d.column_names.get(k) {
            Some(name) => name.to_string(),
            None if of > 1 => format!("{} [{}]", kind.name(), k + 1),
            None => kind.name().to_string(),
        };
        if eq == Equation::Electrical {
            return Column::new(name, "V", false);
        }
        Column::new(name, d.torque_unit, true)
    }
}

/// Diagnose a log against a model structure: the log in weak form, the base and candidate
/// columns of both equations, forward selection in the voltage equation and then in the
/// torque equation ([`equations`]), and the verdict on the model as given ([`judge`]).
pub fn diagnose(log: &MotorLog, st: &Structure, opts: &Options) -> Diagnosis {
    // The log's weak forms, and beside them the same signals on the model's own noise-free
    // run: the parameter check's instruments.
    let (f, (own_run, run)) = rayon::join(
        || equations::weak_forms(log, st, opts),
        || {
            let own_run = simulated_log(log, st);
            let run = own_run.as_ref().map(|l| equations::weak_forms(l, st, opts));
            (own_run, run)
        },
    );
    let run = run.filter(|fs| fs.wf.rows() == f.wf.rows());
    let (acc, alpha_per_test) = passes(&f, run.as_ref(), st, opts);
    let equations::Outcome {
        mut findings,
        tested,
        equations,
        judged,
    } = acc;
    resolve_offsets(&mut findings, st.kt);
    findings.sort_by(|a, b| b.score.total_cmp(&a.score));
    findings.truncate(MAX_FINDINGS);
    let mut verdict = judge(&f, st, &judged, &findings, (opts, alpha_per_test));
    if let Some(own) = &own_run {
        weigh_refit_by_free_run(log, st, own, &mut verdict);
        verdict.adequate = adequate(&judged, &findings, &verdict.unexplained, &verdict.checks);
    }
    verdict.look_alikes =
        lookalikes::find(&findings, &tested, &verdict.unexplained, alpha_per_test);
    Diagnosis {
        effects: findings,
        tested,
        equations,
        alpha_per_test,
        min_explained: opts.min_explained,
        verdict,
    }
}

/// The weak forms' passes: the model's own residuals, the base and candidate columns of
/// both equations (with their instruments on the model's run `run`), and forward selection
/// in the voltage equation, then in the torque equation. Returns what they found and the
/// level of each entry test.
fn passes(
    f: &equations::Forms,
    run: Option<&equations::Forms>,
    st: &Structure,
    opts: &Options,
) -> (equations::Outcome, f64) {
    // The model's own equations with its own numbers, for the verdict.
    let run_current = run.and_then(|g| g.s.i.as_deref());
    let (mut given_mech, mut given_elec) = match st
        .motor
        .map(|m| verdict::given_residuals(&f.s, &f.wf, &f.wf_m, &st.effects, &m, run_current))
    {
        Some((m, e)) => (Some(m), e),
        None => (None, None),
    };
    // Less the same residual on the model's own noise-free run: what the discrete equations
    // leave of a perfect model's motion, which a correct model's data leave too.
    if let (Some(g), Some(m)) = (run, st.motor) {
        let (on_run, on_run_elec) =
            verdict::given_residuals(&g.s, &g.wf, &g.wf_m, &st.effects, &m, None);
        less_own_run(&mut given_mech, Some(on_run));
        less_own_run(&mut given_elec, on_run_elec);
    }
    let (mut elec, mut mech) = equations::base_equations(f, run, st);
    let mut pre = equations::PreslidingTest::default();
    let n_variants = equations::add_candidates(f, st, &mut elec, &mut mech, &mut pre);
    let alpha_per_test = opts.alpha / n_variants.max(1) as f64;
    let mut pass = equations::Pass {
        opts,
        alpha_per_test,
        units: Units {
            r: MotorParams::<f64>::paper().r,
            kt: st.kt,
            mech_scale: 1.0,
        },
        acc: equations::Outcome::default(),
    };
    let mut kb = 0.0;
    if f.voltage && !elec.y.is_empty() {
        kb = equations::electrical_pass(f, &elec, &mut mech, given_elec, &mut pass);
    }
    if !f.wf.centres.is_empty() {
        equations::mechanical_pass((f, run), st, mech, pre, (kb, given_mech), &mut pass);
    }
    (pass.acc, alpha_per_test)
}

/// `given` less the model's residual on its own run, row by row (unchanged when either is
/// missing or their lengths differ).
fn less_own_run(given: &mut Option<Vec<f64>>, on_run: Option<Vec<f64>>) {
    if let (Some(g), Some(r)) = (given.as_mut(), on_run) {
        if g.len() == r.len() {
            g.iter_mut().zip(&r).for_each(|(x, y)| *x -= y);
        }
    }
}

/// The model as given, run by the emulator on the log's input ([`extrapolated_run`];
/// voltage plant, motor constants and a measured current only): the log with its angle and current replaced by
/// the run's noise-free ones (the current as the model's sensor reads it). The parameter check takes its instruments from it
/// ([`verdict::parameter_check`]): columns computed from the measured angle carry the
/// angle's rounding error, which the model's residual carries too, and their correlation
/// is an errors-in-variables bias that a refit reads as wrong parameters (an inertia 20-40 %
/// low on slow multisines, where the rounding is a larger part of the acceleration). The
/// same columns on a run driven by the input alone do not share that error. A model without
/// bristles runs with a bristle stiffness that holds its static friction within a hundredth
/// of the Hall step (the run only has to follow the motion; `None` when the emulator refuses
/// the model).
fn simulated_log(log: &MotorLog, st: &Structure) -> Option<MotorLog> {
    let m = st.motor?;
    if st.plant != Plant::Voltage || log.i.is_none() || log.len() < 2 {
        return None;
    }
    let mut cfg = crate::emulator::EmulatorConfig::paper();
    cfg.motor = m;
    let mut law = control::lugre::LugreParams::friction_law(&st.effects);
    if law.sigma0.is_nan() || law.sigma0 <= 0.0 {
        let step = log
            .meta_f64("hall_resolution_rad")
            .filter(|h| *h > 0.0)
            .unwrap_or(cfg.hall_resolution());
        law.sigma0 = 100.0 * (law.alpha0 + law.alpha1).max(1e-6) / step;
        // Critically damped bristles on the rotor's inertia.
        law.sigma1 = 2.0 * (law.sigma0 * m.j.max(1e-12)).sqrt();
    }
    cfg.lugre = law;
    let kinds = control::lugre::LugreParams::<f64>::LAW_KINDS;
    cfg.effects = st
        .effects
        .iter()
        .filter(|e| !kinds.contains(&e.kind()) && e.kind() != EffectKind::Presliding)
        .copied()
        .collect();
    cfg.current_noise = 0.0;
    let (theta, i) = extrapolated_run(&cfg, &log.u, log.sample_period())?;
    if theta.len() != log.len() || i.len() != log.len() {
        return None;
    }
    // The log holds the current as the model's sensor reads it: its offset included.
    let i0 = control::effects::total_sensor_offset(&cfg.effects);
    let mut out = log.clone();
    out.theta = theta;
    out.i = Some(i.into_iter().map(|c| c + i0).collect());
    Some(out)
}

/// Largest internal step [s] of the model's own run ([`extrapolated_run`]).
const RUN_STEP: f64 = 2e-3;

/// The true angle and current at the samples of the emulator's run of `cfg` under `u`
/// (held for `ts` each), extrapolated to a zero internal step: the run at the largest step
/// that divides `ts` and is at most [`RUN_STEP`], and at half that step, side by side on
/// two threads, combined as twice the half-step run less the full-step one (Richardson).
/// The plant's implicit scheme is first order in its step, so the combination cancels the
/// leading error of both runs and follows the motion more closely than either, at a small
/// part of the cost of one run at the emulator's default step; the full-step run alone when
/// the emulator refuses the half step. `None` when it refuses both or the run diverges.
fn extrapolated_run(
    cfg: &crate::emulator::EmulatorConfig,
    u: &[f64],
    ts: f64,
) -> Option<(Vec<f64>, Vec<f64>)> {
    let steps = (ts / RUN_STEP - 1e-9).ceil().max(1.0);
    let run_at = |fine_step: f64| {
        let mut c = cfg.clone();
        c.fine_step = fine_step;
        crate::emulator::simulate(&c, u, ts).ok().map(|r| r.truth)
    };
    let (half, full) = rayon::join(|| run_at(0.5 * ts / steps), || run_at(ts / steps));
    // A period so short that the half step is below the emulator's smallest: the full-step
    // run alone, whose step is then a small part of a period anyway.
    let (mut half, full) = match (half, full) {
        (Some(h), Some(f)) => (h, f),
        (None, Some(f)) => return Some((f.theta, f.i)),
        _ => return None,
    };
    let extrapolate = |x: &mut Vec<f64>, y: &[f64]| {
        x.iter_mut().zip(y).for_each(|(a, b)| *a = 2.0 * *a - b);
    };
    extrapolate(&mut half.theta, &full.theta);
    extrapolate(&mut half.i, &full.i);
    Some((half.theta, half.i))
}

/// The log's signals; with `steady_angle`, the angle the torque equation integrates is read
/// as the centre line its readings allow wherever the rotor turns at a steady speed for at
/// least one weak-form window ([`crate::numerics::quantisation`]), so that a correct model's
/// torque residual no longer repeats the slow beat of the angle's rounding against the
/// sampling. The voltage equation takes the readings as they are.
fn signals_of(log: &MotorLog, st: &Structure, half: usize, steady_angle: bool) -> Signals {
    let mut s = Signals::from_log(log, st.plant, st.kt);
    if !steady_angle {
        return s;
    }
    (s.theta_torque, s.theta_torque_var) = crate::numerics::quantisation::dequantise_with_variance(
        &log.theta,
        s.angle_step(),
        2 * half + 1,
    );
    s
}

/// The weak form of a sample-level torque column: the velocity estimate itself (viscous
/// friction) as the weak derivative of the angle, which is exact (its increments are the
/// velocity's integrals over each interval; the smoothed estimate lags steps); any other
/// column by the trapezoid over each interval.
fn weak_torque(wf: &weak_form::WeakForm, s: &Signals, col: &[f64]) -> Vec<f64> {
    if col == s.omega.as_slice() {
        wf.derivative(&s.theta_torque)
    } else {
        wf.integral(col)
    }
}

/// The model's viscous friction [N·m·s/rad] (0 when it has none).
fn viscous_of(effects: &[Effect<f64>]) -> f64 {
    effects
        .iter()
        .map(|e| match e {
            Effect::Viscous { b } if b.is_finite() => *b,
            _ => 0.0,
        })
        .sum()
}

/// Fewest weak-form windows an equation needs for the verdict's tests: 64 (32 disjoint
/// windows, enough for the whiteness regression on 4 lags and for the carriers' 8 knots).
pub const MIN_VERDICT_ROWS: usize = 64;

/// Weight of each row of a residual whose variance differs from row to row: `1/σ_r`, with
/// `σ_r² = α·v_r + β` fitted to the squared residual by least squares (α, β ≥ 0), `v_r` the
/// variance the angle's quantisation puts into row `r`; scaled to a mean square of 1. Windows
/// through a transient, where the angle keeps its readings' error, then weigh no more than
/// their noise deserves against windows at a steady speed, and a term that lives in the
/// transients (a braking drive, a coupling) is not taken in by their larger scatter. Both
/// variance parts come from the residual itself, so noise of another origin (the current,
/// the model's own approximations) sets the floor β.
fn row_scale(resid: &[f64], v: &[f64]) -> Vec<f64> {
    let n = resid.len().min(v.len());
    if n < 3 {
        return vec![1.0; resid.len()];
    }
    let r2: Vec<f64> = resid[..n].iter().map(|r| r * r).collect();
    let ones = vec![1.0; n];
    let fit = least_squares::lstsq(&[&v[..n], &ones], &r2);
    let mean_r2 = r2.iter().sum::<f64>() / n as f64;
    let mean_v = v[..n].iter().sum::<f64>() / n as f64;
    let (mut alpha, mut beta) = (
        fit.beta.first().copied().unwrap_or(0.0),
        fit.beta.get(1).copied().unwrap_or(mean_r2),
    );
    if !(alpha >= 0.0 && beta >= 0.0) {
        // One part alone: the one whose fit by its own mean is better.
        if alpha < 0.0 || !alpha.is_finite() || mean_v <= 0.0 {
            (alpha, beta) = (0.0, mean_r2);
        } else {
            (alpha, beta) = (mean_r2 / mean_v, 0.0);
        }
    }
    let w: Vec<f64> = v[..n]
        .iter()
        .map(|vr| {
            let var = alpha * vr + beta;
            if var > 0.0 && var.is_finite() {
                1.0 / var.sqrt()
            } else {
                1.0
            }
        })
        .collect();
    let norm = (w.iter().map(|x| x * x).sum::<f64>() / n as f64).sqrt();
    if norm > 0.0 && norm.is_finite() {
        w.iter().map(|x| x / norm).collect()
    } else {
        vec![1.0; n]
    }
}

/// One equation's residuals for the verdict.
struct Judged {
    eq: Equation,
    /// Weight of each kept row ([`row_scale`]); the residuals are already weighted.
    scale: Option<Vec<f64>>,
    /// Which windows the equation kept.
    keep: Vec<bool>,
    /// The model's residual with its own numbers (kept rows), when it has motor constants.
    given: Option<Vec<f64>>,
    /// The refit of the model's structure (kept rows).
    base: Vec<f64>,
    /// After the findings.
    after: Vec<f64>,
    /// The refit's coefficients.
    beta: Vec<f64>,
    /// The refit's columns (kept rows, weighted as the residuals).
    cols: Vec<Vec<f64>>,
    /// What each column's coefficient is.
    names: Vec<Column>,
    /// Each column computed on the model's own noise-free run ([`simulated_log`]), where
    /// there was one (kept rows, weighted): the parameter check's instruments.
    instruments: Vec<Option<Vec<f64>>>,
    /// The input at each kept window's centre.
    input: Vec<f64>,
    /// Effects left significant but below the share a finding must explain
    /// ([`forward_select::Small`]).
    small: Vec<forward_select::Small>,
}

/// Factors by which [`bristle_moves`] scales the model's bristles: 2^(m/2), m = −16..=16.
fn bristle_factors() -> impl Iterator<Item = f64> {
    (-16..=16).map(|m| 2f64.powf(0.5 * f64::from(m)))
}

/// For the torque equation `j` (its columns on its kept rows, weighted as its residual):
/// the model's bristles (σ0, σ1) scaled together by each factor c of
/// [`bristle_factors`], and the coefficient on the presliding column of the change this
/// makes to the model's residual (its friction, from the LuGre observer along the measured
/// speed as in [`verdict::model_torque`], in the equation's units, regressed on all the
/// columns). Scaling both keeps σ1/σ0, the time constant the column is built with. Empty
/// when the model has no bristles or no presliding column.
fn bristle_moves(f: &equations::Forms, st: &Structure, j: &Judged) -> Vec<(f64, f64)> {
    let (keep, scale) = (&j.keep, j.scale.as_deref());
    let Some(k) = j
        .names
        .iter()
        .position(|c| c.name == EffectKind::Presliding.name())
    else {
        return vec![];
    };
    let Some(m) = st.motor else {
        return vec![];
    };
    let law = control::lugre::LugreParams::friction_law(&st.effects);
    if !(law.is_valid() && law.sigma1 > 0.0) {
        return vec![];
    }
    let ratio = if f.voltage && m.kt != 0.0 {
        m.r / m.kt
    } else {
        1.0
    };
    let s = &f.s;
    let friction = |p: control::lugre::LugreParams<f64>| -> Vec<f64> {
        let mut o = control::lugre::LugreObserver::new(p);
        s.omega.iter().map(|w| o.step(*w, s.dt)).collect()
    };
    let own = friction(law);
    let cols: Vec<&[f64]> = j.cols.iter().map(|c| c.as_slice()).collect();
    bristle_factors()
        .filter_map(|c| {
            let p = control::lugre::LugreParams {
                sigma0: c * law.sigma0,
                sigma1: c * law.sigma1,
                ..law
            };
            let d: Vec<f64> = friction(p).iter().zip(&own).map(|(a, b)| a - b).collect();
            let mut y = select_rows(&f.wf_m.integral(&d), keep);
            for (r, v) in y.iter_mut().enumerate() {
                *v *= ratio * scale.and_then(|w| w.get(r)).copied().unwrap_or(1.0);
            }
            let b = least_squares::lstsq(&cols, &y).beta.get(k).copied()?;
            b.is_finite().then_some((c, b))
        })
        .collect()
}

/// The verdict on the model as given ([`verdict`], [`carriers`]).
fn judge(
    f: &equations::Forms,
    st: &Structure,
    judged: &[Judged],
    findings: &[Finding],
    (opts, findings_level): (&Options, f64),
) -> Verdict {
    let (s, wf) = (&f.s, &f.wf);
    let per_eq = 3 + carriers::test_count();
    let level = verdict::ADEQUACY_ALPHA;
    let level_per_test = level / (per_eq * judged.len()).max(1) as f64;
    let mut checks = Vec::new();
    let mut unexplained: Vec<carriers::Carrier> = Vec::new();
    let mut refit = Vec::new();
    let all_clusters = verdict::hold_clusters(&s.raw_u, &wf.centres);
    for j in judged {
        // Too few windows to test anything: the verdict cannot be "adequate".
        if j.base.len() < MIN_VERDICT_ROWS {
            checks.push(too_few_windows(j));
            continue;
        }
        let cluster: Vec<usize> = all_clusters
            .iter()
            .zip(&j.keep)
            .filter(|(_, k)| **k)
            .map(|(c, _)| *c)
            .collect();
        if let Some(given) = &j.given {
            let mut c = parameter_check(j, given, &cluster, level_per_test);
            if !c.passed && c.p_value.is_finite() {
                let times: Vec<f64> = select_rows(
                    &wf.centres.iter().map(|&k| s.t[k]).collect::<Vec<f64>>(),
                    &j.keep,
                );
                c.drift = parameter_drift(j, given, &times, &cluster, level_per_test);
                if let Some(d) = &c.drift {
                    c.detail = format!("{}; {}", c.detail, d.words());
                }
            }
            if !c.passed {
                let r = electrical_constant(judged, "R");
                let kb = electrical_constant(judged, "K_b");
                refit.extend(refitted_constants(
                    (f, j),
                    st,
                    given,
                    &cluster,
                    (r, kb, level_per_test),
                ));
            }
            checks.push(c);
        }
        checks.extend(verdict::small_effects_check(
            j.eq.label(),
            &j.small,
            opts.min_explained,
            findings_level,
        ));
        checks.extend(residual_checks(j, &cluster, level_per_test));
        let rows = carriers::Rows {
            wf,
            keep: &j.keep,
            resid: &j.after,
            scale: j.scale.as_deref(),
            label: j.eq.label(),
            cluster: &cluster,
        };
        let carried = carriers::carriers(s, &rows, level_per_test, opts.min_explained);
        checks.extend(untested_carriers(j, &carried.untested));
        merge_carriers(&mut unexplained, carried.carriers);
    }
    unexplained.sort_by(|a, b| b.share.total_cmp(&a.share));
    // A check whose test cannot reject on this log (p-value NaN) leaves the verdict unjudged.
    let testable = !judged.is_empty()
        && checks
            .iter()
            .all(|c| c.name != "data" && !c.p_value.is_nan());
    Verdict {
        adequate: adequate(judged, findings, &unexplained, &checks),
        judged: testable,
        level,
        level_per_test,
        checks,
        unexplained,
        refit,
        look_alikes: Vec::new(),
    }
}

/// The failed "data" check of an equation with too few windows to test its residual.
fn too_few_windows(j: &Judged) -> verdict::Check {
    verdict::Check {
        name: "data",
        statistic: j.base.len() as f64,
        p_value: f64::NAN,
        share: 0.0,
        passed: false,
        note: None,
        drift: None,
        detail: format!(
            "{}: only {} usable windows (at least {MIN_VERDICT_ROWS} are needed to test the residual); record a longer log with more motion",
            j.eq.label(),
            j.base.len()
        ),
    }
}

/// The parameter check's columns: the tested ones (the model's parameters) with the index
/// of each, and the free ones ([`Column::free`]); each is its instrument when it has one
/// of the same length, the measured column otherwise.
fn tested_columns(j: &Judged) -> (Vec<usize>, Vec<Vec<f64>>, Vec<Vec<f64>>) {
    let col = |k: usize| -> Vec<f64> {
        j.instruments
            .get(k)
            .and_then(|z| z.as_ref())
            .filter(|z| z.len() == j.cols[k].len() && z.iter().all(|v| v.is_finite()))
            .unwrap_or(&j.cols[k])
            .clone()
    };
    let free = |k: usize| j.names.get(k).is_some_and(|c| c.free);
    let idx: Vec<usize> = (0..j.cols.len()).filter(|&k| !free(k)).collect();
    let tested = idx.iter().map(|&k| col(k)).collect();
    let nuisance = (0..j.cols.len()).filter(|&k| free(k)).map(col).collect();
    (idx, tested, nuisance)
}

/// Are the model's own parameters as good as a refit of its structure? `given` is the
/// residual with the model's numbers.
fn parameter_check(
    j: &Judged,
    given: &[f64],
    cluster: &[usize],
    level_per_test: f64,
) -> verdict::Check {
    let (_, tested, nuisance) = tested_columns(j);
    let mut c = verdict::parameter_check(
        given,
        &j.base,
        (&tested, &nuisance),
        cluster,
        level_per_test,
    );
    c.detail = format!("{}: {}", j.eq.label(), c.detail);
    c
}

/// Do the parameters of one equation's check drift along the log? The test of
/// [`verdict::parameter_drift`] on the check's residual and instruments, where it rejects at
/// `level` (`times`: each kept row's time). Asked only once the check's Wald test has
/// rejected, so that a check failed by a drift is never more likely than one failed by that
/// test alone.
fn parameter_drift(
    j: &Judged,
    given: &[f64],
    times: &[f64],
    cluster: &[usize],
    level: f64,
) -> Option<verdict::Drift> {
    let (_, tested, nuisance) = tested_columns(j);
    let (t, share) = verdict::parameter_drift(given, &j.base, (&tested, &nuisance), times, cluster);
    let t = t.filter(|t| t.p_value < level)?;
    Some(verdict::Drift {
        statistic: t.t2,
        p_value: t.p_value,
        share,
    })
}

/// Adequate: an equation was judged, nothing is missing or carried, and every check passed.
fn adequate(
    judged: &[Judged],
    findings: &[Finding],
    unexplained: &[carriers::Carrier],
    checks: &[verdict::Check],
) -> bool {
    !judged.is_empty()
        && findings.is_empty()
        && unexplained.is_empty()
        && checks.iter().all(|c| c.passed)
}

/// The value of the voltage equation's refitted constant `name` (`R` [Ω], `K_b` [V·s/rad]),
/// when that equation was judged. The refitted model ([`refitted_structure`]) takes K_b as
/// its torque constant too, so torque-side values are read with both.
fn electrical_constant(judged: &[Judged], name: &str) -> Option<f64> {
    let e = judged.iter().find(|e| e.eq == Equation::Electrical)?;
    let k = e.names.iter().position(|c| c.name == name)?;
    e.beta.get(k).copied()
}

/// The whiteness and input checks of one equation's residual after the findings; `cluster`
/// is the hold cluster of each kept window.
fn residual_checks(j: &Judged, cluster: &[usize], level_per_test: f64) -> [verdict::Check; 2] {
    let mut w = verdict::whiteness_check(&j.after, cluster, level_per_test);
    w.detail = format!("{}: {}", j.eq.label(), w.detail);
    let mut x = verdict::input_check(&j.after, &j.input, cluster, level_per_test);
    x.detail = format!("{}: {}", j.eq.label(), x.detail);
    [w, x]
}

/// The failed "carriers" check naming the variables whose test cannot decide, if any.
fn untested_carriers(j: &Judged, untested: &[&str]) -> Option<verdict::Check> {
    if untested.is_empty() {
        return None;
    }
    Some(verdict::Check {
        name: "carriers",
        statistic: f64::NAN,
        p_value: f64::NAN,
        share: 0.0,
        passed: false,
        note: None,
        drift: None,
        detail: format!(
            "{}: cannot judge what {} carry: too few windows or held inputs for the test to reject anything",
            j.eq.label(),
            untested.join(", ")
        ),
    })
}

/// Add one equation's carriers to those of the equations before: one per variable, the one
/// with the larger share.
fn merge_carriers(unexplained: &mut Vec<carriers::Carrier>, found: Vec<carriers::Carrier>) {
    for c in found {
        match unexplained.iter_mut().find(|u| u.variable == c.variable) {
            Some(u) if u.share >= c.share => {}
            Some(u) => *u = c,
            None => unexplained.push(c),
        }
    }
}

/// The refitted value of every parameter that moved significantly (name, value, unit), from
/// one equation's base coefficients ([`verdict::moved_columns`] at the check's level); all
/// of them when none moved alone (the error is shared among correlated parameters).
fn refitted_constants(
    (f, j): (&equations::Forms, &Judged),
    st: &Structure,
    given: &[f64],
    cluster: &[usize],
    (r_refit, kb_refit, level): (Option<f64>, Option<f64>, f64),
) -> Vec<(String, f64, String)> {
    let (_, tested, nuisance) = tested_columns(j);
    let mut moved = verdict::moved_columns(given, &j.base, (&tested, &nuisance), cluster, level);
    // The parameters moved together, none alone: the whole refit.
    if !moved.contains(&true) {
        moved.iter_mut().for_each(|m| *m = true);
    }
    refit_values((f, j), st, given, r_refit, kb_refit)
        .into_iter()
        .filter(|(t, _)| moved.get(*t).copied().unwrap_or(false))
        .map(|(_, v)| v)
        .collect()
}

/// The refitted value (name, value, unit) of each tested parameter of one equation whose
/// column is not all zero, with its position among the tested columns. A torque term of a
/// voltage plant's torque equation, written in volts, is its coefficient times `K_t/R`,
/// with R and K_t = K_b the refitted ones when the voltage equation gave them (the refitted
/// model runs with them). The presliding column's coefficient becomes the bristle
/// parameters whose friction moves it as far as the refit did ([`bristles_of_refit`]),
/// where some do; `given` is the model's residual with its own numbers.
fn refit_values(
    (f, j): (&equations::Forms, &Judged),
    st: &Structure,
    given: &[f64],
    r_refit: Option<f64>,
    kb_refit: Option<f64>,
) -> Vec<(usize, (String, f64, String))> {
    let m = st.motor.unwrap_or(MotorParams::paper());
    let (idx, _, _) = tested_columns(j);
    let r = r_refit.filter(|r| *r > 0.0).unwrap_or(m.r);
    let kt = kb_refit
        .filter(|k| *k > 0.0 && r_refit.is_some())
        .unwrap_or(m.kt);
    let voltage = st.plant == Plant::Voltage;
    let scale = if voltage && r > 0.0 { kt / r } else { 1.0 };
    // How far the refit moved each coefficient: that of the model's residual on the same
    // columns.
    let delta = {
        let cols: Vec<&[f64]> = j.cols.iter().map(|c| c.as_slice()).collect();
        least_squares::lstsq(&cols, given).beta
    };
    let mut out = Vec::new();
    for (t, &k) in idx.iter().enumerate() {
        if !j.cols[k].iter().any(|v| *v != 0.0) {
            continue;
        }
        let (Some(b), Some(col)) = (j.beta.get(k), j.names.get(k)) else {
            continue;
        };
        let (value, unit) = match (col.torque, voltage) {
            (true, true) => (b * scale, col.unit.to_string()),
            (true, false) => (*b, format!("u per ({})", col.unit)),
            (false, _) => (*b, col.unit.to_string()),
        };
        let bristles = (col.name == EffectKind::Presliding.name())
            .then(|| delta.get(k).copied())
            .flatten()
            .and_then(|d| bristles_of_refit(st, &bristle_moves(f, st, j), d));
        match bristles {
            Some((sigma0, sigma1)) => {
                out.push((t, (SIGMA0.to_string(), sigma0, "N·m/rad".to_string())));
                out.push((t, (SIGMA1.to_string(), sigma1, "N·m·s/rad".to_string())));
            }
            None => out.push((t, (col.name.clone(), value, unit))),
        }
    }
    out
}

/// Names of the refitted bristle parameters ([`bristles_of_refit`]).
const SIGMA0: &str = "sigma0 (presliding)";
const SIGMA1: &str = "sigma1 (presliding)";

/// The bristle stiffness and damping (σ0, σ1) the refit's move `delta` of the presliding
/// column's coefficient stands for: the model's own scaled by the factor c whose change to
/// the model's residual has that coefficient ([`bristle_moves`], interpolated in log c
/// between the two factors around it, the crossing nearest c = 1). `None` when the model
/// has no bristles or no factor within 2^±8 reaches `delta`: no bristles of this kind give
/// the refit, which then cannot be run.
fn bristles_of_refit(st: &Structure, moves: &[(f64, f64)], delta: f64) -> Option<(f64, f64)> {
    let (sigma0, sigma1) = st.effects.iter().find_map(|e| match *e {
        Effect::Presliding { sigma0, sigma1 } => Some((sigma0, sigma1)),
        _ => None,
    })?;
    if !(delta.is_finite() && sigma0 > 0.0 && sigma1 > 0.0) {
        return None;
    }
    let mid = moves.iter().position(|(c, _)| *c == 1.0)?;
    // Outward from c = 1 on either side; the crossing at the smaller distance.
    let crossing = |pair: (&(f64, f64), &(f64, f64))| {
        let ((c0, b0), (c1, b1)) = (*pair.0, *pair.1);
        ((b0 - delta) * (b1 - delta) <= 0.0 && b0 != b1).then(|| {
            let w = (delta - b0) / (b1 - b0);
            (c0.ln() + w * (c1.ln() - c0.ln())).exp()
        })
    };
    let up = moves[mid..]
        .iter()
        .zip(&moves[mid + 1..])
        .position(|p| crossing(p).is_some());
    let down = moves[..=mid]
        .iter()
        .rev()
        .zip(moves[..mid].iter().rev())
        .position(|p| crossing(p).is_some());
    let c = match (up, down) {
        (Some(u), Some(d)) if d < u => crossing((&moves[mid - d], &moves[mid - d - 1])),
        (Some(u), _) => crossing((&moves[mid + u], &moves[mid + u + 1])),
        (None, Some(d)) => crossing((&moves[mid - d], &moves[mid - d - 1])),
        (None, None) => None,
    }?;
    (c.is_finite() && c > 0.0).then_some((c * sigma0, c * sigma1))
}

/// The model with the refit's values `refit` (name, value) of its motor constants, its
/// static friction law and its bristles ([`bristles_of_refit`]), every other parameter as
/// given, and the names of the refitted parameters it leaves as given: those whose refitted
/// value is out of the range a run takes (not positive for the motor constants and the
/// bristles, negative for the friction), a column standing in for something else rather
/// than a value the model could have. Returns `None` when a refitted parameter is one the
/// run does not take at all, or not finite, or every one is out of range: a run could then
/// not show what the refit changes.
fn refitted_structure(
    st: &Structure,
    refit: &[(String, f64, String)],
) -> Option<(Structure, Vec<String>)> {
    let mut out = st.clone();
    let mut m = st.motor?;
    let mut as_given = Vec::new();
    for (name, v, _) in refit {
        let v = *v;
        if !v.is_finite() {
            return None;
        }
        let positive = v > 0.0;
        let motor = matches!(name.as_str(), "R" | "J" | "L" | "K_b");
        if motor {
            if positive {
                match name.as_str() {
                    "R" => m.r = v,
                    "J" => m.j = v,
                    "L" => m.l = v,
                    _ => (m.kb, m.kt) = (v, v),
                }
            } else {
                as_given.push(name.clone());
            }
            continue;
        }
        let mut known = false;
        for e in out.effects.iter_mut() {
            let (x, in_range) = match (e, name.as_str()) {
                (Effect::Coulomb { fc }, "fc (Coulomb)") => (fc, v >= 0.0),
                (Effect::Viscous { b }, "b (viscous)") => (b, v >= 0.0),
                (Effect::Stribeck { fs, .. }, "fs − fc (Stribeck)") => (fs, v >= 0.0),
                (Effect::Presliding { sigma0, .. }, SIGMA0) => (sigma0, positive),
                (Effect::Presliding { sigma1, .. }, SIGMA1) => (sigma1, positive),
                _ => continue,
            };
            known = true;
            if in_range {
                *x = v;
            } else {
                as_given.push(name.clone());
            }
        }
        if !known {
            return None;
        }
    }
    // Every refitted value out of range: the run would be the model's own.
    if as_given.len() == refit.len() {
        return None;
    }
    out.kt = m.kt;
    out.motor = Some(m);
    Some((out, as_given))
}

/// A failed parameter check stands only when the refitted values of the parameters that
/// moved also run closer to the log than the model's own: the free run of the refitted model
/// ([`refitted_structure`]) against the model's own run `own`, on the log's input, compared
/// by [`verdict::free_run_gain`] at the family level [`verdict::ADEQUACY_ALPHA`].
/// Otherwise the check passes with the comparison in its detail: the refit reads the
/// equations better, not the motion (a model fitted on its free run sits a little off the
/// equations' optimum, and a physics its structure lacks can pull the refit anywhere).
fn weigh_refit_by_free_run(log: &MotorLog, st: &Structure, own: &MotorLog, verdict: &mut Verdict) {
    // A non-finite residual (statistic infinite) fails whatever a run shows.
    let failed = |c: &verdict::Check| {
        c.name == "parameters" && !c.passed && c.p_value.is_finite() && c.statistic.is_finite()
    };
    if !verdict.checks.iter().any(failed) {
        return;
    }
    // A refit the model cannot run keeps the Wald test's result: no run could show it.
    let Some((refitted, as_given)) = refitted_structure(st, &verdict.refit) else {
        for c in verdict.checks.iter_mut().filter(|c| failed(c)) {
            c.detail = format!(
                "{}; the refit moves a parameter a free run of this model cannot take, so the test's result stands",
                c.detail
            );
        }
        return;
    };
    let Some(other) = simulated_log(log, &refitted) else {
        return;
    };
    let Some(gain) = verdict::free_run_gain(log, own, &other) else {
        return;
    };
    // The gate's own level is the family's: rejecting both tests is never more likely than
    // rejecting the Wald test alone, so the check keeps its level whatever the gate's.
    let level = verdict.level;
    let better = gain.p_value < level;
    let kept = if as_given.is_empty() {
        String::new()
    } else {
        format!(
            " (with the model's own {}: the refit's value is out of its range)",
            as_given.join(", ")
        )
    };
    let words = format!(
        "the refit's free run{kept} is {} the log's angle and current by {:.1}% of the model's own squared error (one-sided p = {:.1e} on {} blocks, level {:.1e})",
        if gain.gain >= 0.0 { "closer to" } else { "further from" },
        100.0 * gain.gain.abs(),
        gain.p_value,
        gain.blocks,
        level
    );
    for c in verdict.checks.iter_mut().filter(|c| failed(c)) {
        if better {
            c.detail = format!("{}; {words}", c.detail);
        } else if let Some(d) = &c.drift {
            c.detail = format!(
                "{}: the refit reads the equations better, but {words}, so a refit is no cure; {}",
                c.detail.split(':').next().unwrap_or(""),
                d.words()
            );
        } else {
            c.passed = true;
            c.detail = format!(
                "{}: the refit reads the equations better, but {words}, so the model's own parameters stand",
                c.detail.split(':').next().unwrap_or("")
            );
        }
    }
    if !better {
        verdict.refit.clear();
    }
}

/// Presliding candidates: only on top of a static friction law (a model without Coulomb or
/// Stribeck friction has no breakaway for bristles to soften). The law is the model's: its
/// Coulomb friction (refitted when it states none), Stribeck and viscous friction; σ1 follows
/// from the refitted inertia ([`presliding::variants`]).
fn presliding_candidates(s: &Signals, st: &Structure) -> (Vec<Vec<f64>>, Vec<Variant>) {
    if !(st.has(EffectKind::Coulomb) || st.has(EffectKind::Stribeck)) {
        return (vec![], vec![]);
    }
    // Inertia and Coulomb friction refitted on the moving samples.
    let acc =
        crate::numerics::differentiation::smoothed_derivative(&s.omega, s.dt, s.velocity_half);
    let moving: Vec<usize> = (0..s.len())
        .filter(|&k| s.omega[k].abs() >= s.stick_speed())
        .collect();
    let eps = s.velocity_eps();
    let cols: Vec<Vec<f64>> = vec![
        moving.iter().map(|&k| acc[k]).collect(),
        moving
            .iter()
            .map(|&k| control::effects::smooth_sign(s.omega[k], eps))
            .collect(),
        moving.iter().map(|&k| s.omega[k]).collect(),
    ];
    let y: Vec<f64> = moving.iter().map(|&k| s.drive[k]).collect();
    let refs: Vec<&[f64]> = cols.iter().map(|c| c.as_slice()).collect();
    let fit = least_squares::lstsq(&refs, &y);
    let (j, fc_fit) = (
        fit.beta.first().copied().unwrap_or(0.0),
        fit.beta.get(1).copied().unwrap_or(0.0),
    );
    // The model's static law (σ0, σ1 are set per variant). A Stribeck term without a
    // positive velocity has no curve.
    let mut law = control::lugre::LugreParams::friction_law(&st.effects);
    if law.v0 <= 0.0 || law.v0.is_nan() {
        (law.alpha1, law.v0) = (0.0, 1.0);
    }
    if law.alpha0 <= 0.0 {
        law.alpha0 = fc_fit.max(0.0);
    }
    let nuisance = presliding::variants(s, &law, j, &[presliding::NUISANCE_STEPS])
        .into_iter()
        .flat_map(|v| v.columns)
        .collect();
    (
        nuisance,
        presliding::variants(s, &law, j, &presliding::DEFLECTION_GRID),
    )
}

/// The presliding test's data: the mechanical equation on every window, reversals and
/// standstills included (presliding lives in the windows the other candidates leave out;
/// the stick column of the base stands for the friction while stuck). Its base: the model's
/// structure, a bristle term of half an angle step (the nuisance: where a Hall sensor puts the
/// friction's sign change at a reversal is uncertain by about that much, and a term that
/// short explains that error on data without any soft bristles) and the mechanical findings.
fn presliding_pass(
    mech: &EqData,
    found: &[Finding],
    (y, mut base_cols): (Vec<f64>, Vec<Vec<f64>>),
    cand: Vec<(Variant, Vec<Vec<f64>>)>,
    wf: &weak_form::WeakForm,
    s: &Signals,
) -> EqData {
    for f in found {
        let same = |v: &Variant| {
            Some(v.kind) == f.kind
                && EffectSpec::parse(&f.spec)
                    .is_ok_and(|sp| v.fixed.iter().all(|(k, x)| (sp.get(k) - x).abs() < 1e-9))
        };
        if let Some((v, _)) = mech.cand.iter().find(|(v, _)| same(v)) {
            base_cols.extend(v.columns.iter().map(|c| weak_torque(wf, s, c)));
        }
    }
    let mut data = EqData::new(
        Equation::Mechanical,
        y,
        verdict::hold_clusters(&s.raw_u, &wf.centres),
    );
    data.base_cols = base_cols;
    data.min_torque = mech.min_torque;
    data.coulomb_col = mech.coulomb_col;
    data.cand = cand;
    data
}

/// The drive torque the model's own mechanical structure predicts from the motion, sample
/// by sample: a least-squares fit of the measured drive on inertia (smoothed acceleration)
/// and the structure's friction columns, evaluated while moving.
fn modelled_drive(s: &Signals, st: &Structure) -> Vec<f64> {
    let acc =
        crate::numerics::differentiation::smoothed_derivative(&s.omega, s.dt, s.velocity_half);
    let mut cols = vec![acc];
    for e in &st.effects {
        if e.kind() == EffectKind::LoadFriction {
            continue;
        }
        for (eq, col) in candidates::present_columns(e, s) {
            if eq == Equation::Mechanical {
                cols.push(col);
            }
        }
    }
    if !st.has(EffectKind::Coulomb) {
        cols.push(
            s.omega
                .iter()
                .map(|w| control::effects::smooth_sign(*w, s.velocity_eps()))
                .collect(),
        );
    }
    if !st.has(EffectKind::Viscous) {
        cols.push(s.omega.clone());
    }
    let moving: Vec<usize> = (0..s.len())
        .filter(|&k| s.omega[k].abs() >= s.stick_speed())
        .collect();
    let y: Vec<f64> = moving.iter().map(|&k| s.drive[k]).collect();
    let sub: Vec<Vec<f64>> = cols
        .iter()
        .map(|c| moving.iter().map(|&k| c[k]).collect())
        .collect();
    let refs: Vec<&[f64]> = sub.iter().map(|c| c.as_slice()).collect();
    let fit = least_squares::lstsq(&refs, &y);
    (0..s.len())
        .map(|k| cols.iter().zip(&fit.beta).map(|(c, b)| b * c[k]).sum())
        .collect()
}

/// The rows of `v` where `keep` is true.
pub(crate) fn select_rows(v: &[f64], keep: &[bool]) -> Vec<f64> {
    v.iter()
        .zip(keep)
        .filter(|(_, k)| **k)
        .map(|(x, _)| *x)
        .collect()
}

/// Smallest torque of a second inertia on a coupling (`compliance`) worth reporting, as a
/// fraction of the model's Coulomb friction (or of the RMS drive torque when the model has
/// none): 10 %. Only that effect has it: its column, like the inertia's, is computed from the
/// measured angle, whose rounding the residual shares, and on slow multisines the entry test
/// reads that shared error as a small load (`docs/decisions/0024-significance-not-size.md`);
/// every other effect is reported when it is significant and explains its share. When the model has Coulomb friction
/// without a positive value, the one refitted in the base is used; when `diagnose` finds
/// Coulomb friction, the one found is used for the effects tested after it (a closed-loop
/// positioning axis spends its drive on inertia: its RMS drive can be several times its
/// friction, so that smaller effects would never count while Coulomb is unknown).
pub const MIN_TORQUE_FRACTION: f64 = 0.10;

fn min_torque(st: &Structure, s: &Signals) -> f64 {
    let fc = st.effects.iter().find_map(|e| match e {
        Effect::Coulomb { fc } if *fc > 0.0 => Some(*fc),
        _ => None,
    });
    MIN_TORQUE_FRACTION * fc.unwrap_or_else(|| statistics::rms(&s.drive))
}

/// Largest factor by which the fitted gain of a presliding column may differ from 1: 2. The
/// column is the torque the bristles of that stiffness add to the model's own static friction
/// law, so the right stiffness fits with a gain near 1. On emulated data with a breakaway
/// deflection of 2.6 Hall steps, the grid's stiffer bristles (1 step) fitted with gain 3.6
/// and explained the residual best: a sharper term than the bristles, standing in for the
/// error of the friction's sign at a reversal that a Hall sensor leaves.
pub const PRESLIDING_GAIN: f64 = 2.0;

/// Largest load-dependent friction coefficient taken as physical: 0.5, a drive that loses
/// half of its torque in friction (worm gears reach it; spur gears and ball screws lose
/// 2–10 %). A larger fitted value means the column is standing in for something else.
pub const MAX_LOAD_FRICTION: f64 = 0.5;

/// Physical plausibility of a finding's parameters, by its effect's descriptor
/// ([`crate::effects::Diagnose::plausible`]): dissipative terms must dissipate (Coulomb,
/// viscous, Stribeck, dead time, heating ≥ 0) and load-dependent friction must stay below
/// [`MAX_LOAD_FRICTION`]. An implausible best fit is not reported.
pub fn plausible(spec: &EffectSpec) -> bool {
    (crate::effects::of(spec.kind).diagnose.plausible)(spec)
}

/// A current-sensor offset `i0` also shows in the torque equation as a constant `K_t·i0`;
/// when both `current_offset` and `offset` are found and the latter is mostly that constant,
/// only the current offset is real.
fn resolve_offsets(findings: &mut Vec<Finding>, kt: f64) {
    let get = |name: &str| {
        findings
            .iter()
            .find(|f| f.name == name)
            .and_then(|f| EffectSpec::parse(&f.spec).ok())
    };
    if let (Some(co), Some(off)) = (get("current_offset"), get("offset")) {
        let implied = kt * co.get("i0");
        let t0 = off.get("t0");
        if t0 != 0.0 && (t0 - implied).abs() < 0.5 * t0.abs() {
            findings.retain(|f| f.name != "offset");
        }
    }
}

/// One sentence of physics for a finding: its effect's clause
/// ([`crate::effects::Diagnose::explain`]) and the share it explains.
pub fn explain(spec: &EffectSpec, score: f64, eq: Equation) -> String {
    let pct = 100.0 * score;
    let what = (crate::effects::of(spec.kind).diagnose.explain)(spec);
    format!(
        "{}{}; it explains {:.0}% of the {} residual.",
        what[..1].to_uppercase(),
        &what[1..],
        pct,
        eq.label()
    )
}

impl Structure {
    /// The paper motor's LuGre law (the emulator's own friction) with its K_t.
    pub fn lugre_paper(plant: Plant) -> Structure {
        Structure::with_effects(
            plant,
            control::lugre::LugreParams::<f64>::paper()
                .to_effects()
                .to_vec(),
        )
    }

    /// The structure of an identified model: its friction law as effects (linear: viscous;
    /// LuGre: Coulomb, Stribeck, viscous, presliding; SINDYc: Coulomb and viscous, the terms
    /// its library always offers) plus its added effects.
    pub fn from_model(m: &crate::model::Model) -> Structure {
        use crate::model::ModelKind;
        let mut effects = Vec::new();
        match (m.kind, &m.lugre) {
            (ModelKind::Lugre, Some(l)) => effects = l.to_effects().to_vec(),
            (ModelKind::Sindyc, _) => {
                effects.push(Effect::Coulomb { fc: 0.0 });
                effects.push(Effect::Viscous { b: 0.0 });
            }
            _ => effects.push(Effect::Viscous { b: m.viscous }),
        }
        for e in &m.effects {
            if !effects.iter().any(|x| x.kind() == e.kind()) {
                effects.push(*e);
            }
        }
        Structure {
            plant: m.plant,
            effects,
            kt: if m.motor.kt > 0.0 { m.motor.kt } else { 1.0 },
            motor: (m.kind != ModelKind::Sindyc).then_some(m.motor),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{equations, passes, row_scale, Options, Structure};
    use crate::emulator::{simulate_signal, EmulatorConfig, SignalKind};
    use crate::numerics::statistics::white_noise;
    use control::effects::{Effect, EffectKind};

    /// Each column of the parameter check meets its own instrument: with the log itself
    /// standing for the model's run, every instrument equals its column in both equations,
    /// also when the voltage equation finds an effect whose column joins the torque
    /// equation's base (free there, as it is not a parameter of the model as given).
    #[test]
    fn instruments_stay_in_the_order_of_their_columns() {
        let mut cfg = EmulatorConfig::paper();
        cfg.seed = 4;
        cfg.effects = vec![
            Effect::Deadtime { vd: 0.5 },
            Effect::Thermal {
                k: 0.004,
                tau: 20.0,
            },
        ];
        let log = simulate_signal(&cfg, SignalKind::A, 60.0).unwrap().log;
        let mut st = Structure::from_model(&cfg.truth_model());
        st.effects.retain(|e| e.kind() != EffectKind::Deadtime);
        let opts = Options::default();
        let f = equations::weak_forms(&log, &st, &opts);
        let (acc, _) = passes(&f, Some(&f), &st, &opts);
        assert!(
            acc.findings
                .iter()
                .any(|x| x.kind == Some(EffectKind::Deadtime)),
            "the voltage equation must find the dead time for this test to mean anything"
        );
        let mut free_in_torque = 0;
        for j in &acc.judged {
            assert_eq!(j.instruments.len(), j.cols.len());
            assert_eq!(j.names.len(), j.cols.len());
            for (k, (z, c)) in j.instruments.iter().zip(&j.cols).enumerate() {
                let name = &j.names[k].name;
                let z = z.as_ref().unwrap_or_else(|| {
                    assert!(j.names[k].free, "{name} has no instrument");
                    c
                });
                assert!(z == c, "{:?} {name}: instrument is not its column", j.eq);
                if j.eq == super::Equation::Mechanical && j.names[k].free {
                    free_in_torque += 1;
                }
            }
        }
        assert!(
            free_in_torque > 0,
            "no found column joined the torque equation"
        );
    }

    /// Rows whose noise is a known part plus a floor get weights that make them equally
    /// noisy; rows of one variance keep equal weights.
    #[test]
    fn row_scale_evens_out_a_known_variance() {
        let n = 4000;
        let v: Vec<f64> = (0..n).map(|k| if k % 4 == 0 { 9.0 } else { 0.0 }).collect();
        let z = white_noise(n, 11);
        let r: Vec<f64> = z
            .iter()
            .zip(&v)
            .map(|(z, v)| z * (v + 1.0f64).sqrt())
            .collect();
        let w = row_scale(&r, &v);
        let ms = |pick: usize| {
            let x: Vec<f64> = (0..n)
                .filter(|k| (k % 4 == 0) == (pick == 0))
                .map(|k| (r[k] * w[k]).powi(2))
                .collect();
            x.iter().sum::<f64>() / x.len() as f64
        };
        let ratio = ms(0) / ms(1);
        // Mean squares of 1000 and 3000 weighted normal rows: each has a relative standard
        // error of √(2/n), the ratio about 0.05; 0.8..1.25 is about four of them either side.
        assert!((0.8..1.25).contains(&ratio), "{ratio}");
        let flat = row_scale(&z, &vec![0.5; n]);
        // One variance: equal weights of 1, up to rounding.
        assert!(flat.iter().all(|x| (x - 1.0).abs() < 1e-9));
    }
}
