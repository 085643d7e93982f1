//! Stage 3 — `Texels`: every covered lightmap texel becomes a radiosity patch.
//!
//! `raster.rs` rasterises each triangle into its page. A texel covered by several triangles
//! (or partly covered) gets the area-weighted average of what covers it: position, normal,
//! albedo and emission, and the world area actually covered.

mod cuts;
mod raster;
pub mod validity;

use glam::{Vec2, Vec3};

use crate::atlas::PageSize;
use crate::trace::{Hit, Tracer};

pub(crate) use cuts::Cuts;
pub use raster::build;

/// No texel at this page position.
pub(crate) const NO_TEXEL: u32 = u32::MAX;

/// Where a ray from a surface ends ([`Texels::ray_end`]).
#[derive(Clone, Copy, Debug)]
pub(crate) enum RayEnd {
    /// It left the scene: it sees the sky.
    Escaped,
    /// On the back of a single-sided surface, or on a surface without texels.
    Absorbed,
    /// On the front of a surface, in texel `j`.
    Texel(Hit, u32),
}

/// The radiosity patches, structure of arrays indexed by texel id.
#[derive(Clone, Debug, Default)]
pub struct Texels {
    pub(crate) pages: Vec<PageSize>,
    /// Area-weighted centroid of the covered part of the texel (world space).
    pub position: Vec<Vec3>,
    /// Area-weighted unit normal (front side of the surface the texel lies on).
    pub normal: Vec<Vec3>,
    /// World-space area covered (m²).
    pub area: Vec<f32>,
    /// Lambertian reflectance ρ (linear RGB, clamped to
    /// [0, [`MAX_ALBEDO`](crate::scene::MAX_ALBEDO)]).
    pub albedo: Vec<Vec3>,
    /// Emitted radiance `Le` (W/(sr·m²)); emitted radiosity is `π·Le`.
    pub emission: Vec<Vec3>,
    /// Page and texel coordinates.
    pub page: Vec<u32>,
    /// Texel coordinates (x, y) on its page.
    pub xy: Vec<[u32; 2]>,
    /// The triangle covering most of the texel.
    pub(crate) triangle: Vec<u32>,
    /// World-space vectors spanning one texel step in x and in y on `triangle`'s plane
    /// (the texel footprint is `position + s·du + t·dv`, s,t ∈ [−½, ½]).
    pub du: Vec<Vec3>,
    /// The step in y (see `du`).
    pub dv: Vec<Vec3>,
    /// Fraction of the footprint that sample points jitter over: 1, or the candidate cell
    /// (1/G of a side) around a sample point that validity moved out of geometry, so gathering
    /// rays do not start back inside it, narrowed further to stay clear of a wall that divides
    /// the texel (`Cuts`). Empty means 1 everywhere.
    pub jitter: Vec<f32>,
    /// Per page, row-major `width × height`: texel id or [`NO_TEXEL`].
    pub(crate) index: Vec<Vec<u32>>,
    /// Per scene triangle: one texel it covers (fallback for hit lookups that land in a gutter).
    pub(crate) triangle_texel: Vec<u32>,
    /// Triangle lightmap UVs in texel units of its page, per scene triangle (for hit lookups).
    pub(crate) triangle_uv: Vec<[Vec2; 3]>,
    pub(crate) triangle_page: Vec<u32>,
    /// Texels whose footprint has no point outside geometry (ascending ids; see
    /// [`validity`]): solved, but their lightmap value is filled from valid neighbours.
    pub invalid: Vec<u32>,
    /// Texels another surface divides: which texel serves each part of them ([`Cuts`]).
    pub(crate) cuts: Cuts,
}

impl Texels {
    /// Texels held.
    pub fn len(&self) -> usize {
        self.position.len()
    }

