//! `motorid record`: run an excitation on the board and save the log.
use crate::board::link::Link;
use crate::emulator::SignalKind;
use crate::log::MotorLog;
use anyhow::{bail, Result};
use control::frame::{BoardMsg, Excitation, HostMsg, Mode, Sample, Warning};
use control::telemetry::Telemetry;
use indicatif::{ProgressBar, ProgressStyle};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Duration;

/// Run one of the paper's excitations open loop (or closed-loop speed control) on the board
/// and save what it measured as a motor log (CSV: t, u, i, theta, omega).
///
/// The board plays the voltage signal for the given duration and streams a sample every
/// 12 ms; the log holds the voltage actually applied, the measured current, the
/// Hall-quantised angle and the firmware's velocity estimate. The board's loop telemetry
/// during the run goes into metadata lines: `loop_period_us` (mean control period),
/// `loop_jitter_us` (largest deviation of one period from 12 ms), `loop_overruns` (periods
/// that overran), `step_cycles_max` (most CPU cycles one period's work took; 0 on the
/// emulated board) and `hall_edges_lost` (Hall edges the capture queue dropped).
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Serial device of the board (e.g. /dev/ttyACM0, or what `motorid board --pty` printed).
    /// Default: the only serial port of this computer (an error lists them when there are
    /// several).
    #[arg(long, value_name = "P")]
    pub port: Option<String>,
    /// Excitation, open loop, with amplitudes relative to the board's voltage limit u_max (the
    /// uploaded coefficients'; the paper's values at u_max = 24 V): a (fitting, up to u_max/2),
    /// b (up to u_max/4), c (low speed, up to u_max/48), d (steps up to 5/12·u_max), each at
    /// most 0.35·R·i_max (the board's current trip through the winding); steady
    /// (constant levels from 2/3 to all of --amplitude, both signs, 3 s each: the static
    /// friction curve `fit --model lugre` asks for), ramp (slow ramps from rest to ±2/3 of
    /// --amplitude at two slopes: breakaway) and speeds (12 constant levels from 1/15 of
    /// --amplitude to all of it, up then down, each sign, 2 s each: the friction curve over a
    /// wide speed range).
    #[arg(long, value_parser = ["a", "b", "c", "d", "steady", "ramp", "speeds"], required_unless_present = "speed_ref", conflicts_with = "speed_ref")]
    pub signal: Option<String>,
    /// Largest voltage of steady, ramp and speeds as a fraction of u_max (0 < F <= 1).
    /// Default 0.05 for steady and ramp: 0.6 V at u_max = 12 V, the paper's levels for its
    /// motor; raise it for a motor with more friction. Default 0.5 for speeds: 6 V at
    /// u_max = 12 V, its lowest level 0.4 V (the emulator's levels).
    #[arg(long, value_name = "F")]
    pub amplitude: Option<f64>,
    /// The board's loop voltage limit u_max [V] as uploaded (`motorid export --u-max`), for
    /// --amplitude; at most the board's rated bus voltage.
    #[arg(long, value_name = "V", default_value_t = 12.0)]
    pub u_max: f64,
    /// Instead of an excitation: closed-loop speed control at this reference [rad/s], with
    /// the board's friction compensation (the uploaded coefficients). At most the board's
    /// speed limit: the no-load speed at its voltage limit, min(u_max, 0.95·V_bus)/K_b, and
    /// the speed whose Hall edges the board captures (373 rad/s with 11 pole pairs, see
    /// --pole-pairs). The board ramps the speed up at half the current limit's torque over
    /// the inertia, 0.5·K_t·i_limit/J.
    #[arg(long, value_name = "RAD_S", allow_hyphen_values = true)]
    pub speed_ref: Option<f32>,
    /// Duration [s] of a-d or --speed-ref. Default: the signal's (a, b: 90 s; c, d: see
    /// `motorid simulate --help`), 10 s with --speed-ref. Steady, ramp and speeds are
    /// programs of fixed length (66 s, 155 s, 96 s).
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

/// Default largest voltage of steady and ramp as a fraction of u_max: the paper's 0.6 V at
/// the default u_max of 12 V.
pub const DEFAULT_AMPLITUDE: f64 = 0.05;
/// Default largest voltage of speeds as a fraction of u_max: the emulator's 6 V at the
/// default u_max of 12 V.
pub const DEFAULT_SPEEDS_AMPLITUDE: f64 = 0.5;

