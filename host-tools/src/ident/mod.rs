//! Identification: fit a linear, LuGre or SINDYc model to motor logs, and score a model.
//!
//! | module | what it is |
//! |---|---|
//! | [`effect_residual`] | added effects estimated on a fitted model's residual |
//! | [`fitpct`] | the paper's fit percentage |
//! | [`freerun`] | free-run simulation of a model with a log's input |
//! | [`tangent`] | dual numbers: the free run's sensitivities to the parameters |
//! | [`sensor_chain`] | Hall quantisation and the firmware's velocity estimator |
//! | [`linear`] | the linear model (viscous friction), paper eqs. 1–2 |
//! | [`lugre_fit`] | LuGre static curve and dynamic parameters |
//! | [`nlsq`] | bounded nonlinear least squares (Levenberg–Marquardt with projection) |
//! | [`progress`] | progress of a running fit (stage, iteration, cost) for a progress bar |
//! | [`hankel`], [`stlsq`], [`library`], [`sindyc`] | SINDYc |
//!
//! Entry points: [`fit`] and [`score`]. Least squares, statistics, differentiation and the
//! weak form are in [`crate::numerics`].
pub mod effect_residual;
pub mod fitpct;
pub mod free_params;
pub mod freerun;
pub mod hankel;
pub mod library;
pub mod linear;
pub mod lugre_fit;
pub mod nlsq;
pub mod progress;
pub mod sensor_chain;
pub mod sim_error;
pub mod sindyc;
pub mod stlsq;
pub mod tangent;

use crate::effect_spec::EffectSpec;
use crate::log::{MotorLog, Plant};
use crate::model::{Model, ModelKind};
use anyhow::{bail, Result};
use control::effects::EffectKind;
pub use freerun::Prediction;
use serde::Serialize;
use std::collections::BTreeMap;

/// What to fit.
#[derive(Debug, Clone, Copy)]
pub struct FitRequest<'a> {
    pub kind: ModelKind,
    /// Logs to fit on (at least one).
    pub logs: &'a [MotorLog],
    /// Logs not fitted on: validation logs, or selection logs where the fit chooses among
    /// candidate models on them (the guard of added effects, SINDYc's thresholding).
    pub validate: &'a [MotorLog],
    /// Effects to add to the model's structure (`fit --add`).
    pub adds: &'a [EffectSpec],
    pub plant: Plant,
    /// Parameters the user knows (`fit --fix`, `--bound`); [`free_params::Constraints::NONE`]
    /// when none.
    pub constraints: &'a free_params::Constraints,
}

/// The result of [`fit`].
#[derive(Debug, Clone)]
pub struct FitReport {
    pub model: Model,
    /// A readable summary: parameter table with units and standard errors, fit percentages.
    pub summary_text: String,
    /// The fit percentages of the summary, one per log (fitted logs first, then validation).
    pub scores: Vec<LogScores>,
}

/// The scores of the fitted model on one log, as the summary prints them.
#[derive(Debug, Clone)]
pub struct LogScores {
    /// `fit` (a fitted log), `validation`, or `selection log (chose among N candidates)`
    /// where the fit chose among candidate models on it.
    pub role: String,
    /// The log's path.
    pub file: String,
    /// The scores, or why the model could not be scored on this log.
    pub scores: std::result::Result<Scores, String>,
}

/// Fit percentages of angle, velocity and current.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Fits {
    pub x: f64,
    pub xdot: f64,
    pub i: Option<f64>,
}

/// The scores `compare` prints.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Scores {
    /// Model states as they are against the log's columns.
    pub fit: Fits,
    /// Model states through the sensor chain first.
    pub fit_sensor: Fits,
    pub samples: usize,
}

/// Minimum number of samples a log needs to be fitted: a few velocity-estimator windows.
pub const MIN_SAMPLES: usize = 50;

/// Checks a log is usable for fitting: enough samples, a non-constant input and angle.
pub fn check_log(log: &MotorLog, plant: Plant) -> Result<()> {
    let p = crate::log::echo_path(&log.source);
    if log.len() < MIN_SAMPLES {
        bail!(
            "{p}: only {} samples; fitting needs at least {MIN_SAMPLES}",
            log.len()
        );
    }
    let constant = |v: &[f64]| {
        let (lo, hi) = v
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                (a.min(x), b.max(x))
            });
        hi - lo <= 1e-12 * (1.0 + hi.abs())
    };
    // Line 0 would be wrong: name the column; the whole column is at fault.
    if constant(&log.u) {
        bail!("{p}: column 'u': the input is constant, so it excites nothing to identify");
    }
    if constant(&log.theta) {
        bail!("{p}: column 'theta': the angle never changes (the motor did not move)");
    }
    if plant == Plant::Voltage {
        if let Some(i) = &log.i {
            if constant(i) {
                bail!("{p}: column 'i': the current is constant (is the sensor connected?)");
            }
        }
    }
    Ok(())
}

