//! Denser probes where light changes: grid cells divided `FACTOR` times along each axis, and
//! their sub-cells again, level by level.
//!
//! **Why.** Between probes the lookup interpolates, and the error of interpolating the true
//! field — not the probes' own error — is what dominates between probes: on `two_rooms` at
//! 1024 uniform probes, 10.1% of the 9.2% (relative RMSE) is the trilinear interpolation of the
//! path tracer's own values at the cell corners, 3.1% the probes' error at the corners, and four
//! fifths of the squared error lies within 50 cm of the emissive panel, where irradiance changes
//! over less than a spacing (`examples/dev/probe_diagnose.rs`). A uniform grid spends most of its
//! probes where light is even; beside a lamp or a panel's edge one halving is not enough either.
//!
//! **How.** The grid takes `1 − refine` of the budget; its probes are baked first. Cells form a
//! tree: level 0 is the grid's cells, and a divided cell of level `ℓ` has `FACTOR³` children of
//! level `ℓ + 1` (at most `levels` levels of division). Refinement runs in passes, one per
//! level: each pass scores every undivided cell (a *leaf*) that may still be divided by the
//! spread of its eight corners' `E/π` at the six axis normals (the largest max − min over the
//! sides, summed over the channels: how much light changes across it), over `FACTOR^ℓ` for a
//! cell of level `ℓ` (a finer cell serves less of the free space), and divides the best whose
//! spread is above `MIN_SPREAD` of the grid probes' mean, while their new nodes fit in the pass's
//! share of what is left of the budget (`PASS_SHARE`, three quarters; the last pass all of it);
//! the new nodes are then baked and the next pass scores the cells again, the new ones among
//! them. (Measured on both fixtures at 1024 probes: spread alone, or half per pass, spent the
//! budget on fine cells by the emitters and lost more between the coarse cells than it gained;
//! see the guide's "Light probes".) A cell of level `ℓ` has
//! its corners on the level's lattice (step `step / FACTOR^ℓ`); the added probes are the nodes
//! of the finest lattice a divided cell needs beyond the grid's probes, after the grid's entries,
//! sorted by (z, y, x) finest-lattice coordinate: neighbouring cells share them.
//!
//! **Continuity.** A node on a face or an edge of a coarser leaf (not one of its corners) would
//! make the light jump where the leaf's bilinear face meets its finer neighbours; such a node is
//! not gathered but takes that leaf's trilinear value there (a constrained "hanging" node, as in
//! adaptive finite elements), so the lookup is continuous across the boundary (where every probe
//! is valid and in sight). Nodes are filled coarsest lattice first, so a leaf's corners hold their
//! final values before the nodes hanging on it read them. Buried nodes take the value of the
//! divided cell that made them.
//!
//! **Lookup.** From the grid cell around a point, descend into the child holding it while the
//! cell is divided; interpolate the leaf's eight corners.
//!
//! Limits: grids with a single probe along some axis are not refined; the score sees only what
//! the corners see (a change smaller than a cell that leaves the corners alike is not found).

use std::collections::BTreeSet;

use glam::Vec3;
use rayon::prelude::*;

use super::{Grid, Sh2, sh};

/// Sub-cells per divided cell along each axis.
pub const FACTOR: u32 = 2;
/// Levels of division a file may hold (the finest lattice's coordinates stay small integers).
pub const MAX_LEVELS: u32 = 6;
/// Cells whose spread is below this share of the grid probes' mean `E/π` are not divided:
/// evenly lit space keeps the grid's spacing.
const MIN_SPREAD: f32 = 0.1;
/// Share of the budget still left that a pass may spend (the last pass spends all of it).
pub(crate) const PASS_SHARE: f32 = 0.75;

