//! `motorid export`: MODEL.toml → the coefficient blob the firmware loads, or the same
//! coefficients as JSON or a C header.
use crate::board::coeff_text;
use crate::board::coeffs::{self, LoopSettings};
use crate::model::Model;
use anyhow::{Context, Result};
use control::effects::EffectKind as K;
use std::path::PathBuf;

/// Write the coefficient blob (magic, version, postcard payload, CRC-32) for a model.
///
/// The blob carries the model (kind, motor constants, LuGre or SINDYc coefficients, added
/// effects), the Hall and velocity-estimator setup, and the speed-loop gains, so that the
/// board (or `motorid board`) runs the model's friction compensation. Check it with
/// `motorid inspect`, put it on the board with `motorid flash` or `motorid upload`.
/// `--format json` and `--format c-header` write the same coefficients, each with its unit,
/// and the blob's layout, for firmware not written in Rust.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The identified model (written by `motorid fit`).
    pub model: PathBuf,
    /// Output file (written atomically; missing folders are created below the current
    /// directory, elsewhere only the file's own folder, never at the root).
    #[arg(short, long, value_name = "COEFFS.bin")]
    pub output: PathBuf,
    /// What to write: the binary blob the firmware loads, a JSON object (every coefficient
    /// with its unit, the coefficients object, the blob layout) or a C header (one #define
    /// per coefficient, units in comments).
    #[arg(long, value_enum, default_value_t = Format::Blob)]
    pub format: Format,
    /// Speed-loop proportional gain [V per rad/s]. Default: 0.05, see control::step.
    #[arg(long, value_parser = crate::validate::parse_kp, allow_hyphen_values = true, default_value_t = LoopSettings::default().kp)]
    pub kp: f32,
    /// Speed-loop integral gain [V per rad]. Default: 0.8, see control::step.
    #[arg(long, value_parser = crate::validate::parse_ki, allow_hyphen_values = true, default_value_t = LoopSettings::default().ki)]
    pub ki: f32,
    /// Voltage limit of the speed loop [V].
    #[arg(long, value_parser = crate::validate::parse_u_max, allow_hyphen_values = true, default_value_t = LoopSettings::default().u_max)]
    pub u_max: f32,
    /// Weight of the friction compensation voltage, 0..1: 1 = full (the paper's eq. 40),
    /// 0 = off, 0.5 = half the compensation voltage.
    #[arg(long, value_parser = crate::validate::parse_comp_gain, allow_hyphen_values = true, default_value_t = LoopSettings::default().comp_gain)]
    pub comp_gain: f32,
    /// Estimate the velocity from Hall-edge timing (standstill after this many seconds
    /// without an edge) instead of the paper's 10-sample moving average.
    #[arg(long, value_name = "TIMEOUT_S", value_parser = crate::validate::parse_edge_timeout, allow_hyphen_values = true)]
    pub edge_timing: Option<f32>,
}

/// Output format of `export`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// The coefficient blob (magic, version, postcard payload, CRC-32).
    Blob,
    /// A JSON object.
    Json,
    /// A C header.
    CHeader,
}

pub fn run(args: Args) -> Result<()> {
    crate::atomic::check_outputs(&[&args.output], &[&args.model])?;
    let model = Model::load(&args.model)?;
    let settings = LoopSettings {
        kp: args.kp,
        ki: args.ki,
        u_max: args.u_max,
        comp_gain: args.comp_gain,
        edge_timing: args.edge_timing,
    };
    // The board smooths the sign of the velocity over its own fixed width.
    if model.sign_width != control::effects::VELOCITY_EPS
        && model.effects.iter().any(|e| {
            matches!(
                e.kind(),
                K::Coulomb | K::Stribeck | K::Asymmetry | K::LoadFriction
            )
        })
    {
        eprintln!(
            "warning: {}: the model's friction sign is smoothed over {:.3e} rad/s (sign_width, \
             from its slow log); the board compensates with {} rad/s",
            crate::log::echo_path(&args.model),
            model.sign_width,
            control::effects::VELOCITY_EPS
        );
    }
    // The board compensates friction and the effects' torques on the rotor; a load behind
    // a coupling is a state of the plant the control step does not simulate.
    for e in &model.effects {
        let name = e.kind().name();
        if coeffs::is_absent_load(e) {
            eprintln!(
                "note: {}: the model's {name} has no load inertia (j2 = 0); it is left out of \
                 the coefficients",
                crate::log::echo_path(&args.model)
            );
        } else if matches!(e.kind(), K::Compliance | K::Backlash) {
            eprintln!(
                "note: {}: the coefficients carry the {name} load ({}) for the record; the \
                 board's compensation has no load state and compensates friction only, not \
                 the load's inertia",
                crate::log::echo_path(&args.model),
                crate::effect_spec::EffectSpec::from_effect(e)
            );
        }
    }
    let co = coeffs::coefficients(&model, settings)
        .with_context(|| crate::log::echo_path(&args.model).to_string())?;
    let bytes =
        coeffs::encode(&co).with_context(|| crate::log::echo_path(&args.model).to_string())?;
    let source = args.model.display().to_string();
    match args.format {
        Format::Blob => crate::atomic::write(&args.output, &bytes)?,
        Format::Json => {
            let v = coeff_text::to_json(&co, &source, &bytes)?;
            crate::atomic::write_str(&args.output, &(serde_json::to_string_pretty(&v)? + "\n"))?
        }
        Format::CHeader => {
            crate::atomic::write_str(&args.output, &coeff_text::to_c_header(&co, &source)?)?
        }
    }
    if args.format != Format::Blob {
        eprintln!(
            "wrote {} ({} model, {} effects)",
            crate::log::echo_path(&args.output),
            model.kind.name(),
            co.effects.len()
        );
        return Ok(());
    }
    eprintln!(
        "wrote {} ({} bytes: {} model, {} effects)",
        crate::log::echo_path(&args.output),
        bytes.len(),
        model.kind.name(),
        co.effects.len()
    );
    Ok(())
}
