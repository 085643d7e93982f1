//! Where probes go: a regular grid over the scene's bounds at the spacing the budget allows,
//! probes buried in solids marked invalid, probes too close to a surface moved away from it.
//!
//! **Grid.** The automatic grid spans the free space's box ([`fit`]): a sketch grid of an
//! eighth of the budget over the scene's bounds finds how far its free probes see along the
//! axes. The grid's share `N` of the budget (`ProbeParams::grid_budget`; the rest goes to
//! refinement, `super::refine`) sets the spacing `s`, the smallest for which `⌊(extent −
//! 2·CLEARANCE·s)/s⌋ + 1` probes per axis fit in `N`; the outermost probes lie `CLEARANCE·s`
//! inside the box's faces ([`spanning`]), so points beside a wall lie between probes. A node's
//! box (below) is filled cell-centred ([`grid`]: `⌊extent/s⌋` probes per axis at the centres of
//! equal cells, `s = ∛(V/N)`), so that Bevy's volume is the box.
//!
//! **From a node** (`--probes-from NODE`, [`start`]): the node's children's world positions,
//! one probe each (the artist's placement: no budget, no grid); or, when the node has no
//! children, its box — the unit cube centred on the node (side 1, Bevy's light-probe volume)
//! under its world transform — filled with the cell-centred grid in the box's own axes.
//!
//! **Buried.** From each probe `TEST_RAYS` rays go out over the sphere (a Hammersley set turned
//! by the probe's own random stream). A probe is buried — inside a closed solid, or outside
//! the closed shell of an interior, where rays meet the backs of its walls — when more than
//! `MAX_BACK` of them hit a back face (the texels' validity test, Unity's "backface
//! tolerance"). Double-sided surfaces have no back, so a probe inside a closed double-sided
//! mesh is not found (a limit).
//!
//! **Clearance.** A probe whose nearest surface is closer than `CLEARANCE` of the smallest grid
//! step (looking both ways along each test ray, so that a probe lying exactly on a surface —
//! a grid plane through a wall — finds it too) is moved straight away from it to the
//! clearance, if the move itself crosses no surface, and tested again (`NUDGES` times at most): a probe a hair from a wall reads that
//! wall at grazing angles only, and a point beside the wall interpolates it. Interpolation
//! keeps the probe's grid cell (each move is at most a fifth of a step, four moves at most).
//! A probe placed one by one takes a fifth of the distance to its nearest neighbour as its
//! step; a probe a refinement adds, the refined lattice's step.

use std::path::Path;

use glam::{Quat, Vec2, Vec3};
use rayon::prelude::*;

use super::{Grid, ProbeParams};
use crate::sampling::{Rng, hammersley, uniform_sphere};
use crate::scene::{Scene, SceneNode};
use crate::texels::validity::MAX_BACK;
use crate::trace::Tracer;
use crate::{Error, Result};

/// Rays per probe of the buried test.
const TEST_RAYS: u32 = 64;
/// Wanted distance from the nearest surface, as a fraction of the smallest grid step.
pub(crate) const CLEARANCE: f32 = 0.2;
/// Moves away from a surface at most.
const NUDGES: u32 = 3;
/// Random-stream purpose of the buried test (the gather uses its own).
const PLACE: u64 = 1;
/// Random-stream purpose of the sketch grid's buried test ([`fit`]).
const FIT: u64 = 3;

/// The grid and what the tests found, before any light is gathered.
#[derive(Clone, Debug)]
pub(crate) struct Placement {
    /// The grid the probes are on (`None`: placed one by one).
    pub(crate) grid: Option<Grid>,
    /// Where each probe is (its grid or given position, or moved off a surface); on a grid, x
    /// fastest, then y, z.
    pub(crate) position: Vec<Vec3>,
    /// Not buried.
    pub(crate) valid: Vec<bool>,
    /// Probes moved away from a surface.
    pub(crate) moved: usize,
    /// Rays the tests cast.
    pub(crate) rays: u64,
}

/// Where the probes start, before the tests.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Start {
    /// The automatic grid of `budget` probes over the free space within the bounds `lo..hi`
    /// ([`fit`]: the free space is found with the tracer).
    Fit { lo: Vec3, hi: Vec3, budget: u32 },
    /// A grid (filling a node's box).
    Grid(Grid),
    /// Positions given one by one (a node's children).
    Points(Vec<Vec3>),
}