    /// Per texel: not in [`Texels::invalid`].
    pub fn valid_mask(&self) -> Vec<bool> {
        let mut valid = vec![true; self.len()];
        for &i in &self.invalid {
            valid[i as usize] = false;
        }
        valid
    }
    /// Calls `f(dx, dy, j)` for the valid texels `j` of `i`'s page within `radius` of it on the
    /// page grid (itself included) that lie on its surface: normals within `acos(min_cos)` of
    /// its own, positions within `√gate2` of where the grid offset puts them on its plane
    /// (`p_i + dx·du_i + dy·dv_i`). So other charts packed beside `i`'s, texels across creases
    /// and sample points validity moved are left out. Row by row; plain loops (the denoiser's
    /// window runs it per texel: an iterator chain took it 0.08 → 0.12 s on the interior).
    #[inline]
    pub(crate) fn for_surface_neighbours(
        &self,
        i: usize,
        radius: i64,
        valid: &[bool],
        (min_cos, gate2): (f32, f32),
        mut f: impl FnMut(i64, i64, usize),
    ) {
        let page = self.page[i] as usize;
        let (width, height) = (
            self.pages[page].width as i64,
            self.pages[page].height as i64,
        );
        let index = &self.index[page];
        let [xi, yi] = self.xy[i];
        let (p_i, n_i, du, dv) = (self.position[i], self.normal[i], self.du[i], self.dv[i]);
        for dy in -radius..=radius {
            let y = yi as i64 + dy;
            if !(0..height).contains(&y) {
                continue;
            }
            for dx in -radius..=radius {
                let x = xi as i64 + dx;
                if !(0..width).contains(&x) {
                    continue;
                }
                let j = index[(y * width + x) as usize];
                if j == NO_TEXEL || !valid[j as usize] {
                    continue;
                }
                let j = j as usize;
                let expected = p_i + dx as f32 * du + dy as f32 * dv;
                if self.normal[j].dot(n_i) < min_cos
                    || self.position[j].distance_squared(expected) > gate2
                {
                    continue;
                }
                f(dx, dy, j);
            }
        }
    }

    /// No texels.
    pub fn is_empty(&self) -> bool {
        self.position.is_empty()
    }

    /// The texel a surface hit on triangle `t` at barycentrics (`u`, `v`) lands in
    /// (`p = (1−u−v)·p0 + u·p1 + v·p2`), or `NO_TEXEL` for triangles with no texels. A hit
    /// on the far side of a wall that divides its texel reads the neighbour there (`Cuts`).
    #[inline]
    pub fn texel_at(&self, t: u32, bary: Vec2) -> u32 {
        let (page, cell, frac) = self.page_cell(t, bary);
        let id = self.index[page][cell];
        if id != NO_TEXEL {
            // The part of a divided texel beyond a wall belongs to the neighbour there.
            self.cuts.resolve(id, frac)
        } else {
            self.triangle_texel[t as usize]
        }
    }

    /// Where a hit lands on its page: the page, the cell in its index, and the position in
    /// that cell (`[0,1)²`).
    #[inline]
    fn page_cell(&self, t: u32, bary: Vec2) -> (usize, usize, Vec2) {
        let [a, b, c] = self.triangle_uv[t as usize];
        let p = a * (1.0 - bary.x - bary.y) + b * bary.x + c * bary.y;
        let page = self.triangle_page[t as usize] as usize;
        let size = self.pages[page];
        let x = (p.x.max(0.0) as u32).min(size.width - 1);
        let y = (p.y.max(0.0) as u32).min(size.height - 1);
        let frac = p - Vec2::new(x as f32, y as f32);
        (page, (y * size.width + x) as usize, frac)
    }

    /// Starts loading the page index entry [`Texels::texel_at`] will read for this hit.
    #[inline]
    pub(crate) fn prefetch_texel(&self, hit: &Hit) {
        let (page, cell, _) = self.page_cell(hit.triangle, hit.bary);
        if let Some(entry) = self.index[page].get(cell) {
            prefetch(entry);
        }
    }

    /// Where the ray from `origin` along `dir` ends: the sky, an absorbing surface, or a texel.
    /// Transport, gathering and the reference follow their rays through this one function
    /// (or its two halves, [`Texels::ray_hit`] then [`Texels::texel_at`]).
    #[inline]
    pub(crate) fn ray_end(&self, tracer: &Tracer, origin: Vec3, dir: Vec3) -> RayEnd {
        let hit = match self.ray_hit(tracer, origin, dir) {
            Ok(hit) => hit,
            Err(end) => return end,
        };
        match self.texel_at(hit.triangle, hit.bary) {
            NO_TEXEL => RayEnd::Absorbed,
            j => RayEnd::Texel(hit, j),
        }
    }

    /// The first half of [`Texels::ray_end`]: the front-face hit, or how the ray ended
    /// without one. It starts loading the hit triangle's lightmap UVs, so that a caller that
    /// traces several rays before it looks their texels up ([`Texels::texel_at`]) waits for
    /// memory once for all of them, not once per ray: the lookup's cache misses were a
    /// quarter of a bake's time (`perf`, the interior at `high`).
    #[inline]
    pub(crate) fn ray_hit(&self, tracer: &Tracer, origin: Vec3, dir: Vec3) -> Result<Hit, RayEnd> {
        let Some(hit) = tracer.closest(origin, dir, f32::INFINITY) else {
            return Err(RayEnd::Escaped);
        };
        if !hit.front {
            return Err(RayEnd::Absorbed); // the back of a single-sided surface absorbs
        }
        if let (Some(uv), Some(page)) = (
            self.triangle_uv.get(hit.triangle as usize),
            self.triangle_page.get(hit.triangle as usize),
        ) {
            prefetch(uv);
            prefetch(page);
        }
        Ok(hit)
    }

