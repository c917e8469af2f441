//! `motorid upload` (not yet written).
use anyhow::{bail, Result};

/// Not yet written.
#[derive(clap::Args, Debug)]
pub struct Args {}

pub fn run(_args: Args) -> Result<()> {
    bail!("'motorid upload' is not implemented yet")
}
