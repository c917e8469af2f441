//! `motorid upload`: send a coefficient blob to the board over its serial port.
use crate::board::coeffs;
use crate::board::link::Link;
use crate::cmd::inspect::kind_name;
use anyhow::{bail, Result};
use control::commission::CommissionOutcome;
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;

/// Send a coefficient blob (from `motorid export`) to the board over its serial port: the
/// board checks length, CRC and content, stores it in its spare flash slot (the old
/// coefficients stay until the new ones are complete) and runs with it at once.
///
/// The motor must be stopped. Works with the real board (ST-LINK virtual COM port, e.g.
/// /dev/ttyACM0) and with `motorid board --pty`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The blob to send.
    pub blob: PathBuf,
    /// Serial device of the board (e.g. /dev/ttyACM0, or what `motorid board --pty` printed).
    #[arg(long, value_name = "P")]
    pub port: String,
}

pub fn run(args: Args) -> Result<()> {
    // Refuse a damaged blob here, with the file's name, before the board does.
    let (mut bytes, mut co) = coeffs::decode_file(&args.blob)?;
    let mut link = Link::open(&args.port)?;
    let before = link.identify()?;
    // A blob from `export` carries the default Hall table; the board's commissioning (the
    // table learned on this motor's wiring) must survive the upload, or the motor would be
    // commutated with a table it was never checked against.
    if co.commission.is_none() {
        if let (CommissionOutcome::Done(c), _) = link.read_commission()? {
            co.apply_commissioning(c);
            let mut buf = vec![0u8; control::blob::MAX_BLOB_LEN];
            bytes = control::blob::encode(&co, &mut buf)
                .map_err(|e| {
                    anyhow::anyhow!(
                        "{}: cannot keep the board's commissioning: {e:?}",
                        crate::log::echo_path(&args.blob)
                    )
                })?
                .to_vec();
            eprintln!(
                "note: kept the board's Hall commissioning (sequence {:?}) in the uploaded coefficients",
                c.sequence
            );
        }
    }
    let bar = ProgressBar::new(bytes.len() as u64);
    bar.set_style(
        ProgressStyle::with_template("uploading {bar:30} {bytes}/{total_bytes}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let seq = link.upload(&bytes, |n| bar.set_position(n as u64));
    bar.finish_and_clear();
    let seq = seq?;
    // Read back: the board must now report the new slot and the blob's model kind.
    let after = link.identify()?;
    if after.coeff_seq != seq || after.model != co.model {
        bail!(
            "{}: the board committed slot {seq} but now reports slot {} with model {}",
            args.port,
            after.coeff_seq,
            kind_name(after.model)
        );
    }
    println!(
        "uploaded {} ({} bytes, {} model) to {} (firmware {}): active as flash slot sequence {seq} (was {})",
        crate::log::echo_path(&args.blob),
        bytes.len(),
        kind_name(co.model),
        args.port,
        after.firmware,
        before.coeff_seq
    );
    Ok(())
}
