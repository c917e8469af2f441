//! `motorid real-data`: fit and diagnose the measured data sets in `../shared/data` (EMPS
//! benchmark, TRO2021 screw drives, OmniRobot DC motors), write the figures and print the
//! markdown tables of the README's "Real data" section.
use crate::real_data::plots::{self, Series};
use crate::real_data::static_curve::{Selection, Term};
use crate::real_data::{emps, emps_loop, locate, omni_dc, screw_drives};
use anyhow::{Context, Result};
use std::fmt::Write;
use std::path::{Path, PathBuf};

/// Reproduce the real-data results.
#[derive(clap::Args, Debug)]
#[command(
    long_about = "Fit and diagnose the measured data sets that live beside the repository in \
    ../shared/data (see its README.md for where each comes from and its licence):\n\
    - EMPS benchmark (ball-screw axis under a position loop): the authors' IDIM-LS model \
    reproduced, then the generic loop (fit linear, diagnose, add what was found, refit) with \
    --plant torque --map t=t_s,u=vir_V,theta=qm_m, scored by the benchmark's free-run test;\n\
    - TRO2021 screw drives: static friction curves (Coulomb, viscous, offset, asymmetry, \
    Stribeck) from the steady-state runs, with an F-test for each term;\n\
    - OmniRobot DC motors: Coulomb + viscous friction beside the authors' b and T_0.\n\
    Writes SVG figures and real-data.md into --out and prints the markdown tables."
)]
pub struct Args {
    /// Folder that holds EMPS/, TRO2021_screw_drives/ and OmniRobot_DC_motors/
    /// [default: ../shared/data beside the repository].
    #[arg(long, value_name = "DIR")]
    pub data: Option<PathBuf>,
    /// Folder for the figures and the tables (real-data.md); created if missing.
    #[arg(long, value_name = "DIR", default_value = "real-data")]
    pub out: PathBuf,
    /// Skip the generic fit/diagnose loop on EMPS (the slow part: a few seconds).
    #[arg(long)]
    pub no_generic: bool,
}

fn progress(msg: &str) {
    eprintln!("real-data: {msg}");
}

fn fig_link(md: &mut String, out: &Path, name: &str, alt: &str) {
    let _ = writeln!(md, "\n![{alt}]({}/{name})\n", out.display());
}

pub fn run(args: Args) -> Result<()> {
    let data = locate(args.data.as_deref())?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("{}: cannot create the output folder", args.out.display()))?;
    let mut md = String::new();
    emps_section(&mut md, &data, &args)?;
    screw_section(&mut md, &data, &args.out)?;
    omni_section(&mut md, &data, &args.out)?;
    let path = args.out.join("real-data.md");
    crate::atomic::write_str(&path, &md)?;
    print!("{md}");
    progress(&format!(
        "wrote {} and the figures beside it",
        path.display()
    ));
    Ok(())
}

