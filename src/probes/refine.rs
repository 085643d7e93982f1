//! Denser probes where light changes: grid cells divided `FACTOR` times along each axis.
//!
//! **Why.** Between probes the lookup interpolates, and the error of interpolating the true
//! field — not the probes' own error — is what dominates between probes: on `two_rooms` at
//! 1024 uniform probes, 10.1% of the 9.2% (relative RMSE) is the trilinear interpolation of the
//! path tracer's own values at the cell corners, 3.1% the probes' error at the corners, and four
//! fifths of the squared error lies within 50 cm of the emissive panel, where irradiance changes
//! over less than a spacing (`examples/dev/probe_diagnose.rs`). A uniform grid spends most of its
//! probes where light is even.
//!
//! **How.** The grid takes `1 − refine` of the budget; its probes are baked first. Each cell then
//! scores the spread of its eight (valid) corners' `E/π` at the six axis normals (the largest
//! max − min over the sides, summed over the channels): how much light changes across it. The
//! cells scoring highest, above `MIN_SPREAD` of the probes' mean, are divided into `FACTOR³`
//! sub-cells, best first, while their new lattice nodes fit in the rest of the budget. Nodes of
//! the fine lattice (step `step / FACTOR`) that a refined cell needs beyond the grid's probes are
//! probes of their own, after the grid's entries, sorted by (z, y, x) lattice coordinate:
//! neighbouring refined cells share them.
//!
//! **Continuity.** A node on a face or an edge of an unrefined cell would make the light jump
//! where the coarse cell's bilinear face meets the refined cell's finer one; such a node is not
//! gathered but takes the coarse cell's trilinear value there (a constrained "hanging" node, as
//! in adaptive finite elements), so the lookup is continuous across the boundary (where every
//! probe is valid and in sight). Buried nodes take the coarse value too.
//!
//! Limits: one level of refinement; grids with a single probe along some axis are not
//! refined; the score sees only what the grid's probes see (a change smaller than a cell that
//! leaves the corners alike is not found).

use glam::Vec3;
use rayon::prelude::*;

use super::{Grid, Sh2, sh};

/// Sub-cells per refined cell along each axis.
pub const FACTOR: u32 = 2;
/// Cells whose spread is below this share of the probes' mean `E/π` are not refined: evenly lit
/// space keeps the grid's spacing.
const MIN_SPREAD: f32 = 0.1;

/// Grid cells divided [`FACTOR`] times along each axis, and the probes their lattice adds
/// (entry `grid.len() + k` is node `k`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Refinement {
    /// Refined cells by their lowest corner's grid coordinates, sorted by (z, y, x).
    pub cells: Vec<[u32; 3]>,
    /// Fine-lattice coordinates (`FACTOR` × grid coordinates) of the added probes, sorted by
    /// (z, y, x).
    pub nodes: Vec<[u32; 3]>,
}

/// (z, y, x): the order of both lists.
#[inline]
fn key(c: &[u32; 3]) -> (u32, u32, u32) {
    (c[2], c[1], c[0])
}

impl Refinement {
    /// No cell refined.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.cells.is_empty()
    }

    /// Whether the cell with lowest corner `base` is refined.
    #[inline]
    #[must_use]
    pub fn is_refined(&self, base: [u32; 3]) -> bool {
        self.cells.binary_search_by_key(&key(&base), key).is_ok()
    }

    /// The probe at fine-lattice coordinates `c` of `grid`: a grid probe when every coordinate
    /// is a multiple of [`FACTOR`], else an added node (`None` if it was not added).
    #[inline]
    #[must_use]
    pub fn probe_at(&self, grid: &Grid, c: [u32; 3]) -> Option<usize> {
        if c.iter().all(|&x| x.is_multiple_of(FACTOR)) {
            return Some(grid.index(c.map(|x| x / FACTOR)));
        }
        (self.nodes.binary_search_by_key(&key(&c), key).ok()).map(|k| grid.len() + k)
    }

    /// The nodes and `(cell, constrained)` of refining `cells` (sorted) of `grid`: each node
    /// with a cell that holds it, an unrefined one when there is any (the node is constrained
    /// to its value).
    fn nodes_of(grid: &Grid, cells: &[[u32; 3]]) -> Vec<([u32; 3], [u32; 3], bool)> {
        let mut nodes: Vec<[u32; 3]> = Vec::new();
        for base in cells {
            for_lattice(*base, |c| {
                if c.iter().any(|&x| !x.is_multiple_of(FACTOR)) {
                    nodes.push(c);
                }
            });
        }
        nodes.sort_unstable_by_key(key);
        nodes.dedup();
        let refined = |b: [u32; 3]| cells.binary_search_by_key(&key(&b), key).is_ok();
        (nodes.into_iter())
            .map(|c| {
                let mut holder = None;
                for_cells_holding(grid, c, |b| {
                    let coarse = !refined(b);
                    match holder {
                        Some((_, true)) => {}
                        Some(_) if !coarse => {}
                        _ => holder = Some((b, coarse)),
                    }
                });
                let (b, coarse) = holder.unwrap_or((c.map(|x| x / FACTOR), false));
                (c, b, coarse)
            })
            .collect()
    }
}