/// Cells divided [`FACTOR`] times along each axis, level by level, and the probes their lattices
/// add (entry `grid.len() + k` is node `k`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Refinement {
    /// Per level `ℓ` (0: the grid's cells), its divided cells by their lowest corner's
    /// coordinates on the level's lattice (`FACTOR^ℓ` × grid coordinates), sorted by (z, y, x).
    /// A cell of level `ℓ ≥ 1` lies in a divided cell of level `ℓ − 1`. The number of levels is
    /// the length; the last level has a divided cell.
    pub cells: Vec<Vec<[u32; 3]>>,
    /// Finest-lattice coordinates (`FACTOR^levels` × grid coordinates) of the added probes,
    /// sorted by (z, y, x).
    pub nodes: Vec<[u32; 3]>,
}

/// (z, y, x): the order of every list.
#[inline]
fn key(c: &[u32; 3]) -> (u32, u32, u32) {
    (c[2], c[1], c[0])
}

impl Refinement {
    /// No cell divided.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.cells.iter().all(Vec::is_empty)
    }

    /// Levels of division.
    #[must_use]
    pub fn levels(&self) -> u32 {
        self.cells.len() as u32
    }

    /// Divided cells over all levels.
    #[must_use]
    pub fn divided(&self) -> usize {
        self.cells.iter().map(Vec::len).sum()
    }

    /// Whether the cell of `level` with lowest corner `cell` (on the level's lattice) is divided.
    #[inline]
    #[must_use]
    pub fn is_divided(&self, level: u32, cell: [u32; 3]) -> bool {
        (self.cells.get(level as usize))
            .is_some_and(|c| c.binary_search_by_key(&key(&cell), key).is_ok())
    }

    /// Whether the cell of `level` at `cell` is in the tree: a grid cell, or a child of a
    /// divided cell.
    #[inline]
    fn exists(&self, level: u32, cell: [u32; 3]) -> bool {
        level == 0 || self.is_divided(level - 1, cell.map(|x| x / FACTOR))
    }

    /// Finest-lattice units per unit of level `level`'s lattice.
    #[inline]
    fn scale(&self, level: u32) -> u32 {
        FACTOR.pow(self.levels() - level)
    }

    /// The probe at finest-lattice coordinates `c` of `grid`: a grid probe on the grid's
    /// lattice, else an added node (`None` if it was not added).
    #[inline]
    #[must_use]
    pub fn probe_at(&self, grid: &Grid, c: [u32; 3]) -> Option<usize> {
        let s = self.scale(0);
        if c.iter().all(|&x| x.is_multiple_of(s)) {
            return Some(grid.index(c.map(|x| x / s)));
        }
        (self.nodes.binary_search_by_key(&key(&c), key).ok()).map(|k| grid.len() + k)
    }

    /// The leaf holding grid coordinates `x` (clamped to the grid) of grid cell `base`: its
    /// level and lowest corner on that level's lattice.
    #[inline]
    #[must_use]
    pub fn leaf(&self, base: [u32; 3], x: Vec3) -> (u32, [u32; 3]) {
        let (mut level, mut cell) = (0, base);
        while self.is_divided(level, cell) {
            level += 1;
            let s = FACTOR.pow(level) as f32;
            cell = std::array::from_fn(|a| {
                let c = (x[a] * s).max(0.0).floor() as u32;
                c.clamp(cell[a] * FACTOR, cell[a] * FACTOR + FACTOR - 1)
            });
        }
        (level, cell)
    }

    /// The probes at the corners of the cell of `level` at `cell` and their trilinear weights
    /// at grid coordinates `x`, in corner order; `None` when a corner was not added (a file
    /// that does not hold its nodes).
    #[inline]
    #[must_use]
    pub fn corners(
        &self,
        grid: &Grid,
        (level, cell): (u32, [u32; 3]),
        x: Vec3,
    ) -> Option<[(usize, f32); 8]> {
        let up = self.scale(level);
        let mut out = [(0, 0.0); 8];
        let at = x * FACTOR.pow(level) as f32;
        for (k, (c, w)) in trilinear(cell, at).into_iter().enumerate() {
            out[k] = (self.probe_at(grid, c.map(|v| v * up))?, w);
        }
        Some(out)
    }

    /// The coarsest lattice (level) finest node `c` lies on.
    #[inline]
    fn node_level(&self, c: [u32; 3]) -> u32 {
        (0..=self.levels())
            .find(|&l| c.iter().all(|&x| x.is_multiple_of(self.scale(l))))
            .unwrap_or(self.levels())
    }

    /// The cell an added node `c` takes its value from when it is not gathered, and whether it
    /// is constrained: the coarsest leaf that holds `c` without having it as a corner (the node
    /// hangs on it), else a divided cell of the level above the node's that holds it (the cell
    /// whose division made it).
    fn holder(&self, grid: &Grid, c: [u32; 3]) -> ((u32, [u32; 3]), bool) {
        let l = self.node_level(c).max(1);
        for m in 0..l {
            let mut leaf = None;
            for_cells_holding(grid, (self.levels(), m), c, |b| {
                if leaf.is_none() && self.exists(m, b) && !self.is_divided(m, b) {
                    leaf = Some(b);
                }
            });
            if let Some(b) = leaf {
                return ((m, b), true);
            }
        }
        let mut parent = None;
        for_cells_holding(grid, (self.levels(), l - 1), c, |b| {
            if parent.is_none() && self.is_divided(l - 1, b) {
                parent = Some(b);
            }
        });
        let fallback = c.map(|x| x / self.scale(l - 1));
        ((l - 1, parent.unwrap_or(fallback)), false)
    }
}

