//! Logs in other units and delimiters, as a user brings them: the same data with `t` in ms,
//! `theta` in degrees and `;` between fields fits to the same model as the SI file, `fit
//! --json` prints one JSON object, and numbers that do not fit the units draw a `warning:`.
use e2e::motorid;
use serde_json::Value;
use std::path::Path;

/// A decimal number written by the emulator (no exponent) times 1000, exactly, as text:
/// `0.036` → `36`, `1.5` → `1500`, `-0.0125` → `-12.5`.
fn times_1000(s: &str) -> String {
    assert!(!s.contains(['e', 'E']), "no exponent expected: {s}");
    let (sign, digits) = match s.strip_prefix('-') {
        Some(d) => ("-", d),
        None => ("", s),
    };
    let (int, frac) = digits.split_once('.').unwrap_or((digits, ""));
    let frac = format!("{frac:0<3}");
    let int = format!("{int}{}", &frac[..3]);
    let int = int.trim_start_matches('0');
    let int = if int.is_empty() { "0" } else { int };
    let rest = frac[3..].trim_end_matches('0');
    if rest.is_empty() {
        format!("{sign}{int}")
    } else {
        format!("{sign}{int}.{rest}")
    }
}

/// The motor-log CSV `text` rewritten with t in ms, theta in degrees and `;` delimiters;
/// with `unit_lines`, the `# unit.t=ms` and `# unit.theta=deg` lines that declare it.
fn rewrite_ms_deg(text: &str, unit_lines: bool) -> String {
    let mut out = String::new();
    let mut header: Option<Vec<String>> = None;
    for line in text.lines() {
        if let Some(meta) = line.strip_prefix("# ") {
            let (k, v) = meta.split_once('=').unwrap();
            let v = if k == "sample_period" {
                times_1000(v)
            } else {
                v.to_string()
            };
            out.push_str(&format!("# {k}={v}\n"));
            continue;
        }
        match &header {
            None => {
                if unit_lines {
                    out.push_str("# unit.t=ms\n# unit.theta=deg\n");
                }
                let h: Vec<String> = line.split(',').map(str::to_string).collect();
                out.push_str(&h.join(";"));
                out.push('\n');
                header = Some(h);
            }
            Some(h) => {
                let fields: Vec<String> = line
                    .split(',')
                    .zip(h)
                    .map(|(f, name)| match name.as_str() {
                        "t" => times_1000(f),
                        "theta" => format!("{}", f.parse::<f64>().unwrap().to_degrees()),
                        _ => f.to_string(),
                    })
                    .collect();
                out.push_str(&fields.join(";"));
                out.push('\n');
            }
        }
    }
    out
}

/// `motorid fit --model linear --json` on `file`: its JSON object and its stderr.
fn fit_json(dir: &Path, file: &str) -> (Value, String) {
    let model = format!("{file}.toml");
    let out = motorid(
        dir,
        &["fit", "--model", "linear", "--json", "-o", &model, file],
    );
    let stderr = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(out.status.success(), "fit {file}: {stderr}");
    let stdout = String::from_utf8(out.stdout).unwrap();
    let v: Value = serde_json::from_str(&stdout)
        .unwrap_or_else(|e| panic!("fit --json stdout is not one JSON object ({e}): {stdout}"));
    assert!(v.is_object());
    assert!(dir.join(&model).is_file(), "--json still writes the model");
    (v, stderr)
}

