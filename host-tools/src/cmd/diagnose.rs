//! `motorid diagnose`: which physical effects a model is missing, from its residuals.
use crate::diagnose::{self, Options, Structure};
use crate::log::{column_options, MotorLog};
use crate::model::Model;
use anyhow::Result;
use std::path::PathBuf;

/// Find the physical effects a model is missing.
#[derive(clap::Args, Debug)]
#[command(
    after_help = "How it decides: the log is written as two equation residuals \
    (the torque balance and, for a voltage plant, the voltage balance) in weak form \
    (integrated against smooth windows, so the Hall-quantised angle is never differentiated). \
    The model's own structure is refitted in each; then every effect of the contract's list \
    that the model lacks adds its regressors (searched over cogging harmonics 2..16, \
    Stribeck velocities, thermal time constants...). Forward selection keeps an effect only \
    when it is SIGNIFICANT: nested-model F-test p < 0.001 / (number of candidate variants) \
    (Bonferroni; the sample count is shrunk to an effective one for autocorrelated \
    residuals) and a lower BIC, AND RELEVANT: it explains at least 2% of the equation's \
    residual sum of squares. No finding means the model explains the data down to its noise.\n\n\
    Velocity thresholds (standstill, the smooth sign's width, the Stribeck grid) scale with the \
    log's speed (its 99th-percentile |velocity| against 50 rad/s) and the windows are in seconds, \
    so a linear axis in metres at 1 kHz is diagnosed like a rotary motor at 12 ms.\n\n\
    Limits: presliding is found only when the bristles deflect about two or more Hall steps \
    before breakaway (a geared axis seen at the rotor); stiffer bristles act inside one Hall \
    step (0.095 rad) and are not reported, rather than something false. Load-dependent \
    friction shows only where the drive brakes the moving rotor (after fast voltage drops); \
    on smooth signals it is a slightly lower torque constant and cannot be told apart.\n\n\
    Each finding's `spec` carries the estimated parameters and is accepted by \
    `motorid fit --add SPEC`. --json prints {\"effects\": [{\"name\", \"spec\", \"score\", \
    \"explanation\"}, ...]}, most important first; score = fraction of the residual explained."
)]
pub struct Args {
    /// The model (written by `motorid fit`).
    #[arg(value_name = "MODEL.toml")]
    pub model: PathBuf,
    /// The log to diagnose against (CSV).
    #[arg(value_name = "DATA.csv")]
    pub data: PathBuf,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
    /// Write an HTML report with plots into this directory.
    #[arg(long, value_name = "DIR")]
    pub report: Option<PathBuf>,
    /// Column names of the log: STD=NAME[,STD=NAME...].
    #[arg(long, value_name = "M")]
    pub map: Option<String>,
    /// Units of your files' columns where they are not SI: COLUMN=UNIT[,COLUMN=UNIT...]
    /// (e.g. t=ms,theta=deg,omega=rpm,i=mA); overrides the files' `# unit.COLUMN=UNIT` lines.
    /// COLUMN: t, u, i, theta, omega or a name mapped with --map.
    #[arg(long, value_name = "U")]
    pub units: Option<String>,
}

#[derive(serde::Serialize)]
struct JsonEffect<'a> {
    name: &'a str,
    spec: &'a str,
    score: f64,
    explanation: &'a str,
}

pub fn run(args: Args) -> Result<()> {
    let model = Model::load(&args.model)?;
    let (map, units) = column_options(args.map.as_deref(), args.units.as_deref())?;
    let log = MotorLog::read_and_warn(&args.data, &map, &units, model.plant)?;
    crate::ident::check_log(&log, model.plant)?;
    let st = Structure::from_model(&model);
    let d = diagnose::diagnose(&log, &st, &Options::default());
    if let Some(dir) = &args.report {
        let pred = crate::ident::freerun::simulate(&model, &log).ok();
        let w = crate::report::write_diagnose_report(dir, &model, &log, &d, pred.as_ref())?;
        if !args.json {
            println!("report: {}", w.path.display());
            for s in &w.sentences {
                println!("  {s}");
            }
        }
    }
    if args.json {
        let effects: Vec<JsonEffect> = d
            .effects
            .iter()
            .map(|f| JsonEffect {
                name: &f.name,
                spec: &f.spec,
                score: f.score,
                explanation: &f.explanation,
            })
            .collect();
        println!("{}", serde_json::json!({ "effects": effects }));
        return Ok(());
    }
    if d.effects.is_empty() {
        println!(
            "No missing effect is significant: the {} model explains {} down to its noise.",
            model.kind.name(),
            args.data.display()
        );
    } else {
        println!("Missing effects, most important first (add with `motorid fit --add SPEC`):");
        for f in &d.effects {
            println!("  {:<15} score {:.3}  {}", f.name, f.score, f.spec);
            println!("      {}", f.explanation);
        }
    }
    Ok(())
}
