//! Light probes: the bake's light at points in empty space, for what moves through the scene
//! (characters, props placed at run time), as L2 spherical harmonics of the incident radiance on
//! a regular grid with its cells divided where light changes (or at positions a node of the
//! scene gives).
//!
//! ## Pipeline stage
//!
//! Plain data in, plain data out, after the solve (`bake::finish`):
//!
//! ```text
//!   Scene + Tracer ─ place::place ──▶ Placement      grid positions, buried ones marked
//!   + Texels + solved H ─ gather ───▶ grid probes     9 RGB SH coefficients per probe
//!                     ─ refine ─────▶ Probes          cells where light changes divided,
//!                                                     their added probes gathered
//!                     ─ file ───────▶ <stem>_probes.json, named in the glTF's root extras
//!                     ─ volume ─────▶ <stem>_probes.ktx2, Bevy's irradiance volume (grids)
//! ```
//!
//! **Placement** (`place.rs`): a regular grid spanning the scene's free space (found by a sketch
//! grid: how far free probes see along the axes), its outermost probes a fifth of a spacing
//! from the walls, at the spacing three quarters of the budget allow (`--probes N`; without a
//! number the budget follows the bake, [`ProbeParams::budget_for`]: the probes whose rays are
//! [`RAY_SHARE`] of the bake's, from [`DEFAULT_BUDGET`] to [`MAX_FOLLOWING_BUDGET`], as the
//! error between probes falls with their spacing and a bake that casts more rays affords more
//! probes at the same share of its time; [`ProbeParams::refine`] keeps the rest for
//! refinement), or where a node
//! of the scene says
//! (`--probes-from NODE`: its children's positions, or a grid filling its box, the unit cube
//! under its transform, in the box's axes); probes buried in solids (or outside an
//! interior's closed shell) are marked invalid, probes too close to a surface are moved off it.
//! The grid stays regular because every engine can read it without a mesh or a tree (Bevy's
//! irradiance volume, Godot's and three.js's probe grids are regular) and its lookup is a few
//! lines of trilinear weights.
//!
//! **Refinement** ([`refine`]): between probes the error is mostly that of interpolating the
//! true light, not the probes' own, and it gathers where light changes within a spacing (beside
//! emitters): a denser uniform grid spends its probes where light is even. So after the grid's
//! probes are gathered, the cells whose corners disagree most (the spread of `E/π` at the six
//! axis normals) are divided in two along each axis, best first, while their added probes fit
//! in a pass's share of the rest of the budget; the added probes are gathered, and the next pass
//! scores the cells again, the new sub-cells among them, down to [`ProbeParams::levels`] levels.
//! Nodes on a face or edge of a coarser undivided cell take that cell's interpolated value (they
//! are not gathered), so the lookup does not jump at the boundary. The grid's entries come first
//! in every list; Bevy's volume is the grid alone.
//!
//! **Gathering** (`Gatherer::gather`): per probe, up to `rays` directions over the sphere in four
//! quarters, each a stratified set (Hammersley, turned by the probe's own random stream
//! `(seed, probe)`: the result does not depend on the thread count). Every probe casts two
//! quarters; only a probe whose two disagree by more than [`NOISY`] of the light's scale (the
//! mean light of the grid's probes) casts the other two: where light is smooth half the rays
//! leave a probe's own noise far below the error of interpolating between probes, and beside
//! emitters they do not. A ray that hits texel `j` from the front reads the solved
//! radiance leaving it, `ρ_j·H_j/π + Le_j` (the solution itself, not the dilated pages); one
//! that escapes reads the sky; the back of a single-sided surface absorbs. Small emitters are
//! also light-sampled, one sample per ray, combined with the sphere rays by the power heuristic
//! (as the directional gather and the reference do); punctual lights add their unoccluded flux
//! density along their direction, unless `indirect_only` (engines that light characters with
//! the same lights at run time). Emitted and sky light reaching the probe directly stays in
//! either way: no engine renders it at run time. Each sample is projected onto the SH basis
//! ([`sh`]). Invalid probes are then filled from valid neighbours ring by ring, so a renderer
//! that ignores the validity flags still reads plausible light.
//!
//! **Lookup** ([`Probes::sh_at`], [`Probes::irradiance_over_pi`]): trilinear weights of the
//! eight probes around the point (the corners of the smallest cell holding it: from the grid
//! cell, into the sub-cell holding the point while the cell is divided),
//! invalid probes and probes the point cannot see (a shadow ray
//! from the point to the probe; only when a [`Tracer`] is given) dropped and the rest
//! renormalised; with none left, inverse-square weights of the visible valid probes in the
//! 4 × 4 × 4 block around it, then the nearest valid probe. Beyond the grid's outermost probes
//! (the slab between them and the walls) the outer cell's light is continued linearly, up to
//! [`BEYOND`] of a spacing out. The visibility test is what keeps
//! light from leaking through a wall thinner than the spacing; an engine without ray queries
//! can precompute it per cell or accept the leak near walls. Probes placed one by one
//! (`--probes-from` a node's children) have no cells: the eight nearest valid probes the point
//! sees are blended by inverse squared distance (Shepard's weights, exact at a probe), else the
//! nearest valid probe. `lightbake probes --at`, `render`, the viewer and the tests read probes
//! through this one function.
//!
//! Units: coefficients are of incident radiance (W/(sr·m²)), so irradiance over π from them is
//! in the lightmaps' unit `H/π` (see [`sh`] for the convolution and three.js's convention).
//!
//! | parameter       | default | effect                                                        |
//! |-----------------|---------|---------------------------------------------------------------|
//! | `budget`        | follows the bake | probes at most; spacing `∛(bounds volume / budget)`; `None`: 10% of the bake's rays, 1024 to 8192 |
//! | `rays`          | 256     | sphere rays per probe at most (+ as many emitter samples); noise ∝ 1/√rays |
//! | `noisy`         | 0.04    | half the rays where their noise is below this share of the mean light; 0: all rays everywhere |
//! | `indirect_only` | false   | leave out punctual lights' direct light                       |
//! | `from`          | none    | a node's children or box instead of the automatic grid        |
//! | `refine`        | 0.25    | share of the budget kept for refining cells; 0: a uniform grid of the whole budget |
//! | `levels`        | 3       | levels of division (each halves the spacing); 1: grid cells halved once |
//!
//! Limits: a probe inside a closed
//! double-sided mesh is not found buried; trilinear interpolation still blurs light that
//! changes faster than the finer spacing (within centimetres of an emitter, above all beside an
//! emitter's edge in its own plane); points between the outermost probes and the walls (a fifth
//! of a spacing) read the outer cells' light continued, not probes there.
//! [`measure`] says how the probes are measured against the path tracer.