    /// A point of texel `i`'s footprint for `u ∈ [0,1)²`, on the surface. A partly covered
    /// texel (at a chart border) is sampled around the centroid of its covered part with the
    /// footprint scaled by the covered fraction: jittering over the whole texel started rays
    /// beyond the edge of the surface (outside a closed box: a 28% furnace error). A texel
    /// whose sample was moved out of geometry jitters within its [`Texels::jitter`] cell.
    /// Bake and reference sample texels through this one function.
    #[inline]
    pub(crate) fn footprint_point(&self, i: usize, u: Vec2) -> Vec3 {
        let (du, dv) = (self.du[i], self.dv[i]);
        let full = du.cross(dv).length();
        let cover = if full > 0.0 {
            (self.area[i] / full).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let scale =
            if cover > 0.99 { 1.0 } else { cover } * self.jitter.get(i).copied().unwrap_or(1.0);
        let o = (u - Vec2::splat(0.5)) * scale;
        self.position[i] + du * o.x + dv * o.y
    }

    /// Where texel `i` reads a punctual light for the footprint point `p` (lifted off the
    /// surface by the ray epsilon): `p` when the surface between the texel's sample point and
    /// `p` is clear, else the sample point. A footprint can reach past a thin solid standing on
    /// it — a lamp's pole under its shade, with the bulb inside the pole — and a point there
    /// sees what the solid hides from every visible point of the texel: one such sample made a
    /// shade texel read `ρ·H` ≈ 80 beside neighbours at 0.4–0.6. Gathering rays from such a
    /// point end on back faces (absorbed), so only lights, which a shadow ray reaches from
    /// anywhere, need this.
    #[inline]
    pub(crate) fn punctual_point(&self, tracer: &Tracer, i: usize, p: Vec3) -> Vec3 {
        let (a, b) = self.punctual_segment(tracer, i, p);
        if tracer.occluded(a, b) {
            self.sample_point(tracer, i)
        } else {
            p
        }
    }

    /// The segment [`Texels::punctual_point`] tests for footprint point `p`: from the sample
    /// point to `p`, both lifted as the divided-texel probe lifts them (`cuts::LIFT`).
    #[inline]
    pub(crate) fn punctual_segment(&self, tracer: &Tracer, i: usize, p: Vec3) -> (Vec3, Vec3) {
        let lift = self.normal[i] * (cuts::LIFT - 1.0) * tracer.epsilon;
        (self.sample_point(tracer, i) + lift, p + lift)
    }

    /// Texel `i`'s sample point, lifted off the surface by the ray epsilon.
    #[inline]
    pub(crate) fn sample_point(&self, tracer: &Tracer, i: usize) -> Vec3 {
        self.position[i] + self.normal[i] * tracer.epsilon
    }

    /// Debug-build consistency check: finite values, areas positive, index consistent.
    #[cfg(debug_assertions)]
    pub(crate) fn validate(&self) {
        let n = self.len();
        for v in [
            &self.normal,
            &self.albedo,
            &self.emission,
            &self.du,
            &self.dv,
        ] {
            assert_eq!(v.len(), n);
        }
        assert_eq!(self.area.len(), n);
        assert_eq!(self.page.len(), n);
        assert_eq!(self.xy.len(), n);
        assert_eq!(self.triangle.len(), n);
        assert!(self.jitter.is_empty() || self.jitter.len() == n);
        for i in 0..n {
            assert!(self.position[i].is_finite() && self.normal[i].is_finite());
            assert!(self.area[i] > 0.0 && self.area[i].is_finite());
            assert!(
                self.albedo[i].min_element() >= 0.0
                    && self.albedo[i].max_element() <= crate::scene::MAX_ALBEDO
            );
            let [x, y] = self.xy[i];
            let p = self.page[i] as usize;
            assert_eq!(
                self.index[p][(y * self.pages[p].width + x) as usize],
                i as u32
            );
        }
    }
}

/// Asks the CPU to start loading `value`'s cache line (a hint: it never faults, and does
/// nothing off x86-64).
#[inline(always)]
pub(crate) fn prefetch<T>(value: &T) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        // SAFETY: a prefetch reads nothing and cannot fault; the pointer is a live reference.
        unsafe { _mm_prefetch::<_MM_HINT_T0>((value as *const T).cast::<i8>()) };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = value;
}