/// Seconds each level of the steady program is held: the emulator's `steady` signal.
const STEADY_BLOCK_S: f64 = 3.0;

/// The board runs of a steady, ramp or speeds program: (excitation, seconds), the voltages
/// those of the emulator's `steady`, `ramp` and `speeds` signals
/// ([`crate::emulator::signals`]) scaled so that the largest steady level (the top of the
/// speeds ladder for speeds) is `peak` volts.
pub fn program(kind: &str, peak: f64) -> Vec<(Excitation, f64)> {
    use crate::emulator::signals::{
        speeds_blocks, RAMP_END, RAMP_REST, RAMP_SLOPES, SPEEDS_BLOCK, SPEEDS_HIGH, STEADY_LEVELS,
    };
    let top = STEADY_LEVELS.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    let g = peak / top;
    match kind {
        "speeds" => speeds_blocks()
            .into_iter()
            .map(|v| {
                let volts = (v * peak / SPEEDS_HIGH) as f32;
                (Excitation::Steady { volts }, SPEEDS_BLOCK)
            })
            .collect(),
        "steady" => STEADY_LEVELS
            .iter()
            .copied()
            .chain(STEADY_LEVELS.iter().map(|v| -v))
            .map(|v| {
                let volts = (v * g) as f32;
                (Excitation::Steady { volts }, STEADY_BLOCK_S)
            })
            .collect(),
        _ => {
            let mut runs = Vec::new();
            for s in RAMP_SLOPES {
                for sign in [1.0, -1.0] {
                    runs.push((Excitation::Steady { volts: 0.0 }, RAMP_REST));
                    let volts_per_s = (sign * s * g) as f32;
                    runs.push((Excitation::Ramp { volts_per_s }, RAMP_END / s));
                }
            }
            runs
        }
    }
}

/// `--speed-ref` `w` [rad/s] within ±`limit` [rad/s] (`whose` names the limit): one error
/// line naming the flag otherwise.
fn check_speed_ref(w: f32, limit: f32, whose: &str) -> Result<()> {
    if !w.is_finite() {
        bail!(
            "--speed-ref: must be a number of rad/s (got {})",
            crate::validate::show(f64::from(w))
        );
    }
    if w.abs() > limit {
        bail!(
            "--speed-ref: {} rad/s is beyond {whose} speed limit of {limit:.1} rad/s \
             (the board refuses it)",
            crate::validate::show(f64::from(w))
        );
    }
    Ok(())
}

/// The serial port to use when none is given: the only candidate, else an error that lists
/// them (or says there is none).
pub fn pick_port(candidates: &[String]) -> Result<String> {
    match candidates {
        [one] => Ok(one.clone()),
        [] => bail!(
            "no serial port found; connect the board or give --port (for the emulated \
             board, the device `motorid board --pty` printed)"
        ),
        many => bail!(
            "{} serial ports found ({}); give the board's with --port",
            many.len(),
            many.join(", ")
        ),
    }
}

/// The serial ports of this computer, by device name.
fn serial_ports() -> Result<Vec<String>> {
    let ports = serialport::available_ports()
        .map_err(|e| anyhow::anyhow!("cannot list the serial ports ({e}); give --port"))?;
    Ok(ports.into_iter().map(|p| p.port_name).collect())
}

/// Longest silence during a run before giving up [s]: the board sends a sample every
/// 12 ms, so 3 s means it stopped or the cable is out.
const SILENCE: Duration = Duration::from_secs(3);
/// Samples between heartbeats: 0.12 s of board time, far below the board's link timeout
/// (`control::board::LINK_TIMEOUT_PERIODS`, 2 s).
const HEARTBEAT_SAMPLES: usize = 10;