/// The finest-lattice nodes that the divided `cells` (per level, of a refinement of
/// `cells.len()` levels) need beyond the grid's probes, sorted by (z, y, x).
pub(crate) fn node_set(cells: &[Vec<[u32; 3]>]) -> Vec<[u32; 3]> {
    let levels = cells.len() as u32;
    let grid_scale = FACTOR.pow(levels);
    let mut nodes: Vec<[u32; 3]> = Vec::new();
    for (l, level) in cells.iter().enumerate() {
        // The children's lattice (level l + 1) in finest units.
        let up = FACTOR.pow(levels - l as u32 - 1);
        for base in level {
            for_lattice(*base, |c| {
                let c = c.map(|x| x * up);
                if c.iter().any(|&x| !x.is_multiple_of(grid_scale)) {
                    nodes.push(c);
                }
            });
        }
    }
    nodes.sort_unstable_by_key(key);
    nodes.dedup();
    nodes
}

/// Calls `f` with the coordinates on the children's lattice of every node of the cell at
/// `base`.
fn for_lattice(base: [u32; 3], mut f: impl FnMut([u32; 3])) {
    let o = base.map(|x| x * FACTOR);
    for k in 0..=FACTOR {
        for j in 0..=FACTOR {
            for i in 0..=FACTOR {
                f([o[0] + i, o[1] + j, o[2] + k]);
            }
        }
    }
}

/// Calls `f` with the lowest corner (on level `m`'s lattice) of every cell of level `m` of
/// `grid` that holds finest node `c` of a refinement of `levels` levels (whether or not the
/// cell is in the tree).
fn for_cells_holding(
    grid: &Grid,
    (levels, m): (u32, u32),
    c: [u32; 3],
    mut f: impl FnMut([u32; 3]),
) {
    let s = FACTOR.pow(levels - m);
    let range = |a: usize| {
        let cells = (grid.count[a] - 1) * FACTOR.pow(m);
        let lo = c[a] / s;
        let from = if c[a].is_multiple_of(s) {
            lo.saturating_sub(1)
        } else {
            lo
        };
        from..=lo.min(cells - 1)
    };
    for k in range(2) {
        for j in range(1) {
            for i in range(0) {
                let b = [i, j, k];
                // On a plane, the cell below holds the node only if the node is its top.
                if (0..3).all(|a| b[a] * s <= c[a] && c[a] <= (b[a] + 1) * s) {
                    f(b);
                }
            }
        }
    }
}