pub mod file;
pub mod measure;
mod place;
pub mod refine;
pub mod sh;
pub mod volume;

use std::f32::consts::PI;

use std::path::Path;

use glam::{Quat, Vec3};
use rayon::prelude::*;

use crate::lights::{Emitters, punctual_irradiance, triangle_point};
use crate::sampling::{Rng, hammersley, power_weight, uniform_sphere};
use crate::scene::LightKind;
use crate::texels::RayEnd;
use crate::trace::Tracer;
use crate::transport::Surfaces;
use crate::{Error, Progress, Result};
use place::Placement;
pub use refine::Refinement;
pub use sh::Sh2;

/// The least budget when `--probes` gives no number ([`ProbeParams::budget_for`]).
pub const DEFAULT_BUDGET: u32 = 1024;
/// With no number given, the budget rises to the probes whose rays are at most this share of
/// the bake's own rays: the probes' error between them falls with their spacing (the
/// furnished interior at `medium`, over all free-space points: 62.7% at 1024, 42.1% at 4800,
/// 23.9% at 8192), and a bake that spends more rays on its lightmaps can afford them at the
/// same share of its time (the probe stage was 5.0% of the interior's `medium` bake, 1.2% of
/// its `high` one, where the cap holds).
pub const RAY_SHARE: f64 = 0.1;
/// The most probes a budget that follows the bake rises to (a JSON file of about 3 MB).
pub const MAX_FOLLOWING_BUDGET: u32 = 8192;
/// Sphere rays per probe.
pub const DEFAULT_RAYS: u32 = 256;
/// Share of the budget kept for refining cells where light changes.
pub const DEFAULT_REFINE: f32 = 0.25;
/// Levels of division refinement may use.
pub const DEFAULT_LEVELS: u32 = 3;
/// Probes per parallel work item.
const CHUNK: usize = 16;
/// A probe's rays come in this many stratified sets ([`Gatherer::gather`]); every probe casts
/// the first two.
const QUARTERS: u32 = 4;
/// A probe whose first two quarters differ by more than this share of the light's scale (half
/// their RMS difference over the six axis normals: the noise of their mean) casts the other
/// two. Where light is smooth half the rays suffice; beside emitters it is not.
pub const NOISY: f32 = 0.04;
/// Mixed into the seed: the probes' streams differ from the texels' of the same index.
const SALT: u64 = 0x5052_4f42_4553; // "PROBES"
/// Random-stream purpose of the gather (placement uses its own).
const GATHER: u64 = 2;
/// How far beyond the grid's outermost probes, in spacings along each axis, the lookup
/// continues the outer cells' light linearly (the slab by the walls is a fifth of a spacing;
/// half a spacing keeps the point it reads inside the outer cell).
pub const BEYOND: f32 = 0.5;

/// How probes are placed and baked.
#[derive(Clone, Debug, PartialEq)]
pub struct ProbeParams {
    /// Probes at most; `None`: the budget follows the bake ([`ProbeParams::budget_for`]).
    pub budget: Option<u32>,
    /// Sphere rays per probe.
    pub rays: u32,
    /// Leave out punctual lights' direct light.
    pub indirect_only: bool,
    /// Place the probes from the scene's node of this name instead of the automatic grid: at
    /// its children's world positions, or, without children, on a grid within the budget
    /// filling its box (the unit cube centred on the node, side 1, under its transform).
    pub from: Option<String>,
    /// Share of the budget kept for refining grid cells where light changes ([`refine`]); the
    /// grid takes the rest. 0: a uniform grid of the whole budget.
    pub refine: f32,
    /// Levels of division refinement may use (1: grid cells halved once; at most
    /// [`refine::MAX_LEVELS`]).
    pub levels: u32,
    /// A probe casts the second half of its rays only where the first half's noise is above
    /// this share of the light's scale ([`NOISY`]); 0: every probe casts all its rays.
    pub noisy: f32,
}

impl ProbeParams {
    /// The budget for a bake that cast `bake_rays` rays: the one given, or the probes whose
    /// rays (sphere rays and as many light samples, at most) are [`RAY_SHARE`] of the bake's,
    /// within [`DEFAULT_BUDGET`]..=[`MAX_FOLLOWING_BUDGET`]. The bake's ray count does not
    /// depend on the thread count, so neither does the budget.
    #[must_use]
    pub fn budget_for(&self, bake_rays: u64) -> u32 {
        self.budget.unwrap_or_else(|| {
            let per_probe = 2.0 * f64::from(self.rays.max(1));
            let afforded = (RAY_SHARE * bake_rays as f64 / per_probe) as u32;
            afforded.clamp(DEFAULT_BUDGET, MAX_FOLLOWING_BUDGET)
        })
    }

    /// The budget given, or the least one ([`DEFAULT_BUDGET`]) before the bake's rays are known.
    fn budget(&self) -> u32 {
        self.budget.unwrap_or(DEFAULT_BUDGET)
    }

    /// Probes the grid may take: the budget less the share kept for refinement (at least one).
    #[must_use]
    pub fn grid_budget(&self) -> u32 {
        let budget = self.budget();
        let kept = (budget as f32 * self.refine.clamp(0.0, 1.0)).floor() as u32;
        budget.saturating_sub(kept).max(1)
    }
}

