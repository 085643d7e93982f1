//! Hierarchical radiosity (Hanrahan, Salzman & Aupperle 1991; clusters after Smits, Arvo &
//! Greenberg 1994): the links between nodes of a quadtree over each page's texel grid
//! (`tree.rs`), and the direct light. [`crate::solve::hierarchical`] iterates them; its doc
//! is the method's manual (equations, parameters, measurements).
//!
//! Links are refined only where the transferred power `F_pq · B_q · A_p` exceeds
//! `ε = η · Φ / N` (Φ: the scene's radiosity power `Σ A_i B_i` used by the oracle, N texels,
//! `η = 1/√K` from the Monte Carlo method's `gather_rays` K, so one quality knob drives both).
//! Coplanar node pairs (blocks of one flat face) are culled, not refined.
//!
//! Per-texel row correction: a link's `F_pq` is the mean over the receiver node, and pushing
//! it down unchanged is wrong, systematically, for texels near a node's edge (a floor texel
//! next to a wall sees more of the wall than its block does). After each refinement every
//! texel's inherited links are re-evaluated at its own centre (kernels only, times the link's
//! visible fraction) and the pushed irradiance is scaled by `R*_i / R_i`, the ratio of that
//! row sum to the hierarchy's (`links::Refiner::row_scale`). A uniform radiosity (the
//! furnace) is then exact per texel; the spread of light over a row's sources stays the
//! nodes'.
//!
//! Light sources: small emitters (those `Emitters` samples) are light-sampled into
//! `H_direct` with `light_samples` shadow rays per texel (no gathering rays, so no MIS);
//! large emitters (more than a quarter of the scene's area, as in the furnace) stay in the
//! hierarchy as `E = π·Le`, where they are smooth and cheap; punctual lights use 2×2 points per
//! texel; the sky uses `min(K, 64)` cosine rays per texel for the escape fraction, only when
//! the sky is not black. With `indirect_only` the first bounce of large emitters therefore
//! stays in the lightmap.

// Internals of the refinement: public only to the developer diagnostics in examples/dev
// (feature `testing`).
#[cfg(feature = "testing")]
#[doc(hidden)]
pub mod links;
#[cfg(not(feature = "testing"))]
pub(crate) mod links;
#[cfg(feature = "testing")]
#[doc(hidden)]
pub mod tree;
#[cfg(not(feature = "testing"))]
pub(crate) mod tree;

use std::f32::consts::PI;

use glam::{Vec2, Vec3};

use super::rows;
use super::{Surfaces, Transport};
use crate::config::TransportParams;
use crate::lights::{Emitters, punctual_irradiance};
use crate::sampling::{Rng, cosine_hemisphere, frame, hammersley};
use crate::texels::Texels;
use crate::{Error, Progress, Result};
use links::{Footprint, Links, Refiner, footprint_point};
use tree::Tree;

/// Texels per parallel work item of the direct-light pass.
const CHUNK: usize = 128;
/// Cap on the sky rays per texel.
const SKY_RAYS: u32 = 64;
/// Random-stream purpose of the direct-light pass.
const PURPOSE_DIRECT: u64 = 0x4852_4449;

/// What links are built on: the quadtree over the texel pages and every texel's footprint.
pub(crate) struct Hierarchy {
    pub(crate) tree: Tree,
    footprints: Vec<Footprint>,
}

impl Hierarchy {
    pub(crate) fn new(surfaces: Surfaces) -> Hierarchy {
        Hierarchy {
            tree: Tree::build(surfaces.texels),
            footprints: links::footprints(surfaces.scene, surfaces.texels),
        }
    }

    /// The links of refinement `pass` from the radiosity `b` of every node, and each texel's
    /// row scale (`Refiner::row_scale`). Pass 0 (from direct light) adds the mean radiosity
    /// as an ambient guess and refines 4× coarser: it only guesses `B` for the oracle of
    /// pass 1.
    pub(crate) fn link(
        &self,
        surfaces: Surfaces,
        b: &[Vec3],
        pass: u64,
        params: &TransportParams,
        progress: &dyn Progress,
    ) -> Result<(Links, Vec<f32>)> {
        let tree = &self.tree;
        let n = surfaces.texels.len();
        let eta = 1.0 / (params.gather_rays as f32).sqrt();
        // Oracle radiosity: the current B, plus its mean as an ambient guess on the first pass.
        let b: Vec<f32> = b.iter().map(|b| b.max_element()).collect();
        let total: f64 = tree
            .roots
            .iter()
            .map(|&r| (b[r as usize] * tree.area[r as usize]) as f64)
            .sum();
        let area: f64 = tree
            .roots
            .iter()
            .map(|&r| tree.area[r as usize] as f64)
            .sum();
        let ambient = if pass == 0 && area > 0.0 {
            (total / area) as f32
        } else {
            0.0
        };
        let b: Vec<f32> = b.iter().map(|b| b + ambient).collect();
        let power = total + ambient as f64 * area;
        let coarse = if pass == 0 { 4.0 } else { 1.0 };
        let epsilon = (coarse * eta as f64 * power / n.max(1) as f64) as f32;
        progress.begin("hierarchy links", 1);
        let refiner = Refiner {
            texels: surfaces.texels,
            tracer: surfaces.tracer,
            tree,
            footprints: &self.footprints,
            b: &b,
            epsilon,
            seed: params.seed ^ pass,
        };
        let links = refiner
            .refine(&|| progress.aborted())
            .ok_or(Error::Aborted)?;
        progress.advance(1);
        progress.end();
        let scale = refiner.row_scale(&links);
        Ok((links, scale))
    }
}

