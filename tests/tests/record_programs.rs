//! `motorid record --signal steady|ramp` on the emulated board (`motorid board --pty`): the
//! programs `fit --model lugre` asks for, played as board runs with voltages relative to the
//! board's u_max, in one log with a continuous clock; amplitudes above the ratings refused;
//! a run the board ends early is an error that writes no log.
use e2e::{motorid, motorid_bin, PAPER_LUGRE_MODEL};
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};

/// The emulated board, killed when dropped.
struct Board {
    child: Child,
    port: String,
}

impl Board {
    /// The emulated board at 10× real time: its 2 s link timeout is then 0.2 s of real time,
    /// longer than a busy two-core machine pauses the recording process.
    fn start(dir: &Path) -> Board {
        Board::start_at(dir, "10")
    }

    /// The emulated board at time factor `speed`.
    fn start_at(dir: &Path, speed: &str) -> Board {
        let mut child = Command::new(motorid_bin())
            .args(["board", "--pty", "--speed", speed])
            .current_dir(dir)
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("cannot start motorid board");
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        let port = line.trim().to_string();
        assert!(port.starts_with("/dev/"), "board printed '{line}'");
        Board { child, port }
    }
}

impl Drop for Board {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn ok(out: &std::process::Output) {
    assert!(
        out.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Rows (t, u, i, theta, omega) of a recorded log.
fn rows(path: &Path) -> Vec<Vec<f64>> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#'))
        .skip(1)
        .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
        .collect()
}

#[test]
fn steady_and_ramp_programs_play_on_the_board() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("m.toml"), PAPER_LUGRE_MODEL).unwrap();
    ok(&motorid(d, &["export", "m.toml", "-o", "c.bin"]));
    let board = Board::start(d);
    ok(&motorid(d, &["upload", "c.bin", "--port", &board.port]));

    // Steady at 10 % of u_max = 12 V: 22 levels from ±0.8 to ±1.2 V, 3 s each.
    let rec = |extra: &[&str]| {
        let mut a = vec!["record", "--port", &board.port];
        a.extend(extra);
        motorid(d, &a)
    };
    ok(&rec(&[
        "--signal",
        "steady",
        "--amplitude",
        "0.1",
        "-o",
        "steady.csv",
    ]));
    let r = rows(&d.join("steady.csv"));
    // Every sample is in the log or counted as lost on the link (a busy machine can drop
    // some of the emulated board's frames).
    let text = std::fs::read_to_string(d.join("steady.csv")).unwrap();
    let lost: usize = text
        .lines()
        .find_map(|l| l.strip_prefix("# lost_samples="))
        .unwrap()
        .parse()
        .unwrap();
    assert_eq!(r.len() + lost, 22 * 250, "samples ({lost} lost)");
    assert!(lost < 250, "{lost} samples lost");
    // One clock across the runs: steps of 12 ms (several where a sample was lost), to 1 % of
    // a step: the board sends f32 seconds, whose ulp over this 66 s program is under 8 µs.
    for w in r.windows(2) {
        let steps = (w[1][0] - w[0][0]) / 0.012;
        assert!(
            steps > 0.5 && (steps - steps.round()).abs() < 0.01,
            "clock {w:?}"
        );
    }
    let mut levels: Vec<f64> = Vec::new();
    for x in &r {
        if levels.last() != Some(&x[1]) {
            levels.push(x[1]);
        }
    }
    assert_eq!(levels.len(), 22, "{levels:?}");
    // 1e-5 V: the board sends f32 volts (an ulp at 1.2 V is 1.2e-7 V).
    assert!((levels[0] - 0.8).abs() < 1e-5, "{levels:?}");
    assert!((levels[10] - 1.2).abs() < 1e-5, "{levels:?}");
    assert!((levels[21] + 1.2).abs() < 1e-5, "{levels:?}");
    // The motor turns both ways at the top levels.
    let last_at = |u: f64| r.iter().rev().find(|x| x[1] == u).unwrap()[4];
    assert!(last_at(levels[10]) > 0.0 && last_at(levels[21]) < 0.0);