impl Default for ProbeParams {
    fn default() -> Self {
        ProbeParams {
            budget: None,
            rays: DEFAULT_RAYS,
            indirect_only: false,
            from: None,
            refine: DEFAULT_REFINE,
            levels: DEFAULT_LEVELS,
            noisy: NOISY,
        }
    }
}

/// A regular grid of probes: probe `(i, j, k)` lies at `origin + rotation·(step ⊙ (i, j, k))`
/// and is entry `i + nx·(j + ny·k)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Grid {
    /// Grid position of probe (0, 0, 0) (world space).
    pub origin: Vec3,
    /// Distance between neighbouring grid positions along the grid's x, y, z.
    pub step: Vec3,
    /// Probes along x, y, z.
    pub count: [u32; 3],
    /// The grid's axes in the world: identity for the automatic grid, a box node's rotation
    /// for `--probes-from`.
    pub rotation: Quat,
}

impl Grid {
    /// World grid position of probe `(i, j, k)`.
    #[inline]
    #[must_use]
    pub fn position(&self, ijk: [u32; 3]) -> Vec3 {
        self.origin + self.rotation * (self.step * Vec3::from(ijk.map(|c| c as f32)))
    }

    /// `p` in grid coordinates: probe `(i, j, k)` is at `(i, j, k)`.
    #[inline]
    #[must_use]
    pub fn local(&self, p: Vec3) -> Vec3 {
        (self.rotation.inverse() * (p - self.origin)) / self.step
    }

    /// Probes on the grid.
    #[must_use]
    pub fn len(&self) -> usize {
        self.count.iter().map(|&c| c as usize).product()
    }

    /// A grid of no probes.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Flat index of grid probe (i, j, k).
    #[inline]
    pub(crate) fn index(&self, [i, j, k]: [u32; 3]) -> usize {
        let [nx, ny, _] = self.count;
        (i + nx * (j + ny * k)) as usize
    }
}

/// Baked probes: on a regular [`Grid`], or placed one by one (an empty node's children,
/// `--probes-from`).
#[derive(Clone, Debug, PartialEq)]
pub struct Probes {
    /// The grid the probes are on, entry by entry; `None` for probes placed one by one.
    pub grid: Option<Grid>,
    /// Cells divided where light changes, level by level; their added probes follow the grid's
    /// entries.
    pub refinement: Refinement,
    /// Where each probe was baked: its grid (or given) position, or moved off a nearby surface
    /// (by at most four fifths of the clearance's step: up to four moves of at most a fifth).
    pub position: Vec<Vec3>,
    /// False for probes buried in geometry (their coefficients are filled from neighbours).
    pub valid: Vec<bool>,
    /// Radiance SH coefficients per probe ([`sh`]).
    pub sh: Vec<Sh2>,
    /// Punctual lights' direct light left out.
    pub indirect_only: bool,
    /// Rays cast by placement and gathering.
    pub rays: u64,
    /// Probes moved away from a surface.
    pub moved: usize,
    /// The budget they were placed within (0 for probes read from a file).
    pub budget: u32,
}

impl Probes {
    /// Probes held.
    pub fn len(&self) -> usize {
        self.position.len()
    }

    /// No probes.
    pub fn is_empty(&self) -> bool {
        self.position.is_empty()
    }

    /// Valid probes.
    pub fn valid_count(&self) -> usize {
        self.valid.iter().filter(|&&v| v).count()
    }

    /// Per probe, whether it holds light gathered at its position: valid, and not an added
    /// probe constrained to its coarse cell's interpolated value ([`refine`]).
    #[must_use]
    pub fn gathered(&self) -> Vec<bool> {
        let mut gathered = self.valid.clone();
        if let (Some(grid), false) = (&self.grid, self.refinement.is_empty()) {
            for (k, c) in refine::constrained(grid, &self.refinement)
                .into_iter()
                .enumerate()
            {
                if let Some(g) = gathered.get_mut(grid.len() + k) {
                    *g &= !c;
                }
            }
        }
        gathered
    }

    /// The interpolated coefficients at `p` (see the module docs); `visible(q)` says whether
    /// the point sees a probe at `q` (always true without ray queries).
    pub fn sh_at(&self, p: Vec3, visible: impl FnMut(Vec3) -> bool) -> Sh2 {
        let mut sum = [Vec3::ZERO; 9];
        self.weights_at(p, visible, |q, w| {
            sum = sh::add(&sum, &sh::scaled(&self.sh[q], w));
        });
        sum
    }

    /// The probes [`Probes::sh_at`] blends at `p` and their weights, `emit(q, w)` once per
    /// probe and part (a probe may come twice: the slab's continuation weighs the outer cell's
    /// probes twice and subtracts those a step in). The lookup is `Σ w·sh[q]`, linear in the
    /// probes' coefficients: a tool can precompute it, or fit the coefficients to light
    /// gathered between probes (the `probe_fit` experiment; the guide's light-probe page).
    /// Nothing is emitted when there are no probes.
    pub fn weights_at(
        &self,
        p: Vec3,
        visible: impl FnMut(Vec3) -> bool,
        emit: impl FnMut(usize, f32),
    ) {
        if self.is_empty() {
            return;
        }
        match &self.grid {
            Some(grid) => self.weights_on_grid(grid, p, visible, emit),
            None => self.weights_from_nearest(p, visible, emit),
        }
    }