pub fn run(args: Args) -> Result<()> {
    let plan = Plan::of(&args)?;
    let port = match &args.port {
        Some(p) => p.clone(),
        None => {
            let p = pick_port(&serial_ports()?)?;
            eprintln!("using serial port {p} (the only one found)");
            p
        }
    };
    crate::atomic::check_outputs(&[&args.output], &[std::path::Path::new(&port)])?;
    let mut link = Link::open(&port)?;
    // From here on the port as messages show it.
    let port = link.name().to_string();
    let id = link.identify()?;
    if let Some(w) = args.speed_ref {
        check_speed_ref(w, id.speed_max, "the board's")?;
    }
    // The board's state (no hardware stop, default constants) is worth seeing before a run.
    crate::warnings::flush();
    link.command(&HostMsg::Stop, "stop")?;
    let before = link.read_telemetry()?;
    link.pending_telemetry.clear();
    let mut rec = record_runs(&mut link, &plan, &args, &port)?;
    rec.windows.append(&mut link.pending_telemetry);
    let after = link.read_telemetry()?;
    if rec.samples.is_empty() {
        bail!("{port}: the board sent no sample");
    }
    let mut meta = log_meta(&args, &plan, &port, &id.firmware, rec.lost);
    for (k, v) in telemetry_meta(&before, &rec.windows, &after) {
        meta.insert(k.to_string(), v);
    }
    write_log(&args, meta, &rec.samples)?;
    let ts = f64::from(control::CONTROL_PERIOD_S);
    eprintln!(
        "recorded {} samples ({:.1} s, {}{}) from {} into {}",
        rec.samples.len(),
        rec.samples.len() as f64 * ts,
        plan.what,
        if rec.lost > 0 {
            format!(", {} samples lost on the link", rec.lost)
        } else {
            String::new()
        },
        port,
        crate::log::echo_path(&args.output)
    );
    Ok(())
}

/// What the board is asked to run, from the checked arguments.
struct Plan {
    /// The signal's name, or the speed reference, for the closing line.
    what: String,
    /// A program of several board runs (steady, ramp).
    program_kind: bool,
    /// Largest voltage of a program as a fraction of u_max.
    amplitude: f64,
    /// The board runs: one excitation (a-d), a program (steady, ramp), or speed control
    /// (None); each with its duration [s].
    runs: Vec<(Option<Excitation>, f64)>,
}

impl Plan {
    /// Check the arguments and lay out the board runs.
    fn of(args: &Args) -> Result<Plan> {
        let what = match (&args.signal, args.speed_ref) {
            (Some(s), _) => s.clone(),
            (None, Some(w)) => format!("speed {w} rad/s"),
            (None, None) => bail!("give --signal or --speed-ref"),
        };
        let program_kind = matches!(args.signal.as_deref(), Some("steady" | "ramp" | "speeds"));
        if let Some(w) = args.speed_ref {
            check_speed_ref(
                w,
                control::step::rated_speed(args.pole_pairs),
                "the Hall capture's",
            )?;
        }
        let rated = f64::from(control::blob::RATED_VBUS_MAX);
        if !(args.u_max.is_finite() && args.u_max > 0.0 && args.u_max <= rated) {
            bail!(
                "--u-max: must be positive and at most the board's rated {rated} V (got {})",
                crate::validate::show(args.u_max)
            );
        }
        if args.amplitude.is_some() && !program_kind {
            bail!(
                "--amplitude: only for --signal steady, ramp or speeds (the board scales a-d to its u_max)"
            );
        }
        let amplitude = args.amplitude.unwrap_or(match args.signal.as_deref() {
            Some("speeds") => DEFAULT_SPEEDS_AMPLITUDE,
            _ => DEFAULT_AMPLITUDE,
        });
        if !(amplitude.is_finite() && amplitude > 0.0 && amplitude <= 1.0) {
            bail!(
                "--amplitude: must be a fraction of u_max above 0 and at most 1 (got {})",
                crate::validate::show(amplitude)
            );
        }
        if program_kind && args.duration.is_some() {
            bail!("--duration: steady, ramp and speeds are programs of fixed length; leave it out");
        }
        let runs = board_runs(args, amplitude);
        for (_, duration) in &runs {
            if !(duration.is_finite() && *duration > 0.0 && *duration <= 3600.0) {
                bail!(
                    "--duration: must be between 0 and 3600 s (got {})",
                    crate::validate::show(*duration)
                );
            }
        }
        if args.pole_pairs == 0 {
            bail!("--pole-pairs: must be at least 1");
        }
        Ok(Plan {
            what,
            program_kind,
            amplitude,
            runs,
        })
    }
}

