//! Hostile input: numbers that would size allocations and loops, NaN/inf/absurd
//! parameters, outputs that are inputs, malformed flags. Every case must fail within a time
//! cap with one `error:` line naming the file or flag, and leave the directory as it was.
use e2e::{motorid_bin, PAPER_LUGRE_MODEL};
use std::collections::BTreeMap;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Kill the child after this long: a hostile input must not make a command run away.
const TIME_CAP: Duration = Duration::from_secs(20);

struct Run {
    code: Option<i32>,
    stdout: String,
    stderr: String,
}

/// Run `motorid ARGS...` in `dir`; panics if it had to be killed after [`TIME_CAP`].
fn run(dir: &Path, args: &[&str]) -> Run {
    let mut child = Command::new(motorid_bin())
        .args(args)
        .current_dir(dir)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("cannot start motorid");
    let mut out = child.stdout.take().unwrap();
    let mut err = child.stderr.take().unwrap();
    let t_out = std::thread::spawn(move || {
        let mut s = Vec::new();
        let _ = out.read_to_end(&mut s);
        s
    });
    let t_err = std::thread::spawn(move || {
        let mut s = Vec::new();
        let _ = err.read_to_end(&mut s);
        s
    });
    let start = Instant::now();
    let status = loop {
        if let Some(st) = child.try_wait().unwrap() {
            break st;
        }
        if start.elapsed() > TIME_CAP {
            let _ = child.kill();
            let _ = child.wait();
            panic!("motorid {args:?} ran longer than {TIME_CAP:?} and was killed");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    Run {
        code: status.code(),
        stdout: String::from_utf8_lossy(&t_out.join().unwrap()).into_owned(),
        stderr: String::from_utf8_lossy(&t_err.join().unwrap()).into_owned(),
    }
}

/// Every file and link under `dir`: relative path → (contents or link target, mode bits).
fn snapshot(dir: &Path) -> BTreeMap<PathBuf, (Vec<u8>, u32)> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let e = e.unwrap();
            let p = e.path();
            let meta = std::fs::symlink_metadata(&p).unwrap();
            let rel = p.strip_prefix(dir).unwrap().to_path_buf();
            #[cfg(unix)]
            let mode = {
                use std::os::unix::fs::PermissionsExt;
                meta.permissions().mode()
            };
            #[cfg(not(unix))]
            let mode = 0;
            if meta.file_type().is_symlink() {
                let t = std::fs::read_link(&p).unwrap();
                out.insert(rel, (t.to_string_lossy().as_bytes().to_vec(), mode));
            } else if meta.is_dir() {
                out.insert(rel, (b"<dir>".to_vec(), mode));
                stack.push(p);
            } else {
                out.insert(rel, (std::fs::read(&p).unwrap(), mode));
            }
        }
    }
    out
}

/// `motorid ARGS` in `dir` must fail within the cap, with exactly one stderr line that starts
/// with `error:` and contains every `want`, no panic, and `dir` unchanged.
fn refused(dir: &Path, args: &[&str], want: &[&str]) {
    let before = snapshot(dir);
    let r = run(dir, args);
    let after = snapshot(dir);
    assert_ne!(r.code, Some(0), "motorid {args:?} succeeded: {}", r.stdout);
    assert!(r.code.is_some(), "motorid {args:?} died of a signal");
    let lines: Vec<&str> = r.stderr.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(
        lines.len(),
        1,
        "motorid {args:?}: one stderr line expected, got:\n{}",
        r.stderr
    );
    assert!(lines[0].starts_with("error: "), "{args:?}: {}", r.stderr);
    assert!(
        !lines[0].contains('\u{1b}'),
        "escape sequence echoed: {:?}",
        lines[0]
    );
    assert!(!r.stderr.contains("panicked") && !r.stderr.contains("internal error"));
    for w in want {
        assert!(
            lines[0].contains(w),
            "{args:?}: '{w}' missing in: {}",
            lines[0]
        );
    }
    let changed: Vec<&PathBuf> = before
        .keys()
        .chain(after.keys())
        .filter(|k| before.get(*k) != after.get(*k))
        .collect();
    assert!(
        changed.is_empty(),
        "motorid {args:?} changed or left files: {changed:?}"
    );
}

/// A plausible 12 ms log with `n` rows.
fn log_text(n: usize, dt: f64, meta: &str) -> String {
    let mut s = String::from(meta);
    s.push_str("t,u,i,theta\n");
    for k in 0..n {
        s.push_str(&format!(
            "{:e},{},{},{}\n",
            k as f64 * dt,
            3.0 * (k as f64 * 0.05).sin(),
            0.1 * (k % 7) as f64,
            0.01 * k as f64
        ));
    }
    s
}

fn setup() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(
        d.join("data.csv"),
        log_text(300, 0.012, "# sample_period=0.012\n"),
    )
    .unwrap();
    std::fs::write(d.join("m.toml"), PAPER_LUGRE_MODEL).unwrap();
    dir
}

