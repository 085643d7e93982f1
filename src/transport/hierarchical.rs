//! Hierarchical radiosity with clustering (being written).
use super::Transport;
use crate::config::{SolveParams, TransportParams};
use crate::scene::Scene;
use crate::solve::Solution;
use crate::texels::Texels;
use crate::trace::Tracer;
use crate::{Error, Progress, Result};

/// Builds the link hierarchy and solves it; the returned `Transport` holds `direct` and `rays`
/// (no texel rows).
pub fn solve(
    scene: &Scene,
    texels: &Texels,
    tracer: &Tracer,
    params: &TransportParams,
    solve: &SolveParams,
    progress: &dyn Progress,
) -> Result<(Transport, Solution)> {
    let _ = (scene, texels, tracer, params, solve, progress);
    Err(Error::Option(
        "the hierarchical method is not available yet".into(),
    ))
}
