//! Chart borders as a renderer reads them: texel values at texel centres.
//!
//! A renderer blends the four texel *centres* around a lookup. Inside a chart a texel's value
//! is measured at its centre; at a chart border it is not: a partly covered texel is sampled at
//! the centroid of its covered part (up to half a texel inside the chart), so a lookup between
//! it and the next texel read the light of the wrong place wherever light changes towards the
//! border — room corners, walls' feet, the ends of a table top. On the point yardstick
//! (`examples/dev/point_breakdown`) lookups touching partly covered texels carried 40–70% of
//! the squared error of the Cornell box, two_rooms and the furnished interior at draft.
//! (Lookups that reach the dilated empty cells beyond a border are rare: giving those cells
//! the plane's value too changed no figure measurably, so dilation is left as it is.)
//!
//! [`extrapolate`] gives a partly covered texel the value a renderer needs there: a weighted
//! least-squares plane `x ≈ a + b·s + c·t` through the solved texels of the same chart within [`RADIUS`] (each at
//! the texel-grid position of its covered part's centroid; Gaussian weights of [`SIGMA`]
//! texels), evaluated at the texel's centre, when those texels spread in both directions (as
//! the denoiser's plane fit asks; a chart one or two texels wide keeps its values). The same
//! chart means: valid, normal within [`MIN_COS`] of the texel's and lying where the grid puts
//! it on that texel's plane (within one texel diagonal), as the denoiser gates. An extrapolated value stays within half the spread of the values it came
//! from, and above half the lowest (a hard shadow edge beside the border is not extended
//! without bound, and a small chart's poor plane never turns a texel black).
//! Only pages are changed; the per-texel solution (what the texel yardstick reads) is not.

use glam::{DMat3, DVec3, Vec2, Vec3};
use rayon::prelude::*;

use super::LightmapPages;
use crate::scene::Scene;
use crate::texels::{NO_TEXEL, Texels};

/// Window half-size in texels.
pub const RADIUS: i64 = 2;
/// Spatial weight's standard deviation, in texels.
pub const SIGMA: f32 = 1.0;
/// Neighbours with normals further apart than this (cosine) belong to another surface.
pub const MIN_COS: f32 = 0.9;
/// A texel covered less than this is a border texel.
const FULL: f32 = 0.99;
/// Minimum determinant of the normalised moment matrix for a plane fit (texels⁴): the
/// neighbours must not lie on one line.
const MIN_SPREAD: f64 = 1e-4;
/// The extrapolated value may carry at most this multiple of one texel's noise variance.
const MAX_NOISE_GAIN: f64 = 1.0;

/// Writes border values into `pages` (laid out from `values` by
/// [`LightmapPages::from_texels`], before dilation): partly covered texels get their chart's
/// plane at their centre.
pub fn extrapolate(scene: &Scene, texels: &Texels, values: &[Vec3], pages: &mut LightmapPages) {
    let offset = centroid_offsets(scene, texels);
    let mut solved = vec![true; texels.len()];
    for &i in &texels.invalid {
        solved[i as usize] = false;
    }
    let fit = Fit {
        texels,
        values,
        offset: &offset,
        solved: &solved,
    };
    for (p, page) in pages.pages.iter_mut().enumerate() {
        let w = page.width as i64;
        let index = &texels.index[p];
        // Each partly covered texel of the page (its own anchor).
        let anchors: Vec<(usize, usize)> = (0..index.len())
            .filter_map(|k| match index[k] {
                NO_TEXEL => None,
                i if solved[i as usize] && coverage(texels, i as usize) < FULL => {
                    Some((k, i as usize))
                }
                _ => None,
            })
            .collect();
        let fitted: Vec<(usize, Option<Vec3>)> = anchors
            .par_iter()
            .map(|&(k, anchor)| (k, fit.at(anchor, [(k as i64) % w, (k as i64) / w])))
            .collect();
        for (k, v) in fitted {
            if let Some(v) = v {
                page.rgb[k] = v;
            }
        }
    }
}

/// Covered fraction of texel `i`'s square.
fn coverage(texels: &Texels, i: usize) -> f32 {
    let full = texels.du[i].cross(texels.dv[i]).length();
    if full > 0.0 {
        texels.area[i] / full
    } else {
        1.0
    }
}

