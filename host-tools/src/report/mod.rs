//! Self-contained HTML reports with inline SVG plots (no scripts, no external files):
//! `compare --report DIR`, `diagnose --report DIR` and `demo --report DIR` each write
//! `DIR/index.html`.
//!
//! Entry points: [`write_compare_report`], [`write_diagnose_report`], [`write_demo_report`].
pub mod html;
pub mod shape;
pub mod svg;

use crate::diagnose::regions::{self, Breakdown, RegionInputs};
use crate::diagnose::{Diagnosis, EquationResidual};
use crate::ident::{self, Fits, Prediction, Scores};
use crate::log::MotorLog;
use crate::model::Model;
use anyhow::Result;
use html::Page;
use std::path::{Path, PathBuf};

/// What a written report says in words, for the terminal.
#[derive(Debug, Clone)]
pub struct Written {
    /// `DIR/index.html`.
    pub path: PathBuf,
    /// The worst regions of the error, in words.
    pub sentences: Vec<String>,
}

/// Measured velocity the way `compare` scores it: the log's `omega`, or the firmware's
/// estimator applied to `theta`.
fn measured_velocity(model: &Model, log: &MotorLog) -> Vec<f64> {
    ident::sensor_chain::measured_velocity(log, model.sensor.velocity_window)
}

/// Breakdown of the free-run velocity error of a prediction by operating region.
pub fn velocity_error_breakdown(model: &Model, log: &MotorLog, pred: &Prediction) -> Breakdown {
    let w = measured_velocity(model, log);
    let n = w.len().min(pred.omega.len());
    let err: Vec<f64> = (0..n).map(|k| w[k] - pred.omega[k]).collect();
    regions::breakdown(&RegionInputs {
        t: &log.t[..n],
        theta: &log.theta[..n],
        omega: &w[..n],
        current: log.i.as_deref().map(|i| &i[..n]),
        error: &err,
        what: "velocity error",
    })
}

fn fits_row(name: &str, f: &Fits) -> Vec<String> {
    vec![
        name.to_string(),
        format!("{:.2}", f.x),
        format!("{:.2}", f.xdot),
        f.i.map(|v| format!("{v:.2}")).unwrap_or_else(|| "-".into()),
    ]
}

fn region_section(page: &mut Page, b: &Breakdown, unit: &str) {
    page.list(&b.sentences);
    for group in ["velocity", "direction", "angle", "current", "time"] {
        let rs: Vec<&regions::Region> = b.regions.iter().filter(|r| r.group == group).collect();
        if rs.is_empty() {
            continue;
        }
        let labels: Vec<String> = rs.iter().map(|r| r.label.clone()).collect();
        let values: Vec<f64> = rs.iter().map(|r| r.rms).collect();
        page.chart(svg::bar_chart(
            &format!("RMS error by {group}"),
            &format!("RMS [{unit}]"),
            &labels,
            &values,
        ));
    }
    let rows: Vec<Vec<String>> = b
        .regions
        .iter()
        .map(|r| {
            vec![
                r.group.to_string(),
                r.label.clone(),
                r.samples.to_string(),
                format!("{:.4}", r.rms),
                format!("{:.2}", r.ratio),
            ]
        })
        .collect();
    page.table(&["group", "region", "samples", "RMS", "× overall"], &rows);
    let labels: Vec<String> = b.spectrum.iter().map(|l| l.harmonic.to_string()).collect();
    let values: Vec<f64> = b.spectrum.iter().map(|l| 100.0 * l.explained).collect();
    page.chart(svg::bar_chart(
        "Error variance explained by each harmonic of the rotor angle (periods per revolution)",
        "% of variance",
        &labels,
        &values,
    ));
}

fn prediction_charts(page: &mut Page, model: &Model, log: &MotorLog, pred: &Prediction) {
    let n = log.len().min(pred.t.len());
    let t = &log.t[..n];
    page.chart(svg::line_chart(
        "Angle: measured vs model (free run)",
        "t [s]",
        "θ [rad]",
        &[
            ("measured", t, &log.theta[..n]),
            ("model", t, &pred.theta[..n]),
        ],
    ));
    let w = measured_velocity(model, log);
    page.chart(svg::line_chart(
        "Velocity: measured (estimator) vs model (free run)",
        "t [s]",
        "ω [rad/s]",
        &[("measured", t, &w[..n]), ("model", t, &pred.omega[..n])],
    ));
    if let (Some(i), Some(ip)) = (&log.i, &pred.i) {
        page.chart(svg::line_chart(
            "Current: measured vs model (free run)",
            "t [s]",
            "I [A]",
            &[("measured", t, &i[..n]), ("model", t, &ip[..n])],
        ));
    }
    let err: Vec<f64> = (0..n).map(|k| w[k] - pred.omega[k]).collect();
    page.chart(svg::line_chart(
        "Velocity error (measured − model) over time",
        "t [s]",
        "error [rad/s]",
        &[("error", t, &err)],
    ));
}

