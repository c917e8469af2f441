//! The built-in motor emulator: the reference paper's BLDC motor (DC-equivalent model, LuGre
//! friction with the paper's parameters) plus any of the named physical effects, read
//! through the board's sensors (Hall sensors and decoder, noisy current sensor, the
//! firmware's velocity estimator) at the 12 ms control period.
//!
//! | module | what it is |
//! |---|---|
//! | [`plant`] | the motor, step by step, with its implicit integrator ([`Plant`]) |
//! | [`sensors`] | Hall sensors + decoder, current sensor, velocity estimator |
//! | [`signals`] | the paper's excitation signals `a`, `b`, `c`, `d`, `steady`, `ramp` |
//! | [`experiments`] | closed-form steady states (for checks) and the static-friction experiment |
//!
//! ```no_run
//! use motorid::emulator::{simulate, signal, EmulatorConfig, SignalKind, SAMPLE_PERIOD};
//! let mut cfg = EmulatorConfig::paper();
//! cfg.effects.push(control::effects::Effect::Offset { t0: 0.03 });
//! let u = signal(SignalKind::A, 90.0, cfg.seed);
//! let res = simulate(&cfg, &u, SAMPLE_PERIOD).unwrap();
//! res.log_with_truth().write(std::path::Path::new("a.csv")).unwrap();
//! ```
pub mod experiments;
pub mod plant;
pub mod scalar_root;
pub mod sensors;
pub mod signals;

pub use plant::{LoadInputs, LoadState, Plant, TrueState};
pub use sensors::HallEdge;
pub use signals::{signal, signal_at, SignalKind, SAMPLE_PERIOD};

use crate::effect_spec::EffectSpec;
use crate::log::MotorLog;
use anyhow::{bail, Result};
use control::effects::Effect;
use control::lugre::LugreParams;
use control::motor::MotorParams;
use control::velocity::{MovingAverage, VelocityEstimator, PAPER_WINDOW};
use std::path::PathBuf;
use std::sync::Arc;

/// An extra load torque [N·m] opposing motion, as a function of the true state: physics the
/// effect list does not have (a tabulated load curve, a non-sinusoidal cogging profile,
/// temperature-dependent friction...). It is evaluated inside the implicit solve, so it
/// must be a pure function of its inputs; jumps (a hard `sgn(ω)`) are handled.
pub type ExtraLoad = Arc<dyn Fn(LoadInputs) -> f64 + Send + Sync>;

/// Default Hall pole pairs: the paper's 0.095 rad resolution is 2π/(6·11).
pub const DEFAULT_POLE_PAIRS: u16 = control::hall::PAPER_POLE_PAIRS;
/// Most Hall pole pairs the emulator takes: beyond any motor it could stand for.
pub const MAX_POLE_PAIRS: u16 = 1000;
/// Default current-sensor noise [A] (standard deviation): a typical shunt amplifier + 12-bit
/// ADC on the B-G431B-ESC1 after the firmware's averaging.
pub const DEFAULT_CURRENT_NOISE: f64 = 0.02;
/// Default fine integration step [s]: 0.2 ms, 60 steps per 12 ms sample, 1/7 of the
/// winding's L/R = 1.4 ms.
pub const DEFAULT_FINE_STEP: f64 = 0.2e-3;

/// Everything that defines an emulated motor.
#[derive(Clone)]
pub struct EmulatorConfig {
    /// Motor constants (default: the paper's, `MotorParams::paper()`).
    pub motor: MotorParams<f64>,
    /// LuGre friction of the base motor (default: the paper's table). A `presliding` effect
    /// replaces its σ0 and σ1.
    pub lugre: LugreParams<f64>,
    /// Physical effects added to the base motor.
    pub effects: Vec<Effect<f64>>,
    /// Pole pairs seen by the Hall sensors (resolution 2π/(6·pole_pairs)).
    pub pole_pairs: u16,
    /// Current-sensor noise standard deviation [A].
    pub current_noise: f64,
    /// Seed of the sensor noise (and, by convention, of the excitation signal).
    pub seed: u64,
    /// Largest fine integration step [s].
    pub fine_step: f64,
    /// Extra load torque, for tests that need physics outside the effect list.
    pub extra_load: Option<ExtraLoad>,
}

