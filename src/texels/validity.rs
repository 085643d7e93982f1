//! Texel validity and sample placement: keeps sample points out of geometry.
//!
//! A texel's sample point is the centroid of its covered footprint. Where geometry intersects or
//! rests on a surface (a box standing on the floor, a wall piercing a floor) the centroid can lie
//! inside a closed, single-sided solid; gathering rays from there hit back faces (absorbed) and
//! the texel turns black, and bilinear filtering spreads that black along the contact line.
//!
//! For each texel, `R` short cosine-distributed rays leave the sample point (lifted by the ray
//! epsilon) and count back-face hits within `reach = REACH·s`, `s = √|du × dv|` the texel's world
//! side:
//!
//! ```text
//!   b(p) = #{ k < R : ray(p, ω_k) hits a back face at t ≤ reach }
//! ```
//!
//! If `b(centroid) > 0`, a `G × G` grid of candidate points over the footprint
//! (`centroid + s·du + t·dv`, `s, t ∈ {(a + ½)/G − ½}`, scaled by the covered fraction for
//! partly covered texels, as the gathering rays are) is tested with the same directions, and
//! the texel moves to the candidate with the fewest back hits (the nearest to the centroid on
//! ties) when it has fewer than the centroid. If even that has more than `MAX_BACK·R` back hits,
//! the texel is **invalid**: it is still solved (it absorbs light, so energy stays correct), but
//! its value is replaced by [`fill_invalid`] with the mean of valid neighbours on its page
//! (same chart, normals within 60°), ring by ring, before dilation. An invalid texel with no
//! valid texel in reach keeps its solved (dark) value.
//!
//! | parameter  | default | meaning                                                          |
//! |------------|---------|------------------------------------------------------------------|
//! | `rays` R   | 16      | probe rays per point (same directions for every candidate)        |
//! | `MAX_BACK` | 0.25    | more than this fraction of back hits ⇒ inside geometry (as Unity's backface tolerance, Bakery) |
//! | `REACH`    | 8       | probe length in texel sides: finds the inside of solids up to ~8 texels across |
//! | `grid` G   | 4       | candidate points per side of the footprint                        |
//!
//! When to use: always (it costs `R` rays per texel, `R·(1 + G²)` for texels near back faces).
//! Limits: only single-sided solids are detected — a zero-thickness double-sided wall has no
//! back side; [`fix`] hands texels such a wall divides to `cuts.rs` next. Solids deeper than `REACH`
//! texels leave their inner texels black but valid (never visible). A moved texel's gathering
//! rays jitter within the candidate cell around its new point (`Texels::jitter` = 1/G), not
//! over the whole footprint, which would start some of them back inside the solid.

use std::sync::atomic::{AtomicBool, Ordering};

use glam::{Vec2, Vec3};

use super::Texels;
use super::cuts::{self, page_neighbours};
use crate::sampling::{Rng, cosine_hemisphere, frame, hammersley};
use crate::scene::Scene;
use crate::shard::{self, Alone, Packed, Shards, flag};
use crate::trace::Tracer;
use crate::{Error, Progress, Result};

/// Random-stream purpose of the probe directions (distinct from the transport's streams).
const PURPOSE: u64 = 0x7a11_d17e;
/// More than this fraction of probe rays on back faces ⇒ the point is inside geometry.
pub(crate) const MAX_BACK: f32 = 0.25;
/// Probe rays per point: the validity pass's default, and what the point samples of the planner
/// and the point reference cast to tell a visible point from one inside geometry.
pub(crate) const PROBE_RAYS: u32 = 16;
/// Candidate points per side of a footprint (the module docs' `G`).
pub(crate) const GRID: u32 = 4;
/// Probe length in texel sides.
pub(crate) const REACH: f32 = 8.0;
/// Neighbours whose normals differ by more than this (cosine of 60°) do not fill each other.
const FILL_COS: f32 = 0.5;

/// Probe settings (see the module docs).
#[derive(Clone, Debug)]
pub struct ValidityParams {
    pub(crate) rays: u32,
    pub(crate) grid: u32,
    pub(crate) seed: u64,
}

impl Default for ValidityParams {
    fn default() -> Self {
        ValidityParams {
            rays: PROBE_RAYS,
            grid: GRID,
            seed: 0,
        }
    }
}

