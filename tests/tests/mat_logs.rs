//! MATLAB MAT-files as logs: the EMPS benchmark's `.mat` files (../shared/data/EMPS, read in
//! place) give the same log as its CSV files, and `motorid fit` takes them with `--map`.
use motorid::log::{ColumnMap, MotorLog, Plant};
use std::path::PathBuf;
use tests::motorid;

/// The EMPS folder; absent data skips the test with a printed reason, but fails under CI.
fn emps_dir(test: &str) -> Option<PathBuf> {
    let d = tests::root()
        .join("..")
        .join("shared")
        .join("data")
        .join("EMPS");
    if d.join("DATA_EMPS.mat").is_file() {
        return Some(d);
    }
    assert!(
        std::env::var_os("CI").is_none(),
        "{test}: {} is missing under CI",
        d.join("DATA_EMPS.mat").display()
    );
    eprintln!("SKIPPED {test}: {} is not present", d.display());
    None
}

#[test]
fn emps_mat_files_read_as_their_csv_twins() {
    let Some(d) = emps_dir("emps_mat_files_read_as_their_csv_twins") else {
        return;
    };
    for name in ["DATA_EMPS", "DATA_EMPS_PULSES"] {
        let mat = MotorLog::read(
            &d.join(format!("{name}.mat")),
            &ColumnMap::parse("u=vir,theta=qm").unwrap(),
            Plant::Torque,
        )
        .unwrap();
        let csv = MotorLog::read(
            &d.join(format!("{name}.csv")),
            &ColumnMap::parse("t=t_s,u=vir_V,theta=qm_m").unwrap(),
            Plant::Torque,
        )
        .unwrap();
        assert_eq!(mat.len(), csv.len(), "{name}");
        assert!(mat.len() > 20_000, "{name}: {} samples", mat.len());
        // The CSV holds 10 significant digits.
        for (a, b) in [(&mat.t, &csv.t), (&mat.u, &csv.u), (&mat.theta, &csv.theta)] {
            let worst = a
                .iter()
                .zip(b.iter())
                .map(|(x, y)| (x - y).abs() / y.abs().max(1e-6))
                .fold(0.0, f64::max);
            assert!(worst < 1e-8, "{name}: relative difference {worst}");
        }
        // The scalars (gear ratio and gains) are metadata; the other vectors extra columns.
        assert!(mat.meta_f64("gtau").is_some_and(|g| g > 1.0), "{name}");
        assert!(mat.extra("qg").is_some(), "{name}");
    }
}

#[test]
fn fit_takes_a_mat_file_with_map() {
    let Some(d) = emps_dir("fit_takes_a_mat_file_with_map") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let train = d.join("DATA_EMPS.mat");
    let out = motorid(
        dir.path(),
        &[
            "fit",
            "--model",
            "linear",
            "--plant",
            "torque",
            "--map",
            "u=vir,theta=qm",
            "--units",
            "theta=m",
            "-o",
            "emps.toml",
            train.to_str().unwrap(),
        ],
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let text = std::fs::read_to_string(dir.path().join("emps.toml")).unwrap();
    assert!(
        text.contains("DATA_EMPS.mat"),
        "the model names its source:\n{text}"
    );
    // A wrong name is one error line naming the file and the variables it has.
    let out = motorid(
        dir.path(),
        &[
            "fit",
            "--model",
            "linear",
            "--plant",
            "torque",
            "--map",
            "u=vir,theta=position",
            "-o",
            "x.toml",
            train.to_str().unwrap(),
        ],
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(
        stderr.starts_with("error: ")
            && stderr.contains("DATA_EMPS.mat: missing column 'position'"),
        "{stderr}"
    );
    assert!(stderr.contains("qm"), "{stderr}");
}