/// The board runs of the arguments: (excitation or speed control, seconds).
fn board_runs(args: &Args, amplitude: f64) -> Vec<(Option<Excitation>, f64)> {
    match args.signal.as_deref() {
        Some(k @ ("steady" | "ramp" | "speeds")) => program(k, amplitude * args.u_max)
            .into_iter()
            .map(|(e, d)| (Some(e), d))
            .collect(),
        Some(k) => {
            let (sig, kind) = match k {
                "a" => (Excitation::A, SignalKind::A),
                "b" => (Excitation::B, SignalKind::B),
                "c" => (Excitation::C, SignalKind::C),
                _ => (Excitation::D, SignalKind::D),
            };
            vec![(Some(sig), args.duration.unwrap_or(kind.default_duration()))]
        }
        None => vec![(None, args.duration.unwrap_or(10.0))],
    }
}

/// What the board sent over all runs.
struct Recording {
    /// Samples on one clock from 0.
    samples: Vec<Sample>,
    /// The board's telemetry windows during the runs.
    windows: Vec<Telemetry>,
    /// Samples lost on the link (gaps in the sequence numbers).
    lost: u64,
}

/// Play every run of `plan` on the board and gather its samples; an error when the board
/// ends a run early (nothing is written then).
fn record_runs(link: &mut Link, plan: &Plan, args: &Args, port: &str) -> Result<Recording> {
    let runs = &plan.runs;
    let ts = f64::from(control::CONTROL_PERIOD_S);
    let total: f64 = runs.iter().map(|(_, d)| d).sum();
    let bar = ProgressBar::new((total / ts).round() as u64);
    bar.set_style(
        ProgressStyle::with_template("recording {bar:30} {pos}/{len} samples ({elapsed})")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut rec = Recording {
        samples: Vec::new(),
        windows: Vec::new(),
        lost: 0,
    };
    for (index, (excitation, duration)) in runs.iter().enumerate() {
        start_run(link, *excitation, *duration, args.speed_ref)?;
        let expected = (duration / ts).round() as usize;
        let before = rec.samples.len();
        let (run, end) = collect(link, expected, port, &bar, before, &mut rec.windows)?;
        if let Some(end) = end {
            if excitation.is_none() {
                // Speed mode runs until told otherwise; a board that lost the link stopped.
                let _ = link.command(&HostMsg::Stop, "stop");
            }
            bar.finish_and_clear();
            let which = if runs.len() > 1 {
                format!(" (board run {} of {})", index + 1, runs.len())
            } else {
                String::new()
            };
            let got = rec.samples.len() + run.len();
            let total_n: usize = runs.iter().map(|(_, d)| (d / ts).round() as usize).sum();
            bail!(
                "{port}: the board ended the run early{which}: {got} of {total_n} samples \
                 ({:.1} of {total:.1} s): {end}; nothing written to {} (record again)",
                got as f64 * ts,
                crate::log::echo_path(&args.output)
            );
        }
        if excitation.is_none() {
            // Speed mode runs until told otherwise.
            link.command(&HostMsg::Stop, "stop")?;
        }
        rec.lost += run
            .windows(2)
            .map(|w| u64::from(w[1].seq.wrapping_sub(w[0].seq).saturating_sub(1)))
            .sum::<u64>();
        // Each run's time starts at 0 on the board: continue the log's clock.
        let t0 = rec
            .samples
            .last()
            .map_or(0.0, |s| s.t + control::CONTROL_PERIOD_S);
        rec.samples.extend(run.into_iter().map(|mut s| {
            s.t += t0;
            s
        }));
    }
    bar.finish_and_clear();
    Ok(rec)
}

/// Start one board run: an excitation for `duration` seconds, or speed control at
/// `speed_ref` [rad/s].
fn start_run(
    link: &mut Link,
    excitation: Option<Excitation>,
    duration: f64,
    speed_ref: Option<f32>,
) -> Result<()> {
    match excitation {
        Some(sig) => link.start_experiment(sig, duration as f32),
        None => {
            link.command(
                &HostMsg::SetSpeed {
                    omega_ref: speed_ref.unwrap_or(0.0),
                },
                "the speed reference",
            )?;
            link.pending_samples.clear();
            link.command(&HostMsg::SetMode { mode: Mode::Speed }, "speed mode")
        }
    }
}

/// The log's metadata lines other than the telemetry's.
fn log_meta(
    args: &Args,
    plan: &Plan,
    port: &str,
    firmware: &str,
    lost: u64,
) -> BTreeMap<String, String> {
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
    if plan.program_kind {
        meta.insert(
            "amplitude_v".to_string(),
            format!("{}", plan.amplitude * args.u_max),
        );
    }
    meta.insert(
        "source".to_string(),
        format!("board {port} firmware {firmware}"),
    );
    meta.insert("lost_samples".to_string(), lost.to_string());
    meta
}

/// Write the samples as a motor log to `args.output` (atomically).
fn write_log(args: &Args, meta: BTreeMap<String, String>, samples: &[Sample]) -> Result<()> {
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
    log.write(&args.output)
}

/// Why a board run ended before its duration.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum EarlyEnd {
    /// The board stopped the run: it heard no frame from the host for its link timeout.
    LinkLost,
    /// The board sent nothing for [`SILENCE`].
    Silent,
}

