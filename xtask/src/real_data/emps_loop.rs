//! The generic identification loop on the EMPS benchmark: the same code paths as
//! `motorid fit` / `diagnose` / `fit --add` (`ident::fit`, `diagnose::diagnose`,
//! `ident::freerun`), run on data nobody here recorded, read with
//! `--map t=t_s,u=vir_V,theta=qm_m --plant torque`.
//!
//! With `u = vir` [V] and the model's input gain fixed to 1, every force parameter comes out in
//! volts of `vir`; multiplied by gτ = 35.15 N/V it is in newtons (M = gτ·J, Fv = gτ·b, ...).
//! The loop works in millimetres on the logs' own 1 kHz ([`prepare`], [`POSITION_SCALE`],
//! [`DECIMATION`]).
//!
//! The benchmark's test is a free run `vir` → `qm` after a 20-sample initialisation window
//! ([`benchmark_rmse_mm`]): the generic free-run simulation is started at sample 19 from the
//! state that a straight line through the first 20 measured positions gives.
use super::emps;
use anyhow::{Context, Result};
use control::effects::Effect;
use motorid::diagnose::{self, Diagnosis, Structure};
use motorid::effect_spec::EffectSpec;
use motorid::ident::free_params::Constraints;
use motorid::ident::{self, freerun, FitRequest};
use motorid::log::{MotorLog, Plant};
use motorid::model::{Model, ModelKind};
use motorid::numerics::statistics::FTest;
use motorid::workflow;

/// Most refits of the loop (each adds one effect the last kept diagnosis found).
pub const MAX_ROUNDS: usize = 5;
/// Position unit of the loop: millimetres (qm [m] × 1000). The generic tools' velocity
/// constants are set for a motor in rad/s (stick speed 1 rad/s in `diagnose`, smooth sign
/// 0.05 rad/s in `control::effects`); EMPS moves at most 0.13 m/s, so in metres every sample
/// would count as standing still. In mm/s the same constants mean 1 mm/s and 0.05 mm/s.
pub const POSITION_SCALE: f64 = 1000.0;
/// Decimation of the training log: none. The generic tools' windows and speed constants come
/// from the log (seconds, its own speeds), so the loop reads the 1 kHz log as a user's
/// `motorid fit` would, and fits at the rate the benchmark's free-run test simulates.
pub const DECIMATION: usize = 1;

/// The log the loop works on: position in mm, and every `r`-th sample with the input
/// averaged over the `r` samples it stands for (zero-order hold over the new period).
pub fn prepare(log: &MotorLog, r: usize) -> MotorLog {
    let r = r.max(1);
    let n = log.len() / r;
    MotorLog {
        source: log.source.clone(),
        meta: log.meta.clone(),
        t: (0..n).map(|k| log.t[k * r]).collect(),
        u: (0..n)
            .map(|k| log.u[k * r..k * r + r].iter().sum::<f64>() / r as f64)
            .collect(),
        i: None,
        theta: (0..n).map(|k| POSITION_SCALE * log.theta[k * r]).collect(),
        omega: None,
        extra: Vec::new(),
        units: log.units.clone(),
    }
}

/// The benchmark's free-run test of a generic model on an EMPS log prepared by [`prepare`]
/// (position in mm): RMSE [mm] of the simulated position from sample 20 on, and the simulated
/// position [mm] (the first 19 samples are the measurement).
pub fn benchmark_rmse_mm(model: &Model, log: &MotorLog) -> Result<(f64, Vec<f64>)> {
    let n0 = emps::INIT_WINDOW;
    let dt = log.sample_period();
    let (q0, v0) = emps::initial_state(&log.theta, dt, n0);
    let mut tail = MotorLog {
        source: log.source.clone(),
        meta: log.meta.clone(),
        t: log.t[n0 - 1..].to_vec(),
        u: log.u[n0 - 1..].to_vec(),
        i: None,
        theta: log.theta[n0 - 1..].to_vec(),
        // Only its first value is used: the free run's initial velocity.
        omega: Some(vec![v0; log.len() - n0 + 1]),
        extra: Vec::new(),
        units: log.units.clone(),
    };
    tail.theta[0] = q0;
    let pred = freerun::simulate(model, &tail)?;
    let mut sim = log.theta[..n0 - 1].to_vec();
    sim.extend(pred.theta);
    let rmse = emps::rms_diff(&log.theta[n0..], &sim[n0..]);
    Ok((1000.0 * rmse / POSITION_SCALE, sim))
}

