//! The identification loop as a library: fit → diagnose → add what the diagnosis names →
//! refit, with one stopping policy. `motorid demo`, the real-data runs and the tests all run
//! this loop; a user runs the same steps by hand with `fit`, `diagnose` and `fit --add`.
//!
//! # Data
//! Three roles, never mixed: the *fitting* data estimates the parameters and is diagnosed;
//! the *selection* data decides whether a refit is kept (and is `fit --validate`'s data); the
//! caller reports scores on *test* data no choice was made on. Without selection logs the
//! loop holds out the last [`SELECT_FRACTION`] of every fitting log in time ([`split_in_time`]):
//! the model is fitted on the first part and judged on its continuation, as it will be used.
//! (Alternating blocks would interleave the two, but every block would then be a short free
//! run dominated by its initial state, and the held-out part would not be the future of the
//! fitted one.)
//!
//! # Policy
//! Each round fits the model with the effects added so far and diagnoses it on every fitting
//! log. The next addition is the strongest significant effect `diagnose` names that the model
//! does not have yet (over all fitting logs), else, when the model is not adequate, the first
//! variable that carries unexplained structure and comes with a term to add (a `table:`
//! spec). One addition per round, so that each refit answers for one change.
//!
//! A refit is kept when it explains the selection data significantly better than the model it
//! extends ([`selection_test`]: the nested-model F-test of [`statistics::f_test`] on the
//! simulation-error residual the fit itself minimises, with the effective sample size of that
//! residual, at the level [`SELECTION_ALPHA`]). A refit that is not kept is recorded, its
//! addition is set aside, and the next candidate of the kept model's diagnoses is tried.
//!
//! A named effect the fit cannot estimate yet (it refuses the request) is set aside the same
//! way, without a round, and listed in [`Outcome::not_fitted`].
//!
//! When the selection data was held out in time, the final structure is refitted on the whole
//! fitting logs ([`Outcome::refit_on_all`]).
//!
//! The loop stops when
//! - the model is adequate on every fitting log ([`Stop::Adequate`]);
//! - it is not, but nothing untried can be added ([`Stop::NothingToAdd`]: the verdict says
//!   which variable carries the rest);
//! - the last candidates were all refitted and none was kept ([`Stop::NoGain`]), or
//! - [`Config::max_rounds`] refits have run ([`Stop::MaxRounds`]).
use crate::diagnose::{self, Diagnosis, Structure};
use crate::effect_spec::EffectSpec;
use crate::ident::free_params::{self, Constraints};
use crate::ident::sim_error::Residuals;
use crate::ident::{self, FitRequest};
use crate::log::{MotorLog, Plant};
use crate::model::{Model, ModelKind};
use crate::numerics::statistics::{self, FTest};
use anyhow::{bail, Context, Result};
use control::effects::EffectKind;

/// Share of each fitting log held out in time for selection when no selection logs are
/// given: the last 30 %, enough for several of the slowest excitation cycles while the fit
/// keeps most of the data.
pub const SELECT_FRACTION: f64 = 0.3;

/// Level of the keep-or-not test of a refit: a refit whose addition does nothing is kept with
/// probability at most 1 % per round (at most a few percent over a loop of a few rounds),
/// while a real improvement on a few thousand held-out samples passes easily.
pub const SELECTION_ALPHA: f64 = 0.01;

/// What the loop fits, on which data.
pub struct Config<'a> {
    pub kind: ModelKind,
    pub plant: Plant,
    /// Logs the model is fitted on; each is diagnosed.
    pub fit_logs: &'a [MotorLog],
    /// Logs that choose among models (passed to the fit as validation logs, and the data of
    /// the keep-or-not test); empty: the last [`SELECT_FRACTION`] of each fitting log.
    pub select_logs: &'a [MotorLog],
    /// Effects in the model from the first round on.
    pub start: Vec<EffectSpec>,
    /// Parameters the user knows (`fit --fix`, `--bound`).
    pub constraints: &'a Constraints,
    /// Refits after the first fit, at most.
    pub max_rounds: usize,
    pub diagnose: diagnose::Options,
}

