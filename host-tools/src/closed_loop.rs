//! The reference paper's friction-compensation experiment, on the emulated board: PI speed
//! control of the emulated motor with no compensation, LuGre compensation or SINDYc
//! compensation (the paper's eqs. 38–40 in `control::compensation`), the same PI gains in
//! every case, tracking a sinusoidal or a stepped speed reference.
//!
//! Each run is the firmware's control step in f32 ([`crate::board::step_rig::Rig`]) configured
//! from the coefficient blob `motorid export` would write, so what is measured here is what
//! the board would run. Scores: RMS of `ω_ref − ω` over the whole run and over the samples
//! where `|ω_ref|` is below [`LOW_SPEED`], with `ω` the emulator's true velocity (the
//! quantity the compensation is for; the firmware's own estimate lags by its 60 ms window).
//!
//! How the compensation differs from a literal reading of the paper (both in `control`, so
//! the firmware runs the same): the observer integrates the speed reference ω_ref instead of
//! the measured velocity (reference-based feed-forward compensation,
//! `control::step`, where it calls the observer: the 10-sample moving average lags ≈ 60 ms and flips
//! the friction sign late at every reversal), and the LuGre compensation torque is
//! `σ0·z + α2·v` without the σ1·ż term, whose one-sample pulse at every reversal is ≈ 15× the
//! Coulomb friction at a 12 ms step (`control::lugre::LugreObserver::step_compensation`).
//! The PI gains (kp 0.05 V/(rad/s), ki 0.8 V/rad) are the same in every case; on the
//! emulated paper motor higher gains (kp 0.1 or ki 1.6) lower the uncompensated error by
//! < 10 % but raise the compensated one, and kp 0.2 starts to oscillate against the
//! estimator's lag.
use crate::board::coeffs::{self, LoopSettings};
use crate::board::emulated_board::V_BUS_NOMINAL;
use crate::board::step_rig::{Rig, RigSample};
use crate::emulator::EmulatorConfig;
use crate::model::{Model, ModelKind};
use anyhow::{anyhow, Result};
use control::blob::Coefficients;
use control::step::{StepConfig, StepInputs};

/// "Low speed" for the scores [rad/s]: below the paper's Stribeck velocity v0 = 3.676 rad/s,
/// where friction dominates.
pub const LOW_SPEED: f64 = 3.676;

/// Speed references.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Reference {
    /// 10 rad/s sine at 0.2 Hz (a reversal every 2.5 s), 20 s.
    Sine,
    /// Steps 0, +2, −2, +5, −5, +10, −10, +1, −1 rad/s, held 2 s each, 18 s.
    Step,
}

/// Step levels of [`Reference::Step`] [rad/s].
const STEP_LEVELS: [f64; 9] = [0.0, 2.0, -2.0, 5.0, -5.0, 10.0, -10.0, 1.0, -1.0];

impl Reference {
    /// Duration [s].
    pub fn duration(self) -> f64 {
        match self {
            Reference::Sine => 20.0,
            Reference::Step => 2.0 * STEP_LEVELS.len() as f64,
        }
    }

    /// ω_ref(t) [rad/s]. The paper gives no amplitudes; these span the low-speed range where
    /// its friction models differ (v0 = 3.7 rad/s) and a moderate speed.
    pub fn at(self, t: f64) -> f64 {
        match self {
            Reference::Sine => 10.0 * (std::f64::consts::TAU * 0.2 * t).sin(),
            Reference::Step => {
                let k = ((t / 2.0).floor() as usize).min(STEP_LEVELS.len() - 1);
                STEP_LEVELS[k]
            }
        }
    }

    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Reference::Sine => "sine",
            Reference::Step => "step",
        }
    }
}

/// Which friction compensation runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Compensation {
    /// PI only.
    None,
    /// LuGre observer (needs a LuGre MODEL.toml).
    Lugre,
    /// SINDYc model (needs a SINDYc MODEL.toml).
    Sindyc,
}

