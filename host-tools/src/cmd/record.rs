//! `motorid record`: run an excitation on the board and save the log.
use crate::board::link::Link;
use crate::emulator::SignalKind;
use crate::log::MotorLog;
use anyhow::{bail, Result};
use control::frame::{BoardMsg, Excitation, HostMsg, Mode, Sample};
use indicatif::{ProgressBar, ProgressStyle};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Duration;

/// Run one of the paper's excitations open loop (or closed-loop speed control) on the board
/// and save what it measured as a motor log (CSV: t, u, i, theta, omega).
///
/// The board plays the voltage signal for the given duration and streams a sample every
/// 12 ms; the log holds the voltage actually applied, the measured current, the
/// Hall-quantised angle and the firmware's velocity estimate.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Serial device of the board (e.g. /dev/ttyACM0, or what `motorid board --pty` printed).
    #[arg(long, value_name = "P")]
    pub port: String,
    /// Excitation, open loop: a (fitting, up to 12 V), b (up to 6 V), c (low speed, up to
    /// 0.5 V), d (steps up to 10 V).
    #[arg(long, value_parser = ["a", "b", "c", "d"], required_unless_present = "speed_ref", conflicts_with = "speed_ref")]
    pub signal: Option<String>,
    /// Instead of an excitation: closed-loop speed control at this reference [rad/s], with
    /// the board's friction compensation (the uploaded coefficients).
    #[arg(long, value_name = "RAD_S", allow_hyphen_values = true)]
    pub speed_ref: Option<f32>,
    /// Duration [s]. Default: the signal's (a, b: 90 s; c, d: see `motorid simulate --help`),
    /// 10 s with --speed-ref.
    #[arg(long)]
    pub duration: Option<f64>,
    /// Motor pole pairs, for the log's Hall resolution 2π/(6·pole pairs). Default 11: the
    /// paper's motor (0.095 rad).
    #[arg(long, default_value_t = control::hall::PAPER_POLE_PAIRS)]
    pub pole_pairs: u16,
    /// Output log (CSV, written atomically; missing folders are created below the current
    /// directory, elsewhere only the file's own folder, never at the root).
    #[arg(short, long, value_name = "LOG.csv")]
    pub output: PathBuf,
}

/// Longest silence during a run before giving up [s]: the board sends a sample every
/// 12 ms, so 3 s means it stopped or the cable is out.
const SILENCE: Duration = Duration::from_secs(3);
/// Samples between heartbeats: 0.12 s of board time, far below the board's link timeout
/// (`control::board::LINK_TIMEOUT_PERIODS`, 2 s).
const HEARTBEAT_SAMPLES: usize = 10;