/// Why the next round adds what it adds.
#[derive(Debug, Clone)]
pub enum Reason {
    /// A named effect `diagnose` found: the share of the equation's residual it explains and
    /// its sentence of physics.
    Effect { score: f64, explanation: String },
    /// No named effect, but `variable` carries this share of the residual.
    Unexplained { variable: String, share: f64 },
}

/// The addition a round proposes for the next one.
#[derive(Debug, Clone)]
pub struct Next {
    pub spec: EffectSpec,
    /// Index of the fitting log whose diagnosis named it.
    pub log: usize,
    pub reason: Reason,
}

/// One fit, its keep-or-not test and its diagnoses.
#[derive(Debug, Clone)]
pub struct Round {
    /// Effects added to the base model in this round's fit.
    pub adds: Vec<EffectSpec>,
    pub model: Model,
    /// The diagnosis on each fitting log, in order (empty for a refit that was not kept).
    pub diagnoses: Vec<Diagnosis>,
    /// Mean angle fit % of the free run on the selection data ([`selection_fit`]).
    pub selection_fit: f64,
    /// The statistic the keep-or-not test compares: the multiple-shooting residual sum of
    /// squares of this model on the selection data ([`selection_rss`]).
    pub selection_rss: f64,
    /// The test of this refit against the kept model it extends, on the selection data
    /// ([`selection_test`]); None for the first fit.
    pub selection_test: Option<FTest>,
    /// What the next round adds (None on the last round).
    pub next: Option<Next>,
    /// False when this refit did not explain the selection data significantly better.
    pub kept: bool,
}

/// Why the loop ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stop {
    Adequate,
    NothingToAdd,
    NoGain,
    MaxRounds,
}

/// The rounds of a loop and why it ended.
#[derive(Debug, Clone)]
pub struct Outcome {
    pub rounds: Vec<Round>,
    pub stop: Stop,
    /// True when the selection data was the held-out end of the fitting logs.
    pub held_out_in_time: bool,
    /// With the selection data held out in time: the final round's effects refitted on the
    /// whole fitting logs (the structure is chosen on the split, its parameters use all the
    /// data).
    pub refit_on_all: Option<Model>,
    /// Effects the diagnosis named that the fit could not add, with its reason; each was
    /// set aside and the next candidate tried.
    pub not_fitted: Vec<(EffectSpec, String)>,
}

impl Outcome {
    /// The last kept round: the structure the loop ends with.
    pub fn final_round(&self) -> &Round {
        self.rounds
            .iter()
            .rev()
            .find(|r| r.kept)
            .expect("the first round is always kept")
    }

    /// The model the loop ends with: the final round's structure refitted on the whole
    /// fitting logs when they were split, else the final round's model.
    pub fn final_model(&self) -> &Model {
        self.refit_on_all
            .as_ref()
            .unwrap_or(&self.final_round().model)
    }
}

/// The log cut at `fraction` of its samples from the end: (first part, last part), each a
/// log of its own (sources say which part). Errors when a part would be too short to fit or
/// to score.
pub fn split_in_time(log: &MotorLog, fraction: f64) -> Result<(MotorLog, MotorLog)> {
    let n = log.len();
    let cut = n - ((fraction.clamp(0.0, 1.0) * n as f64).round() as usize).min(n);
    if cut < ident::MIN_SAMPLES || n - cut < ident::MIN_SAMPLES {
        bail!(
            "{}: {n} samples are too few to hold out the last {:.0} % for model selection \
             (each part needs {}); give selection logs apart",
            log.source.display(),
            100.0 * fraction,
            ident::MIN_SAMPLES
        );
    }
    let part = |a: usize, b: usize, what: String| MotorLog {
        source: format!("{} ({what})", log.source.display()).into(),
        meta: log.meta.clone(),
        t: log.t[a..b].to_vec(),
        u: log.u[a..b].to_vec(),
        i: log.i.as_ref().map(|v| v[a..b].to_vec()),
        theta: log.theta[a..b].to_vec(),
        omega: log.omega.as_ref().map(|v| v[a..b].to_vec()),
        extra: log
            .extra
            .iter()
            .map(|(k, v)| (k.clone(), v[a..b].to_vec()))
            .collect(),
        units: log.units.clone(),
    };
    let pct = (100.0 * fraction).round();
    Ok((
        part(0, cut, format!("first {:.0} %", 100.0 - pct)),
        part(cut, n, format!("last {pct:.0} %, held out")),
    ))
}