/// What [`fix`] changed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ValidityReport {
    /// Texels whose sample point moved within the footprint.
    pub moved: usize,
    /// Texels with no valid point (listed in [`Texels::invalid`]).
    pub invalid: usize,
    /// Texels another surface divides (a wall standing on them; see `Cuts`).
    pub divided: usize,
}

/// Moves sample points out of geometry, records invalid texels in `texels.invalid`, then keeps
/// the samples of texels another surface divides on one side (`cuts::divide`).
/// Stops with [`Error::Aborted`] soon after `progress` is aborted.
pub fn fix(
    texels: &mut Texels,
    scene: &Scene,
    tracer: &Tracer,
    params: &ValidityParams,
    progress: &dyn Progress,
) -> Result<ValidityReport> {
    fix_sharded(texels, scene, tracer, params, &Alone, progress)
}

/// [`fix`] with the texels' probes divided among `shards`.
pub(crate) fn fix_sharded(
    texels: &mut Texels,
    scene: &Scene,
    tracer: &Tracer,
    params: &ValidityParams,
    shards: &dyn Shards,
    progress: &dyn Progress,
) -> Result<ValidityReport> {
    let grid = params.grid.max(1);
    let outcome = probe(texels, tracer, params, None, shards, progress)?;
    let mut report = ValidityReport::default();
    texels.invalid.clear();
    for (i, Probed { moved, invalid }) in outcome.into_iter().enumerate() {
        if let Some(p) = moved {
            texels.position[i] = p;
            if let Some(j) = texels.jitter.get_mut(i) {
                *j = 1.0 / grid as f32;
            }
            report.moved += 1;
        }
        if invalid {
            texels.invalid.push(i as u32);
        }
    }
    report.invalid = texels.invalid.len();
    let divided = cuts::divide(texels, scene, tracer, grid);
    report.moved += divided.moved;
    report.divided = divided.divided;
    Ok(report)
}

/// [`fix_sharded`] after an edit confined to `changed` (world boxes around what moved, where it
/// was and where it is): a texel whose probe rays, candidate points and cut cells stay farther
/// than its [`REACH`] (and four texel sides) from every box sees the same geometry as before
/// and keeps `previous`'s results (the same layout's texels after a pass over the scene before
/// the edit: sample point, jitter, invalid, cell map); only the others are probed. The texels
/// come out as a full pass leaves them (`tests/incremental.rs` compares them bit for bit),
/// except where a probe ray meets two surfaces at the same distance (a rug's underside on the
/// floor): which one the BVH reports depends on its build, so a full pass over the edited
/// scene can differ there from the pass before it, far from the edit (34 of the furnished
/// interior's 148,505 texels, a chair moved 1.5 m away; 7 of them invalid in one pass and not
/// the other). Keeping the earlier result is as right, and re-traces fewer rows. `texels` are
/// fresh from `texels::build`; the report counts as moved every texel whose sample point is
/// not where the raster put it. Texels beyond `previous`'s (an added node's) are all probed.
#[allow(clippy::too_many_arguments)]
pub(crate) fn fix_near(
    texels: &mut Texels,
    previous: &Texels,
    changed: &[(Vec3, Vec3)],
    scene: &Scene,
    tracer: &Tracer,
    params: &ValidityParams,
    shards: &dyn Shards,
    progress: &dyn Progress,
) -> Result<ValidityReport> {
    let n = texels.len();
    let grid = params.grid.max(1);
    let near: Vec<bool> = (0..n)
        .map(|i| {
            let (du, dv) = (texels.du[i], texels.dv[i]);
            let margin = reach(texels, tracer, i) + 4.0 * (du.length() + dv.length());
            let p = texels.position[i];
            // A texel `previous` does not have (an added node's, on a page of its own) is new.
            i >= previous.len()
                || changed
                    .iter()
                    .any(|&(lo, hi)| (lo - p).max(p - hi).max(Vec3::ZERO).length() <= margin)
        })
        .collect();
    let redo: Vec<usize> = (0..n).filter(|&i| near[i]).collect();
    let raw = texels.position.clone();
    let outcome = probe(texels, tracer, params, Some(&redo), shards, progress)?;
    let mut invalid = vec![false; n];
    for &i in &previous.invalid {
        invalid[i as usize] = !near[i as usize];
    }
    for i in (0..n).filter(|&i| !near[i]) {
        texels.position[i] = previous.position[i];
        if let (Some(j), Some(&was)) = (texels.jitter.get_mut(i), previous.jitter.get(i)) {
            *j = was;
        }
    }
    for (
        &i,
        Probed {
            moved,
            invalid: buried,
        },
    ) in redo.iter().zip(outcome)
    {
        if let Some(p) = moved {
            texels.position[i] = p;
            if let Some(j) = texels.jitter.get_mut(i) {
                *j = 1.0 / grid as f32;
            }
        }
        invalid[i] = buried;
    }
    texels.invalid = (0..n as u32).filter(|&i| invalid[i as usize]).collect();
    let divided = cuts::divide_near(texels, scene, tracer, grid, Some((&near, &previous.cuts)));
    Ok(ValidityReport {
        moved: (0..n).filter(|&i| texels.position[i] != raw[i]).count(),
        invalid: texels.invalid.len(),
        divided: divided.divided,
    })
}

