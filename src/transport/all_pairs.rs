//! The all-pairs driver shared by the `point` and `polygon` methods: every receiving texel `i`
//! against every source texel `j`, O(N²) kernel evaluations and visibility rays.
//!
//! Rows carry emission (`B_j = π·Le_j + ρ_j H_j` is gathered through them), so `direct` holds
//! only punctual lights (at 2×2 stratified footprint points, as the Monte Carlo method does)
//! and the sky, `L_sky · π · escape` with `escape = max(0, 1 − Σ_j F_ij)`: that assumes the
//! rows are complete, i.e. the kernel accounts for every surface, which all-pairs ensures.
//!
//! | parameter     | value                 | why                                                    |
//! |---------------|-----------------------|--------------------------------------------------------|
//! | [`MAX_TEXELS`]| 10 000                | N² pairs: 10⁸ kernels, ~4·10⁸ rays, rows up to ~400 MB  |
//! | chunk         | 32 receivers          | one progress tick and abort check each                 |
//!
//! A row whose sum exceeds 1 is scaled down to 1: energy can never be created, whatever the
//! kernel's approximation error (overlapping footprints of partly covered texels, the point
//! kernel near corners).

use glam::{Vec2, Vec3};

use super::rows::{self, ChunkRows};
use super::{Surfaces, Transport};
use crate::config::TransportParams;
use crate::lights::punctual_irradiance;
use crate::sampling::Rng;
use crate::scene::Scene;
use crate::texels::Texels;
use crate::{Error, Progress, Result};

/// Above this many texels the all-pairs methods refuse to run.
pub(crate) const MAX_TEXELS: usize = 10_000;
/// Receivers per parallel work item.
const CHUNK: usize = 32;
/// Jittered points per side of a texel for punctual lights.
const PUNCTUAL_GRID: u32 = 2;
/// Random-stream purposes (the Monte Carlo method uses 0).
const PURPOSE_PAIRS: u64 = 1;
const PURPOSE_PUNCTUAL: u64 = 2;

/// A form-factor method: `F_ij` for one pair, and the rays it cast.
pub(crate) trait PairKernel: Sync {
    /// `F_ij` (receiver `i`, source `j ≠ i`), visibility included; `rng` is receiver `i`'s stream.
    fn f_ij(&self, i: usize, j: usize, rng: &mut Rng, rays: &mut u64) -> f32;
}

/// Builds every row with `kernel`; `method` names it in errors.
pub(crate) fn build(
    surfaces: Surfaces,
    params: &TransportParams,
    progress: &dyn Progress,
    method: &str,
    kernel: &impl PairKernel,
) -> Result<Transport> {
    let n = surfaces.texels.len();
    if n > MAX_TEXELS {
        return Err(Error::Option(format!(
            "the {method} method computes all N² texel pairs and is limited to {MAX_TEXELS} texels; \
             this scene has {n} at this texel density: lower the density, or use \
             `--method montecarlo` or `--method hierarchical`"
        )));
    }
    let mut t = rows::build(n, CHUNK, "transport", progress, |range, out| {
        for i in range {
            row(surfaces, params, kernel, i, out);
        }
    })?;
    t.rows_carry_emission = true;
    Ok(t)
}

/// Row `i`: non-zero `F_ij` straight into the chunk's arrays, then direct light.
fn row(
    surfaces: Surfaces,
    params: &TransportParams,
    kernel: &impl PairKernel,
    i: usize,
    out: &mut ChunkRows,
) {
    let Surfaces {
        scene,
        texels,
        tracer,
    } = surfaces;
    let mut rng = Rng::new(params.seed, i as u64, PURPOSE_PAIRS);
    let start = out.col.len();
    let mut sum = 0.0f64;
    for j in 0..texels.len() {
        if j == i {
            continue;
        }
        let f_ij = kernel.f_ij(i, j, &mut rng, &mut out.rays);
        if f_ij > 0.0 && f_ij.is_finite() {
            out.col.push(j as u32);
            out.f.push(f_ij);
            sum += f_ij as f64;
        }
    }
    if sum > 1.0 {
        let scale = (1.0 / sum) as f32;
        out.f[start..].iter_mut().for_each(|f| *f *= scale);
        sum = 1.0;
    }
    let escape = (1.0 - sum as f32).max(0.0);

    let normal = texels.normal[i];
    let mut punctual = Vec3::ZERO;
    if !scene.lights.is_empty() {
        let mut rng = Rng::new(params.seed, i as u64, PURPOSE_PUNCTUAL);
        let footprint = Footprint::of(scene, texels, i);
        let g = PUNCTUAL_GRID;
        for s in 0..g * g {
            let u = (Vec2::new((s % g) as f32, (s / g) as f32) + rng.next_vec2()) / g as f32;
            let p = texels.punctual_point(tracer, i, footprint.point(u) + normal * tracer.epsilon);
            for light in &scene.lights {
                punctual += punctual_irradiance(light, p, normal, tracer);
            }
        }
        punctual /= (g * g) as f32;
        out.rays += (g * g) as u64 * scene.lights.len() as u64;
    }
    let direct = punctual + params.sky * (std::f32::consts::PI * escape);
    out.end_row(start, escape, direct);
}