pub fn run(args: Args) -> Result<()> {
    let what = match (&args.signal, args.speed_ref) {
        (Some(s), _) => s.clone(),
        (None, Some(w)) => format!("speed {w} rad/s"),
        (None, None) => bail!("give --signal or --speed-ref"),
    };
    let signal = match args.signal.as_deref() {
        Some("a") => Some((Excitation::A, SignalKind::A)),
        Some("b") => Some((Excitation::B, SignalKind::B)),
        Some("c") => Some((Excitation::C, SignalKind::C)),
        Some(_) => Some((Excitation::D, SignalKind::D)),
        None => None,
    };
    if let Some(w) = args.speed_ref {
        if !w.is_finite() {
            bail!("--speed-ref: must be a number of rad/s (got {w})");
        }
    }
    let duration = args
        .duration
        .unwrap_or(signal.map_or(10.0, |(_, k)| k.default_duration()));
    if !(duration.is_finite() && duration > 0.0 && duration <= 3600.0) {
        bail!("--duration: must be between 0 and 3600 s (got {duration})");
    }
    if args.pole_pairs == 0 {
        bail!("--pole-pairs: must be at least 1");
    }
    crate::atomic::check_outputs(&[&args.output], &[std::path::Path::new(&args.port)])?;
    let mut link = Link::open(&args.port)?;
    let id = link.identify()?;
    link.command(&HostMsg::Stop, "stop")?;
    match (signal, args.speed_ref) {
        (Some((sig, _)), _) => link.start_experiment(sig, duration as f32)?,
        (None, w) => {
            link.command(
                &HostMsg::SetSpeed {
                    omega_ref: w.unwrap_or(0.0),
                },
                "the speed reference",
            )?;
            link.pending_samples.clear();
            link.command(&HostMsg::SetMode { mode: Mode::Speed }, "speed mode")?;
        }
    }

    let ts = f64::from(control::CONTROL_PERIOD_S);
    let expected = (duration / ts).round() as u64;
    let bar = ProgressBar::new(expected);
    bar.set_style(
        ProgressStyle::with_template("recording {bar:30} {pos}/{len} samples ({elapsed})")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut samples: Vec<Sample> = std::mem::take(&mut link.pending_samples);
    loop {
        if samples.len() as u64 >= expected {
            break;
        }
        match link.recv(SILENCE)? {
            Some(BoardMsg::Sample(s)) => {
                samples.push(s);
                bar.set_position(samples.len() as u64);
                // The board stops a run that hears nothing (link loss): a sign of life
                // every HEARTBEAT_SAMPLES samples, in the board's time whatever its speed.
                if samples.len().is_multiple_of(HEARTBEAT_SAMPLES) {
                    link.send(&HostMsg::Heartbeat)?;
                }
            }
            Some(BoardMsg::Fault(f)) => {
                bar.finish_and_clear();
                bail!("{}: the board stopped with a fault: {f:?}", args.port)
            }
            Some(_) => {}
            // Silence: the run ended (the board stops on its own at the duration).
            None => break,
        }
    }
    bar.finish_and_clear();
    if args.speed_ref.is_some() {
        // Speed mode runs until told otherwise.
        link.command(&HostMsg::Stop, "stop")?;
    }
    samples.truncate(expected as usize);
    if samples.is_empty() {
        bail!("{}: the board sent no sample", args.port);
    }
    let lost = samples
        .windows(2)
        .map(|w| u64::from(w[1].seq.wrapping_sub(w[0].seq).saturating_sub(1)))
        .sum::<u64>();
    let mut meta = BTreeMap::new();
    meta.insert(
        "sample_period".to_string(),
        control::CONTROL_PERIOD_S.to_string(),
    );
    let res = std::f64::consts::TAU / (6.0 * f64::from(args.pole_pairs));
    meta.insert("hall_resolution_rad".to_string(), format!("{res}"));
    match (&args.signal, args.speed_ref) {
        (Some(s), _) => meta.insert("signal".to_string(), s.clone()),
        (None, w) => meta.insert("speed_ref".to_string(), w.unwrap_or(0.0).to_string()),
    };
    meta.insert(
        "source".to_string(),
        format!("board {} firmware {}", args.port, id.firmware),
    );
    meta.insert("lost_samples".to_string(), lost.to_string());
    // Each f32 as the f64 of its shortest decimal form (0.012, not 0.012000000104).
    let f = |g: fn(&Sample) -> f32| {
        samples
            .iter()
            .map(|s| crate::cmd::inspect::f32_shortest(g(s)))
            .collect::<Vec<_>>()
    };
    let log = MotorLog {
        source: args.output.clone(),
        meta,
        t: f(|s| s.t),
        u: f(|s| s.u),
        i: Some(f(|s| s.i)),
        theta: f(|s| s.theta),
        omega: Some(f(|s| s.omega)),
        extra: Vec::new(),
        units: Default::default(),
    };
    log.write(&args.output)?;
    eprintln!(
        "recorded {} samples ({:.1} s, {}{}) from {} into {}",
        samples.len(),
        samples.len() as f64 * ts,
        what,
        if lost > 0 {
            format!(", {lost} samples lost on the link")
        } else {
            String::new()
        },
        args.port,
        args.output.display()
    );
    Ok(())
}
