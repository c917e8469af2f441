//! `motorid demo`: the identification loop ([`workflow::run`]) on the built-in emulator with a
//! hidden physical effect: simulate fitting (signals a and d), selection (signal b: it decides
//! which refits are kept) and test data (another draw of signal b, on which no choice is
//! made); print the test fit after each step, name the hidden effect and whether it was found.
use crate::diagnose::{self, Options};
use crate::effect_spec::EffectSpec;
use crate::emulator::{simulate_signal, EmulatorConfig, SignalKind};
use crate::ident::free_params::Constraints;
use crate::ident::{self, FitRequest};
use crate::log::{MotorLog, Plant};
use crate::model::{Model, ModelKind};
use crate::report::{self, Iteration};
use crate::workflow;
use anyhow::{Context, Result};
use control::effects::EffectKind;
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;

/// Effects the demo may hide (`--random`): those a LuGre model lacks and `diagnose` can name,
/// i.e. the effects after the four of its own friction law (coulomb, viscous, stribeck,
/// presliding) in the effect list's order, up to load friction (saturation is reported through
/// the variable that carries it, not by name).
pub const RANDOM_EFFECTS: &[EffectKind] = EffectKind::ALL.split_at(12).0.split_at(4).1;

/// Effect the demo hides when neither `--effect` nor `--random` is given: a constant load
/// torque (`offset`, 0.03 N·m, a third of the motor's Coulomb friction). It enters the torque
/// balance as one constant column, which the diagnosis tests directly and `fit --add`
/// estimates as one more linear coefficient: `motorid demo` with no argument shows the whole
/// loop, the error falling included.
pub const DEFAULT_EFFECT: EffectKind = EffectKind::Offset;

/// Physics outside the effect list that the demo can hide (`--unnamed`), through the
/// emulator's extra load: no named effect has its law, so the loop can only add a table on
/// the variable that carries it (after any named effect that takes part of it).
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Unnamed {
    /// A fan or pump on the shaft: an aerodynamic drag c·ω·|ω| with c = 1e-5 N·m·s²/rad²
    /// (0.016 N·m at 40 rad/s), quadratic in the speed where the list's friction laws are
    /// constant or linear in it.
    Fan,
    /// A cam on the shaft lifting a spring-loaded follower (a valve or plunger drive): the
    /// cam lifts it 5 mm over 240° against a spring of 5 N preload and 1 kN/m, holds it for
    /// 30° and lets it fall back over 90°: a load that depends on the angle alone but is no
    /// sinusoid, so the list's one-harmonic angle terms take only part of it.
    Cam,
}

/// Drag coefficient of [`Unnamed::Fan`] [N·m·s²/rad²]: 0.016 N·m at the fitting signal's RMS
/// speed (40 rad/s), a sixth of the paper motor's Coulomb friction, 0.23 N·m at its fastest.
pub const FAN_DRAG: f64 = 1e-5;

/// Lift of [`Unnamed::Cam`]'s follower [m].
pub const CAM_LIFT: f64 = 5e-3;
/// Spring force on [`Unnamed::Cam`]'s follower at the bottom of its travel [N].
pub const CAM_PRELOAD: f64 = 5.0;
/// Stiffness of [`Unnamed::Cam`]'s follower spring [N/m].
pub const CAM_STIFFNESS: f64 = 1000.0;
/// Angles of [`Unnamed::Cam`]'s rise, dwell at the top and fall [rad]; the rest of the
/// revolution is a dwell at the bottom.
pub const CAM_RISE: f64 = 4.0 * std::f64::consts::PI / 3.0;
/// See [`CAM_RISE`].
pub const CAM_DWELL: f64 = std::f64::consts::PI / 6.0;
/// See [`CAM_RISE`].
pub const CAM_FALL: f64 = std::f64::consts::PI / 2.0;

/// Cycloidal motion over `span` [rad] at `phi` into it: the follower's lift as a share of
/// the full lift, and its derivative over the angle [1/rad] (zero speed and acceleration at
/// both ends, the standard cam law for a follower held by a spring).
fn cycloidal(phi: f64, span: f64) -> (f64, f64) {
    let q = std::f64::consts::TAU * phi / span;
    (
        phi / span - q.sin() / std::f64::consts::TAU,
        (1.0 - q.cos()) / span,
    )
}

/// Load torque of [`Unnamed::Cam`] at the rotor angle `theta` [N·m, opposing positive
/// motion]: with the follower's lift s(θ) and the spring's force F = F0 + k·s, the work the
/// shaft does is F·ds, so the torque is F·ds/dθ whatever the follower's geometry (no
/// friction in the follower). It is conservative: its mean over a revolution is zero.
pub fn cam_torque(theta: f64) -> f64 {
    let phi = theta.rem_euclid(std::f64::consts::TAU);
    let (lift, slope) = if phi < CAM_RISE {
        cycloidal(phi, CAM_RISE)
    } else if phi < CAM_RISE + CAM_DWELL {
        (1.0, 0.0)
    } else if phi < CAM_RISE + CAM_DWELL + CAM_FALL {
        let (l, d) = cycloidal(phi - CAM_RISE - CAM_DWELL, CAM_FALL);
        (1.0 - l, -d)
    } else {
        (0.0, 0.0)
    };
    (CAM_PRELOAD + CAM_STIFFNESS * CAM_LIFT * lift) * CAM_LIFT * slope
}