/// Fit a model.
pub fn fit(req: &FitRequest) -> Result<FitReport> {
    if req.logs.is_empty() {
        bail!("no data to fit: give at least one DATA.csv");
    }
    for log in req.logs {
        check_log(log, req.plant)?;
    }
    free_params::check_constraints(req.constraints, req.kind, req.plant, req.adds)?;
    // Presliding is a state (the bristle deflection), not a term a linear model can carry:
    // the LuGre model is the static friction law with that state.
    if req.kind == ModelKind::Linear && req.adds.iter().any(|s| s.kind == EffectKind::Presliding) {
        bail!(
            "--add presliding: a linear model has no friction state to deflect; fit \
             `--model lugre` instead (Coulomb, Stribeck and viscous friction with the \
             presliding bristle state) and add the other effects to it"
        );
    }
    // A free run carries at most `MAX_LOADS` loads behind a coupling.
    let loads = req
        .adds
        .iter()
        .filter(|s| matches!(s.kind, EffectKind::Compliance | EffectKind::Backlash))
        .count();
    if loads > freerun::MAX_LOADS {
        bail!(
            "--add: {loads} loads behind a coupling (compliance, backlash); a model carries \
             at most {}",
            freerun::MAX_LOADS
        );
    }
    if req.kind == ModelKind::Sindyc && req.adds.iter().any(|s| s.kind == EffectKind::Table) {
        bail!(
            "--add table: a SINDYc library has no lookup-table terms; fit --model lugre \
             (or linear) --add table:..."
        );
    }
    let mut model = if req.adds.is_empty() || req.kind == ModelKind::Sindyc {
        fit_kind(req)?
    } else {
        // The base structure is one start of the refinement with the added effects (and a
        // candidate of their guard): fitted from the beginning on a thread of its own, side
        // by side with the weak-form start's estimates and bristle grid, instead of after
        // them; the refinement takes it from [`BASE_FITS`].
        std::thread::scope(|scope| {
            let base = scope.spawn(|| base_structure_fit(req).map(drop));
            let model = fit_kind(req);
            if let Err(panic) = base.join() {
                std::panic::resume_unwind(panic);
            }
            model
        })?
    };
    // The guard's other candidates (effects at zero, weak-form re-estimates of the motor
    // constants and effects) would not hold what --fix and --bound assert.
    let mut validate_role = String::from("validation");
    if !req.adds.is_empty()
        && !req.validate.is_empty()
        && req.kind != ModelKind::Sindyc
        && req.constraints.is_empty()
    {
        let (guarded, candidates) = guard_added_effects(req, model)?;
        model = guarded;
        validate_role = format!("selection log (chose among {candidates} candidates)");
    } else if req.kind == ModelKind::Sindyc && !req.validate.is_empty() {
        validate_role = "selection log (chose the SINDYc terms on it)".to_string();
    }
    if validate_role != "validation" {
        model.data.method = format!(
            "{}; the --validate logs are a {validate_role}, so their scores are no \
             validation",
            model.data.method
        );
    }
    model.data.files = req
        .logs
        .iter()
        .map(|l| l.source.display().to_string())
        .collect();
    model.data.validate = req
        .validate
        .iter()
        .map(|l| l.source.display().to_string())
        .collect();
    model.data.samples = req.logs.iter().map(MotorLog::len).sum();
    // Where the data came from, the same for every kind of model.
    model.data.sample_period = model.sample_period;
    if model.sensor.hall_resolution_rad == 0.0 {
        if let Some(first) = req.logs.first() {
            model.sensor.hall_resolution_rad = sensor_chain::hall_resolution(first);
        }
    }
    model.data.units = declared_units(req.logs.iter().chain(req.validate));
    relabel_units(&mut model, req.logs);
    let scores = score_logs(&model, req, &validate_role);
    let summary_text = summary_of(&model, &scores);
    Ok(FitReport {
        model,
        summary_text,
        scores,
    })
}