/// `compare --report DIR`: measured vs predicted over time, the fit table, and the velocity
/// error broken down by operating region (velocity bands, reversals, direction, rotor angle,
/// current level, time) with the worst regions named in words.
pub fn write_compare_report(
    dir: &Path,
    model: &Model,
    log: &MotorLog,
    pred: &Prediction,
    scores: &Scores,
) -> Result<Written> {
    let mut page = Page::new(&format!(
        "{} model on {}",
        model.kind.name(),
        crate::log::echo_path(&log.source)
    ));
    page.paragraph(&format!(
        "Free-run simulation of the model with the log's input, {} samples. Fit percentage \
         100·(1 − ‖y − ŷ‖/‖y − ȳ‖): 100 is perfect, 0 is as good as the mean.",
        scores.samples
    ));
    page.table(
        &["score", "x (angle) %", "xdot (velocity) %", "i (current) %"],
        &[
            fits_row("fit", &scores.fit),
            fits_row("fit_sensor", &scores.fit_sensor),
        ],
    );
    let effects: Vec<String> = model.effect_specs().iter().map(|s| s.to_string()).collect();
    page.paragraph(&format!(
        "Model effects: {}",
        if effects.is_empty() {
            "none besides its friction law".to_string()
        } else {
            effects.join(", ")
        }
    ));
    page.heading("Measured vs predicted");
    prediction_charts(&mut page, model, log, pred);
    page.heading("Where the model fails: velocity error by operating region");
    let b = velocity_error_breakdown(model, log, pred);
    region_section(&mut page, &b, "rad/s");
    let path = page.write(dir)?;
    Ok(Written {
        path,
        sentences: b.sentences,
    })
}

fn equation_section(page: &mut Page, e: &EquationResidual) {
    page.heading(&format!("Residual of the {}", e.equation.label()));
    page.paragraph(&format!(
        "Weak-form residual per window ({}), the model's own structure refitted; {} windows, \
         {:.0} effectively independent (autocorrelation). {:.0}% of the autocorrelation lags and \
         {:.0}% of the input cross-correlation lags lie outside the 99% band (white noise: about 1%).",
        e.unit,
        e.base.len(),
        e.n_eff,
        100.0 * e.whiteness.acf_outside,
        100.0 * e.whiteness.xcf_outside
    ));
    page.chart(svg::line_chart(
        &format!(
            "{} residual: model as it is, and with the findings added",
            e.equation.label()
        ),
        "t [s]",
        e.unit,
        &[("model", &e.t, &e.base), ("with findings", &e.t, &e.after)],
    ));
    let lags: Vec<f64> = (1..=e.whiteness.acf.len()).map(|k| k as f64).collect();
    page.chart(svg::correlation_chart(
        "Whiteness: autocorrelation of the residual (99% band)",
        &lags,
        &e.whiteness.acf,
        e.whiteness.band,
    ));
    let m = (e.whiteness.xcf.len() / 2) as f64;
    let lags: Vec<f64> = (0..e.whiteness.xcf.len()).map(|k| k as f64 - m).collect();
    page.chart(svg::correlation_chart(
        "Cross-correlation of the residual with the input (99% band)",
        &lags,
        &e.whiteness.xcf,
        e.whiteness.band,
    ));
}