impl Unnamed {
    /// What the user reads about it.
    pub fn describe(self) -> String {
        match self {
            Unnamed::Fan => {
                format!("fan drag {FAN_DRAG:e}·ω·|ω| N·m (a law the effect list lacks)")
            }
            Unnamed::Cam => format!(
                "a cam lifting a spring-loaded follower {:.0} mm over {:.0}° and dropping it over \
                 {:.0}° once a revolution, up to {:.3} N·m (an angle profile the effect list lacks)",
                CAM_LIFT * 1e3,
                CAM_RISE.to_degrees(),
                CAM_FALL.to_degrees(),
                cam_peak()
            ),
        }
    }

    /// The table variable that should carry it.
    pub fn carrier(self) -> control::effects::TableVar {
        match self {
            Unnamed::Fan => control::effects::TableVar::Omega,
            Unnamed::Cam => control::effects::TableVar::Theta,
        }
    }

    /// Its load torque [N·m] at a true state.
    pub fn torque(self, x: crate::emulator::LoadInputs) -> f64 {
        match self {
            Unnamed::Fan => FAN_DRAG * x.omega * x.omega.abs(),
            Unnamed::Cam => cam_torque(x.theta),
        }
    }

    fn hide(self, cfg: EmulatorConfig) -> EmulatorConfig {
        cfg.with_extra_load(move |x| self.torque(x))
    }
}

/// Largest magnitude of [`cam_torque`] over a revolution [N·m] (on a 0.1° grid).
fn cam_peak() -> f64 {
    (0..3600)
        .map(|k| cam_torque(f64::from(k).to_radians() / 10.0).abs())
        .fold(0.0, f64::max)
}

/// Most diagnose → add → refit rounds.
pub const MAX_ROUNDS: usize = 4;
/// Length of the fitting and validation signals [s]: long enough for the slow (0.05 Hz)
/// validation components and a thermal time constant of 20 s, short enough that the demo
/// runs in about a minute on two cores.
pub const DURATION: f64 = 90.0;
/// Length of the braking experiment (signal d, voltage steps) fitted and diagnosed beside
/// signal a [s]: 17-25 braking transients a minute on the paper motor. (Without it, a
/// hidden load_friction was NOT FOUND: fitted on signal a alone it is a lower K_t.)
pub const STEP_DURATION: f64 = 30.0;

/// Run the whole loop on the emulator with a hidden effect.
#[derive(clap::Args, Debug)]
#[command(
    after_help = "Without --effect, the hidden effect is offset (a constant load torque) at its default size and the seed \
    is 1, so a bare `motorid demo` always runs the same case. With --random, one effect is \
    drawn (from the seed) among: cogging, position_load, offset, asymmetry, deadtime, \
    current_offset, thermal, load_friction, with its default size. Give --effect more than once to hide several.\n\n\
    Each round: fit a LuGre model (with the effects added so far) on signal a plus 30 s of \
    the step signal d (a braking experiment: load_friction shows only where the drive brakes \
    the moving rotor, which signal a never does), score it (fit %, the paper's eq. 48) on a \
    second draw of signal b that no choice is made on, diagnose it on a and on d, add \
    the strongest new finding (or, when no effect of the list is left but the model is not \
    adequate, a table on the variable that carries the rest). A refit is kept only when it \
    explains signal b significantly better (F-test at the 1 % level); otherwise the next \
    finding is tried. Stops when the model is adequate, nothing is left to add, or after 4 refits.\n\n\
    --unnamed hides physics the effect list has no law for, instead of the default effect: fan \
    (a drag c·ω·|ω|, carried by omega) or cam (a cam lifting a spring-loaded follower once a \
    revolution, carried by theta; the one-harmonic angle terms position_load and cogging take \
    part of it first). The loop can take the rest in only through a table on the variable that \
    carries it, and the demo prints the start and final models' load torque against the true \
    one, as RMS over the test run's true states."
)]
pub struct Args {
    /// Hidden effect, NAME or NAME:key=value,... (repeatable; default: offset).
    #[arg(long, value_name = "SPEC")]
    pub effect: Vec<String>,
    /// Hide one effect drawn at random from the seed instead of the default (ignored with --effect).
    #[arg(long)]
    pub random: bool,
    /// Hide physics outside the effect list (instead of the default effect; with --effect,
    /// beside it).
    #[arg(long, value_enum, value_name = "KIND")]
    pub unnamed: Option<Unnamed>,
    /// Seed of the emulator's noise, the signals and the random effect.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Where to write the HTML report.
    #[arg(long, value_name = "DIR", default_value = "out/demo-report")]
    pub report: PathBuf,
    /// Length of each signal in seconds.
    #[arg(long, value_name = "S", default_value_t = DURATION)]
    pub duration: f64,
    /// No progress bar on stderr (it is shown only when stderr is a terminal).
    #[arg(short, long)]
    pub quiet: bool,
}