/// The base structure of `req` (its model kind without the added effects) fitted on the
/// same logs: the start of a fit with added effects, and a candidate of their guard. Taken
/// from [`BASE_FITS`] when this process fitted it before.
pub fn base_structure_fit(req: &FitRequest) -> Result<Model> {
    fit_kind(&FitRequest { adds: &[], ..*req })
}

/// The free-run refinement of `model`'s `free` parameters on `req`'s logs, on the exact
/// Jacobian: the base structure from `model` alone; with added effects, from the cheaper of
/// `model` and the base structure refined without them ([`sim_error::refine_added_effects`]).
pub fn refine_free_run(
    model: &mut Model,
    free: &[free_params::Free],
    req: &FitRequest,
) -> Result<Vec<crate::model::Parameter>> {
    let opts = nlsq::Options::default();
    if req.adds.is_empty() {
        let mut report = |it: usize, c: f64| {
            progress::report("free-run simulation error", it, c);
        };
        let sens = sim_error::Jacobian::Sensitivities;
        sim_error::refine(model, free, req.logs, sens, opts, &mut report)
    } else {
        let weak_form = model.clone();
        let weak_form_start = || Ok(weak_form.clone());
        let base_start = || base_structure_fit(req);
        let starts: [&sim_error::StartMaker; 2] = [&weak_form_start, &base_start];
        sim_error::refine_added_effects(model, &starts, free, req.logs, opts)
    }
}

fn fit_kind(req: &FitRequest) -> Result<Model> {
    match req.kind {
        ModelKind::Linear => base_fit_memo(req, linear::fit),
        ModelKind::Lugre => base_fit_memo(req, lugre_fit::fit),
        ModelKind::Sindyc => sindyc_fit(req),
    }
}

/// Base structures (no added effects) fitted in this process, by [`fit_fingerprint`]: a fit
/// with added effects starts from the base structure, its guard scores it, and the demo's
/// loop fits it in its first round and again in every later round's guard. The fit is
/// deterministic (the parallel Jacobian gives the same iterates), so the stored model is the
/// one a refit gives. A slot is filled once: a caller that finds it being filled by another
/// thread waits for that fit; `None` in it is a fit that failed.
static BASE_FITS: std::sync::Mutex<Vec<(u64, BaseFitSlot)>> = std::sync::Mutex::new(Vec::new());

/// A base fit of [`BASE_FITS`], filled by the first caller.
type BaseFitSlot = std::sync::Arc<std::sync::OnceLock<Option<Model>>>;

/// Most base fits kept (a model is a few kilobytes).
const BASE_FITS_KEPT: usize = 4;

/// `fit(req)`, taken from [`BASE_FITS`] when the same base structure was fitted (or is being
/// fitted) on the same logs in this process; requests with added effects are fitted every
/// time. A fit that failed is fitted again for its error.
fn base_fit_memo(req: &FitRequest, fit: fn(&FitRequest) -> Result<Model>) -> Result<Model> {
    if !req.adds.is_empty() {
        return fit(req);
    }
    let key = fit_fingerprint(req);
    let slot: Option<BaseFitSlot> = BASE_FITS.lock().ok().map(|mut fits| {
        if let Some((_, s)) = fits.iter().find(|(k, _)| *k == key) {
            return s.clone();
        }
        if fits.len() >= BASE_FITS_KEPT {
            fits.remove(0);
        }
        let s = BaseFitSlot::default();
        fits.push((key, s.clone()));
        s
    });
    let Some(slot) = slot else {
        return fit(req);
    };
    let mut error = None;
    let stored = slot.get_or_init(|| fit(req).map_err(|e| error = Some(e)).ok());
    match (stored, error) {
        (Some(m), _) => Ok(m.clone()),
        (None, Some(e)) => Err(e),
        (None, None) => fit(req),
    }
}

/// A hash of what a base fit depends on: model kind, plant, and every log's source, metadata
/// and samples (bit patterns).
fn fit_fingerprint(req: &FitRequest) -> u64 {
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    req.kind.name().hash(&mut h);
    (req.plant == Plant::Voltage).hash(&mut h);
    for (k, v) in &req.constraints.fixed {
        (k, v.to_bits()).hash(&mut h);
    }
    for (k, (lo, hi)) in &req.constraints.bounds {
        (k, lo.to_bits(), hi.to_bits()).hash(&mut h);
    }
    for log in req.logs {
        log.source.hash(&mut h);
        log.meta.hash(&mut h);
        let cols = [Some(&log.t), Some(&log.u), log.i.as_ref(), Some(&log.theta)];
        for col in cols.into_iter().chain([log.omega.as_ref()]) {
            match col {
                Some(v) => {
                    v.len().hash(&mut h);
                    v.iter().for_each(|x| x.to_bits().hash(&mut h));
                }
                None => usize::MAX.hash(&mut h),
            }
        }
    }
    h.finish()
}

