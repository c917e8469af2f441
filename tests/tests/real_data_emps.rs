//! EMPS benchmark (../shared/data/EMPS): the authors' IDIM-LS model is reproduced, the
//! friction terms they report are significant, the generic diagnosis finds Coulomb friction,
//! and the generic CLI fits the data through `--map` and `--plant torque`.
use e2e::{motorid, shared_data};
use xtask::real_data::{emps, emps_loop};

fn logs(test: &str) -> Option<(motorid::log::MotorLog, motorid::log::MotorLog)> {
    let d = shared_data(test)?.join("EMPS");
    Some((
        emps::read(&d.join("DATA_EMPS.csv")).unwrap(),
        emps::read(&d.join("DATA_EMPS_PULSES.csv")).unwrap(),
    ))
}

#[test]
fn idim_ls_matches_the_published_estimates() {
    let Some((train, test)) = logs("idim_ls_matches_the_published_estimates") else {
        return;
    };
    let id = emps::idim_ls(&train, emps::GTAU, false).unwrap();
    // Every parameter within 3 of the authors' standard deviations of their value
    // (M ±0.33 kg, Fv ±3.4 N·s/m, Fc ±0.30 N, OF ±0.13 N).
    for (k, (name, val, sd)) in emps::REFERENCE.iter().enumerate() {
        let ours = id.ols.theta[k];
        assert!(
            (ours - val).abs() < 3.0 * sd,
            "{name}: {ours} vs reference {val} ± {sd}"
        );
    }
    // Condition number and relative errors near the published 25.99, 4.08 %, 5.98 %
    // (tolerances: the filter and decimation are written anew, not the authors' scripts).
    assert!((id.ols.cond - 25.99).abs() < 1.0, "cond {}", id.ols.cond);
    assert!((id.ols.rel_error_pct() - 4.08).abs() < 0.5);
    let cross = emps::idim_relative_error(&id.axis, &test, emps::GTAU);
    assert!((cross - 5.98).abs() < 1.0, "cross-test error {cross} %");
    // Asymmetric model: within 1 % of the published values. The same method on the same
    // data, only the filter and decimation written anew: the largest difference is 0.2 %.
    let asy = emps::idim_ls(&train, emps::GTAU, true).unwrap();
    for (k, (name, val)) in emps::REFERENCE_ASYM.iter().enumerate() {
        let ours = asy.ols.theta[k];
        assert!(
            (ours - val).abs() < 0.01 * val.abs(),
            "{name}: {ours} vs {val}"
        );
    }
}

#[test]
fn coulomb_offset_and_asymmetry_are_significant() {
    let Some((train, _)) = logs("coulomb_offset_and_asymmetry_are_significant") else {
        return;
    };
    let tests = emps::term_tests(&train, emps::GTAU).unwrap();
    // p < 1e-6: far below any level the tool tests at, so not a matter of the level chosen;
    // explains > 10 % of the residual: a term that matters, not only one that 25 000 samples
    // make significant (here p < 1e-90, 44-84 %).
    for name in ["coulomb", "offset", "asymmetry"] {
        let t = tests.iter().find(|t| t.name == name).unwrap();
        assert!(
            t.test.p_value < 1e-6 && t.test.explained > 0.1,
            "{name}: p = {}, explains {}",
            t.test.p_value,
            t.test.explained
        );
    }
}

#[test]
fn benchmark_free_run_of_the_rigid_model() {
    let Some((train, test)) = logs("benchmark_free_run_of_the_rigid_model") else {
        return;
    };
    let id = emps::idim_ls(&train, emps::GTAU, false).unwrap();
    let (rmse, sim) = emps::benchmark_rmse_mm(&id.axis, emps::GTAU, &test);
    assert_eq!(sim.len(), test.len());
    // The first 20 samples are the initialisation window: the measurement itself.
    assert_eq!(&sim[..19], &test.theta[..19]);
    // Published open-loop test RMSEs span 0.45 (dynoNet) to 12.6 mm (ARX); the physical model
    // must at least beat ARX, and a model without friction (Fc = OF = 0) must do worse.
    assert!(rmse < 12.6, "rigid model test RMSE {rmse} mm");
    let no_friction = emps::RigidAxis {
        fc: 0.0,
        offset: 0.0,
        ..id.axis
    };
    let (rmse0, _) = emps::benchmark_rmse_mm(&no_friction, emps::GTAU, &test);
    // A factor 2 asks only that friction matters on this axis, whatever the filter's details
    // (it is a factor of about 18).
    assert!(
        rmse0 > 2.0 * rmse,
        "without friction {rmse0} mm, with {rmse} mm"
    );
}