/// The rigid-axis numbers of a generic model, in newtons (×gτ): M, Fv, Fc, OF and the
/// asymmetry (dv, dc) when present.
#[derive(Debug, Clone, Copy, Default)]
pub struct Physical {
    pub m: f64,
    pub fv: f64,
    pub fc: Option<f64>,
    pub offset: Option<f64>,
    pub asym: Option<(f64, f64)>,
}

/// Convert a generic model fitted with `u = vir` on a [`prepare`]d log (mm) to newtons and
/// metres.
pub fn physical(m: &Model, gain: f64) -> Physical {
    let g = gain / m.motor.kt;
    let mut p = Physical {
        m: g * m.motor.j * POSITION_SCALE,
        fv: g * m.viscous * POSITION_SCALE,
        ..Physical::default()
    };
    for e in &m.effects {
        match *e {
            Effect::Coulomb { fc } => p.fc = Some(g * fc),
            Effect::Viscous { b } => p.fv += g * b * POSITION_SCALE,
            Effect::Offset { t0 } => p.offset = Some(g * t0),
            Effect::Asymmetry { dv, dc } => p.asym = Some((g * dv * POSITION_SCALE, g * dc)),
            _ => {}
        }
    }
    p
}

/// One round of the loop, scored by the benchmark's test.
#[derive(Debug, Clone)]
pub struct Round {
    /// Effects added to the linear model (specs as `fit --add` takes them).
    pub adds: Vec<String>,
    pub model: Model,
    /// Paper fit % of angle and velocity on the whole training log and on the
    /// test log.
    pub train: ident::Scores,
    pub test: ident::Scores,
    /// Benchmark RMSE [mm] on the test log.
    pub rmse_test_mm: f64,
    /// The test's simulated position [mm].
    pub sim_test: Vec<f64>,
    /// Diagnosis of this model on the data it was fitted on (None for a refit that was not
    /// kept).
    pub diagnosis: Option<Diagnosis>,
    /// Position fit % of the free run on the selection data (the held-out end of the
    /// training log), and the keep-or-not test against the kept model before it.
    pub selection_fit: f64,
    pub selection_test: Option<FTest>,
    /// False when this refit did not explain the selection data significantly better
    /// (see [`workflow`]).
    pub kept: bool,
    /// True for the last row of [`run`]: the final structure refitted on the whole training
    /// log.
    pub whole_log: bool,
}

impl Round {
    /// A fitted model scored on the whole training log and by the benchmark's test.
    fn scored(
        adds: &[EffectSpec],
        model: Model,
        diagnosis: Option<Diagnosis>,
        train: &MotorLog,
        test: &MotorLog,
    ) -> Result<Round> {
        let (rmse_test_mm, sim_test) = benchmark_rmse_mm(&model, test)?;
        Ok(Round {
            adds: adds.iter().map(|a| a.to_string()).collect(),
            train: ident::score(&model, train)?,
            test: ident::score(&model, test)?,
            model,
            rmse_test_mm,
            sim_test,
            diagnosis,
            selection_fit: f64::NAN,
            selection_test: None,
            kept: true,
            whole_log: false,
        })
    }
}

/// The last kept round of [`run`].
pub fn final_round(rounds: &[Round]) -> Option<&Round> {
    rounds.iter().rev().find(|r| r.kept)
}

/// What `diagnose` says about the linear model once Coulomb friction (at the value the first
/// diagnosis found, `fc` in volts of `vir`) is in it: every remaining candidate's test, so
/// that the offset and the asymmetry can be compared (on this trajectory they explain the
/// same residual; see docs/real-data.md).
pub fn after_coulomb(train: &MotorLog, linear: &Model, fc: f64) -> Diagnosis {
    let train = prepare(train, DECIMATION);
    let mut st = Structure::from_model(linear);
    st.effects.push(Effect::Coulomb { fc });
    diagnose::diagnose(&train, &st, &diagnose::Options::default())
}