    /// [`Probes::weights_at`] on a grid: inside the box of the grid's positions, the cell's (or
    /// sub-cell's) corners; beyond a face of that box — the slab between the outermost probes
    /// and the walls — the outer cell's light continued linearly, `2·v(x) − v(x − d)` for `x`
    /// the nearest point of the box and `d` the step out (at most [`BEYOND`] of a spacing along
    /// each axis, the value held farther out).
    fn weights_on_grid(
        &self,
        grid: &Grid,
        p: Vec3,
        mut visible: impl FnMut(Vec3) -> bool,
        mut emit: impl FnMut(usize, f32),
    ) {
        let g = grid.local(p);
        let last = Vec3::from(grid.count.map(|c| c.saturating_sub(1) as f32));
        let x = g.clamp(Vec3::ZERO, last);
        let d = (g - x).clamp(Vec3::splat(-BEYOND), Vec3::splat(BEYOND));
        if d == Vec3::ZERO {
            return self.weights_in_box(grid, p, visible, emit);
        }
        // Holding the face's value instead left the slab reading light from a fifth of a
        // spacing in, where it is weaker beside an emitter and differs beside a wall.
        let world = |l: Vec3| grid.origin + grid.rotation * (grid.step * l);
        self.weights_in_box(grid, world(x), &mut visible, |q, w| emit(q, 2.0 * w));
        let inner = (x - d).clamp(Vec3::ZERO, last);
        self.weights_in_box(grid, world(inner), &mut visible, |q, w| emit(q, -w));
    }

    /// [`Probes::weights_on_grid`] at a point `p` of the box of the grid's positions (held on
    /// its faces beyond).
    fn weights_in_box(
        &self,
        grid: &Grid,
        p: Vec3,
        mut visible: impl FnMut(Vec3) -> bool,
        mut emit: impl FnMut(usize, f32),
    ) {
        let g = grid.local(p);
        let mut base = [0u32; 3];
        let mut x = Vec3::ZERO;
        for a in 0..3 {
            let last = grid.count[a].saturating_sub(1) as f32;
            x[a] = g[a].clamp(0.0, last);
            base[a] = (x[a].floor() as u32).min(grid.count[a].saturating_sub(2));
        }
        // Trilinear over the corners of the cell, or of its sub-cell where it is refined, that
        // are valid and visible.
        let mut corners = self.corners(grid, base, x);
        let mut total = 0.0f32;
        for (q, w) in &mut corners {
            if *w > 0.0 && self.valid[*q] && visible(self.position[*q]) {
                total += *w;
            } else {
                *w = 0.0;
            }
        }
        if total > 1e-6 {
            for (q, w) in corners {
                if w > 0.0 {
                    emit(q, w / total);
                }
            }
            return;
        }
        // None of the cell's corners: the visible valid probes of the 4 × 4 × 4 block around it.
        let mut block = [(0usize, 0.0f32); 64];
        let (mut taken, mut total) = (0, 0.0f32);
        for dk in -1..=2i64 {
            for dj in -1..=2i64 {
                for di in -1..=2i64 {
                    let ijk = [di, dj, dk];
                    let mut at = [0u32; 3];
                    let mut inside = true;
                    for a in 0..3 {
                        let c = base[a] as i64 + ijk[a];
                        inside &= c >= 0 && c < grid.count[a] as i64;
                        at[a] = c.max(0) as u32;
                    }
                    if !inside {
                        continue;
                    }
                    let q = grid.index(at);
                    if self.valid[q] && visible(self.position[q]) {
                        let w = 1.0 / (self.position[q] - p).length_squared().max(1e-8);
                        block[taken] = (q, w);
                        taken += 1;
                        total += w;
                    }
                }
            }
        }
        if total > 0.0 {
            for &(q, w) in &block[..taken] {
                emit(q, w / total);
            }
        } else if let Some(q) = self.nearest_valid(p) {
            emit(q, 1.0);
        }
    }

    /// The probes around grid coordinates `x` (clamped to the grid) in the cell at `base` and
    /// their trilinear weights: the cell's corners, or those of its sub-cell where the cell is
    /// refined. An axis of one probe has weight 0 on its upper side.
    fn corners(&self, grid: &Grid, base: [u32; 3], x: Vec3) -> [(usize, f32); 8] {
        let flat = |ijk: [u32; 3], w: f32| {
            let ijk: [u32; 3] = std::array::from_fn(|a| ijk[a].min(grid.count[a] - 1));
            (grid.index(ijk), w)
        };
        let coarse = refine::trilinear(base, x).map(|(ijk, w)| flat(ijk, w));
        if self.refinement.is_empty() {
            return coarse;
        }
        match self.refinement.leaf(base, x) {
            (0, _) => coarse,
            // A divided cell lacking a node (not from a bake): the grid cell's own corners.
            leaf => self.refinement.corners(grid, leaf, x).unwrap_or(coarse),
        }
    }

    /// [`Probes::weights_at`] for probes placed one by one: the `NEAREST` nearest valid probes
    /// that `p` sees, by inverse squared distance (Shepard's weights: the value at a probe is
    /// its own), else the nearest valid probe.
    fn weights_from_nearest(
        &self,
        p: Vec3,
        mut visible: impl FnMut(Vec3) -> bool,
        mut emit: impl FnMut(usize, f32),
    ) {
        /// Probes blended at most.
        const NEAREST: usize = 8;
        let mut by_distance: Vec<(f32, usize)> = (0..self.len())
            .filter(|&q| self.valid[q])
            .map(|q| ((self.position[q] - p).length_squared(), q))
            .collect();
        // Ties by index: the same probes on any machine.
        by_distance.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let mut near = [(0usize, 0.0f32); NEAREST];
        let (mut taken, mut total) = (0, 0.0f32);
        for &(d2, q) in &by_distance {
            if taken == NEAREST {
                break;
            }
            if visible(self.position[q]) {
                if d2 < 1e-12 {
                    return emit(q, 1.0);
                }
                near[taken] = (q, 1.0 / d2);
                total += 1.0 / d2;
                taken += 1;
            }
        }
        if total > 0.0 {
            for &(q, w) in &near[..taken] {
                emit(q, w / total);
            }
        } else if let Some(&(_, q)) = by_distance.first() {
            emit(q, 1.0);
        }
    }