/// Trilinear weights of the eight corners of the cell at `base` at lattice coordinates `g`, in
/// corner order (bit `a` of the corner index: the upper side along axis `a`).
#[inline]
pub(crate) fn trilinear(base: [u32; 3], g: Vec3) -> [([u32; 3], f32); 8] {
    std::array::from_fn(|corner| {
        let mut w = 1.0;
        let mut ijk = base;
        for a in 0..3 {
            let t = (g[a] - base[a] as f32).clamp(0.0, 1.0);
            if (corner >> a) & 1 == 1 {
                ijk[a] += 1;
                w *= t;
            } else {
                w *= 1.0 - t;
            }
        }
        (ijk, w)
    })
}

/// The trilinear value of the probes `corners` (with weights), as the lookup would read them
/// there: corners valid and `visible` only (renormalised), and whether any was; with none, all
/// corners.
fn coarse_value(
    (valid, sh): (&[bool], &[Sh2]),
    corners: &[(usize, f32); 8],
    mut visible: impl FnMut(usize) -> bool,
) -> (Sh2, bool) {
    let mut sum = [Vec3::ZERO; 9];
    let mut total = 0.0;
    for strict in [true, false] {
        for &(q, w) in corners {
            if w > 0.0 && (!strict || (valid[q] && visible(q))) {
                sum = sh::add(&sum, &sh::scaled(&sh[q], w));
                total += w;
            }
        }
        if total > 0.0 {
            return (sh::scaled(&sum, 1.0 / total), strict);
        }
    }
    (sum, false)
}

/// A refinement being built pass by pass: a tree of at most `levels` levels, its nodes on the
/// finest lattice of all of them until [`Builder::finish`].
pub(crate) struct Builder {
    grid: Grid,
    work: Refinement,
    /// Spreads at or below this are not divided.
    floor: f32,
}

impl Builder {
    /// A builder for `grid` from its baked probes (`valid`, `sh`, grid entries only); `None`
    /// for grids flat along an axis or without a valid probe.
    pub(crate) fn new(grid: &Grid, levels: u32, (valid, sh): (&[bool], &[Sh2])) -> Option<Self> {
        if levels == 0 || grid.count.iter().any(|&c| c < 2) {
            return None;
        }
        let (mut mean, mut n) = (0.0f64, 0u32);
        for q in (0..grid.len()).filter(|&q| valid[q]) {
            mean += f64::from(side_sums(&sh[q]).iter().sum::<f32>()) / 6.0;
            n += 1;
        }
        (n > 0).then(|| Builder {
            grid: *grid,
            work: Refinement {
                cells: vec![Vec::new(); levels.min(MAX_LEVELS) as usize],
                nodes: Vec::new(),
            },
            floor: MIN_SPREAD * (mean / f64::from(n)) as f32,
        })
    }

    /// The refinement so far (nodes on the finest lattice of every level the builder may use).
    pub(crate) fn refinement(&self) -> &Refinement {
        &self.work
    }

