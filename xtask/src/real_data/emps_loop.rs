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
//! state that a straight line through the first 20 measured positions gives
//! ([`protocol_tail`]).
//!
//! The free run of an integrating axis drifts with any force error, so its RMSE depends on
//! the criterion the final parameters minimise: [`criteria`] refits the loop's structure by
//! each [`Criterion`], [`stroke_table_routes`] adds a force that depends on the position
//! along the stroke, and [`choose`] picks one route on the held-out end of the training log
//! alone.
use super::emps;
use anyhow::{Context, Result};
use control::effects::Effect;
use motorid::diagnose::{self, Diagnosis, Structure};
use motorid::effect_spec::EffectSpec;
use motorid::ident::free_params::Constraints;
use motorid::ident::free_params::{Free, Slot};
use motorid::ident::{self, freerun, linear, nlsq, sensor_chain, sim_error, FitRequest};
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
    let pred = freerun::simulate(model, &protocol_tail(log, model.sensor.velocity_window))?;
    let mut sim = log.theta[..n0 - 1].to_vec();
    sim.extend(pred.theta);
    let rmse = emps::rms_diff(&log.theta[n0..], &sim[n0..]);
    Ok((1000.0 * rmse / POSITION_SCALE, sim))
}

/// The part of `log` the benchmark's free run covers, from sample 19 on, starting from the
/// protocol's state: position and velocity of a straight line through the first 20 measured
/// positions ([`emps::initial_state`]). Its velocity column is the estimate over `window`
/// samples (what a fit compares with) with the protocol's velocity as its first value (the
/// free run's initial velocity).
pub fn protocol_tail(log: &MotorLog, window: usize) -> MotorLog {
    let n0 = emps::INIT_WINDOW;
    let (q0, v0) = emps::initial_state(&log.theta, log.sample_period(), n0);
    let t = log.t[n0 - 1..].to_vec();
    let mut theta = log.theta[n0 - 1..].to_vec();
    theta[0] = q0;
    let mut omega = sensor_chain::velocity_estimate(&t, &theta, window);
    omega[0] = v0;
    MotorLog {
        source: log.source.clone(),
        meta: log.meta.clone(),
        u: log.u[n0 - 1..].to_vec(),
        t,
        i: None,
        theta,
        omega: Some(omega),
        extra: Vec::new(),
        units: log.units.clone(),
    }
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

/// The loop's configuration on a prepared training log: a linear model, torque plant, the
/// last [`workflow::SELECT_FRACTION`] held out for selection.
fn loop_config(train: &MotorLog) -> workflow::Config<'_> {
    static NONE: Constraints = Constraints::NONE;
    workflow::Config {
        kind: ModelKind::Linear,
        plant: Plant::Torque,
        fit_logs: std::slice::from_ref(train),
        select_logs: &[],
        start: Vec::new(),
        constraints: &NONE,
        max_rounds: MAX_ROUNDS,
        diagnose: diagnose::Options::default(),
    }
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
    let cfg = loop_config(train);
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

/// How the final structure's parameters are refitted before the benchmark's free run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Criterion {
    /// As `fit` leaves them: its multiple-shooting simulation error (2 s segments).
    AsFitted,
    /// `fit`'s simulation error (velocity and position, each scaled by its spread) over one
    /// free run of the whole log from the protocol's state ([`protocol_tail`]).
    FreeRun,
    /// The benchmark's own criterion: the free-run position error from the protocol's state
    /// (output error).
    OutputError,
}

impl Criterion {
    /// Every criterion, in the order the page lists them.
    pub const ALL: [Criterion; 3] = [
        Criterion::AsFitted,
        Criterion::FreeRun,
        Criterion::OutputError,
    ];

    /// How the page names the route.
    pub fn describe(self) -> &'static str {
        match self {
            Criterion::AsFitted => "as `fit` leaves it (simulation error over 2 s segments)",
            Criterion::FreeRun => {
                "refitted on `fit`'s simulation error over one free run from the protocol's state"
            }
            Criterion::OutputError => {
                "refitted on the free-run position error from the protocol's state (the \
                 benchmark's criterion)"
            }
        }
    }
}

/// The parameters a linear fit of `m`'s structure moves: J, the viscous coefficient and the
/// effects' continuous keys, with the fit's bounds.
fn linear_free(m: &Model) -> Vec<Free> {
    let mut free = linear::motor_free(Plant::Torque);
    free.push(Free {
        slot: Slot::Viscous,
        lo: 0.0,
        hi: 100.0,
    });
    free.extend(linear::effect_free(m));
    free
}

