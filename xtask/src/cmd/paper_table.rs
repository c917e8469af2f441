//! `cargo xtask paper-table`: regenerate the reference paper's fit table (its Table 3) on the
//! built-in emulator: fit the linear, LuGre and SINDYc models on signal a, score them in free
//! run on signals a, b, c, d, and print the table beside the paper's numbers.
use anyhow::Result;
use motorid::emulator::{self, EmulatorConfig, SignalKind};
use motorid::ident::{self, FitRequest, Scores};
use motorid::log::{MotorLog, Plant};
use motorid::model::{Model, ModelKind};
use std::fmt::Write;
use std::path::PathBuf;

/// The paper's Table 3 (fit %, x and ẋ on signals a, b, c, d).
pub const PAPER: [(&str, [f64; 8]); 3] = [
    (
        "Linear",
        [78.43, 73.76, 83.89, 75.07, -3.71, 16.68, 95.78, 86.89],
    ),
    (
        "LuGre",
        [74.30, 77.83, 85.35, 75.68, -9.14, -11.93, 94.64, 87.94],
    ),
    (
        "SINDYc",
        [91.32, 91.46, 87.45, 92.67, 45.58, 41.87, 96.03, 90.82],
    ),
];

/// Regenerate the paper's fit table on emulated data.
#[derive(clap::Args, Debug)]
#[command(
    after_help = "The emulated motor is the paper's (LuGre friction, Hall sensors of \
    0.095 rad, 10-sample moving-average velocity, 12 ms). The LuGre model's static curve is \
    fitted on the emulator's `steady` experiment as in the paper; every model is then scored \
    in free run. Two tables: `fit` (model states as they are) and `fit_sensor` (model states \
    through the board's sensor chain), each beside the paper's numbers."
)]
pub struct Args {
    /// Write the markdown table to this file as well.
    #[arg(long, value_name = "FILE.md")]
    pub out: Option<PathBuf>,
    /// Duration of each emulated signal in seconds.
    #[arg(long, value_name = "S", default_value_t = 60.0)]
    pub duration: f64,
    /// Seed of the signals and sensor noise.
    #[arg(long, value_name = "N", default_value_t = 1)]
    pub seed: u64,
}

fn named(mut log: MotorLog, name: &str) -> MotorLog {
    log.source = PathBuf::from(format!("signal-{name}"));
    log
}

pub fn run(args: Args) -> Result<()> {
    if let Some(out) = &args.out {
        motorid::atomic::check_outputs(&[out], &[])?;
    }
    if !(args.duration.is_finite() && args.duration >= 5.0 && args.duration <= 3600.0) {
        anyhow::bail!(
            "--duration: {} is not a duration between 5 and 3600 seconds",
            args.duration
        );
    }
    let mut cfg = EmulatorConfig::paper();
    cfg.seed = args.seed;
    let kinds = [SignalKind::A, SignalKind::B, SignalKind::C, SignalKind::D];
    let bar = indicatif::ProgressBar::new(4 + 1 + 4 + 5 * 4);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{bar:30} {pos}/{len} {msg}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let mut logs = Vec::new();
    for k in kinds {
        bar.set_message(format!("emulating signal {}", k.name()));
        let res = emulator::simulate_signal(&cfg, k, args.duration)?;
        logs.push(named(res.log, k.name()));
        bar.inc(1);
    }
    bar.set_message("emulating the steady experiment");
    let steady = named(
        emulator::simulate_signal(
            &cfg,
            SignalKind::Steady,
            SignalKind::Steady.default_duration(),
        )?
        .log,
        "steady",
    );
    bar.inc(1);
    // The truth: the emulator's own model, scored by the same function.
    let mut truth = Model::new(ModelKind::Lugre, Plant::Voltage, emulator::SAMPLE_PERIOD);
    truth.motor = cfg.motor;
    truth.lugre = Some(cfg.lugre);
    truth.sensor.hall_resolution_rad = cfg.hall_resolution();
    let mut rows: Vec<(String, Vec<Option<Scores>>)> = Vec::new();
    let mut notes = Vec::new();
    let presliding = [motorid::effect_spec::EffectSpec::parse("presliding")?];
    let fits: [(ModelKind, &[motorid::effect_spec::EffectSpec]); 4] = [
        (ModelKind::Linear, &[]),
        (ModelKind::Lugre, &[]),
        (ModelKind::Sindyc, &[]),
        (ModelKind::Sindyc, &presliding),
    ];
    for (kind, adds) in fits {
        bar.set_message(format!("fitting {}", kind.name()));
        let fit_logs: Vec<MotorLog> = match kind {
            ModelKind::Lugre => vec![logs[0].clone(), steady.clone()],
            _ => vec![logs[0].clone()],
        };
        let fitted = ident::fit(&FitRequest {
            kind,
            logs: &fit_logs,
            validate: &[],
            adds,
            plant: Plant::Voltage,
            constraints: &motorid::ident::free_params::Constraints::NONE,
        });
        bar.inc(1);
        let name = match kind {
            ModelKind::Linear => "Linear",
            ModelKind::Lugre => "LuGre",
            ModelKind::Sindyc if adds.is_empty() => "SINDYc",
            ModelKind::Sindyc => "SINDYc --add presliding",
        };
        match fitted {
            Ok(rep) => {
                let mut sc = Vec::new();
                for log in &logs {
                    bar.set_message(format!("scoring {name} on {}", log.source.display()));
                    sc.push(ident::score(&rep.model, log).ok());
                    bar.inc(1);
                }
                rows.push((name.to_string(), sc));
            }
            Err(e) => {
                notes.push(format!("{name}: not fitted: {e:#}"));
                bar.inc(4);
                rows.push((name.to_string(), vec![None; 4]));
            }
        }
    }
    bar.set_message("scoring the emulator's own model");
    let sc: Vec<Option<Scores>> = logs.iter().map(|l| ident::score(&truth, l).ok()).collect();
    rows.push(("Truth (emulator's model)".into(), sc));
    bar.inc(4);
    bar.finish_and_clear();
    let text = render(&rows, &notes, args.duration);
    print!("{text}");
    if let Some(p) = &args.out {
        motorid::atomic::write_str(p, &text)?;
    }
    Ok(())
}

