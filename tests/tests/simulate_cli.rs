//! `motorid simulate` as a user runs it: motor logs, `--truth`, `--help`, bad input.
use e2e::motorid;
use motorid::log::{ColumnMap, MotorLog, Plant};
use std::path::Path;

fn read(path: &Path) -> MotorLog {
    MotorLog::read(path, &ColumnMap::default(), Plant::Voltage).unwrap()
}

#[test]
fn signal_a_with_cogging_writes_a_motor_log() {
    let dir = tempfile::tempdir().unwrap();
    let out = motorid(
        dir.path(),
        &[
            "simulate", "--signal", "a", "--effect", "cogging", "-o", "a.csv",
        ],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let summary = String::from_utf8_lossy(&out.stdout);
    assert!(summary.contains("7500 samples"), "summary: {summary}");
    let log = read(&dir.path().join("a.csv"));
    assert_eq!(log.len(), 7500);
    assert_eq!(log.sample_period(), 0.012);
    let res = log.meta_f64("hall_resolution_rad").unwrap();
    // The metadata is the full f64, computed in another order: rounding only.
    assert!((res - 2.0 * std::f64::consts::PI / 66.0).abs() < 1e-12);
    assert_eq!(log.meta["signal"], "a");
    assert!(log.meta["effects"].starts_with("cogging"));
    let omega = log.omega.as_ref().expect("omega column");
    let i = log.i.as_ref().expect("i column");
    // The fitting signal spans 0-12 V both ways and moves the motor both ways.
    let umax = log.u.iter().fold(0.0f64, |a, x| a.max(x.abs()));
    assert!(umax > 11.0 && umax <= 12.0, "max |u| = {umax}");
    assert!(omega.iter().any(|w| *w > 50.0) && omega.iter().any(|w| *w < -50.0));
    assert!(i.iter().all(|x| x.is_finite()));
    // Without --truth there are no truth columns.
    assert!(log.extra("theta_true").is_none());
}

#[test]
fn truth_columns_and_determinism() {
    let dir = tempfile::tempdir().unwrap();
    let run = |seed: &str, name: &str| {
        let out = motorid(
            dir.path(),
            &[
                "simulate",
                "--signal",
                "d",
                "--duration",
                "10",
                "--seed",
                seed,
                "--truth",
                "--effect",
                "offset:t0=0.02",
                "--effect",
                "current_offset",
                "-o",
                name,
            ],
        );
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        std::fs::read_to_string(dir.path().join(name)).unwrap()
    };
    let a = run("3", "x.csv");
    assert_eq!(a, run("3", "y.csv"), "same seed, same log");
    assert_ne!(a, run("4", "z.csv"), "another seed, another log");
    let log = read(&dir.path().join("x.csv"));
    assert_eq!(log.len(), (10.0f64 / 0.012).round() as usize);
    for c in ["theta_true", "omega_true", "z_true", "i_true"] {
        assert!(log.extra(c).is_some(), "missing {c}");
    }
    // Measured current = true + offset (0.2 A default) + noise (0.02 A): the mean difference
    // is the offset.
    let i = log.i.as_ref().unwrap();
    let it = log.extra("i_true").unwrap();
    let mean = i.iter().zip(it).map(|(a, b)| a - b).sum::<f64>() / i.len() as f64;
    // 0.005 A: twenty standard errors of the mean of 833 noise draws of 0.02 A.
    assert!((mean - 0.2).abs() < 0.005, "mean offset {mean}");
}

#[test]
fn help_lists_every_signal_and_effect_with_keys() {
    let dir = tempfile::tempdir().unwrap();
    let out = motorid(dir.path(), &["simulate", "--help"]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    for name in control::effects::EffectKind::ALL.map(|k| k.name()) {
        assert!(text.contains(name), "--help does not list effect {name}");
    }
    for key in ["harmonic=", "sigma0=", "vd=", "tau=", "j2=", "gap="] {
        assert!(text.contains(key), "--help does not list key {key}");
    }
    for sig in ["steady", "ramp", "0.1-1 Hz", "0.5 V"] {
        assert!(text.contains(sig), "--help does not describe {sig}");
    }
}

#[test]
fn bad_effect_is_one_error_line_and_no_file() {
    let dir = tempfile::tempdir().unwrap();
    for (spec, says) in [
        ("cogging:h=3", "unknown key 'h'"),
        ("gravity", "gravity"),
        ("offset:t0=abc", "not a number"),
        ("compliance:k=-1", "compliance"),
        ("compliance:j2=0", "compliance"),
        ("backlash:width=0.1", "unknown key 'width'"),
        ("backlash:gap=-0.1", "gap"),
    ] {
        let out = motorid(
            dir.path(),
            &[
                "simulate", "--signal", "c", "--effect", spec, "-o", "bad.csv",
            ],
        );
        assert!(!out.status.success(), "{spec} was accepted");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.starts_with("error:"), "stderr: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "stderr: {err}");
        assert!(err.contains(says), "{spec}: stderr {err}");
        assert!(!dir.path().join("bad.csv").exists());
    }
    let out = motorid(
        dir.path(),
        &[
            "simulate",
            "--signal",
            "a",
            "--duration=-3",
            "-o",
            "bad.csv",
        ],
    );
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).starts_with("error:"));
}

