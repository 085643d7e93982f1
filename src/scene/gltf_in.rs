//! glTF loader (stub: being written).
use std::path::Path;
use super::{Scene, Source};
use crate::Result;
pub fn load(path: &Path) -> Result<(Scene, Source)> {
    let _ = path;
    todo!("scene loader")
}