    /// The cells to divide next, as `(level, lowest corner)`: the leaves that may still be
    /// divided, by the spread of their corners (`probes`: every probe of the refinement so far,
    /// filled), best first, while their new nodes number at most `budget`.
    pub(crate) fn choose(
        &self,
        (valid, sh): (&[bool], &[Sh2]),
        budget: usize,
    ) -> Vec<(u32, [u32; 3])> {
        let (grid, work) = (&self.grid, &self.work);
        let cube: Vec<[f32; 6]> = sh.iter().map(side_sums).collect();
        let spread = |corners: [(usize, f32); 8]| {
            let (mut lo, mut hi) = ([f32::INFINITY; 6], [f32::NEG_INFINITY; 6]);
            for (q, _) in corners.into_iter().filter(|&(q, _)| valid[q]) {
                for s in 0..6 {
                    lo[s] = lo[s].min(cube[q][s]);
                    hi[s] = hi[s].max(cube[q][s]);
                }
            }
            (0..6).map(|s| hi[s] - lo[s]).fold(0.0f32, f32::max)
        };
        let mut scored: Vec<(f32, u32, [u32; 3])> = Vec::new();
        let mut score = |level: u32, b: [u32; 3]| {
            if work.is_divided(level, b) {
                return;
            }
            if let Some(corners) = work.corners(grid, (level, b), Vec3::ZERO) {
                let s = spread(corners);
                // A finer cell counts in proportion to its size: it serves a smaller share of
                // the free space, so it is divided only where light changes faster across it
                // than across the coarser cells left.
                if s > self.floor {
                    scored.push((s / FACTOR.pow(level) as f32, level, b));
                }
            }
        };
        let [cx, cy, cz] = grid.count.map(|c| c - 1);
        for k in 0..cz {
            for j in 0..cy {
                for i in 0..cx {
                    score(0, [i, j, k]);
                }
            }
        }
        for level in 1..work.levels() {
            for parent in &work.cells[level as usize - 1] {
                for child in 0..FACTOR.pow(3) {
                    let d = [
                        child % FACTOR,
                        (child / FACTOR) % FACTOR,
                        child / FACTOR / FACTOR,
                    ];
                    score(level, std::array::from_fn(|a| parent[a] * FACTOR + d[a]));
                }
            }
        }
        // Best first; ties by level and position, so every machine divides the same cells.
        scored.sort_unstable_by(|a, b| {
            (b.0.total_cmp(&a.0))
                .then(a.1.cmp(&b.1))
                .then(key(&a.2).cmp(&key(&b.2)))
        });
        let mut chosen = Vec::new();
        let mut new: BTreeSet<(u32, u32, u32)> = BTreeSet::new();
        for &(_, level, base) in &scored {
            let added = self.new_nodes(level, base, &new);
            if new.len() + added.len() > budget {
                break;
            }
            new.extend(added);
            chosen.push((level, base));
        }
        chosen
    }

    /// The nodes dividing the cell of `level` at `base` adds to the refinement and `also`.
    fn new_nodes(
        &self,
        level: u32,
        base: [u32; 3],
        also: &BTreeSet<(u32, u32, u32)>,
    ) -> Vec<(u32, u32, u32)> {
        let up = self.work.scale(level + 1);
        let mut out = Vec::new();
        for_lattice(base, |c| {
            let c = c.map(|x| x * up);
            let k = key(&c);
            if self.work.probe_at(&self.grid, c).is_none() && !also.contains(&k) {
                out.push(k);
            }
        });
        out
    }

    /// Divides `cells` (`(level, lowest corner)`, leaves of the tree); returns the nodes added
    /// (finest-lattice coordinates, sorted).
    pub(crate) fn divide(&mut self, cells: &[(u32, [u32; 3])]) -> Vec<[u32; 3]> {
        for &(level, base) in cells {
            self.work.cells[level as usize].push(base);
        }
        for level in &mut self.work.cells {
            level.sort_unstable_by_key(key);
            level.dedup();
        }
        let nodes = node_set(&self.work.cells);
        let old: BTreeSet<(u32, u32, u32)> = self.work.nodes.iter().map(key).collect();
        let added = (nodes.iter())
            .filter(|c| !old.contains(&key(c)))
            .copied()
            .collect();
        self.work.nodes = nodes;
        added
    }

    /// The node's level: its coarsest lattice (1 for a node of a divided grid cell's lattice).
    pub(crate) fn node_level(&self, c: [u32; 3]) -> u32 {
        self.work.node_level(c)
    }

    /// World position of finest node `c` on the grid.
    pub(crate) fn position(&self, c: [u32; 3]) -> Vec3 {
        let g = Vec3::from(c.map(|x| x as f32)) / self.work.scale(0) as f32;
        self.grid.origin + self.grid.rotation * (self.grid.step * g)
    }

    /// The refinement, its levels cut to those with a divided cell (the nodes on their finest
    /// lattice).
    pub(crate) fn finish(self) -> Refinement {
        let mut work = self.work;
        let used = work
            .cells
            .iter()
            .rposition(|c| !c.is_empty())
            .map_or(0, |l| l + 1);
        let drop = FACTOR.pow(work.levels() - used as u32);
        work.cells.truncate(used);
        for c in &mut work.nodes {
            *c = c.map(|x| x / drop);
        }
        work
    }
}

