//! `motorid export` → `motorid inspect`: the blob round-trips the model, and damaged blobs
//! are refused with one `error:` line naming the file.
use e2e::{motorid, PAPER_LUGRE_MODEL};
use std::path::Path;

/// The paper's LuGre motor with two effects.
fn model() -> String {
    format!("{PAPER_LUGRE_MODEL}{EFFECTS}")
}

const EFFECTS: &str = r#"
[[effects]]
name = "cogging"
harmonic = 6
amp = 0.01
phase = 0.5

[[effects]]
name = "offset"
t0 = -0.02
"#;

fn export(dir: &Path) -> Vec<u8> {
    std::fs::write(dir.join("m.toml"), model()).unwrap();
    let out = motorid(dir, &["export", "m.toml", "-o", "c.bin"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    std::fs::read(dir.join("c.bin")).unwrap()
}

fn error_line(out: &std::process::Output) -> String {
    assert!(!out.status.success(), "expected a failure");
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    let lines: Vec<&str> = err.lines().collect();
    assert_eq!(lines.len(), 1, "one error line expected, got: {err}");
    assert!(lines[0].starts_with("error: "), "{err}");
    assert!(
        !err.contains("panicked") && !err.contains("internal error"),
        "{err}"
    );
    lines[0].to_string()
}

#[test]
fn export_inspect_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let bytes = export(dir.path());
    assert_eq!(&bytes[..4], b"MIDC");
    let out = motorid(dir.path(), &["inspect", "c.bin", "--json"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["model"], "lugre");
    assert_eq!(v["bytes"], bytes.len());
    let names: Vec<&str> = v["effects"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["cogging", "offset"]);
    assert_eq!(
        v["effects"][0]["spec"],
        "cogging:harmonic=6,amp=0.01,phase=0.5"
    );
    let c = &v["coefficients"];
    // The limits the board derives from the blob are shown beside it.
    let d = &v["derived_limits"];
    let i_max = c["limits"]["i_max"].as_f64().unwrap();
    let held = d["current_limit_a"].as_f64().unwrap();
    assert!(held > 0.0 && held < i_max, "{held} vs {i_max}");
    assert!(d["speed_limit_rad_s"].as_f64().unwrap() > 0.0);
    assert!(d["ramp_rad_s2"].as_f64().unwrap() > 0.0);
    // f32 on the board: compare at single precision.
    let close = |x: &serde_json::Value, want: f64| {
        let x = x.as_f64().unwrap();
        assert!(
            (x - want).abs() <= 1e-6 * want.abs().max(1.0),
            "{x} vs {want}"
        );
    };
    close(&c["lugre"]["sigma0"], 317.225);
    close(&c["lugre"]["alpha0"], 0.08);
    close(&c["motor"]["kt"], 0.07126);
    // 0.095 rad Hall steps of the paper's motor: 11 pole pairs by default.
    assert_eq!(c["pole_pairs"], 11);
}

#[test]
fn damaged_blobs_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let bytes = export(dir.path());
    // Truncated: every proper prefix is refused.
    for cut in [0, 3, 8, bytes.len() / 2, bytes.len() - 1] {
        std::fs::write(dir.path().join("t.bin"), &bytes[..cut]).unwrap();
        let line = error_line(&motorid(dir.path(), &["inspect", "t.bin", "--json"]));
        assert!(line.contains("t.bin"), "{line}");
    }
    // One flipped bit anywhere: refused (CRC, magic, version or length).
    for pos in [0, 5, 12, bytes.len() / 2, bytes.len() - 1] {
        let mut b = bytes.clone();
        b[pos] ^= 0x10;
        std::fs::write(dir.path().join("x.bin"), &b).unwrap();
        let line = error_line(&motorid(dir.path(), &["inspect", "x.bin"]));
        assert!(line.contains("x.bin"), "{line}");
    }
    let mid = bytes.len() / 2;
    let mut b = bytes.clone();
    b[mid] ^= 0x10;
    std::fs::write(dir.path().join("x.bin"), &b).unwrap();
    let line = error_line(&motorid(dir.path(), &["inspect", "x.bin"]));
    assert!(line.contains("CRC"), "{line}");
}

#[test]
fn bad_model_leaves_no_blob() {
    let dir = tempfile::tempdir().unwrap();
    let bad = model().replace("j = 0.0003", "j = -1.0");
    std::fs::write(dir.path().join("m.toml"), bad).unwrap();
    let line = error_line(&motorid(dir.path(), &["export", "m.toml", "-o", "c.bin"]));
    assert!(
        line.contains("m.toml") && line.contains("motor.j"),
        "{line}"
    );
    assert!(!dir.path().join("c.bin").exists());
}
