//! The HTML report is a real page: headless Chromium renders it and its DOM holds the SVG
//! plots and the tables. Chromium comes from Debian's `chromium` package; the test installs it
//! when missing, or skips with a message when it cannot.
use control::effects::Effect;
use motorid::diagnose::{diagnose, Options, Structure};
use motorid::emulator::{simulate_signal, EmulatorConfig, SignalKind};
use motorid::log::Plant;
use motorid::model::{LugreParams, Model, ModelKind};
use std::process::Command;

fn chromium() -> Option<&'static str> {
    let have = |b: &str| {
        Command::new(b)
            .arg("--version")
            .output()
            .is_ok_and(|o| o.status.success())
    };
    for b in ["chromium", "chromium-browser"] {
        if have(b) {
            return Some(b);
        }
    }
    let ok = Command::new("apt-get")
        .args(["install", "-y", "chromium"])
        .status()
        .is_ok_and(|s| s.success());
    if ok && have("chromium") {
        return Some("chromium");
    }
    eprintln!("SKIPPED report_renders_in_chromium: Debian's chromium is not installed and `apt-get install -y chromium` failed");
    None
}

#[test]
fn report_renders_in_chromium() {
    let Some(bin) = chromium() else { return };
    let mut cfg = EmulatorConfig::paper();
    cfg.effects.push(Effect::Cogging {
        harmonic: 7,
        amp: 0.03,
        phase: 0.0,
    });
    let mut log = simulate_signal(&cfg, SignalKind::A, 30.0).unwrap().log;
    log.source = "emulated.csv".into();
    let mut model = Model::new(ModelKind::Lugre, Plant::Voltage, 0.012);
    model.lugre = Some(LugreParams::paper());
    let d = diagnose(&log, &Structure::from_model(&model), &Options::default());
    let pred = motorid::ident::freerun::simulate(&model, &log).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let w =
        motorid::report::write_diagnose_report(dir.path(), &model, &log, &d, Some(&pred)).unwrap();
    let out = Command::new(bin)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-background-networking",
            "--dump-dom",
        ])
        .arg(format!("file://{}", w.path.display()))
        .output()
        .expect("cannot run chromium");
    let dom = String::from_utf8_lossy(&out.stdout);
    let svgs = dom.matches("<svg").count();
    let tables = dom.matches("<table").count();
    // The page as written holds 16 plots and 2 tables for such a log: fewer than half the
    // plots, or a table missing, after rendering means chromium did not render it.
    assert!(svgs >= 8, "only {svgs} svg elements after rendering");
    assert!(tables >= 2, "only {tables} tables after rendering");
    assert!(dom.contains("cogging"), "the finding is not on the page");
    assert!(!w.sentences.is_empty());
}