fn emps_section(md: &mut String, data: &Path, args: &Args) -> Result<()> {
    let out = &args.out;
    progress("EMPS: reading");
    let train = emps::read(&data.join("EMPS").join("DATA_EMPS.csv"))?;
    let test = emps::read(&data.join("EMPS").join("DATA_EMPS_PULSES.csv"))?;
    let g = emps::GTAU;
    let sym = emps::idim_ls(&train, g, false)?;
    let asy = emps::idim_ls(&train, g, true)?;
    let _ = writeln!(
        md,
        "### EMPS benchmark (ball-screw axis, closed loop, 1 kHz)\n"
    );
    let _ = writeln!(
        md,
        "Rigid model `gτ·vir = M·q̈ + Fv·q̇ + Fc·sign(q̇) + OF`, identified by IDIM-LS as the \
         benchmark's scripts do (4th-order Butterworth 100 Hz zero-phase, central differences, \
         parallel decimation by 10) on DATA_EMPS; σ% is the relative standard deviation.\n"
    );
    let _ = writeln!(
        md,
        "| parameter | reference (σ%) | this tool (σ%) | difference |"
    );
    let _ = writeln!(md, "|---|---|---|---|");
    for (k, (name, val, sd)) in emps::REFERENCE.iter().enumerate() {
        let ours = sym.ols.theta[k];
        let _ = writeln!(
            md,
            "| {name} | {val:.4} ({:.3}) | {ours:.4} ({:.3}) | {:+.2} % |",
            100.0 * sd / val.abs(),
            sym.ols.rel_sigma_pct(k),
            100.0 * (ours - val) / val.abs()
        );
    }
    let _ = writeln!(
        md,
        "| condition number | 25.99 | {:.2} | |\n| relative error on DATA_EMPS | 4.083 % | {:.3} % | |\n\
         | cross-test relative error on DATA_EMPS_PULSES | 5.982 % | {:.3} % | |\n",
        sym.ols.cond,
        sym.ols.rel_error_pct(),
        emps::idim_relative_error(&sym.axis, &test, g)
    );
    let _ = writeln!(
        md,
        "Asymmetric friction (the authors' §4.2 model, one Fv/Fc per direction):\n"
    );
    let _ = writeln!(md, "| parameter | reference | this tool |");
    let _ = writeln!(md, "|---|---|---|");
    for (k, (name, val)) in emps::REFERENCE_ASYM.iter().enumerate() {
        let _ = writeln!(md, "| {name} | {val:.4} | {:.4} |", asy.ols.theta[k]);
    }
    let _ = writeln!(
        md,
        "| relative error on DATA_EMPS | 3.112 % | {:.3} % |\n",
        asy.ols.rel_error_pct()
    );
    let _ = writeln!(
        md,
        "Are the friction terms needed? Nested F-tests on the same regression, with the \
         effective sample size of the residual (the statistics `diagnose` uses):\n"
    );
    let _ = writeln!(md, "| effect | tested against | explains | F | p |");
    let _ = writeln!(md, "|---|---|---|---|---|");
    for t in emps::term_tests(&train, g)? {
        let _ = writeln!(
            md,
            "| {} | {} | {:.1} % of the residual | {:.1} | {:.1e} |",
            t.name,
            t.against,
            100.0 * t.test.explained,
            t.test.f,
            t.test.p_value
        );
    }
    md.push('\n');

    // Benchmark free-run test.
    let (rmse_sym, sim_sym) = emps::benchmark_rmse_mm(&sym.axis, g, &test);
    let (rmse_asy, _) = emps::benchmark_rmse_mm(&asy.axis, g, &test);
    let (rmse_sym_tr, _) = emps::benchmark_rmse_mm(&sym.axis, g, &train);
    let mut rows: Vec<(String, f64, f64)> = vec![
        (
            "IDIM-LS rigid model, symmetric friction".into(),
            rmse_sym_tr,
            rmse_sym,
        ),
        (
            "IDIM-LS rigid model, asymmetric friction".into(),
            emps::benchmark_rmse_mm(&asy.axis, g, &train).0,
            rmse_asy,
        ),
    ];
    let mut loop_md = String::new();
    let mut generic_sim = None;
    if !args.no_generic {
        let rounds = emps_loop::run(&train, &test, &mut |m| progress(m))?;
        progress("EMPS: generic fits with the authors' structures");
        let authors = emps_loop::authors_structures(&train, &test)?;
        let n_loop = rounds.len();
        let rounds: Vec<emps_loop::Round> = rounds.into_iter().chain(authors).collect();
        let _ = writeln!(
            loop_md,
            "The generic loop on the same data: the code paths of `motorid fit --model linear \
             --plant torque --map {}`, `motorid diagnose` and `fit --add` (ident::fit, \
             diagnose::diagnose), on the training log in mm at 100 Hz (the generic tools' \
             velocity constants are set for rad/s of a motor sampled at ~10 ms; see \
             `real_data::emps_loop`). With `u = vir` the force parameters come out in volts of \
             `vir`; they are shown ×gτ in newtons. Fit % (the paper's, free run) on the \
             100 Hz training log and the 1 kHz test log.\n",
            emps::MAP
        );
        let _ = writeln!(
            loop_md,
            "| round | added effects | M [kg] | Fv [N·s/m] | Fc [N] | OF [N] | asymmetry dv, dc | fit % q / q̇ (train) | fit % q / q̇ (test) | test RMSE [mm] | diagnosed next (share of residual) |"
        );
        let _ = writeln!(loop_md, "|---|---|---|---|---|---|---|---|---|---|---|");
        for (k, r) in rounds.iter().enumerate() {
            let p = emps_loop::physical(&r.model, g);
            let opt = |v: Option<f64>| v.map_or("–".to_string(), |x| format!("{x:.2}"));
            let found: Vec<String> = r
                .diagnosis
                .effects
                .iter()
                .map(|f| format!("{} ({:.0} %)", f.name, 100.0 * f.score))
                .collect();
            let _ = writeln!(
                loop_md,
                "| {} | {} | {:.2} | {:.2} | {} | {} | {} | {:.1} / {:.1} | {:.1} / {:.1} | {:.3} | {} |",
                if k >= n_loop { "authors' structure".to_string() } else if r.kept { k.to_string() } else { format!("{k} (not kept: worse training free run)") },
                if r.adds.is_empty() { "– (linear)".to_string() } else { r.adds.iter().map(|a| format!("`{a}`")).collect::<Vec<_>>().join(" ") },
                p.m,
                p.fv,
                opt(p.fc),
                opt(p.offset),
                p.asym.map_or("–".to_string(), |(a, b)| format!("{a:.1}, {b:.2}")),
                r.train.fit.x,
                r.train.fit.xdot,
                r.test.fit.x,
                r.test.fit.xdot,
                r.rmse_test_mm,
                if found.is_empty() { "nothing".to_string() } else { found.join(", ") }
            );
            let label = if k == 0 {
                "generic linear model (viscous only)".to_string()
            } else if k < n_loop {
                format!("generic model after round {k}")
            } else {
                format!("generic model + {}", r.adds.join(" + "))
            };
            rows.push((label, benchmark_train(&r.model, &train), r.rmse_test_mm));
        }
        let last = emps_loop::final_round(&rounds[..n_loop]).expect("round 0 is always kept");
        generic_sim = Some((last.sim_test.clone(), last.adds.join(" + ")));
        loop_result(&mut loop_md, &train, &rounds[..n_loop], last)?;
        let _ = writeln!(
            loop_md,
            "\nEvery candidate's best test per diagnosis (Bonferroni level {:.1e}):\n",
            rounds[0].diagnosis.alpha_per_test
        );
        for (k, r) in rounds.iter().enumerate() {
            let tested: Vec<String> = r
                .diagnosis
                .tested
                .iter()
                .map(|t| {
                    format!(
                        "{} p = {:.1e}{}",
                        t.name,
                        t.p_value,
                        if t.kept { " (kept)" } else { "" }
                    )
                })
                .collect();
            let what = if k < n_loop {
                format!("round {k}")
            } else {
                format!("with {}", r.adds.join(" + "))
            };
            let _ = writeln!(loop_md, "- {what}: {}", tested.join(", "));
        }
        loop_md.push('\n');
    }
    md.push_str(&loop_md);
    let _ = writeln!(
        md,
        "Benchmark test (nonlinear_benchmarks convention): free run `vir` → `qm` on \
         DATA_EMPS_PULSES, state initialised from the first {} samples, RMSE of the simulated \
         position in mm. The open-loop free run of an integrating axis drifts with any force \
         error, which is why these numbers are in millimetres while the closed-loop simulation \
         below is in micrometres.\n",
        emps::INIT_WINDOW
    );
    let _ = writeln!(md, "| model | train RMSE [mm] | test RMSE [mm] |");
    let _ = writeln!(md, "|---|---|---|");
    for (name, tr, te) in &rows {
        let _ = writeln!(md, "| {name} (this tool) | {tr:.3} | {te:.3} |");
    }
    for (name, v) in emps::PUBLISHED_TEST_RMSE_MM {
        let _ = writeln!(md, "| {name} (published) | | {v} |");
    }
    // Closed-loop reference simulation.
    let _ = writeln!(
        md,
        "\nThe authors' own validation is a closed-loop simulation (reference `qg` through the \
         position/velocity loop, 10 V saturation); relative position error `100·‖q − q̂‖/‖q‖` \
         from sample 50 (published figures use filtered measurements; the pulses of the test run \
         are not in the model):\n"
    );
    let _ = writeln!(
        md,
        "| data | published | IDIM-LS symmetric (this tool) | asymmetric (this tool) |"
    );
    let _ = writeln!(md, "|---|---|---|---|");
    for (log, name, publ) in [
        (&train, "DATA_EMPS", "0.0138 %"),
        (&test, "DATA_EMPS_PULSES", "0.0080 %"),
    ] {
        let qg = log
            .extra("qg_m")
            .with_context(|| format!("{}: missing column 'qg_m'", log.source.display()))?;
        let e = |a: &emps::RigidAxis| {
            let (q, _) = emps::simulate_closed_loop(a, qg, log.sample_period(), log.theta[0]);
            emps::relative_error_pct(&log.theta[50..], &q[50..])
        };
        let _ = writeln!(
            md,
            "| {name} | {publ} | {:.4} % | {:.4} % |",
            e(&sym.axis),
            e(&asy.axis)
        );
    }
    // Figure.
    let mut series = vec![
        Series::line(
            "measured qm",
            plots::thin(&test.t, &scale(&test.theta, 1e3), 10),
            0,
        ),
        Series::line(
            &format!("IDIM-LS model, free run ({rmse_sym:.2} mm)"),
            plots::thin(&test.t, &scale(&sim_sym, 1e3), 10),
            1,
        ),
    ];
    if let Some((sim, k)) = &generic_sim {
        series.push(Series::line(
            &format!("generic model + {k}"),
            plots::thin(&test.t, sim, 10),
            2,
        ));
    }
    plots::figure(
        &out.join("emps_test_free_run.svg"),
        "EMPS, DATA_EMPS_PULSES: open-loop free run vir -> qm",
        "t [s]",
        "position [mm]",
        &series,
    )?;
    fig_link(md, out, "emps_test_free_run.svg", "EMPS free-run test");
    Ok(())
}

