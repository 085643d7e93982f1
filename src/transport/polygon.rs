//! Point-to-polygon form factors (being written).
use super::Transport;
use crate::config::TransportParams;
use crate::scene::Scene;
use crate::texels::Texels;
use crate::trace::Tracer;
use crate::{Error, Progress, Result};

pub fn build(
    scene: &Scene,
    texels: &Texels,
    tracer: &Tracer,
    params: &TransportParams,
    progress: &dyn Progress,
) -> Result<Transport> {
    let _ = (scene, texels, tracer, params, progress);
    Err(Error::Option(
        "the polygon method is not available yet".into(),
    ))
}