#[test]
fn generic_diagnosis_finds_coulomb_friction() {
    let Some((train, _)) = logs("generic_diagnosis_finds_coulomb_friction") else {
        return;
    };
    let prepared = emps_loop::prepare(&train, emps_loop::DECIMATION);
    let rep = motorid::ident::fit(&motorid::ident::FitRequest {
        kind: motorid::model::ModelKind::Linear,
        logs: std::slice::from_ref(&prepared),
        validate: &[],
        adds: &[],
        plant: motorid::log::Plant::Torque,
        constraints: &motorid::ident::free_params::Constraints::NONE,
    })
    .unwrap();
    let d = motorid::diagnose::diagnose(
        &prepared,
        &motorid::diagnose::Structure::from_model(&rep.model),
        &motorid::diagnose::Options::default(),
    );
    let names: Vec<&str> = d.effects.iter().map(|f| f.name.as_str()).collect();
    assert_eq!(names.first(), Some(&"coulomb"), "found {names:?}");
    // Its estimate, in newtons, is near the reference Fc = 20.39 N (25 %: on the linear model
    // the residual also holds the offset and the asymmetry, which bias a one-term estimate).
    let spec = motorid::effect_spec::EffectSpec::parse(&d.effects[0].spec).unwrap();
    let fc = emps::GTAU * spec.get("fc");
    assert!((fc - 20.39).abs() < 0.25 * 20.39, "fc = {fc} N");
}

