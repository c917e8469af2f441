//! `motorid simulate`: run the built-in motor emulator under one of the paper's excitations
//! and write the log the board would record (motor-log CSV).
use crate::effect_spec::EffectSpec;
use crate::emulator::{self, EmulatorConfig, SignalKind};
use anyhow::Result;
use std::path::PathBuf;

fn after_help() -> String {
    let mut s = String::from("Signals (--signal):\n");
    for k in SignalKind::ALL {
        s.push_str(&format!("  {:<7} {}\n", k.name(), k.describe()));
    }
    s.push_str(
        "\nThe base motor is the reference paper's BLDC motor (R = 0.216 ohm, L = 0.3 mH, \
         K_t = K_b = 0.0713, J = 3e-4 kg m^2) with the paper's LuGre friction \
         (alpha0 0.08, alpha1 0.0175, alpha2 0.0016, v0 3.676, sigma0 317.2, sigma1 22.2). \
         --effect adds one physical effect to it (repeat for more; 'presliding' replaces \
         sigma0 and sigma1; 'compliance' and 'backlash' each add a load inertia j2 behind \
         the coupling, which --truth reports as theta_load_true, omega_load_true). Measured \
         on the rotor like on the board: Hall angle (2*pi/(6*pole pairs) \
         steps), current with noise, velocity by the paper's 10-sample moving average, \
         every 12 ms.\n\n",
    );
    s.push_str(&EffectSpec::help_text());
    s.push_str(
        "\nExample: motorid simulate --signal a --effect cogging:harmonic=7,amp=0.03 -o a.csv\n",
    );
    s
}

/// Simulate the emulated motor and write a log.
#[derive(clap::Args, Debug)]
#[command(after_help = after_help())]
pub struct Args {
    /// Excitation (commanded voltage): a, b, c, d (the paper's), steady, ramp or speeds
    /// (friction experiments); see below.
    #[arg(long, value_enum)]
    pub signal: SignalKind,
    /// Duration in seconds (default: the signal's own, see below).
    #[arg(long, value_name = "S", value_parser = crate::validate::parse_duration, allow_hyphen_values = true)]
    pub duration: Option<f64>,
    /// Seed of the signal and of the sensor noise: the same seed gives the same log.
    #[arg(long, value_name = "N", default_value_t = 1)]
    pub seed: u64,
    /// Add a physical effect: NAME or NAME:key=value,... (repeatable; list below).
    #[arg(long = "effect", value_name = "SPEC")]
    pub effects: Vec<String>,
    /// Add the true states as columns theta_true, omega_true, z_true, i_true (and the load's
    /// theta_load_true, omega_load_true with compliance or backlash).
    #[arg(long)]
    pub truth: bool,
    /// Pole pairs seen by the Hall sensors (the paper's 0.095 rad resolution is 11).
    #[arg(long, value_name = "P", default_value_t = emulator::DEFAULT_POLE_PAIRS,
          value_parser = clap::value_parser!(u16).range(1..=i64::from(emulator::MAX_POLE_PAIRS)))]
    pub pole_pairs: u16,
    /// Current-sensor noise, standard deviation in amperes.
    #[arg(long, value_name = "A", value_parser = crate::validate::parse_noise, allow_hyphen_values = true, default_value_t = emulator::DEFAULT_CURRENT_NOISE)]
    pub noise: f64,
    /// Largest internal integration step in seconds.
    #[arg(long, value_name = "S", value_parser = crate::validate::parse_fine_step, allow_hyphen_values = true, default_value_t = emulator::DEFAULT_FINE_STEP)]
    pub fine_step: f64,
    /// Output log (CSV, written atomically; missing folders are created below the current
    /// directory, elsewhere only the file's own folder, never at the root).
    #[arg(short, long, value_name = "OUT.csv")]
    pub output: PathBuf,
}

pub fn run(args: Args) -> Result<()> {
    let mut effects = Vec::new();
    for spec in &args.effects {
        let s = EffectSpec::parse_flag("--effect", spec)?;
        effects.push(s.to_effect());
    }
    let duration = args
        .duration
        .unwrap_or_else(|| args.signal.default_duration());
    crate::atomic::check_outputs(&[&args.output], &[])?;
    let cfg = EmulatorConfig {
        effects,
        pole_pairs: args.pole_pairs,
        current_noise: args.noise,
        seed: args.seed,
        fine_step: args.fine_step,
        ..EmulatorConfig::paper()
    };
    cfg.check().map_err(|e| {
        if args.effects.is_empty() {
            e.context("emulator settings")
        } else {
            anyhow::anyhow!(
                "--effect {}: {e:#}",
                crate::log::echo(&args.effects.join(" "))
            )
        }
    })?;
    let res = emulator::simulate_signal(&cfg, args.signal, duration).map_err(|e| {
        if args.effects.is_empty() {
            e
        } else {
            anyhow::anyhow!(
                "--effect {}: {e:#}",
                crate::log::echo(&args.effects.join(" "))
            )
        }
    })?;
    let mut log = if args.truth {
        res.log_with_truth()
    } else {
        res.log.clone()
    };
    // The specs as typed, so the log says what the user asked for.
    if !args.effects.is_empty() {
        log.meta.insert("effects".into(), args.effects.join(";"));
    }
    log.source = args.output.clone();
    log.write(&args.output)?;
    let range = |v: &[f64]| {
        v.iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
                (lo.min(*x), hi.max(*x))
            })
    };
    let (wlo, whi) = range(&res.truth.omega);
    let (ilo, ihi) = range(&res.truth.i);
    println!(
        "wrote {}: {} samples, {:.1} s, signal {}, effects: {}; speed {:.1} .. {:.1} rad/s, current {:.1} .. {:.1} A",
        crate::log::echo_path(&args.output),
        res.log.len(),
        res.log.len() as f64 * emulator::SAMPLE_PERIOD,
        args.signal.name(),
        if args.effects.is_empty() {
            "none".to_string()
        } else {
            args.effects.join(" ")
        },
        wlo,
        whi,
        ilo,
        ihi
    );
    Ok(())
}