/// Validation score used to choose between candidate models: the mean over the validation
/// logs of the velocity fit and (when measured) the current fit; −∞ when a model cannot be
/// simulated on one of them.
///
/// The model's velocity is its angle through the firmware's moving average *without* Hall
/// quantisation (as in the simulation-error fit). Through the full sensor chain, a model
/// whose angle stays within a fraction of a Hall step of the truth reproduces the
/// measurement's quantisation pattern sample by sample, and a model a little further off
/// (a slightly wrong inertia) loses as much of that fit as a missing effect costs. That
/// premium for tracking the quantisation noise would decide between candidates instead of
/// the physics.
pub fn validation_score(model: &Model, validate: &[MotorLog]) -> f64 {
    let mut total = 0.0;
    for log in validate {
        let Ok(p) = freerun::simulate(model, log) else {
            return f64::NEG_INFINITY;
        };
        let window = model.sensor.velocity_window;
        let wm = sensor_chain::measured_velocity(log, window);
        let wp = sensor_chain::velocity_estimate(&p.t, &p.theta, window);
        let Ok(fw) = fitpct::fit_percent(&wm, &wp) else {
            return f64::NEG_INFINITY;
        };
        let fi = match (&log.i, &p.i) {
            (Some(i), Some(ip)) => fitpct::fit_percent(i, ip).ok(),
            _ => None,
        };
        total += match fi {
            Some(i) => 0.5 * (fw + i),
            None => fw,
        };
    }
    total / validate.len().max(1) as f64
}

/// `fit --add` must never make the model worse than the base structure: a wrongly estimated
/// position-dependent or current-dependent torque makes a free run stick or drift on new
/// data. Candidates: the fit with the added effects, the same with the effects' magnitudes
/// at zero, the added effects estimated by weak form on the residual of the fit and of the
/// base structure fitted afresh, and that base structure itself (keeping the added effects
/// in the structure at zero magnitude, so the model still names them). The validation logs
/// decide ([`validation_score`]).
fn guard_added_effects(req: &FitRequest, with: Model) -> Result<(Model, usize)> {
    progress::report(
        "choosing among candidates on the --validate logs (selection)",
        0,
        f64::NAN,
    );
    let zeroed = sim_error::scale_effect_magnitudes(&with, 0.0);
    let weak_with = weak_form_candidate(&with, &with, req.logs);
    // The base structure (the fit's start, kept in the process).
    let from_base = base_structure_fit(req).ok().map(|base| {
        let cand = weak_form_candidate(&base, &with, req.logs);
        (cand, base_with_added_effects_at_zero(base, &with))
    });
    // The candidates' validation runs are independent: scored side by side.
    let mut candidates = vec![&with, &zeroed, &weak_with];
    if let Some((cand, base)) = &from_base {
        candidates.extend([cand, base]);
    }
    let scores: Vec<f64> = {
        use rayon::prelude::*;
        candidates
            .par_iter()
            .map(|m| validation_score(m, req.validate))
            .collect()
    };
    let count = candidates.len();
    let score_with = scores[0];
    let mut choice = GuardChoice {
        best: (score_with, with.clone(), false),
        weak_form: None,
    };
    tracing::debug!(
        "guard: with {score_with:.2} ({:?}), zeroed {:.2}",
        with.effects,
        scores[1]
    );
    choice.offer_zeroed(scores[1], zeroed);
    choice.offer_weak_form(scores[2], weak_with);
    if let Some((cand, base)) = from_base {
        tracing::debug!(
            "guard: with {score_with:.2}, residual estimate on the base fit {:.2}",
            scores[3]
        );
        choice.offer_weak_form(scores[3], cand);
        tracing::debug!("guard: base fitted afresh {:.2}", scores[4]);
        choice.offer_zeroed(scores[4], base);
    }
    Ok((choice.into_model(score_with), count))
}

/// The guard's running choice among its candidates, by validation score [%].
struct GuardChoice {
    /// The best of the fit as given and the candidates with the added effects at zero:
    /// (score, model, whether the added effects are at zero).
    best: (f64, Model, bool),
    /// The best weak-form candidate among those that beat `best` when they were scored.
    weak_form: Option<(f64, Model)>,
}