/// The loop's final model beside the authors' parameters, and the offset/asymmetry tests.
fn loop_result(
    md: &mut String,
    train: &crate::log::MotorLog,
    rounds: &[emps_loop::Round],
    last: &emps_loop::Round,
) -> Result<()> {
    let g = emps::GTAU;
    let p = emps_loop::physical(&last.model, g);
    let (fvp, fcp, fvm, fcm) = emps_loop::per_direction(&p);
    let found: Vec<&str> = rounds[0]
        .diagnosis
        .effects
        .iter()
        .map(|f| f.name.as_str())
        .collect();
    let _ = writeln!(
        md,
        "\nResult of the loop (`diagnose` on the linear model found: {}; refit with `fit --add` \
         of those specs; test RMSE on DATA_EMPS_PULSES {:.2} mm), beside the authors' IDIM-LS \
         estimates. The generic asymmetry `dv·|v| + dc·|sgn v|` is the authors' per-direction \
         model (Fv± = Fv ± dv, Fc± = Fc ± dc ± OF):\n",
        found.join(", "),
        last.rmse_test_mm
    );
    let _ = writeln!(
        md,
        "| parameter | authors, symmetric | authors, per direction | generic loop |"
    );
    let _ = writeln!(md, "|---|---|---|---|");
    let a = emps::REFERENCE_ASYM;
    let opt = |v: Option<f64>| v.map_or("–".to_string(), |x| format!("{x:.2}"));
    let rows: [(&str, String, String, String); 8] = [
        (
            "M [kg]",
            "95.11".into(),
            format!("{:.2}", a[0].1),
            format!("{:.2}", p.m),
        ),
        (
            "Fv [N·s/m] (mean of both directions)",
            "203.50".into(),
            format!("{:.2}", 0.5 * (a[1].1 + a[3].1)),
            format!("{:.2}", p.fv),
        ),
        (
            "Fc [N] (mean of both directions)",
            "20.39".into(),
            format!("{:.2}", 0.5 * (a[2].1 + a[4].1)),
            opt(p.fc),
        ),
        ("OF [N]", "−3.16".into(), "– (in Fc±)".into(), opt(p.offset)),
        (
            "asymmetry dv = (Fv+ − Fv−)/2 [N·s/m]",
            "–".into(),
            format!("{:.2}", 0.5 * (a[1].1 - a[3].1)),
            opt(p.asym.map(|x| x.0)),
        ),
        (
            "asymmetry dc = (Fc+ − Fc−)/2 [N]",
            "–".into(),
            format!("{:.2}", 0.5 * (a[2].1 - a[4].1)),
            opt(p.asym.map(|x| x.1 + p.offset.unwrap_or(0.0))),
        ),
        (
            "Fv+ / Fv− [N·s/m]",
            "–".into(),
            format!("{:.2} / {:.2}", a[1].1, a[3].1),
            format!("{fvp:.2} / {fvm:.2}"),
        ),
        (
            "Fc+ / Fc− [N]",
            "–".into(),
            format!("{:.2} / {:.2}", a[2].1, a[4].1),
            format!("{fcp:.2} / {fcm:.2}"),
        ),
    ];
    for (name, sym, asym, ours) in rows {
        let _ = writeln!(md, "| {name} | {sym} | {asym} | {ours} |");
    }
    // Offset against asymmetry once Coulomb friction is in the model.
    let fc = rounds[0]
        .diagnosis
        .effects
        .iter()
        .find(|f| f.name == "coulomb")
        .and_then(|f| crate::effect_spec::EffectSpec::parse(&f.spec).ok())
        .map(|s| s.get("fc"));
    if let Some(fc) = fc {
        let d = emps_loop::after_coulomb(train, &rounds[0].model, fc);
        let t = |name: &str| d.tested.iter().find(|t| t.name == name);
        if let (Some(o), Some(a)) = (t("offset"), t("asymmetry")) {
            let _ = writeln!(
                md,
                "\nWhy no separate offset: with Coulomb friction in the model, `diagnose` tests \
                 the offset (explains {:.0} % of the residual, p = {:.1e}, `{}` = {:.2} N) and \
                 the asymmetry (explains {:.0} %, p = {:.1e}); both are significant, and it keeps \
                 the one that explains more. On this trajectory the axis moves at nearly the same \
                 speed in both directions and the standstill windows are left out, so `dv·|v|` \
                 and a constant are nearly the same column: the symmetric model's OF is the \
                 asymmetry seen at the typical speed. With the asymmetry in, the offset explains \
                 {} of what is left.",
                100.0 * o.explained,
                o.p_value,
                o.spec,
                g * crate::effect_spec::EffectSpec::parse(&o.spec)
                    .map_or(f64::NAN, |s| s.get("t0")),
                100.0 * a.explained,
                a.p_value,
                rounds
                    .get(1)
                    .and_then(|r| r.diagnosis.tested.iter().find(|t| t.name == "offset"))
                    .map_or("–".to_string(), |t| format!(
                        "{:.1} % (p = {:.1e})",
                        100.0 * t.explained,
                        t.p_value
                    ))
            );
        }
    }
    Ok(())
}

