//! `motorid demo` as a user runs it: the hidden effect is named and found, the validation
//! error falls, and the report is written.
use tests::motorid;

fn xdot_of(line: &str) -> f64 {
    let at = line.find("xdot").expect("no xdot on the step line");
    line[at + 4..]
        .split_whitespace()
        .next()
        .unwrap()
        .parse()
        .unwrap()
}

#[test]
fn demo_finds_the_hidden_effect_and_the_error_falls() {
    let dir = tempfile::tempdir().unwrap();
    let out = motorid(
        dir.path(),
        &[
            "demo",
            "--effect",
            "position_load:amp=0.05",
            "--duration",
            "45",
            "--seed",
            "3",
            "--report",
            "rep",
        ],
    );
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "demo failed: {text}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(text.contains("position_load: FOUND"), "{text}");
    let steps: Vec<f64> = text
        .lines()
        .filter(|l| l.starts_with("step "))
        .map(xdot_of)
        .collect();
    assert!(steps.len() >= 2, "{text}");
    assert!(
        steps.last().unwrap() > steps.first().unwrap(),
        "validation velocity fit did not improve: {steps:?}"
    );
    let html = std::fs::read_to_string(dir.path().join("rep").join("index.html")).unwrap();
    assert!(html.contains("<svg") && html.contains("position_load"));
}