#[test]
fn sample_periods_and_steps_outside_the_physical_range_are_refused() {
    let dir = setup();
    let d = dir.path();
    for (name, meta) in [
        ("tiny.csv", "# sample_period=1e-300\n"),
        ("nano.csv", "# a=b\n# sample_period=1e-9\n"),
        ("nan.csv", "# sample_period=NaN\n"),
        ("huge.csv", "# sample_period=1e307\n"),
    ] {
        std::fs::write(d.join(name), log_text(300, 0.012, meta)).unwrap();
    }
    refused(
        d,
        &["fit", "--model", "linear", "-o", "out.toml", "tiny.csv"],
        &["tiny.csv:1", "sample_period", "1 µs .. 10 s"],
    );
    refused(
        d,
        &["fit", "--model", "lugre", "-o", "out.toml", "nano.csv"],
        &["nano.csv:2", "sample_period"],
    );
    refused(
        d,
        &["fit", "--model", "sindyc", "-o", "out.toml", "nan.csv"],
        &["nan.csv:1", "sample_period"],
    );
    refused(
        d,
        &["diagnose", "m.toml", "huge.csv"],
        &["huge.csv:1", "sample_period"],
    );
    // No metadata: the time column itself.
    std::fs::write(d.join("t_nano.csv"), log_text(300, 1e-9, "")).unwrap();
    std::fs::write(d.join("t_far.csv"), log_text(100, 1e306, "")).unwrap();
    std::fs::write(d.join("t_slow.csv"), log_text(100, 100.0, "")).unwrap();
    refused(
        d,
        &["compare", "m.toml", "t_slow.csv"],
        &["t_slow.csv", "column 't'", "median time step"],
    );
    std::fs::write(d.join("t_min.csv"), log_text(300, 1e-300, "")).unwrap();
    refused(
        d,
        &["fit", "--model", "linear", "-o", "out.toml", "t_nano.csv"],
        &["t_nano.csv", "column 't'"],
    );
    refused(
        d,
        &["compare", "m.toml", "t_far.csv"],
        &["t_far.csv", "column 't'"],
    );
    refused(
        d,
        &["diagnose", "m.toml", "t_min.csv"],
        &["t_min.csv", "column 't'"],
    );
    refused(
        d,
        &["compare", "m.toml", "data.csv", "--units", "t=us"],
        &["data.csv:1", "sample_period"],
    );
    // One step of 1e307 s in a log of 12 ms steps: the free run must not loop on it.
    let mut text = log_text(300, 0.012, "");
    text.push_str("1e307,1,0.1,3\n");
    std::fs::write(d.join("jump.csv"), text).unwrap();
    // A single 1e307 s jump: the reader refuses it (the line), nothing loops on it.
    refused(
        d,
        &["compare", "m.toml", "jump.csv"],
        &["jump.csv:302", "column 't'", "jumps"],
    );
    refused(
        d,
        &["fit", "--model", "sindyc", "-o", "s.toml", "jump.csv"],
        &["jump.csv:302", "column 't'"],
    );
}

#[test]
fn simulation_sizes_from_flags_and_effects_are_bounded() {
    let dir = setup();
    let d = dir.path();
    let sim = |extra: &[&str], want: &[&str]| {
        let mut a = vec!["simulate", "--signal", "a", "-o", "out.csv"];
        a.extend_from_slice(extra);
        refused(d, &a, want);
    };
    sim(&["--effect", "offset:t0=1e10"], &["--effect", "t0"]);
    sim(&["--effect", "offset:t0=nan"], &["--effect", "t0", "NaN"]);
    sim(&["--effect", "thermal:tau=-inf"], &["--effect", "tau"]);
    sim(
        &["--effect", "cogging:harmonic=1e300"],
        &["--effect", "harmonic"],
    );
    sim(&["--fine-step", "1e-300"], &["--fine-step"]);
    sim(&["--duration", "1e12"], &["--duration"]);
    sim(&["--duration", "-5"], &["--duration"]);
    sim(&["--noise", "1e308"], &["--noise"]);
    sim(&["--noise", "inf"], &["--noise"]);
    refused(d, &["board", "--pty", "--speed", "1e-300"], &["--speed"]);
    refused(d, &["board", "--pty", "--speed", "nan"], &["--speed"]);
    // In range but far beyond this motor: diverges, and says so quickly.
    let r = run(
        d,
        &[
            "simulate",
            "--signal",
            "a",
            "--duration",
            "5",
            "--effect",
            "offset:t0=5000",
            "-o",
            "big.csv",
        ],
    );
    if r.code != Some(0) {
        let lines: Vec<&str> = r.stderr.lines().collect();
        assert_eq!(lines.len(), 1, "{}", r.stderr);
        assert!(lines[0].starts_with("error: --effect"), "{}", r.stderr);
        assert!(!d.join("big.csv").exists());
    }
}

