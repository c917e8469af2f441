//! `motorid export --format json|c-header`: the coefficients for firmware not written in
//! Rust read back into the very numbers of the blob, and the C header compiles.
use control::blob::{self, Coefficients};
use e2e::{motorid, PAPER_LUGRE_MODEL};
use std::path::Path;

fn model() -> String {
    format!(
        "{PAPER_LUGRE_MODEL}\n[[effects]]\nname = \"cogging\"\nharmonic = 6\namp = 0.01\n\
         phase = 0.5\n\n[[effects]]\nname = \"offset\"\nt0 = -0.02\n"
    )
}

/// `motorid export m.toml --kp 0.07 ARGS... -o OUT`; stderr on failure.
fn export(dir: &Path, out: &str, args: &[&str]) {
    let mut all = vec!["export", "m.toml", "--kp", "0.07", "-o", out];
    all.extend_from_slice(args);
    let o = motorid(dir, &all);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

fn setup() -> (tempfile::TempDir, Coefficients) {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("m.toml"), model()).unwrap();
    export(dir.path(), "c.bin", &[]);
    let co = blob::decode(&std::fs::read(dir.path().join("c.bin")).unwrap()).unwrap();
    (dir, co)
}

#[test]
fn json_export_reads_back_into_the_blobs_coefficients() {
    let (dir, co) = setup();
    export(dir.path(), "c.json", &["--format", "json"]);
    let v: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("c.json")).unwrap()).unwrap();
    let back: Coefficients = serde_json::from_value(v["coefficients"].clone()).unwrap();
    assert_eq!(back, co);
    assert_eq!(v["model"], "lugre");
    let param = |name: &str| {
        v["parameters"]
            .as_array()
            .unwrap()
            .iter()
            .find(|p| p["name"] == name)
            .unwrap_or_else(|| panic!("no parameter {name}"))
            .clone()
    };
    // Each number is the model's (as f32) with its unit, the effects' too.
    assert_eq!(
        param("motor.r")["value"].as_f64().unwrap() as f32,
        0.2162f32
    );
    assert_eq!(param("motor.r")["unit"], "ohm");
    assert_eq!(
        param("lugre.sigma0")["value"].as_f64().unwrap() as f32,
        317.225f32
    );
    assert_eq!(param("lugre.sigma0")["unit"], "N·m/rad");
    assert_eq!(param("pi.kp")["value"].as_f64().unwrap() as f32, 0.07f32);
    assert_eq!(
        param("effects.1.offset.t0")["value"].as_f64().unwrap() as f32,
        -0.02f32
    );
    assert_eq!(param("effects.1.offset.t0")["unit"], "N·m");
    assert_eq!(param("effects.0.cogging.harmonic")["value"], 6);
    // The layout adds up to the blob's size.
    let bytes = std::fs::read(dir.path().join("c.bin")).unwrap();
    assert_eq!(v["blob"]["bytes"], bytes.len());
    let last = v["blob"]["layout"]
        .as_array()
        .unwrap()
        .last()
        .unwrap()
        .clone();
    assert_eq!(
        last["offset"].as_u64().unwrap() + last["size"].as_u64().unwrap(),
        bytes.len() as u64
    );
}

#[test]
fn c_header_holds_every_number_and_compiles() {
    let (dir, co) = setup();
    export(dir.path(), "coeffs.h", &["--format", "c-header"]);
    let h = std::fs::read_to_string(dir.path().join("coeffs.h")).unwrap();
    let define = |name: &str| -> String {
        let line = h
            .lines()
            .find(|l| l.starts_with(&format!("#define {name} ")))
            .unwrap_or_else(|| panic!("no {name} in\n{h}"));
        line.split_whitespace().nth(2).unwrap().to_string()
    };
    let float = |name: &str| -> f32 { define(name).trim_end_matches('f').parse().unwrap() };
    assert_eq!(float("MOTORID_MOTOR_R"), co.motor.r);
    assert_eq!(float("MOTORID_MOTOR_J"), co.motor.j);
    assert_eq!(float("MOTORID_LUGRE_ALPHA0"), co.lugre.unwrap().alpha0);
    assert_eq!(float("MOTORID_PI_KP"), co.pi.kp);
    assert_eq!(float("MOTORID_EFFECTS_1_OFFSET_T0"), -0.02f32);
    assert_eq!(define("MOTORID_EFFECTS_0_COGGING_HARMONIC"), "6");
    assert_eq!(define("MOTORID_EFFECT_COUNT"), "2");
    assert!(
        h.contains("#define MOTORID_MOTOR_R 0.2162f /* [ohm] */"),
        "{h}"
    );
    let Ok(gcc) = which_gcc() else {
        eprintln!("SKIPPED the compile check: no gcc on PATH");
        return;
    };
    let c = dir.path().join("use.c");
    std::fs::write(
        &c,
        "#include \"coeffs.h\"\n#include \"coeffs.h\"\n\
         static const float r = MOTORID_MOTOR_R, a0 = MOTORID_LUGRE_ALPHA0;\n\
         static const char *kind = MOTORID_MODEL;\n\
         _Static_assert(MOTORID_EFFECT_COUNT == 2, \"two effects\");\n\
         _Static_assert(MOTORID_POLE_PAIRS > 0, \"pole pairs\");\n\
         float use(void) { return r + a0 + (float)kind[0]; }\n",
    )
    .unwrap();
    let out = std::process::Command::new(gcc)
        .args(["-std=c11", "-Wall", "-Werror", "-fsyntax-only"])
        .arg(&c)
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}\n{h}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn which_gcc() -> Result<&'static str, ()> {
    std::process::Command::new("gcc")
        .arg("--version")
        .output()
        .map(|_| "gcc")
        .map_err(|_| ())
}