/// Where the probes of `params` start in `scene`: the automatic grid over the scene's bounds,
/// or the node [`ProbeParams::from`] names (`input` names the glTF in errors).
pub(crate) fn start(scene: &Scene, params: &ProbeParams, input: &Path) -> Result<Start> {
    let budget = params.grid_budget();
    let Some(name) = &params.from else {
        let (lo, hi) = bounds(scene).unwrap_or((Vec3::ZERO, Vec3::ZERO));
        return Ok(Start::Fit { lo, hi, budget });
    };
    let named: Vec<&SceneNode> = (scene.nodes.iter())
        .filter(|n| n.name.as_deref() == Some(name.as_str()))
        .collect();
    let node = match named[..] {
        [node] => node,
        [] => {
            return Err(Error::invalid(
                input,
                format!(
                    "--probes-from {name:?}: the scene has no node of that name (probes are placed \
                     at an empty node's children, or fill its box when it has none)"
                ),
            ));
        }
        _ => {
            return Err(Error::invalid(
                input,
                format!(
                    "--probes-from {name:?}: {} nodes of the scene have that name; give one a name of its own",
                    named.len()
                ),
            ));
        }
    };
    if !node.children.is_empty() {
        // The children's world positions (the loader visits every child of a scene node).
        let positions = (node.children.iter())
            .filter_map(|&c| scene.nodes.iter().find(|n| n.index == c))
            .map(|n| n.world.w_axis.truncate())
            .collect();
        return Ok(Start::Points(positions));
    }
    // The unit cube centred on the node under its transform (Bevy's light-probe volume); a
    // mirroring scale keeps the same box.
    let (scale, rotation, translation) = node.world.to_scale_rotation_translation();
    let size = scale.abs();
    if !(size.min_element() > 0.0 && size.is_finite() && rotation.is_finite()) {
        return Err(Error::invalid(
            input,
            format!(
                "--probes-from {name:?}: the node has no children and its box (the unit cube under \
                 its transform) is flat: scale {scale}"
            ),
        ));
    }
    let (origin, step, count) = grid(-size * 0.5, size * 0.5, budget);
    Ok(Start::Grid(Grid {
        origin: translation + rotation * origin,
        step,
        count,
        rotation,
    }))
}

/// The scene's bounding box over its triangles' vertices (`None` without triangles).
pub(crate) fn bounds(scene: &Scene) -> Option<(Vec3, Vec3)> {
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for t in &scene.triangles {
        for &v in t {
            let p = scene.positions[v as usize];
            lo = lo.min(p);
            hi = hi.max(p);
        }
    }
    (lo.x <= hi.x).then_some((lo, hi))
}

/// The grid for `budget` probes over the box `lo..hi`: (origin, step, count).
pub(crate) fn grid(lo: Vec3, hi: Vec3, budget: u32) -> (Vec3, Vec3, [u32; 3]) {
    let extent = (hi - lo).max(Vec3::ZERO);
    // The spacing over the axes longer than it (a flat scene, a floor alone, gets one layer):
    // `s = (Π extent / budget)^(1/d)` over those d axes, shrinking d while an axis is shorter.
    let mut long = [true; 3];
    let mut s = 0.0f32;
    for _ in 0..3 {
        let d = long.iter().filter(|&&l| l).count();
        let product: f32 = (0..3).filter(|&a| long[a]).map(|a| extent[a]).product();
        s = match d {
            0 => 1.0,
            d => (product / budget.max(1) as f32).powf(1.0 / d as f32),
        };
        let shorter = (0..3)
            .filter(|&a| long[a] && extent[a] < s)
            .collect::<Vec<_>>();
        if shorter.is_empty() {
            break;
        }
        shorter.into_iter().for_each(|a| long[a] = false);
    }
    let count = std::array::from_fn(|a| match long[a] && s > 0.0 {
        true => ((extent[a] / s + 1e-3).floor() as u32).max(1),
        false => 1,
    });
    let cell = Vec3::from(count.map(|c| c as f32));
    // One probe on an axis: at the middle; its step only sets the clearance.
    let step = Vec3::from(std::array::from_fn::<f32, 3, _>(|a| match count[a] {
        1 => s.max(extent[a]),
        c => extent[a] / c as f32,
    }));
    (lo + extent / cell * 0.5, step, count)
}

/// Probes of the sketch [`fit`] tests, as a share of the budget.
const SKETCH: u32 = 8;

