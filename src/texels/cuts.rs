//! Texels divided by another surface: a zero-thickness wall standing on a floor that runs on
//! under it, a wall meeting a side wall, an object resting on a floor.
//!
//! Such a texel's footprint lies on both sides of the wall, but it holds one value. Left alone
//! it gathers from both rooms (its rays jitter over the whole footprint) and every ray that hits
//! it, from either room, reads that mix: on the `two_rooms` fixture (8 texels/m, K = 1024) the
//! partition's room-B texels next to the side walls read 0.17 where the reference has 0.08, and
//! its room-A texels there 0.82 for 0.92 — the 40 worst texels of the bake, 28% of its squared
//! error (`examples/dev/error_map.rs`). Validity ([`super::validity`]) cannot see such a wall: it
//! has no back side.
//!
//! A surface divides texel `i` when it stands across the texel's plane (more than 30° from it)
//! between the sample point and the footprint: segments from the sample point, lifted by
//! [`LIFT`] ray epsilons along the normal, to the 4 corners and 4 edge midpoints of the texel's
//! square (lifted alike) are tested for such a surface. Surfaces nearly parallel to the texel
//! (its own, a curved neighbour facet) never divide it. A divided texel then
//!
//! 1. keeps its sample on **one side**: the candidate point (the sample point and a `G × G` grid
//!    over its jitter area) with the largest clear jitter area wins (the sample point on ties),
//!    and the jitter area shrinks to what is clear of the wall, so gathering rays, and the
//!    reference's paths, start on that side only;
//! 2. **passes hits on the other side to a neighbour**: its square is cut into `CELLS × CELLS`
//!    cells; a cell whose centre cannot see the sample point is served by the nearest of the
//!    8 page neighbours facing the same way (normals within 60°) whose sample point it sees.
//!    [`Texels::texel_at`] applies this map, so a ray from room B that hits the floor just
//!    beside the wall reads the room-B texel there.
//!
//! What it costs: 8 short rays per texel, about `8·(1 + G²) + CELLS²·(1..9)` for the divided
//! ones (a strip along each wall). Limits: the lightmap still holds one value per texel, so a
//! renderer's bilinear lookup shows the other room's value within a texel of the wall (only
//! splitting charts along walls would remove that); the wall's position is resolved to
//! `1/CELLS` of a texel. Only methods that look hits up read the cell map (Monte Carlo rows,
//! the gather solver); point, polygon and hierarchical form factors integrate over whole source
//! footprints and still see both sides of a divided source texel.

use glam::{Vec2, Vec3};
use rayon::prelude::*;

use super::{NO_TEXEL, Texels};
use crate::scene::Scene;
use crate::trace::Tracer;

/// Cells per side of a divided texel's square.
pub(crate) const CELLS: usize = 8;
/// Sample points and cell centres are lifted by this many ray epsilons: above the surface's own
/// triangles, below anything that stands on it.
pub(crate) const LIFT: f32 = 4.0;
/// Hits on surfaces within 30° of the texel's plane (|cos| above this) do not divide it.
const PARALLEL_COS: f32 = 0.866;
/// Neighbours whose normals differ by more than 60° never take over a cell.
const NEIGHBOUR_COS: f32 = 0.5;
/// The clear jitter area keeps this margin from the wall.
const MARGIN: f32 = 0.95;

/// Which texel serves each cell of a divided texel ([`Texels::texel_at`] reads it).
#[derive(Clone, Debug, Default)]
pub(crate) struct Cuts {
    /// One bit per texel: set when another surface divides it. Every ray hit asks, so the
    /// answer is a bit (an L2-resident set) and not a slot per texel: a `u32` per texel made
    /// this test a cache miss on 37% of `texel_at`'s time (`perf`, the interior at `high`).
    /// Empty when no texel is divided.
    divided: Vec<u64>,
    /// The divided texels' ids, ascending, and their maps in the same order.
    ids: Vec<u32>,
    /// Row-major `CELLS × CELLS` texel ids, y down as on the page.
    cells: Vec<[u32; CELLS * CELLS]>,
}