/// Emission the hierarchy carries (`π·Le`): every emitter that is not light-sampled.
pub(crate) fn carried_emission(texels: &Texels, emitters: &Emitters) -> Vec<Vec3> {
    (0..texels.len())
        .map(|i| {
            let sampled = emitters.pdf_area[texels.triangle[i] as usize] > 0.0;
            if sampled {
                Vec3::ZERO
            } else {
                texels.emission[i] * PI
            }
        })
        .collect()
}

/// `H_direct` per texel — light-sampled small emitters, punctual lights, sky — and the rays
/// cast, as a [`Transport`] without rows.
pub(crate) fn direct_light(
    surfaces: Surfaces,
    params: &TransportParams,
    emitters: &Emitters,
    progress: &dyn Progress,
) -> Result<Transport> {
    let n = surfaces.texels.len();
    rows::build(n, CHUNK, "direct light", progress, |range, out| {
        for i in range {
            let (h, rays) = texel_direct(surfaces, params, emitters, i);
            let h = if h.is_finite() {
                h.max(Vec3::ZERO)
            } else {
                Vec3::ZERO
            };
            out.end_row(out.col.len(), 0.0, h);
            out.rays += rays;
        }
    })
}

/// Direct irradiance of texel `i` and the rays it took.
fn texel_direct(
    surfaces: Surfaces,
    params: &TransportParams,
    emitters: &Emitters,
    i: usize,
) -> (Vec3, u64) {
    let Surfaces {
        scene,
        texels,
        tracer,
    } = surfaces;
    let n = texels.normal[i];
    let mut rng = Rng::new(params.seed, i as u64, PURPOSE_DIRECT);
    let mut h = Vec3::ZERO;
    let mut rays = 0u64;

    // Small emitters: area sampling, Le cosθ_i cosθ_l / (r² p_area).
    let l = if emitters.is_empty() {
        0
    } else {
        params.light_samples
    };
    // Stratified over the emitters' area (a Hammersley set rotated per texel, as the Monte
    // Carlo method): independent samples left ~1% more error on the Cornell box at L = 256.
    let light_shift = rng.next_vec2();
    for s in 0..l {
        let u = hammersley(s, l, light_shift);
        let x = footprint_point(texels, tracer, i, rng.next_vec2());
        if let Some(y) = emitters.sample_from((scene, texels, tracer), x, Some(n), u) {
            h += y.le * (y.cos_i * y.cos_l / (y.r2 * y.pdf_area));
        }
    }
    if l > 0 {
        h /= l as f32;
        rays += l as u64;
    }

    // Punctual lights at 2×2 stratified points.
    if !scene.lights.is_empty() {
        let mut punctual = Vec3::ZERO;
        for s in 0..4u32 {
            let u = (Vec2::new((s % 2) as f32, (s / 2) as f32) + rng.next_vec2()) * 0.5;
            let x = texels.punctual_point(tracer, i, footprint_point(texels, tracer, i, u));
            for light in &scene.lights {
                punctual += punctual_irradiance(light, x, n, tracer);
            }
        }
        h += punctual / 4.0;
        rays += 4 * scene.lights.len() as u64;
    }

    // Sky: L_sky · π · (fraction of cosine rays that escape).
    if params.sky.max_element() > 0.0 {
        let k = params.gather_rays.min(SKY_RAYS);
        let (tx, ty) = frame(n);
        let shift = rng.next_vec2();
        let escaped = (0..k)
            .filter(|&s| {
                let local = cosine_hemisphere(hammersley(s, k, shift));
                let dir = tx * local.x + ty * local.y + n * local.z;
                let x = footprint_point(texels, tracer, i, rng.next_vec2());
                tracer.escapes(x, dir, f32::INFINITY)
            })
            .count();
        h += params.sky * (PI * escaped as f32 / k as f32);
        rays += k as u64;
    }
    (h, rays)
}
