//! Host side of the parity check: run the same trace, compare with QEMU's output, count
//! instructions per step from QEMU's `-d exec` log.
use qemu_parity::{run_trace, Blobs, Observer, Trace, N_OUTPUTS};
use std::collections::BTreeMap;
use std::io::{BufRead, Write};
use std::process::ExitCode;

const USAGE: &str = "\
usage: qemu-parity                      print the host run (same lines as the QEMU run)
       qemu-parity compare QEMU_OUT [--ulp N]
                                        compare QEMU's printed outputs with the host run;
                                        exit 1 if any output differs by more than N ulp (0)
       qemu-parity count QEMU_OUT < EXEC_LOG
                                        instructions per control step, per observer, from
                                        QEMU's `-d exec,nochain -singlestep` log on stdin";

pub fn main(trace: &[u8], blobs: &Blobs<'_>) -> ExitCode {
    let inputs = Inputs {
        trace,
        blobs: *blobs,
    };
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.first().map(String::as_str) {
        None => print_host(&inputs),
        Some("compare") if args.len() >= 2 => {
            let ulp = match args.iter().position(|a| a == "--ulp") {
                Some(p) => args
                    .get(p + 1)
                    .and_then(|s| s.parse::<u64>().ok())
                    .ok_or_else(|| "--ulp needs a whole number".to_string()),
                None => Ok(0),
            };
            ulp.and_then(|ulp| compare(&inputs, &args[1], ulp))
        }
        Some("count") if args.len() >= 2 => count(&args[1]),
        _ => Err(USAGE.to_string()),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

/// The embedded trace and blobs.
pub struct Inputs<'a> {
    trace: &'a [u8],
    blobs: Blobs<'a>,
}

type Outputs = BTreeMap<(String, usize), [u32; N_OUTPUTS]>;

/// Most instructions one 12 ms control period (board logic and step) may take on the
/// Cortex-M4F: 4,000, 1 % of the period at 170 MHz at five cycles an instruction. Five is a
/// pessimistic mean for this code: the FPU adds and multiplies in one cycle and divides in
/// 14, loads take two, and the flash's wait states are hidden by the ART accelerator on
/// straight code. The other 99 % are left to the Hall and PWM interrupts and the link.
const STEP_BUDGET: u64 = 4000;

fn host_outputs(inp: &Inputs) -> Result<(Outputs, usize), String> {
    let trace = Trace::parse(inp.trace).map_err(|e| format!("embedded trace: {e:?}"))?;
    let mut outs = Outputs::new();
    run_trace(
        &trace,
        &inp.blobs,
        |obs, k, o| {
            outs.insert((obs.name().to_string(), k), *o);
        },
        |_, _| {},
    )
    .map_err(|e| format!("embedded coefficient blob: {e}"))?;
    Ok((outs, trace.steps))
}

fn print_host(inp: &Inputs) -> Result<(), String> {
    let (outs, steps) = host_outputs(inp)?;
    let stdout = std::io::stdout();
    let mut w = std::io::BufWriter::new(stdout.lock());
    let io = |e: std::io::Error| e.to_string();
    for obs in Observer::ALL {
        for k in 0..steps {
            let o = outs[&(obs.name().to_string(), k)];
            write!(w, "out {} {}", obs.name(), k).map_err(io)?;
            for b in o {
                write!(w, " {b:08x}").map_err(io)?;
            }
            writeln!(w).map_err(io)?;
        }
    }
    writeln!(w, "done {steps}").map_err(io)?;
    Ok(())
}

/// Distance in units in the last place between two f32 bit patterns (0 = identical).
pub fn ulp_distance(a: u32, b: u32) -> u64 {
    let ordered = |bits: u32| {
        let i = bits as i32;
        if i < 0 {
            i64::from(i32::MIN) - i64::from(i)
        } else {
            i64::from(i)
        }
    };
    (ordered(a) - ordered(b)).unsigned_abs()
}

/// What a QEMU run printed: outputs, the `done` step count, the marker addresses.
type QemuRun = (Outputs, Option<usize>, Option<[u64; MARKERS]>);

/// Marker addresses a QEMU run prints: one begin marker per observer, then the end marker.
const MARKERS: usize = Observer::ALL.len() + 1;

fn read_qemu(path: &str) -> Result<QemuRun, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{path}: {e}"))?;
    let mut outs = Outputs::new();
    let mut done = None;
    let mut markers = None;
    for (n, line) in text.lines().enumerate() {
        let bad = || format!("{path}:{}: cannot read line '{line}'", n + 1);
        let mut f = line.split_whitespace();
        match f.next() {
            Some("out") => {
                let obs = f.next().ok_or_else(bad)?.to_string();
                let k: usize = f.next().and_then(|s| s.parse().ok()).ok_or_else(bad)?;
                let mut o = [0u32; N_OUTPUTS];
                for v in o.iter_mut() {
                    *v = f
                        .next()
                        .and_then(|s| u32::from_str_radix(s, 16).ok())
                        .ok_or_else(bad)?;
                }
                outs.insert((obs, k), o);
            }
            Some("done") => done = f.next().and_then(|s| s.parse().ok()),
            Some("markers") => {
                let mut m = [0u64; MARKERS];
                for v in m.iter_mut() {
                    let s = f.next().ok_or_else(bad)?;
                    *v = u64::from_str_radix(s.trim_start_matches("0x"), 16).map_err(|_| bad())?;
                }
                markers = Some(m);
            }
            _ => {}
        }
    }
    Ok((outs, done, markers))
}