impl Cuts {
    /// Every divided texel with its cell map, in texel order (a kept transport stores them).
    pub(crate) fn entries(&self) -> impl Iterator<Item = (u32, &[u32; CELLS * CELLS])> + '_ {
        self.ids.iter().copied().zip(&self.cells)
    }

    /// The cell maps `entries` (texel ids below `n`, ascending) of `n` texels.
    pub(crate) fn from_entries(n: usize, entries: Vec<(u32, [u32; CELLS * CELLS])>) -> Cuts {
        let mut cuts = Cuts::default();
        for (i, map) in entries {
            if cuts.divided.is_empty() {
                cuts.divided = vec![0; n.div_ceil(64)];
            }
            debug_assert!(
                cuts.ids.last().is_none_or(|&last| last < i),
                "ascending ids"
            );
            cuts.divided[i as usize / 64] |= 1 << (i % 64);
            cuts.ids.push(i);
            cuts.cells.push(map);
        }
        cuts
    }

    /// Texels with a cell map.
    pub(crate) fn len(&self) -> usize {
        self.cells.len()
    }
    /// Texel `id`'s cell map, `None` when no surface divides it.
    #[inline]
    pub(crate) fn cells(&self, id: usize) -> Option<&[u32; CELLS * CELLS]> {
        let word = *self.divided.get(id / 64)?;
        if word & (1 << (id % 64)) == 0 {
            return None;
        }
        let k = self.ids.binary_search(&(id as u32)).ok()?;
        Some(&self.cells[k])
    }
    /// The texel serving position `frac ∈ [0,1)²` within texel `id`'s square.
    #[inline]
    pub(crate) fn resolve(&self, id: u32, frac: Vec2) -> u32 {
        match self.cells(id as usize) {
            Some(cells) => {
                let c = |f: f32| ((f * CELLS as f32) as usize).min(CELLS - 1);
                cells[c(frac.y) * CELLS + c(frac.x)]
            }
            None => id,
        }
    }
}

/// What [`divide`] changed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct CutReport {
    /// Texels with a cell map: hits on part of them are passed to a neighbour.
    pub(crate) divided: usize,
    /// Texels whose sample point moved to the larger clear side.
    pub(crate) moved: usize,
}

/// Finds texels that another surface divides, keeps their samples on one side and builds the
/// cell maps ([`Texels::cuts`]). Run after [`super::validity::fix`] (it keeps the samples that
/// pass moved, and narrows their jitter only where a wall crosses it). `grid` is the candidate
/// grid per side.
pub(crate) fn divide(texels: &mut Texels, scene: &Scene, tracer: &Tracer, grid: u32) -> CutReport {
    divide_near(texels, scene, tracer, grid, None)
}

/// [`divide`] placing and mapping again only the texels `near` marks; the others keep their
/// sample points as they are and `previous`'s cell maps (an earlier pass's over the same
/// texels, where nothing within their reach changed). `None`: every texel.
pub(crate) fn divide_near(
    texels: &mut Texels,
    scene: &Scene,
    tracer: &Tracer,
    grid: u32,
    keep: Option<(&[bool], &Cuts)>,
) -> CutReport {
    let redo = |i: usize| keep.is_none_or(|(near, _)| near[i]);
    let n = texels.len();
    let mut invalid = vec![false; n];
    for &i in &texels.invalid {
        invalid[i as usize] = true;
    }
    let probe = Probe {
        scene,
        tracer,
        lift: LIFT * tracer.epsilon,
    };

    // 1. Sample point and jitter of every texel whose square a surface crosses.
    let texels_ref = &*texels;
    let placed: Vec<Option<(Vec3, f32)>> = (0..n)
        .into_par_iter()
        .map(|i| {
            if invalid[i] || !redo(i) {
                return None;
            }
            probe.place(texels_ref, i, grid.max(1))
        })
        .collect();
    let mut report = CutReport::default();
    let mut crossed = Vec::new();
    for (i, p) in placed.into_iter().enumerate() {
        if let Some((position, jitter)) = p {
            if position != texels.position[i] {
                report.moved += 1;
            }
            texels.position[i] = position;
            if let Some(j) = texels.jitter.get_mut(i) {
                *j = jitter;
            }
            crossed.push(i as u32);
        }
    }

    // 2. Cell maps, from the final sample points of the texel and its neighbours.
    let texels_ref = &*texels;
    let maps: Vec<Option<[u32; CELLS * CELLS]>> = crossed
        .par_iter()
        .map(|&i| probe.cells(texels_ref, i as usize, &invalid))
        .collect();
    // In texel order, the kept texels' maps among the new ones.
    let mut mapped: Vec<(u32, [u32; CELLS * CELLS])> = crossed
        .iter()
        .zip(maps)
        .filter_map(|(&i, map)| map.map(|m| (i, m)))
        .collect();
    if let Some((_, previous)) = keep {
        mapped.extend(
            (previous.entries())
                .filter(|&(i, _)| !redo(i as usize))
                .map(|(i, m)| (i, *m)),
        );
        mapped.sort_unstable_by_key(|&(i, _)| i);
    }
    let cuts = Cuts::from_entries(n, mapped);
    report.divided = cuts.len();
    texels.cuts = cuts;
    report
}

