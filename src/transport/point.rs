//! Point-to-point form factors between texel centres, with the near-field cure.
//!
//! ```text
//!   F_ij = min( cosθ_i cosθ_j A_j / (π r²),  A_j / (π r² + A_j) ) · V_ij
//! ```
//!
//! The first term is the differential kernel [`kernel::point_to_point`]; `V_ij` is one shadow
//! ray between the two centres (lifted off their surfaces by the ray epsilon).
//!
//! **The failure it cures.** The raw kernel grows like 1/r²: for the two texels touching at a
//! corner (`r = h/√2` for texel size `h`) it gives `1/π` where the true factor is ~0.2, and
//! rows of texels near corners sum to more than 1 — energy is created and the solver diverges
//! for ρ near 1. **The cure**: each entry is capped by [`kernel::point_to_disk_bound`], the
//! factor of a facing coaxial disk of the source's area at that distance (the most an area
//! `A_j` can subtend head-on, bounded by 1), and any row still summing to more than 1 is scaled
//! to 1 (see `all_pairs`). Rows are then bounded and the solver converges, but near corners
//! the factors stay approximate (a few % in the furnace); use `polygon` for accuracy.
//!
//! | parameter        | effect                                                            |
//! |------------------|-------------------------------------------------------------------|
//! | texel density    | N² pairs and rays; refused above `all_pairs::MAX_TEXELS` texels    |
//! | `light_samples`, `gather_rays` | unused (one visibility ray per pair)                 |
//!
//! When to use: as the cheap baseline of the method comparison, on small scenes. Limits:
//! all-pairs (N² time and up to N² row storage), binary visibility per pair (hard shadow
//! edges at texel resolution), approximate near field.

use super::all_pairs::{self, PairKernel};
use super::kernel::{point_to_disk_bound, point_to_point};
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
    let Surfaces { texels, tracer, .. } = surfaces;
    let kernel = CuredPoint { texels, tracer };
    all_pairs::build(surfaces, params, progress, "point", &kernel)
}

struct CuredPoint<'a> {
    texels: &'a Texels,
    tracer: &'a Tracer,
}

impl PairKernel for CuredPoint<'_> {
    #[inline]
    fn f_ij(&self, i: usize, j: usize, _rng: &mut Rng, rays: &mut u64) -> f32 {
        let t = self.texels;
        let (x_i, n_i, x_j, n_j) = (t.position[i], t.normal[i], t.position[j], t.normal[j]);
        let raw = point_to_point(x_i, n_i, x_j, n_j, t.area[j]);
        if raw <= 0.0 {
            return 0.0;
        }
        let f = raw.min(point_to_disk_bound(x_i.distance_squared(x_j), t.area[j]));
        let eps = self.tracer.epsilon;
        *rays += 1;
        if self.tracer.occluded(x_i + n_i * eps, x_j + n_j * eps) {
            0.0
        } else {
            f
        }
    }
}