impl GuardChoice {
    /// Keeps `m`, a model with the added effects at zero, when it beats the best.
    fn offer_zeroed(&mut self, score: f64, m: Model) {
        if score > self.best.0 {
            self.best = (score, m, true);
        }
    }

    /// Keeps `m`, a weak-form candidate, when it beats the best and the weak-form candidate
    /// kept before.
    fn offer_weak_form(&mut self, score: f64, m: Model) {
        if score > self.best.0 && self.weak_form.as_ref().is_none_or(|(r, _)| score > *r) {
            self.weak_form = Some((score, m));
        }
    }

    /// The chosen model: the weak-form candidate when it still beats the best, else the
    /// best, its rows marked when the added effects were set to zero (`score_with`: the
    /// validation score of the fit as given).
    fn into_model(self, score_with: f64) -> Model {
        if let Some((s, m)) = self.weak_form {
            if s > self.best.0 {
                tracing::debug!("residual estimate of the added effects: {:?}", m.effects);
                return m;
            }
        }
        let (_, mut model, zeroed) = self.best;
        if zeroed {
            mark_set_to_zero(&mut model, score_with);
        }
        model
    }
}

/// The guard's weak-form candidate: `with`'s added effects estimated by weak form on what
/// the fitted model `from` leaves unexplained ([`effect_residual::estimate`]), its parameter
/// rows showing the values the model now has.
fn weak_form_candidate(from: &Model, with: &Model, logs: &[MotorLog]) -> Model {
    let mut m = effect_residual::estimate(from, with, logs);
    let mut params = reestimated_base_rows(from, &m);
    params.extend(weak_form_effect_rows(with, &m));
    m.parameters = params;
    m.data.method = format!(
        "{}; added effects by weak form on the fitted model's residual",
        from.data.method
    );
    m
}

/// `from`'s rows of the base structure (no effect keys) with the values of `m`: the
/// electrical regression re-estimates the motor constants (and rescales the mechanical
/// ones with K_t), and a row whose value moved loses its standard error.
fn reestimated_base_rows(from: &Model, m: &Model) -> Vec<crate::model::Parameter> {
    let mut params: Vec<_> = from
        .parameters
        .iter()
        .filter(|p| !p.name.contains('.'))
        .cloned()
        .collect();
    for p in &mut params {
        let v = match (base_slot(&p.name), p.name.as_str()) {
            (Some(sl), _) => sl.get(m),
            (None, "Kt") => m.motor.kt,
            _ => continue,
        };
        if (v - p.value).abs() > 1e-9 * p.value.abs() {
            p.value = v;
            p.std_err = None;
            p.note = "re-estimated by weak form jointly with the added effects".into();
        }
    }
    params
}

/// The slot of a base-structure row by its name (R, L, Kb, J, b, the LuGre parameters).
fn base_slot(name: &str) -> Option<free_params::Slot> {
    use free_params::Slot;
    match name {
        "R" => Some(Slot::R),
        "L" => Some(Slot::L),
        "Kb" => Some(Slot::Kb),
        "J" => Some(Slot::J),
        "b" => Some(Slot::Viscous),
        "alpha0" => Some(Slot::Lugre("alpha0")),
        "alpha1" => Some(Slot::Lugre("alpha1")),
        "alpha2" => Some(Slot::Lugre("alpha2")),
        "sigma0" => Some(Slot::Lugre("sigma0")),
        "sigma1" => Some(Slot::Lugre("sigma1")),
        _ => None,
    }
}

/// `with`'s effect rows (`NAME.key`) with the values of `m`'s effects; the estimated keys
/// (all but a cogging harmonic) say they come from the weak form, without a standard error.
fn weak_form_effect_rows(with: &Model, m: &Model) -> Vec<crate::model::Parameter> {
    let mut rows = Vec::new();
    for mut p in with
        .parameters
        .iter()
        .filter(|p| p.name.contains('.'))
        .cloned()
    {
        if let Some((name, key)) = p.name.split_once('.') {
            if let Some(e) = m.effects.iter().find(|e| e.kind().name() == name) {
                p.value = EffectSpec::from_effect(e).get(key);
            }
            if key != "harmonic" {
                p.std_err = None;
                p.identifiable = true;
                p.note = "weak form on the fitted model's residual".into();
            }
        }
        rows.push(p);
    }
    rows
}

