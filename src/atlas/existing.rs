//! Reuse of the input's TEXCOORD_1 (stub: being written).
use super::Atlas;
use crate::config::AtlasParams;
use crate::scene::{Scene, Source};
use crate::Result;
pub fn reuse(scene: &Scene, source: &Source, params: &AtlasParams) -> Result<Atlas> {
    let _ = (scene, source, params);
    todo!("existing uvs")
}
