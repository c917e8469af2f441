//! `motorid clear-fault`: clear the board's latched fault over its serial port.
use crate::board::link::Link;
use anyhow::{bail, Result};
use std::time::Duration;

/// Clear the board's latched fault (`ClearFault`), so that runs are accepted again.
///
/// A fault (over-current, hardware over-current stop, stall, over-temperature, bus voltage,
/// Hall fault, overrun) turns the bridge off and latches: the board refuses every run
/// (`Faulted`) until it is cleared here or the board is reset. Clearing does not turn the
/// bridge on: it stays off until a run starts (`motorid record`). Clearing also re-arms the
/// hardware over-current stop. If the cause persists (a hot board, a bus out of range) the
/// board latches the fault again at its next 12 ms period: this command then says which and
/// exits non-zero. Find the cause first: docs/bring-up.md lists what each fault means.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Serial device of the board (e.g. /dev/ttyACM0, or what `motorid board --pty` printed).
    #[arg(long, value_name = "P")]
    pub port: String,
}

/// How long to listen for the fault latching again: several 12 ms control periods.
const SETTLE: Duration = Duration::from_millis(250);

pub fn run(args: Args) -> Result<()> {
    let mut link = Link::open(&args.port)?;
    link.identify()?;
    match link.clear_fault(SETTLE)? {
        None => {
            eprintln!(
                "{}: fault cleared; the bridge stays off until a run starts",
                args.port
            );
            Ok(())
        }
        Some(f) => bail!(
            "{}: cleared, but the board latched {f:?} again at once: its cause persists",
            args.port
        ),
    }
}