/// Mean angle (or position) fit % of the model's free run on `logs`, the one state every log
/// carries and the one a position-controlled axis is judged by; −∞ when the model cannot be
/// simulated on one of them.
pub fn selection_fit(model: &Model, logs: &[MotorLog]) -> f64 {
    let mut sum = 0.0;
    for log in logs {
        let Ok(s) = ident::score(model, log) else {
            return f64::NEG_INFINITY;
        };
        sum += s.fit.x;
    }
    sum / logs.len().max(1) as f64
}

/// The residual sum of squares [`selection_test`] compares, of `model` on `logs`: the
/// multiple-shooting simulation error of [`Residuals::segmented`] (velocity, current and
/// angle, each scaled by its spread); +∞ when the model cannot be simulated there.
pub fn selection_rss(model: &Model, logs: &[MotorLog]) -> f64 {
    selection_residual(model, logs).map_or(f64::INFINITY, |r| sum_of_squares(&r))
}

/// The residual of [`selection_rss`], on the targets `model`'s velocity window makes.
fn selection_residual(model: &Model, logs: &[MotorLog]) -> Result<Vec<f64>> {
    Residuals::segmented(logs, model.sensor.velocity_window).eval(model)
}

fn sum_of_squares(r: &[f64]) -> f64 {
    r.iter().map(|v| v * v).sum()
}

/// Does `refit` (the model `base` plus the effect `added`) explain the selection `logs`
/// significantly better than `base`? The nested-model F-test ([`statistics::f_test`]) on the
/// residual the fit minimises (the multiple-shooting simulation error of
/// [`Residuals::segmented`]: velocity, current and angle, each scaled by its spread), with
/// `q` the estimable keys of the added effect and the effective sample size
/// `n / τ` of the refit's residual ([`statistics::correlation_time`]). No parameter was
/// fitted on these samples, so the denominator keeps `n_eff − q` degrees of freedom; on
/// held-out data a larger model is not better by construction, which makes the test
/// conservative. A base that cannot be simulated loses to any refit that can; a refit that
/// cannot loses (p = 1). Both models are run on the targets of the refit's velocity window,
/// so both residuals measure the same thing.
pub fn selection_test(base: &Model, refit: &Model, added: &EffectSpec, logs: &[MotorLog]) -> FTest {
    let residuals = Residuals::segmented(logs, refit.sensor.velocity_window);
    let r1 = residuals.eval(refit);
    let rss0 = || residuals.eval(base).map(|r| sum_of_squares(&r));
    f_test_of(r1, rss0, added)
}

/// [`selection_test`] from the refit's residual `r1` and the base's residual sum of squares
/// (asked only when the refit could be simulated), both on the same targets.
fn f_test_of(
    r1: Result<Vec<f64>>,
    rss0: impl FnOnce() -> Result<f64>,
    added: &EffectSpec,
) -> FTest {
    let Ok(r1) = r1 else {
        return FTest {
            f: 0.0,
            p_value: 1.0,
            explained: 0.0,
            delta_bic: f64::INFINITY,
        };
    };
    let Ok(rss0) = rss0() else {
        return FTest {
            f: f64::INFINITY,
            p_value: 0.0,
            explained: 1.0,
            delta_bic: f64::NEG_INFINITY,
        };
    };
    let q = free_params::effect_keys_of(&added.to_effect()).len().max(1);
    let n_eff = r1.len() as f64 / statistics::correlation_time(&r1);
    statistics::f_test(rss0, sum_of_squares(&r1), q, 0, n_eff)
}