    /// The valid probe nearest to `p` (the lowest index among equals).
    fn nearest_valid(&self, p: Vec3) -> Option<usize> {
        (0..self.len()).filter(|&q| self.valid[q]).min_by(|&a, &b| {
            let da = (self.position[a] - p).length_squared();
            let db = (self.position[b] - p).length_squared();
            da.total_cmp(&db).then(a.cmp(&b))
        })
    }

    /// `n` random points in free space between the probes, each with a random unit normal,
    /// to measure the probes against the path tracer: uniform in the box of the grid
    /// positions (of the probes' positions without a grid), points buried in geometry (the
    /// probes' own test) drawn again. With `whole_cells` (grids only), only points whose eight
    /// cell probes are all valid and visible from them (away from walls and furniture: the
    /// interpolation's own error) are kept. Point `k` comes from its own random stream
    /// `(seed, k)`.
    pub fn points_between(
        &self,
        tracer: &Tracer,
        n: usize,
        seed: u64,
        whole_cells: bool,
    ) -> Vec<(Vec3, Vec3)> {
        // A point of the box from a point of the unit cube.
        let in_box = |u: Vec3| match &self.grid {
            Some(g) => {
                let last = Vec3::from(g.count.map(|c| c.saturating_sub(1) as f32));
                g.origin + g.rotation * (g.step * last * u)
            }
            None => {
                let lo = self
                    .position
                    .iter()
                    .copied()
                    .fold(Vec3::INFINITY, Vec3::min);
                let hi = (self.position.iter().copied()).fold(Vec3::NEG_INFINITY, Vec3::max);
                lo + (hi - lo) * u
            }
        };
        place::free_points(tracer, n, seed ^ SALT, in_box, |p| {
            let (true, Some(grid)) = (whole_cells, &self.grid) else {
                return true;
            };
            let (mut all, mut corners) = (true, 0);
            self.sh_at(p, |q| {
                corners += 1;
                all &= !tracer.occluded(p, q);
                true
            });
            all && corners == 1 << grid.count.iter().filter(|&&c| c > 1).count()
        })
    }

    /// `E/π` at `p` about unit normal `n` from the interpolated coefficients, in the lightmaps'
    /// unit; with a `tracer`, probes that `p` (lifted by the ray offset along `n`) cannot see
    /// are left out.
    pub fn irradiance_over_pi(&self, p: Vec3, n: Vec3, tracer: Option<&Tracer>) -> Vec3 {
        let c = match tracer {
            Some(t) => {
                let from = p + n * t.epsilon;
                self.sh_at(p, |q| !t.occluded(from, q))
            }
            None => self.sh_at(p, |_| true),
        };
        sh::irradiance_over_pi(&c, n)
    }
}

/// Checks that the probes of `params` can be placed in `scene` (the node of
/// [`ProbeParams::from`] exists, once, with a usable box): before the bake, so a wrong name
/// fails at once. `input` names the glTF in errors.
pub(crate) fn check(scene: &crate::scene::Scene, params: &ProbeParams, input: &Path) -> Result<()> {
    place::start(scene, params, input).map(|_| ())
}

/// Probes for a finished bake, with other parameters than its own (another budget, layout or
/// rays): the light the bake solved is gathered again without baking the lightmaps anew. With
/// the bake's own parameters the probes are the ones it made. `input` is the glTF the bake read
/// (named in errors, e.g. of `from`).
pub fn for_bake(
    baked: &crate::Baked,
    params: &ProbeParams,
    input: &Path,
    progress: &dyn Progress,
) -> Result<Probes> {
    let tracer = Tracer::new(&baked.scene);
    let surfaces = Surfaces {
        scene: &baked.scene,
        texels: &baked.texels,
        tracer: &tracer,
    };
    let transport = &baked.config.transport;
    let bake_rays = crate::bake::lightmap_rays(baked.transport.rays, baked.plan.as_ref());
    let bake_params = (transport.seed, transport.sky, input, bake_rays);
    bake(
        surfaces,
        &baked.solution.irradiance,
        params,
        bake_params,
        progress,
    )
}

/// Places probes (`place::place`) and gathers the solved light at them; `h` is the solved
/// irradiance per texel (`H`, W/m²), `seed` and `sky` the bake's, `input` the glTF (for errors),
/// `bake_rays` the rays the bake cast (a budget that follows the bake reads them).
pub(crate) fn bake(
    surfaces: Surfaces,
    h: &[Vec3],
    params: &ProbeParams,
    (seed, sky, input, bake_rays): (u64, Vec3, &Path, u64),
    progress: &dyn Progress,
) -> Result<Probes> {
    let budget = params.budget_for(bake_rays);
    let params = &ProbeParams {
        budget: Some(budget),
        ..params.clone()
    };
    let start = place::start(surfaces.scene, params, input)?;
    let placement = place::place(surfaces.tracer, start, seed ^ SALT);
    let gatherer = Gatherer {
        surfaces,
        h,
        emitters: Emitters::new(surfaces.scene, surfaces.texels),
        params,
        seed: seed ^ SALT,
        sky,
    };
    let (mut sh, mut rays, scale) =
        gatherer.gather_all(&placement.position, &placement.valid, |i| i, None, progress)?;
    rays += placement.rays;
    fill_invalid(&placement, &mut sh);
    let Placement {
        grid,
        mut position,
        mut valid,
        mut moved,
        ..
    } = placement;
    // Denser where light changes: the grid's probes say where (`refine`).
    let refinement = match grid {
        // With no share kept, the grid alone (whatever of the budget it leaves unused).
        Some(grid) if params.refine > 0.0 => {
            let left = (budget as usize).saturating_sub(grid.len());
            let probes = (&mut position, &mut valid, &mut sh);
            let (refinement, added_rays, added_moved) =
                refine_all(&gatherer, &grid, probes, (left, scale), progress)?;
            rays += added_rays;
            moved += added_moved;
            refinement
        }
        _ => Refinement::default(),
    };
    Ok(Probes {
        grid,
        refinement,
        position,
        valid,
        sh,
        indirect_only: params.indirect_only,
        rays,
        moved,
        budget,
    })
}