/// `model` (a linear model) refitted on `log` (prepared, mm) by `criterion`, from its own
/// parameters.
pub fn refit(model: &Model, log: &MotorLog, criterion: Criterion) -> Result<Model> {
    let free = linear_free(model);
    let opts = nlsq::Options::default();
    match criterion {
        Criterion::AsFitted => Ok(model.clone()),
        Criterion::FreeRun => {
            let mut m = model.clone();
            let tail = protocol_tail(log, m.sensor.velocity_window);
            let fd = sim_error::Jacobian::FiniteDifferences;
            sim_error::refine(&mut m, &free, &[tail], fd, opts, &mut |_, _| {})?;
            Ok(m)
        }
        Criterion::OutputError => {
            let at = |x: &[f64]| {
                let mut m = model.clone();
                for (f, v) in free.iter().zip(x) {
                    f.slot.set(&mut m, *v);
                }
                m
            };
            let n0 = emps::INIT_WINDOW;
            let residual = |x: &[f64]| -> Result<Vec<f64>> {
                let (_, sim) = benchmark_rmse_mm(&at(x), log)?;
                Ok(sim[n0..]
                    .iter()
                    .zip(&log.theta[n0..])
                    .map(|(a, b)| a - b)
                    .collect())
            };
            let x0: Vec<f64> = free.iter().map(|f| f.slot.get(model)).collect();
            let lo: Vec<f64> = free.iter().map(|f| f.lo).collect();
            let hi: Vec<f64> = free.iter().map(|f| f.hi).collect();
            let scale: Vec<f64> = x0.iter().map(|x| x.abs().max(1e-9)).collect();
            let sol = nlsq::solve_parallel(&residual, &x0, &lo, &hi, &scale, opts, &mut |_, _| {})?;
            Ok(at(&sol.x))
        }
    }
}

/// One way to the final model, scored by the benchmark's free run.
#[derive(Debug, Clone)]
pub struct Route {
    pub kind: ModelKind,
    pub criterion: Criterion,
    /// Nodes of the position table over the stroke added to the loop's structure
    /// ([`stroke_table`]); None for the loop's structure as it is.
    pub table_bins: Option<usize>,
    /// The loop's keep-or-not test of the table ([`workflow::selection_test`] on the
    /// held-out part, against the loop's model there); None without a table.
    pub table_test: Option<FTest>,
    /// RMSE [mm] on the held-out last 30 % of the training log of the model fitted on the
    /// first 70 %: the only score a choice is made on.
    pub held_out_mm: f64,
    /// RMSE [mm] of the whole-log model on the training log and on the test log.
    pub train_mm: f64,
    pub test_mm: f64,
    /// The position table's node forces [N] in the whole-log model (empty without a table).
    pub table_forces_n: Vec<f64>,
    /// The lowest held-out RMSE of the routes compared.
    pub chosen: bool,
}

/// The node values of the first table in `m` (in volts of `vir` for a model fitted with
/// `u = vir`); empty without one.
fn table_values(m: &Model) -> Vec<f64> {
    m.effects
        .iter()
        .find_map(|e| match *e {
            Effect::Table { bins, values, .. } => Some(values[..bins as usize].to_vec()),
            _ => None,
        })
        .unwrap_or_default()
}

/// The training log split as the loop split it (first part, held-out part) and the last
/// round the loop kept on that split.
fn held_out_split<'r>(
    train: &MotorLog,
    rounds: &'r [Round],
) -> Result<(MotorLog, MotorLog, &'r Round)> {
    let (first, held_out) = workflow::split_in_time(train, workflow::SELECT_FRACTION)?;
    let split = rounds
        .iter()
        .rev()
        .find(|r| r.kept && !r.whole_log)
        .context("no kept round")?;
    Ok((first, held_out, split))
}

/// The structure the loop kept, refitted by each [`Criterion`]: on the first 70 % of the
/// training log from the loop's model there (scored on the held-out 30 %), and on the whole
/// training log from the loop's final model (scored on both logs). `rounds` are [`run`]'s.
pub fn criteria(train: &MotorLog, test: &MotorLog, rounds: &[Round]) -> Result<Vec<Route>> {
    let (train, test) = (&prepare(train, DECIMATION), &prepare(test, 1));
    let (first, held_out, split) = held_out_split(train, rounds)?;
    let whole = rounds
        .iter()
        .find(|r| r.whole_log)
        .context("no whole-log refit")?;
    let score = |m: &Model, log: &MotorLog| benchmark_rmse_mm(m, log).map_or(f64::NAN, |r| r.0);
    let mut out = Vec::new();
    for criterion in Criterion::ALL {
        let on_split = refit(&split.model, &first, criterion)?;
        let on_all = refit(&whole.model, train, criterion)?;
        out.push(Route {
            kind: ModelKind::Linear,
            criterion,
            table_bins: None,
            table_test: None,
            held_out_mm: score(&on_split, &held_out),
            train_mm: score(&on_all, train),
            test_mm: score(&on_all, test),
            table_forces_n: Vec::new(),
            chosen: false,
        });
    }
    Ok(out)
}

