//! `motorid diagnose`: which physical effects a model is missing, from its residuals.
use crate::diagnose::{self, Options, Structure};
use crate::log::{column_options, MotorLog};
use crate::model::Model;
use anyhow::Result;
use std::path::PathBuf;

/// Find the physical effects a model is missing.
#[derive(clap::Args, Debug)]
#[command(
    after_help = "How it decides. First the model AS GIVEN: its own equations with its own \
    numbers are written as weak-form residuals (the torque balance and, for a voltage plant, \
    the voltage balance, integrated against smooth windows so the Hall-quantised angle is never \
    differentiated). PARAMETERS: when the structure's own columns (computed on the model's \
    noise-free run on the same input) significantly explain that residual less the same \
    residual on that run, and the refitted values of the parameters that moved make a free \
    run that follows the log's angle and current significantly closer, the parameters are off \
    and each moved one is printed with its refitted value: refit first. When the log is too \
    short for that test's clusters to span 5 correlation times of the residual, a NOTE says \
    so (JSON: the check's \"note\"): the check's level was not measured at that length. WHITENESS: the residual must not be predictable from its own past \
    (Breusch-Godfrey on disjoint windows). INPUT: it must not be explained by the input of the \
    last windows. Both, and the carriers below, use robust tests that hold their level where the \
    residual is noisier in some windows than others (slips, steps) and where the windows of one \
    held input share an error of the angle's reading. A log on which a test cannot decide (too \
    few usable windows or held inputs for an equation; whiteness on voltage steps, whose angle \
    rounding drifts within each hold) gets \"Cannot judge\" (JSON \"judged\": false, the \
    check's statistic and p_value null). Judge a model on a multisine: on voltage steps even \
    a correct model is often not adequate (docs/limits.md). Then what is MISSING: every effect of the list that the model lacks adds its \
    regressors (searched over cogging harmonics, Stribeck velocities, thermal time constants...) \
    and forward selection keeps an effect when it is significant (the cluster-robust Wald \
    test of its columns beyond the model's, jackknifed, on disjoint windows clustered by held \
    input: p < 0.001 / number of candidate variants, Bonferroni; and a lower BIC) and \
    relevant (it explains at least 2% of the residual). What \
    no effect explains is ranked by the VARIABLE that carries it (theta, omega, acceleration, \
    current, time, reversal, frequency), each a smooth function tested the same way. The \
    model is ADEQUATE only when every check passes at the 1% family level and both lists are \
    empty; only then does diagnose say the model explains the data.\n\n\
    Velocity thresholds (standstill, the smooth sign's width, the Stribeck grid) scale with the \
    log's speed and the windows are in seconds.\n\n\
    Limits: presliding is found only when the bristles deflect about two or more Hall steps \
    before breakaway. Load-dependent friction shows only where the drive brakes the moving \
    rotor. SINDYc models get no parameter check (their equations are not motor constants).\n\n\
    Each finding's `spec` carries the estimated parameters and is accepted by \
    `motorid fit --add SPEC`. --json prints {\"adequate\": BOOL, \"judged\": BOOL, \"effects\": [{\"name\", \
    \"spec\", \"score\", \"explanation\"}, ...], \"unexplained\": [{\"variable\", \"share\", \
    \"explanation\", \"shape\": {\"x\", \"y\", \"x_unit\", \"y_unit\", ...}}, ...], \"checks\": [...], \"refit\": [...]}, most important first; \
    score and share = fraction of the residual explained."
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
struct JsonUnexplained<'a> {
    variable: &'a str,
    share: f64,
    explanation: &'a str,
    p_value: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    hz: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    spec: Option<&'a str>,
    /// The residual's function of the variable, in units (x and y arrays).
    shape: crate::report::shape::Drawn,
}

#[derive(serde::Serialize)]
struct JsonEffect<'a> {
    name: &'a str,
    spec: &'a str,
    score: f64,
    explanation: &'a str,
    /// Another finding this one looks like on this log (both entered forward selection and
    /// share much of what they explain), and the experiment that tells them apart.
    #[serde(skip_serializing_if = "Option::is_none")]
    looks_like: Option<JsonLooksLike<'a>>,
}

#[derive(serde::Serialize)]
struct JsonLooksLike<'a> {
    name: &'a str,
    experiment: &'a str,
}

/// The finding a found look-alike pair pairs `name` with, and the separating experiment.
fn found_look_alike<'a>(v: &'a diagnose::Verdict, name: &str) -> Option<(&'a str, &'a str)> {
    v.look_alikes
        .iter()
        .filter(|l| l.both_found)
        .find_map(|l| match &l.names {
            [a, b] if a == name => Some((b.as_str(), l.experiment.as_str())),
            [a, b] if b == name => Some((a.as_str(), l.experiment.as_str())),
            _ => None,
        })
}

