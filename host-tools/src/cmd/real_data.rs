//! `motorid real-data` (not yet written).
use anyhow::{bail, Result};

/// Not yet written.
#[derive(clap::Args, Debug)]
pub struct Args {}

pub fn run(_args: Args) -> Result<()> {
    bail!("'motorid real-data' is not implemented yet")
}
