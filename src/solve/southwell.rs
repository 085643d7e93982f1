//! Southwell progressive refinement (being written).
use super::Solution;
use crate::config::SolveParams;
use crate::texels::Texels;
use crate::transport::Transport;
use crate::{Error, Progress, Result};

pub fn solve(
    transport: &Transport,
    texels: &Texels,
    params: &SolveParams,
    progress: &dyn Progress,
) -> Result<Solution> {
    let _ = (transport, texels, params, progress);
    Err(Error::Option(
        "the southwell solver is not available yet".into(),
    ))
}