struct Probe<'a> {
    scene: &'a Scene,
    tracer: &'a Tracer,
    lift: f32,
}

impl Probe<'_> {
    /// Fraction of the way from `a` to `b` (both lifted) at which a surface standing across
    /// normal `n` blocks the segment; `None` when nothing does. Parallel surfaces are passed
    /// through (a curved surface's own facets, a step's tread).
    fn blocked(&self, n: Vec3, a: Vec3, b: Vec3) -> Option<f32> {
        let d = b - a;
        let len = d.length();
        if len <= self.tracer.epsilon {
            return None;
        }
        let dir = d / len;
        let mut t0 = 0.0;
        // A few parallel surfaces at most lie along one short segment.
        for _ in 0..4 {
            let hit = self.tracer.closest(a + dir * t0, dir, len - t0)?;
            let t = t0 + hit.t;
            let n_hit = self.scene.surface_point(hit.triangle, hit.bary).n_geo;
            if n_hit.dot(n).abs() < PARALLEL_COS {
                return Some(t / len);
            }
            t0 = t + self.tracer.epsilon;
            if t0 >= len {
                return None;
            }
        }
        None
    }

    /// The world centre of texel `i`'s square, from the affine map of its main triangle.
    fn square_centre(&self, texels: &Texels, i: usize) -> Option<Vec3> {
        let t = texels.triangle[i] as usize;
        let [a, b, c] = texels.triangle_uv[t];
        let [x, y] = texels.xy[i];
        let uv = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
        let (e1, e2, q) = (b - a, c - a, uv - a);
        let det = e1.perp_dot(e2);
        if det.abs() < 1e-12 {
            return None;
        }
        let (u, v) = (q.perp_dot(e2) / det, e1.perp_dot(q) / det);
        let [i0, i1, i2] = self.scene.triangles[t].map(|k| self.scene.positions[k as usize]);
        let p = i0 * (1.0 - u - v) + i1 * u + i2 * v;
        p.is_finite().then_some(p)
    }

    /// Smallest blocked fraction over the segments from `p` to the corners and edge midpoints
    /// of the parallelogram `p ± h·du ± h·dv` (1 when all are clear, 0 when `p` is inside a solid).
    fn clearance(&self, texels: &Texels, i: usize, p: Vec3, h: f32) -> f32 {
        let n = texels.normal[i];
        let (du, dv) = (texels.du[i] * h, texels.dv[i] * h);
        let from = p + n * self.lift;
        let mut clear = 1.0f32;
        for (a, b) in OFFSETS {
            let to = from + du * a + dv * b;
            if let Some(f) = self.blocked(n, from, to) {
                clear = clear.min(f);
            }
        }
        clear
    }

    /// New (position, jitter) for texel `i` when a surface crosses its square, else `None`.
    fn place(&self, texels: &Texels, i: usize, grid: u32) -> Option<(Vec3, f32)> {
        let n = texels.normal[i];
        let (du, dv) = (texels.du[i], texels.dv[i]);
        let centre = self.square_centre(texels, i)?;
        let p = texels.position[i];
        let from = p + n * self.lift;
        let crossed = OFFSETS.iter().any(|&(a, b)| {
            let to = centre + (du * a + dv * b) * 0.5 + n * self.lift;
            self.blocked(n, from, to).is_some()
        });
        if !crossed {
            return None;
        }
        // The jitter parallelogram as `Texels::footprint_point` spans it.
        let full = du.cross(dv).length();
        let cover = if full > 0.0 {
            (texels.area[i] / full).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let jitter = texels.jitter.get(i).copied().unwrap_or(1.0);
        let scale = if cover > 0.99 { 1.0 } else { cover } * jitter;
        let h = 0.5 * scale;
        let mut best = (self.clearance(texels, i, p, h), 0.0f32, p);
        if best.0 < 0.5 {
            for a in 0..grid {
                for b in 0..grid {
                    let o = (Vec2::new(a as f32 + 0.5, b as f32 + 0.5) / grid as f32 - 0.5) * scale;
                    let q = p + du * o.x + dv * o.y;
                    let clear = self.clearance(texels, i, q, h);
                    let distance = o.length();
                    if clear > best.0 || (clear == best.0 && distance < best.1) {
                        best = (clear, distance, q);
                    }
                }
            }
        }
        let narrowed = if best.0 < 1.0 {
            jitter * (best.0 * MARGIN).max(0.0)
        } else {
            jitter
        };
        Some((best.2, narrowed))
    }

    /// The cell map of texel `i`, or `None` when its own sample point serves every cell.
    fn cells(&self, texels: &Texels, i: usize, invalid: &[bool]) -> Option<[u32; CELLS * CELLS]> {
        let n = texels.normal[i];
        let centre = self.square_centre(texels, i)?;
        let sample = |k: usize| texels.position[k] + texels.normal[k] * self.lift;
        let mut neighbours: Vec<u32> = page_neighbours(texels, i)
            .filter(|&k| !invalid[k] && texels.normal[k].dot(n) >= NEIGHBOUR_COS)
            .map(|k| k as u32)
            .collect();
        let mut map = [i as u32; CELLS * CELLS];
        let mut divided = false;
        for (c, slot) in map.iter_mut().enumerate() {
            let o =
                Vec2::new((c % CELLS) as f32 + 0.5, (c / CELLS) as f32 + 0.5) / CELLS as f32 - 0.5;
            let w = centre + texels.du[i] * o.x + texels.dv[i] * o.y + n * self.lift;
            if self.blocked(n, w, sample(i)).is_none() {
                continue;
            }
            neighbours.sort_by(|&a, &b| {
                let (da, db) = (
                    w.distance_squared(sample(a as usize)),
                    w.distance_squared(sample(b as usize)),
                );
                da.total_cmp(&db).then(a.cmp(&b))
            });
            if let Some(&k) = neighbours
                .iter()
                .find(|&&k| self.blocked(n, w, sample(k as usize)).is_none())
            {
                *slot = k;
                divided = true;
            }
        }
        divided.then_some(map)
    }
}

/// Corners and edge midpoints of a parallelogram, in units of its half sides.
const OFFSETS: [(f32, f32); 8] = [
    (-1.0, -1.0),
    (1.0, -1.0),
    (-1.0, 1.0),
    (1.0, 1.0),
    (-1.0, 0.0),
    (1.0, 0.0),
    (0.0, -1.0),
    (0.0, 1.0),
];

/// Texel ids of the (up to 8) page neighbours of texel `i`.
pub(crate) fn page_neighbours(texels: &Texels, i: usize) -> impl Iterator<Item = usize> + '_ {
    let page = texels.page[i] as usize;
    let size = texels.pages[page];
    let [x, y] = texels.xy[i];
    (-1..=1i64)
        .flat_map(move |dy| (-1..=1i64).map(move |dx| (x as i64 + dx, y as i64 + dy)))
        .filter(move |&(nx, ny)| {
            (nx, ny) != (x as i64, y as i64)
                && nx >= 0
                && ny >= 0
                && nx < size.width as i64
                && ny < size.height as i64
        })
        .map(move |(nx, ny)| texels.index[page][(ny as u32 * size.width + nx as u32) as usize])
        .filter(|&j| j != NO_TEXEL)
        .map(|j| j as usize)
}