/// Per texel, where its covered part's centroid lies relative to the texel's centre, in texels
/// (from the dominant triangle's lightmap UVs at the centroid's barycentrics).
fn centroid_offsets(scene: &Scene, texels: &Texels) -> Vec<Vec2> {
    (0..texels.len())
        .into_par_iter()
        .map(|i| {
            let t = texels.triangle[i] as usize;
            let [a, b, c] = scene.triangles[t].map(|v| scene.positions[v as usize]);
            let [qa, qb, qc] = texels.triangle_uv[t];
            let (e1, e2, d) = (b - a, c - a, texels.position[i] - a);
            let (d11, d12, d22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
            let det = d11 * d22 - d12 * d12;
            if det <= 0.0 || coverage(texels, i) >= FULL {
                return Vec2::ZERO;
            }
            let u = (d22 * d.dot(e1) - d12 * d.dot(e2)) / det;
            let v = (d11 * d.dot(e2) - d12 * d.dot(e1)) / det;
            let uv = qa + (qb - qa) * u + (qc - qa) * v;
            let [x, y] = texels.xy[i];
            let o = uv - Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
            if o.is_finite() {
                o.clamp(Vec2::splat(-0.5), Vec2::splat(0.5))
            } else {
                Vec2::ZERO
            }
        })
        .collect()
}

struct Fit<'a> {
    texels: &'a Texels,
    values: &'a [Vec3],
    offset: &'a [Vec2],
    solved: &'a [bool],
}

impl Fit<'_> {
    /// The plane of `anchor`'s chart evaluated at the centre of page cell `cell`; `None` when
    /// the chart's texels there do not span a plane.
    fn at(&self, anchor: usize, cell: [i64; 2]) -> Option<Vec3> {
        let t = self.texels;
        let page = t.page[anchor] as usize;
        let (w, h) = (t.pages[page].width as i64, t.pages[page].height as i64);
        let index = &t.index[page];
        let [ax, ay] = t.xy[anchor].map(|c| c as i64);
        let (du, dv, n) = (t.du[anchor], t.dv[anchor], t.normal[anchor]);
        // Where the grid puts texel centres on the anchor's plane.
        let o = self.offset[anchor];
        let origin = t.position[anchor] - du * o.x - dv * o.y;
        let gate2 = (du + dv).length_squared();
        let inv_2ss = 1.0 / (2.0 * SIGMA * SIGMA);
        let mut a = DMat3::ZERO;
        let mut a2 = DMat3::ZERO;
        let mut b = [DVec3::ZERO; 3];
        let (mut lo, mut hi) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
        for y in cell[1] - RADIUS..=cell[1] + RADIUS {
            for x in cell[0] - RADIUS..=cell[0] + RADIUS {
                if !(0..w).contains(&x) || !(0..h).contains(&y) {
                    continue;
                }
                let j = index[(y * w + x) as usize];
                if j == NO_TEXEL || !self.solved[j as usize] {
                    continue;
                }
                let j = j as usize;
                let oj = self.offset[j];
                let expected =
                    origin + du * ((x - ax) as f32 + oj.x) + dv * ((y - ay) as f32 + oj.y);
                if t.normal[j].dot(n) < MIN_COS || t.position[j].distance_squared(expected) > gate2
                {
                    continue;
                }
                let s = Vec2::new((x - cell[0]) as f32 + oj.x, (y - cell[1]) as f32 + oj.y);
                let weight = (-s.length_squared() * inv_2ss).exp() as f64;
                let phi = DVec3::new(1.0, s.x as f64, s.y as f64);
                let outer = DMat3::from_cols(phi * phi.x, phi * phi.y, phi * phi.z);
                a += outer * weight;
                a2 += outer * (weight * weight);
                for (b_k, phi_k) in b.iter_mut().zip(phi.to_array()) {
                    *b_k += weight * phi_k * self.values[j].as_dvec3();
                }
                lo = lo.min(self.values[j]);
                hi = hi.max(self.values[j]);
            }
        }
        let weight = a.x_axis.x;
        if weight <= 0.0 || (a / weight).determinant() <= MIN_SPREAD {
            return None;
        }
        let e = a.inverse().x_axis; // first row = first column (a is symmetric)
        // The fitted value is Σ c_j x_j with c_j = w_j eᵀφ_j; Σ c_j² = eᵀ(Σ w_j² φφᵀ)e is how
        // much of the texels' noise it carries. Above one texel's own, the plane is too poorly
        // held (a chart one or two texels across) to extrapolate.
        if e.dot(a2 * e) > MAX_NOISE_GAIN {
            return None;
        }
        let v = (b[0] * e.x + b[1] * e.y + b[2] * e.z).as_vec3();
        let margin = (hi - lo) * 0.5;
        let v = v.clamp((lo - margin).max(lo * 0.5), hi + margin);
        v.is_finite().then_some(v)
    }
}
