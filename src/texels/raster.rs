//! Rasteriser (stub: being written).
use super::Texels;
use crate::atlas::Atlas;
use crate::scene::Scene;
use crate::Result;
pub fn build(scene: &Scene, atlas: &Atlas) -> Result<Texels> {
    let _ = (scene, atlas);
    todo!("raster")
}