fn benchmark_train(model: &crate::model::Model, train: &crate::log::MotorLog) -> f64 {
    emps_loop::benchmark_rmse_mm(model, &emps_loop::prepare(train, 1)).map_or(f64::NAN, |r| r.0)
}

fn scale(x: &[f64], k: f64) -> Vec<f64> {
    x.iter().map(|v| v * k).collect()
}

fn fmt_opt(v: Option<f64>) -> String {
    v.map_or("–".to_string(), |x| format!("{x:.3e}"))
}

fn stribeck_p(sel: &Selection) -> String {
    match sel.test_of(Term::Stribeck) {
        Some(c) => format!(
            "{:.1e}{}",
            c.p,
            c.rejected
                .as_ref()
                .map_or(String::new(), |r| format!(" ({r})"))
        ),
        None => "–".into(),
    }
}

fn one_sided(o: &crate::real_data::static_curve::OneSided) -> String {
    let verdict = if o.has_stribeck() {
        "**Stribeck**"
    } else {
        "line"
    };
    match (o.p, o.vs) {
        (Some(p), Some(vs)) => format!("{p:.1e}, {vs:.2} → {verdict}"),
        _ => format!("no Fs > 0 fit → {verdict}"),
    }
}

fn screw_section(md: &mut String, data: &Path, out: &Path) -> Result<()> {
    progress("screw drives: static curves");
    let _ = writeln!(md, "\n### TRO2021 screw drives (static friction curves)\n");
    let _ = writeln!(
        md,
        "Each speed set-point is reduced to one (mean velocity, mean torque) point (first 10 % \
         of each run skipped). Starting from Coulomb + viscous, offset, asymmetry (|v|) and \
         Stribeck `Fs·exp(−(v/vs)²)·sgn v` are added one at a time while the extra-sum-of-squares \
         F-test gives p < {} (Stribeck also needs Fs > 0). Stribeck is also tested in each \
         direction alone (line + Stribeck against a line, Fs > 0), and each direction gets its \
         own curve (→ line or Stribeck; drawn in the figures). Velocity in rad/s at the motor \
         (as recorded: the authors' loader negates both signals), torque in N·m.\n",
        crate::real_data::static_curve::ALPHA
    );
    let _ = writeln!(md, "| drive | points | selected terms | Fc | Fv | offset | Dv | Fs | vs [rad/s] | authors' strbVelocity | Stribeck p (both directions) | Stribeck p, vs → curve (v > 0 only) | Stribeck p, vs → curve (v < 0 only) | residual σ |");
    let _ = writeln!(
        md,
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
    );
    for k in 1..=3 {
        let r = screw_drives::analyse(data, k)?;
        let c = &r.selection.chosen;
        let names: Vec<&str> = c.terms.iter().map(|t| t.name()).collect();
        let _ = writeln!(
            md,
            "| {} {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {:.2e} |",
            k,
            r.name,
            r.points.len(),
            names.join(", "),
            fmt_opt(c.get(Term::Coulomb)),
            fmt_opt(c.get(Term::Viscous)),
            fmt_opt(c.get(Term::Offset)),
            fmt_opt(c.get(Term::Asymmetry)),
            fmt_opt(c.get(Term::Stribeck)),
            c.vs.map_or("–".into(), |v| format!("{v:.3}")),
            r.authors_vs,
            stribeck_p(&r.selection),
            one_sided(&r.one_sided[0]),
            one_sided(&r.one_sided[1]),
            c.residual_std()
        );
        let vmax = r.points.iter().map(|p| p.v.abs()).fold(0.0, f64::max);
        let grid: Vec<f64> = (0..=400)
            .map(|j| -vmax + 2.0 * vmax * j as f64 / 400.0)
            .filter(|v| *v != 0.0)
            .collect();
        let curve = |cv: &crate::real_data::static_curve::Curve| -> Vec<(f64, f64)> {
            grid.iter().map(|&v| (v, 1e3 * cv.eval(v))).collect()
        };
        let (neg, pos): (Vec<_>, Vec<_>) = curve(c).into_iter().partition(|p| p.0 < 0.0);
        let (bneg, bpos): (Vec<_>, Vec<_>) = curve(&r.selection.base)
            .into_iter()
            .partition(|p| p.0 < 0.0);
        let pts: Vec<(f64, f64)> = r.points.iter().map(|p| (p.v, 1e3 * p.tau)).collect();
        // The curve of each direction fitted on its own points (line, + Stribeck if selected).
        let side = |o: &crate::real_data::static_curve::OneSided| -> Vec<(f64, f64)> {
            o.curve.as_ref().map_or(Vec::new(), |cv| {
                grid.iter()
                    .filter(|v| o.sign * **v > 0.0)
                    .map(|&v| (v, 1e3 * cv.eval(v)))
                    .collect()
            })
        };
        let label = |o: &crate::real_data::static_curve::OneSided| {
            if o.has_stribeck() {
                "with Stribeck"
            } else {
                "line"
            }
        };
        let side_label = format!(
            "per direction: v > 0 {}, v < 0 {}",
            label(&r.one_sided[0]),
            label(&r.one_sided[1])
        );
        let name = format!("screw_drive_{k}_static_curve.svg");
        plots::figure(
            &out.join(&name),
            &format!("TRO2021 drive {k} ({}): steady-state friction", r.name),
            "velocity [rad/s]",
            "torque [mN·m]",
            &[
                Series::dots("measured (mean per set-point)", pts, 0),
                Series::line("Coulomb + viscous", bneg, 1),
                Series::line("", bpos, 1),
                Series::line(&format!("selected: {}", names.join(" + ")), neg, 2),
                Series::line("", pos, 2),
                Series::line(&side_label, side(&r.one_sided[0]), 3),
                Series::line("", side(&r.one_sided[1]), 3),
            ],
        )?;
    }
    for k in 1..=3 {
        fig_link(
            md,
            out,
            &format!("screw_drive_{k}_static_curve.svg"),
            &format!("screw drive {k}"),
        );
    }
    Ok(())
}

