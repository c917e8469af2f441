//! `motorid emulate`: the compensation experiment on the emulated board.
use e2e::motorid;

const LUGRE: &str = e2e::PAPER_LUGRE_MODEL;

fn json(out: &std::process::Output) -> serde_json::Value {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn pi_tracks_and_compensation_changes_the_loop() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("l.toml"), LUGRE).unwrap();
    let none = json(&motorid(
        d,
        &["emulate", "--reference", "step", "--json", "--svg", "s.svg"],
    ));
    assert_eq!(none["compensation"], "none");
    assert_eq!(none["samples"], 1500);
    let rms = none["rms"].as_f64().unwrap();
    // The PI loop tracks: the error is a fraction of the ±10 rad/s steps, not zero (Hall
    // quantisation, stiction at every reversal).
    assert!(rms > 0.05 && rms < 5.0, "rms {rms}");
    let svg = std::fs::read_to_string(d.join("s.svg")).unwrap();
    assert!(svg.starts_with("<svg") && svg.contains("ω_ref"));

    let lugre = json(&motorid(
        d,
        &[
            "emulate",
            "--reference",
            "step",
            "--compensation",
            "lugre",
            "--model",
            "l.toml",
            "--json",
        ],
    ));
    assert_eq!(lugre["compensation"], "lugre");
    assert_ne!(lugre["rms"], none["rms"], "compensation had no effect");
    assert!(lugre["rms_low"].as_f64().unwrap().is_finite());
}

/// LuGre compensation must cut the low-speed tracking error on the sine reference. The
/// model here is the emulator's TRUE LuGre (the paper's parameters, `LUGRE` above), not a
/// fitted one: fitting takes too long for a test; `scripts/compensation-table.sh` runs the
/// same experiment with fitted models.
#[test]
fn lugre_compensation_cuts_low_speed_error_on_sine_true_parameters() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("l.toml"), LUGRE).unwrap();
    let run = |comp: &str| {
        json(&motorid(
            d,
            &[
                "emulate",
                "--reference",
                "sine",
                "--compensation",
                comp,
                "--model",
                "l.toml",
                "--json",
            ],
        ))
    };
    let (none, lugre) = (run("none"), run("lugre"));
    let low = |v: &serde_json::Value| v["rms_low"].as_f64().unwrap();
    let all = |v: &serde_json::Value| v["rms"].as_f64().unwrap();
    assert!(none["low_speed_samples"].as_u64().unwrap() > 100);
    // At least a 25 % cut at low speed, and no loss overall.
    assert!(
        low(&lugre) < 0.75 * low(&none),
        "low-speed RMS: lugre {} vs none {}",
        low(&lugre),
        low(&none)
    );
    assert!(
        all(&lugre) < all(&none),
        "overall RMS: lugre {} vs none {}",
        all(&lugre),
        all(&none)
    );
}

#[test]
fn compensation_without_its_model_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let out = motorid(dir.path(), &["emulate", "--compensation", "sindyc"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.starts_with("error: --compensation sindyc"), "{err}");
}

#[test]
fn trace_out_records_every_step() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = motorid(
        d,
        &["emulate", "--reference", "sine", "--trace-out", "t.qpt"],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let b = std::fs::read(d.join("t.qpt")).unwrap();
    assert_eq!(&b[..4], b"QPT2");
    let steps = u32::from_le_bytes(b[4..8].try_into().unwrap());
    assert_eq!(steps, 1667); // 20 s at 12 ms
                             // Walk the records: each is 24 bytes plus 8 per Hall edge; the motor turns, so edges exist.
    let (mut at, mut edges) = (8usize, 0usize);
    for _ in 0..steps {
        let n = b[at + 1] as usize;
        edges += n;
        at += 24 + 8 * n;
    }
    assert_eq!(at, b.len());
    assert!(edges > 100, "{edges} Hall edges");
}
