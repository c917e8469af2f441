//! `motorid emulate`: the paper's friction-compensation experiment on the emulated board.
use crate::board::coeffs::LoopSettings;
use crate::closed_loop::{self, Compensation, LoopRun, Reference, LOW_SPEED};
use crate::effect_spec::EffectSpec;
use crate::emulator::EmulatorConfig;
use crate::model::Model;
use anyhow::{bail, Result};
use serde_json::json;
use std::path::{Path, PathBuf};

/// Closed-loop speed control of the emulated motor with friction compensation, as in the
/// reference paper's compensation experiment: PI control (the same gains in every case)
/// with no compensation, LuGre compensation or SINDYc compensation (eqs. 38-40), tracking a
/// sine or a stepped speed reference. Reports the RMS velocity tracking error over the run
/// and at low speed (|ω_ref| below the paper's Stribeck velocity, 3.676 rad/s).
///
/// Each run is the firmware's own control step (f32) configured from the coefficient blob
/// `motorid export` would write for the model, on the built-in motor emulator.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Identified models to compensate with (`motorid fit --model lugre|sindyc`); give one of
    /// each kind for --table.
    #[arg(long = "model", value_name = "MODEL.toml")]
    pub models: Vec<PathBuf>,
    /// Speed reference: sine (10 rad/s, 0.2 Hz, 20 s) or step (0, ±2, ±5, ±10, ±1 rad/s, 2 s each).
    #[arg(long, value_enum, default_value_t = Reference::Sine)]
    pub reference: Reference,
    /// Friction compensation.
    #[arg(long, value_enum, default_value_t = Compensation::None)]
    pub compensation: Compensation,
    /// Run every reference with every compensation and print a Markdown table.
    #[arg(long)]
    pub table: bool,
    /// Print the result as JSON.
    #[arg(long)]
    pub json: bool,
    /// Write a chart of ω_ref and ω (SVG); with --table, the three compensations on --reference.
    #[arg(long, value_name = "FILE")]
    pub svg: Option<PathBuf>,
    /// Add a physical effect to the emulated motor (`NAME` or `NAME:key=value,...`).
    #[arg(long = "effect", value_name = "SPEC")]
    pub effects: Vec<String>,
    /// Seed of the sensor noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// PI proportional gain [V per rad/s] (the same for every compensation).
    #[arg(long, value_parser = crate::validate::parse_kp, allow_hyphen_values = true, default_value_t = LoopSettings::default().kp)]
    pub kp: f32,
    /// PI integral gain [V per rad].
    #[arg(long, value_parser = crate::validate::parse_ki, allow_hyphen_values = true, default_value_t = LoopSettings::default().ki)]
    pub ki: f32,
    /// Velocity from Hall-edge timing (standstill after this many seconds without an edge)
    /// instead of the paper's 10-sample moving average, for every compensation.
    #[arg(long, value_name = "TIMEOUT_S", value_parser = crate::validate::parse_edge_timeout, allow_hyphen_values = true)]
    pub edge_timing: Option<f32>,
    /// Write the run's time series as CSV (t, omega_ref, omega, omega_est, u, v_comp,
    /// friction, i).
    #[arg(long, value_name = "FILE")]
    pub csv: Option<PathBuf>,
    /// Write the control step's inputs of this run as a QEMU parity trace (qemu-parity crate).
    #[arg(long, value_name = "FILE")]
    pub trace_out: Option<PathBuf>,
}

fn plant(args: &Args) -> Result<EmulatorConfig> {
    let mut p = EmulatorConfig::paper();
    p.seed = args.seed;
    for spec in &args.effects {
        let s = EffectSpec::parse_flag("--effect", spec)?;
        p.effects.push(s.to_effect());
    }
    Ok(p)
}

fn one(
    args: &Args,
    models: &[(String, Model)],
    reference: Reference,
    comp: Compensation,
) -> Result<LoopRun> {
    let settings = LoopSettings {
        kp: args.kp,
        ki: args.ki,
        edge_timing: args.edge_timing,
        ..LoopSettings::default()
    };
    let co = closed_loop::coefficients_for(comp, models, settings)?;
    closed_loop::run(plant(args)?, &co, reference, comp)
}

fn run_json(r: &LoopRun) -> serde_json::Value {
    let s = r.scores();
    json!({
        "reference": r.reference.name(),
        "compensation": r.compensation.name(),
        "rms": s.rms,
        "rms_low": s.rms_low,
        "rms_estimate": s.rms_estimate,
        "samples": s.n,
        "low_speed_samples": s.n_low,
        "low_speed_below": LOW_SPEED,
    })
}

fn chart(runs: &[&LoopRun], path: &Path) -> Result<()> {
    let t: Vec<f64> = runs[0].samples.iter().map(|s| s.t).collect();
    let wref: Vec<f64> = runs[0].samples.iter().map(|s| s.omega_ref).collect();
    let ws: Vec<(String, Vec<f64>)> = runs
        .iter()
        .map(|r| {
            (
                format!("ω, compensation {}", r.compensation.name()),
                r.samples.iter().map(|s| s.omega_true).collect(),
            )
        })
        .collect();
    let mut series: Vec<crate::report::svg::Series> = vec![("ω_ref", &t, &wref)];
    for (name, w) in &ws {
        series.push((name.as_str(), &t, w));
    }
    let svg = crate::report::svg::line_chart(
        &format!("Speed tracking, {} reference", runs[0].reference.name()),
        "t [s]",
        "ω [rad/s]",
        &series,
    )?;
    crate::atomic::write_str(path, &svg)
}

