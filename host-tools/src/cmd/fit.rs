//! `motorid fit`: identify a linear, LuGre or SINDYc model from motor logs and write
//! MODEL.toml.
use crate::effect_spec::EffectSpec;
use crate::ident::{self, FitRequest};
use crate::log::{ColumnMap, MotorLog, Plant};
use crate::model::ModelKind;
use anyhow::{Context, Result};
use std::path::PathBuf;

fn after_help() -> String {
    let mut s = String::from(
        "Models (--model):\n  \
         linear  the paper's eqs. 1-2 with viscous friction only\n  \
         lugre   LuGre friction (paper eqs. 12-14): static curve from steady-state runs \
         (fit on a `simulate --signal steady` log too), sigma0/sigma1 on the simulation error\n  \
         sindyc  sparse nonlinear equations with a hidden friction state (SINDYc)\n\n\
         Every parameter is printed with its unit and standard error; a parameter the data \
         cannot pin down is marked NOT IDENTIFIABLE.\n\n",
    );
    s.push_str(&EffectSpec::help_text());
    s.push_str(
        "\nExample: motorid fit --model lugre --add cogging:harmonic=7 -o model.toml a.csv steady.csv\n",
    );
    s
}

/// Fit a model to motor logs.
#[derive(clap::Args, Debug)]
#[command(after_help = after_help())]
pub struct Args {
    /// Model structure: linear, lugre or sindyc.
    #[arg(long, value_enum)]
    pub model: ModelKind,
    /// Add a physical effect to the model and estimate its parameters: NAME or a spec that
    /// `diagnose` printed (NAME:key=value,...; given values are starting points, structural
    /// keys such as cogging's harmonic stay fixed). Repeatable.
    #[arg(long = "add", value_name = "SPEC")]
    pub adds: Vec<String>,
    /// A log to validate on (not fitted); its fit percentages are printed. Repeatable.
    #[arg(long = "validate", value_name = "VAL.csv")]
    pub validate: Vec<PathBuf>,
    /// What the input u is: voltage (u in volts, current i measured) or torque (u is a
    /// torque/force command, no electrical equation).
    #[arg(long, value_enum, default_value_t = Plant::Voltage)]
    pub plant: Plant,
    /// Column names of your files: STD=NAME[,STD=NAME...] (STD: t, u, i, theta, omega).
    #[arg(long, value_name = "M")]
    pub map: Option<String>,
    /// Output model (TOML).
    #[arg(short, long, value_name = "MODEL.toml")]
    pub output: PathBuf,
    /// Logs to fit on (CSV).
    #[arg(value_name = "DATA.csv", required = true)]
    pub data: Vec<PathBuf>,
}

pub fn run(args: Args) -> Result<()> {
    let map = match &args.map {
        Some(m) => ColumnMap::parse(m)?,
        None => ColumnMap::default(),
    };
    let adds: Vec<EffectSpec> = args
        .adds
        .iter()
        .map(|s| EffectSpec::parse(s).with_context(|| format!("--add '{s}'")))
        .collect::<Result<_>>()?;
    let logs: Vec<MotorLog> = args
        .data
        .iter()
        .map(|p| MotorLog::read(p, &map, args.plant))
        .collect::<Result<_>>()?;
    let validate: Vec<MotorLog> = args
        .validate
        .iter()
        .map(|p| MotorLog::read(p, &map, args.plant))
        .collect::<Result<_>>()?;
    for log in &validate {
        ident::check_log(log, args.plant)?;
    }
    let bar = indicatif::ProgressBar::new_spinner();
    bar.set_message(format!("fitting the {} model", args.model.name()));
    bar.enable_steady_tick(std::time::Duration::from_millis(150));
    let report = ident::fit(&FitRequest {
        kind: args.model,
        logs: &logs,
        validate: &validate,
        adds: &adds,
        plant: args.plant,
    });
    bar.finish_and_clear();
    let report = report?;
    report.model.save(&args.output)?;
    print!("{}", report.summary_text);
    println!("wrote {}", args.output.display());
    Ok(())
}