/// The automatic grid for `budget` probes within the bounds `lo..hi`, and the rays cast: a
/// sketch grid of an eighth of the budget finds the free space's box (from each of its
/// probes that is not buried, a ray along each axis both ways; the box reaches the farthest
/// surface any of them meets, or the bounds where a ray escapes), and the grid spans that box
/// with its outermost probes a clearance from the box's faces ([`spanning`]). So a room whose
/// walls are solids gets probes up to its inner faces, not in its walls, and points beside a
/// wall or under a ceiling light lie between probes, not beyond the outermost ones.
pub(crate) fn fit(tracer: &Tracer, (lo, hi): (Vec3, Vec3), budget: u32, seed: u64) -> (Grid, u64) {
    let (origin, step, count) = grid(lo, hi, (budget / SKETCH).max(8));
    let sketch = Grid {
        origin,
        step,
        count,
        rotation: Quat::IDENTITY,
    };
    let axes = [Vec3::X, Vec3::Y, Vec3::Z];
    let found: Vec<Option<(Vec3, Vec3)>> = (0..sketch.len())
        .into_par_iter()
        .map(|i| {
            let p = sketch.position(unflatten(i, count));
            let shift = Rng::new(seed, i as u64, FIT).next_vec2();
            if buried(tracer, p, shift) {
                return None;
            }
            let (mut low, mut high) = (lo, hi);
            for (a, &axis) in axes.iter().enumerate() {
                if let Some(hit) = tracer.closest(p, axis, f32::INFINITY) {
                    high[a] = (p[a] + hit.t).min(hi[a]);
                }
                if let Some(hit) = tracer.closest(p, -axis, f32::INFINITY) {
                    low[a] = (p[a] - hit.t).max(lo[a]);
                }
            }
            Some((low, high))
        })
        .collect();
    let rays = sketch.len() as u64 * u64::from(TEST_RAYS + 6);
    // The farthest any free probe sees along each axis (the bounds without any).
    let (mut free_lo, mut free_hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
    for (low, high) in found.iter().flatten() {
        free_lo = free_lo.min(*low);
        free_hi = free_hi.max(*high);
    }
    if !(free_lo.cmple(free_hi).all()) {
        (free_lo, free_hi) = (lo, hi);
    }
    let (origin, step, count) = spanning(free_lo, free_hi, budget);
    let grid = Grid {
        origin,
        step,
        count,
        rotation: Quat::IDENTITY,
    };
    (grid, rays)
}

/// The grid of at most `budget` probes spanning the box `lo..hi`: (origin, step, count). Its
/// outermost probes lie `CLEARANCE` of the spacing inside the box's faces (what the
/// clearance test would move them to), the others evenly between; an axis shorter than the
/// spacing gets one probe, at its middle.
pub(crate) fn spanning(lo: Vec3, hi: Vec3, budget: u32) -> (Vec3, Vec3, [u32; 3]) {
    let extent = (hi - lo).max(Vec3::ZERO);
    // From below the cell-centred grid's spacing, widened until the probes fit the budget.
    let (_, start, cells) = grid(lo, hi, budget);
    let finest = (0..3)
        .filter(|&a| cells[a] > 1)
        .map(|a| start[a])
        .fold(f32::INFINITY, f32::min);
    let mut s = match finest.is_finite() {
        true => 0.8 * finest,
        false => start.max_element(),
    }
    .max(1e-6);
    let (mut count, mut inner) = ([1u32; 3], extent);
    for _ in 0..1000 {
        inner = (extent - Vec3::splat(2.0 * CLEARANCE * s)).max(Vec3::ZERO);
        count = std::array::from_fn(|a| match extent[a] >= s {
            true => (inner[a] / s + 1e-3).floor() as u32 + 1,
            false => 1,
        });
        if count.iter().map(|&c| u64::from(c)).product::<u64>() <= u64::from(budget.max(1)) {
            break;
        }
        s *= 1.01;
    }
    let step = Vec3::from(std::array::from_fn::<f32, 3, _>(|a| match count[a] {
        1 => s.max(extent[a]),
        c => inner[a] / (c - 1) as f32,
    }));
    let origin = Vec3::from(std::array::from_fn::<f32, 3, _>(|a| match count[a] {
        1 => lo[a] + extent[a] * 0.5,
        _ => lo[a] + (extent[a] - inner[a]) * 0.5,
    }));
    (origin, step, count)
}

/// Tests the probes from `start` (see the module docs), each probe's streams seeded by `seed`
/// and its index.
pub(crate) fn place(tracer: &Tracer, start: Start, seed: u64) -> Placement {
    let (start, fit_rays) = match start {
        Start::Fit { lo, hi, budget } => {
            let (grid, rays) = fit(tracer, (lo, hi), budget, seed);
            (Start::Grid(grid), rays)
        }
        other => (other, 0),
    };
    let (grid, positions, clearance) = match start {
        Start::Fit { .. } => unreachable!("fitted above"),
        Start::Grid(g) => {
            let positions = (0..g.len()).map(|i| g.position(unflatten(i, g.count)));
            let clearance = vec![CLEARANCE * g.step.min_element(); g.len()];
            (Some(g), positions.collect(), clearance)
        }
        Start::Points(p) => {
            // A fifth of the way to the nearest other probe (none: not moved), as on a grid.
            let clearance = (0..p.len())
                .map(|i| {
                    let nearest = (0..p.len())
                        .filter(|&j| j != i)
                        .map(|j| p[i].distance(p[j]))
                        .fold(f32::INFINITY, f32::min);
                    if nearest.is_finite() {
                        CLEARANCE * nearest
                    } else {
                        0.0
                    }
                })
                .collect();
            (None, p, clearance)
        }
    };
    let mut placement = settle_all(tracer, &positions, &clearance, seed, 0);
    placement.grid = grid;
    placement.rays += fit_rays;
    placement
}

/// Tests the probes at `positions` (entries `first..` of the probes: each probe's stream is
/// seeded by `seed` and its index), each moved off surfaces to its `clearance`.
pub(crate) fn settle_all(
    tracer: &Tracer,
    positions: &[Vec3],
    clearance: &[f32],
    seed: u64,
    first: usize,
) -> Placement {
    let tested: Vec<(Vec3, bool, bool, u64)> = (0..positions.len())
        .into_par_iter()
        .map(|i| {
            let shift = Rng::new(seed, (first + i) as u64, PLACE).next_vec2();
            settle(tracer, positions[i], shift, clearance[i])
        })
        .collect();
    Placement {
        grid: None,
        position: tested.iter().map(|t| t.0).collect(),
        valid: tested.iter().map(|t| t.1).collect(),
        moved: tested.iter().filter(|t| t.2).count(),
        rays: tested.iter().map(|t| t.3).sum(),
    }
}

/// Grid index (i, j, k) of flat index `i` (x fastest).
#[inline]
pub(crate) fn unflatten(i: usize, count: [u32; 3]) -> [u32; 3] {
    let (nx, ny) = (count[0] as usize, count[1] as usize);
    [
        (i % nx) as u32,
        ((i / nx) % ny) as u32,
        (i / (nx * ny)) as u32,
    ]
}

/// The probe that starts at `p`: (where it ends, not buried, moved, rays cast).
fn settle(tracer: &Tracer, mut p: Vec3, shift: Vec2, clearance: f32) -> (Vec3, bool, bool, u64) {
    let limit = (MAX_BACK * TEST_RAYS as f32) as u32;
    let mut moved = false;
    let mut rays = 0;
    for _ in 0..=NUDGES {
        let (back, nearest) = look_around(tracer, p, shift, clearance);
        rays += 2 * u64::from(TEST_RAYS);
        if back > limit {
            return (p, false, moved, rays);
        }
        match nearest {
            Some((t, dir)) if t < clearance => {
                let to = p - dir * (clearance - t);
                rays += 1;
                // Tested from where it goes: the surface `p` lies on (the one it moves off)
                // is in the segment's untested last epsilon.
                if tracer.occluded(to, p) {
                    break;
                }
                p = to;
                moved = true;
            }
            _ => break,
        }
    }
    (p, true, moved, rays)
}

/// Up to `n` random points with random unit normals: point `k` comes from its own stream
/// `(salt, k)`, at `at(u)` for a point `u` of the unit cube, and is kept when it is not buried
/// and `keep` accepts it; at most 200 draws per point asked.
pub(crate) fn free_points(
    tracer: &Tracer,
    n: usize,
    salt: u64,
    at: impl Fn(Vec3) -> Vec3,
    mut keep: impl FnMut(Vec3) -> bool,
) -> Vec<(Vec3, Vec3)> {
    let mut points = Vec::with_capacity(n);
    for k in 0..(n as u64).saturating_mul(200) {
        if points.len() == n {
            break;
        }
        let mut rng = Rng::new(salt, k, 0);
        let p = at(Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()));
        let normal = uniform_sphere(rng.next_vec2());
        if !buried(tracer, p, rng.next_vec2()) && keep(p) {
            points.push((p, normal));
        }
    }
    points
}