/// Node counts of the position tables [`stroke_table_routes`] tries: from a coarse trend
/// to the finest a table holds ([`control::effects::TABLE_MAX_BINS`], about 16 mm between
/// nodes over the EMPS stroke).
pub const STROKE_TABLE_BINS: [usize; 4] = [4, 8, 12, control::effects::TABLE_MAX_BINS];

/// Criteria the page refits the routes with a position table by: as fitted and the
/// benchmark's own criterion (the two ends of [`Criterion::ALL`]).
pub const STROKE_TABLE_CRITERIA: [Criterion; 2] = [Criterion::AsFitted, Criterion::OutputError];

/// A force over the position along the stroke of `log` (prepared, mm): `fit --add
/// table:var=theta,bins=N,lo=..,hi=..` with its nodes from the lowest to the highest
/// position the log reaches (a linear axis: the table does not wrap around).
pub fn stroke_table(log: &MotorLog, bins: usize) -> Result<EffectSpec> {
    let (lo, hi) = log
        .theta
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        });
    EffectSpec::parse(&format!("table:var=theta,bins={bins},lo={lo},hi={hi}"))
}

/// The loop's structure plus a position table over the stroke ([`stroke_table`], each of
/// `bins`), refitted by each of `criteria`: fitted on the first 70 % of the
/// training log (the held-out 30 % as the fit's validation data, as in the loop) and scored
/// on the held-out part, then fitted on the whole training log and scored on both logs. Each
/// route also carries the loop's own keep-or-not test of the table on the held-out part.
/// `rounds` are [`run`]'s.
pub fn stroke_table_routes(
    train: &MotorLog,
    test: &MotorLog,
    rounds: &[Round],
    bins: &[usize],
    criteria: &[Criterion],
) -> Result<Vec<Route>> {
    let (train, test) = (&prepare(train, DECIMATION), &prepare(test, 1));
    let (first, held_out, split) = held_out_split(train, rounds)?;
    let base = split
        .adds
        .iter()
        .map(|a| EffectSpec::parse(a))
        .collect::<Result<Vec<_>>>()?;
    let score = |m: &Model, log: &MotorLog| benchmark_rmse_mm(m, log).map_or(f64::NAN, |r| r.0);
    let mut out = Vec::new();
    for &n in bins {
        let table = stroke_table(train, n)?;
        let adds: Vec<EffectSpec> = base.iter().cloned().chain([table.clone()]).collect();
        let fit = |logs: &[MotorLog], validate: &[MotorLog]| -> Result<Model> {
            Ok(ident::fit(&FitRequest {
                kind: ModelKind::Linear,
                logs,
                validate,
                adds: &adds,
                plant: Plant::Torque,
                constraints: &Constraints::NONE,
            })?
            .model)
        };
        let held = std::slice::from_ref(&held_out);
        let on_split = fit(std::slice::from_ref(&first), held)?;
        let on_all = fit(std::slice::from_ref(train), &[])?;
        let table_test = workflow::selection_test(&split.model, &on_split, &table, held);
        for &criterion in criteria {
            let (s, a) = (
                refit(&on_split, &first, criterion)?,
                refit(&on_all, train, criterion)?,
            );
            out.push(Route {
                kind: ModelKind::Linear,
                criterion,
                table_bins: Some(n),
                table_test: Some(table_test),
                held_out_mm: score(&s, &held_out),
                train_mm: score(&a, train),
                test_mm: score(&a, test),
                table_forces_n: table_values(&a)
                    .iter()
                    .map(|v| v * emps::GTAU / a.motor.kt)
                    .collect(),
                chosen: false,
            });
        }
    }
    Ok(out)
}