/// Share of the start model's gap to the true model's test fit that the final model must
/// close on every channel for a named effect to count as found: one half
/// (docs/decisions/0010-found-means-near-the-truth.md).
pub const GAP_CLOSED: f64 = 0.5;
/// Distance to the true model's test fit [fit-% points] within which a channel counts as
/// closed whatever its start: 1 point, about the spread of one model's test fit over fresh
/// draws of the noise, so that a gap that was tiny to begin with is not judged by its noise.
pub const NEAR_TRUTH: f64 = 1.0;

/// How far the final model is from the truth, on the fresh test log (fit %, eq. 48).
#[derive(Debug, Clone, Copy)]
pub struct Closeness {
    /// The model the loop started from (no effect added).
    pub start: ident::Fits,
    /// The final model.
    pub last: ident::Fits,
    /// The emulator's own model (its constants, LuGre law and hidden effects).
    pub truth: ident::Fits,
}

impl Closeness {
    /// Each channel scored in all three: (name, share of the start's gap closed, distance of
    /// the final model to the truth in points, closed enough).
    pub fn channels(&self) -> Vec<(&'static str, f64, f64, bool)> {
        let trio = [
            (
                "x",
                Some(self.start.x),
                Some(self.last.x),
                Some(self.truth.x),
            ),
            (
                "xdot",
                Some(self.start.xdot),
                Some(self.last.xdot),
                Some(self.truth.xdot),
            ),
            ("i", self.start.i, self.last.i, self.truth.i),
        ];
        trio.into_iter()
            .filter_map(|(name, a, b, t)| {
                let (a, b, t) = (a?, b?, t?);
                let gap = t - a;
                let closed = if gap > 0.0 { (b - a) / gap } else { 1.0 };
                let ok = t - b <= NEAR_TRUTH.max((1.0 - GAP_CLOSED) * gap);
                Some((name, closed, t - b, ok))
            })
            .collect()
    }

    /// The final model is within the stated distance of the truth on every channel.
    pub fn near_truth(&self) -> bool {
        self.channels().iter().all(|c| c.3)
    }

    /// One line: each channel's share of the gap closed and distance to the truth.
    pub fn describe(&self) -> String {
        self.channels()
            .iter()
            .map(|(n, closed, dist, _)| {
                format!(
                    "{n}: {:.0} % of the gap closed, {dist:.2} points from the truth",
                    100.0 * closed
                )
            })
            .collect::<Vec<_>>()
            .join("; ")
    }
}

/// The outcome of a demo run (for tests and the report).
#[derive(Debug, Clone)]
pub struct Outcome {
    pub hidden: Vec<EffectSpec>,
    pub unnamed: Option<Unnamed>,
    pub iterations: Vec<Iteration>,
    /// Effects added, in order.
    pub added: Vec<EffectSpec>,
    /// The final model against the truth on the test log; `None` where the truth is no model
    /// of the list's terms (unnamed physics).
    pub closeness: Option<Closeness>,
    /// With unnamed physics: the models' load torque against the true one over the test
    /// run's states.
    pub torque: Option<TorqueDistance>,
    pub report: Option<PathBuf>,
}

/// How far a model's load torque is from the true one, as RMS over the true states of the
/// test run [N·m]: where the truth is no model of the list's terms (unnamed physics hidden),
/// the distance that still means something is between the torques themselves, whatever
/// terms make them up.
#[derive(Debug, Clone, Copy)]
pub struct TorqueDistance {
    /// The model the loop started from (no effect added).
    pub start: f64,
    /// The final model.
    pub last: f64,
    /// RMS of the hidden physics' own torque, the start's distance had the rest been exact.
    pub hidden: f64,
}

/// A model's load torque at a true state [N·m]: its friction law at steady state (the
/// bristles settled; the sign smoothed over the model's own width) and its effects' torques.
fn model_load_torque(m: &Model, x: crate::emulator::LoadInputs) -> f64 {
    let lugre = m.lugre.map_or(0.0, |p| {
        p.s(x.omega) * control::effects::smooth_sign(x.omega, m.sign_width) + p.alpha2 * x.omega
    });
    let friction = lugre + m.viscous * x.omega;
    let e = control::effects::EffectInputs {
        theta: x.theta,
        omega: x.omega,
        current: x.i,
        kt: m.motor.kt,
    };
    friction + control::effects::total_torque_with_width(&m.effects, &e, m.sign_width)
}

impl Outcome {
    /// True when every hidden effect's kind was added and the final model is within the
    /// stated distance of the truth ([`Closeness::near_truth`]), and a table on the variable
    /// that carries the unnamed physics was added.
    pub fn found_all(&self) -> bool {
        self.hidden.iter().all(|h| self.named(h))
            && (self.hidden.is_empty() || self.closeness.is_none_or(|c| c.near_truth()))
            && self.unnamed.is_none_or(|u| self.table_found(u))
    }