#[test]
fn model_parameters_must_be_finite_and_physical() {
    let dir = setup();
    let d = dir.path();
    let bad = |name: &str, text: String| {
        std::fs::write(d.join(name), text).unwrap();
    };
    bad(
        "alpha.toml",
        PAPER_LUGRE_MODEL.replace("alpha0 = 0.08", "alpha0 = nan"),
    );
    bad(
        "kt.toml",
        PAPER_LUGRE_MODEL.replace("kt = 0.07126", "kt = inf"),
    );
    bad(
        "sp.toml",
        PAPER_LUGRE_MODEL.replace("sample_period = 0.012", "sample_period = 1e-300"),
    );
    bad(
        "sigma.toml",
        PAPER_LUGRE_MODEL.replace("sigma1 = 22.2464", "sigma1 = -1e300"),
    );
    bad(
        "effect.toml",
        format!("{PAPER_LUGRE_MODEL}\n[[effects]]\nname = \"offset\"\nt0 = 1e30\n"),
    );
    bad(
        "window.toml",
        format!("{PAPER_LUGRE_MODEL}\n[sensor]\nhall_resolution_rad = 0.095\nvelocity_window = 1000000000000\n"),
    );
    refused(
        d,
        &["compare", "alpha.toml", "data.csv"],
        &["alpha.toml", "lugre.alpha0", "NaN"],
    );
    refused(
        d,
        &["export", "kt.toml", "-o", "c.bin"],
        &["kt.toml", "motor.kt", "not a finite number"],
    );
    refused(
        d,
        &["diagnose", "sp.toml", "data.csv"],
        &["sp.toml", "sample_period"],
    );
    refused(
        d,
        &["compare", "sigma.toml", "data.csv"],
        &["sigma.toml", "lugre.sigma1"],
    );
    refused(
        d,
        &[
            "emulate",
            "--model",
            "effect.toml",
            "--compensation",
            "lugre",
        ],
        &["effect.toml", "t0"],
    );
    refused(
        d,
        &["compare", "window.toml", "data.csv"],
        &["window.toml", "velocity_window"],
    );
}

#[test]
fn numeric_flags_are_validated_by_their_parser() {
    let dir = setup();
    let d = dir.path();
    refused(d, &["emulate", "--kp", "nan"], &["--kp", "NaN"]);
    refused(d, &["emulate", "--ki", "1e40"], &["--ki"]);
    refused(d, &["emulate", "--edge-timing", "-1"], &["--edge-timing"]);
    refused(
        d,
        &["export", "m.toml", "-o", "c.bin", "--kp=-1"],
        &["--kp"],
    );
    refused(
        d,
        &["export", "m.toml", "-o", "c.bin", "--ki=-1e30"],
        &["--ki"],
    );
    refused(
        d,
        &["export", "m.toml", "-o", "c.bin", "--u-max", "0"],
        &["--u-max"],
    );
    refused(
        d,
        &["export", "m.toml", "-o", "c.bin", "--comp-gain", "inf"],
        &["--comp-gain"],
    );
    refused(
        d,
        &["export", "m.toml", "-o", "c.bin", "--edge-timing", "1e-30"],
        &["--edge-timing"],
    );
}

#[test]
fn an_output_is_never_an_input() {
    let dir = setup();
    let d = dir.path();
    refused(
        d,
        &["fit", "--model", "linear", "-o", "data.csv", "data.csv"],
        &["data.csv", "also an input"],
    );
    refused(
        d,
        &[
            "fit",
            "--model",
            "linear",
            "-o",
            "./x/../data.csv",
            "data.csv",
        ],
        &["data.csv", "also an input"],
    );
    refused(
        d,
        &["export", "m.toml", "-o", "m.toml"],
        &["m.toml", "also an input"],
    );
    #[cfg(unix)]
    {
        std::os::unix::fs::symlink("m.toml", d.join("link.toml")).unwrap();
        refused(
            d,
            &["export", "m.toml", "-o", "link.toml"],
            &["link.toml", "also an input"],
        );
    }
    refused(
        d,
        &[
            "emulate", "--model", "m.toml", "--svg", "o.svg", "--csv", "o.svg",
        ],
        &["o.svg", "same file"],
    );
    refused(
        d,
        &["emulate", "--model", "m.toml", "--csv", "m.toml"],
        &["m.toml", "also an input"],
    );
}