impl std::fmt::Debug for EmulatorConfig {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EmulatorConfig")
            .field("motor", &self.motor)
            .field("lugre", &self.lugre)
            .field("effects", &self.effects)
            .field("pole_pairs", &self.pole_pairs)
            .field("current_noise", &self.current_noise)
            .field("seed", &self.seed)
            .field("fine_step", &self.fine_step)
            .field("extra_load", &self.extra_load.as_ref().map(|_| "closure"))
            .finish()
    }
}

impl Default for EmulatorConfig {
    fn default() -> Self {
        Self::paper()
    }
}

impl EmulatorConfig {
    /// The paper's motor with no added effect, default sensors, seed 1.
    pub fn paper() -> Self {
        EmulatorConfig {
            motor: MotorParams::paper(),
            lugre: LugreParams::paper(),
            effects: Vec::new(),
            pole_pairs: DEFAULT_POLE_PAIRS,
            current_noise: DEFAULT_CURRENT_NOISE,
            seed: 1,
            fine_step: DEFAULT_FINE_STEP,
            extra_load: None,
        }
    }

    /// The same with these effects.
    pub fn with_effects(mut self, effects: Vec<Effect<f64>>) -> Self {
        self.effects = effects;
        self
    }

    /// The same with an extra load closure.
    pub fn with_extra_load(
        mut self,
        f: impl Fn(LoadInputs) -> f64 + Send + Sync + 'static,
    ) -> Self {
        self.extra_load = Some(Arc::new(f));
        self
    }

    /// The LuGre parameters in force: the base ones, with σ0/σ1 of a `presliding` effect.
    pub fn effective_lugre(&self) -> LugreParams<f64> {
        let mut p = self.lugre;
        for e in &self.effects {
            if let Effect::Presliding { sigma0, sigma1 } = *e {
                p.sigma0 = sigma0;
                p.sigma1 = sigma1;
            }
        }
        p
    }

    /// The emulated motor as a LuGre [`crate::model::Model`]: the truth a fit is measured
    /// against (motor constants, LuGre parameters in force, effects, Hall step; the paper's
    /// 12 ms sample period).
    pub fn truth_model(&self) -> crate::model::Model {
        use crate::model::{Model, ModelKind};
        let mut m = Model::new(ModelKind::Lugre, crate::log::Plant::Voltage, SAMPLE_PERIOD);
        m.motor = self.motor;
        m.lugre = Some(self.effective_lugre());
        m.effects = self.effects.clone();
        m.sensor.hall_resolution_rad = self.hall_resolution();
        m
    }

    /// Hall resolution [rad].
    pub fn hall_resolution(&self) -> f64 {
        sensors::hall_resolution(self.pole_pairs)
    }

    /// The effects as spec strings (`cogging:harmonic=7,amp=0.03,phase=0`).
    pub fn effect_specs(&self) -> Vec<String> {
        self.effects
            .iter()
            .map(|e| EffectSpec::from_effect(e).to_string())
            .collect()
    }