pub fn run(args: Args) -> Result<()> {
    if let Some(dir) = &args.report {
        crate::atomic::check_outputs(&[&dir.join("index.html")], &[&args.model, &args.data])?;
    }
    let model = Model::load(&args.model)?;
    let (map, units) = column_options(args.map.as_deref(), args.units.as_deref())?;
    let log = MotorLog::read_and_warn(&args.data, &map, &units, model.plant)?;
    crate::ident::check_log(&log, model.plant)?;
    let st = Structure::from_model(&model);
    let d = diagnose::diagnose(&log, &st, &Options::default());
    tracing::debug!(
        adequate = d.verdict.adequate,
        effects = d.effects.len(),
        unexplained = d.verdict.unexplained.len(),
        "diagnosis done"
    );
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
                looks_like: found_look_alike(&d.verdict, &f.name)
                    .map(|(name, experiment)| JsonLooksLike { name, experiment }),
            })
            .collect();
        let unexplained: Vec<JsonUnexplained> = d
            .verdict
            .unexplained
            .iter()
            .map(|u| JsonUnexplained {
                variable: u.variable,
                share: u.share,
                explanation: &u.explanation,
                p_value: u.p_value,
                hz: u.hz,
                spec: u.spec.as_deref(),
                shape: crate::report::shape::drawn(u, &model, &log),
            })
            .collect();
        let refit: Vec<serde_json::Value> = d
            .verdict
            .refit
            .iter()
            .map(|(n, v, u)| serde_json::json!({"name": n, "value": v, "unit": u}))
            .collect();
        println!(
            "{}",
            serde_json::json!({
                "adequate": d.verdict.adequate,
                "judged": d.verdict.judged,
                "effects": effects,
                "unexplained": unexplained,
                "checks": d.verdict.checks,
                "refit": refit,
                "look_alikes": d.verdict.look_alikes,
                "level": d.verdict.level,
            })
        );
        return Ok(());
    }
    print_text(&model, &log, &args, &d);
    Ok(())
}

fn print_text(model: &Model, log: &MotorLog, args: &Args, d: &diagnose::Diagnosis) {
    let v = &d.verdict;
    print_verdict(model, log, args, d);
    for l in &v.look_alikes {
        if l.both_found {
            println!(
                "Look-alikes, both found: {} ({:.0}% alone) and {} ({:.0}% alone) explain much of the same residual on this log (their columns overlap, so the log cannot tell whether one or both are there): add the first and diagnose again before adding the second. To tell them apart: {}.",
                l.names[0],
                100.0 * l.shares[0],
                l.names[1],
                100.0 * l.shares[1],
                l.experiment
            );
            continue;
        }
        println!(
            "Look-alikes: {} ({:.0}%) and {} ({:.0}%) explain the residual about equally on this log. To tell them apart: {}.",
            l.names[0],
            100.0 * l.shares[0],
            l.names[1],
            100.0 * l.shares[1],
            l.experiment
        );
    }
}

/// The caveats of the checks, passed or failed, each under the check's name and equation.
fn print_notes(v: &diagnose::Verdict) {
    for c in &v.checks {
        if let Some(note) = &c.note {
            let eq = c.detail.split(':').next().unwrap_or("");
            println!("  NOTE {:<10} {eq}: {note}", c.name);
        }
    }
}

fn print_verdict(model: &Model, log: &MotorLog, args: &Args, d: &diagnose::Diagnosis) {
    let v = &d.verdict;
    let failed: Vec<&diagnose::verdict::Check> = v.checks.iter().filter(|c| !c.passed).collect();
    if v.adequate {
        println!(
            "Adequate: the {} model explains {} down to its noise (every check passes at the {:.0}% level; no effect of the list is missing).",
            model.kind.name(),
            crate::log::echo_path(&args.data),
            100.0 * v.level
        );
        print_notes(v);
        return;
    }
    // Every failed check is one that could not decide (its p-value NaN), and nothing else
    // was found: the log cannot judge the model.
    let only_undecided = !v.judged
        && failed.iter().all(|c| c.p_value.is_nan())
        && d.effects.is_empty()
        && v.unexplained.is_empty();
    if only_undecided {
        println!(
            "Cannot judge: {} has too little motion or too few held inputs to test the {} model (not adequate until a log can show it; a multisine judges best).",
            crate::log::echo_path(&args.data),
            model.kind.name()
        );
    } else {
        println!(
            "Not adequate: the {} model leaves structure in {} (checks at the {:.0}% family level).",
            model.kind.name(),
            crate::log::echo_path(&args.data),
            100.0 * v.level
        );
    }
    for c in &failed {
        let tag = if c.p_value.is_nan() {
            "UNDECIDED"
        } else {
            "FAILED"
        };
        println!("  {tag} {:<10} {}", c.name, c.detail);
    }
    print_notes(v);
    if !v.refit.is_empty() {
        let vals: Vec<String> = v
            .refit
            .iter()
            .map(|(n, x, u)| format!("{n} = {x:.4e} {u}"))
            .collect();
        println!("  refitted: {}", vals.join(", "));
    }
    if d.effects.is_empty() {
        println!("No effect of the list explains it significantly.");
    } else {
        println!("Missing effects, most important first (add with `motorid fit --add SPEC`):");
        for f in &d.effects {
            println!("  {:<15} score {:.3}  {}", f.name, f.score, f.spec);
            println!("      {}", f.explanation);
            if let Some((other, _)) = found_look_alike(v, &f.name) {
                println!("      looks like {other} on this log (see Look-alikes below)");
            }
        }
    }
    if !v.unexplained.is_empty() {
        println!("Unexplained structure, by the variable that carries it:");
        for u in &v.unexplained {
            println!(
                "  {:<13} share {:.3}  p {:.1e}",
                u.variable, u.share, u.p_value
            );
            println!("      {}", u.explanation);
            let shape = crate::report::shape::drawn(u, model, log).summary();
            if !shape.is_empty() {
                println!("      {shape}");
            }
        }
    }
}
