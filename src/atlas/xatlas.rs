//! xatlas unwrapping (stub: being written).
use super::Atlas;
use crate::config::AtlasParams;
use crate::scene::{Scene, Source};
use crate::Result;
pub fn unwrap(scene: &Scene, source: &Source, params: &AtlasParams) -> Result<Atlas> {
    let _ = (scene, source, params);
    todo!("xatlas")
}
