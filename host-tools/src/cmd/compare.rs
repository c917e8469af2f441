//! `motorid compare`: run a model in free run on a log and score it with the paper's fit
//! percentage, as the model states are and through the board's sensor chain.
use crate::ident;
use crate::log::{column_options, MotorLog};
use crate::model::Model;
use anyhow::Result;
use std::path::PathBuf;

/// Score a model on a log.
#[derive(clap::Args, Debug)]
#[command(
    after_help = "Fit percentage (the paper's eq. 48): 100*(1 - |y - yhat| / |y - mean(y)|); \
    100 is perfect, 0 is as good as the mean, negative is worse.\n\
    fit: the model's angle, velocity and current against the columns theta, omega (or the \
    firmware's 10-sample moving-average estimator applied to theta) and i.\n\
    fit_sensor: the model's angle first Hall-quantised and its velocity estimated like the \
    firmware does.\n\n\
    --json prints {\"fit\": {\"x\": F, \"xdot\": F, \"i\": F|null}, \"fit_sensor\": {...}, \"samples\": N}."
)]
pub struct Args {
    /// The model (written by `motorid fit`).
    #[arg(value_name = "MODEL.toml")]
    pub model: PathBuf,
    /// The log to compare with (CSV).
    #[arg(value_name = "DATA.csv")]
    pub data: PathBuf,
    /// Print one JSON object instead of a table.
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

pub fn run(args: Args) -> Result<()> {
    if let Some(dir) = &args.report {
        crate::atomic::check_outputs(&[&dir.join("index.html")], &[&args.model, &args.data])?;
    }
    let model = Model::load(&args.model)?;
    let (map, units) = column_options(args.map.as_deref(), args.units.as_deref())?;
    let log = MotorLog::read_and_warn(&args.data, &map, &units, model.plant)?;
    let pred = ident::freerun::simulate(&model, &log)?;
    let sc = ident::score_prediction(&model, &log, &pred)?;
    if let Some(dir) = &args.report {
        // The HTML report with its plots (host-tools/src/report/).
        write_report(dir, &model, &log, &pred, &sc)?;
    }
    if args.json {
        println!("{}", serde_json::to_string(&sc)?);
    } else {
        println!(
            "{} model on {} ({} samples)",
            model.kind.name(),
            crate::log::echo_path(&args.data),
            sc.samples
        );
        println!("              {:>9} {:>9} {:>9}", "x", "xdot", "i");
        let row = |name: &str, f: &ident::Fits| {
            let i =
                f.i.map(|v| format!("{v:9.2}"))
                    .unwrap_or_else(|| format!("{:>9}", "-"));
            println!("  {name:<11} {:9.2} {:9.2} {i}   (%)", f.x, f.xdot);
        };
        row("fit", &sc.fit);
        row("fit_sensor", &sc.fit_sensor);
    }
    Ok(())
}

/// `--report DIR`: the HTML report (crate::report); the worst regions go to stderr.
fn write_report(
    dir: &std::path::Path,
    model: &Model,
    log: &MotorLog,
    pred: &ident::Prediction,
    scores: &ident::Scores,
) -> Result<()> {
    let w = crate::report::write_compare_report(dir, model, log, pred, scores)?;
    eprintln!("report: {}", w.path.display());
    for s in &w.sentences {
        eprintln!("  {s}");
    }
    Ok(())
}