/// The whole loop ([`motorid::workflow::run`]: fit linear, diagnose, add one finding, refit,
/// keep a refit only when the held-out end of the training log says it is better):
/// `diagnose` names Coulomb friction and the direction asymmetry (which carries the symmetric
/// model's offset on this trajectory), both are kept, and the final structure refitted on the
/// whole log lands near the authors' per-direction estimates.
#[test]
fn generic_loop_finds_coulomb_and_asymmetry_and_refits() {
    let Some((train, test)) = logs("generic_loop_finds_coulomb_and_asymmetry_and_refits") else {
        return;
    };
    let rounds = emps_loop::run(&train, &test, &mut |_| {}).unwrap();
    let names: Vec<&str> = rounds[0]
        .diagnosis
        .iter()
        .flat_map(|d| &d.effects)
        .map(|f| f.name.as_str())
        .collect();
    assert_eq!(
        names.get(..2),
        Some(&["coulomb", "asymmetry"][..]),
        "diagnosis of the linear model: {names:?}"
    );
    let last = emps_loop::final_round(&rounds).unwrap();
    assert!(
        last.whole_log,
        "the final structure is refitted on the whole log"
    );
    // Every kept refit explained the held-out end of the training log better beyond noise.
    for r in rounds.iter().skip(1).filter(|r| r.kept && !r.whole_log) {
        let t = r.selection_test.expect("a refit is tested");
        assert!(t.p_value < motorid::workflow::SELECTION_ALPHA, "{t:?}");
    }
    for kind in ["coulomb", "asymmetry"] {
        assert!(
            last.adds.iter().any(|a| a.starts_with(kind)),
            "final structure {:?} lacks {kind}",
            last.adds
        );
    }
    let p = emps_loop::physical(&last.model, emps::GTAU);
    let (fvp, _, fvm, _) = emps_loop::per_direction(&p);
    // Authors (asymmetric IDIM-LS): M 95.15 kg, Fc ≈ 20.39 N, Fv+ 166.7, Fv- 240.4 N·s/m.
    // Tolerances: the generic loop fits the free run on the 1 kHz log, not IDIM-LS on
    // filtered derivatives, so it lands near, not on, the authors' estimates.
    assert!((p.m - 95.15).abs() < 0.06 * 95.15, "M = {} kg", p.m);
    let fc = p.fc.unwrap();
    assert!((fc - 20.39).abs() < 0.15 * 20.39, "Fc = {fc} N");
    assert!(
        fvp < fvm,
        "Fv+ = {fvp}, Fv- = {fvm}: the asymmetry has the wrong sign"
    );
    let dv = p.asym.unwrap().0;
    assert!(
        (dv + 36.86).abs() < 0.4 * 36.86,
        "dv = {dv} N·s/m (authors −36.86)"
    );
    // The refit beats the linear model on the benchmark test by a factor of 5 and the
    // published ARX figure (12.6 mm).
    assert!(
        last.rmse_test_mm < 12.6 && last.rmse_test_mm < rounds[0].rmse_test_mm / 5.0,
        "test RMSE {} mm (linear {} mm)",
        last.rmse_test_mm,
        rounds[0].rmse_test_mm
    );
    // With Coulomb friction in, the offset alone is significant too (the symmetric model's
    // OF), but explains less than the asymmetry.
    let fc_v = fc / emps::GTAU;
    let d = emps_loop::after_coulomb(&train, &rounds[0].model, fc_v);
    let t = |n: &str| d.tested.iter().find(|t| t.name == n).unwrap();
    let (o, a) = (t("offset"), t("asymmetry"));
    assert!(o.p_value < d.alpha_per_test && a.p_value < d.alpha_per_test);
    assert!(a.explained > o.explained, "offset {o:?}, asymmetry {a:?}");
    let of = emps::GTAU
        * motorid::effect_spec::EffectSpec::parse(&o.spec)
            .unwrap()
            .get("t0");
    // Tolerance: the offset and the direction asymmetry are nearly the same column on this
    // trajectory (docs/real-data.md), so only the sign and a factor of two of the authors' OF
    // are asked of it.
    assert!(
        of < -3.16 / 2.0 && of > -3.16 * 2.0,
        "offset {of} N (authors −3.16)"
    );
    // The final structure refitted on the benchmark's own criterion (the free-run position
    // error from the protocol's state) fits the training log at least as well by that
    // criterion as the parameters `fit` leaves, and the route chosen on the held-out part is
    // the one with the lowest held-out error (same loop run: it is the slow part).
    let mut routes = emps_loop::criteria(&train, &test, &rounds).unwrap();
    emps_loop::choose(&mut routes);
    let by = |c: emps_loop::Criterion| routes.iter().find(|r| r.criterion == c).unwrap();
    let (fitted, oe) = (
        by(emps_loop::Criterion::AsFitted),
        by(emps_loop::Criterion::OutputError),
    );
    // Tolerance: the refit starts from the fitted parameters and only accepts steps that
    // lower its cost, so it can match but not lose (1 µm of rounding).
    assert!(
        oe.train_mm <= fitted.train_mm + 1e-3,
        "output error {} mm, as fitted {} mm",
        oe.train_mm,
        fitted.train_mm
    );
    let chosen: Vec<_> = routes.iter().filter(|r| r.chosen).collect();
    assert_eq!(chosen.len(), 1);
    // A route whose free run failed (NaN) is never chosen over one that ran.
    assert!(routes
        .iter()
        .all(|r| r.held_out_mm.is_nan() || r.held_out_mm >= chosen[0].held_out_mm));
}

/// A force over the position along the stroke (`table:var=theta` with the stroke's range,
/// 16 nodes), added to the loop's structure: the benchmark's free run on the held-out end of
/// the training log is closer with it than without, and the whole-log model's free run on
/// the test log is below the published pNARX figure (5.17 mm). The loop's own keep-or-not
/// test (the simulation error over 2 s segments) does not see the gain: a force of about a
/// newton matters only to a free run over many strokes.
/// `fit --model lugre --add asymmetry` on the first 70 % of DATA_EMPS, as the loop with a
/// LuGre model runs it: the refit explains the held-out end far better than the LuGre base
/// structure (the loop's keep-or-not test passes) and its benchmark free run there stays
/// within a few millimetres. The base structure refined alone ends with α0 at 0 and a
/// Stribeck bump below 0.1 mm/s standing in for Coulomb friction; a refinement of the added
/// effect from that start alone stays in the corner (held-out RMSE 13.6 mm, test failed).
#[test]
fn lugre_fit_with_asymmetry_leaves_the_base_structure_corner() {
    use motorid::{effect_spec::EffectSpec, ident, log::Plant, model::ModelKind, workflow};
    let Some((train, _)) = logs("lugre_fit_with_asymmetry_leaves_the_base_structure_corner") else {
        return;
    };
    let train = emps_loop::prepare(&train, emps_loop::DECIMATION);
    let (fit_part, held_out) = workflow::split_in_time(&train, workflow::SELECT_FRACTION).unwrap();
    let fit_logs = std::slice::from_ref(&fit_part);
    let select = std::slice::from_ref(&held_out);
    let asymmetry = [EffectSpec::parse("asymmetry").unwrap()];
    let fit = |adds: &[EffectSpec]| {
        ident::fit(&ident::FitRequest {
            kind: ModelKind::Lugre,
            logs: fit_logs,
            validate: select,
            adds,
            plant: Plant::Torque,
            constraints: &ident::free_params::Constraints::NONE,
        })
        .unwrap()
        .model
    };
    let base = fit(&[]);
    let refit = fit(&asymmetry);
    let t = workflow::selection_test(&base, &refit, &asymmetry[0], select);
    assert!(t.p_value < workflow::SELECTION_ALPHA, "{t:?}");
    let (rmse, _) = emps_loop::benchmark_rmse_mm(&refit, &held_out).unwrap();
    assert!(rmse < 8.0, "held-out free-run RMSE {rmse} mm");
}

