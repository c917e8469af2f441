//! `cargo xtask real-data`: writes the figures and the markdown tables of docs/real-data.md.
use e2e::{shared_data, xtask};

#[test]
fn real_data_writes_figures_and_tables() {
    let Some(data) = shared_data("real_data_writes_figures_and_tables") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = xtask(
        dir.path(),
        &[
            "real-data",
            "--data",
            data.to_str().unwrap(),
            "--out",
            "figs",
            // The generic loops and the criteria refits are tested in real_data_emps.rs;
            // here the command's pages and figures (minutes less of CI).
            "--no-generic",
        ],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let md = String::from_utf8_lossy(&out.stdout);
    let saved = std::fs::read_to_string(dir.path().join("figs/real-data.md")).unwrap();
    assert_eq!(md, saved);
    for needle in [
        "| M | 95.1089",
        "DATA_EMPS_PULSES",
        "screw drives",
        "OmniRobot",
    ] {
        assert!(md.contains(needle), "tables lack {needle}");
    }
    for f in [
        "emps_test_free_run.svg",
        "screw_drive_1_static_curve.svg",
        "screw_drive_2_static_curve.svg",
        "screw_drive_3_static_curve.svg",
        "omni_dc_motors_friction.svg",
    ] {
        let svg = std::fs::read_to_string(dir.path().join("figs").join(f)).unwrap();
        assert!(
            svg.contains("<svg") && svg.trim_end().ends_with("</svg>"),
            "{f}"
        );
        // Each figure links from the tables.
        assert!(md.contains(f), "{f} not linked");
    }
}

#[test]
fn missing_data_folder_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let out = xtask(dir.path(), &["real-data", "--data", "no/such/dir"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.starts_with("error: no/such/dir"), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
}