#[test]
fn outputs_keep_permissions_follow_links_and_announce_new_folders() {
    let dir = setup();
    let d = dir.path();
    let r = run(d, &["export", "m.toml", "-o", "new/c.bin"]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    assert!(
        r.stderr.contains("note: created directory new"),
        "{}",
        r.stderr
    );
    assert!(d.join("new/c.bin").is_file());
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::write(d.join("c.bin"), b"old").unwrap();
        std::fs::set_permissions(d.join("c.bin"), std::fs::Permissions::from_mode(0o640)).unwrap();
        std::os::unix::fs::symlink("c.bin", d.join("l.bin")).unwrap();
        let r = run(d, &["export", "m.toml", "-o", "l.bin"]);
        assert_eq!(r.code, Some(0), "{}", r.stderr);
        let meta = std::fs::symlink_metadata(d.join("l.bin")).unwrap();
        assert!(meta.file_type().is_symlink(), "the link stays a link");
        let target = std::fs::read(d.join("c.bin")).unwrap();
        assert_ne!(target, b"old", "written through to the link's target");
        let mode = std::fs::metadata(d.join("c.bin"))
            .unwrap()
            .permissions()
            .mode();
        assert_eq!(mode & 0o777, 0o640);
        std::os::unix::fs::symlink("missing.bin", d.join("dangling.bin")).unwrap();
        refused(
            d,
            &["export", "m.toml", "-o", "dangling.bin"],
            &["dangling.bin"],
        );
    }
    let leftovers: Vec<_> = snapshot(d)
        .into_keys()
        .filter(|p| p.to_string_lossy().ends_with(".tmp"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

#[test]
fn command_line_errors_are_one_line_and_help_is_not_an_error() {
    let dir = setup();
    let d = dir.path();
    refused(
        d,
        &["simulate", "--signal", "z", "-o", "x.csv"],
        &["--signal", "'z'"],
    );
    refused(d, &["simulate", "-o", "x.csv"], &["--signal"]);
    refused(d, &["fit", "--model", "linear", "data.csv"], &["--output"]);
    refused(d, &["frobnicate"], &["frobnicate"]);
    refused(
        d,
        &["compare", "m.toml", "data.csv", "--bogus"],
        &["--bogus"],
    );
    refused(
        d,
        &[
            "simulate",
            "--signal",
            "a",
            "--effect",
            "\u{1b}[31mevil\u{7}",
            "-o",
            "x.csv",
        ],
        &["--effect", "evil"],
    );
    let long = "x".repeat(5000);
    refused(
        d,
        &[
            "simulate",
            "--signal",
            "a",
            "--effect",
            &format!("offset:t0={long}"),
            "-o",
            "x.csv",
        ],
        &["--effect", "t0"],
    );
    for args in [
        &["--help"][..],
        &["--version"],
        &["simulate", "--help"],
        &["fit", "-h"],
    ] {
        let r = run(d, args);
        assert_eq!(r.code, Some(0), "{args:?}: {}", r.stderr);
        assert!(r.stdout.lines().count() >= 1, "{args:?}");
        assert!(!r.stdout.starts_with("error"), "{args:?}");
    }
    let r = run(d, &["simulate", "--help"]);
    assert!(r.stdout.contains("Usage:") && r.stdout.lines().count() > 10);
}

#[test]
fn endless_or_duplicated_inputs_are_refused_before_reading() {
    let dir = setup();
    let d = dir.path();
    for args in [
        &["inspect", "/dev/zero"][..],
        &["compare", "m.toml", "/dev/zero"][..],
        &["compare", "/dev/zero", "data.csv"][..],
    ] {
        refused(d, args, &["/dev/zero", "not a regular file"]);
    }
    let text = log_text(300, 0.012, "# sample_period=0.012\n").replacen(
        "t,u,i,theta\n",
        "t,u,i,theta,theta\n",
        1,
    );
    let text: String = text
        .lines()
        .enumerate()
        .map(|(k, l)| match k {
            0 | 1 => format!("{l}\n"),
            _ => format!("{l},0\n"),
        })
        .collect();
    std::fs::write(d.join("dup.csv"), text).unwrap();
    refused(
        d,
        &["compare", "m.toml", "dup.csv"],
        &["dup.csv", "'theta' appears twice"],
    );
}

#[test]
fn metadata_is_validated_like_data() {
    let dir = setup();
    let d = dir.path();
    let with = |name: &str, meta: &str| {
        std::fs::write(
            d.join(name),
            log_text(300, 0.012, &format!("# sample_period=0.012\n{meta}")),
        )
        .unwrap();
    };
    with("pp_huge.csv", "# pole_pairs=18446744073709551615\n");
    with("pp_abc.csv", "# note=free text\n# pole_pairs=abc\n");
    with("hall_inf.csv", "# hall_resolution_rad=-inf\n");
    with("sp_twice.csv", "# sample_period=0.024\n");
    with("unit_twice.csv", "# unit.t=s\n# unit.t=ms\n");
    let fit = |file: &str, want: &[&str]| {
        refused(
            d,
            &["fit", "--model", "linear", "-o", "out.toml", file],
            want,
        );
    };
    fit("pp_huge.csv", &["pp_huge.csv:2", "pole_pairs", "1 .. 255"]);
    fit("pp_abc.csv", &["pp_abc.csv:3", "pole_pairs", "'abc'"]);
    fit(
        "hall_inf.csv",
        &["hall_inf.csv:2", "hall_resolution_rad", "-inf"],
    );
    fit(
        "sp_twice.csv",
        &["sp_twice.csv:2", "sample_period", "twice"],
    );
    refused(
        d,
        &["compare", "m.toml", "unit_twice.csv"],
        &["unit_twice.csv:3", "unit.t", "twice"],
    );
    // A gap of 900,000 s between two sample rows (two recordings pasted together): every
    // command refuses the log at the row after the gap.
    let gap: String = log_text(300, 0.012, "")
        .lines()
        .enumerate()
        .map(|(k, line)| match line.split_once(',') {
            Some((t, rest)) if k > 150 => {
                format!("{:e},{rest}\n", t.parse::<f64>().unwrap() + 9e5)
            }
            _ => format!("{line}\n"),
        })
        .collect();
    std::fs::write(d.join("gap.csv"), gap).unwrap();
    for cmd in [
        &["fit", "--model", "linear", "-o", "out.toml", "gap.csv"][..],
        &["compare", "m.toml", "gap.csv"],
        &["diagnose", "m.toml", "gap.csv"],
    ] {
        refused(d, cmd, &["gap.csv:152", "gap", "split"]);
    }
    // Keys the tools do not read are ignored, even twice.
    with("unknown.csv", "# operator=me\n# operator=you\n");
    let r = run(d, &["compare", "m.toml", "unknown.csv"]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
}

#[test]
fn a_log_given_twice_is_refused() {
    let dir = setup();
    let d = dir.path();
    let fit = |files: &[&str], want: &[&str]| {
        let mut a = vec!["fit", "--model", "linear", "-o", "out.toml"];
        a.extend_from_slice(files);
        refused(d, &a, want);
    };
    fit(&["data.csv", "data.csv"], &["data.csv", "given twice"]);
    fit(
        &["data.csv", "./x/../data.csv"],
        &["data.csv", "given twice"],
    );
    #[cfg(unix)]
    {
        std::os::unix::fs::symlink("data.csv", d.join("link.csv")).unwrap();
        std::fs::hard_link(d.join("data.csv"), d.join("hard.csv")).unwrap();
        fit(&["data.csv", "link.csv"], &["link.csv", "given twice"]);
        fit(&["hard.csv", "data.csv"], &["data.csv", "given twice"]);
    }
    refused(
        d,
        &[
            "fit",
            "--model",
            "linear",
            "-o",
            "out.toml",
            "--validate",
            "data.csv",
            "--validate",
            "data.csv",
            "data.csv",
        ],
        &["data.csv", "--validate"],
    );
}

#[test]
fn every_command_applies_the_same_physical_model_ranges() {
    let dir = setup();
    let d = dir.path();
    let bad = |name: &str, from: &str, to: &str| {
        assert!(PAPER_LUGRE_MODEL.contains(from));
        std::fs::write(d.join(name), PAPER_LUGRE_MODEL.replace(from, to)).unwrap();
    };
    bad("j.toml", "j = 0.0003", "j = 1e-300");
    bad("r.toml", "r = 0.2162", "r = 1e12");
    bad("v0.toml", "v0 = 3.676", "v0 = 0");
    for (file, field) in [
        ("j.toml", "motor.j"),
        ("r.toml", "motor.r"),
        ("v0.toml", "lugre.v0"),
    ] {
        refused(d, &["compare", file, "data.csv"], &[file, field, "outside"]);
        refused(
            d,
            &["diagnose", file, "data.csv"],
            &[file, field, "outside"],
        );
        refused(
            d,
            &["export", file, "-o", "c.bin"],
            &[file, field, "outside"],
        );
        refused(
            d,
            &["emulate", "--model", file, "--compensation", "lugre"],
            &[file, field],
        );
    }
    std::fs::write(
        d.join("pp.toml"),
        format!(
            "{PAPER_LUGRE_MODEL}\n[sensor]\nhall_resolution_rad = 0.095\nvelocity_window = 10\n\
             pole_pairs = 4294967295\n"
        ),
    )
    .unwrap();
    refused(
        d,
        &["export", "pp.toml", "-o", "c.bin"],
        &["pp.toml", "sensor.pole_pairs"],
    );
    std::fs::write(
        d.join("win.toml"),
        format!(
            "{PAPER_LUGRE_MODEL}\n[sensor]\nhall_resolution_rad = 0.095\nvelocity_window = 100\n"
        ),
    )
    .unwrap();
    refused(
        d,
        &["export", "win.toml", "-o", "c.bin"],
        &["win.toml", "sensor.velocity_window"],
    );
    // In range for a model, beyond the board: its rated current cannot break the friction loose.
    bad("strong.toml", "alpha0 = 0.08", "alpha0 = 50");
    refused(
        d,
        &["export", "strong.toml", "-o", "c.bin"],
        &["strong.toml", "lugre.alpha0", "rated"],
    );
    bad("kb.toml", "kb = 0.07126", "kb = 0");
    refused(
        d,
        &["export", "kb.toml", "-o", "c.bin"],
        &["kb.toml", "motor.kb"],
    );
}

#[test]
fn messages_name_the_file_and_one_line_and_show_control_characters() {
    let dir = setup();
    let d = dir.path();
    // A row with a field too many: the line once.
    let text = log_text(300, 0.012, "# sample_period=0.012\n");
    let line = 5;
    let text: String = text
        .lines()
        .enumerate()
        .map(|(k, l)| match k + 1 == line {
            true => format!("{l},9\n"),
            false => format!("{l}\n"),
        })
        .collect();
    std::fs::write(d.join("fields.csv"), &text).unwrap();
    let r = run(d, &["compare", "m.toml", "fields.csv"]);
    assert!(
        r.stderr
            .starts_with(&format!("error: fields.csv:{line}: 5 fields")),
        "{}",
        r.stderr
    );
    assert!(!r.stderr.contains("line:"), "{}", r.stderr);
    refused(d, &["compare", "m.toml", "fields.csv"], &["header has 4"]);
    // A NUL byte in a field is shown, not swallowed.
    let text = log_text(300, 0.012, "").replacen("\n1.2e-2,", "\n1.2e-2\u{0}7,", 1);
    assert!(text.contains('\u{0}'));
    std::fs::write(d.join("nul.csv"), text).unwrap();
    refused(
        d,
        &["compare", "m.toml", "nul.csv"],
        &["nul.csv:3", "'1.2e-2\\07'"],
    );
    // A log that only warns, then one that fails: the error alone.
    std::fs::write(
        d.join("warns.csv"),
        log_text(300, 0.012, "# sample_period=0.0125\n"),
    )
    .unwrap();
    std::fs::write(d.join("bad.csv"), "t,u,i,theta\n0,1,2,3\n").unwrap();
    refused(
        d,
        &[
            "fit",
            "--model",
            "linear",
            "-o",
            "out.toml",
            "warns.csv",
            "bad.csv",
        ],
        &["bad.csv"],
    );
    // A fit the data cannot carry names the data: an input that never rests gives no
    // steady-state point for the static LuGre curve.
    let mut text = String::from("t,u,i,theta\n");
    for k in 0..400u64 {
        let u = ((k * 7919) % 13) as f64 - 6.0;
        text.push_str(&format!(
            "{},{u},{},{}\n",
            k as f64 * 0.012,
            0.1 * u,
            0.01 * k as f64
        ));
    }
    std::fs::write(d.join("restless.csv"), text).unwrap();
    refused(
        d,
        &["fit", "--model", "lugre", "-o", "out.toml", "restless.csv"],
        &["restless.csv", "not physical", "lugre.alpha0"],
    );
    let r = run(
        d,
        &[
            "simulate",
            "--signal",
            "a",
            "--duration",
            "20",
            "-o",
            "a.csv",
        ],
    );
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    refused(
        d,
        &["fit", "--model", "lugre", "-o", "out.toml", "a.csv"],
        &["a.csv: only", "steady-state points"],
    );
}

#[test]
fn oversized_models_and_endless_lines_cost_their_cap_not_their_size() {
    let dir = setup();
    let d = dir.path();
    let mut model = String::from(PAPER_LUGRE_MODEL);
    while model.len() <= 300 * 1024 {
        model.push_str("[[effects]]\n");
    }
    std::fs::write(d.join("many.toml"), model).unwrap();
    refused(
        d,
        &["compare", "many.toml", "data.csv"],
        &["many.toml", "too large"],
    );
    // One line of NUL bytes, 1 MiB: refused at the line cap.
    std::fs::write(d.join("nul.csv"), vec![0u8; 1 << 20]).unwrap();
    refused(
        d,
        &["compare", "m.toml", "nul.csv"],
        &["nul.csv:1", "line longer than 65536 bytes"],
    );
    let mut text = log_text(10, 0.012, "# sample_period=0.012\n");
    text.push_str(&"1".repeat(100_000));
    std::fs::write(d.join("long.csv"), text).unwrap();
    refused(
        d,
        &["fit", "--model", "linear", "-o", "o.toml", "long.csv"],
        &["long.csv:13", "line longer"],
    );
}

#[test]
fn missing_folders_are_created_below_the_working_directory_or_one_level_elsewhere() {
    let dir = setup();
    let d = dir.path();
    // Two missing levels, absolute or relative: refused, nothing created.
    let abs = d.join("nowhere").join("deeper").join("x.csv");
    let abs = abs.to_str().unwrap();
    refused(
        d,
        &["simulate", "--signal", "a", "--duration", "1", "-o", abs],
        &["nowhere", "does not exist"],
    );
    let sub = d.join("sub");
    std::fs::create_dir(&sub).unwrap();
    refused(
        &sub,
        &["export", "../m.toml", "-o", "../a/b/c.bin"],
        &["a", "does not exist"],
    );
    assert!(!d.join("a").exists());
    // Below the current directory, every missing level is created.
    let r = run(d, &["export", "m.toml", "-o", "out/cmp/c.bin"]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    assert!(d.join("out/cmp/c.bin").is_file());
    // A new folder at the root: refused (and removed should it appear).
    let root = format!("/motorid-hostile-{}", std::process::id());
    let r = run(d, &["export", "m.toml", "-o", &format!("{root}/c.bin")]);
    let made = Path::new(&root).exists();
    if made {
        let _ = std::fs::remove_dir_all(&root);
    }
    assert!(!made && r.code != Some(0), "{}", r.stderr);
    assert!(r.stderr.contains("does not exist"), "{}", r.stderr);
    // The output's own folder, in one that exists: created and announced.
    let own = d.join("runs").join("x.csv");
    let r = run(
        d,
        &[
            "simulate",
            "--signal",
            "a",
            "--duration",
            "1",
            "-o",
            own.to_str().unwrap(),
        ],
    );
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    assert!(r.stderr.contains("note: created directory"), "{}", r.stderr);
    assert!(own.is_file());
}

#[test]
fn typos_duplicates_and_endless_side_files_are_refused() {
    let dir = setup();
    let d = dir.path();
    // A key in the wrong table or misspelt is not silently ignored.
    std::fs::write(
        d.join("typo.toml"),
        format!("{PAPER_LUGRE_MODEL}kind = \"linear\"\n"),
    )
    .unwrap();
    refused(
        d,
        &["compare", "typo.toml", "data.csv"],
        &["typo.toml", "lugre.kind", "unknown field"],
    );
    std::fs::write(
        d.join("viscus.toml"),
        PAPER_LUGRE_MODEL.replacen(
            "sample_period = 0.012",
            "sample_period = 0.012\nviscus = 1",
            1,
        ),
    )
    .unwrap();
    refused(
        d,
        &["export", "viscus.toml", "-o", "c.bin"],
        &["viscus.toml", "viscus"],
    );
    std::fs::write(
        d.join("hall.toml"),
        format!(
            "{PAPER_LUGRE_MODEL}\n[sensor]\nhall_resolution_rad = 1e-300\nvelocity_window = 10\n"
        ),
    )
    .unwrap();
    refused(
        d,
        &["compare", "hall.toml", "data.csv"],
        &["hall.toml", "sensor.hall_resolution_rad", "finer"],
    );
    refused(
        d,
        &["compare", "m.toml", "data.csv", "--map", "t=u,t=theta"],
        &["--map", "twice"],
    );
    refused(
        d,
        &["compare", "m.toml", "data.csv", "--map", "u=x,i=x"],
        &["--map", "'x'", "both"],
    );
    refused(
        d,
        &["compare", "m.toml", "data.csv", "--units", "t=ms,t=s"],
        &["--units", "twice"],
    );
    // A control character in a path is shown escaped, never sent to the terminal.
    refused(
        d,
        &["compare", "m.toml", "gone\u{1b}[2J.csv"],
        &["gone\\x1b[2J.csv", "cannot read"],
    );
    // The emulated board's flash file must be a flash image, not an endless device.
    refused(
        d,
        &["board", "--pty", "--flash", "/dev/zero"],
        &["/dev/zero", "not a regular file"],
    );
    std::fs::write(d.join("flash.bin"), vec![0u8; 1 << 20]).unwrap();
    refused(
        d,
        &["board", "--pty", "--flash", "flash.bin"],
        &["flash.bin", "too large"],
    );
}

/// Every line `r` holds is at most `max` characters (two paths of 100 and the text) and free of control
/// characters.
fn lines_bounded(r: &Run, max: usize) {
    for line in r.stdout.lines().chain(r.stderr.lines()) {
        assert!(
            line.chars().count() <= max,
            "{} characters: {line}",
            line.chars().count()
        );
        assert!(!line.chars().any(char::is_control), "{line:?}");
    }
}

#[test]
fn echoed_values_are_cut_and_escaped_in_every_message() {
    let dir = setup();
    let d = dir.path();
    let long = format!("\u{1b}[31m{}", "k".repeat(3000));
    // A note: bounds far beyond the parameter are shown as numbers, not 300 digits.
    let r = run(
        d,
        &[
            "simulate",
            "--signal",
            "a",
            "--duration",
            "20",
            "-o",
            "a.csv",
        ],
    );
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    let r = run(
        d,
        &[
            "fit",
            "--model",
            "linear",
            "--bound",
            "R=1e-300..1e300",
            "-o",
            "o.toml",
            "a.csv",
        ],
    );
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    assert!(r.stdout.contains("--bound 1e-300..1e300"), "{}", r.stdout);
    lines_bounded(&r, 200);
    // Errors: a command-line value clap refuses, one the command refuses, a number.
    refused(
        d,
        &["simulate", "--signal", "a", "--seed", &long],
        &["--seed", "…"],
    );
    refused(
        d,
        &["board", "--pty", "--hall-order", &long],
        &["--hall-order", "…"],
    );
    refused(
        d,
        &[
            "record",
            "--port",
            "/dev/null",
            "--signal",
            "a",
            "--u-max",
            "1e300",
            "-o",
            "r.csv",
        ],
        &["--u-max", "1e300"],
    );
    // Names inside a MODEL.toml.
    std::fs::write(
        d.join("name.toml"),
        format!(
            "{PAPER_LUGRE_MODEL}\n[[effects]]\nname = \"{}\"\n",
            "k".repeat(3000)
        ),
    )
    .unwrap();
    refused(
        d,
        &["compare", "name.toml", "data.csv"],
        &["name.toml", "…"],
    );
    // A path: its start and its file name.
    let path = format!("{}/x.csv", "p".repeat(3000));
    refused(d, &["compare", "m.toml", &path], &["ppp…", "p/x.csv"]);
    for args in [
        &["simulate", "--signal", "a", "--seed", &long][..],
        &["board", "--pty", "--hall-order", &long],
        &["compare", "name.toml", "data.csv"],
        &["compare", "m.toml", &path],
        &["compare", "m.toml", "data.csv", "--report", &long],
    ] {
        lines_bounded(&run(d, args), 300);
    }
}

/// A SINDYc model of the paper's motor (voltage plant).
const SINDYC_MODEL: &str = include_str!("../../host-tools/tests/fixtures/paper_sindyc.toml");

#[test]
fn models_that_cannot_move_or_mix_kinds_are_refused() {
    let dir = setup();
    let d = dir.path();
    std::fs::write(d.join("s.toml"), SINDYC_MODEL).unwrap();
    let r = run(d, &["compare", "s.toml", "data.csv"]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    // No term of the current or the input: the modelled rotor never moves.
    let idle = SINDYC_MODEL
        .replace("i = 85.9\n", "")
        .replace("\"tanh(a*xdot)\" = -168.2\n", "");
    std::fs::write(d.join("idle.toml"), &idle).unwrap();
    for cmd in [
        &["compare", "idle.toml", "data.csv"][..],
        &["export", "idle.toml", "-o", "c.bin"],
    ] {
        refused(d, cmd, &["idle.toml", "sindy.accel", "cannot move"]);
    }
    // A table of another kind is not ignored.
    std::fs::write(
        d.join("mixed.toml"),
        format!("{SINDYC_MODEL}\n[lugre]\nalpha0 = 0.08\nalpha1 = 0.01\nalpha2 = 0.001\nv0 = 3\nsigma0 = 300\nsigma1 = 20\n"),
    )
    .unwrap();
    refused(
        d,
        &["compare", "mixed.toml", "data.csv"],
        &["mixed.toml", "field 'lugre'", "kind 'sindyc'"],
    );
}

#[test]
fn simulation_lengths_and_pole_pairs_are_bounded_for_every_command() {
    let dir = setup();
    let d = dir.path();
    // A demo of 1e9 s would allocate hundreds of GB.
    refused(
        d,
        &["demo", "--duration", "1e9", "-q"],
        &["--duration", "1e9"],
    );
    // Below two samples there is no log.
    refused(
        d,
        &[
            "simulate",
            "--signal",
            "a",
            "--duration",
            "0.001",
            "-o",
            "x.csv",
        ],
        &["--duration", "0.001"],
    );
    refused(
        d,
        &[
            "simulate",
            "--signal",
            "a",
            "--pole-pairs",
            "0",
            "-o",
            "x.csv",
        ],
        &["--pole-pairs"],
    );
}

#[test]
fn outputs_must_name_a_file_below_a_folder() {
    let dir = setup();
    let d = dir.path();
    refused(
        d,
        &["export", "m.toml", "-o", "newdir/"],
        &["newdir/", "directory name"],
    );
    assert!(!d.join("newdir").exists());
    refused(
        d,
        &["export", "m.toml", "-o", "data.csv/c.bin"],
        &["data.csv is a file, not a folder"],
    );
    // A report folder that is a file: named, and no temporary file's name in the message.
    refused(
        d,
        &["compare", "m.toml", "data.csv", "--report", "data.csv"],
        &["data.csv is a file, not a folder"],
    );
}

#[test]
fn lone_cr_line_ends_are_named_whatever_the_size() {
    let dir = setup();
    let d = dir.path();
    let text = log_text(300, 0.012, "# sample_period=0.012\n").replace('\n', "\r");
    std::fs::write(d.join("small.csv"), &text).unwrap();
    let big = log_text(5000, 0.012, "# sample_period=0.012\n").replace('\n', "\r");
    assert!(big.len() > 65536);
    std::fs::write(d.join("big.csv"), &big).unwrap();
    for file in ["small.csv", "big.csv"] {
        refused(
            d,
            &["compare", "m.toml", file],
            &[&format!("{file}:1"), "lone CR"],
        );
    }
}

/// Ctrl-C during a long fit: exit 130, no model, no temporary file.
#[cfg(unix)]
#[test]
fn an_interrupted_fit_leaves_nothing() {
    let dir = setup();
    let d = dir.path();
    let r = run(
        d,
        &[
            "simulate",
            "--signal",
            "a",
            "--duration",
            "300",
            "-o",
            "long.csv",
        ],
    );
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    let before = snapshot(d);
    let child = Command::new(motorid_bin())
        .args([
            "fit", "--model", "linear", "--add", "cogging", "--add", "offset",
        ])
        .args(["-o", "o.toml", "long.csv"])
        .current_dir(d)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(1500));
    let st = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(st.success());
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(130), "{err}");
    assert_eq!(err.trim(), "error: interrupted");
    assert_eq!(snapshot(d), before, "files changed or left behind");
}