/// Friction per direction of a generic model in newtons (the authors' asymmetric
/// parametrisation, doc §4.2): (Fv+, Fc+, Fv−, Fc−) from `b ± dv` and `fc ± dc`; the offset,
/// if any, shifts Fc+ up and Fc− down.
pub fn per_direction(p: &Physical) -> (f64, f64, f64, f64) {
    let (dv, dc) = p.asym.unwrap_or((0.0, 0.0));
    let fc = p.fc.unwrap_or(0.0);
    let of = p.offset.unwrap_or(0.0);
    (p.fv + dv, fc + dc + of, p.fv - dv, fc - dc - of)
}

/// The generic linear model with the authors' structures added by name (`fit --add coulomb
/// --add offset [--add asymmetry]`), fitted on the whole training log, for comparison with
/// the loop's own choices.
pub fn authors_structures(train: &MotorLog, test: &MotorLog) -> Result<Vec<Round>> {
    let (train, test) = (&prepare(train, DECIMATION), &prepare(test, 1));
    let fit = |names: &[&str]| -> Result<Round> {
        let adds = names
            .iter()
            .map(|n| EffectSpec::parse(n))
            .collect::<Result<Vec<_>>>()?;
        let model = ident::fit(&FitRequest {
            kind: ModelKind::Linear,
            logs: std::slice::from_ref(train),
            validate: &[],
            adds: &adds,
            plant: Plant::Torque,
            constraints: &Constraints::NONE,
        })?
        .model;
        let d = diagnose::diagnose(
            train,
            &Structure::from_model(&model),
            &diagnose::Options::default(),
        );
        Round::scored(&adds, model, Some(d), train, test)
    };
    Ok(vec![
        fit(&["coulomb", "offset"])?,
        fit(&["coulomb", "offset", "asymmetry"])?,
    ])
}

/// The identification loop of [`workflow::run`] on the training log (linear model, torque
/// plant, the last [`workflow::SELECT_FRACTION`] of the log held out for selection), every
/// round scored by the benchmark's test on `test` (no choice is made on it). `progress` is
/// called with a line per fit. The last round is the final structure refitted on the whole
/// training log.
pub fn run(
    train: &MotorLog,
    test: &MotorLog,
    progress: &mut dyn FnMut(&str),
) -> Result<Vec<Round>> {
    let (train, test) = (&prepare(train, DECIMATION), &prepare(test, 1));
    let cfg = workflow::Config {
        kind: ModelKind::Linear,
        plant: Plant::Torque,
        fit_logs: std::slice::from_ref(train),
        select_logs: &[],
        start: Vec::new(),
        constraints: &Constraints::NONE,
        max_rounds: MAX_ROUNDS,
        diagnose: diagnose::Options::default(),
    };
    let mut fit = |req: &FitRequest| -> Result<Model> {
        let labels: Vec<String> = req.adds.iter().map(|a| a.to_string()).collect();
        progress(&format!(
            "EMPS: fitting linear{}",
            if labels.is_empty() {
                String::new()
            } else {
                format!(" --add {}", labels.join(" --add "))
            }
        ));
        Ok(ident::fit(req)?.model)
    };
    let out = workflow::run(&cfg, &mut fit, &mut |_| {})?;
    let adds = out.final_round().adds.clone();
    let refit = out.refit_on_all.context("the training log was split")?;
    let mut rounds = out
        .rounds
        .into_iter()
        .map(|r| {
            let mut scored = Round::scored(
                &r.adds,
                r.model,
                r.diagnoses.into_iter().next(),
                train,
                test,
            )?;
            scored.selection_fit = r.selection_fit;
            scored.selection_test = r.selection_test;
            scored.kept = r.kept;
            Ok(scored)
        })
        .collect::<Result<Vec<_>>>()?;
    let d = diagnose::diagnose(
        train,
        &Structure::from_model(&refit),
        &diagnose::Options::default(),
    );
    let mut last = Round::scored(&adds, refit, Some(d), train, test)?;
    last.whole_log = true;
    rounds.push(last);
    Ok(rounds)
}
