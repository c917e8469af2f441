//! The identification loop as a library: fit → diagnose → add what the diagnosis names →
//! refit, with one stopping policy. `motorid demo`, the real-data runs and the tests all run
//! this loop; a user runs the same steps by hand with `fit`, `diagnose` and `fit --add`.
//!
//! # Policy
//! Each round fits the model with the effects added so far and diagnoses it on every fitting
//! log. The next addition is the strongest significant effect `diagnose` names that the model
//! does not have yet (over all fitting logs), else, when the model is not adequate, the first
//! variable that carries unexplained structure and comes with a term to add (a `table:`
//! spec). One addition per round, so that each refit answers for one change.
//!
//! The loop stops when
//! - the model is adequate on every fitting log ([`Stop::Adequate`]);
//! - it is not, but nothing named can be added ([`Stop::NothingToAdd`]: the verdict says which
//!   variable carries the rest);
//! - a refit scores worse on the selection logs than the model before it
//!   ([`Stop::Worse`]: that round is kept in the list, marked not kept, and the model before
//!   it stands; only with selection logs apart from the fitting logs: without them the
//!   diagnosis's significance test on the fitting logs is the only judge), or
//! - [`Config::max_rounds`] refits have run ([`Stop::MaxRounds`]).
//!
//! Selection and reporting: the selection logs choose (they are `fit --validate`'s logs and
//! the keep/stop score); scores a user reads should come from other data, which the caller
//! owns (the demo scores a fresh test log no choice was made on).
use crate::diagnose::{self, Diagnosis, Structure};
use crate::effect_spec::EffectSpec;
use crate::ident::free_params::Constraints;
use crate::ident::{self, FitRequest};
use crate::log::{MotorLog, Plant};
use crate::model::{Model, ModelKind};
use anyhow::{Context, Result};
use control::effects::EffectKind;

/// What the loop fits, on which data.
pub struct Config<'a> {
    pub kind: ModelKind,
    pub plant: Plant,
    /// Logs the model is fitted on; each is diagnosed.
    pub fit_logs: &'a [MotorLog],
    /// Logs that choose among models (passed to the fit as validation logs, and scored to
    /// decide whether a refit is kept); empty: none (scores are then on the fitting logs,
    /// for information only).
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

/// One fit and its diagnoses.
#[derive(Debug, Clone)]
pub struct Round {
    /// Effects added to the base model in this round's fit.
    pub adds: Vec<EffectSpec>,
    pub model: Model,
    /// The diagnosis on each fitting log, in order.
    pub diagnoses: Vec<Diagnosis>,
    /// Mean angle fit % on the selection logs ([`selection_fit`]).
    pub selection_fit: f64,
    /// What the next round adds (None on the last round).
    pub next: Option<Next>,
    /// False when this refit scored worse on the selection logs than the round before.
    pub kept: bool,
}

/// Why the loop ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stop {
    Adequate,
    NothingToAdd,
    Worse,
    MaxRounds,
}

/// The rounds of a loop and why it ended.
#[derive(Debug, Clone)]
pub struct Outcome {
    pub rounds: Vec<Round>,
    pub stop: Stop,
}