impl std::fmt::Display for EarlyEnd {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            EarlyEnd::LinkLost => write!(
                f,
                "it stopped on link loss (no frame from this computer for {:.0} s of board \
                 time: was this process paused or the machine overloaded?)",
                control::board::LINK_TIMEOUT_PERIODS as f64 * f64::from(control::CONTROL_PERIOD_S)
            ),
            EarlyEnd::Silent => write!(
                f,
                "it fell silent for {} s (cable out, board reset or powered off?)",
                SILENCE.as_secs()
            ),
        }
    }
}

/// Samples of the run `run` covers in board time: up to its last sample's (lost samples in
/// between count, the log reports them as `lost_samples`).
fn covered(run: &[Sample], ts: f64) -> usize {
    run.last()
        .map_or(0, |s| (f64::from(s.t) / ts).round() as usize + 1)
}

/// The samples of one board run: up to `expected` of them, until the board falls silent
/// or stops the run. `before` samples are already on the bar; the board's telemetry windows
/// are appended to `windows`. The second value says why the run ended before its last
/// period, by the board's clock (`None`: the run is complete; samples lost on the link
/// within it are counted by the caller).
fn collect(
    link: &mut Link,
    expected: usize,
    port: &str,
    bar: &ProgressBar,
    before: usize,
    windows: &mut Vec<Telemetry>,
) -> Result<(Vec<Sample>, Option<EarlyEnd>)> {
    let mut samples: Vec<Sample> = std::mem::take(&mut link.pending_samples);
    let mut end = None;
    while samples.len() < expected {
        match link.recv(SILENCE)? {
            Some(BoardMsg::Sample(s)) => {
                samples.push(s);
                bar.set_position((before + samples.len()) as u64);
                // The board stops a run that hears nothing (link loss): a sign of life
                // every HEARTBEAT_SAMPLES samples, in the board's time whatever its speed.
                if samples.len().is_multiple_of(HEARTBEAT_SAMPLES) {
                    link.send(&HostMsg::Heartbeat)?;
                }
            }
            Some(BoardMsg::Fault(f)) => {
                bar.finish_and_clear();
                bail!("{port}: the board stopped with a fault: {f:?}")
            }
            Some(BoardMsg::Telemetry(t)) => windows.push(t),
            Some(BoardMsg::Warning(Warning::LinkLost)) => {
                end = Some(EarlyEnd::LinkLost);
                break;
            }
            Some(_) => {}
            // Silence: the run ended, at its duration or before.
            None => {
                end = Some(EarlyEnd::Silent);
                break;
            }
        }
    }
    samples.truncate(expected);
    // The board's clock says whether the run reached its end: its last sample is the
    // run's last period (a few samples of slack for the board's f32 clock).
    let ts = f64::from(control::CONTROL_PERIOD_S);
    if covered(&samples, ts) + 1 >= expected {
        end = None;
    }
    Ok((samples, end))
}

