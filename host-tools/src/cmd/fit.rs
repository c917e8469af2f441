//! `motorid fit`: identify a linear, LuGre or SINDYc model from motor logs and write
//! MODEL.toml.
use crate::effect_spec::EffectSpec;
use crate::ident::free_params::Constraints;
use crate::ident::{self, FitRequest};
use crate::log::{column_options, MotorLog, Plant};
use crate::model::ModelKind;
use anyhow::Result;
use std::path::PathBuf;

fn after_help() -> String {
    let mut s = String::from(
        "Models (--model):\n  \
         linear  the paper's eqs. 1-2 with viscous friction only\n  \
         lugre   LuGre friction (paper eqs. 12-14): static curve from steady-state runs \
         (fit on a `simulate --signal steady` log too), sigma0/sigma1 on the simulation error\n  \
         sindyc  sparse nonlinear equations with a hidden friction state (SINDYc); with \
         --add presliding the friction's sign is a bristle state, for the host only \
         (export refuses it)\n\n\
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
    /// Hold a known parameter at a value instead of estimating it: KEY=VALUE, KEY a name of
    /// the parameter table in its units: R [Ω], L [H], Kt (= Kb) [N·m/A = V·s/rad], J [kg·m²;
    /// torque plant: u·s²/rad], b [N·m·s/rad] (linear), alpha0, alpha1 [N·m], alpha2,
    /// sigma1 [N·m·s/rad], v0 [rad/s], sigma0 [N·m/rad] (lugre), and the keys of added
    /// effects as NAME.KEY (coulomb.fc [N·m], ...). Recorded in MODEL.toml ([data.fixed]).
    /// Repeatable.
    #[arg(long = "fix", value_name = "KEY=VALUE")]
    pub fix: Vec<String>,
    /// Keep a parameter inside a known range: KEY=LO..HI (keys and units as --fix; LO < HI).
    /// Recorded in MODEL.toml ([data.bounds]). Repeatable.
    #[arg(long = "bound", value_name = "KEY=LO..HI")]
    pub bound: Vec<String>,
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
    /// Units of your files' columns where they are not SI: COLUMN=UNIT[,COLUMN=UNIT...]
    /// (e.g. t=ms,theta=deg,omega=rpm,i=mA); overrides the files' `# unit.COLUMN=UNIT` lines.
    /// COLUMN: t, u, i, theta, omega or a name mapped with --map.
    #[arg(long, value_name = "U")]
    pub units: Option<String>,
    /// Print one JSON object on stdout (model kind, plant, every parameter with its value,
    /// unit and standard error, the fit percentages); the text summary is not printed.
    #[arg(long)]
    pub json: bool,
    /// No progress bar on stderr (it is shown only when stderr is a terminal).
    #[arg(short, long)]
    pub quiet: bool,
    /// Output model (TOML, written atomically; missing folders are created below the current
    /// directory, elsewhere only the file's own folder, never at the root).
    #[arg(short, long, value_name = "MODEL.toml")]
    pub output: PathBuf,
    /// Logs to fit on (CSV).
    #[arg(value_name = "DATA.csv", required = true)]
    pub data: Vec<PathBuf>,
}

pub fn run(args: Args) -> Result<()> {
    let inputs: Vec<&std::path::Path> = args
        .data
        .iter()
        .chain(&args.validate)
        .map(PathBuf::as_path)
        .collect();
    crate::atomic::check_outputs(&[&args.output], &inputs)?;
    crate::input::check_distinct(&inputs[..args.data.len()], "DATA.csv")?;
    crate::input::check_distinct(&inputs[args.data.len()..], "--validate")?;
    let (map, units) = column_options(args.map.as_deref(), args.units.as_deref())?;
    if args.adds.len() > crate::model::ranges::MAX_EFFECTS {
        anyhow::bail!(
            "--add: {} effects; a model carries at most {}",
            args.adds.len(),
            crate::model::ranges::MAX_EFFECTS
        );
    }
    parse_constraints(&args.fix, &args.bound)?;
    let adds: Vec<EffectSpec> = args
        .adds
        .iter()
        .map(|s| EffectSpec::parse_flag("--add", s))
        .collect::<Result<_>>()?;
    // Warnings once per file, even when a file is both fitted and validated on.
    let mut warned = std::collections::BTreeSet::new();
    let mut read = |p: &PathBuf| -> Result<MotorLog> {
        let log = MotorLog::read_with_units(p, &map, &units, args.plant)?;
        if warned.insert(p.clone()) {
            for w in log.sanity_warnings() {
                crate::warnings::hold(w);
            }
        }
        Ok(log)
    };
    let logs: Vec<MotorLog> = args.data.iter().map(&mut read).collect::<Result<_>>()?;
    let validate: Vec<MotorLog> = args.validate.iter().map(&mut read).collect::<Result<_>>()?;
    for log in logs.iter().chain(&validate) {
        ident::check_log(log, args.plant)?;
    }
    crate::warnings::flush();
    let bar = progress_bar(
        args.quiet,
        &format!("fitting the {} model", args.model.name()),
    );
    let constraints = parse_constraints(&args.fix, &args.bound)?;
    let req = FitRequest {
        kind: args.model,
        logs: &logs,
        validate: &validate,
        adds: &adds,
        plant: args.plant,
        constraints: &constraints,
    };
    let report = ident::progress::observe(show_on(&bar), || ident::fit(&req));
    bar.finish_and_clear();
    let report = report.map_err(|e| name_the_data(e, &args.data))?;
    // A model every later command would refuse is not written.
    report.model.validate().map_err(|e| {
        anyhow::anyhow!(
            "{}: the fitted model is not physical: {e:#}; check the logs' units and that they \
             excite the motor",
            crate::log::echo_path(&args.data[0])
        )
    })?;
    report.model.save(&args.output)?;
    if args.json {
        println!("{}", serde_json::to_string(&json_report(&report))?);
        eprintln!("wrote {}", crate::log::echo_path(&args.output));
    } else {
        print!("{}", report.summary_text);
        println!("wrote {}", crate::log::echo_path(&args.output));
    }
    Ok(())
}

/// `--fix KEY=VALUE` and `--bound KEY=LO..HI` flags as fit constraints (keys as the
/// parameter table names them, `Kt` for `Kb`); an error names the flag and what is wrong.
pub fn parse_constraints(fix: &[String], bound: &[String]) -> Result<Constraints> {
    use crate::ident::free_params::canonical_key;
    let echo = crate::log::echo;
    let number = |flag: &str, arg: &str, text: &str| -> Result<f64> {
        match text.trim().parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            Ok(_) => anyhow::bail!(
                "{flag} {}: '{}' is not a finite number",
                echo(arg),
                echo(text)
            ),
            Err(_) => anyhow::bail!(
                "{flag} {}: '{}' is not a number (write it as 0.5, -2 or 1e-3)",
                echo(arg),
                echo(text)
            ),
        }
    };
    let split = |flag: &str, arg: &str| -> Result<(String, String)> {
        match arg.split_once('=') {
            Some((k, v)) if !k.trim().is_empty() => Ok((canonical_key(k.trim()), v.to_string())),
            _ => anyhow::bail!("{flag} {}: expected KEY=VALUE", echo(arg)),
        }
    };
    let mut c = Constraints::default();
    for arg in fix {
        let (key, value) = split("--fix", arg)?;
        let v = number("--fix", arg, &value)?;
        // A motor constant must lie in the range every model is held to.
        let range = match key.as_str() {
            "R" => Some(crate::model::ranges::R),
            "L" => Some(crate::model::ranges::L),
            "Kb" => Some(crate::model::ranges::KT),
            "J" => Some(crate::model::ranges::J),
            _ => None,
        };
        if let Some(Err(e)) = range.map(|r| r.check(v)) {
            anyhow::bail!("--fix {}: {e}", echo(arg));
        }
        if c.fixed.insert(key.clone(), v).is_some() {
            anyhow::bail!("--fix {key}: given twice");
        }
    }
    for arg in bound {
        let (key, range) = split("--bound", arg)?;
        let Some((lo, hi)) = range.split_once("..") else {
            anyhow::bail!("--bound {}: expected KEY=LO..HI", echo(arg));
        };
        let (lo, hi) = (number("--bound", arg, lo)?, number("--bound", arg, hi)?);
        if lo >= hi {
            anyhow::bail!(
                "--bound {}: the range is empty (LO must be below HI)",
                echo(arg)
            );
        }
        if c.bounds.insert(key.clone(), (lo, hi)).is_some() {
            anyhow::bail!("--bound {key}: given twice");
        }
        if c.fixed.contains_key(&key) {
            anyhow::bail!("--fix and --bound both give {key}: give one");
        }
    }
    Ok(c)
}