    // Ramp: the applied voltage rises at the paper's slopes scaled by the amplitude.
    ok(&rec(&[
        "--signal",
        "ramp",
        "--amplitude",
        "0.05",
        "-o",
        "ramp.csv",
    ]));
    let r = rows(&d.join("ramp.csv"));
    let slope_max = r
        .windows(2)
        .map(|w| (w[1][1] - w[0][1]) / 0.012)
        .filter(|s| s.abs() < 1.0)
        .fold(0.0f64, |a, s| a.max(s));
    // 1 mV/s: tells the 12 mV/s ramp from the 9.5 mV/s one; f32 volts differenced over a
    // 12 ms step are good to about 1e-5 V/s.
    assert!(
        (slope_max - 12e-3).abs() < 1e-3,
        "steepest slope {slope_max} V/s"
    );
    let u_top = r.iter().map(|x| x[1]).fold(f64::MIN, f64::max);
    // 5 %: the top is the last sample before the ramp turns, within a step of it; a wrong
    // amplitude would miss by far more.
    assert!((u_top - 0.4).abs() < 0.02, "ramp top {u_top} V");

    // Refused: above the board's limit, above its rating, and for a-d (scaled by the board).
    for (args, want) in [
        (
            &["--signal", "steady", "--amplitude", "1.5"][..],
            "--amplitude",
        ),
        (&["--signal", "ramp", "--u-max", "60"][..], "--u-max"),
        (&["--signal", "a", "--amplitude", "0.2"][..], "--amplitude"),
    ] {
        let mut a = args.to_vec();
        a.extend(["-o", "bad.csv"]);
        let out = rec(&a);
        assert!(!out.status.success(), "{a:?} succeeded");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.starts_with("error: ") && err.contains(want), "{err}");
        assert!(!d.join("bad.csv").exists());
    }
}

/// A run the board stops before its end (here: link loss while `record` is paused, as on an
/// overloaded machine) is an error naming the samples received of those asked for and why,
/// and leaves no log that looks complete.
#[cfg(unix)]
#[test]
fn a_run_the_board_ends_early_is_an_error_and_writes_no_log() {
    use std::time::Duration;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("m.toml"), PAPER_LUGRE_MODEL).unwrap();
    ok(&motorid(d, &["export", "m.toml", "-o", "c.bin"]));
    // Five times real time: the 20 s run takes 4 s. While `record` is paused its output
    // piles up unread and the board runs at real time: a pause of 3 s outlasts the board's
    // 2 s link timeout, as on the real board.
    let board = Board::start_at(d, "5");
    ok(&motorid(d, &["upload", "c.bin", "--port", &board.port]));
    let rec = Command::new(motorid_bin())
        .args(["record", "--port", &board.port, "--signal", "a"])
        .args(["--duration", "20", "-o", "rec.csv"])
        .current_dir(d)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let pid = rec.id().to_string();
    let signal = |s: &str| {
        let st = Command::new("kill").args([s, &pid]).status().unwrap();
        assert!(st.success(), "kill {s}");
    };
    std::thread::sleep(Duration::from_millis(1000));
    signal("-STOP");
    std::thread::sleep(Duration::from_millis(3000));
    signal("-CONT");
    let out = rec.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "record succeeded: {err}");
    let lines: Vec<&str> = err.lines().collect();
    assert_eq!(lines.len(), 1, "{err}");
    assert!(
        lines[0].starts_with("error: ")
            && lines[0].contains("ended the run early")
            && lines[0].contains("of 1667 samples")
            && lines[0].contains("link loss"),
        "{err}"
    );
    let got: usize = lines[0]
        .split("early: ")
        .nth(1)
        .and_then(|r| r.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no sample count in: {err}"));
    assert!(got > 0 && got < 1667, "{got}");
    let left: Vec<String> = std::fs::read_dir(d)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("rec") || n.ends_with(".tmp"))
        .collect();
    assert!(left.is_empty(), "{left:?}");
}