/// The log's telemetry metadata: period, jitter and cycles over the one-second windows the
/// board reported during the run (the board's last window when the run was shorter than
/// one), overruns and lost Hall edges as the increase of the board's counts over the run.
fn telemetry_meta(
    before: &Telemetry,
    windows: &[Telemetry],
    after: &Telemetry,
) -> Vec<(&'static str, String)> {
    let seen: &[Telemetry] = if windows.is_empty() {
        std::slice::from_ref(after)
    } else {
        windows
    };
    let timed: Vec<&Telemetry> = seen.iter().filter(|t| t.period_us > 0.0).collect();
    let period = if timed.is_empty() {
        f64::NAN
    } else {
        timed.iter().map(|t| f64::from(t.period_us)).sum::<f64>() / timed.len() as f64
    };
    let jitter = seen.iter().map(|t| t.jitter_us).fold(0.0f32, f32::max);
    let cycles = seen.iter().map(|t| t.step_cycles_max).max().unwrap_or(0);
    vec![
        ("loop_period_us", format!("{period:.1}")),
        ("loop_jitter_us", format!("{jitter:.1}")),
        (
            "loop_overruns",
            after.overruns.saturating_sub(before.overruns).to_string(),
        ),
        ("step_cycles_max", cycles.to_string()),
        (
            "hall_edges_lost",
            after
                .edges_lost
                .saturating_sub(before.edges_lost)
                .to_string(),
        ),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_port_is_picked_and_several_are_listed() {
        assert_eq!(pick_port(&["/dev/ttyACM0".into()]).unwrap(), "/dev/ttyACM0");
        let e = pick_port(&["/dev/ttyACM0".into(), "/dev/ttyUSB0".into()])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("2 serial ports") && e.contains("/dev/ttyUSB0"),
            "{e}"
        );
        assert!(pick_port(&[]).unwrap_err().to_string().contains("--port"));
    }

    #[test]
    fn programs_scale_with_the_amplitude() {
        let steady = program("steady", 1.2);
        assert_eq!(steady.len(), 22);
        let top = steady
            .iter()
            .map(|(e, _)| match e {
                Excitation::Steady { volts } => volts.abs(),
                _ => panic!("{e:?}"),
            })
            .fold(0.0f32, f32::max);
        // f32 holds 1.2 V to about one ulp (1.2e-7): 1e-6 allows a few roundings.
        assert!((top - 1.2).abs() < 1e-6, "{top}");
        let ramp = program("ramp", 0.6);
        let slopes: Vec<f32> = ramp
            .iter()
            .filter_map(|(e, _)| match e {
                Excitation::Ramp { volts_per_s } => Some(*volts_per_s),
                _ => None,
            })
            .collect();
        assert_eq!(slopes, [9.5e-3, -9.5e-3, 12e-3, -12e-3]);
        // Speeds: the emulator's ladder, scaled so that its top is the peak, both signs.
        let speeds = program("speeds", 3.0);
        let blocks = crate::emulator::signals::speeds_blocks();
        assert_eq!(speeds.len(), blocks.len());
        for ((e, d), v) in speeds.iter().zip(blocks) {
            let want = (v * 3.0 / crate::emulator::signals::SPEEDS_HIGH) as f32;
            assert!(matches!(e, Excitation::Steady { volts } if (volts - want).abs() < 1e-6));
            assert_eq!(*d, crate::emulator::signals::SPEEDS_BLOCK);
        }
    }

    #[test]
    fn telemetry_meta_summarises_the_windows_of_the_run() {
        let w = |period_us, jitter_us, overruns, step_cycles_max, edges_lost| Telemetry {
            periods: 83,
            period_us,
            jitter_us,
            overruns,
            step_cycles_max,
            edges_lost,
        };
        let before = w(12_000.0, 1.0, 2, 900, 5);
        let windows = [w(12_000.0, 3.0, 2, 1000, 5), w(12_002.0, 7.5, 3, 1400, 9)];
        let after = w(12_001.0, 2.0, 4, 1200, 9);
        let m: BTreeMap<_, _> = telemetry_meta(&before, &windows, &after)
            .into_iter()
            .collect();
        assert_eq!(m["loop_period_us"], "12001.0");
        assert_eq!(m["loop_jitter_us"], "7.5");
        assert_eq!(m["loop_overruns"], "2");
        assert_eq!(m["step_cycles_max"], "1400");
        assert_eq!(m["hall_edges_lost"], "4");
        // A run shorter than a window: the board's latest window.
        let m: BTreeMap<_, _> = telemetry_meta(&before, &[], &after).into_iter().collect();
        assert_eq!(m["loop_period_us"], "12001.0");
        assert_eq!(m["step_cycles_max"], "1200");
    }
}