/// An added probe while refinement runs.
struct Node {
    /// Where it is baked.
    position: Vec3,
    /// Not buried.
    placed: bool,
    /// Its gathered light, once gathered.
    sh: Option<Sh2>,
    /// Its random streams' index.
    stream: usize,
}

/// Refines `grid` in passes, one per level (`refine`): each pass divides the cells whose
/// corners disagree most while their new nodes fit in its share of `budget`, places the new
/// nodes and gathers those no coarser cell constrains; constrained and buried nodes are filled
/// from the cells they hang on. `probes` holds the grid's probes on entry and all of them on
/// return. Returns the refinement, the rays cast and the nodes moved off surfaces.
fn refine_all(
    gatherer: &Gatherer,
    grid: &Grid,
    (position, valid, sh): (&mut Vec<Vec3>, &mut Vec<bool>, &mut Vec<Sh2>),
    (budget, scale): (usize, f32),
    progress: &dyn Progress,
) -> Result<(Refinement, u64, usize)> {
    let params = gatherer.params;
    let tracer = gatherer.surfaces.tracer;
    let n = grid.len();
    let levels = params.levels.clamp(1, refine::MAX_LEVELS);
    let Some(mut builder) = refine::Builder::new(grid, levels, (&valid[..], &sh[..])) else {
        return Ok((Refinement::default(), 0, 0));
    };
    let mut nodes: std::collections::BTreeMap<(u32, u32, u32), Node> = Default::default();
    let key = |c: &[u32; 3]| (c[2], c[1], c[0]);
    let (mut left, mut rays, mut moved, mut streams) = (budget, 0u64, 0usize, n);
    // The probes as they stand: the grid's, then the nodes in order, the ungathered filled.
    let assemble =
        |refinement: &Refinement,
         nodes: &std::collections::BTreeMap<(u32, u32, u32), Node>,
         (position, valid, sh): (&mut Vec<Vec3>, &mut Vec<bool>, &mut Vec<Sh2>)| {
            position.truncate(n);
            valid.truncate(n);
            sh.truncate(n);
            for node in nodes.values() {
                position.push(node.position);
                valid.push(node.placed);
                sh.push(node.sh.unwrap_or([Vec3::ZERO; 9]));
            }
            let ungathered: Vec<bool> = nodes.values().map(|v| v.sh.is_none()).collect();
            let probes = (&position[..], &mut valid[..], &mut sh[..]);
            refine::fill(grid, refinement, probes, &ungathered, |a, b| {
                !tracer.occluded(a, b)
            });
        };
    for pass in 0..levels {
        assemble(builder.refinement(), &nodes, (position, valid, sh));
        let share = match pass + 1 == levels {
            true => left,
            false => (left as f32 * refine::PASS_SHARE) as usize,
        };
        let cells = builder.choose((&valid[..], &sh[..]), share);
        if cells.is_empty() {
            continue;
        }
        let added = builder.divide(&cells);
        left = left.saturating_sub(added.len());
        // Placed as the grid's probes are, a fifth of their own level's step from surfaces.
        let at: Vec<Vec3> = added.iter().map(|&c| builder.position(c)).collect();
        let clearance: Vec<f32> = (added.iter())
            .map(|&c| {
                let step =
                    grid.step.min_element() / refine::FACTOR.pow(builder.node_level(c)) as f32;
                place::CLEARANCE * step
            })
            .collect();
        let settled = place::settle_all(tracer, &at, &clearance, gatherer.seed, streams);
        rays += settled.rays;
        moved += settled.moved;
        for (k, c) in added.iter().enumerate() {
            let node = Node {
                position: settled.position[k],
                placed: settled.valid[k],
                sh: None,
                stream: streams + k,
            };
            nodes.insert(key(c), node);
        }
        streams += added.len();
        // Gathered: every placed node no coarser leaf constrains that holds no light yet.
        let constrained = refine::constrained(grid, builder.refinement());
        let todo: Vec<(u32, u32, u32)> = (nodes.iter().zip(&constrained))
            .filter(|((_, v), c)| v.placed && !**c && v.sh.is_none())
            .map(|((k, _), _)| *k)
            .collect();
        let at: Vec<Vec3> = todo.iter().map(|k| nodes[k].position).collect();
        let stream: Vec<usize> = todo.iter().map(|k| nodes[k].stream).collect();
        let every = vec![true; at.len()];
        let (got, gathered_rays, _) =
            gatherer.gather_all(&at, &every, |i| stream[i], Some(scale), progress)?;
        rays += gathered_rays;
        for (k, c) in todo.iter().zip(got) {
            nodes.get_mut(k).expect("a node").sh = Some(c);
        }
    }
    let refinement = builder.finish();
    assemble(&refinement, &nodes, (position, valid, sh));
    Ok((refinement, rays, moved))
}

/// The gather of incident radiance at probes.
struct Gatherer<'a> {
    surfaces: Surfaces<'a>,
    h: &'a [Vec3],
    emitters: Emitters,
    params: &'a ProbeParams,
    seed: u64,
    sky: Vec3,
}