    /// True when an effect of the hidden one's kind was added.
    pub fn named(&self, h: &EffectSpec) -> bool {
        self.added.iter().any(|a| a.kind == h.kind)
    }

    /// True when a table on the variable that carries `u` was added.
    pub fn table_found(&self, u: Unnamed) -> bool {
        self.added
            .iter()
            .any(|a| a.kind == EffectKind::Table && a.table_var() == u.carrier())
    }
}

fn label(adds: &[EffectSpec]) -> String {
    let mut s = String::from("LuGre");
    for a in adds {
        s.push_str(" + ");
        if a.kind == EffectKind::Table {
            s.push_str(&format!("table({})", a.table_var().name()));
        } else {
            s.push_str(a.kind.name());
        }
    }
    s
}

/// The demo loop ([`workflow::run`] on emulated logs); `say` receives each line for the
/// terminal.
pub fn run_loop(
    hidden: &[EffectSpec],
    unnamed: Option<Unnamed>,
    seed: u64,
    duration: f64,
    report_dir: Option<&std::path::Path>,
    say: &mut dyn FnMut(&str),
    bar: &ProgressBar,
) -> Result<Outcome> {
    bar.set_message("simulating signals a and d (fit), b (selection) and b (test)");
    let logs = DemoLogs::emulate(hidden, unnamed, seed, duration)?;
    bar.inc(1);
    let test_log = &logs.test;
    let loop_cfg = workflow::Config {
        kind: ModelKind::Lugre,
        plant: Plant::Voltage,
        fit_logs: &logs.fit,
        select_logs: std::slice::from_ref(&logs.select),
        start: Vec::new(),
        constraints: &Constraints::NONE,
        max_rounds: MAX_ROUNDS,
        diagnose: Options::default(),
    };
    let mut fit = fit_on_bar(bar);
    let mut iterations = Vec::new();
    let mut scored: Result<()> = Ok(());
    // The selection statistic of the model a refit is tested against.
    let mut kept_rss: Option<f64> = None;
    let mut on_round = |r: &workflow::Round| {
        let sc = match ident::score(&r.model, test_log) {
            Ok(sc) => sc,
            Err(e) => {
                scored = Err(e);
                return;
            }
        };
        say_round(say, iterations.len(), r, &sc, kept_rss);
        if r.kept {
            kept_rss = Some(r.selection_rss);
        }
        iterations.push(Iteration {
            label: if r.kept {
                label(&r.adds)
            } else {
                format!("{} (not kept)", label(&r.adds))
            },
            validation: sc.fit,
            added: r.next.as_ref().map(|n| n.spec.to_string()),
        });
    };
    let out = workflow::run(&loop_cfg, &mut fit, &mut on_round)?;
    scored?;
    let last = out.final_round();
    let (pred, final_fit) = say_final(say, &out, test_log)?;
    let closeness = say_closeness(say, &logs, &iterations, final_fit)?;
    let torque = unnamed.map(|u| {
        let d = torque_distance(
            u,
            &logs,
            out.rounds.first().map_or(&last.model, |r| &r.model),
            &last.model,
        );
        say(&format!(
            "final model against the truth: load torque over the test run's true states, RMS \
             error {:.4} N·m (start model: {:.4} N·m; the unnamed physics' own torque: {:.4} N·m \
             RMS)",
            d.last, d.start, d.hidden
        ));
        d
    });
    let mut outcome = Outcome {
        hidden: hidden.to_vec(),
        unnamed,
        iterations,
        added: last.adds.clone(),
        closeness,
        torque,
        report: None,
    };
    if let Some(dir) = report_dir {
        bar.set_message("writing the report");
        outcome.report = Some(write_report(dir, &outcome, last, test_log, &pred)?);
    }
    Ok(outcome)
}

/// The loop's fit, its stage and progress shown on `bar`, one round after another.
fn fit_on_bar(bar: &ProgressBar) -> impl FnMut(&FitRequest) -> Result<Model> + '_ {
    let mut round = 0;
    move |req: &FitRequest| -> Result<Model> {
        let what = format!("round {round}: fitting {}", label(req.adds));
        round += 1;
        bar.set_message(what.clone());
        let b = bar.clone();
        let show = move |u: &ident::progress::Update| {
            b.set_message(format!("{what}: {}", super::fit::progress_message(u)))
        };
        let model = ident::progress::observe(show, || ident::fit(req))?.model;
        bar.inc(1);
        bar.set_message("scoring on signal b and diagnosing on a and d");
        Ok(model)
    }
}

