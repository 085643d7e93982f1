//! Point-to-polygon form factors: Lambert's contour integral over each source texel's
//! footprint, visibility from stratified shadow rays (ray-traced form factors, Wallace 1989).
//!
//! ```text
//!   F_ij = F(dA_i → P_j) · V_ij,
//!   F(dA_i → P_j) = (1/2π) Σ_e γ_e · n_i·(R_e × R_e+1)/‖R_e × R_e+1‖     (kernel::point_to_polygon)
//!   V_ij = (1/S) Σ_s [x_i sees y_s],  y_s stratified on P_j
//! ```
//!
//! `x_i` is the centre of receiving texel `i`; `P_j` is source texel `j`'s footprint, the
//! parallelogram `position_j ± du_j/2 ± dv_j/2`, clipped to the receiver's horizon by the
//! kernel. A partly covered texel (chart border) is the covered rectangle around its centroid
//! (`all_pairs::Footprint`), scaled to keep the texel's area `A_j`; visibility points are
//! stratified over the covered rectangle, so they stay on the surface. Only the front of a source
//! emits: `F_ij = 0` when `x_i` is behind `j`'s plane.
//!
//! | parameter            | default                | effect                                         |
//! |----------------------|------------------------|------------------------------------------------|
//! | `light_samples` L    | 64 (medium) → S = 4    | `S = g²`, `g = ⌊√(L/16)⌋` in 1..=4: shadow rays per pair (draft 1, medium 4, high 16) |
//! | texel density        |                        | N² pairs; refused above `all_pairs::MAX_TEXELS`  |
//!
//! When to use: small scenes where accuracy matters (reference factors, validating other
//! methods): the kernel is exact for an unoccluded planar source and bounded at any range, so
//! adjacent texels at corners are right. Limits: O(N²) pairs and rays; the receiver is a point
//! (its centre), so a factor is the receiver's midpoint-rule value; visibility is sampled by S
//! rays, so partial occlusion is quantised to 1/S and pairs are not exactly reciprocal.

use glam::{Vec2, Vec3};

use super::all_pairs::{self, Footprint, PairKernel};
use super::kernel::point_to_polygon;
use super::{Surfaces, Transport};
use crate::config::TransportParams;
use crate::sampling::Rng;
use crate::texels::Texels;
use crate::trace::Tracer;
use crate::{Progress, Result};

pub(crate) fn build(
    surfaces: Surfaces,
    params: &TransportParams,
    progress: &dyn Progress,
) -> Result<Transport> {
    let Surfaces {
        scene,
        texels,
        tracer,
    } = surfaces;
    let footprints: Vec<Footprint> = (0..texels.len())
        .map(|j| Footprint::of(scene, texels, j))
        .collect();
    let polygons = footprints
        .iter()
        .zip(&texels.area)
        .map(|(f, &a_j)| f.with_area(a_j).corners())
        .collect();
    let kernel = Polygon {
        texels,
        tracer,
        polygons,
        footprints,
        grid: visibility_grid(params.light_samples),
    };
    all_pairs::build(surfaces, params, progress, "polygon", &kernel)
}

/// Shadow rays per side of the visibility grid for `light_samples` (S = grid²).
pub(crate) fn visibility_grid(light_samples: u32) -> u32 {
    ((light_samples as f32 / 16.0).sqrt() as u32).clamp(1, 4)
}

struct Polygon<'a> {
    texels: &'a Texels,
    tracer: &'a Tracer,
    /// Per source: the footprint polygon (area `A_j`) and the covered part visibility samples.
    polygons: Vec<[Vec3; 4]>,
    footprints: Vec<Footprint>,
    grid: u32,
}

impl PairKernel for Polygon<'_> {
    #[inline]
    fn f_ij(&self, i: usize, j: usize, rng: &mut Rng, rays: &mut u64) -> f32 {
        let t = self.texels;
        let (x_i, n_i, n_j) = (t.position[i], t.normal[i], t.normal[j]);
        if n_j.dot(x_i - t.position[j]) <= 0.0 {
            return 0.0; // i sees the back of j
        }
        let f = point_to_polygon(x_i, n_i, &self.polygons[j]);
        if f <= 0.0 {
            return 0.0;
        }
        let eps = self.tracer.epsilon;
        let origin = x_i + n_i * eps;
        let g = self.grid;
        let mut visible = 0u32;
        for s in 0..g * g {
            let u = (Vec2::new((s % g) as f32, (s / g) as f32) + rng.next_vec2()) / g as f32;
            let y = self.footprints[j].point(u) + n_j * eps;
            if !self.tracer.occluded(origin, y) {
                visible += 1;
            }
        }
        *rays += (g * g) as u64;
        f * visible as f32 / (g * g) as f32
    }
}