impl Gatherer<'_> {
    /// Gathers the probes at `positions` that `gather` marks (`stream(i)` the random stream of
    /// entry `i`), in parallel chunks, in two rounds: every probe's first two quarters of its
    /// rays, then the last two quarters of the probes whose first two disagree by more than
    /// [`NOISY`] of `scale` (the light's scale: the mean over these probes when `None`).
    /// Returns their coefficients (zero where not gathered), the rays cast and the scale.
    fn gather_all(
        &self,
        positions: &[Vec3],
        gather: &[bool],
        stream: impl Fn(usize) -> usize + Sync,
        scale: Option<f32>,
        progress: &dyn Progress,
    ) -> Result<(Vec<Sh2>, u64, f32)> {
        let n = positions.len();
        // One tick per probe and round.
        progress.begin("probes", 2 * n as u64);
        let each = |todo: &[bool], quarters: [u32; 2]| -> Result<Vec<(Sh2, Sh2, u64)>> {
            let mut out = vec![([Vec3::ZERO; 9], [Vec3::ZERO; 9], 0u64); n];
            out.par_chunks_mut(CHUNK)
                .enumerate()
                .try_for_each(|(c, chunk)| {
                    if progress.aborted() {
                        return Err(Error::Aborted);
                    }
                    for (k, (a, b, rays)) in chunk.iter_mut().enumerate() {
                        let i = c * CHUNK + k;
                        if todo[i] {
                            *rays = self.gather(stream(i), positions[i], quarters[0], a)
                                + self.gather(stream(i), positions[i], quarters[1], b);
                        }
                    }
                    progress.advance(chunk.len() as u64);
                    Ok(())
                })?;
            Ok(out)
        };
        let first = each(gather, [0, 1])?;
        // Each gathered probe's two quarters at the six axis normals (the ambient cube's sides).
        let grey =
            |c: &Sh2| volume::SIDES.map(|n| sh::irradiance_over_pi(c, n).element_sum() / 3.0);
        let sides: Vec<Option<[[f32; 6]; 2]>> = (first.iter().zip(gather))
            .map(|((a, b, _), &g)| g.then(|| [grey(a), grey(b)]))
            .collect();
        // The light's scale: the mean over these probes and the six sides (summed in order, so
        // the same on any thread count).
        let scale = scale.unwrap_or_else(|| {
            let gathered = sides.iter().flatten().count().max(1);
            let sum: f64 = (sides.iter().flatten())
                .map(|[a, b]| (0..6).map(|k| f64::from(a[k] + b[k]) / 12.0).sum::<f64>())
                .sum();
            (sum / gathered as f64) as f32
        });
        // The noise of the two quarters' mean is half their difference (RMS over the sides).
        let noisy: Vec<bool> = (sides.iter())
            .map(|s| {
                s.is_some_and(|[a, b]| {
                    let square = (0..6).map(|k| (a[k] - b[k]).powi(2)).sum::<f32>() / 6.0;
                    square.sqrt() / 2.0 >= self.params.noisy * scale
                })
            })
            .collect();
        let second = each(&noisy, [2, 3])?;
        progress.end();
        let mut rays = 0;
        let sh = (first.into_iter().zip(second).zip(&noisy))
            .map(|(((a, b, r1), (c, d, r2)), &more)| {
                rays += r1 + r2;
                let half = sh::add(&a, &b);
                match more {
                    false => sh::scaled(&half, 0.5),
                    true => sh::scaled(&sh::add(&half, &sh::add(&c, &d)), 0.25),
                }
            })
            .collect();
        Ok((sh, rays, scale))
    }

    /// Projects the incident radiance at `x` (probe `i`) into `c` from quarter `q` of its rays
    /// (a stratified set of `rays / 4` directions turned by the quarter's own shift, and as many
    /// light samples), as an estimate of the whole; returns the rays cast.
    fn gather(&self, i: usize, x: Vec3, q: u32, c: &mut Sh2) -> u64 {
        let Surfaces {
            scene,
            texels,
            tracer,
        } = self.surfaces;
        let k = self.params.rays.div_ceil(QUARTERS).max(1);
        let kf = k as f32;
        let mut rng = Rng::new(self.seed, i as u64, GATHER);
        for _ in 0..q {
            rng.next_vec2();
            rng.next_vec2();
        }
        let (shift, light_shift) = (rng.next_vec2(), rng.next_vec2());
        // Uniform over the sphere: every direction matters for the projection.
        let p_sphere = 1.0 / (4.0 * PI);
        let mut rays = 0u64;
        for s in 0..k {
            let dir = uniform_sphere(hammersley(s, k, shift));
            rays += 1;
            match texels.ray_end(tracer, x, dir) {
                RayEnd::Escaped => sh::project(c, dir, self.sky / (p_sphere * kf)),
                RayEnd::Texel(hit, j) => {
                    let j = j as usize;
                    let mut l = texels.albedo[j] * self.h[j] / PI / p_sphere;
                    let le = texels.emission[j];
                    if le.max_element() > 0.0 {
                        let (_, n_l) = triangle_point(scene, hit.triangle, hit.bary);
                        let p_light = self.emitters.pdf_toward(hit.triangle, n_l, dir, hit.t);
                        l += le * power_weight(p_sphere, p_light);
                    }
                    sh::project(c, dir, l / kf);
                }
                RayEnd::Absorbed => {}
            }
            if !self.emitters.is_empty() {
                rays += 1;
                let u = hammersley(s, k, light_shift);
                if let Some((dir, w)) = self.light_sample(x, u, p_sphere) {
                    sh::project(c, dir, w / kf);
                }
            }
        }
        if !self.params.indirect_only {
            for light in &scene.lights {
                let l = match light.kind {
                    LightKind::Directional => -light.direction,
                    _ => (light.position - x).normalize_or_zero(),
                };
                rays += 1;
                // About its own direction the light's irradiance is its flux density.
                sh::project(c, l, punctual_irradiance(light, x, l, tracer));
            }
        }
        rays
    }

    /// One light sample of the small emitters seen from the free point `x` (no surface: every
    /// direction counts): its direction and MIS-weighted radiance over density, or `None` when
    /// the emitter faces away, has no texel or is hidden.
    #[inline]
    fn light_sample(&self, x: Vec3, u: glam::Vec2, p_sphere: f32) -> Option<(Vec3, Vec3)> {
        let Surfaces {
            scene,
            texels,
            tracer,
        } = self.surfaces;
        let s = self
            .emitters
            .sample_from((scene, texels, tracer), x, None, u)?;
        let dir = (s.point - x) / s.r2.sqrt();
        Some((dir, s.le * power_weight(s.pdf_solid_angle(), p_sphere)))
    }
}