/// Write the QEMU parity trace: `QPT2`, u32 step count, then per step `hall` u8, edge count
/// u8, flags u8 (bit 0 edge overflow, bit 1 voltage override), 0 u8, now_ticks u32,
/// i_meas f32, v_bus f32, omega_ref f32, v_override f32, then per edge ticks u32, state u8,
/// 3 zero bytes. Little-endian. Read by `qemu-parity` (`qemu_parity::Trace`).
pub fn write_trace(path: &Path, run: &LoopRun) -> Result<()> {
    let mut b = Vec::new();
    b.extend_from_slice(b"QPT2");
    b.extend_from_slice(&(run.inputs.len() as u32).to_le_bytes());
    for inp in &run.inputs {
        let flags = u8::from(inp.edges_overflow) | (u8::from(inp.v_override.is_some()) << 1);
        b.extend_from_slice(&[inp.hall, inp.edges.len() as u8, flags, 0]);
        b.extend_from_slice(&inp.now_ticks.to_le_bytes());
        for x in [
            inp.i_meas,
            inp.v_bus,
            inp.omega_ref,
            inp.v_override.unwrap_or(0.0),
        ] {
            b.extend_from_slice(&x.to_le_bytes());
        }
        for e in &inp.edges {
            b.extend_from_slice(&e.ticks.to_le_bytes());
            b.extend_from_slice(&[e.state, 0, 0, 0]);
        }
    }
    crate::atomic::write(path, &b)
}

pub fn run(args: Args) -> Result<()> {
    let outputs: Vec<&Path> = [&args.svg, &args.csv, &args.trace_out]
        .into_iter()
        .flatten()
        .map(PathBuf::as_path)
        .collect();
    let inputs: Vec<&Path> = args.models.iter().map(PathBuf::as_path).collect();
    crate::atomic::check_outputs(&outputs, &inputs)?;
    crate::input::check_distinct(&inputs, "--model")?;
    let models: Vec<(String, Model)> = args
        .models
        .iter()
        .map(|p| Ok((p.display().to_string(), Model::load(p)?)))
        .collect::<Result<_>>()?;
    if !args.table {
        let r = one(&args, &models, args.reference, args.compensation)?;
        if let Some(p) = &args.svg {
            chart(&[&r], p)?;
        }
        if let Some(p) = &args.trace_out {
            write_trace(p, &r)?;
        }
        if let Some(p) = &args.csv {
            let mut text = String::from("t,omega_ref,omega,omega_est,u,v_comp,friction,i\n");
            for s in &r.samples {
                text.push_str(&format!(
                    "{},{},{},{},{},{},{},{}\n",
                    s.t,
                    s.omega_ref,
                    s.omega_true,
                    s.out.omega,
                    s.out.v_cmd,
                    s.out.v_comp,
                    s.out.friction,
                    s.i_meas
                ));
            }
            crate::atomic::write_str(p, &text)?;
        }
        let s = r.scores();
        if args.json {
            println!("{}", run_json(&r));
        } else {
            println!(
                "{} reference, compensation {}: RMS tracking error {:.3} rad/s overall, {:.3} rad/s at low speed (|ω_ref| < {LOW_SPEED} rad/s, {} of {} samples)",
                r.reference.name(),
                r.compensation.name(),
                s.rms,
                s.rms_low,
                s.n_low,
                s.n
            );
        }
        return Ok(());
    }
    if args.trace_out.is_some() {
        bail!("--trace-out records one run: leave out --table");
    }
    let comps: Vec<Compensation> = Compensation::ALL
        .into_iter()
        .filter(|c| {
            *c == Compensation::None
                || closed_loop::coefficients_for(*c, &models, LoopSettings::default()).is_ok()
        })
        .collect();
    if comps.len() == 1 {
        bail!("--table: give a LuGre and/or a SINDYc model with --model MODEL.toml");
    }
    let bar = indicatif::ProgressBar::new(2 * comps.len() as u64);
    let mut runs = Vec::new();
    for reference in [Reference::Sine, Reference::Step] {
        for &c in &comps {
            runs.push(one(&args, &models, reference, c)?);
            bar.inc(1);
        }
    }
    bar.finish_and_clear();
    if let Some(p) = &args.svg {
        let sel: Vec<&LoopRun> = runs
            .iter()
            .filter(|r| r.reference == args.reference)
            .collect();
        chart(&sel, p)?;
    }
    if args.json {
        let all: Vec<_> = runs.iter().map(run_json).collect();
        println!("{}", json!({ "runs": all }));
        return Ok(());
    }
    println!(
        "| reference | compensation | RMS error [rad/s] | RMS error at \\|ω_ref\\| < {LOW_SPEED} rad/s | low-speed error vs none |"
    );
    println!("|---|---|---|---|---|");
    for reference in [Reference::Sine, Reference::Step] {
        let base = runs
            .iter()
            .find(|r| r.reference == reference && r.compensation == Compensation::None)
            .map(|r| r.scores().rms_low)
            .unwrap_or(f64::NAN);
        for r in runs.iter().filter(|r| r.reference == reference) {
            let s = r.scores();
            println!(
                "| {} | {} | {:.3} | {:.3} | {:+.0} % |",
                reference.name(),
                r.compensation.name(),
                s.rms,
                s.rms_low,
                100.0 * (s.rms_low / base - 1.0)
            );
        }
    }
    Ok(())
}
