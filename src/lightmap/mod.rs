//! Stage 7 — `LightmapPages`: the solution laid back into page images, dilated, seams stitched.
//!
//! A texel stores `H/π` (irradiance over π): the radiance a white Lambertian surface would
//! reflect, so a renderer shades with `baseColor × lightmap + emission`. With `--directional`,
//! [`directional`] adds pages of L1 spherical harmonics of the incident radiance.

pub mod denoise;
mod dilate;
pub mod directional;
pub mod seams;

use glam::{Vec2, Vec3};

use crate::atlas::PageSize;
use crate::texels::Texels;

pub use dilate::dilate;

/// One lightmap page.
#[derive(Clone, Debug)]
pub struct Page {
    /// Texels across.
    pub width: u32,
    /// Texels down.
    pub height: u32,
    /// Row-major, row 0 at the top (v = 0), linear RGB `H/π`.
    pub rgb: Vec<Vec3>,
    /// Texel holds a solved patch (false in gutters until dilation fills them).
    pub valid: Vec<bool>,
}

impl Page {
    /// Bilinear lookup at `uv` as a renderer samples a lightmap: glTF's image convention (v
    /// grows downward, row 0 at the top; texel (x, y) covers u ∈ [x/W, (x+1)/W],
    /// v ∈ [y/H, (y+1)/H] and its value sits at the centre), clamped to the edge (dilation
    /// filled the gutters).
    pub(crate) fn bilinear(&self, uv: Vec2) -> Vec3 {
        let [a, b, c, d] = self.footprint(uv).map(|(k, _)| self.rgb[k]);
        let (fx, fy) = self.fractions(uv);
        a.lerp(b, fx).lerp(c.lerp(d, fx), fy)
    }

    /// The four texels `Page::bilinear` blends at `uv` — top-left, top-right, bottom-left,
    /// bottom-right, as indices into `rgb` (repeated at a clamped edge) — with their weights.
    pub fn footprint(&self, uv: Vec2) -> [(usize, f32); 4] {
        let (w, h) = (self.width as i64, self.height as i64);
        let (x0, y0) = self.corner(uv);
        let (fx, fy) = self.fractions(uv);
        let k = |x: i64, y: i64| (y.clamp(0, h - 1) * w + x.clamp(0, w - 1)) as usize;
        [
            (k(x0, y0), (1.0 - fx) * (1.0 - fy)),
            (k(x0 + 1, y0), fx * (1.0 - fy)),
            (k(x0, y0 + 1), (1.0 - fx) * fy),
            (k(x0 + 1, y0 + 1), fx * fy),
        ]
    }

    /// Continuous texel coordinates of `uv`, with texel centres on integers.
    fn texel_coords(&self, uv: Vec2) -> Vec2 {
        uv * Vec2::new(self.width as f32, self.height as f32) - 0.5
    }

    /// The top-left texel of `uv`'s bilinear footprint (before clamping).
    fn corner(&self, uv: Vec2) -> (i64, i64) {
        let p = self.texel_coords(uv).floor();
        (p.x as i64, p.y as i64)
    }

    /// How far `uv` lies from the top-left texel's centre towards the next, in x and y.
    fn fractions(&self, uv: Vec2) -> (f32, f32) {
        let p = self.texel_coords(uv);
        (p.x - p.x.floor(), p.y - p.y.floor())
    }
}

/// All pages of a bake.
#[derive(Clone, Debug, Default)]
pub struct LightmapPages {
    /// The pages, in atlas page order.
    pub pages: Vec<Page>,
}

impl LightmapPages {
    /// Lays per-texel values (`H/π`, indexed like [`Texels`]) into pages. Non-finite values
    /// never reach a page: they are written as zero (and the solver's own checks make that
    /// unreachable in practice).
    pub fn from_texels(texels: &Texels, values: &[Vec3]) -> LightmapPages {
        Self::lay_out(texels, values, |v| v.max(Vec3::ZERO))
    }

    /// [`LightmapPages::from_texels`] keeping negative values (signed coefficients such as
    /// [`directional`]'s L1).
    pub(crate) fn from_texels_signed(texels: &Texels, values: &[Vec3]) -> LightmapPages {
        Self::lay_out(texels, values, |v| v)
    }

    fn lay_out(texels: &Texels, values: &[Vec3], keep: impl Fn(Vec3) -> Vec3) -> LightmapPages {
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
            page.rgb[k] = if v.is_finite() { keep(*v) } else { Vec3::ZERO };
            page.valid[k] = true;
        }
        LightmapPages { pages }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 2 × 2 page: 0 and 1 on the top row (v = 0), 2 and 3 below it.
    fn page() -> Page {
        Page {
            width: 2,
            height: 2,
            rgb: [0.0, 1.0, 2.0, 3.0].map(Vec3::splat).to_vec(),
            valid: vec![true; 4],
        }
    }

    fn at(u: f32, v: f32) -> f32 {
        page().bilinear(Vec2::new(u, v)).x
    }

    #[test]
    fn bilinear_lookup_follows_the_gltf_image_convention() {
        // Texel centres give texel values: (x + ½)/W, (y + ½)/H, row 0 at v ≈ 0.
        assert_eq!(at(0.25, 0.25), 0.0);
        assert_eq!(at(0.75, 0.25), 1.0);
        assert_eq!(at(0.25, 0.75), 2.0);
        assert_eq!(at(0.75, 0.75), 3.0);
        // Half-way between the centres: the mean of all four.
        assert_eq!(at(0.5, 0.5), 1.5);
        // A quarter of the way from texel 0 to texel 1 (u = 0.25 + 0.125), at the top row.
        assert_eq!(at(0.375, 0.25), 0.25);
        // Three quarters of the way down from the top row, at the left column: 0 + 0.75·2.
        assert_eq!(at(0.25, 0.625), 1.5);
        // Outside the centres the edge texels hold (clamp-to-edge).
        assert_eq!(at(0.0, 0.0), 0.0);
        assert_eq!(at(1.0, 0.0), 1.0);
        assert_eq!(at(0.1, 1.0), 2.0);
        assert_eq!(at(1.0, 1.0), 3.0);
    }

    #[test]
    fn footprint_weights_sum_to_one_and_name_the_blended_texels() {
        let f = page().footprint(Vec2::new(0.375, 0.625));
        assert_eq!(f.map(|(k, _)| k), [0, 1, 2, 3]);
        // fx = 0.25, fy = 0.75.
        let w = f.map(|(_, w)| w);
        assert_eq!(w, [0.1875, 0.0625, 0.5625, 0.1875]);
        // At a clamped corner every tap is the corner texel.
        let corner = page().footprint(Vec2::new(0.0, 0.0));
        assert!(corner.iter().all(|&(k, _)| k == 0));
        let blended: f32 = f.iter().map(|&(k, w)| w * page().rgb[k].x).sum();
        assert_eq!(blended, at(0.375, 0.625));
    }
}
