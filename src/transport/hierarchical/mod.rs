//! Hierarchical radiosity with clustering (Hanrahan, Salzman & Aupperle 1991; clusters after
//! Smits, Arvo & Greenberg 1994), on lightmap texels.
//!
//! Per colour channel, for every node `p` of a quadtree over each page's texel grid
//! (see [`tree`]), and for every texel `i` with ancestors `a ∋ i`:
//!
//! ```text
//!   G_p = Σ_{links p←q} F_pq · B_q                 gathered at the level of the link
//!   H_i = H_direct,i + Σ_{a ∋ i} G_a               push: irradiance flows down unchanged
//!   B_i = E_i + ρ_i H_i,   B_p = Σ_c A_c B_c / A_p  pull: area-averaged radiosity flows up
//! ```
//!
//! Links are refined only where the transferred power `F_pq · B_q · A_p` exceeds
//! `ε = η · Φ / N` (Φ: the scene's radiosity power `Σ A_i B_i` used by the oracle, N texels,
//! `η = 1/√K` from the Monte Carlo method's `gather_rays` K, so one quality knob drives both).
//! Links are built once from direct light (plus the mean radiosity as an ambient guess, with a
//! 4× coarser ε), the system is solved, and the links are rebuilt from the solved `B` and
//! solved again. Coplanar node pairs (blocks of one flat face) are culled, not refined.
//!
//! Per-texel row correction: a link's `F_pq` is the mean over the receiver node, and pushing
//! it down unchanged is wrong, systematically, for texels near a node's edge (a floor texel
//! next to a wall sees more of the wall than its block does). After each refinement every
//! texel's inherited links are re-evaluated at its own centre (kernels only, times the link's
//! visible fraction) and the pushed irradiance is scaled by `R*_i / R_i`, the ratio of that
//! row sum to the hierarchy's ([`links::Refiner::row_scale`]). A uniform radiosity (the
//! furnace) is then exact per texel; the spread of light over a row's sources stays the
//! nodes'.
//!
//! Measured (2 shared cores under load; `examples/dev/hierarchical_diagnose.rs`,
//! `examples/dev/hierarchical_compare.rs`), before → after this correction, the exact footprints
//! of chart-corner texels and stratified light sampling:
//!
//! | case                                                  | before        | after         |
//! |-------------------------------------------------------|---------------|---------------|
//! | furnace ρ 0.5, 8 texels/unit, worst texel             | 8.5%          | 0.36%         |
//! | furnace ρ 0.9, 8 texels/unit, worst texel             | 12%           | 0.44%         |
//! | furnace ρ 0.9, 16 texels/unit, worst texel            | 16%           | 0.7%          |
//! | furnace ρ 0.9 vs path-traced reference (noise 1.08%)  | 5.4–8.4%      | 1.12–1.15%    |
//! | Cornell 32/unit vs Monte Carlo K=1024, K=256          | 3.9%, 8.4 s cpu | 2.5%, 6.5 s cpu |
//! | Cornell 32/unit vs Monte Carlo K=1024, K=1024         | 2.6%, 9.2 s cpu | 2.1%, 7.6 s cpu |
//! | Cornell vs reference (chart), K=1024                  | 3.34%         | 2.78% (before stratified light) |
//! | two_rooms vs reference (chart), K=1024                | 6.37%         | 5.63% (idem)  |
//!
//! For scale: the Monte Carlo method itself is 2.6% (K=64, 0.2 s cpu) and 1.5% (K=256, 0.5 s)
//! from its K=1024 result on that Cornell box, so at these sizes it is both faster and more
//! accurate. The hierarchy has ~150 links per texel there (1.1M links for 7167 texels, about
//! 5 shadow rays each, two passes): the link count hardly depends on ε (a 4× coarser ε gives
//! 10% fewer links), so it is the near field (`NEAR`) and the per-link cost, not the oracle,
//! that set the time; what is left is there.
//!
//! Light sources: small emitters (those [`Emitters`] samples) are light-sampled into
//! `H_direct` with `light_samples` shadow rays per texel (no gathering rays, so no MIS);
//! large emitters (more than a quarter of the scene's area, as in the furnace) stay in the
//! hierarchy as `E = π·Le`, where they are smooth and cheap; punctual lights use 2×2 points per
//! texel; the sky uses `min(K, 64)` cosine rays per texel for the escape fraction, only when
//! the sky is not black. With `indirect_only` the first bounce of large emitters therefore
//! stays in the lightmap.
//!
//! | parameter        | default (medium) | effect                                                 |
//! |------------------|------------------|--------------------------------------------------------|
//! | `gather_rays` K  | 256              | η = 1/√K: links ∝ 1/η, error ∝ η                        |
//! | `light_samples`  | 64               | shadow rays per texel to small emitters                 |
//! | [`links::KERNEL_SAMPLES`] | 16      | kernel samples per link (no rays)                       |
//! | [`links::SAMPLES`] | 4              | shadow rays per accepted link                           |
//! | `tolerance`      | 1e-4             | stopping rule as in [`crate::solve`]                    |
//!
//! When to use: large scenes and dense lightmaps, where rows of K entries per texel do not fit
//! or take too long: links grow about linearly with texels. Limits: irradiance is constant
//! over a link's receiver node before the push, so coarse links show as soft blocks of size
//! ε allows; visibility of a link is sampled by 4 rays, so partly occluded links are noisy
//! until refined; the near field is refined down to texels, where form factors are exact
//! (Lambert's formula) but visibility is still sampled.