fn omni_section(md: &mut String, data: &Path, out: &Path) -> Result<()> {
    progress("OmniRobot DC motors");
    let _ = writeln!(md, "\n### OmniRobot DC motors (Coulomb + viscous)\n");
    let _ = writeln!(
        md,
        "Steady-state points per speed plateau (first 30 % of each plateau skipped, current \
         signed by the velocity, torque = k_t·i with k_t = {} N·m/A), fitted with \
         `T = T_0·sgn ω + b·ω`; beside the authors' values.\n",
        omni_dc::KT
    );
    let _ = writeln!(md, "| motor | speed loop | b [N·m·s/rad] (authors) | b (this tool) | T_0 [N·m] (authors) | T_0 (this tool) | further terms the F-test supports |");
    let _ = writeln!(md, "|---|---|---|---|---|---|---|");
    let mut series = Vec::new();
    for m in 1..=3 {
        let (b_ref, t0_ref) = omni_dc::REFERENCE[m - 1];
        for (fi, file) in omni_dc::FILES.iter().enumerate() {
            let r = omni_dc::analyse(data, file, m)?;
            let b = r.curve.get(Term::Viscous).unwrap_or(f64::NAN);
            let t0 = r.curve.get(Term::Coulomb).unwrap_or(f64::NAN);
            let extra: Vec<&str> = r
                .selection
                .chosen
                .terms
                .iter()
                .filter(|t| !matches!(t, Term::Coulomb | Term::Viscous))
                .map(|t| t.name())
                .collect();
            let _ = writeln!(
                md,
                "| {m} | {} | {b_ref:.4e} | {b:.4e} ± {:.1e} | {t0_ref:.5} | {t0:.5} ± {:.1e} | {} |",
                if fi == 0 { "P" } else { "PI" },
                r.curve.sigma[1],
                r.curve.sigma[0],
                if extra.is_empty() { "none".to_string() } else { extra.join(", ") }
            );
            if fi == 0 {
                series.push(Series::dots(
                    &format!("motor {m} measured"),
                    r.points.iter().map(|p| (p.v, 1e3 * p.torque)).collect(),
                    m,
                ));
                let vmax = r.points.iter().map(|p| p.v.abs()).fold(0.0, f64::max);
                for sign in [-1.0, 1.0] {
                    let pts: Vec<(f64, f64)> = (1..=100)
                        .map(|j| sign * vmax * j as f64 / 100.0)
                        .map(|v| (v, 1e3 * (t0_ref * v.signum() + b_ref * v)))
                        .collect();
                    let label = if sign > 0.0 {
                        format!("motor {m}: authors' b, T_0")
                    } else {
                        String::new()
                    };
                    series.push(Series::line(&label, pts, m));
                }
            }
        }
    }
    plots::figure(
        &out.join("omni_dc_motors_friction.svg"),
        "OmniRobot DC motors: steady-state friction (P speed loop)",
        "velocity [rad/s]",
        "torque k_t·i [mN·m]",
        &series,
    )?;
    fig_link(
        md,
        out,
        "omni_dc_motors_friction.svg",
        "OmniRobot DC motors",
    );
    Ok(())
}
