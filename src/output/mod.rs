//! Stage 8 — output files: EXR pages and PNG previews (`exr.rs`), and the updated glTF
//! (`gltf_out.rs`). Everything is written under a temporary name in the output directory and
//! renamed into place only when all files are complete ([`Staging`]).

mod exr;
mod gltf_out;
mod gltf_out_accessor;
mod staging;

pub use exr::{read_exr, write_exr, write_png_preview};
pub use gltf_out::{PageFiles, write_gltf};
pub use staging::Staging;