    /// Refuse what cannot be simulated, with a message for a person.
    pub fn check(&self) -> Result<()> {
        for e in &self.effects {
            match *e {
                Effect::Compliance { j2, k, c } if !(j2 > 0.0 && k > 0.0 && c >= 0.0) => {
                    bail!(
                        "effect compliance: give a load inertia j2 > 0 [kg·m²], a stiffness \
                         k > 0 [N·m/rad] and a damping c ≥ 0 [N·m·s/rad] (got j2={}, k={}, \
                         c={})",
                        crate::validate::show(j2),
                        crate::validate::show(k),
                        crate::validate::show(c)
                    );
                }
                Effect::Backlash { j2, gap } if !(j2 > 0.0 && gap >= 0.0) => {
                    bail!(
                        "effect backlash: give a load inertia j2 > 0 [kg·m²] and a gap ≥ 0 \
                         [rad] (got j2={}, gap={})",
                        crate::validate::show(j2),
                        crate::validate::show(gap)
                    );
                }
                control::effects::Effect::Table {
                    var,
                    bins,
                    lo,
                    hi,
                    values,
                } => {
                    if values.iter().all(|v| *v == 0.0) {
                        bail!(
                            "effect table: give the torque at its nodes, b0 to b{} [N·m]; a \
                             table of zeros adds nothing",
                            bins.saturating_sub(1)
                        );
                    }
                    if var != control::effects::TableVar::Theta
                        && (hi.is_nan() || lo.is_nan() || hi <= lo)
                    {
                        bail!(
                            "effect table:var={}: give the range its nodes span, lo < hi",
                            var.name()
                        );
                    }
                }
                _ => {}
            }
        }
        let m = &self.motor;
        for (name, v) in [
            ("R", m.r),
            ("L", m.l),
            ("K_t", m.kt),
            ("K_b", m.kb),
            ("J", m.j),
        ] {
            if !(v.is_finite() && v > 0.0) {
                bail!(
                    "motor constant {name} must be a positive number (got {})",
                    crate::validate::show(v)
                );
            }
        }
        if self.pole_pairs == 0 || self.pole_pairs > MAX_POLE_PAIRS {
            bail!(
                "pole pairs must be between 1 and {MAX_POLE_PAIRS} (got {})",
                self.pole_pairs
            );
        }
        if !(self.current_noise.is_finite() && self.current_noise >= 0.0) {
            bail!(
                "current noise must be 0 or more amperes (got {})",
                crate::validate::show(self.current_noise)
            );
        }
        // At least 1 µs: the sub-step count per sample is sample / fine_step.
        if let Err(e) = crate::validate::in_range(self.fine_step, 1e-6, 0.012) {
            bail!("fine step [s]: {e}");
        }
        for e in &self.effects {
            crate::effect_spec::EffectSpec::from_effect(e).check_values()?;
        }
        let p = self.effective_lugre();
        if !p.is_valid() || p.s(0.0) <= 0.0 || p.sigma1 < 0.0 || p.alpha2 < 0.0 {
            bail!("LuGre parameters are not usable: need σ0 > 0, σ1 ≥ 0, α2 ≥ 0, s(0) > 0 (got {p:?})");
        }
        for e in &self.effects {
            if let Effect::Thermal { tau, .. } = e {
                if tau.is_nan() || *tau <= 0.0 {
                    bail!(
                        "effect 'thermal': tau must be positive (got {})",
                        crate::validate::show(*tau)
                    );
                }
            }
        }
        Ok(())
    }
}

/// The true states at the samples of a simulation.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Truth {
    /// True angle [rad].
    pub theta: Vec<f64>,
    /// True velocity [rad/s].
    pub omega: Vec<f64>,
    /// True bristle deflection [rad].
    pub z: Vec<f64>,
    /// True current [A].
    pub i: Vec<f64>,
    /// True angle [rad] and speed [rad/s] of each load behind a coupling (`compliance`,
    /// `backlash`), in the order of the effects.
    pub loads: Vec<LoadTruth>,
}

/// The true states of one load behind a coupling at the samples of a simulation.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LoadTruth {
    /// Load angle [rad].
    pub theta: Vec<f64>,
    /// Load speed [rad/s].
    pub omega: Vec<f64>,
}

/// What [`simulate`] returns: the log as the board would record it, and the truth.
#[derive(Debug, Clone)]
pub struct SimResult {
    pub log: MotorLog,
    pub truth: Truth,
}

impl SimResult {
    /// The log with the truth as extra columns `theta_true, omega_true, z_true, i_true`, then
    /// `theta_load_true, omega_load_true` for a load behind a coupling (`theta_load2_true`,
    /// ... for a second one).
    pub fn log_with_truth(&self) -> MotorLog {
        let mut log = self.log.clone();
        log.extra
            .push(("theta_true".into(), self.truth.theta.clone()));
        log.extra
            .push(("omega_true".into(), self.truth.omega.clone()));
        log.extra.push(("z_true".into(), self.truth.z.clone()));
        log.extra.push(("i_true".into(), self.truth.i.clone()));
        for (k, load) in self.truth.loads.iter().enumerate() {
            let n = if k == 0 {
                String::new()
            } else {
                (k + 1).to_string()
            };
            log.extra
                .push((format!("theta_load{n}_true"), load.theta.clone()));
            log.extra
                .push((format!("omega_load{n}_true"), load.omega.clone()));
        }
        log
    }
}

/// Above this speed [rad/s] (about 10⁶ rpm) the emulation has diverged: [`simulate`] stops
/// with an error instead of writing numbers no motor makes.
pub const MAX_SPEED: f64 = 1e5;
/// Above this current [A] the emulation has diverged.
pub const MAX_CURRENT: f64 = 1e5;