pub mod links;
pub mod tree;

use std::f32::consts::PI;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use glam::{Vec2, Vec3};
use rayon::prelude::*;

use super::Transport;
use crate::config::{SolveParams, TransportParams};
use crate::lights::{Emitters, punctual_irradiance, triangle_point};
use crate::sampling::{
    Rng, cosine_hemisphere, frame, hammersley, triangle_point as sample_triangle,
};
use crate::scene::Scene;
use crate::solve::{Iteration, Solution};
use crate::texels::Texels;
use crate::trace::Tracer;
use crate::{Error, Progress, Result};
use links::{Links, Refiner, footprint_point};
use tree::Tree;

/// Texels per parallel work item of the direct-light pass.
const CHUNK: usize = 128;
/// Cap on the sky rays per texel.
const SKY_RAYS: u32 = 64;
/// Random-stream purpose of the direct-light pass.
const PURPOSE_DIRECT: u64 = 0x4852_4449;

/// Statistics of a hierarchical solve (links of the final refinement).
#[derive(Clone, Copy, Debug, Default)]
pub struct Stats {
    pub nodes: usize,
    pub links: usize,
}

/// Builds the link hierarchy and solves it; the returned `Transport` holds `direct` and `rays`
/// (no texel rows).
pub fn solve(
    scene: &Scene,
    texels: &Texels,
    tracer: &Tracer,
    params: &TransportParams,
    solve: &SolveParams,
    progress: &dyn Progress,
) -> Result<(Transport, Solution)> {
    solve_with_stats(scene, texels, tracer, params, solve, progress).map(|(t, s, _)| (t, s))
}