/// True when `s` is one of `specs`' effects (a table: on the same variable).
fn contains(specs: &[EffectSpec], s: &EffectSpec) -> bool {
    specs.iter().any(|a| {
        a.kind == s.kind && (a.kind != EffectKind::Table || a.table_var() == s.table_var())
    })
}

/// The addition the diagnoses propose for a model with the effects `adds`, leaving out the
/// effects in `set_aside` (refits that were not kept); see the policy in the module doc.
pub fn next_addition(
    diagnoses: &[Diagnosis],
    adds: &[EffectSpec],
    set_aside: &[EffectSpec],
) -> Option<Next> {
    let new = |s: &EffectSpec| !contains(adds, s) && !contains(set_aside, s);
    let named = diagnoses
        .iter()
        .enumerate()
        .flat_map(|(k, d)| d.effects.iter().map(move |f| (k, f)))
        .filter_map(|(k, f)| {
            let spec = EffectSpec::parse(&f.spec).ok()?;
            new(&spec).then_some((k, f, spec))
        })
        .max_by(|a, b| a.1.score.total_cmp(&b.1.score));
    if let Some((log, f, spec)) = named {
        return Some(Next {
            spec,
            log,
            reason: Reason::Effect {
                score: f.score,
                explanation: f.explanation.clone(),
            },
        });
    }
    diagnoses
        .iter()
        .enumerate()
        .filter(|(_, d)| !d.verdict.adequate)
        .flat_map(|(k, d)| d.verdict.unexplained.iter().map(move |c| (k, c)))
        .find_map(|(log, c)| {
            let spec = EffectSpec::parse(c.spec.as_deref()?).ok()?;
            new(&spec).then(|| Next {
                spec,
                log,
                reason: Reason::Unexplained {
                    variable: c.variable.to_string(),
                    share: c.share,
                },
            })
        })
}

/// Run the loop. `fit` performs one fit (the caller may wrap it in a progress display; pass
/// `|req| Ok(ident::fit(req)?.model)` for a plain one); `on_round` sees each round as soon as
/// it is decided.
pub fn run(
    cfg: &Config,
    fit: &mut dyn FnMut(&FitRequest) -> Result<Model>,
    on_round: &mut dyn FnMut(&Round),
) -> Result<Outcome> {
    let held_out_in_time = cfg.select_logs.is_empty();
    let (fit_owned, select_owned) = if held_out_in_time {
        split_each_in_time(cfg.fit_logs)?
    } else {
        (Vec::new(), Vec::new())
    };
    let data = if held_out_in_time {
        LoopData {
            fit: &fit_owned,
            select: &select_owned,
        }
    } else {
        LoopData {
            fit: cfg.fit_logs,
            select: cfg.select_logs,
        }
    };
    let mut state = LoopState::new(cfg.start.clone());
    let stop = run_rounds(cfg, &data, fit, on_round, &mut state)?;
    let mut out = Outcome {
        rounds: state.rounds,
        stop,
        held_out_in_time,
        refit_on_all: None,
        not_fitted: state.not_fitted,
    };
    if held_out_in_time {
        out.refit_on_all = Some(refit_on_whole_logs(cfg, fit, &out.final_round().adds)?);
    }
    Ok(out)
}

/// The logs of one loop: fitted (and diagnosed), and selecting among the refits.
struct LoopData<'a> {
    fit: &'a [MotorLog],
    select: &'a [MotorLog],
}

/// What the loop carries from one round to the next.
struct LoopState {
    /// Effects of the next fit.
    adds: Vec<EffectSpec>,
    /// Effects not to propose again: refits not kept, and effects the fit refused.
    set_aside: Vec<EffectSpec>,
    rounds: Vec<Round>,
    /// Index in `rounds` of the last kept round.
    kept_at: Option<usize>,
    /// Effects the fit refused, with its reason.
    not_fitted: Vec<(EffectSpec, String)>,
}

