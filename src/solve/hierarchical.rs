//! Hierarchical radiosity with clustering (Hanrahan, Salzman & Aupperle 1991; clusters after
//! Smits, Arvo & Greenberg 1994), on lightmap texels.
//!
//! Per colour channel, for every node `p` of a quadtree over each page's texel grid
//! (see `transport/hierarchical/tree.rs`), and for every texel `i` with ancestors `a ∋ i`:
//!
//! ```text
//!   G_p = Σ_{links p←q} F_pq · B_q                 gathered at the level of the link
//!   H_i = H_direct,i + Σ_{a ∋ i} G_a               push: irradiance flows down unchanged
//!   B_i = E_i + ρ_i H_i,   B_p = Σ_c A_c B_c / A_p  pull: area-averaged radiosity flows up
//! ```
//!
//! Links (which node pairs exchange light, refined by the oracle) and the per-texel row
//! correction are built in [`crate::transport::hierarchical`]; this file iterates them. Links
//! are built once from direct light (plus the mean radiosity as an ambient guess, with a 4×
//! coarser ε), the system is solved, and the links are rebuilt from the solved `B` and solved
//! again, each time by Jacobi sweeps of gather, push and pull until the stopping rule of
//! [`crate::solve`].
//!
//! Measured (2 shared cores under load; `examples/dev/hierarchical_diagnose.rs`,
//! `examples/dev/hierarchical_compare.rs`), before → after the per-texel row correction, the exact footprints
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
//! | parameter        | default (medium) | effect                                                 |
//! |------------------|------------------|--------------------------------------------------------|
//! | `gather_rays` K  | 256              | η = 1/√K: links ∝ 1/η, error ∝ η                        |
//! | `light_samples`  | 64               | shadow rays per texel to small emitters                 |
//! | `links::KERNEL_SAMPLES` | 16      | kernel samples per link (no rays)                       |
//! | `links::SAMPLES` | 4              | shadow rays per accepted link                           |
//! | `tolerance`      | 1e-4             | stopping rule as in [`crate::solve`]                    |
//!
//! When to use: large scenes and dense lightmaps, where rows of K entries per texel do not fit
//! or take too long: links grow about linearly with texels. Limits: irradiance is constant
//! over a link's receiver node before the push, so coarse links show as soft blocks of size
//! ε allows; visibility of a link is sampled by 4 rays, so partly occluded links are noisy
//! until refined; the near field is refined down to texels, where form factors are exact
//! (Lambert's formula) but visibility is still sampled.

use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;

use super::{Solution, Stopping};
use crate::config::{SolveParams, TransportParams};
use crate::lights::Emitters;
use crate::texels::Texels;
use crate::transport::hierarchical::{self, Hierarchy, links::Links, tree::Tree};
use crate::transport::{Surfaces, Transport};
use crate::{Progress, Result};

/// Statistics of a hierarchical solve (links of the final refinement).
#[derive(Clone, Copy, Debug, Default)]
pub struct Stats {
    /// Nodes of the hierarchy (texels included).
    pub nodes: usize,
    /// Links of the final refinement.
    pub links: usize,
}

/// Builds the link hierarchy and solves it; the returned `Transport` holds `direct` and `rays`
/// (no texel rows).
pub(crate) fn solve(
    surfaces: Surfaces,
    params: &TransportParams,
    solve: &SolveParams,
    progress: &dyn Progress,
) -> Result<(Transport, Solution)> {
    solve_with_stats(surfaces, params, solve, progress).map(|(t, s, _)| (t, s))
}

/// `solve`, also returning node and link counts (for benchmarks and tests).
pub fn solve_with_stats(
    surfaces: Surfaces,
    params: &TransportParams,
    solve: &SolveParams,
    progress: &dyn Progress,
) -> Result<(Transport, Solution, Stats)> {
    let texels = surfaces.texels;
    let emitters = Emitters::new(surfaces.scene, texels);
    let mut transport = hierarchical::direct_light(surfaces, params, &emitters, progress)?;
    let emitted = hierarchical::carried_emission(texels, &emitters);
    let hierarchy = Hierarchy::new(surfaces);
    let tree = &hierarchy.tree;
    let mut state = State::new(tree, texels, &transport.direct, &emitted);
    let start = Instant::now();
    let mut solution = Solution::default();
    let mut stats = Stats {
        nodes: tree.len(),
        links: 0,
    };
    for pass in 0..2 {
        let (links, scale) = hierarchy.link(surfaces, &state.b, pass, params, progress)?;
        transport.rays += links.rays;
        stats.links = links.len();
        state.scale = scale;
        solution.converged = state.iterate(tree, &links, solve, start, &mut solution, progress)?;
    }
    solution.irradiance = state.h;
    debug_assert!(solution.irradiance.iter().all(|h| h.is_finite()));
    Ok((transport, solution, stats))
}

/// Irradiance per texel and radiosity per node.
struct State<'a> {
    texels: &'a Texels,
    direct: &'a [Vec3],
    emitted: &'a [Vec3],
    /// Per-texel correction of the pushed irradiance (`links::Refiner::row_scale`).
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

    /// Jacobi sweeps of gather, push and pull until the stopping rule of [`crate::solve`]; true
    /// when it converged.
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
        let history = &mut solution.history;
        let mut stopping =
            Stopping::begin(("hierarchical", "sweeps"), params, history, start, progress);
        let mut converged = false;
        while stopping.next()? {
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
            if stopping.sweep(change, total)? {
                converged = true;
                break;
            }
        }
        stopping.end();
        Ok(converged)
    }
}
