//! `motorid commission`: run the board's Hall commissioning over its serial port.
use crate::board::link::Link;
use anyhow::{bail, Result};
use control::commission::{CommissionError, CommissionOutcome, Commissioning};
use std::time::Duration;

/// Run the board's Hall commissioning: with the motor free to turn, the board holds three
/// centre vectors in turn (two phases high, one low: each field points at the middle of a
/// Hall sector) at a limited voltage (a quarter of u_max, at most the voltage that drives
/// 30 % of i_max at standstill), both directions, and learns which Hall
/// state belongs to which sector (the Hall table), the direction, the current-sense sign and
/// whether the Hall sensors have the motor's pole pairs (6 edges per electrical revolution).
/// The board stores the result with its coefficients (a new flash slot) and uses it at once.
///
/// Works with the real board and with `motorid board --pty` (try `--hall-order 213` or
/// `--phase-order 132` there).
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Serial device of the board (e.g. /dev/ttyACM0, or what `motorid board --pty` printed).
    #[arg(long, value_name = "P")]
    pub port: String,
    /// Only read the stored result, do not run the commissioning.
    #[arg(long)]
    pub read: bool,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Longest wait for the result after the start: the run itself is 9 holds of 0.3 s, the
/// first extended while its current ramp runs, by up to 7.2 s, and up to eight times that
/// for coefficients with a large back-EMF constant
/// ([`control::commission::RUN_PERIODS_MAX`]: 60.3 s in all).
const RESULT_TIMEOUT: Duration = Duration::from_secs(75);

fn error_text(e: CommissionError) -> String {
    let text = match e {
        CommissionError::NoMotion => {
            "the Hall state did not change (rotor blocked, voltage too low, or Hall sensors not connected)"
        }
        CommissionError::InvalidState => "a Hall state 000 or 111 was read (a sensor is not connected?)",
        CommissionError::NotSixStates => "the three centre vectors did not give three different Hall states",
        CommissionError::NotAdjacent => "centre vectors 120° apart gave Hall states other than two sensors apart",
        CommissionError::Inconsistent => "the backward pass read other Hall states than the forward pass",
        CommissionError::PolePairs => {
            "not the sequence's 6 Hall edges per electrical revolution: the Hall magnet's pole pairs differ from the motor's"
        }
        CommissionError::Aborted => "stopped before the end (a stop command or a fault)",
        CommissionError::NoCurrent => {
            "the board measured little or no current while it held the voltage (current sense not working, motor phases not connected, or a winding resistance over four times the coefficients' R); nothing was stored"
        }
        CommissionError::RampStalled => {
            "the board raises the voltage slowly at the start until it measures a current, and it never measured enough (a quarter of the commissioning current) with the rotor at rest, so the voltage stayed low and the run failed; check that the current sense works and the motor's three phases are connected, that the rotor turns freely and is not held or driven, that the coefficients' dead time suits the bridge (a drop over twice the expected one needs a higher voltage), and that the commissioning current is not too low (below about 6.5 A, an i_max below about 22 A, the ramp runs out of time): raise i_max within the motor's rating for the run; nothing was stored"
        }
        CommissionError::BackEmfTooLarge => {
            return format!(
                "the coefficients' back-EMF constant per pole pair (motor.kb over pole_pairs) is over {} times the {:.4} V·s/rad the board's current ramp at the start is sized for, so the board refused the run before driving anything; check that motor.kb is in V·s/rad (not V/krpm) and pole_pairs is the motor's; a motor whose constant really is that large (a gimbal or hub motor) cannot be commissioned by the board yet; nothing was stored",
                control::commission::RAMP_K_RATIO_MAX,
                control::commission::RAMP_K_EMF
            )
        }
    };
    text.to_string()
}

/// The result as JSON.
pub fn to_json(c: &Commissioning, seq: u32) -> serde_json::Value {
    let table: Vec<serde_json::Value> = (0..8u8)
        .map(|s| match c.sequence.iter().position(|&x| x == s) {
            Some(k) => serde_json::json!(k),
            None => serde_json::Value::Null,
        })
        .collect();
    serde_json::json!({
        "hall_sequence": c.sequence,
        "hall_table": table,
        "reversed": c.reversed,
        "permuted": c.permuted,
        "current_sign": c.current_sign,
        "edges_per_electrical_rev": c.edges_per_elec_rev,
        "volts": crate::cmd::inspect::f32_shortest(c.volts),
        "stored_seq": seq,
    })
}

pub fn run(args: Args) -> Result<()> {
    let mut link = Link::open(&args.port)?;
    link.identify()?;
    crate::warnings::flush();
    let (outcome, seq) = if args.read {
        link.read_commission()?
    } else {
        if !args.json {
            eprintln!(
                "commissioning on {}: the motor turns slowly both ways",
                args.port
            );
        }
        link.commission(RESULT_TIMEOUT)?
    };
    let c = match outcome {
        CommissionOutcome::Done(c) => c,
        CommissionOutcome::Failed(e) => {
            bail!("{}: commissioning failed: {}", args.port, error_text(e))
        }
        CommissionOutcome::NotRun => bail!(
            "{}: no commissioning result on the board (none was run, or the stored one came \
             from an older firmware that numbered the Hall sectors otherwise and is not used): \
             run `motorid commission --port {}`",
            args.port,
            args.port
        ),
        CommissionOutcome::Running => bail!("{}: commissioning is still running", args.port),
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&to_json(&c, seq))?);
        return Ok(());
    }
    // `permuted` is never set: a swapped Hall connector reads as the default order reversed.
    let dir = if c.reversed {
        "reversed (default Hall order backward)"
    } else {
        "default"
    };
    println!("Hall sequence (sectors 0-5): {:?}", c.sequence);
    println!("direction: {dir}");
    println!("current-sense sign: {:+}", c.current_sign);
    println!(
        "Hall edges per electrical revolution: {} (pole pairs {})",
        c.edges_per_elec_rev,
        if c.edges_per_elec_rev == 6 {
            "match"
        } else {
            "differ"
        }
    );
    println!(
        "centre vector voltage: {} V",
        crate::cmd::inspect::f32_shortest(c.volts)
    );
    if seq == 0 {
        println!("not stored (the board's flash write failed)");
    } else {
        println!("stored with the coefficients as flash slot sequence {seq}");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_host_waits_longer_than_the_longest_run() {
        let longest =
            f64::from(control::commission::RUN_PERIODS_MAX) * f64::from(control::CONTROL_PERIOD_S);
        assert!(RESULT_TIMEOUT.as_secs_f64() > longest, "{longest} s");
    }

    #[test]
    fn a_refused_back_emf_constant_names_the_ratio_and_the_units() {
        let text = error_text(CommissionError::BackEmfTooLarge);
        let ratio = control::commission::RAMP_K_RATIO_MAX.to_string();
        assert!(text.contains(&format!("over {ratio} times")), "{text}");
        assert!(
            text.contains("V·s/rad") && text.contains("V/krpm"),
            "{text}"
        );
    }
}