impl LoopState {
    fn new(start: Vec<EffectSpec>) -> LoopState {
        LoopState {
            adds: start,
            set_aside: Vec::new(),
            rounds: Vec::new(),
            kept_at: None,
            not_fitted: Vec::new(),
        }
    }

    /// A refit the fit refused (an effect it cannot estimate yet): its effect is set aside
    /// with the reason, and, when `more` refits are allowed, the next candidate of the kept
    /// round `kept_at` is queued. Returns the stop when no candidate is queued.
    fn set_refused_aside(&mut self, e: anyhow::Error, kept_at: usize, more: bool) -> Option<Stop> {
        let spec = self.adds.pop().expect("a refit adds an effect");
        self.not_fitted.push((spec.clone(), format!("{e:#}")));
        self.set_aside.push(spec);
        let kept = &self.rounds[kept_at];
        if more {
            if let Some(n) = next_addition(&kept.diagnoses, &self.adds, &self.set_aside) {
                self.adds.push(n.spec);
                return None;
            }
        }
        let adequate = kept.diagnoses.iter().all(|d| d.verdict.adequate);
        Some(if adequate {
            Stop::Adequate
        } else {
            Stop::NothingToAdd
        })
    }

    /// Records a decided round (the last kept one when it was kept).
    fn push_round(&mut self, r: Round) {
        let kept = r.kept;
        self.rounds.push(r);
        if kept {
            self.kept_at = Some(self.rounds.len() - 1);
        }
    }
}

/// Each fitting log split in time: (first parts, held-out last parts), see [`split_in_time`].
fn split_each_in_time(logs: &[MotorLog]) -> Result<(Vec<MotorLog>, Vec<MotorLog>)> {
    let split: Vec<(MotorLog, MotorLog)> = logs
        .iter()
        .map(|l| split_in_time(l, SELECT_FRACTION))
        .collect::<Result<_>>()?;
    Ok(split.into_iter().unzip())
}

/// The fit request of `cfg` on `logs`, validated on `validate`, with the effects `adds`.
fn request<'a>(
    cfg: &'a Config,
    logs: &'a [MotorLog],
    validate: &'a [MotorLog],
    adds: &'a [EffectSpec],
) -> FitRequest<'a> {
    FitRequest {
        kind: cfg.kind,
        logs,
        validate,
        adds,
        plant: cfg.plant,
        constraints: cfg.constraints,
    }
}

/// Fits, judges and records round after round; returns why the loop stopped.
fn run_rounds(
    cfg: &Config,
    data: &LoopData,
    fit: &mut dyn FnMut(&FitRequest) -> Result<Model>,
    on_round: &mut dyn FnMut(&Round),
    state: &mut LoopState,
) -> Result<Stop> {
    let mut round = 0;
    loop {
        let fitted = fit(&request(cfg, data.fit, data.select, &state.adds));
        let model = match (fitted, state.kept_at) {
            (Ok(m), _) => m,
            // A refused refit tries the next candidate of the kept model, in the same round.
            (Err(e), Some(k)) => match state.set_refused_aside(e, k, round < cfg.max_rounds) {
                Some(stop) => return Ok(stop),
                None => continue,
            },
            (Err(e), None) => {
                return Err(e).with_context(|| format!("round {round} of the identification loop"))
            }
        };
        let (r, adequate) = judge_round(cfg, data, state, model, round);
        let next = r.next.clone();
        let kept = r.kept;
        on_round(&r);
        state.push_round(r);
        if let Some(n) = next {
            state.adds.push(n.spec);
        } else {
            return Ok(stop_without_next(adequate, round == cfg.max_rounds, kept));
        }
        round += 1;
    }
}