/// The effects set aside and the final model's test fit; returns its free run on the test
/// log.
fn say_final(
    say: &mut dyn FnMut(&str),
    out: &workflow::Outcome,
    test_log: &MotorLog,
) -> Result<(ident::Prediction, ident::Fits)> {
    for (spec, why) in &out.not_fitted {
        say(&format!(
            "set aside: {} was named but cannot be fitted: {}",
            spec.kind.name(),
            why.lines().next().unwrap_or_default()
        ));
    }
    let last = out.final_round();
    let pred = ident::freerun::simulate(&last.model, test_log)?;
    let sc = ident::score_prediction(&last.model, test_log, &pred)?;
    say(&format!(
        "final model: {} — test fit on fresh signal b, no choice made on it: x {:.2} %, xdot {:.2} %, i {}",
        label(&last.adds),
        sc.fit.x,
        sc.fit.xdot,
        sc.fit.i.map(|v| format!("{v:.2} %")).unwrap_or_else(|| "-".into())
    ));
    Ok((pred, sc.fit))
}

/// The final model against the truth on the test log, said in one line; `None` where the
/// truth is no model of the list's terms (unnamed physics hidden) or no round ran.
fn say_closeness(
    say: &mut dyn FnMut(&str),
    logs: &DemoLogs,
    iterations: &[Iteration],
    last: ident::Fits,
) -> Result<Option<Closeness>> {
    let (Some(truth), Some(first)) = (&logs.truth, iterations.first()) else {
        return Ok(None);
    };
    let c = Closeness {
        start: first.validation,
        last,
        truth: ident::score(truth, &logs.test)?.fit,
    };
    say(&format!(
        "final model against the true model (test fit on fresh signal b: x {:.2} %, xdot {:.2} %, i {}): {}",
        c.truth.x,
        c.truth.xdot,
        c.truth.i.map(|v| format!("{v:.2} %")).unwrap_or_else(|| "-".into()),
        c.describe()
    ));
    Ok(Some(c))
}

/// The demo's emulated logs: signals a and d to fit, b to select refits, a fresh b to test.
struct DemoLogs {
    fit: [MotorLog; 2],
    select: MotorLog,
    test: MotorLog,
    /// The emulator's own model; `None` when unnamed physics is hidden (no model of the
    /// list's terms is the truth then).
    truth: Option<crate::model::Model>,
    /// The emulator's model without the unnamed physics, and the test run's true states.
    named_truth: crate::model::Model,
    test_states: crate::emulator::Truth,
}

impl DemoLogs {
    /// Emulate the paper's motor with the `hidden` effects (and the `unnamed` one), each
    /// log with its own noise seed.
    fn emulate(
        hidden: &[EffectSpec],
        unnamed: Option<Unnamed>,
        seed: u64,
        duration: f64,
    ) -> Result<DemoLogs> {
        let mut cfg = EmulatorConfig::paper();
        cfg.seed = seed;
        cfg.effects = hidden.iter().map(EffectSpec::to_effect).collect();
        if let Some(u) = unnamed {
            cfg = u.hide(cfg);
        }
        let sim = |offset: u64, kind: SignalKind, duration: f64, name: &str| {
            let mut c = cfg.clone();
            c.seed = seed.wrapping_add(offset);
            let mut res = simulate_signal(&c, kind, duration)?;
            res.log.source = PathBuf::from(name);
            anyhow::Ok(res)
        };
        let fit_log = sim(0, SignalKind::A, duration, "emulated signal a")?.log;
        // The braking experiment: after each voltage step down the drive brakes the moving
        // rotor, the only place where load-dependent friction differs from a lower K_t.
        let step_log = sim(2000, SignalKind::D, STEP_DURATION, "emulated signal d")?.log;
        let select = sim(1000, SignalKind::B, duration, "emulated signal b")?.log;
        // The selection log decides which refits are kept; the scores are reported on a
        // fresh log that no choice was made on.
        let test = sim(3000, SignalKind::B, duration, "emulated signal b (test)")?;
        Ok(DemoLogs {
            fit: [fit_log, step_log],
            select,
            test: test.log,
            truth: unnamed.is_none().then(|| cfg.truth_model()),
            named_truth: cfg.truth_model(),
            test_states: test.truth,
        })
    }
}

/// The start and final models' load torque against the true one (the emulator's named
/// part and the unnamed physics `u`) over the true states of the test run.
fn torque_distance(u: Unnamed, logs: &DemoLogs, start: &Model, last: &Model) -> TorqueDistance {
    let s = &logs.test_states;
    let states: Vec<crate::emulator::LoadInputs> = (0..s.theta.len())
        .map(|k| crate::emulator::LoadInputs {
            t: logs.test.t[k],
            theta: s.theta[k],
            omega: s.omega[k],
            i: s.i[k],
        })
        .collect();
    let rms = |f: &dyn Fn(crate::emulator::LoadInputs) -> f64| {
        (states.iter().map(|x| f(*x).powi(2)).sum::<f64>() / states.len().max(1) as f64).sqrt()
    };
    let truth = |x| model_load_torque(&logs.named_truth, x) + u.torque(x);
    TorqueDistance {
        start: rms(&|x| model_load_torque(start, x) - truth(x)),
        last: rms(&|x| model_load_torque(last, x) - truth(x)),
        hidden: rms(&|x| u.torque(x)),
    }
}