/// Whether the point `p` is buried (the probes' test, its rays turned by `shift`).
pub(crate) fn buried(tracer: &Tracer, p: Vec3, shift: Vec2) -> bool {
    look_around(tracer, p, shift, 0.0).0 > (MAX_BACK * TEST_RAYS as f32) as u32
}

/// Back-face hits of `TEST_RAYS` rays from `p`, and the nearest surface along them (distance,
/// direction towards it). Along each direction a second ray comes back through `p` from `reach` away: the
/// tracer loses hits closer than its entry clamp (see `trace`), so a probe lying on a surface
/// (a grid plane through a wall) would not see the surface it lies on from there.
fn look_around(tracer: &Tracer, p: Vec3, shift: Vec2, reach: f32) -> (u32, Option<(f32, Vec3)>) {
    let mut back = 0;
    let mut nearest: Option<(f32, Vec3)> = None;
    let mut closer = |t: f32, dir: Vec3| {
        if nearest.is_none_or(|(n, _)| t < n) {
            nearest = Some((t, dir));
        }
    };
    for k in 0..TEST_RAYS {
        let dir = uniform_sphere(hammersley(k, TEST_RAYS, shift));
        if let Some(hit) = tracer.closest(p, dir, f32::INFINITY) {
            back += u32::from(!hit.front);
            closer(hit.t, dir);
        }
        // Back from `reach` beyond `p` to `reach` before it: a surface through `p` lies
        // mid-way, away from both ends.
        if reach > 0.0
            && let Some(hit) = tracer.closest(p + dir * reach, -dir, 2.0 * reach)
        {
            let toward = if hit.t <= reach { dir } else { -dir };
            closer((reach - hit.t).abs(), toward);
        }
    }
    (back, nearest)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_grid_keeps_to_the_budget_and_centres_its_cells() {
        let (lo, hi) = (Vec3::new(-2.0, 0.0, -1.0), Vec3::new(2.0, 2.0, 1.0));
        let (origin, step, count) = grid(lo, hi, 1024);
        assert_eq!(count, [16, 8, 8]);
        assert!((step - Vec3::splat(0.25)).abs().max_element() < 1e-5);
        assert!((origin - (lo + step * 0.5)).abs().max_element() < 1e-5);
        for budget in [1, 7, 100, 999, 5000] {
            let (_, _, c) = grid(lo, hi, budget);
            assert!(c[0] * c[1] * c[2] <= budget.max(1), "{budget}: {c:?}");
        }
        // A flat scene gets one layer, in its plane.
        let (origin, _, count) = grid(Vec3::ZERO, Vec3::new(4.0, 0.0, 4.0), 100);
        assert_eq!(count[1], 1);
        assert_eq!(origin.y, 0.0);
    }

    #[test]
    fn the_spanning_grid_keeps_to_the_budget_and_reaches_the_faces() {
        let (lo, hi) = (Vec3::new(-2.0, 0.0, -1.0), Vec3::new(2.0, 2.0, 1.0));
        for budget in [100, 512, 1024, 4096] {
            let (origin, step, count) = spanning(lo, hi, budget);
            assert!(
                count.iter().product::<u32>() <= budget,
                "{budget}: {count:?}"
            );
            // Nearly all of the budget: one more probe along the longest axis would not fit.
            let more = (count[0] + 1) * count[1] * count[2];
            assert!(more > budget / 2, "{budget}: {count:?} wastes the budget");
            let last = origin + step * Vec3::from(count.map(|c| (c - 1) as f32));
            for a in 0..3 {
                let (low, high) = (origin[a] - lo[a], hi[a] - last[a]);
                assert!((low - high).abs() < 1e-4, "{budget}: not centred along {a}");
                assert!(
                    low > 0.0 && low <= CLEARANCE * step[a] + 1e-5,
                    "{budget}: {low} from the face"
                );
            }
        }
        // A flat box gets one layer, in its plane.
        let (origin, _, count) = spanning(Vec3::ZERO, Vec3::new(4.0, 0.0, 4.0), 100);
        assert_eq!(count[1], 1);
        assert_eq!(origin.y, 0.0);
    }
}