/// Judges this round's fitted `model`: its selection fit, its test against the kept model it
/// extends, and, when kept, its diagnoses on every fitting log (a refit not kept sets its
/// addition aside). Returns the round, with the next addition unless this is the last
/// round, and whether the model the next round builds on is adequate.
fn judge_round(
    cfg: &Config,
    data: &LoopData,
    state: &mut LoopState,
    model: Model,
    round: usize,
) -> (Round, bool) {
    let selection_fit = selection_fit(&model, data.select);
    // The selection data is simulated once per model: this round's residual serves its RSS
    // and the test, and the kept model's RSS from its own round is reused when it was run
    // on the same targets (the same velocity window; a fit keeps the model's window, so
    // this is the rule, and a differing window is run again on the refit's targets).
    let residual = selection_residual(&model, data.select);
    let selection_rss = residual
        .as_ref()
        .map_or(f64::INFINITY, |r| sum_of_squares(r));
    let test = state.kept_at.map(|k| {
        let added = state.adds.last().expect("a refit adds an effect");
        let base = &state.rounds[k];
        let same_targets = base.model.sensor.velocity_window == model.sensor.velocity_window;
        let rss0 = || {
            if same_targets && base.selection_rss.is_finite() {
                Ok(base.selection_rss)
            } else {
                Residuals::segmented(data.select, model.sensor.velocity_window)
                    .eval(&base.model)
                    .map(|r| sum_of_squares(&r))
            }
        };
        f_test_of(residual, rss0, added)
    });
    let kept = test.is_none_or(|t| t.p_value < SELECTION_ALPHA);
    let fitted = state.adds.clone();
    let diagnoses: Vec<Diagnosis> = if kept {
        diagnose_each(&model, data.fit, &cfg.diagnose)
    } else {
        state.set_aside.extend(state.adds.pop());
        Vec::new()
    };
    let base = if kept {
        &diagnoses
    } else {
        &state.rounds[state.kept_at.expect("a refit follows a kept round")].diagnoses
    };
    let adequate = base.iter().all(|d| d.verdict.adequate);
    let next = if round == cfg.max_rounds {
        None
    } else {
        next_addition(base, &state.adds, &state.set_aside)
    };
    let r = Round {
        adds: fitted,
        model,
        diagnoses,
        selection_fit,
        selection_rss,
        selection_test: test,
        next,
        kept,
    };
    (r, adequate)
}

/// The diagnosis of `model` on each of `logs`, in order.
fn diagnose_each(model: &Model, logs: &[MotorLog], opts: &diagnose::Options) -> Vec<Diagnosis> {
    let st = Structure::from_model(model);
    logs.iter()
        .map(|l| diagnose::diagnose(l, &st, opts))
        .collect()
}

/// Why a round with nothing to add next ends the loop: the model it builds on is
/// `adequate`, the `last_round` ran, its refit was not `kept`, or nothing is left to add.
fn stop_without_next(adequate: bool, last_round: bool, kept: bool) -> Stop {
    if adequate {
        Stop::Adequate
    } else if last_round {
        Stop::MaxRounds
    } else if !kept {
        Stop::NoGain
    } else {
        Stop::NothingToAdd
    }
}