/// The lines of one round: its test fit, the keep-or-not test on the selection log (the
/// statistic it compares: the multiple-shooting RSS of this model and of the kept model
/// `base_rss` it extends), and what the diagnosis names next (or its verdict on the final
/// model).
fn say_round(
    say: &mut dyn FnMut(&str),
    step: usize,
    r: &workflow::Round,
    sc: &ident::Scores,
    base_rss: Option<f64>,
) {
    say(&format!(
        "step {step}{}: {:<32} test fit (fresh signal b): x {:6.2} %, xdot {:6.2} %, i {}",
        if r.kept { "" } else { " (not kept)" },
        label(&r.adds),
        sc.fit.x,
        sc.fit.xdot,
        sc.fit
            .i
            .map(|v| format!("{v:6.2} %"))
            .unwrap_or_else(|| "-".into())
    ));
    say(&format!(
        "        selection (signal b): multiple-shooting RSS {:.4e}{}",
        r.selection_rss,
        r.selection_test
            .map(|t| format!(
                "{}; {} (F = {:.1}, p {}, level {:.0} %)",
                base_rss
                    .map(|b| format!(
                        " against {b:.4e} for the kept model ({:+.1} %)",
                        100.0 * (r.selection_rss / b - 1.0)
                    ))
                    .unwrap_or_default(),
                if r.kept {
                    "kept: explains it better beyond noise"
                } else {
                    "not kept: no better beyond noise, the model before stands"
                },
                t.f,
                if t.p_value >= 1e-300 {
                    format!("= {:.1e}", t.p_value)
                } else {
                    "< 1e-300".to_string()
                },
                100.0 * workflow::SELECTION_ALPHA
            ))
            .unwrap_or_default()
    ));
    match &r.next {
        Some(n) => say(&format!(
            "        diagnose (fitting signals a, d): {}",
            match &n.reason {
                workflow::Reason::Effect { score, explanation } =>
                    format!("{} (score {score:.2}) — {explanation}", n.spec),
                workflow::Reason::Unexplained { variable, share } => format!(
                    "NOT adequate, carried by {variable} ({:.0} % of the residual): add {}",
                    100.0 * share,
                    n.spec
                ),
            }
        )),
        None if r.kept => {
            for (d, name) in r.diagnoses.iter().zip(["a", "d"]) {
                say(&format!(
                    "        diagnose (fitting signal {name}): {}",
                    verdict_line(&d.verdict)
                ));
            }
        }
        None => {}
    }
}

/// The demo's HTML report in `dir`: the hidden effects, the verdict, the rounds and the final
/// model's free run on the test log. Returns the report's path.
fn write_report(
    dir: &std::path::Path,
    outcome: &Outcome,
    last: &workflow::Round,
    test_log: &MotorLog,
    pred: &ident::Prediction,
) -> Result<PathBuf> {
    let verdict = if outcome.found_all() {
        "Found: every hidden effect was identified and added."
    } else {
        "Not found: some hidden effect was not identified."
    };
    let mut hidden_s: Vec<String> = outcome.hidden.iter().map(|h| h.to_string()).collect();
    hidden_s.extend(outcome.unnamed.map(Unnamed::describe));
    let d = last
        .diagnoses
        .iter()
        .find(|d| !d.verdict.adequate)
        .or(last.diagnoses.first())
        .context("the final model has no diagnosis")?;
    let w = report::write_demo_report(
        dir,
        &hidden_s,
        verdict,
        &outcome.iterations,
        (&last.model, test_log, d, pred),
    )?;
    Ok(w.path)
}

/// The effects to hide: `--effect`s, else one drawn from the seed (`--random`), else
/// [`DEFAULT_EFFECT`], each at its default size.
pub fn hidden_effects(args: &Args) -> Result<Vec<EffectSpec>> {
    Ok(if args.effect.is_empty() && args.unnamed.is_some() {
        Vec::new()
    } else if args.effect.is_empty() {
        use rand::{Rng, SeedableRng};
        let k = if args.random {
            let mut rng = rand::rngs::StdRng::seed_from_u64(args.seed);
            RANDOM_EFFECTS[rng.random_range(0..RANDOM_EFFECTS.len())]
        } else {
            DEFAULT_EFFECT
        };
        let mut spec = EffectSpec::bare(k);
        for key in crate::effects::of(k).keys {
            spec.values.insert(key.name.to_string(), key.default);
        }
        vec![spec]
    } else {
        args.effect
            .iter()
            .map(|s| EffectSpec::parse_flag("--effect", s))
            .collect::<Result<_>>()?
    })
}