impl Outcome {
    /// The last kept round: the model the loop ends with.
    pub fn final_round(&self) -> &Round {
        self.rounds
            .iter()
            .rev()
            .find(|r| r.kept)
            .expect("the first round is always kept")
    }
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

/// The addition the diagnoses propose for a model with the effects `adds` (see the policy in
/// the module doc).
pub fn next_addition(diagnoses: &[Diagnosis], adds: &[EffectSpec]) -> Option<Next> {
    let have = |s: &EffectSpec| {
        adds.iter().any(|a| {
            a.kind == s.kind && (a.kind != EffectKind::Table || a.table_var() == s.table_var())
        })
    };
    let named = diagnoses
        .iter()
        .enumerate()
        .flat_map(|(k, d)| d.effects.iter().map(move |f| (k, f)))
        .filter_map(|(k, f)| {
            let spec = EffectSpec::parse(&f.spec).ok()?;
            (!have(&spec)).then_some((k, f, spec))
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
            (!have(&spec)).then(|| Next {
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
/// it is diagnosed.
pub fn run(
    cfg: &Config,
    fit: &mut dyn FnMut(&FitRequest) -> Result<Model>,
    on_round: &mut dyn FnMut(&Round),
) -> Result<Outcome> {
    let select = if cfg.select_logs.is_empty() {
        cfg.fit_logs
    } else {
        cfg.select_logs
    };
    let mut adds = cfg.start.clone();
    let mut rounds: Vec<Round> = Vec::new();
    let mut round = 0;
    loop {
        let model = fit(&FitRequest {
            kind: cfg.kind,
            logs: cfg.fit_logs,
            validate: cfg.select_logs,
            adds: &adds,
            plant: cfg.plant,
            constraints: cfg.constraints,
        })
        .with_context(|| format!("round {round} of the identification loop"))?;
        let score = selection_fit(&model, select);
        // Only held-out logs can say a refit is worse: on the fitting logs a larger model
        // is never worse at its optimum, and their free-run angle fit is dominated by drift.
        let worse = !cfg.select_logs.is_empty()
            && rounds
                .iter()
                .rev()
                .find(|r| r.kept)
                .is_some_and(|prev| score < prev.selection_fit);
        let st = Structure::from_model(&model);
        let diagnoses: Vec<Diagnosis> = cfg
            .fit_logs
            .iter()
            .map(|l| diagnose::diagnose(l, &st, &cfg.diagnose))
            .collect();
        let next = if worse || round == cfg.max_rounds {
            None
        } else {
            next_addition(&diagnoses, &adds)
        };
        let adequate = diagnoses.iter().all(|d| d.verdict.adequate);
        let r = Round {
            adds: adds.clone(),
            model,
            diagnoses,
            selection_fit: score,
            next: next.clone(),
            kept: !worse,
        };
        on_round(&r);
        rounds.push(r);
        let stop = if worse {
            Some(Stop::Worse)
        } else if let Some(n) = next {
            adds.push(n.spec);
            None
        } else if adequate {
            Some(Stop::Adequate)
        } else if round == cfg.max_rounds {
            Some(Stop::MaxRounds)
        } else {
            Some(Stop::NothingToAdd)
        };
        if let Some(stop) = stop {
            return Ok(Outcome { rounds, stop });
        }
        round += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::emulator::{simulate_signal, EmulatorConfig, SignalKind};

    /// On an emulated motor with LuGre friction and a constant load, the linear model's loop
    /// adds one named effect per round, each round refits with what the round before
    /// proposed, and the loop ends with a kept model and a stop that matches its last round.
    #[test]
    fn each_round_adds_what_the_last_one_named_and_the_loop_ends() {
        let mut cfg = EmulatorConfig::paper();
        cfg.seed = 3;
        cfg.effects = vec![EffectSpec::parse("offset").unwrap().to_effect()];
        let log = simulate_signal(&cfg, SignalKind::A, 40.0).unwrap().log;
        let logs = [log];
        let loop_cfg = Config {
            kind: ModelKind::Linear,
            plant: Plant::Voltage,
            fit_logs: &logs,
            select_logs: &[],
            start: Vec::new(),
            constraints: &Constraints::NONE,
            max_rounds: 2,
            diagnose: diagnose::Options::default(),
        };
        let mut seen = Vec::new();
        let out = run(&loop_cfg, &mut |req| Ok(ident::fit(req)?.model), &mut |r| {
            seen.push(r.adds.len())
        })
        .unwrap();
        assert_eq!(seen.len(), out.rounds.len());
        let first = &out.rounds[0];
        let next = first
            .next
            .as_ref()
            .expect("the linear model misses friction");
        assert!(matches!(next.reason, Reason::Effect { .. }), "{next:?}");
        for w in out.rounds.windows(2) {
            let proposed = w[0].next.as_ref().expect("a refit follows a proposal");
            assert_eq!(w[1].adds.len(), w[0].adds.len() + 1);
            assert_eq!(w[1].adds.last().unwrap().kind, proposed.spec.kind);
        }
        let last = out.rounds.last().unwrap();
        assert!(last.next.is_none());
        match out.stop {
            Stop::Worse => assert!(!last.kept),
            Stop::Adequate => assert!(last.diagnoses.iter().all(|d| d.verdict.adequate)),
            Stop::MaxRounds => assert_eq!(out.rounds.len(), 3),
            Stop::NothingToAdd => assert!(last.diagnoses.iter().any(|d| !d.verdict.adequate)),
        }
        assert!(out.final_round().kept);
        assert!(out.final_round().selection_fit.is_finite());
    }
}