/// The final structure `adds` refitted on the whole fitting logs, without validation logs.
fn refit_on_whole_logs(
    cfg: &Config,
    fit: &mut dyn FnMut(&FitRequest) -> Result<Model>,
    adds: &[EffectSpec],
) -> Result<Model> {
    fit(&request(cfg, cfg.fit_logs, &[], adds))
        .context("refitting the final model on the whole fitting logs")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::emulator::{simulate_signal, EmulatorConfig, SignalKind};

    static NO_CONSTRAINTS: Constraints = Constraints::NONE;

    /// The loop from a linear model on `logs`, selection held out of them, no constraints.
    fn linear_loop(logs: &[MotorLog], max_rounds: usize) -> Config<'_> {
        Config {
            kind: ModelKind::Linear,
            plant: Plant::Voltage,
            fit_logs: logs,
            select_logs: &[],
            start: Vec::new(),
            constraints: &NO_CONSTRAINTS,
            max_rounds,
            diagnose: diagnose::Options::default(),
        }
    }

    #[test]
    fn split_in_time_keeps_every_sample_once_and_names_the_parts() {
        let log = simulate_signal(&EmulatorConfig::paper(), SignalKind::A, 6.0)
            .unwrap()
            .log;
        let (a, b) = split_in_time(&log, SELECT_FRACTION).unwrap();
        assert_eq!(a.len() + b.len(), log.len());
        assert_eq!(b.t[0], log.t[a.len()]);
        assert_eq!(b.theta.last(), log.theta.last());
        assert_eq!(b.i.as_ref().map(Vec::len), Some(b.len()));
        let share = b.len() as f64 / log.len() as f64;
        // The cut rounds to a whole sample: within half a sample of the fraction.
        assert!(
            (share - SELECT_FRACTION).abs() <= 0.5 / log.len() as f64 + 1e-12,
            "{share}"
        );
        assert!(b.source.to_string_lossy().contains("held out"));
        let mut short = log.clone();
        for v in [&mut short.t, &mut short.u, &mut short.theta] {
            v.truncate(ident::MIN_SAMPLES);
        }
        short.i = None;
        assert!(split_in_time(&short, SELECT_FRACTION).is_err());
    }

    /// On held-out data, the true effect added to a model that lacks it passes the test, and
    /// an effect the motor does not have, added to the true model, does not.
    #[test]
    fn selection_test_keeps_a_real_effect_and_rejects_a_useless_one() {
        let mut cfg = EmulatorConfig::paper();
        cfg.seed = 5;
        let offset = EffectSpec::parse("offset").unwrap();
        cfg.effects = vec![offset.to_effect()];
        let held_out = [simulate_signal(&cfg, SignalKind::B, 20.0).unwrap().log];
        let truth = cfg.truth_model();
        let mut without = truth.clone();
        without.effects.clear();
        let real = selection_test(&without, &truth, &offset, &held_out);
        assert!(real.p_value < SELECTION_ALPHA, "{real:?}");
        // A cogging torque a hundredth of the offset's size: nothing to see in the data.
        let cogging = EffectSpec::parse("cogging:harmonic=5,amp=0.0003,phase=1").unwrap();
        let mut extra = truth.clone();
        extra.effects.push(cogging.to_effect());
        let useless = selection_test(&truth, &extra, &cogging, &held_out);
        assert!(useless.p_value >= SELECTION_ALPHA, "{useless:?}");
    }

    /// A refit that was not kept sets its effect aside: the next proposal is another one.
    #[test]
    fn next_addition_skips_what_was_set_aside() {
        let mut cfg = EmulatorConfig::paper();
        cfg.seed = 2;
        cfg.effects = vec![
            EffectSpec::parse("offset").unwrap().to_effect(),
            EffectSpec::parse("position_load:amp=0.05")
                .unwrap()
                .to_effect(),
        ];
        let log = simulate_signal(&cfg, SignalKind::A, 40.0).unwrap().log;
        let mut model = cfg.truth_model();
        model.effects.clear();
        let d = vec![diagnose::diagnose(
            &log,
            &Structure::from_model(&model),
            &diagnose::Options::default(),
        )];
        let names: Vec<&str> = d[0].effects.iter().map(|f| f.name.as_str()).collect();
        assert!(names.len() >= 2, "two effects are missing, found {names:?}");
        let first = next_addition(&d, &[], &[]).expect("two effects are missing");
        let second = next_addition(&d, &[], std::slice::from_ref(&first.spec))
            .expect("the other effect is still proposed");
        assert_ne!(first.spec.kind, second.spec.kind);
    }

    /// A refit the fit refuses (an effect it cannot estimate) is set aside without a round,
    /// and the loop goes on with the next candidate.
    #[test]
    fn an_effect_the_fit_refuses_is_set_aside_and_the_loop_goes_on() {
        let mut cfg = EmulatorConfig::paper();
        cfg.seed = 4;
        cfg.effects = vec![EffectSpec::parse("offset").unwrap().to_effect()];
        let logs = [simulate_signal(&cfg, SignalKind::A, 30.0).unwrap().log];
        let loop_cfg = linear_loop(&logs, 1);
        let mut refused: Option<EffectKind> = None;
        let out = run(
            &loop_cfg,
            &mut |req| {
                if let Some(a) = req.adds.last() {
                    if refused.is_none_or(|k| k == a.kind) {
                        refused = Some(a.kind);
                        anyhow::bail!("--add {}: not estimable", a.kind.name());
                    }
                }
                Ok(ident::fit(req)?.model)
            },
            &mut |_| {},
        )
        .unwrap();
        let kind = refused.expect("the linear model misses friction: a refit was asked");
        assert_eq!(out.not_fitted.len(), 1, "{:?}", out.not_fitted);
        assert_eq!(out.not_fitted[0].0.kind, kind);
        assert!(out.not_fitted[0].1.contains("not estimable"));
        assert!(out
            .rounds
            .iter()
            .all(|r| r.adds.iter().all(|a| a.kind != kind)));
        assert!(out.rounds.len() <= 2);
    }

    /// On an emulated motor with LuGre friction and a constant load, the linear model's loop
    /// holds out the end of its only log, adds one effect per round, each round refits with
    /// what the last kept round proposed, and the loop ends with a kept model and a stop that
    /// matches its last round.
    #[test]
    fn each_round_adds_what_the_last_kept_one_named_and_the_loop_ends() {
        let mut cfg = EmulatorConfig::paper();
        cfg.seed = 3;
        cfg.effects = vec![EffectSpec::parse("offset").unwrap().to_effect()];
        let log = simulate_signal(&cfg, SignalKind::A, 40.0).unwrap().log;
        let logs = [log];
        let loop_cfg = linear_loop(&logs, 2);
        let mut seen = Vec::new();
        let out = run(&loop_cfg, &mut |req| Ok(ident::fit(req)?.model), &mut |r| {
            seen.push(r.adds.len())
        })
        .unwrap();
        assert!(out.held_out_in_time);
        assert_eq!(seen.len(), out.rounds.len());
        let first = &out.rounds[0];
        assert!(first.kept && first.selection_test.is_none());
        let next = first
            .next
            .as_ref()
            .expect("the linear model misses friction");
        assert!(matches!(next.reason, Reason::Effect { .. }), "{next:?}");
        let (_, select) = split_each_in_time(&logs).unwrap();
        let mut kept = first;
        for r in &out.rounds[1..] {
            let proposed = kept.next.as_ref().expect("a refit follows a proposal");
            assert_eq!(r.adds.len(), kept.adds.len() + 1);
            assert_eq!(r.adds.last().unwrap().kind, proposed.spec.kind);
            let t = r.selection_test.expect("every refit is tested");
            assert_eq!(r.kept, t.p_value < SELECTION_ALPHA);
            // The loop reuses each model's selection residual; running both models again
            // gives the same test, bit for bit.
            let again = selection_test(&kept.model, &r.model, r.adds.last().unwrap(), &select);
            assert_eq!(format!("{t:?}"), format!("{again:?}"));
            if r.kept {
                kept = r;
            }
        }
        let last = out.rounds.last().unwrap();
        assert!(last.next.is_none());
        match out.stop {
            Stop::NoGain => assert!(!last.kept),
            Stop::Adequate => assert!(kept.diagnoses.iter().all(|d| d.verdict.adequate)),
            Stop::MaxRounds => assert_eq!(out.rounds.len(), 3),
            Stop::NothingToAdd => assert!(kept.diagnoses.iter().any(|d| !d.verdict.adequate)),
        }
        assert!(out.final_round().kept);
        assert!(out.final_round().selection_fit.is_finite());
        let all = out.refit_on_all.as_ref().expect("the log was split");
        assert_eq!(all.effects.len(), out.final_round().model.effects.len());
    }
}