fn compare(inp: &Inputs, path: &str, ulp_bound: u64) -> Result<(), String> {
    let (host, steps) = host_outputs(inp)?;
    let (qemu, done, _) = read_qemu(path)?;
    if done != Some(steps) {
        return Err(format!(
            "{path}: the QEMU run did not finish (no line 'done {steps}'); see its output"
        ));
    }
    let mut worst_all = 0u64;
    for obs in Observer::ALL {
        let (mut same, mut total, mut worst) = (0usize, 0usize, 0u64);
        for k in 0..steps {
            let key = (obs.name().to_string(), k);
            let q = qemu
                .get(&key)
                .ok_or_else(|| format!("{path}: no output for observer {} step {k}", obs.name()))?;
            for (j, (a, b)) in host[&key].iter().zip(q).enumerate() {
                // The last word is the fault bit set: equal or not.
                let d = if j == N_OUTPUTS - 1 {
                    u64::from(a != b) * u64::MAX
                } else {
                    ulp_distance(*a, *b)
                };
                total += 1;
                same += usize::from(d == 0);
                worst = worst.max(d);
            }
        }
        println!(
            "parity {:<6} {steps} steps, {same}/{total} outputs bit-identical, max difference {worst} ulp",
            obs.name()
        );
        worst_all = worst_all.max(worst);
    }
    if worst_all > ulp_bound {
        return Err(format!(
            "QEMU and host outputs differ by up to {worst_all} ulp (allowed: {ulp_bound})"
        ));
    }
    if worst_all == 0 {
        println!("parity: PASS, bit-exact f32 on QEMU Cortex-M4F and on the host");
    } else {
        println!("parity: PASS, within {worst_all} ulp (allowed: {ulp_bound})");
    }
    Ok(())
}

/// Parse QEMU's `-d exec` line `Trace 0: 0x7f.. [00000000/000001a4/...] symbol` → guest PC.
fn exec_pc(line: &str) -> Option<u64> {
    let rest = line.strip_prefix("Trace ")?;
    let open = rest.find('[')?;
    let mut parts = rest[open + 1..].split('/');
    parts.next()?;
    u64::from_str_radix(parts.next()?, 16).ok()
}

fn count(qemu_out: &str) -> Result<(), String> {
    let (_, _, markers) = read_qemu(qemu_out)?;
    let m = markers.ok_or_else(|| format!("{qemu_out}: no 'markers' line"))?;
    let stdin = std::io::stdin();
    // Per observer: number of steps counted, sum, min, max of instructions between a begin
    // marker's first instruction and the end marker's first instruction.
    let mut stats = [(0u64, 0u64, u64::MAX, 0u64); Observer::ALL.len()];
    let mut current: Option<(usize, u64)> = None;
    let mut lines = 0u64;
    for line in stdin.lock().lines() {
        let line = line.map_err(|e| format!("reading the exec log: {e}"))?;
        let Some(pc) = exec_pc(&line) else { continue };
        lines += 1;
        let end = m[MARKERS - 1];
        if let Some(obs) = m[..MARKERS - 1].iter().position(|&a| a == pc) {
            current = Some((obs, 0));
            continue;
        }
        if pc == end {
            if let Some((obs, n)) = current.take() {
                let s = &mut stats[obs];
                s.0 += 1;
                s.1 += n;
                s.2 = s.2.min(n);
                s.3 = s.3.max(n);
            }
            continue;
        }
        if let Some((_, n)) = current.as_mut() {
            *n += 1;
        }
    }
    if lines == 0 {
        return Err("no 'Trace' lines on stdin: run QEMU with -d exec,nochain -singlestep".into());
    }
    for (obs, s) in Observer::ALL.iter().zip(stats) {
        if s.0 == 0 {
            return Err(format!(
                "no control step of observer {} in the log",
                obs.name()
            ));
        }
        println!(
            "instructions per control period (board logic + step), {:<9}: mean {:.0}, min {}, max {} over {} steps (budget {STEP_BUDGET})",
            obs.name(),
            s.1 as f64 / s.0 as f64,
            s.2,
            s.3,
            s.0
        );
        if s.3 > STEP_BUDGET {
            return Err(format!(
                "observer {}: a control period took {} instructions, over the budget of {STEP_BUDGET}",
                obs.name(),
                s.3
            ));
        }
    }
    Ok(())
}