/// Coefficients of invalid probes: on a grid, from the mean of their valid (or already filled)
/// face neighbours, ring by ring inwards; each ring reads only values known before it, so the
/// result does not depend on order (probes no valid probe reaches stay zero). Probes placed one
/// by one take the nearest valid probe's.
fn fill_invalid(placement: &Placement, sh: &mut [Sh2]) {
    let Some(grid) = placement.grid else {
        for i in (0..sh.len()).filter(|&i| !placement.valid[i]) {
            let p = placement.position[i];
            let nearest = (0..sh.len())
                .filter(|&q| placement.valid[q])
                .min_by(|&a, &b| {
                    let da = (placement.position[a] - p).length_squared();
                    let db = (placement.position[b] - p).length_squared();
                    da.total_cmp(&db).then(a.cmp(&b))
                });
            if let Some(q) = nearest {
                sh[i] = sh[q];
            }
        }
        return;
    };
    let count = grid.count;
    let mut known = placement.valid.clone();
    let mut pending: Vec<usize> = (0..sh.len()).filter(|&i| !known[i]).collect();
    let mut ring: Vec<(usize, Sh2)> = Vec::new();
    while !pending.is_empty() {
        ring.clear();
        for &i in &pending {
            let ijk = place::unflatten(i, count);
            let mut sum = [Vec3::ZERO; 9];
            let mut n = 0u32;
            for a in 0..3 {
                for d in [-1i64, 1] {
                    let c = ijk[a] as i64 + d;
                    if c < 0 || c >= count[a] as i64 {
                        continue;
                    }
                    let mut at = ijk;
                    at[a] = c as u32;
                    let q = (at[0] + count[0] * (at[1] + count[1] * at[2])) as usize;
                    if known[q] {
                        sum = sh::add(&sum, &sh[q]);
                        n += 1;
                    }
                }
            }
            if n > 0 {
                ring.push((i, sh::scaled(&sum, 1.0 / n as f32)));
            }
        }
        if ring.is_empty() {
            break;
        }
        for &(i, v) in &ring {
            sh[i] = v;
            known[i] = true;
        }
        pending.retain(|&i| !known[i]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A budget given is kept; one that follows the bake is the probes whose sphere rays and
    /// light samples are `RAY_SHARE` of the bake's rays, within its floor and cap.
    #[test]
    fn a_budget_follows_the_bake_only_when_none_is_given() {
        let following = ProbeParams::default();
        let per_probe = 2 * u64::from(following.rays);
        assert_eq!(following.budget_for(0), DEFAULT_BUDGET);
        assert_eq!(following.budget_for(3_000_000), DEFAULT_BUDGET);
        let afford = |probes: u64| (probes as f64 * per_probe as f64 / RAY_SHARE).ceil() as u64;
        assert_eq!(following.budget_for(afford(3000)), 3000);
        assert_eq!(following.budget_for(afford(3000) - 1), 2999);
        assert_eq!(following.budget_for(u64::MAX), MAX_FOLLOWING_BUDGET);
        let given = ProbeParams {
            budget: Some(64),
            ..ProbeParams::default()
        };
        assert_eq!(given.budget_for(u64::MAX), 64);
        assert_eq!(given.grid_budget(), 48);
    }

    /// Beyond the outermost probes (the slab by the walls) the lookup continues the outer
    /// cells' light: a field linear in position is read exactly there, up to [`BEYOND`] of a
    /// spacing out, and held farther.
    #[test]
    fn the_slab_beyond_the_outermost_probes_continues_the_outer_cells() {
        let grid = Grid {
            origin: Vec3::new(1.0, 0.0, -1.0),
            step: Vec3::new(0.5, 0.25, 1.0),
            count: [3, 4, 2],
            rotation: Quat::from_rotation_y(0.3),
        };
        let field = |p: Vec3| {
            let mut c = [Vec3::ZERO; 9];
            c[0] = Vec3::new(2.0 + p.x, 3.0 - 2.0 * p.y, 1.5 + 0.5 * p.z);
            c[2] = Vec3::splat(0.2 * p.y);
            c
        };
        let position: Vec<Vec3> = (0..grid.len())
            .map(|i| grid.position(place::unflatten(i, grid.count)))
            .collect();
        let probes = Probes {
            grid: Some(grid),
            refinement: Refinement::default(),
            sh: position.iter().map(|&p| field(p)).collect(),
            valid: vec![true; position.len()],
            position,
            indirect_only: false,
            rays: 0,
            moved: 0,
            budget: 0,
        };
        let world = |l: Vec3| grid.origin + grid.rotation * (grid.step * l);
        let close = |a: &Sh2, b: &Sh2| (0..9).all(|m| (a[m] - b[m]).abs().max_element() < 1e-4);
        // Inside, beyond a face, beyond an edge (two axes out), and beyond a corner.
        for l in [
            Vec3::new(1.3, 2.2, 0.6),
            Vec3::new(-0.2, 1.5, 0.5),
            Vec3::new(2.4, 3.1, 0.5),
            Vec3::new(1.0, -0.15, 1.45),
            Vec3::new(-0.5, 3.3, -0.2),
        ] {
            let p = world(l);
            assert!(close(&probes.sh_at(p, |_| true), &field(p)), "at {l}");
            // The lookup's weights (`weights_at`) sum to one, inside and beyond: the slab's
            // continuation weighs the face's probes twice and subtracts those a step in.
            let (mut sum, mut negative) = (0.0f32, false);
            probes.weights_at(
                p,
                |_| true,
                |_, w| {
                    sum += w;
                    negative |= w < 0.0;
                },
            );
            assert!((sum - 1.0).abs() < 1e-5, "at {l}: {sum}");
            assert_eq!(negative, l != Vec3::new(1.3, 2.2, 0.6), "at {l}");
        }
        // Farther out than BEYOND: the value at BEYOND.
        let (far, held) = (Vec3::new(3.5, 1.0, 0.5), Vec3::new(2.0 + BEYOND, 1.0, 0.5));
        assert!(close(
            &probes.sh_at(world(far), |_| true),
            &field(world(held))
        ));
    }
}