pub fn run(args: Args) -> Result<()> {
    let hidden = hidden_effects(&args)?;
    if let Err(e) =
        crate::validate::in_range(args.duration, 10.0, crate::validate::MAX_SIM_DURATION)
    {
        anyhow::bail!("--duration [s]: {e} (give at least 10 seconds)");
    }
    println!(
        "Emulated motor (paper's BLDC motor, LuGre friction) with {}; fitting on signals a \
         ({} s) and d ({} s, voltage steps), choosing among models on signal b ({} s) and \
         scoring on a second draw of b ({} s) that no choice is made on.",
        match (hidden.len(), args.unnamed) {
            (n, None) => format!("{n} hidden effect(s)"),
            (0, Some(u)) => format!("unnamed physics hidden: {}", u.describe()),
            (n, Some(u)) => format!("{n} hidden effect(s) and unnamed physics: {}", u.describe()),
        },
        args.duration,
        STEP_DURATION,
        args.duration,
        args.duration
    );
    let bar = if args.quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new((2 + MAX_ROUNDS) as u64)
    };
    bar.set_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} {elapsed} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut say = |s: &str| bar.suspend(|| println!("{s}"));
    let out = run_loop(
        &hidden,
        args.unnamed,
        args.seed,
        args.duration,
        Some(&args.report),
        &mut say,
        &bar,
    )?;
    bar.finish_and_clear();
    let hidden_s: Vec<String> = out.hidden.iter().map(|h| h.to_string()).collect();
    if !hidden_s.is_empty() {
        println!("hidden effect: {}", hidden_s.join(", "));
    }
    if !out.hidden.is_empty() {
        println!(
            "  (FOUND: the effect is named and the final model closes at least {:.0} % of the start \
             model's gap to the true model's test fit on every channel, or ends within {NEAR_TRUTH} \
             point of it; docs/decisions/0010-found-means-near-the-truth.md)",
            100.0 * GAP_CLOSED
        );
    }
    let near = out.closeness.is_none_or(|c| c.near_truth());
    for h in &out.hidden {
        let found = out.added.iter().find(|a| a.kind == h.kind);
        match found {
            Some(a) if near => println!("  {}: FOUND (estimated {a})", h.kind.name()),
            Some(a) => println!(
                "  {}: NAMED but NOT FOUND: the final model is not near the truth (estimated {a}; {})",
                h.kind.name(),
                out.closeness.map(|c| c.describe()).unwrap_or_default()
            ),
            None => println!("  {}: NOT FOUND", h.kind.name()),
        }
    }
    if let Some(u) = out.unnamed {
        println!("unnamed physics: {}", u.describe());
        let var = u.carrier().name();
        match out.added.iter().find(|a| a.kind == EffectKind::Table) {
            Some(a) if out.table_found(u) => {
                println!("  carried by {var}: FOUND (table added: {a})")
            }
            _ => println!("  carried by {var}: NOT FOUND (no table on {var} was added)"),
        }
    }
    if let Some(p) = &out.report {
        println!("report: {}", p.display());
    }
    Ok(())
}

