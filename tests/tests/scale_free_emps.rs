//! Scale-free tools: the EMPS training log (../shared/data/EMPS, a ball-screw axis at 1 kHz,
//! position in metres, input in volts) goes through `fit`, `diagnose` and `fit --add` as it is,
//! with `--plant torque --map ...`, and `diagnose` names Coulomb friction. The same log
//! rescaled (position in millimetres, decimated to 100 Hz, resampled to 10 kHz, and as a
//! rotary axis in degrees) gives the same findings: the same effects in the same order, the
//! same Coulomb level (the input, in volts, is not rescaled) and a refit Coulomb friction
//! that agrees.
use e2e::{motorid, shared_data};
use serde_json::Value;
use std::path::Path;

/// The EMPS log's columns: time [s], input `vir` [V], motor position `qm` [m].
struct Emps {
    t: Vec<f64>,
    u: Vec<f64>,
    q: Vec<f64>,
}

fn read_emps(path: &Path) -> Emps {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (ct, cq, cu) = (col("t_s"), col("qm_m"), col("vir_V"));
    let mut e = Emps {
        t: Vec::new(),
        u: Vec::new(),
        q: Vec::new(),
    };
    for line in lines.filter(|l| !l.trim().is_empty()) {
        let f: Vec<f64> = line.split(',').map(|v| v.parse().unwrap()).collect();
        e.t.push(f[ct]);
        e.u.push(f[cu]);
        e.q.push(f[cq]);
    }
    e
}

/// Write `t,u,theta` rows (with optional `# ...` lines first).
fn write_log(path: &Path, meta: &str, rows: impl Iterator<Item = (f64, f64, f64)>) {
    let mut s = String::from(meta);
    s.push_str("t,u,theta\n");
    for (t, u, th) in rows {
        s.push_str(&format!("{t:.9},{u:.9},{th:.9e}\n"));
    }
    std::fs::write(path, s).unwrap();
}

/// What the loop found on one log.
#[derive(Debug)]
struct Findings {
    /// Effect names `diagnose` gave the linear model, most important first.
    names: Vec<String>,
    /// Coulomb level of the first finding [V of vir].
    fc_diagnosed: f64,
    /// Coulomb friction of the refit with it (`fit --add`) [V of vir].
    fc_refit: f64,
}

