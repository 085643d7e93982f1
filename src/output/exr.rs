//! EXR and PNG page encoding (stub: being written).
use std::path::Path;
use crate::lightmap::Page;
use crate::Result;
/// Encodes a page as OpenEXR (linear RGB, half or float). `input` names the scene in errors.
pub fn write_exr(page: &Page, float: bool, input: &Path) -> Result<Vec<u8>> {
    let _ = (page, float, input);
    todo!()
}
/// Reads an EXR page back (round-trip tests, `render`, `--reference`).
pub fn read_exr(path: &Path) -> Result<Page> {
    let _ = path;
    todo!()
}
/// Encodes a tone-mapped 8-bit sRGB PNG preview of a page.
pub fn write_png_preview(page: &Page, exposure: f32) -> Result<Vec<u8>> {
    let _ = (page, exposure);
    todo!()
}
