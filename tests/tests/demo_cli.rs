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

/// Each round's selection line prints the statistic its keep test compares (the
/// multiple-shooting residual sum of squares on the selection log), and a refit that was kept
/// lowered it.
fn check_selection_lines(text: &str) {
    let lines: Vec<&str> = text
        .lines()
        .map(str::trim_start)
        .filter(|l| l.starts_with("selection (signal b)"))
        .collect();
    assert!(!lines.is_empty(), "no selection line: {text}");
    for l in &lines {
        assert!(
            l.contains("multiple-shooting RSS") && !l.contains("x fit"),
            "{l}"
        );
        if l.contains("kept: explains it better") {
            let change: f64 = l
                .split("for the kept model (")
                .nth(1)
                .and_then(|r| r.split(" %)").next())
                .and_then(|v| v.parse().ok())
                .unwrap_or_else(|| panic!("no change against the kept model: {l}"));
            assert!(change < 0.0, "kept, yet its RSS rose: {l}");
        }
    }
}

/// The demo's standard output, after asserting that it succeeded.
fn succeeded(out: &std::process::Output) -> String {
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "demo failed: {text}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    text
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
    let text = succeeded(&out);
    assert!(text.contains("position_load: FOUND"), "{text}");
    check_selection_lines(&text);
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
    // A point: the hidden effect is worth tens of points on the angle and current (the
    // README's example: −3 → 100 % and 75 → 99 %), and models that track the angle equally
    // well scatter by up to a point against the quantised velocity.
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
    // The report's scores are named for the log they were taken on.
    assert!(html.contains("Test fit after each step") && !html.contains("Validation fit"));
}

/// Physics outside the effect list (a fan's drag, quadratic in the speed): the loop says the
/// LuGre model is not adequate and which variable carries the rest, adds a table over it,
/// the test fits rise and the final model's load torque is nearer the true one.
#[test]
fn demo_hides_unnamed_physics_and_a_table_takes_it_in() {
    let text = unnamed_demo("fan", "30");
    // Step 0's diagnosis: not adequate, carried by the speed, and the table it offers.
    let verdict = text
        .lines()
        .find(|l| {
            l.trim_start()
                .starts_with("diagnose (fitting signals a, d)")
        })
        .unwrap_or_else(|| panic!("no diagnosis line: {text}"));
    assert!(
        verdict.contains("NOT adequate, carried by omega")
            && verdict.contains("add table:var=omega"),
        "{verdict}"
    );
    let steps = kept_steps(&text);
    assert!(
        steps.len() >= 2 && steps[1].contains("table(omega)"),
        "{text}"
    );
    the_table_took_it_in(&text, "omega");
}

/// `motorid demo --unnamed KIND --duration SECONDS`'s text.
fn unnamed_demo(kind: &str, seconds: &str) -> String {
    let dir = tempfile::tempdir().unwrap();
    let out = motorid(
        dir.path(),
        &[
            "demo",
            "--unnamed",
            kind,
            "--duration",
            seconds,
            "--quiet",
            "--report",
            "rep",
        ],
    );
    succeeded(&out)
}

/// The demo's kept steps.
fn kept_steps(text: &str) -> Vec<&str> {
    text.lines()
        .filter(|l| l.starts_with("step ") && !l.contains("(not kept)"))
        .collect()
}

/// What an unnamed demo must end with once a table over `var` took the physics in: the
/// carrier FOUND, a kept step with the table, the test fits of angle and current up, the
/// load torque nearer the truth, and no later diagnosis still carried by `var`.
fn the_table_took_it_in(text: &str, var: &str) {
    assert!(text.contains(&format!("carried by {var}: FOUND")), "{text}");
    check_selection_lines(text);
    let steps = kept_steps(text);
    let table = format!("table({var})");
    assert!(
        steps.iter().any(|l| l.contains(&table)),
        "the table over {var} was not kept: {text}"
    );
    let (first, last) = (steps[0], steps[steps.len() - 1]);
    for key in ["x", "i"] {
        assert!(
            fit_of(last, key) > fit_of(first, key),
            "test {key} fit did not improve: {first} -> {last}"
        );
    }
    let (final_rms, start_rms) = torque_distance(text);
    assert!(
        final_rms < start_rms,
        "the final model's load torque is no nearer the truth: {final_rms} against {start_rms}"
    );
    // Once the table is in the model, what it explains is no longer left to its variable.
    let after: Vec<&str> = text
        .lines()
        .skip_while(|l| !(l.starts_with("step ") && l.contains(&table)))
        .filter(|l| l.contains("diagnose ("))
        .collect();
    let carried = format!("carried by {var}");
    assert!(
        !after.is_empty() && after.iter().all(|l| !l.contains(&carried)),
        "the model with the table over {var} is still found carried by it: {after:?}"
    );
}

/// The models' load torque against the true one on the demo's distance line: (final, start).
fn torque_distance(text: &str) -> (f64, f64) {
    let line = text
        .lines()
        .find(|l| l.starts_with("final model against the truth: load torque"))
        .unwrap_or_else(|| panic!("no torque distance: {text}"));
    let after = |key: &str| -> f64 {
        line.split(key)
            .nth(1)
            .and_then(|r| r.split_whitespace().next())
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| panic!("no number after {key:?}: {line}"))
    };
    (after("RMS error "), after("start model: "))
}

/// Physics outside the effect list carried by the angle (a cam lifting a spring-loaded
/// follower once a revolution, no sinusoid): the one-harmonic angle terms may take part of
/// it, then the loop says the model is not adequate with the rest carried by theta, adds a
/// table over the angle and keeps it; the test fits rise and the final model's load torque
/// is nearer the true one than the start model's.
#[test]
fn demo_hides_a_cam_and_a_table_over_the_angle_takes_it_in() {
    let text = unnamed_demo("cam", "60");
    let verdict = text
        .lines()
        .find(|l| l.contains("NOT adequate, carried by"))
        .unwrap_or_else(|| panic!("no not-adequate verdict with a carrier: {text}"));
    assert!(
        verdict.contains("NOT adequate, carried by theta")
            && verdict.contains("add table:var=theta"),
        "{verdict}"
    );
    the_table_took_it_in(&text, "theta");
}