/// The base structure fitted afresh as a guard candidate: `with`'s added effects in its
/// structure at zero magnitude, and their rows after the base rows.
fn base_with_added_effects_at_zero(mut base: Model, with: &Model) -> Model {
    base.effects = sim_error::scale_effect_magnitudes(with, 0.0).effects;
    base.parameters.extend(
        with.parameters
            .iter()
            .filter(|p| p.name.contains('.'))
            .cloned(),
    );
    base
}

/// Says in `model`'s method and effect rows that the added effects were set to zero
/// (`score_with`: the validation fit [%] with their estimated magnitudes).
fn mark_set_to_zero(model: &mut Model, score_with: f64) {
    model.data.method = format!(
        "{}; the added effects were set to zero: with their estimated magnitudes the \
         fit on the --validate logs, which chose among the candidates, was worse \
         ({score_with:.1} %)",
        model.data.method
    );
    let effects = model.effects.clone();
    for p in &mut model.parameters {
        let Some((name, key)) = p.name.split_once('.') else {
            continue;
        };
        if let Some(e) = effects.iter().find(|e| e.kind().name() == name) {
            p.value = EffectSpec::from_effect(e).get(key);
        }
        if key != "harmonic" {
            p.std_err = None;
            p.note = "magnitude set to zero: the selection data did not support it".into();
        }
    }
}

/// Score a fitted model on the request's logs (fitted, then `--validate`), each log's free
/// run in parallel; `validate_role` names the role the `--validate` logs played:
/// `validation`, or a selection log when the fit chose among candidate models on them.
fn score_logs(model: &Model, req: &FitRequest, validate_role: &str) -> Vec<LogScores> {
    use rayon::prelude::*;
    let logs: Vec<(&str, &MotorLog)> = [("fit", req.logs), (validate_role, req.validate)]
        .into_iter()
        .flat_map(|(role, logs)| logs.iter().map(move |l| (role, l)))
        .collect();
    logs.par_iter()
        .map(|&(role, log)| LogScores {
            role: role.to_string(),
            file: log.source.display().to_string(),
            scores: score(model, log).map_err(|e| format!("{e:#}")),
        })
        .collect()
}

/// The summary text of a fitted model and its scores.
pub fn summary_of(model: &Model, scores: &[LogScores]) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{} model ({} plant), {} samples at {} s",
        model.kind.name(),
        match model.plant {
            Plant::Voltage => "voltage",
            Plant::Torque => "torque",
        },
        model.data.samples,
        model.sample_period
    );
    s.push_str(&parameter_table(model));
    for ls in scores {
        match &ls.scores {
            Ok(sc) => {
                let _ = writeln!(s, "{} {}: {}", ls.role, ls.file, fits_line(sc));
            }
            Err(e) => {
                let _ = writeln!(s, "{} {}: cannot score: {e}", ls.role, ls.file);
            }
        }
    }
    s
}

/// The units the logs declared, by column (see [`crate::model::Provenance::units`]).
pub fn declared_units<'a>(logs: impl Iterator<Item = &'a MotorLog>) -> BTreeMap<String, String> {
    let logs: Vec<&MotorLog> = logs.collect();
    let mut out = BTreeMap::new();
    for col in crate::log::ColumnMap::STANDARD {
        let per: Vec<(&MotorLog, &str)> = logs
            .iter()
            .map(|l| (*l, l.units.get(col).map(String::as_str).unwrap_or("SI")))
            .collect();
        if per.iter().all(|(_, u)| *u == "SI") {
            continue;
        }
        let value = if per.iter().all(|(_, u)| *u == per[0].1) {
            per[0].1.to_string()
        } else {
            per.iter()
                .map(|(l, u)| format!("{u} in {}", crate::log::echo_path(&l.source)))
                .collect::<Vec<_>>()
                .join("; ")
        };
        out.insert(col.to_string(), value);
    }
    out
}

/// Parameter units as the data make them: with `--plant torque` the input `u` is a torque or
/// force in whatever unit the log has (its declared unit, else `u`), so `N·m` becomes that
/// unit; on a linear axis (theta in m) `rad` becomes `m` (and, with a voltage plant, `N·m`
/// becomes `N`).
pub fn relabel_units(model: &mut Model, logs: &[MotorLog]) {
    let linear = is_linear(logs);
    // A voltage plant on a rotary axis already has its units (N·m, rad).
    if model.plant == Plant::Voltage && !linear {
        return;
    }
    let torque = torque_unit(model.plant, logs);
    for p in &mut model.parameters {
        p.unit = relabel_unit(&p.unit, &torque, linear);
    }
}