/// `E/π` at the six axis normals of a probe, each summed over the channels.
fn side_sums(c: &Sh2) -> [f32; 6] {
    super::volume::ambient_cube(c).map(|e| e.element_sum())
}

/// Which added probes are constrained to a coarser leaf's value (they are not gathered), in
/// the order of `refinement.nodes`.
#[must_use]
pub fn constrained(grid: &Grid, refinement: &Refinement) -> Vec<bool> {
    (refinement.nodes.iter())
        .map(|&c| refinement.holder(grid, c).1)
        .collect()
}

/// Sets the added probes that `fill` marks (entries `grid.len()..` of `position`, `valid`,
/// `sh`: the constrained and the buried ones) to their holder's trilinear value
/// ([`Refinement::holder`]) from the corners that the node sees (`sees(node, probe)`: a shadow
/// ray in the bake), as the lookup reads the holder there: a node behind a wall takes no light
/// from the other side. A node that sees none of them is marked invalid (the lookup leaves it
/// out) and holds the corners' mean. Coarsest lattice first: a holder's corners are final
/// before the nodes on it read them.
pub(crate) fn fill(
    grid: &Grid,
    refinement: &Refinement,
    (position, valid, sh): (&[Vec3], &mut [bool], &mut [Sh2]),
    fill: &[bool],
    sees: impl Fn(Vec3, Vec3) -> bool + Sync,
) {
    let n = grid.len();
    for level in 1..=refinement.levels() {
        let todo: Vec<usize> = (0..refinement.nodes.len())
            .filter(|&k| fill[k] && refinement.node_level(refinement.nodes[k]) == level)
            .collect();
        let filled: Vec<(usize, Sh2, bool)> = (todo.into_par_iter())
            .map(|k| {
                let c = refinement.nodes[k];
                let (cell, _) = refinement.holder(grid, c);
                let g = Vec3::from(c.map(|x| x as f32)) / refinement.scale(0) as f32;
                let at = position[n + k];
                let sees = |q: usize| sees(at, position[q]);
                match refinement.corners(grid, cell, g) {
                    Some(corners) => {
                        let (value, seen) = coarse_value((valid, sh), &corners, sees);
                        (n + k, value, seen)
                    }
                    None => (n + k, [Vec3::ZERO; 9], false),
                }
            })
            .collect();
        for (i, value, seen) in filled {
            sh[i] = value;
            valid[i] &= seen;
        }
    }
}