/// Covered fraction of texel `i`'s footprint parallelogram.
#[inline]
pub(crate) fn coverage(texels: &Texels, i: usize) -> f32 {
    let full = texels.du[i].cross(texels.dv[i]).length();
    if full > 0.0 {
        (texels.area[i] / full).clamp(0.0, 1.0)
    } else {
        0.0
    }
}

/// The covered part of a texel as a parallelogram `centre + s·du + t·dv`, s, t ∈ [−½, ½].
#[derive(Clone, Copy, Debug)]
pub(crate) struct Footprint {
    pub(crate) centre: Vec3,
    pub(crate) du: Vec3,
    pub(crate) dv: Vec3,
}

impl Footprint {
    /// Texel `i`'s covered part. A partly covered texel (at a chart border) is taken to be cut
    /// by straight borders along its axes: the covered centroid lies `(1 − c_u)/2` texels from
    /// the texel centre along x for a covered width `c_u` (likewise y), which gives the covered
    /// rectangle — exact for a border strip or a corner of an axis-aligned chart, the common
    /// case. (Shrinking the whole square about the centroid instead left gaps along a box's
    /// edges: rows of edge texels summed to 0.94 in the furnace, a 6% error.)
    pub(crate) fn of(scene: &Scene, texels: &Texels, i: usize) -> Footprint {
        let (centre, du, dv) = (texels.position[i], texels.du[i], texels.dv[i]);
        let full = Footprint { centre, du, dv };
        if coverage(texels, i) > 0.99 {
            return full;
        }
        // The texel's geometric centre through its triangle's UV → world map.
        let t = texels.triangle[i] as usize;
        let q0 = texels.triangle_uv[t][0];
        let p0 = scene.positions[scene.triangles[t][0] as usize];
        let [x, y] = texels.xy[i];
        let q = Vec2::new(x as f32 + 0.5, y as f32 + 0.5) - q0;
        let offset = centre - (p0 + du * q.x + dv * q.y);
        // The offset in (du, dv) coordinates: solve the 2×2 normal equations.
        let (uu, uv, vv) = (du.dot(du), du.dot(dv), dv.dot(dv));
        let det = uu * vv - uv * uv;
        let (ou, ov) = (offset.dot(du), offset.dot(dv));
        let o = Vec2::new(vv * ou - uv * ov, uu * ov - uv * ou) / det;
        if det <= 0.0 || !o.is_finite() {
            return full;
        }
        let c = (Vec2::ONE - 2.0 * o.abs()).clamp(Vec2::splat(0.05), Vec2::ONE);
        Footprint {
            centre,
            du: du * c.x,
            dv: dv * c.y,
        }
    }

    /// The point at `u ∈ [0,1)²`, on the surface.
    #[inline]
    pub(crate) fn point(&self, u: Vec2) -> Vec3 {
        self.centre + self.du * (u.x - 0.5) + self.dv * (u.y - 0.5)
    }

    /// The same parallelogram scaled about its centre to have area `area` (a cut that is not
    /// along the axes — a diagonal chart border — gives a rectangle of the wrong area).
    pub(crate) fn with_area(self, area: f32) -> Footprint {
        let current = self.du.cross(self.dv).length();
        if !(current > 0.0 && area > 0.0) {
            return self;
        }
        let s = (area / current).sqrt().clamp(0.5, 2.0);
        Footprint {
            du: self.du * s,
            dv: self.dv * s,
            ..self
        }
    }

    /// Corners, counter-clockwise seen from the side `du × dv` points to.
    pub(crate) fn corners(&self) -> [Vec3; 4] {
        let (c, u, v) = (self.centre, self.du * 0.5, self.dv * 0.5);
        [c - u - v, c + u - v, c + u + v, c - u + v]
    }
}
