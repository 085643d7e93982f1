//! Stage 8 — output files, every file format lightbake writes in one place: EXR pages and
//! rendered images (`exr.rs`), PNG previews, rendered images and RGBM pages (`png.rs`, with the
//! RGBM encoding in `rgbm.rs`), the GLB container (`glb.rs`), the updated glTF
//! (`gltf_out.rs`) and later edits to it (`gltf_edit.rs`: relit values, layers). Everything a
//! bake writes goes under a temporary name in the output directory and is renamed into place
//! only when all files are complete ([`Staging`]).

mod exr;
pub(crate) mod glb;
pub(crate) mod gltf_edit;
mod gltf_out;
mod gltf_out_accessor;
pub mod png;
pub mod rgbm;
mod staging;

pub use exr::{read_exr, write_exr, write_exr_image};
pub(crate) use gltf_out::decode_uri;
pub(crate) use gltf_out::{PageFiles, write_gltf};
pub(crate) use png::{write_png_image, write_png_preview, write_rgbm_png};
pub use staging::Staging;

/// A 3 × 2 page whose texels are all different (one above the RGBM range), with one invalid
/// texel: the round-trip tests of the EXR and RGBM encoders share it.
#[cfg(test)]
fn test_page() -> crate::lightmap::Page {
    use glam::Vec3;
    let rgb = vec![
        Vec3::new(0.123, 5.5, 1000.0),
        Vec3::new(0.0, 1.0, 2.0),
        Vec3::new(7.25, 0.001, 0.5),
        Vec3::new(3.0, 3.0, 3.0),
        Vec3::new(0.75, 0.0625, 42.0),
        Vec3::new(9.0, 9.0, 9.0),
    ];
    let mut valid = vec![true; 6];
    valid[3] = false;
    crate::lightmap::Page {
        width: 3,
        height: 2,
        rgb,
        valid,
    }
}