#[test]
fn a_log_in_ms_and_degrees_fits_like_the_si_log() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = motorid(
        d,
        &[
            "simulate",
            "--signal",
            "a",
            "--duration",
            "20",
            "-o",
            "x.csv",
        ],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(d.join("x.csv")).unwrap();
    std::fs::write(d.join("ms_deg.csv"), rewrite_ms_deg(&text, true)).unwrap();
    std::fs::write(d.join("no_units.csv"), rewrite_ms_deg(&text, false)).unwrap();

    let (si, si_err) = fit_json(d, "x.csv");
    let (ms, ms_err) = fit_json(d, "ms_deg.csv");
    assert!(!si_err.contains("warning:"), "{si_err}");
    assert!(!ms_err.contains("warning:"), "{ms_err}");
    assert_eq!(si["model"], "linear");
    assert_eq!(si["plant"], "voltage");
    assert_eq!(ms["units"]["t"], "ms");
    assert_eq!(ms["units"]["theta"], "deg");
    let (ps, pm) = (
        si["parameters"].as_array().unwrap(),
        ms["parameters"].as_array().unwrap(),
    );
    assert!(ps.len() >= 5, "{si}");
    assert_eq!(ps.len(), pm.len());
    for (a, b) in ps.iter().zip(pm) {
        assert_eq!(a["name"], b["name"]);
        assert_eq!(a["unit"], b["unit"]);
        assert!(a["unit"].is_string() && a.get("std_error").is_some(), "{a}");
        let (x, y) = (a["value"].as_f64().unwrap(), b["value"].as_f64().unwrap());
        // Degrees round-trip to radians up to one rounding: 1e-6 of the value, or for a
        // number the data cannot pin down (it moves with any rounding of the data), 1e-6
        // of its standard error.
        let scale = if a["identifiable"] == true {
            x.abs()
        } else {
            x.abs().max(a["std_error"].as_f64().unwrap_or(0.0))
        };
        assert!(
            (x - y).abs() <= 1e-6 * scale,
            "{}: {x} (SI) vs {y} (ms, deg)",
            a["name"]
        );
    }
    for key in ["x", "xdot", "i"] {
        let (x, y) = (
            si["fit"][key].as_f64().unwrap(),
            ms["fit"][key].as_f64().unwrap(),
        );
        assert!((x - y).abs() <= 1e-6 * x.abs(), "fit {key}: {x} vs {y}");
    }

    // The same numbers without the unit lines: read as seconds, the sample period is 12 s,
    // outside the physical range; fit refuses with one line that names the
    // metadata line and suggests the unit.
    let out = motorid(
        d,
        &["fit", "--model", "linear", "-o", "n.toml", "no_units.csv"],
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    let lines: Vec<&str> = err.lines().collect();
    assert_eq!(lines.len(), 1, "{err}");
    assert!(lines[0].starts_with("error: no_units.csv:"), "{err}");
    assert!(
        lines[0].contains("sample_period") && lines[0].contains("unit.t=ms"),
        "{err}"
    );
    assert!(!d.join("n.toml").exists());
}

#[test]
fn a_decimal_comma_is_one_error_naming_line_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(
        d.join("comma.csv"),
        "# sample_period=0,012\nt;u;i;theta\n0;0;0;0\n0,012;1,5;0,1;0\n",
    )
    .unwrap();
    let out = motorid(
        d,
        &["fit", "--model", "linear", "-o", "m.toml", "comma.csv"],
    );
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(lines.len(), 1, "{err}");
    assert!(
        lines[0].starts_with("error: comma.csv:4: column 't'"),
        "{err}"
    );
    assert!(lines[0].contains("decimal comma"), "{err}");
    assert!(!d.join("m.toml").exists());
    // A unit of the wrong kind names the metadata line; in --units it names the flag.
    std::fs::write(
        d.join("rpm.csv"),
        "# unit.t=rpm\nt,u,i,theta\n0,0,0,0\n1,1,1,1\n",
    )
    .unwrap();
    let out = motorid(d, &["fit", "--model", "linear", "-o", "m.toml", "rpm.csv"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.starts_with("error: rpm.csv:1: unit.t=rpm"), "{err}");
    let out = motorid(
        d,
        &[
            "fit", "--model", "linear", "--units", "t=kg", "-o", "m.toml", "rpm.csv",
        ],
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.starts_with("error: --units: t=kg"), "{err}");
}