/// What the probes find at texels `ids` (all of them for `None`), divided among `shards`.
fn probe(
    texels: &Texels,
    tracer: &Tracer,
    params: &ValidityParams,
    ids: Option<&[usize]>,
    shards: &dyn Shards,
    progress: &dyn Progress,
) -> Result<Vec<Probed>> {
    let (rays, grid) = (params.rays.max(1), params.grid.max(1));
    let limit = (MAX_BACK * rays as f32) as u32;
    let aborted = AtomicBool::new(false);
    let count = ids.map_or(texels.len(), <[usize]>::len);
    let outcome = shard::map(shards, count, |k| {
        // Once per texel: a few dozen rays each, so the check costs nothing.
        if aborted.load(Ordering::Relaxed) || progress.aborted() {
            aborted.store(true, Ordering::Relaxed);
            return Probed::default();
        }
        let i = ids.map_or(k, |ids| ids[k]);
        let (moved, invalid) = probe_texel(texels, tracer, i, rays, grid, limit, params.seed);
        Probed { moved, invalid }
    })?;
    if aborted.into_inner() {
        return Err(Error::Aborted);
    }
    Ok(outcome)
}

/// How far texel `i`'s probe rays look for back faces: [`REACH`] texel sides, at least a few
/// ray offsets.
fn reach(texels: &Texels, tracer: &Tracer, i: usize) -> f32 {
    let full = texels.du[i].cross(texels.dv[i]).length();
    (REACH * full.sqrt()).max(8.0 * tracer.epsilon)
}

/// What the probes found at one texel.
#[derive(Clone, Copy, Debug, Default)]
struct Probed {
    /// The new sample point, when it moved.
    moved: Option<Vec3>,
    /// No candidate point is outside geometry.
    invalid: bool,
}

impl Packed for Probed {
    const FLOATS: usize = 5;
    fn pack(&self, out: &mut Vec<f32>) {
        let p = self.moved.unwrap_or(Vec3::ZERO);
        out.extend([
            p.x,
            p.y,
            p.z,
            flag(self.moved.is_some()),
            flag(self.invalid),
        ]);
    }
    fn unpack(v: &[f32]) -> Self {
        Probed {
            moved: (v[3] != 0.0).then(|| Vec3::new(v[0], v[1], v[2])),
            invalid: v[4] != 0.0,
        }
    }
}