fn findings_section(page: &mut Page, d: &Diagnosis) {
    if d.effects.is_empty() {
        let v = &d.verdict;
        page.paragraph(if v.adequate {
            "No missing effect is significant: the model explains the data down to its noise."
        } else if !v.judged {
            "No missing effect is significant, but the log cannot judge the model: too little motion or too few held inputs for the tests to reject."
        } else if v.checks.iter().any(|c| c.name == "small effects" && !c.passed) {
            "No missing effect is named: the ones left significant explain less of the residual than a finding must, too little to estimate them (see the verdict's failed checks)."
        } else {
            "No named missing effect is significant, but the model leaves structure in the residual (see the verdict's failed checks)."
        });
    } else {
        let rows: Vec<Vec<String>> = d
            .effects
            .iter()
            .map(|f| {
                vec![
                    f.name.clone(),
                    f.spec.clone(),
                    format!("{:.3}", f.score),
                    format!("{:.1e}", f.p_value),
                    f.explanation.clone(),
                ]
            })
            .collect();
        page.table(
            &[
                "effect",
                "spec (for fit --add)",
                "score",
                "p-value",
                "physics",
            ],
            &rows,
        );
    }
    let rows: Vec<Vec<String>> = d
        .tested
        .iter()
        .map(|t| {
            vec![
                t.name.clone(),
                t.equation.label().to_string(),
                format!("{:.1}", 100.0 * t.explained),
                format!("{:.1e}", t.p_value),
                if t.kept { "yes" } else { "no" }.to_string(),
                t.spec.clone(),
            ]
        })
        .collect();
    page.paragraph(&format!(
        "Every candidate effect the model lacks, tested against the model as it is. Kept when \
         p < {:.1e} (0.1% family-wise, Bonferroni over all variants) and it explains at least \
         {:.0}% of the residual.",
        d.alpha_per_test,
        100.0 * d.min_explained
    ));
    page.table(
        &[
            "candidate",
            "equation",
            "explains %",
            "p-value",
            "kept",
            "best spec",
        ],
        &rows,
    );
}

/// A p-value for a table: NaN (the test could not decide) as "cannot decide".
fn p_text(p: f64) -> String {
    if p.is_nan() {
        "cannot decide".into()
    } else {
        format!("{p:.1e}")
    }
}

/// The verdict on the model as given: every check with its p-value and share, the refitted
/// constants, the look-alikes with the experiment that separates them, and one chart per
/// variable that carries unexplained structure (its fitted function, in units).
fn verdict_section(page: &mut Page, model: &Model, log: &MotorLog, d: &Diagnosis) {
    let v = &d.verdict;
    page.heading("Verdict on the model as given");
    page.paragraph(&if v.adequate {
        format!(
            "Adequate: every check passes at the {:.0}% family level, no effect of the list is \
             missing and no variable carries structure.",
            100.0 * v.level
        )
    } else if !v.judged {
        format!(
            "Not adequate: some check cannot decide on this log (the {:.0}% family level, {:.1e} \
             per test).",
            100.0 * v.level,
            v.level_per_test
        )
    } else {
        format!(
            "Not adequate at the {:.0}% family level ({:.1e} per test, Bonferroni over the checks \
             and variables).",
            100.0 * v.level,
            v.level_per_test
        )
    });
    let rows: Vec<Vec<String>> = v
        .checks
        .iter()
        .map(|c| {
            vec![
                c.name.to_string(),
                if c.passed { "passed" } else { "FAILED" }.to_string(),
                p_text(c.p_value),
                format!("{:.1}", 100.0 * c.share),
                c.detail.clone(),
            ]
        })
        .collect();
    page.table(
        &[
            "check",
            "result",
            "p-value",
            "share of residual %",
            "detail",
        ],
        &rows,
    );
    if !v.refit.is_empty() {
        page.paragraph(
            "The parameters are off: a refit of the same structure gives these constants (refit \
             the model first, then diagnose again).",
        );
        let rows: Vec<Vec<String>> = v
            .refit
            .iter()
            .map(|(n, x, u)| vec![n.clone(), format!("{x:.4e}"), u.clone()])
            .collect();
        page.table(&["constant", "refitted value", "unit"], &rows);
    }
    if !v.look_alikes.is_empty() {
        page.paragraph("Look-alikes: explanations this log supports about equally.");
        let rows: Vec<Vec<String>> = v
            .look_alikes
            .iter()
            .map(|l| {
                vec![
                    format!(
                        "{} ({:.0}%) / {} ({:.0}%)",
                        l.names[0],
                        100.0 * l.shares[0],
                        l.names[1],
                        100.0 * l.shares[1]
                    ),
                    if l.both_found {
                        "both found"
                    } else {
                        "about equal"
                    }
                    .to_string(),
                    l.experiment.clone(),
                ]
            })
            .collect();
        page.table(
            &[
                "pair (share alone)",
                "status",
                "experiment that tells them apart",
            ],
            &rows,
        );
    }
    if v.unexplained.is_empty() {
        return;
    }
    page.heading("What carries the rest");
    page.paragraph(
        "Structure no effect of the list explains, by the variable that carries it: the smooth \
         function of that variable fitted to the residual, in the unit of the equation's \
         residual (a torque for the torque equation, with the model's K_t/R where it is written \
         in volts).",
    );
    for c in &v.unexplained {
        let dr = shape::drawn(c, model, log);
        page.paragraph(&format!(
            "{} (p {}, share {:.1}%): {}",
            c.variable,
            p_text(c.p_value),
            100.0 * c.share,
            c.explanation
        ));
        if dr.x.len() < 2 {
            page.paragraph(&format!("({}: no shape to draw)", c.variable));
            continue;
        }
        let (xt, yt) = dr.axis_titles();
        page.chart(svg::line_chart(
            &format!(
                "What carries the rest: {} ({} residual)",
                c.variable,
                c.equation.label()
            ),
            &xt,
            &yt,
            &dr.series(),
        ));
    }
}