/// Every log is on a linear axis (theta in m), and there is at least one.
fn is_linear(logs: &[MotorLog]) -> bool {
    !logs.is_empty() && logs.iter().all(MotorLog::is_linear)
}

/// The unit of a torque (or force) on `plant` fitted to `logs`: a torque plant's input unit
/// when every log declares the same one (`u` otherwise); `N` for a voltage plant on a linear
/// axis, `N·m` on a rotary one.
pub fn torque_unit(plant: Plant, logs: &[MotorLog]) -> String {
    match plant {
        Plant::Torque => {
            let declared: Vec<Option<&String>> = logs.iter().map(|l| l.units.get("u")).collect();
            match declared.first() {
                Some(Some(u)) if declared.iter().all(|d| *d == Some(*u)) => (*u).clone(),
                _ => "u".to_string(),
            }
        }
        Plant::Voltage if is_linear(logs) => "N".to_string(),
        Plant::Voltage => "N·m".to_string(),
    }
}

/// One unit string relabelled (see [`relabel_units`]): `N·m` → `torque`, the word `u` →
/// `torque` (unless it is `u`), and, when `linear`, the word `rad` → `m`.
pub fn relabel_unit(unit: &str, torque: &str, linear: bool) -> String {
    const PLACEHOLDER: char = '\u{1}';
    let unit = if linear && unit == "kg·m²" {
        "kg"
    } else {
        unit
    };
    let s = unit.replace("N·m", &PLACEHOLDER.to_string());
    let mut out = String::new();
    let mut word = String::new();
    let flush = |word: &mut String, out: &mut String| {
        match word.as_str() {
            "u" => out.push_str(torque),
            "rad" if linear => out.push('m'),
            w => out.push_str(w),
        }
        word.clear();
    };
    for c in s.chars() {
        if c.is_alphabetic() {
            word.push(c);
        } else {
            flush(&mut word, &mut out);
            if c == PLACEHOLDER {
                out.push_str(torque);
            } else {
                out.push(c);
            }
        }
    }
    flush(&mut word, &mut out);
    out
}

/// `x 91.2 %, xdot 88.0 %, i 95.1 % (sensor chain: x ..., xdot ...)`.
pub fn fits_line(sc: &Scores) -> String {
    let f = |x: &Fits| {
        let mut s = format!("x {:6.2} %, xdot {:6.2} %", x.x, x.xdot);
        if let Some(i) = x.i {
            s.push_str(&format!(", i {:6.2} %", i));
        }
        s
    };
    format!("{}  (through sensor: {})", f(&sc.fit), f(&sc.fit_sensor))
}

/// The parameter table with units, standard errors and identifiability notes.
pub fn parameter_table(model: &Model) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "  {:<18} {:>13} {:<12} {:>11}  note",
        "parameter", "value", "unit", "std err"
    );
    for p in &model.parameters {
        let se = match p.std_err {
            Some(e) => format!("{e:.3e}"),
            None => "-".to_string(),
        };
        let mut note = p.note.clone();
        if !p.identifiable {
            note = format!("NOT IDENTIFIABLE: {note}");
        }
        let _ = writeln!(
            s,
            "  {:<18} {:>13.6e} {:<12} {:>11}  {}",
            p.name, p.value, p.unit, se, note
        );
    }
    if let Some(f) = model.data.std_err_factor {
        let _ = writeln!(
            s,
            "  (standard errors include a factor {f:.1} for the residual's autocorrelation: \
             white-noise errors would be that many times too small)"
        );
    }
    s
}

/// Score a model on a log: free-run fits of angle, velocity and current, as they are and
/// through the sensor chain.
pub fn score(model: &Model, log: &MotorLog) -> Result<Scores> {
    // The measured velocity does not wait for the free run.
    let (pred, wmeas) = rayon::join(
        || freerun::simulate(model, log),
        || sensor_chain::measured_velocity(log, model.sensor.velocity_window),
    );
    score_against(model, log, &pred?, &wmeas)
}

/// Score an existing prediction (see [`score`]).
pub fn score_prediction(model: &Model, log: &MotorLog, pred: &Prediction) -> Result<Scores> {
    let wmeas = sensor_chain::measured_velocity(log, model.sensor.velocity_window);
    score_against(model, log, pred, &wmeas)
}

