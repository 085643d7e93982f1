//! glTF writer (stub: being written).
use crate::atlas::Atlas;
use crate::scene::{Scene, Source};
use crate::Result;
use super::Staging;
/// File names (relative to the output glTF) of one lightmap page.
#[derive(Clone, Debug)]
pub struct PageFiles {
    pub exr: String,
    pub png: String,
}
/// Writes `<stem>.gltf` + `<stem>.bin` (or `<stem>.glb` for .glb input) into `staging`.
pub fn write_gltf(scene: &Scene, source: &Source, atlas: &Atlas, pages: &[PageFiles], staging: &mut Staging, stem: &str) -> Result<()> {
    let _ = (scene, source, atlas, pages, staging, stem);
    todo!()
}