/// `diagnose --report DIR`: the verdict on the model as given (its checks, refit,
/// look-alikes and the shape of what carries the rest), the findings, every candidate's test, the equation residuals with
/// their whiteness and input cross-correlation, and (given a prediction) measured vs
/// predicted with the error by region.
pub fn write_diagnose_report(
    dir: &Path,
    model: &Model,
    log: &MotorLog,
    d: &Diagnosis,
    pred: Option<&Prediction>,
) -> Result<Written> {
    let mut page = Page::new(&format!(
        "Diagnosis of the {} model on {}",
        model.kind.name(),
        crate::log::echo_path(&log.source)
    ));
    verdict_section(&mut page, model, log, d);
    page.heading("Missing effects");
    findings_section(&mut page, d);
    for e in &d.equations {
        equation_section(&mut page, e);
    }
    let mut sentences = Vec::new();
    if let Some(p) = pred {
        page.heading("Measured vs predicted (free run)");
        prediction_charts(&mut page, model, log, p);
        page.heading("Velocity error by operating region");
        let b = velocity_error_breakdown(model, log, p);
        region_section(&mut page, &b, "rad/s");
        sentences = b.sentences;
    }
    let path = page.write(dir)?;
    Ok(Written { path, sentences })
}

/// One iteration of the demo loop.
#[derive(Debug, Clone)]
pub struct Iteration {
    /// "LuGre", "LuGre + cogging", ...
    pub label: String,
    /// Fits of this model on the test log (no choice was made on it).
    pub validation: Fits,
    /// The effect added after this iteration's diagnosis (its spec), if any.
    pub added: Option<String>,
}

/// `demo --report DIR`: the error falling over the iterations (before/after chart), the
/// hidden effect and whether it was found, then the last diagnosis (its verdict and what
/// carries the rest) and the final model on the test log.
pub fn write_demo_report(
    dir: &Path,
    hidden: &[String],
    verdict: &str,
    iterations: &[Iteration],
    last: (&Model, &MotorLog, &Diagnosis, &Prediction),
) -> Result<Written> {
    let mut page = Page::new("motorid demo: find the hidden effect");
    page.paragraph(&format!(
        "Emulated motor with hidden effect(s): {}. {}",
        if hidden.is_empty() {
            "none".to_string()
        } else {
            hidden.join(", ")
        },
        verdict
    ));
    page.heading("Test fit after each step (a fresh log no choice was made on)");
    let rows: Vec<Vec<String>> = iterations
        .iter()
        .map(|it| {
            let mut r = fits_row(&it.label, &it.validation);
            r.push(it.added.clone().unwrap_or_else(|| "-".into()));
            r
        })
        .collect();
    page.table(&["model", "x %", "xdot %", "i %", "then added"], &rows);
    let labels: Vec<String> = iterations.iter().map(|it| it.label.clone()).collect();
    let gap: Vec<f64> = iterations
        .iter()
        .map(|it| (100.0 - it.validation.xdot).max(0.0))
        .collect();
    page.chart(svg::bar_chart(
        "Velocity error on test data (a fresh log no choice was made on), 100 − fit % (before → after each added effect)",
        "100 − fit %",
        &labels,
        &gap,
    ));
    let (model, log, d, pred) = last;
    page.heading("Last diagnosis");
    verdict_section(&mut page, model, log, d);
    findings_section(&mut page, d);
    for e in &d.equations {
        equation_section(&mut page, e);
    }
    page.heading("Final model on the test log");
    prediction_charts(&mut page, model, log, pred);
    let b = velocity_error_breakdown(model, log, pred);
    region_section(&mut page, &b, "rad/s");
    let path = page.write(dir)?;
    Ok(Written {
        path,
        sentences: b.sentences,
    })
}