/// The loop of [`run`] with a LuGre model (`motorid fit --model lugre --plant torque` and its
/// `diagnose`/`fit --add` steps), as fitted: its kept model on the first 70 % scored on the
/// held-out 30 %, its final refit on the whole training log on both logs.
pub fn lugre_route(train: &MotorLog, test: &MotorLog) -> Result<(Route, Vec<String>)> {
    let (train, test) = (&prepare(train, DECIMATION), &prepare(test, 1));
    let (_, held_out) = workflow::split_in_time(train, workflow::SELECT_FRACTION)?;
    let cfg = workflow::Config {
        kind: ModelKind::Lugre,
        ..loop_config(train)
    };
    let out = workflow::run(&cfg, &mut |req| Ok(ident::fit(req)?.model), &mut |_| {})?;
    let score = |m: &Model, log: &MotorLog| benchmark_rmse_mm(m, log).map_or(f64::NAN, |r| r.0);
    let adds = out
        .final_round()
        .adds
        .iter()
        .map(|a| a.to_string())
        .collect();
    let route = Route {
        kind: ModelKind::Lugre,
        criterion: Criterion::AsFitted,
        table_bins: None,
        table_test: None,
        held_out_mm: score(&out.final_round().model, &held_out),
        train_mm: score(out.final_model(), train),
        test_mm: score(out.final_model(), test),
        table_forces_n: Vec::new(),
        chosen: false,
    };
    Ok((route, adds))
}

/// Mark the route with the lowest held-out RMSE as chosen.
pub fn choose(routes: &mut [Route]) {
    let best = routes
        .iter()
        .enumerate()
        .filter(|(_, r)| r.held_out_mm.is_finite())
        .min_by(|a, b| a.1.held_out_mm.total_cmp(&b.1.held_out_mm))
        .map(|(k, _)| k);
    for (k, r) in routes.iter_mut().enumerate() {
        r.chosen = Some(k) == best;
    }
}

/// The benchmark's test RMSE [mm] of `model` with a constant force of each of `forces_n`
/// [N] added (an offset effect, `gain` newtons per volt of the input): how much of the free
/// run's error a force bias far below the friction's uncertainty decides.
pub fn force_bias_sensitivity(
    model: &Model,
    test: &MotorLog,
    gain: f64,
    forces_n: &[f64],
) -> Result<Vec<(f64, f64)>> {
    let test = prepare(test, 1);
    forces_n
        .iter()
        .map(|&f| {
            let mut m = model.clone();
            m.effects.push(Effect::Offset {
                t0: f * m.motor.kt / gain,
            });
            Ok((f, benchmark_rmse_mm(&m, &test)?.0))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 1 kHz log of an axis moving at 20 mm/s from 5 mm.
    fn ramp_log(n: usize) -> MotorLog {
        let t: Vec<f64> = (0..n).map(|k| k as f64 * 1e-3).collect();
        MotorLog {
            source: "ramp.csv".into(),
            meta: Default::default(),
            theta: t.iter().map(|t| 5.0 + 20.0 * t).collect(),
            u: vec![0.1; n],
            t,
            i: None,
            omega: None,
            extra: Vec::new(),
            units: Default::default(),
        }
    }

    #[test]
    fn the_protocol_tail_starts_at_sample_19_from_the_fitted_line() {
        let log = ramp_log(200);
        let tail = protocol_tail(&log, 4);
        let n0 = emps::INIT_WINDOW;
        assert_eq!(tail.len(), log.len() - n0 + 1);
        assert_eq!(tail.t[0], log.t[n0 - 1]);
        // On a straight line the fitted state is the line's own position and slope.
        assert!((tail.theta[0] - log.theta[n0 - 1]).abs() < 1e-9);
        let omega = tail.omega.as_ref().unwrap();
        assert!(
            (omega[0] - 20.0).abs() < 1e-6,
            "initial velocity {}",
            omega[0]
        );
        // Later samples carry the velocity estimate a fit compares with.
        assert!((omega[50] - 20.0).abs() < 1e-6, "velocity {}", omega[50]);
    }

    fn route(held_out_mm: f64) -> Route {
        Route {
            kind: ModelKind::Linear,
            criterion: Criterion::AsFitted,
            table_bins: None,
            table_test: None,
            held_out_mm,
            train_mm: 1.0,
            test_mm: 1.0,
            table_forces_n: Vec::new(),
            chosen: false,
        }
    }

    #[test]
    fn the_route_with_the_lowest_held_out_error_is_chosen_and_only_it() {
        let mut routes = vec![route(4.0), route(f64::NAN), route(3.0), route(5.0)];
        choose(&mut routes);
        let chosen: Vec<bool> = routes.iter().map(|r| r.chosen).collect();
        assert_eq!(chosen, [false, false, true, false]);
    }
}
