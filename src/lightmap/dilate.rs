//! Dilation (stub: being written).
use super::LightmapPages;
pub fn dilate(pages: &mut LightmapPages, radius: u32) {
    let _ = (pages, radius);
    todo!("dilate")
}