#[test]
fn a_position_table_over_the_stroke_beats_the_published_free_run() {
    let Some((train, test)) = logs("a_position_table_over_the_stroke_beats_the_published_free_run")
    else {
        return;
    };
    let rounds = emps_loop::run(&train, &test, &mut |_| {}).unwrap();
    let split = rounds
        .iter()
        .rev()
        .find(|r| r.kept && !r.whole_log)
        .unwrap();
    let prepared = emps_loop::prepare(&train, emps_loop::DECIMATION);
    let (_, held_out) =
        motorid::workflow::split_in_time(&prepared, motorid::workflow::SELECT_FRACTION).unwrap();
    let without = emps_loop::benchmark_rmse_mm(&split.model, &held_out)
        .unwrap()
        .0;
    let routes = emps_loop::stroke_table_routes(
        &train,
        &test,
        &rounds,
        &[control::effects::TABLE_MAX_BINS],
        &[emps_loop::Criterion::AsFitted],
    )
    .unwrap();
    let r = &routes[0];
    assert!(
        r.held_out_mm < without,
        "held-out RMSE with the table {} mm, without {without} mm",
        r.held_out_mm
    );
    let pnarx = emps::PUBLISHED_TEST_RMSE_MM
        .iter()
        .find(|(n, _)| *n == "pNARX")
        .unwrap()
        .1;
    assert!(r.test_mm < pnarx, "test RMSE {} mm", r.test_mm);
    // The table varies along the stroke by more than a newton (the authors' standard
    // deviation of their constant offset is 0.04 N): a force, not a constant.
    let f = &r.table_forces_n;
    let spread = f.iter().copied().fold(f64::NEG_INFINITY, f64::max)
        - f.iter().copied().fold(f64::INFINITY, f64::min);
    assert!(spread > 1.0, "table forces {f:?} N");
    let t = r.table_test.unwrap();
    assert!(t.p_value >= motorid::workflow::SELECTION_ALPHA, "{t:?}");
}

#[test]
fn cli_fits_emps_through_map_and_torque_plant() {
    let Some(data) = shared_data("cli_fits_emps_through_map_and_torque_plant") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = data.join("EMPS");
    let train = d.join("DATA_EMPS.csv");
    let test = d.join("DATA_EMPS_PULSES.csv");
    let out = motorid(
        dir.path(),
        &[
            "fit",
            "--model",
            "linear",
            "--plant",
            "torque",
            "--map",
            emps::MAP,
            "-o",
            "emps.toml",
            train.to_str().unwrap(),
        ],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let model = motorid::model::Model::load(&dir.path().join("emps.toml")).unwrap();
    // u = vir [V]: the mass in V·s²/m times gτ is a mass in kg of the order of the 95 kg
    // reference (a linear model absorbs friction, so only the order is checked).
    let m = emps::GTAU * model.motor.j;
    assert!((50.0..200.0).contains(&m), "M = {m} kg");
    let out = motorid(
        dir.path(),
        &[
            "compare",
            "emps.toml",
            test.to_str().unwrap(),
            "--map",
            emps::MAP,
            "--json",
        ],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    // The velocity is followed (fit > 50 %) even by the linear model.
    let xdot = v["fit"]["xdot"].as_f64().unwrap();
    assert!(xdot > 50.0, "velocity fit {xdot} %");
}