/// [`score_prediction`] with the log's measured velocity `wmeas` (the firmware's estimator
/// on its angle).
fn score_against(
    model: &Model,
    log: &MotorLog,
    pred: &Prediction,
    wmeas: &[f64],
) -> Result<Scores> {
    let src = crate::log::echo_path(&log.source);
    let window = model.sensor.velocity_window;
    let res = match sensor_chain::hall_resolution(log) {
        r if r > 0.0 => r,
        _ => model.sensor.hall_resolution_rad,
    };
    let named =
        |col: &str, r: Result<f64>| r.map_err(|e| anyhow::anyhow!("{src}: column '{col}': {e}"));
    let fi = match (&log.i, &pred.i) {
        (Some(i), Some(ip)) => Some(named("i", fitpct::fit_percent(i, ip))?),
        _ => None,
    };
    let fit = Fits {
        x: named("theta", fitpct::fit_percent(&log.theta, &pred.theta))?,
        xdot: named("omega", fitpct::fit_percent(wmeas, &pred.omega))?,
        i: fi,
    };
    let (q, wq) = sensor_chain::through_sensor(&pred.t, &pred.theta, res, window);
    let fit_sensor = Fits {
        x: named("theta", fitpct::fit_percent(&log.theta, &q))?,
        xdot: named("omega", fitpct::fit_percent(wmeas, &wq))?,
        i: fi,
    };
    Ok(Scores {
        fit,
        fit_sensor,
        samples: log.len(),
    })
}

/// SINDYc fitting ([`sindyc`]); this is the single call site.
fn sindyc_fit(req: &FitRequest) -> Result<Model> {
    sindyc::fit_model(req)
}

/// SINDYc free-run simulation ([`sindyc`]); this is the single call site.
pub(crate) fn sindyc_simulate(model: &Model, log: &MotorLog) -> Result<Prediction> {
    sindyc::simulate_model(model, log)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn torque_plant_units_name_the_input_not_newton_metres() {
        assert_eq!(relabel_unit("N·m·s/rad", "u", false), "u·s/rad");
        assert_eq!(relabel_unit("u·s²/rad", "u", false), "u·s²/rad");
        assert_eq!(relabel_unit("N·m/rad", "N", true), "N/m");
        assert_eq!(relabel_unit("u·s²/rad", "N", true), "N·s²/m");
        assert_eq!(relabel_unit("rad/s", "N·m", false), "rad/s");
        assert_eq!(relabel_unit("kg·m²", "N", true), "kg");
        assert_eq!(relabel_unit("1/rev", "u", false), "1/rev");
        let mut m = Model::new(ModelKind::Linear, Plant::Torque, 0.001);
        m.parameters = vec![
            crate::model::Parameter::new("b", 1.0, "N·m·s/rad"),
            crate::model::Parameter::new("J", 1.0, "u·s²/rad"),
        ];
        let log = MotorLog {
            units: [("u".to_string(), "N".to_string())].into(),
            ..Default::default()
        };
        // A force input: a linear axis, so rad becomes m as well.
        relabel_units(&mut m, std::slice::from_ref(&log));
        assert_eq!(m.parameters[0].unit, "N·s/m");
        assert_eq!(m.parameters[1].unit, "N·s²/m");
        let mut logs = [log.clone(), log];
        logs[1].units.insert("t".into(), "ms".into());
        logs[0].source = "a.csv".into();
        logs[1].source = "b.csv".into();
        let u = declared_units(logs.iter());
        assert_eq!(u["u"], "N");
        assert_eq!(u["t"], "SI in a.csv; ms in b.csv");
    }

    #[test]
    fn torque_unit_follows_the_plant_the_axis_and_the_declared_input() {
        let rotary = MotorLog::default();
        let newton = MotorLog {
            units: [("u".to_string(), "N".to_string())].into(),
            ..Default::default()
        };
        let metres = MotorLog {
            units: [("theta".to_string(), "m".to_string())].into(),
            ..Default::default()
        };
        let one = std::slice::from_ref;
        assert_eq!(torque_unit(Plant::Voltage, one(&rotary)), "N·m");
        assert_eq!(torque_unit(Plant::Voltage, one(&metres)), "N");
        assert_eq!(torque_unit(Plant::Torque, one(&rotary)), "u");
        assert_eq!(torque_unit(Plant::Torque, one(&newton)), "N");
        // Logs that disagree on the input's unit leave it as `u`.
        assert_eq!(torque_unit(Plant::Torque, &[newton, rotary]), "u");
    }
}