/// Calls `f` with the fine-lattice coordinates of every node of the cell at `base`.
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

/// Calls `f` with the lowest corner of every cell of `grid` that holds fine node `c`.
fn for_cells_holding(grid: &Grid, c: [u32; 3], mut f: impl FnMut([u32; 3])) {
    let range = |a: usize| {
        let cells = grid.count[a] - 1;
        let lo = c[a] / FACTOR;
        let on_plane = c[a].is_multiple_of(FACTOR);
        let from = if on_plane { lo.saturating_sub(1) } else { lo };
        from..=lo.min(cells - 1)
    };
    for k in range(2) {
        for j in range(1) {
            for i in range(0) {
                let b = [i, j, k];
                // On a plane, the cell below holds the node only if the node is its top.
                if (0..3).all(|a| b[a] * FACTOR <= c[a] && c[a] <= (b[a] + 1) * FACTOR) {
                    f(b);
                }
            }
        }
    }
}

/// Trilinear weights of the eight corners of the cell at `base` at grid coordinates `g`, in
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

/// The cell at `base`'s trilinear value at grid coordinates `g` from the grid's probes, as the
/// lookup at that point would read the cell: corners valid and `visible` only (renormalised),
/// and whether any was; with none, all corners.
fn coarse_value(
    grid: &Grid,
    (valid, sh): (&[bool], &[Sh2]),
    base: [u32; 3],
    g: Vec3,
    mut visible: impl FnMut(usize) -> bool,
) -> (Sh2, bool) {
    let corners = trilinear(base, g);
    let mut sum = [Vec3::ZERO; 9];
    let mut total = 0.0;
    for strict in [true, false] {
        for &(ijk, w) in &corners {
            let q = grid.index(ijk);
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

/// The refinement of `grid` for at most `budget` added probes, from its baked probes (`valid`,
/// `sh`, grid entries only); see the module docs. Empty for grids flat along an axis.
pub(crate) fn choose(grid: &Grid, valid: &[bool], sh: &[Sh2], budget: usize) -> Refinement {
    if budget == 0 || grid.count.iter().any(|&c| c < 2) {
        return Refinement::default();
    }
    let cube: Vec<[f32; 6]> = sh
        .iter()
        .map(|c| super::volume::ambient_cube(c).map(|e| e.element_sum()))
        .collect();
    let (mut mean, mut n) = (0.0f64, 0u32);
    for q in (0..cube.len()).filter(|&q| valid[q]) {
        mean += cube[q].iter().map(|&v| v as f64).sum::<f64>() / 6.0;
        n += 1;
    }
    if n == 0 {
        return Refinement::default();
    }
    let floor = MIN_SPREAD * (mean / n as f64) as f32;
    let [cx, cy, cz] = grid.count.map(|c| c - 1);
    let mut scored: Vec<(f32, [u32; 3])> = Vec::new();
    for k in 0..cz {
        for j in 0..cy {
            for i in 0..cx {
                let base = [i, j, k];
                let (mut lo, mut hi) = ([f32::INFINITY; 6], [f32::NEG_INFINITY; 6]);
                for (ijk, _) in trilinear(base, Vec3::ZERO) {
                    let q = grid.index(ijk);
                    if valid[q] {
                        for s in 0..6 {
                            lo[s] = lo[s].min(cube[q][s]);
                            hi[s] = hi[s].max(cube[q][s]);
                        }
                    }
                }
                let spread = (0..6).map(|s| hi[s] - lo[s]).fold(0.0f32, f32::max);
                if spread > floor {
                    scored.push((spread, base));
                }
            }
        }
    }
    // Best first; ties by position, so every machine refines the same cells.
    scored.sort_unstable_by(|a, b| b.0.total_cmp(&a.0).then(key(&a.1).cmp(&key(&b.1))));
    let mut cells: Vec<[u32; 3]> = Vec::new();
    let mut nodes: std::collections::BTreeSet<(u32, u32, u32)> = Default::default();
    for &(_, base) in &scored {
        let mut new = Vec::new();
        for_lattice(base, |c| {
            if c.iter().any(|&x| !x.is_multiple_of(FACTOR)) && !nodes.contains(&key(&c)) {
                new.push(key(&c));
            }
        });
        if nodes.len() + new.len() > budget {
            break;
        }
        nodes.extend(new);
        cells.push(base);
    }
    cells.sort_unstable_by_key(key);
    Refinement {
        nodes: nodes.into_iter().map(|(z, y, x)| [x, y, z]).collect(),
        cells,
    }
}

/// Where the added probes of `refinement` start, before the placement tests: grid positions of
/// the fine lattice.
pub(crate) fn positions(grid: &Grid, refinement: &Refinement) -> Vec<Vec3> {
    (refinement.nodes.iter())
        .map(|c| grid_point(grid, *c))
        .collect()
}

/// World position of fine node `c`.
fn grid_point(grid: &Grid, c: [u32; 3]) -> Vec3 {
    let g = Vec3::from(c.map(|x| x as f32)) / FACTOR as f32;
    grid.origin + grid.rotation * (grid.step * g)
}

/// Which added probes are constrained to a coarse cell's value (they are not gathered), in
/// the order of `refinement.nodes`.
#[must_use]
pub fn constrained(grid: &Grid, refinement: &Refinement) -> Vec<bool> {
    (Refinement::nodes_of(grid, &refinement.cells).into_iter())
        .map(|(_, _, coarse)| coarse)
        .collect()
}

/// Sets the constrained and the buried added probes (entries `grid.len()..` of `position`,
/// `valid`, `sh`) to their coarse cell's trilinear value from the grid's probes that the node
/// sees (`sees(node, probe)`: a shadow ray in the bake), as the lookup reads the coarse cell
/// there: a node behind a wall takes no light from the other side. A node that sees none of
/// them is marked invalid (the lookup leaves it out) and holds the corners' mean.
pub(crate) fn fill(
    grid: &Grid,
    refinement: &Refinement,
    (position, valid, sh): (&[Vec3], &mut [bool], &mut [Sh2]),
    constrained: &[bool],
    sees: impl Fn(Vec3, Vec3) -> bool + Sync,
) {
    let n = grid.len();
    let nodes = Refinement::nodes_of(grid, &refinement.cells);
    let filled: Vec<(usize, Sh2, bool)> = (nodes.into_par_iter().enumerate())
        .filter(|&(k, _)| constrained[k] || !valid[n + k])
        .map(|(k, (c, base, _))| {
            let g = Vec3::from(c.map(|x| x as f32)) / FACTOR as f32;
            let at = position[n + k];
            let sees = |q: usize| sees(at, position[q]);
            let (value, seen) = coarse_value(grid, (&valid[..n], &sh[..n]), base, g, sees);
            (n + k, value, seen)
        })
        .collect();
    for (i, value, seen) in filled {
        sh[i] = value;
        valid[i] &= seen;
    }
}

/// Checks that every node a refined cell of `grid` needs is in `refinement` (a file's
/// consistency), that the lists are sorted and in range.
pub(crate) fn consistent(grid: &Grid, refinement: &Refinement) -> bool {
    let sorted = |v: &[[u32; 3]]| v.windows(2).all(|w| key(&w[0]) < key(&w[1]));
    if grid.count.iter().any(|&c| c < 2) {
        return refinement.is_empty() && refinement.nodes.is_empty();
    }
    let in_cells = (refinement.cells.iter()).all(|b| (0..3).all(|a| b[a] + 1 < grid.count[a]));
    let in_lattice =
        (refinement.nodes.iter()).all(|c| (0..3).all(|a| c[a] <= (grid.count[a] - 1) * FACTOR));
    if !(sorted(&refinement.cells) && sorted(&refinement.nodes) && in_cells && in_lattice) {
        return false;
    }
    let mut all = true;
    for base in &refinement.cells {
        for_lattice(*base, |c| all &= refinement.probe_at(grid, c).is_some());
    }
    all && Refinement::nodes_of(grid, &refinement.cells).len() == refinement.nodes.len()
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

    #[test]
    fn a_refined_cell_adds_its_lattice_and_constrains_its_faces() {
        let g = grid();
        let cells = vec![[1, 0, 0]];
        let nodes = Refinement::nodes_of(&g, &cells);
        // (F+1)³ − 8 nodes; every one on the cell's boundary is on an unrefined neighbour's
        // face or edge, but for the faces at the grid's edge.
        assert_eq!(nodes.len(), ((FACTOR + 1).pow(3) - 8) as usize);
        for (c, base, coarse) in &nodes {
            let inside = (0..3).all(|a| !c[a].is_multiple_of(FACTOR));
            let shared = c[0] == FACTOR || c[0] == 2 * FACTOR || c[1] == FACTOR || c[2] == FACTOR;
            assert_eq!(*coarse, !inside && shared, "{c:?} in {base:?}");
        }
        // Two refined neighbours share their face's nodes, unconstrained there.
        let cells = vec![[1, 0, 0], [2, 0, 0]];
        let nodes = Refinement::nodes_of(&g, &cells);
        let face = [2 * FACTOR, 1, 1];
        let shared = nodes.iter().find(|n| n.0 == face).unwrap();
        assert!(!shared.2);
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
        let r = choose(&g, &valid, &sh, 1000);
        assert_eq!(r.cells, vec![[2, 1, 1]]);
        assert!(consistent(&g, &r));
        // Within the budget: one cell needs (F+1)³ − 8 nodes.
        let r = choose(&g, &valid, &sh, 5);
        assert!(r.is_empty());
    }

    /// The lookup in a refined cell reads its nodes (exact at a node) and meets the unrefined
    /// neighbours' bilinear faces without a jump: the constrained nodes hold the coarse value.
    #[test]
    fn the_lookup_is_exact_at_nodes_and_continuous_across_a_refined_cell() {
        let g = grid();
        let n = g.len();
        // Light that is not trilinear, so coarse and fine interpolation differ.
        let field = |p: Vec3| {
            let mut c = [Vec3::ZERO; 9];
            c[0] = Vec3::new(1.0 + p.x * p.x, 1.0 + p.y * p.z, 2.0 + (p.x * p.y).sin());
            c[1] = Vec3::splat(0.3 * p.z * p.x);
            c
        };
        let refinement = Refinement {
            cells: vec![[1, 1, 0]],
            nodes: Refinement::nodes_of(&g, &[[1, 1, 0]])
                .into_iter()
                .map(|(c, _, _)| c)
                .collect(),
        };
        assert!(consistent(&g, &refinement));
        let mut position: Vec<Vec3> = (0..n)
            .map(|i| g.position(super::super::place::unflatten(i, g.count)))
            .collect();
        position.extend(positions(&g, &refinement));
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
        };
        let at = |p: Vec3| probes.sh_at(p, |_| true);
        let close = |a: &Sh2, b: &Sh2| (0..9).all(|m| (a[m] - b[m]).abs().max_element() < 1e-4);
        // Exact at every node, gathered or constrained.
        for (i, &p) in position.iter().enumerate() {
            assert!(close(&at(p), &sh[i]), "probe {i} at {p}");
        }
        // An unconstrained node inside the refined cell keeps the field's own value.
        let centre = Vec3::new(1.5, 1.5, 0.5);
        assert!(close(&at(centre), &field(centre)));
        // Across the faces the refined cell [1, 2] × [1, 2] × [0, 1] shares with unrefined
        // cells, the values on either side agree.
        let e = 1e-4;
        for (u, v) in [(0.2, 0.3), (0.5, 0.5), (0.75, 0.1), (0.33, 0.9)] {
            for (p, d) in [
                (Vec3::new(1.0, 1.0 + u, v), Vec3::X),
                (Vec3::new(2.0, 1.0 + u, v), Vec3::X),
                (Vec3::new(1.0 + u, 2.0, v), Vec3::Y),
                (Vec3::new(1.0 + u, 1.0 + v, 1.0), Vec3::Z),
                (Vec3::new(1.0 + u, 1.0, v), Vec3::Y),
            ] {
                let (a, b) = (at(p - d * e), at(p + d * e));
                assert!(
                    (0..9).all(|m| (a[m] - b[m]).abs().max_element() < 1e-3),
                    "a jump at {p} across {d}: {:?} vs {:?}",
                    a[0],
                    b[0]
                );
            }
        }
    }
}
