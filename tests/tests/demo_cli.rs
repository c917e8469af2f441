//! `motorid demo` as a user runs it: the hidden effect is named and found, the validation
//! error falls, and the report is written.
use e2e::motorid;

/// The fit percentage after `key` (`x`, `xdot`, `i`) on a demo step line.
fn fit_of(line: &str, key: &str) -> f64 {
    let at = line
        .find(&format!(" {key} "))
        .unwrap_or_else(|| panic!("no {key} on the step line: {line}"));
    line[at + key.len() + 2..]
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
    // The kept models, each scored on the test log no choice was made on.
    let steps: Vec<&str> = text
        .lines()
        .filter(|l| l.starts_with("step ") && !l.contains("(not kept)"))
        .collect();
    assert!(
        steps
            .iter()
            .all(|l| l.contains("test fit (fresh signal b)")),
        "{text}"
    );
    assert!(steps.len() >= 2, "{text}");
    let (first, last) = (steps[0], steps[steps.len() - 1]);
    // The angle and the current fits rise by points; the velocity fit against the Hall-based
    // estimate is bounded by its quantisation noise (about 86-90 %) and must only not fall.
    for key in ["x", "i"] {
        assert!(
            fit_of(last, key) > fit_of(first, key) + 1.0,
            "test {key} fit did not improve: {first} -> {last}"
        );
    }
    assert!(
        fit_of(last, "xdot") > fit_of(first, "xdot") - 1.0,
        "test velocity fit fell: {first} -> {last}"
    );
    let html = std::fs::read_to_string(dir.path().join("rep").join("index.html")).unwrap();
    assert!(html.contains("<svg") && html.contains("position_load"));
}
