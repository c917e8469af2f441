//! MATLAB MAT-files as logs: the EMPS benchmark's `.mat` files (../shared/data/EMPS, read in
//! place) give the same log as its CSV files, and `motorid fit` takes them with `--map`.
use e2e::motorid;
use motorid::log::{ColumnMap, MotorLog, Plant};
use std::path::PathBuf;

/// The EMPS folder ([`e2e::shared_data`]: absent data skips with a printed reason, but
/// fails under CI).
fn emps_dir(test: &str) -> Option<PathBuf> {
    Some(e2e::shared_data(test)?.join("EMPS"))
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

/// `motorid fit ... FILE` expected to fail: its one stderr line, and no model written.
fn refused(dir: &std::path::Path, file: &str) -> String {
    let out = motorid(
        dir,
        &[
            "fit",
            "--model",
            "linear",
            "--plant",
            "torque",
            "--map",
            "u=vir,theta=qm",
            "-o",
            "m.toml",
            file,
        ],
    );
    let stderr = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(!out.status.success(), "{file}: accepted");
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(stderr.starts_with(&format!("error: {file}")), "{stderr}");
    assert!(!dir.join("m.toml").exists(), "{file}: a model was written");
    stderr
}

#[test]
fn v73_truncated_and_damaged_mat_files_are_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A v7.3 file is HDF5 behind the same 128-byte header with version 0x0200.
    let mut v73 = format!("{:<116}", "MATLAB 7.3 MAT-file, Platform: GLNXA64").into_bytes();
    v73.extend_from_slice(&[0; 8]);
    v73.extend_from_slice(&[0x00, 0x02]);
    v73.extend_from_slice(b"IM");
    v73.extend_from_slice(b"\x89HDF\r\n\x1a\n");
    std::fs::write(d.join("v73.mat"), &v73).unwrap();
    let e = refused(d, "v73.mat");
    assert!(e.contains("v7.3") && e.contains("'-v7'"), "{e}");
    std::fs::write(d.join("short.mat"), b"MATLAB 5.0").unwrap();
    let e = refused(d, "short.mat");
    assert!(e.contains("not a MATLAB MAT-file"), "{e}");

    let Some(emps) = emps_dir("v73_truncated_and_damaged_mat_files_are_one_error_line") else {
        return;
    };
    let bytes = std::fs::read(emps.join("DATA_EMPS.mat")).unwrap();
    std::fs::write(d.join("cut.mat"), &bytes[..bytes.len() * 2 / 3]).unwrap();
    let e = refused(d, "cut.mat");
    assert!(e.contains("byte ") && e.contains("truncated"), "{e}");
    let mut damaged = bytes.clone();
    for b in &mut damaged[400..440] {
        *b ^= 0xa5;
    }
    std::fs::write(d.join("damaged.mat"), &damaged).unwrap();
    let e = refused(d, "damaged.mat");
    assert!(e.contains("byte "), "{e}");
}