impl Compensation {
    /// All three, in table order.
    pub const ALL: [Compensation; 3] = [
        Compensation::None,
        Compensation::Lugre,
        Compensation::Sindyc,
    ];

    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Compensation::None => "none",
            Compensation::Lugre => "lugre",
            Compensation::Sindyc => "sindyc",
        }
    }
}

/// The board configuration for one compensation: the coefficients `export` would write for
/// the model of that kind among `models` (none: no model, plain PI), with `settings`.
pub fn coefficients_for(
    comp: Compensation,
    models: &[(String, Model)],
    settings: LoopSettings,
) -> Result<Coefficients> {
    let kind = match comp {
        Compensation::None => {
            let mut co = Coefficients::default();
            co.pi.kp = settings.kp;
            co.pi.ki = settings.ki;
            co.pi.u_max = settings.u_max;
            co.pi.comp_gain = 0.0;
            if let Some(timeout_s) = settings.edge_timing {
                co.estimator = control::blob::Estimator::EdgeTiming { timeout_s };
            }
            if let Some((_, m)) = models.first() {
                co.motor = coeffs::coefficients(m, settings)?.motor;
            }
            return Ok(co);
        }
        Compensation::Lugre => ModelKind::Lugre,
        Compensation::Sindyc => ModelKind::Sindyc,
    };
    let (path, model) = models.iter().find(|(_, m)| m.kind == kind).ok_or_else(|| {
        anyhow!(
            "--compensation {}: give a {} model with --model MODEL.toml (from `motorid fit --model {}`)",
            comp.name(),
            kind.name(),
            kind.name()
        )
    })?;
    coeffs::coefficients(model, settings).map_err(|e| anyhow!("{path}: {e}"))
}

/// One closed-loop run.
#[derive(Debug, Clone)]
pub struct LoopRun {
    pub reference: Reference,
    pub compensation: Compensation,
    pub samples: Vec<RigSample>,
    /// The control step's inputs, step by step (for the QEMU parity trace).
    pub inputs: Vec<StepInputs<f32>>,
}

/// RMS tracking errors of a run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scores {
    /// RMS of ω_ref − ω over the whole run [rad/s].
    pub rms: f64,
    /// The same over the samples with |ω_ref| < [`LOW_SPEED`] [rad/s].
    pub rms_low: f64,
    /// RMS of ω_ref − ω̂ (the firmware's estimate) [rad/s].
    pub rms_estimate: f64,
    /// Number of samples (all, low speed).
    pub n: usize,
    pub n_low: usize,
}

/// Run the loop on the emulated motor `plant` with the board configuration `co`.
pub fn run(
    plant: EmulatorConfig,
    co: &Coefficients,
    reference: Reference,
    compensation: Compensation,
) -> Result<LoopRun> {
    let cfg: StepConfig<f32> = co.step_config(V_BUS_NOMINAL);
    let mut rig = Rig::new(plant, &cfg)?;
    rig.recorded = Some(Vec::new());
    let ts = f64::from(cfg.dt);
    let n = (reference.duration() / ts).round() as usize;
    let samples = (0..n)
        .map(|k| rig.step(reference.at(k as f64 * ts), None))
        .collect();
    Ok(LoopRun {
        reference,
        compensation,
        samples,
        inputs: rig.recorded.take().unwrap_or_default(),
    })
}

impl LoopRun {
    /// RMS tracking errors.
    pub fn scores(&self) -> Scores {
        let (mut s, mut s_low, mut s_est, mut n_low) = (0.0, 0.0, 0.0, 0usize);
        for x in &self.samples {
            let e = x.omega_ref - x.omega_true;
            s += e * e;
            let ee = x.omega_ref - f64::from(x.out.omega);
            s_est += ee * ee;
            if x.omega_ref.abs() < LOW_SPEED {
                s_low += e * e;
                n_low += 1;
            }
        }
        let n = self.samples.len().max(1);
        Scores {
            rms: (s / n as f64).sqrt(),
            rms_low: (s_low / n_low.max(1) as f64).sqrt(),
            rms_estimate: (s_est / n as f64).sqrt(),
            n: self.samples.len(),
            n_low,
        }
    }
}