/// (new position if moved, invalid) for texel `i`.
fn probe_texel(
    texels: &Texels,
    tracer: &Tracer,
    i: usize,
    rays: u32,
    grid: u32,
    limit: u32,
    seed: u64,
) -> (Option<Vec3>, bool) {
    let n = texels.normal[i];
    let (du, dv) = (texels.du[i], texels.dv[i]);
    let full = du.cross(dv).length();
    let reach = reach(texels, tracer, i);
    let shift = Rng::new(seed, i as u64, PURPOSE).next_vec2();
    let back_hits = |p: Vec3| back_hits(tracer, p, n, rays, shift, reach);

    let centroid = texels.position[i];
    let at_centroid = back_hits(centroid);
    if at_centroid == 0 {
        return (None, false);
    }
    // Candidates over the covered footprint, as the gathering rays sample it.
    let cover = if full > 0.0 {
        (texels.area[i] / full).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let scale = if cover > 0.99 { 1.0 } else { cover };
    let mut best = (at_centroid, 0.0f32, centroid);
    for a in 0..grid {
        for b in 0..grid {
            let o = (Vec2::new(a as f32 + 0.5, b as f32 + 0.5) / grid as f32 - 0.5) * scale;
            let distance = o.length();
            if (best.0, best.1) <= (0, distance) {
                continue; // cannot beat the best
            }
            let p = centroid + du * o.x + dv * o.y;
            let b = back_hits(p);
            if (b, distance) < (best.0, best.1) {
                best = (b, distance, p);
            }
        }
    }
    let moved = (best.0 < at_centroid).then_some(best.2);
    (moved, best.0 > limit)
}

/// How many of `rays` cosine-distributed probe rays (Hammersley points shifted by `shift`) from
/// the surface point `p` with normal `n` (lifted here by the ray epsilon) hit a back face within
/// `reach`: the inside-geometry test of texels, and of the points of
/// [`crate::reference::points`].
pub(crate) fn back_hits(
    tracer: &Tracer,
    p: Vec3,
    n: Vec3,
    rays: u32,
    shift: Vec2,
    reach: f32,
) -> u32 {
    let (tx, ty) = frame(n);
    let origin = p + n * tracer.epsilon;
    (0..rays)
        .filter(|&k| {
            let local = cosine_hemisphere(hammersley(k, rays, shift));
            let dir = tx * local.x + ty * local.y + n * local.z;
            tracer
                .closest(origin, dir, reach)
                .is_some_and(|hit| !hit.front && hit.t <= reach)
        })
        .count() as u32
}

/// Replaces the values of invalid texels by the mean of their valid page neighbours (8-connected,
/// normals within 60°), ring by ring from the valid ones inwards; each ring reads only values
/// known before it, so the result does not depend on order. Filled texels count as valid for the
/// next ring. Invalid texels no valid texel reaches keep their value.
pub fn fill_invalid(texels: &Texels, values: &mut [Vec3]) {
    if texels.invalid.is_empty() {
        return;
    }
    let mut known = texels.valid_mask();
    let mut pending: Vec<u32> = texels.invalid.clone();
    let mut ring: Vec<(u32, Vec3)> = Vec::with_capacity(pending.len());
    loop {
        ring.clear();
        for &i in &pending {
            let i = i as usize;
            let (sum, count) = page_neighbours(texels, i)
                .filter(|&j| known[j] && texels.normal[j].dot(texels.normal[i]) >= FILL_COS)
                .fold((Vec3::ZERO, 0u32), |(s, c), j| (s + values[j], c + 1));
            if count > 0 {
                let mean = sum / count as f32;
                ring.push((i as u32, if mean.is_finite() { mean } else { Vec3::ZERO }));
            }
        }
        if ring.is_empty() {
            break;
        }
        for &(i, v) in &ring {
            values[i as usize] = v;
            known[i as usize] = true;
        }
        pending.retain(|&i| !known[i as usize]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::atlas::PageSize;

    /// A 5 × 1 strip of texels on one page, facing up, the middle three invalid.
    fn strip() -> Texels {
        let n = 5;
        Texels {
            pages: vec![PageSize {
                width: 5,
                height: 1,
            }],
            normal: vec![Vec3::Y; n],
            page: vec![0; n],
            xy: (0..n as u32).map(|x| [x, 0]).collect(),
            index: vec![(0..n as u32).collect()],
            position: vec![Vec3::ZERO; n],
            invalid: vec![1, 2, 3],
            ..Texels::default()
        }
    }

    #[test]
    fn invalid_texels_fill_ring_by_ring_from_valid_neighbours() {
        let texels = strip();
        let (a, b) = (Vec3::splat(1.0), Vec3::splat(3.0));
        let mut values = vec![a, Vec3::ZERO, Vec3::ZERO, Vec3::ZERO, b];
        fill_invalid(&texels, &mut values);
        assert_eq!(values, [a, a, (a + b) / 2.0, b, b]);
    }

    #[test]
    fn texels_facing_away_or_unreached_keep_their_value() {
        let mut texels = strip();
        texels.normal[0] = -Vec3::Y; // a fold: not the same surface
        texels.invalid = vec![1];
        let mut values = vec![
            Vec3::ONE,
            Vec3::splat(0.5),
            Vec3::splat(2.0),
            Vec3::ZERO,
            Vec3::ZERO,
        ];
        fill_invalid(&texels, &mut values);
        assert_eq!(
            values[1],
            Vec3::splat(2.0),
            "only the neighbour facing the same way"
        );
        texels.invalid = vec![0, 1, 2, 3, 4];
        let before = values.clone();
        fill_invalid(&texels, &mut values);
        assert_eq!(values, before, "nothing valid to fill from");
    }
}
