//! Stage 7 — `LightmapPages`: the solution laid back into page images, dilated, seams stitched.
//!
//! A texel stores `H/π` (irradiance over π): the radiance a white Lambertian surface would
//! reflect, so a renderer shades with `baseColor × lightmap + emission`.

pub mod denoise;
mod dilate;
pub mod seams;

use glam::Vec3;

use crate::atlas::PageSize;
use crate::texels::Texels;

pub use dilate::dilate;

/// One lightmap page.
#[derive(Clone, Debug)]
pub struct Page {
    pub width: u32,
    pub height: u32,
    /// Row-major, row 0 at the top (v = 0), linear RGB `H/π`.
    pub rgb: Vec<Vec3>,
    /// Texel holds a solved patch (false in gutters until dilation fills them).
    pub valid: Vec<bool>,
}

/// All pages of a bake.
#[derive(Clone, Debug, Default)]
pub struct LightmapPages {
    pub pages: Vec<Page>,
}

impl LightmapPages {
    /// Lays per-texel values (`H/π`, indexed like [`Texels`]) into pages. Non-finite values
    /// never reach a page: they are written as zero (and the solver's own checks make that
    /// unreachable in practice).
    pub fn from_texels(texels: &Texels, values: &[Vec3]) -> LightmapPages {
        let mut pages: Vec<Page> = texels
            .pages
            .iter()
            .map(|&PageSize { width, height }| Page {
                width,
                height,
                rgb: vec![Vec3::ZERO; (width * height) as usize],
                valid: vec![false; (width * height) as usize],
            })
            .collect();
        for (i, v) in values.iter().enumerate() {
            let page = &mut pages[texels.page[i] as usize];
            let [x, y] = texels.xy[i];
            let k = (y * page.width + x) as usize;
            page.rgb[k] = if v.is_finite() {
                v.max(Vec3::ZERO)
            } else {
                Vec3::ZERO
            };
            page.valid[k] = true;
        }
        LightmapPages { pages }
    }
}