/// A fit's error that names neither a file nor a flag names the logs fitted on: every
/// message says where the problem is.
fn name_the_data(e: anyhow::Error, data: &[PathBuf]) -> anyhow::Error {
    let msg = format!("{e:#}");
    let names: Vec<String> = data.iter().map(|p| crate::log::echo_path(p)).collect();
    if msg.starts_with("--") || names.iter().any(|n| msg.contains(n.as_str())) {
        return e;
    }
    anyhow::anyhow!("{}: {msg}", names.join(", "))
}

/// A spinner on stderr with the elapsed time and `what`, hidden with `quiet` (indicatif
/// draws nothing when stderr is not a terminal).
pub fn progress_bar(quiet: bool, what: &str) -> indicatif::ProgressBar {
    let bar = if quiet {
        indicatif::ProgressBar::hidden()
    } else {
        indicatif::ProgressBar::new_spinner()
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template("{spinner} {elapsed:>3} {prefix}: {msg}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_spinner()),
    );
    bar.set_prefix(what.to_string());
    bar.enable_steady_tick(std::time::Duration::from_millis(150));
    bar
}

/// A fit's progress reports shown as `bar`'s message: stage, iteration and cost.
pub fn show_on(bar: &indicatif::ProgressBar) -> impl FnMut(&ident::progress::Update) + 'static {
    let bar = bar.clone();
    move |u| bar.set_message(progress_message(u))
}

