//! `motorid flash`: write a coefficient blob into the board's flash with a debug probe.
//!
//! The blob goes into the firmware's two-slot store (`control::slots`) at the `COEFFS`
//! region of memory.x (0x0801_F000, two 2 KiB pages): the current pages are read through the
//! probe, the slot update is computed with the firmware's own code (the new blob goes into
//! the slot *not* in use, header last), only that page is erased and programmed with
//! probe-rs (`FlashLoader::add_data`, then `commit`), and the pages are read back and decoded
//! to verify.
//!
//! probe-rs is behind the cargo feature `probe` (off by default): it brings a USB, ELF and
//! DWARF stack that adds several minutes to a cold release build on a 2-core machine, which
//! the Quick start's 10-minute budget cannot afford for a command most users run without a
//! probe. `cargo build --release --features probe --bin motorid` turns it on.
use anyhow::Result;
use std::path::PathBuf;

/// Start of the coefficient region (memory.x: `COEFFS : ORIGIN = 0x0801F000, LENGTH = 4K`).
pub const COEFFS_ADDR: u64 = 0x0801_F000;

/// Write a coefficient blob into the board's flash (the coefficient slots) through a debug
/// probe (the B-G431B-ESC1's on-board ST-LINK), read it back and verify it.
///
/// Needs motorid built with the `probe` feature (`cargo build --release --features probe`).
/// Without a probe, `motorid upload --port` does the same over the serial port.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The blob to write (from `motorid export`).
    pub blob: PathBuf,
    /// Target chip, as probe-rs names it.
    #[arg(long, default_value = "STM32G431CBUx")]
    pub chip: String,
}

#[cfg(not(feature = "probe"))]
pub fn run(args: Args) -> Result<()> {
    // Check the blob anyway: a damaged file is reported as such.
    crate::board::coeffs::decode_file(&args.blob)?;
    anyhow::bail!(
        "motorid was built without probe support; rebuild with --features probe \
         (cargo build --release --features probe --bin motorid), or use `motorid upload {} --port PORT`",
        crate::log::echo_path(&args.blob)
    )
}

#[cfg(feature = "probe")]
pub fn run(args: Args) -> Result<()> {
    use crate::board::emulated_flash::{RamFlash, PAGE, SIZE};
    use anyhow::{anyhow, bail, Context};
    use embedded_storage::nor_flash::ReadNorFlash;
    use probe_rs::flashing::{DownloadOptions, FlashLoader};
    use probe_rs::{MemoryInterface, Session, SessionConfig};

    let (bytes, co) = crate::board::coeffs::decode_file(&args.blob)?;
    let mut session =
        Session::auto_attach(args.chip.as_str(), SessionConfig::default()).map_err(|e| {
            anyhow!(
                "no debug probe attached, or it cannot reach the {}: {e}",
                args.chip
            )
        })?;
    let read_region = |session: &mut Session| -> Result<Vec<u8>> {
        let mut image = vec![0u8; SIZE];
        let mut core = session.core(0).context("cannot halt the core")?;
        core.read(COEFFS_ADDR, &mut image)
            .context("cannot read the coefficient flash")?;
        Ok(image)
    };
    let before = read_region(&mut session)?;
    // The slot update, computed on a copy of the two pages with the firmware's code.
    let tmp = tempfile::NamedTempFile::new()?;
    std::fs::write(tmp.path(), &before)?;
    let mut slots = RamFlash::new(Some(tmp.path().to_path_buf())).into_slots()?;
    let info = slots
        .store(&bytes)
        .map_err(|e| anyhow!("cannot prepare the slot: {e:?}"))?;
    let mut ram = slots.into_inner();
    let mut page = vec![0u8; PAGE];
    let off = info.index as usize * PAGE;
    ram.read(off as u32, &mut page)
        .map_err(|e| anyhow!("slot image: {e:?}"))?;

    let mut loader: FlashLoader = session.target().flash_loader();
    loader
        .add_data(COEFFS_ADDR + off as u64, &page)
        .map_err(|e| anyhow!("flash loader: {e}"))?;
    loader
        .commit(&mut session, DownloadOptions::default())
        .map_err(|e| anyhow!("writing the flash failed: {e}"))?;

    let after = read_region(&mut session)?;
    if after[off..off + PAGE] != page[..] {
        bail!("verification failed: the flash does not hold what was written");
    }
    std::fs::write(tmp.path(), &after)?;
    let mut check = RamFlash::new(Some(tmp.path().to_path_buf())).into_slots()?;
    match check.load().map_err(|e| anyhow!("read back: {e:?}"))? {
        Some((got, c)) if got.seq == info.seq && c == co => {}
        _ => bail!("verification failed: the board would not boot with this blob"),
    }
    println!(
        "flashed {} ({} bytes) into coefficient slot {} (sequence {}) of the {}; verified",
        crate::log::echo_path(&args.blob),
        bytes.len(),
        info.index,
        info.seq,
        args.chip
    );
    Ok(())
}
