//! Matrix-free gathering solver (being written).
use super::Solution;
use crate::config::{SolveParams, TransportParams};
use crate::scene::Scene;
use crate::texels::Texels;
use crate::trace::Tracer;
use crate::transport::Transport;
use crate::{Error, Progress, Result};

pub fn solve(
    scene: &Scene,
    texels: &Texels,
    tracer: &Tracer,
    transport: &TransportParams,
    params: &SolveParams,
    progress: &dyn Progress,
) -> Result<(Transport, Solution)> {
    let _ = (scene, texels, tracer, transport, params, progress);
    Err(Error::Option(
        "the gather solver is not available yet".into(),
    ))
}