/// Checks that `refinement` fits `grid` (a file's consistency): at most [`MAX_LEVELS`] levels,
/// the last one with a divided cell; each level's cells sorted, in range and in a divided cell
/// of the level above; the nodes exactly those the divided cells need, sorted.
pub(crate) fn consistent(grid: &Grid, refinement: &Refinement) -> bool {
    if grid.count.iter().any(|&c| c < 2) {
        return refinement.is_empty() && refinement.nodes.is_empty();
    }
    let sorted = |v: &[[u32; 3]]| v.windows(2).all(|w| key(&w[0]) < key(&w[1]));
    let levels = refinement.levels();
    if levels > MAX_LEVELS || refinement.cells.last().is_some_and(Vec::is_empty) {
        return false;
    }
    for (l, cells) in refinement.cells.iter().enumerate() {
        let l = l as u32;
        let in_range = |b: &[u32; 3]| (0..3).all(|a| b[a] < (grid.count[a] - 1) * FACTOR.pow(l));
        if !sorted(cells)
            || !cells
                .iter()
                .all(|b| in_range(b) && refinement.exists(l, *b))
        {
            return false;
        }
    }
    sorted(&refinement.nodes) && node_set(&refinement.cells) == refinement.nodes
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Quat;

    fn grid() -> Grid {
        Grid {
            origin: Vec3::ZERO,
            step: Vec3::ONE,
            count: [4, 3, 3],
            rotation: Quat::IDENTITY,
        }
    }

    fn refinement(cells: Vec<Vec<[u32; 3]>>) -> Refinement {
        let nodes = node_set(&cells);
        Refinement { cells, nodes }
    }

    #[test]
    fn a_refined_cell_adds_its_lattice_and_constrains_its_faces() {
        let g = grid();
        let r = refinement(vec![vec![[1, 0, 0]]]);
        assert!(consistent(&g, &r));
        // (F+1)³ − 8 nodes; every one on the cell's boundary is on an unrefined neighbour's
        // face or edge, but for the faces at the grid's edge.
        assert_eq!(r.nodes.len(), ((FACTOR + 1).pow(3) - 8) as usize);
        for (c, coarse) in r.nodes.iter().zip(constrained(&g, &r)) {
            let inside = (0..3).all(|a| !c[a].is_multiple_of(FACTOR));
            let shared = c[0] == FACTOR || c[0] == 2 * FACTOR || c[1] == FACTOR || c[2] == FACTOR;
            assert_eq!(coarse, !inside && shared, "{c:?}");
        }
        // Two refined neighbours share their face's nodes, unconstrained there.
        let r = refinement(vec![vec![[1, 0, 0], [2, 0, 0]]]);
        let face = [2 * FACTOR, 1, 1];
        let k = r.nodes.iter().position(|&n| n == face).unwrap();
        assert!(!constrained(&g, &r)[k]);
        // A second level: a divided child's nodes hang on its undivided siblings' faces, and
        // the first level's nodes move to the finer lattice.
        let r = refinement(vec![vec![[1, 0, 0]], vec![[3, 1, 1]]]);
        assert!(consistent(&g, &r));
        let f2 = FACTOR * FACTOR;
        assert!(r.nodes.contains(&[f2 + FACTOR, FACTOR, FACTOR])); // the cell's centre
        let con = constrained(&g, &r);
        // The child's centre is free; a node on its face towards an undivided sibling hangs.
        let at = |c: [u32; 3]| con[r.nodes.iter().position(|&n| n == c).unwrap()];
        assert!(!at([7, 3, 3]));
        assert!(at([6, 3, 3]));
        // Not a child of a divided cell, or unsorted: not consistent.
        assert!(!consistent(
            &g,
            &refinement(vec![vec![[1, 0, 0]], vec![[0, 0, 0]]])
        ));
        assert!(!consistent(
            &g,
            &refinement(vec![vec![[2, 0, 0], [1, 0, 0]]])
        ));
        assert!(!consistent(&g, &refinement(vec![vec![[1, 0, 0]], vec![]])));
    }

    #[test]
    fn the_spread_picks_the_cells_where_light_changes() {
        let g = grid();
        let n = g.len();
        // Even light but for one bright probe: the cells around it are refined first.
        let mut sh = vec![[Vec3::ZERO; 9]; n];
        for c in &mut sh {
            c[0] = Vec3::ONE;
        }
        sh[g.index([3, 2, 2])][0] = Vec3::splat(10.0);
        let valid = vec![true; n];
        let b = Builder::new(&g, 2, (&valid, &sh)).unwrap();
        assert_eq!(b.choose((&valid, &sh), 1000), vec![(0, [2, 1, 1])]);
        // Within the budget: one cell needs (F+1)³ − 8 nodes.
        assert!(b.choose((&valid, &sh), 5).is_empty());
        let mut b = b;
        let added = b.divide(&[(0, [2, 1, 1])]);
        assert_eq!(added.len(), 19);
        // The second pass sees the divided cell's children: the one by the bright probe (its
        // nodes hold the coarse cell's values here, so it scores as its parent did, scaled).
        let mut all_sh = sh.clone();
        let mut all_valid = valid.clone();
        let r = b.refinement().clone();
        let positions: Vec<Vec3> = (0..n)
            .map(|i| g.position(super::super::place::unflatten(i, g.count)))
            .chain(r.nodes.iter().map(|&c| b.position(c)))
            .collect();
        all_sh.resize(positions.len(), [Vec3::ZERO; 9]);
        all_valid.resize(positions.len(), true);
        let every = vec![true; r.nodes.len()];
        fill(
            &g,
            &r,
            (&positions, &mut all_valid, &mut all_sh),
            &every,
            |_, _| true,
        );
        let next = b.choose((&all_valid, &all_sh), 1000);
        assert_eq!(next[0], (1, [5, 3, 3]));
        let r = b.finish();
        assert_eq!(r.levels(), 1);
        assert!(consistent(&g, &r));
    }

    /// The lookup in a refined cell reads its nodes (exact at a node) and meets coarser
    /// neighbours' faces without a jump, over two levels: the constrained nodes hold the coarser
    /// leaf's value.
    #[test]
    fn the_lookup_is_exact_at_nodes_and_continuous_across_levels() {
        let g = grid();
        let n = g.len();
        // Light that is not trilinear, so coarse and fine interpolation differ.
        let field = |p: Vec3| {
            let mut c = [Vec3::ZERO; 9];
            c[0] = Vec3::new(1.0 + p.x * p.x, 1.0 + p.y * p.z, 2.0 + (p.x * p.y).sin());
            c[1] = Vec3::splat(0.3 * p.z * p.x);
            c
        };
        let refinement = refinement(vec![vec![[1, 1, 0], [2, 1, 0]], vec![[4, 2, 0], [3, 3, 1]]]);
        assert!(consistent(&g, &refinement));
        let scale = refinement.scale(0) as f32;
        let mut position: Vec<Vec3> = (0..n)
            .map(|i| g.position(super::super::place::unflatten(i, g.count)))
            .collect();
        position.extend((refinement.nodes.iter()).map(|c| Vec3::from(c.map(|x| x as f32)) / scale));
        let mut sh: Vec<Sh2> = position.iter().map(|&p| field(p)).collect();
        let mut valid = vec![true; position.len()];
        let constrained = constrained(&g, &refinement);
        assert!(constrained.iter().any(|&c| c) && constrained.iter().any(|&c| !c));
        let probes = (&position[..], &mut valid[..], &mut sh[..]);
        fill(&g, &refinement, probes, &constrained, |_, _| true);
        let probes = super::super::Probes {
            grid: Some(g),
            refinement,
            position: position.clone(),
            valid,
            sh: sh.clone(),
            indirect_only: false,
            rays: 0,
            moved: 0,
            budget: 0,
        };
        let at = |p: Vec3| probes.sh_at(p, |_| true);
        let close =
            |a: &Sh2, b: &Sh2, e: f32| (0..9).all(|m| (a[m] - b[m]).abs().max_element() < e);
        // Exact at every node, gathered or constrained.
        for (i, &p) in position.iter().enumerate() {
            assert!(close(&at(p), &sh[i], 1e-4), "probe {i} at {p}");
        }
        // An unconstrained node inside a level-2 cell keeps the field's own value.
        let centre = Vec3::new(1.75, 1.75, 0.75);
        assert!(close(&at(centre), &field(centre), 1e-4));
        // On every plane of the finest lattice, the values on either side agree.
        let mut rng = crate::sampling::Rng::new(1, 2, 3);
        let last = Vec3::new(3.0, 2.0, 2.0);
        for _ in 0..4000 {
            let u = rng.next_vec2();
            let a = (rng.next_vec2().x * 3.0) as usize % 3;
            let mut p = Vec3::new(u.x, u.y, rng.next_vec2().x) * last;
            p[a] = ((p[a] * scale).round() / scale).clamp(0.01, last[a] - 0.01);
            let mut d = Vec3::ZERO;
            d[a] = 1e-4;
            let (lo, hi) = (at(p - d), at(p + d));
            assert!(
                close(&lo, &hi, 2e-3),
                "a jump at {p} across axis {a}: {:?} vs {:?}",
                lo[0],
                hi[0]
            );
        }
    }
}