/// [`solve`], also returning node and link counts (for benchmarks and tests).
pub fn solve_with_stats(
    scene: &Scene,
    texels: &Texels,
    tracer: &Tracer,
    params: &TransportParams,
    solve: &SolveParams,
    progress: &dyn Progress,
) -> Result<(Transport, Solution, Stats)> {
    let n = texels.len();
    let emitters = Emitters::new(scene, texels);
    let (direct, mut rays) = direct_light(scene, texels, tracer, params, &emitters, progress)?;
    // Emission the hierarchy carries: every emitter that is not light-sampled.
    let emitted: Vec<Vec3> = (0..n)
        .map(|i| {
            let sampled = emitters.pdf_area[texels.triangle[i] as usize] > 0.0;
            if sampled {
                Vec3::ZERO
            } else {
                texels.emission[i] * PI
            }
        })
        .collect();
    let tree = Tree::build(texels);
    let footprints = links::footprints(scene, texels);
    let mut state = State::new(&tree, texels, &direct, &emitted);
    let eta = 1.0 / (params.gather_rays as f32).sqrt();
    let start = Instant::now();
    let mut solution = Solution::default();
    let mut stats = Stats {
        nodes: tree.len(),
        links: 0,
    };
    for pass in 0..2 {
        // Oracle radiosity: the current B, plus its mean as an ambient guess on the first pass.
        let b: Vec<f32> = state.b.iter().map(|b| b.max_element()).collect();
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
        // The first pass only guesses B for the oracle of the second: 4× coarser links.
        let coarse = if pass == 0 { 4.0 } else { 1.0 };
        let epsilon = (coarse * eta as f64 * power / n.max(1) as f64) as f32;
        progress.begin("hierarchy links", 1);
        let refiner = Refiner {
            texels,
            tracer,
            tree: &tree,
            footprints: &footprints,
            b: &b,
            epsilon,
            seed: params.seed ^ pass,
        };
        let links = refiner
            .refine(&|| progress.aborted())
            .ok_or(Error::Aborted)?;
        progress.advance(1);
        progress.end();
        rays += links.rays;
        stats.links = links.len();
        state.scale = refiner.row_scale(&links);
        let converged = state.iterate(&tree, &links, solve, start, &mut solution, progress)?;
        solution.converged = converged;
    }
    solution.irradiance = state.h;
    debug_assert!(solution.irradiance.iter().all(|h| h.is_finite()));
    let transport = Transport {
        row_start: vec![0; n + 1],
        col: Vec::new(),
        f: Vec::new(),
        escape: vec![0.0; n],
        direct,
        rays,
        rows_carry_emission: false,
    };
    Ok((transport, solution, stats))
}

/// Irradiance per texel and radiosity per node.
struct State<'a> {
    texels: &'a Texels,
    direct: &'a [Vec3],
    emitted: &'a [Vec3],
    /// Per-texel correction of the pushed irradiance ([`Refiner::row_scale`]).
    scale: Vec<f32>,
    h: Vec<Vec3>,
    b: Vec<Vec3>,
}

impl<'a> State<'a> {
    fn new(tree: &Tree, texels: &'a Texels, direct: &'a [Vec3], emitted: &'a [Vec3]) -> Self {
        let mut s = State {
            texels,
            direct,
            emitted,
            scale: vec![1.0; texels.len()],
            h: direct.to_vec(),
            b: vec![Vec3::ZERO; tree.len()],
        };
        s.pull(tree);
        s
    }

    /// `B_i = E_i + ρ_i H_i` at the texels, area-averaged up the tree (children first).
    fn pull(&mut self, tree: &Tree) {
        let n = self.h.len();
        for i in 0..n {
            self.b[i] = self.emitted[i] + self.texels.albedo[i] * self.h[i];
        }
        for k in n..tree.len() {
            let sum = tree.children(k as u32).iter().fold(Vec3::ZERO, |acc, &c| {
                acc + self.b[c as usize] * tree.area[c as usize]
            });
            let a = tree.area[k];
            self.b[k] = if a > 0.0 { sum / a } else { Vec3::ZERO };
        }
    }