/// The verdict in one line: adequate, or which checks failed and what carries the rest.
fn verdict_line(v: &diagnose::Verdict) -> String {
    if v.adequate {
        return format!(
            "adequate: no effect of the list is missing and every check passes at the {:.0}% level",
            100.0 * v.level
        );
    }
    // A check whose test cannot decide on this log (no statistic) has not passed either,
    // but it found nothing: it is listed apart from the checks that rejected.
    let (undecided, failed): (Vec<&diagnose::verdict::Check>, Vec<_>) = v
        .checks
        .iter()
        .filter(|c| !c.passed)
        .partition(|c| c.statistic.is_nan());
    let names =
        |cs: &[&diagnose::verdict::Check]| cs.iter().map(|c| c.name).collect::<Vec<_>>().join(", ");
    let carried: Vec<String> = v
        .unexplained
        .iter()
        .map(|u| format!("{} ({:.0}%)", u.variable, 100.0 * u.share))
        .collect();
    if failed.is_empty() && carried.is_empty() {
        return format!(
            "no effect of the list is left, but the checks cannot judge this log: [{}]",
            names(&undecided)
        );
    }
    let cannot = if undecided.is_empty() {
        String::new()
    } else {
        format!(", cannot judge [{}]", names(&undecided))
    };
    format!(
        "no effect of the list is left, but NOT adequate: failed checks [{}]{cannot}, carried by [{}]",
        names(&failed),
        carried.join(", ")
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(effect: &[&str], random: bool, seed: u64) -> Args {
        Args {
            effect: effect.iter().map(|s| s.to_string()).collect(),
            random,
            unnamed: None,
            seed,
            report: PathBuf::from("unused"),
            duration: DURATION,
            quiet: true,
        }
    }

    #[test]
    fn bare_demo_hides_the_default_effect_whatever_the_seed() {
        for seed in [1, 7] {
            let h = hidden_effects(&args(&[], false, seed)).unwrap();
            assert_eq!(h.len(), 1);
            assert_eq!(h[0].kind, DEFAULT_EFFECT);
            assert_eq!(
                h[0].to_effect(),
                EffectSpec::bare(DEFAULT_EFFECT).to_effect()
            );
        }
    }

    /// Unnamed physics alone hides no named effect, and counts as found only through a table
    /// on the variable that carries it.
    #[test]
    fn unnamed_physics_is_found_only_by_a_table_on_its_carrier() {
        let mut a = args(&[], false, 1);
        a.unnamed = Some(Unnamed::Fan);
        assert!(hidden_effects(&a).unwrap().is_empty());
        let outcome = |added: &[&str]| Outcome {
            hidden: Vec::new(),
            unnamed: Some(Unnamed::Fan),
            iterations: Vec::new(),
            added: added
                .iter()
                .map(|s| EffectSpec::parse(s).unwrap())
                .collect(),
            closeness: None,
            torque: None,
            report: None,
        };
        assert!(outcome(&["table:var=omega,bins=8"]).found_all());
        assert!(!outcome(&["table:var=current,bins=8"]).found_all());
        assert!(!outcome(&["stribeck"]).found_all());
    }

    /// The cam's torque is the follower's spring work per angle: over the rise the shaft
    /// does F0·H + k·H²/2 of work (the spring's energy gained), over the fall it gets the
    /// same back, and nothing over the dwells.
    #[test]
    fn cam_torque_is_the_spring_work_per_angle() {
        let n = 200_000;
        let work = |a: f64, b: f64| {
            let h = (b - a) / n as f64;
            (0..n)
                .map(|k| cam_torque(a + (k as f64 + 0.5) * h) * h)
                .sum::<f64>()
        };
        let energy = CAM_PRELOAD * CAM_LIFT + 0.5 * CAM_STIFFNESS * CAM_LIFT * CAM_LIFT;
        let fall = CAM_RISE + CAM_DWELL;
        assert!((work(0.0, CAM_RISE) - energy).abs() < 1e-6 * energy);
        assert!((work(fall, fall + CAM_FALL) + energy).abs() < 1e-6 * energy);
        assert!(work(0.0, std::f64::consts::TAU).abs() < 1e-6 * energy);
        assert_eq!(cam_torque(CAM_RISE + 0.5 * CAM_DWELL), 0.0);
        // One revolution on: the same torque.
        let t = 1.234;
        assert!((cam_torque(t) - cam_torque(t + std::f64::consts::TAU)).abs() < 1e-12);
    }

    /// Each unnamed kind is found through its own carrier only.
    #[test]
    fn each_unnamed_kind_has_its_carrier() {
        use control::effects::TableVar;
        assert_eq!(Unnamed::Fan.carrier(), TableVar::Omega);
        assert_eq!(Unnamed::Cam.carrier(), TableVar::Theta);
        let outcome = |added: &str| Outcome {
            hidden: Vec::new(),
            unnamed: Some(Unnamed::Cam),
            iterations: Vec::new(),
            added: vec![EffectSpec::parse(added).unwrap()],
            closeness: None,
            torque: None,
            report: None,
        };
        assert!(outcome("table:var=theta,bins=12").found_all());
        assert!(!outcome("table:var=omega,bins=8").found_all());
        assert!(!outcome("position_load").found_all());
    }

    fn fits(x: f64, xdot: f64, i: f64) -> ident::Fits {
        ident::Fits {
            x,
            xdot,
            i: Some(i),
        }
    }

    /// A named effect counts as found only when the final model has closed half of the
    /// start's gap to the truth on every channel (or ends within a point of it).
    #[test]
    fn found_needs_the_name_and_a_model_near_the_truth() {
        let truth = fits(99.0, 97.0, 98.6);
        let start = fits(90.0, 90.0, 70.0);
        let outcome = |last: ident::Fits| Outcome {
            hidden: vec![EffectSpec::parse("deadtime:vd=0.5").unwrap()],
            unnamed: None,
            iterations: Vec::new(),
            added: vec![EffectSpec::parse("deadtime:vd=0.4").unwrap()],
            closeness: Some(Closeness { start, last, truth }),
            torque: None,
            report: None,
        };
        // The name, but the current fit closed half of nothing: 84 % against 98.6 % from 70 %.
        assert!(!outcome(fits(98.5, 96.5, 84.0)).found_all());
        // Half of every gap closed.
        assert!(outcome(fits(95.0, 94.0, 85.0)).found_all());
        // A channel within a point of the truth counts as closed whatever its start.
        let mut near = outcome(fits(98.5, 96.5, 98.0));
        near.closeness.as_mut().unwrap().start = fits(98.4, 96.4, 97.0);
        assert!(near.found_all());
        // The truth without the name is not found.
        let mut unnamed = outcome(fits(99.0, 97.0, 98.6));
        unnamed.added.clear();
        assert!(!unnamed.found_all());
    }

    #[test]
    fn random_draws_from_the_list_and_effect_wins() {
        let h = hidden_effects(&args(&[], true, 1)).unwrap();
        assert!(RANDOM_EFFECTS.contains(&h[0].kind));
        let h = hidden_effects(&args(&["offset:t0=0.01"], true, 1)).unwrap();
        assert_eq!(h[0].kind, EffectKind::Offset);
    }
}