#[test]
fn compliance_and_backlash_change_the_log_and_report_the_load() {
    let dir = tempfile::tempdir().unwrap();
    let run = |effect: Option<&str>, name: &str| {
        let mut args = vec!["simulate", "--signal", "a", "--duration", "10", "--truth"];
        if let Some(e) = effect {
            args.extend(["--effect", e]);
        }
        args.extend(["-o", name]);
        let out = motorid(dir.path(), &args);
        assert!(
            out.status.success(),
            "{effect:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        read(&dir.path().join(name))
    };
    let plain = run(None, "plain.csv");
    assert!(plain.extra("theta_load_true").is_none());
    let w0 = plain.extra("omega_true").unwrap();
    for (effect, name) in [
        ("compliance", "c.csv"),
        ("backlash", "b.csv"),
        ("compliance:j2=3e-4,k=2,c=1e-3", "c2.csv"),
        ("backlash:j2=1e-4,gap=0.5", "b2.csv"),
    ] {
        let log = run(Some(effect), name);
        assert_eq!(log.len(), plain.len());
        for c in ["theta", "omega", "i"] {
            assert!(
                log.extra(&format!("{c}_true")).is_some(),
                "{effect}: {c}_true"
            );
        }
        // The sensors see the rotor; the load is reported beside it and moves with it.
        let (th, thl) = (
            log.extra("theta_true").unwrap(),
            log.extra("theta_load_true").expect("theta_load_true"),
        );
        assert!(log.extra("omega_load_true").is_some());
        let hall = log.meta["hall_resolution_rad"].parse::<f64>().unwrap();
        for (k, q) in log.theta.iter().enumerate() {
            // Half a Hall step, plus 1e-9 rad for the step's rounding in the decoder's count.
            assert!((q - th[k]).abs() <= 0.5 * hall + 1e-9, "{effect}: row {k}");
        }
        let travel = th.iter().fold(0.0f64, |a, x| a.max(x.abs()));
        let lag = th
            .iter()
            .zip(thl)
            .fold(0.0f64, |a, (x, y)| a.max((x - y).abs()));
        // The load follows within a tenth of the rotor's travel: coupled, not left behind.
        assert!(
            travel > 10.0 && lag < 0.1 * travel,
            "{effect}: travel {travel}, lag {lag}"
        );
        // The load changes the rotor's motion.
        let w = log.extra("omega_true").unwrap();
        let d =
            (w.iter().zip(w0).map(|(a, b)| (a - b).powi(2)).sum::<f64>() / w.len() as f64).sqrt();
        assert!(d > 0.1, "{effect}: speed changes by {d} rad/s rms");
    }
}