    /// Jacobi sweeps of gather, push and pull until the stopping rule of [`crate::solve`].
    fn iterate(
        &mut self,
        tree: &Tree,
        links: &Links,
        params: &SolveParams,
        start: Instant,
        solution: &mut Solution,
        progress: &dyn Progress,
    ) -> Result<bool> {
        let mut gathered = vec![Vec3::ZERO; tree.len()];
        let mut pushed = vec![Vec3::ZERO; tree.len()];
        let mut previous_residual = f32::INFINITY;
        let mut sweeps = 0;
        progress.begin("solve", params.max_iterations as u64);
        let converged = loop {
            if sweeps == params.max_iterations {
                break false;
            }
            if progress.aborted() {
                return Err(Error::Aborted);
            }
            sweeps += 1;
            let b = &self.b;
            gathered
                .par_iter_mut()
                .enumerate()
                .with_min_len(1024)
                .for_each(|(p, g)| {
                    let r = links.start[p] as usize..links.start[p + 1] as usize;
                    *g = links.source[r.clone()]
                        .iter()
                        .zip(&links.f[r])
                        .fold(Vec3::ZERO, |acc, (&q, &f)| acc + b[q as usize] * f);
                });
            // Push: parents have larger ids, so a descending pass sees each parent first.
            for k in (0..tree.len()).rev() {
                let parent = tree.parent[k];
                let above = if parent == u32::MAX {
                    Vec3::ZERO
                } else {
                    pushed[parent as usize]
                };
                pushed[k] = above + gathered[k];
            }
            let (mut change, mut total) = (0.0f64, 0.0f64);
            for (i, h) in self.h.iter_mut().enumerate() {
                let new = self.direct[i] + pushed[i] * self.scale[i];
                change += (new - *h).abs().element_sum() as f64;
                total += new.element_sum() as f64;
                *h = new;
            }
            self.pull(tree);
            let residual = if total > 0.0 {
                (change / total) as f32
            } else {
                0.0
            };
            let ratio = if previous_residual.is_finite() && previous_residual > 0.0 {
                (residual / previous_residual).min(0.999)
            } else {
                0.5
            };
            previous_residual = residual;
            let error_estimate = residual * ratio / (1.0 - ratio);
            solution.history.push(Iteration {
                residual,
                error_estimate,
                seconds: start.elapsed().as_secs_f64(),
            });
            progress.advance(1);
            if !residual.is_finite() {
                return Err(Error::Option(format!(
                    "the hierarchical solver diverged (residual {residual}) after {sweeps} sweeps"
                )));
            }
            if error_estimate < params.tolerance && sweeps >= 2 || residual == 0.0 {
                break true;
            }
        };
        progress.end();
        Ok(converged)
    }
}

/// `H_direct` per texel: light-sampled small emitters, punctual lights, sky; and rays cast.
fn direct_light(
    scene: &Scene,
    texels: &Texels,
    tracer: &Tracer,
    params: &TransportParams,
    emitters: &Emitters,
    progress: &dyn Progress,
) -> Result<(Vec<Vec3>, u64)> {
    let n = texels.len();
    let aborted = AtomicBool::new(false);
    progress.begin("direct light", n as u64);
    let chunks: Vec<(Vec<Vec3>, u64)> = (0..n.div_ceil(CHUNK))
        .into_par_iter()
        .map(|c| {
            let range = c * CHUNK..((c + 1) * CHUNK).min(n);
            let mut out = Vec::with_capacity(range.len());
            let mut rays = 0;
            if aborted.load(Ordering::Relaxed) || progress.aborted() {
                aborted.store(true, Ordering::Relaxed);
                return (out, rays);
            }
            for i in range.clone() {
                let (h, r) = texel_direct(scene, texels, tracer, params, emitters, i);
                out.push(if h.is_finite() {
                    h.max(Vec3::ZERO)
                } else {
                    Vec3::ZERO
                });
                rays += r;
            }
            progress.advance(range.len() as u64);
            (out, rays)
        })
        .collect();
    progress.end();
    if aborted.load(Ordering::Relaxed) {
        return Err(Error::Aborted);
    }
    let rays = chunks.iter().map(|c| c.1).sum();
    Ok((chunks.into_iter().flat_map(|c| c.0).collect(), rays))
}

/// Direct irradiance of texel `i` and the rays it took.
fn texel_direct(
    scene: &Scene,
    texels: &Texels,
    tracer: &Tracer,
    params: &TransportParams,
    emitters: &Emitters,
    i: usize,
) -> (Vec3, u64) {
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
        let (tri, u0) = emitters.pick_stratified(u.x);
        let bary = sample_triangle(Vec2::new(u0, u.y));
        let (y, n_l) = triangle_point(scene, tri, bary);
        let x = footprint_point(texels, tracer, i, rng.next_vec2());
        let to = y - x;
        let r2 = to.length_squared();
        if r2 <= 0.0 {
            continue;
        }
        let dir = to / r2.sqrt();
        let (cos_i, cos_l) = (n.dot(dir), -n_l.dot(dir));
        if cos_i <= 0.0 || cos_l <= 0.0 || tracer.occluded(x, y) {
            continue;
        }
        let le = texels.emission[texels.texel_at(tri, bary) as usize];
        h += le * (cos_i * cos_l / (r2 * emitters.pdf_area[tri as usize]));
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
            let x = footprint_point(texels, tracer, i, u);
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