fn run(dir: &Path, args: &[&str]) -> String {
    let out = motorid(dir, args);
    assert!(
        out.status.success(),
        "motorid {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

/// `fit` linear, `diagnose`, `fit --add` the first finding, on `log` (with `extra` flags).
fn findings(dir: &Path, name: &str, log: &Path, extra: &[&str], refit: bool) -> Findings {
    let log = log.to_str().unwrap();
    let lin = format!("{name}.lin.toml");
    let mut fit = vec!["fit", "-q", "--model", "linear", "--plant", "torque"];
    fit.extend(extra);
    run(dir, &[&fit[..], &["-o", &lin, log]].concat());
    let mut diag = vec!["diagnose", &lin, log, "--json"];
    diag.extend(extra);
    let d: Value = serde_json::from_str(&run(dir, &diag)).unwrap();
    let effects = d["effects"].as_array().unwrap();
    let names: Vec<String> = effects
        .iter()
        .map(|e| e["name"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(
        names.first().map(String::as_str),
        Some("coulomb"),
        "{name}: {names:?}"
    );
    let spec = effects[0]["spec"].as_str().unwrap().to_string();
    let fc_diagnosed: f64 = spec.strip_prefix("coulomb:fc=").unwrap().parse().unwrap();
    let mut fc_refit = f64::NAN;
    if refit {
        let with = format!("{name}.coulomb.toml");
        let mut fit = vec![
            "fit", "-q", "--json", "--model", "linear", "--plant", "torque",
        ];
        fit.extend(extra);
        let j: Value = serde_json::from_str(&run(
            dir,
            &[&fit[..], &["--add", &spec, "-o", &with, log]].concat(),
        ))
        .unwrap();
        let p = j["parameters"]
            .as_array()
            .unwrap()
            .iter()
            .find(|p| p["name"] == "coulomb.fc")
            .unwrap_or_else(|| panic!("{name}: no coulomb.fc in {j}"));
        fc_refit = p["value"].as_f64().unwrap();
    }
    Findings {
        names,
        fc_diagnosed,
        fc_refit,
    }
}

#[test]
fn emps_findings_do_not_depend_on_units_or_sample_rate() {
    let Some(data) = shared_data("emps_findings_do_not_depend_on_units_or_sample_rate") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let raw = data.join("EMPS").join("DATA_EMPS.csv");
    let e = read_emps(&raw);
    let n = e.t.len();
    // Millimetres, the numbers only (nothing declares the unit).
    let mm = d.join("mm.csv");
    write_log(&mm, "", (0..n).map(|k| (e.t[k], e.u[k], 1e3 * e.q[k])));
    // Millimetres at 100 Hz: the input averaged over each block of 10 samples, the position
    // at the block's first sample (as the benchmark's own scripts decimate).
    let mm100 = d.join("mm100.csv");
    write_log(
        &mm100,
        "",
        (0..n / 10).map(|b| {
            let k = 10 * b;
            (
                e.t[k],
                e.u[k..k + 10].iter().sum::<f64>() / 10.0,
                1e3 * e.q[k],
            )
        }),
    );
    // 10 kHz: the position interpolated linearly, the input held.
    let fast = d.join("m10k.csv");
    write_log(
        &fast,
        "",
        (0..(n - 1) * 10).map(|j| {
            let (k, a) = (j / 10, (j % 10) as f64 / 10.0);
            let t = e.t[k] + a * (e.t[k + 1] - e.t[k]);
            (t, e.u[k], e.q[k] + a * (e.q[k + 1] - e.q[k]))
        }),
    );
    // A rotary axis in degrees: the screw's motor angle for a 5 mm lead, declared in degrees
    // (converted to radians on read).
    let deg = d.join("deg.csv");
    write_log(
        &deg,
        "# unit.theta=deg\n",
        (0..n).map(|k| (e.t[k], e.u[k], e.q[k] / 0.005 * 360.0)),
    );

    let map = ["--map", "t=t_s,u=vir_V,theta=qm_m"];
    let variants: Vec<(&str, &Path, &[&str], bool)> = vec![
        ("metres_1kHz", &raw, &map, true),
        ("mm_1kHz", &mm, &[], true),
        ("mm_100Hz", &mm100, &[], true),
        ("degrees_1kHz", &deg, &[], true),
        // The 10 kHz log has ten times the samples; its refit costs minutes, so only its
        // diagnosis is compared.
        ("metres_10kHz", &fast, &[], false),
    ];
    let found: Vec<(&str, Findings)> = std::thread::scope(|s| {
        let handles: Vec<_> = variants
            .iter()
            .map(|(name, log, extra, refit)| {
                s.spawn(move || (*name, findings(d, name, log, extra, *refit)))
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    let reference = &found[0].1;
    eprintln!("{found:#?}");
    assert_eq!(
        reference.names.get(..2),
        Some(&["coulomb".to_string(), "asymmetry".to_string()][..]),
        "metres at 1 kHz: {:?}",
        reference.names
    );
    for (name, f) in &found[1..] {
        assert_eq!(f.names, reference.names, "{name}: findings differ");
        // The diagnosed Coulomb level is in volts of the input, which no variant rescales:
        // 2 % (the 100 Hz log averages the input over blocks).
        let rel = |a: f64, b: f64| (a - b).abs() / b.abs();
        assert!(
            rel(f.fc_diagnosed, reference.fc_diagnosed) < 0.02,
            "{name}: fc {} V against {} V",
            f.fc_diagnosed,
            reference.fc_diagnosed
        );
        // The refit's Coulomb friction: 15 % (the 100 Hz log sees a tenth of the samples, and
        // the free run of a decimated log is a different discretisation).
        if f.fc_refit.is_finite() {
            assert!(
                rel(f.fc_refit, reference.fc_refit) < 0.15,
                "{name}: refit fc {} V against {} V",
                f.fc_refit,
                reference.fc_refit
            );
        }
    }
}
