//! `lightbake reference` (being written).

use anyhow::{Result, bail};

#[derive(clap::Args)]
pub struct Args {}

pub fn run(args: &Args) -> Result<()> {
    let _ = args;
    bail!("`lightbake reference` is not available yet")
}