/// Run the emulated motor under `input` (voltages held for `ts` each, zero-order hold) from
/// rest. Row k of the log is what the board measures at `t = k·ts`, before `input[k]` is
/// applied: `theta` from the Hall decoder, `i` from the current sensor, `omega` from the
/// firmware's estimator. Metadata: `sample_period`, `hall_resolution_rad`, `pole_pairs`,
/// `seed`, `current_noise`, `fine_step`, `effects` (spec strings separated by `;`).
pub fn simulate(cfg: &EmulatorConfig, input: &[f64], ts: f64) -> Result<SimResult> {
    if !(ts.is_finite() && ts > 0.0) {
        bail!(
            "sample period must be a positive number of seconds (got {})",
            crate::validate::show(ts)
        );
    }
    if input.len() < 2 {
        bail!(
            "the input has {} samples; a simulation needs at least 2",
            input.len()
        );
    }
    if let Some(k) = input.iter().position(|v| !v.is_finite()) {
        bail!("input sample {k} is not a finite voltage ({})", input[k]);
    }
    let mut plant = Plant::new(cfg.clone())?;
    let mut est = MovingAverage::new(PAPER_WINDOW, ts);
    let n = input.len();
    let mut log = MotorLog {
        source: PathBuf::from("emulator"),
        ..MotorLog::default()
    };
    let (mut i_meas, mut omega_est) = (Vec::with_capacity(n), Vec::with_capacity(n));
    let mut truth = Truth {
        loads: vec![LoadTruth::default(); plant.load_states().len()],
        ..Truth::default()
    };
    for (k, u) in input.iter().enumerate() {
        let th = plant.hall_angle();
        // k·ts, rounded to the nanosecond so the CSV shows 0.036, not 0.036000000000000004.
        log.t.push((k as f64 * ts * 1e9).round() / 1e9);
        log.u.push(*u);
        log.theta.push(th);
        i_meas.push(plant.measured_current());
        omega_est.push(est.update(th, 0));
        let s = plant.truth();
        truth.theta.push(s.theta);
        truth.omega.push(s.omega);
        truth.z.push(s.z);
        truth.i.push(s.i);
        for (lt, ls) in truth.loads.iter_mut().zip(plant.load_states()) {
            lt.theta.push(ls.theta);
            lt.omega.push(ls.omega);
        }
        plant.apply(*u, ts);
        let s = plant.truth();
        if ![s.theta, s.omega, s.z, s.i].iter().all(|v| v.is_finite())
            || s.omega.abs() > MAX_SPEED
            || s.i.abs() > MAX_CURRENT
        {
            bail!(
                "the emulated motor diverged at t = {:.3} s (speed {:.3e} rad/s, current {:.3e} \
                 A): the effects' parameters are not physical for this motor",
                (k + 1) as f64 * ts,
                s.omega,
                s.i
            );
        }
    }
    log.i = Some(i_meas);
    log.omega = Some(omega_est);
    let specs = cfg.effect_specs();
    let meta = [
        ("sample_period", format!("{ts}")),
        ("hall_resolution_rad", format!("{}", cfg.hall_resolution())),
        ("pole_pairs", format!("{}", cfg.pole_pairs)),
        ("seed", format!("{}", cfg.seed)),
        ("current_noise", format!("{}", cfg.current_noise)),
        ("fine_step", format!("{}", cfg.fine_step)),
        (
            "effects",
            if specs.is_empty() {
                "none".to_string()
            } else {
                specs.join(";")
            },
        ),
        (
            "source",
            "motorid emulator (paper motor, LuGre friction)".to_string(),
        ),
    ];
    for (k, v) in meta {
        log.meta.insert(k.to_string(), v);
    }
    Ok(SimResult { log, truth })
}

/// [`simulate`] under one of the paper's signals (seeded with `cfg.seed`), at 12 ms; the
/// log's metadata also names the signal.
pub fn simulate_signal(cfg: &EmulatorConfig, kind: SignalKind, duration: f64) -> Result<SimResult> {
    // The signal and the log are sized by the duration: bounded here for every caller.
    if let Err(e) = crate::validate::in_range(
        duration,
        crate::validate::MIN_SIM_DURATION,
        crate::validate::MAX_SIM_DURATION,
    ) {
        bail!("duration [s]: {e}");
    }
    let u = signal(kind, duration, cfg.seed);
    let mut res = simulate(cfg, &u, SAMPLE_PERIOD)?;
    res.log.meta.insert("signal".into(), kind.name().into());
    Ok(res)
}