fn cell(v: Option<f64>) -> String {
    v.map(|v| format!("{v:.2}")).unwrap_or_else(|| "—".into())
}

/// The markdown text: two tables (fit, fit_sensor) with the paper's rows.
pub fn render(rows: &[(String, Vec<Option<Scores>>)], notes: &[String], duration: f64) -> String {
    let mut s = String::from(
        "<!-- Generated by `cargo xtask paper-table --out docs/paper-table.md`; edit the \
         generator (xtask/src/cmd/paper_table.rs), not this file. -->\n\n",
    );
    let _ = writeln!(
        s,
        "# Fit percentages on the emulated paper motor ({duration} s per signal)\n"
    );
    for (title, sensor) in [
        ("Model states as they are (`fit`)", false),
        ("Model states through the sensor chain (`fit_sensor`)", true),
    ] {
        let _ = writeln!(s, "## {title}\n");
        let _ = writeln!(
            s,
            "| Model | a x | a ẋ | b x | b ẋ | c x | c ẋ | d x | d ẋ |\n|---|---|---|---|---|---|---|---|---|"
        );
        for (name, sc) in rows {
            let mut line = format!("| {name} (ours) ");
            for v in sc {
                let f = v.map(|v| if sensor { v.fit_sensor } else { v.fit });
                let _ = write!(
                    line,
                    "| {} | {} ",
                    cell(f.map(|f| f.x)),
                    cell(f.map(|f| f.xdot))
                );
            }
            let _ = writeln!(s, "{line}|");
            if let Some((_, p)) = PAPER.iter().find(|(n, _)| *n == name.as_str()) {
                let mut line = format!("| {name} (paper) ");
                for v in p {
                    let _ = write!(line, "| {v:.2} ");
                }
                let _ = writeln!(s, "{line}|");
            }
        }
        s.push('\n');
    }
    let _ = writeln!(
        s,
        "## Current (`fit`; not in the paper's table)\n\n| Model | a i | b i | c i | d i |\n|---|---|---|---|---|"
    );
    for (name, sc) in rows {
        let mut line = format!("| {name} (ours) ");
        for v in sc {
            let _ = write!(line, "| {} ", cell(v.and_then(|v| v.fit.i)));
        }
        let _ = writeln!(s, "{line}|");
    }
    s.push('\n');
    for n in notes {
        let _ = writeln!(s, "- {n}");
    }
    s
}
