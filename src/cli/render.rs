//! `lightbake render` (being written).

use anyhow::{Result, bail};

#[derive(clap::Args)]
pub struct Args {}

pub fn run(args: &Args) -> Result<()> {
    let _ = args;
    bail!("`lightbake render` is not available yet")
}