/// `free-run simulation error, iteration 4, cost 8.4243e2` (the stage alone before its
/// first iteration).
pub fn progress_message(u: &ident::progress::Update) -> String {
    if u.iteration == 0 || !u.cost.is_finite() {
        u.stage.to_string()
    } else {
        format!(
            "{}, iteration {}, cost {:.4e}",
            u.stage, u.iteration, u.cost
        )
    }
}

/// The `--json` object: `{"model", "plant", "effects", "parameters": [{"name", "value",
/// "unit", "std_error", "identifiable", "note"}], "fit": {"x", "xdot", "i"}, "fit_sensor",
/// "samples", "sample_period", "units", "std_error_factor", "fixed", "bounds", "logs":
/// [{"file", "role", "fit", "fit_sensor", "samples", "error"}]}`. `std_error_factor` is the
/// factor the standard errors carry for the residual's autocorrelation; `fixed` and `bounds`
/// the parameters given by `--fix` and `--bound`. `fit` and `fit_sensor` are the scores on the first DATA.csv (the
/// summary's first line; `logs` has every file's); null when it could not be scored.
pub fn json_report(report: &ident::FitReport) -> serde_json::Value {
    use serde_json::json;
    let m = &report.model;
    let parameters: Vec<serde_json::Value> = m
        .parameters
        .iter()
        .map(|p| {
            json!({
                "name": p.name,
                "value": finite(p.value),
                "unit": p.unit,
                "std_error": p.std_err.and_then(finite),
                "identifiable": p.identifiable,
                "note": p.note,
            })
        })
        .collect();
    let fits = |f: &ident::Fits| json!({ "x": finite(f.x), "xdot": finite(f.xdot), "i": f.i.and_then(finite) });
    let logs: Vec<serde_json::Value> = report
        .scores
        .iter()
        .map(|ls| match &ls.scores {
            Ok(sc) => json!({
                "file": ls.file, "role": ls.role, "fit": fits(&sc.fit),
                "fit_sensor": fits(&sc.fit_sensor), "samples": sc.samples,
            }),
            Err(e) => json!({
                "file": ls.file, "role": ls.role, "fit": null, "fit_sensor": null, "error": e,
            }),
        })
        .collect();
    let first = report
        .scores
        .iter()
        .find(|ls| ls.role == "fit")
        .and_then(|ls| ls.scores.as_ref().ok());
    let effects: Vec<String> = m.effect_specs().iter().map(|s| s.to_string()).collect();
    json!({
        "model": m.kind.name(),
        "plant": m.plant,
        "effects": effects,
        "parameters": parameters,
        "fit": first.map(|sc| fits(&sc.fit)),
        "fit_sensor": first.map(|sc| fits(&sc.fit_sensor)),
        "samples": m.data.samples,
        "sample_period": m.sample_period,
        "units": m.data.units,
        "std_error_factor": m.data.std_err_factor.and_then(finite),
        "fixed": m.data.fixed,
        "bounds": m.data.bounds,
        "logs": logs,
    })
}

/// JSON has no NaN or infinity: those become null.
fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}
