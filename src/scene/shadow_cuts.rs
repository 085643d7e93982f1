//! Shadow cuts: discontinuity meshing for the hard shadows of punctual lights (Heckbert 1992,
//! Lischinski et al. 1992), as more cuts for the junction split ([`super::junctions`]).
//!
//! Why: a texel holds one value and a renderer filters bilinearly, so a hard shadow edge of a
//! sun, point or spot light is blurred over one texel on each side whatever the density (the
//! point error falls only like the square root of the texel size). Cut along the edge, each
//! side gets its own chart and its texels hold only lit or only shadowed light.
//!
//! For each flat receiver patch (the junction split's) and each punctual light the patch faces:
//! 1. **Outline candidates**: the occluders' silhouette edges with respect to the light (an
//!    edge between a triangle facing it and one facing away, or an open boundary edge; front
//!    instances only, welded across the scene, found once per light) are clipped to the space
//!    between the patch's plane and the light and projected onto the plane (along the direction
//!    for a sun, from the position for a point or spot light), then clipped to the patch. An
//!    edge lying in the plane is a junction, already cut; stretches shorter than a texel are
//!    left out.
//! 2. **Real boundaries only**: along each stretch, once per texel, the light's irradiance is
//!    evaluated half a texel on either side (shadow rays through the caller's tracer). A sample
//!    is a boundary when one side is lit and the other not, and the jump is at least
//!    [`MIN_JUMP`] of all punctual light on the lit side; runs of boundary samples at least a
//!    texel long are kept. So an edge whose projection lies in another object's shadow, or
//!    that the receiver itself hides, gives no cut.
//! 3. The kept pieces go to the junction split as cuts that are never stitched (as junction
//!    edges); their free ends are extended like a doorway's jamb, so the two sides separate,
//!    and in such a patch the extensions are never stitched either (they hug the outline).
//!
//! The work is bounded: at most [`MAX_SAMPLES`] boundary samples per scene and
//! [`MAX_PATCH_CUTS`] pieces per patch (what is left over is counted in the report). The
//! cutter itself is read-only, shared by the instances the junction split cuts in parallel;
//! each instance draws on the scene's budget through its own `ShadowWork`, which records what
//! it asked for, so that the split can replay the budget in instance order.

use std::sync::atomic::{AtomicUsize, Ordering};

use glam::{DVec2, DVec3, Vec3};

use super::geometry::{BoxGrid, Plane, Triangles2d, weld};
use super::{LightKind, Scene};

/// A shadow edge is cut only where the light's jump is at least this share of all punctual
/// light on the lit side. A step of relative height `j` blurred by a bilinear lookup leaves a
/// ramp whose error averages `j/4` over one texel on each side; below 10% that strip's error
/// is under the 2% of `--quality high` even where it is all a renderer shows, while a cut
/// costs a chart border (texels and seams), so fainter steps are left to the texels.
pub(crate) const MIN_JUMP: f32 = 0.1;

/// Boundary samples (each two or more shadow rays) per scene at most: keeps the split's time
/// bounded on big scenes (patches after the budget is spent get no shadow cuts).
pub(crate) const MAX_SAMPLES: usize = 1 << 19;

/// Shadow cut pieces per receiver patch at most (the junction split's cut graph is quadratic
/// in its segments).
pub(crate) const MAX_PATCH_CUTS: usize = 256;

/// Irradiance (any one measure, e.g. the channel mean) at surface point `p` with normal `n`
/// from punctual light `l` (index into [`Scene::lights`]), shadow rays included; `p` lies on
/// the surface (the caller offsets the ray origin). `Sync`: instances are cut in parallel.
pub(crate) type LightAt<'a> = dyn Fn(usize, Vec3, Vec3) -> f32 + Sync + 'a;

/// The scene's punctual lights and their silhouette edges, ready to cut receiver patches
/// (read-only, so `Sync`).
pub(crate) struct ShadowCutter<'a> {
    lights: Vec<Source>,
    /// The scene's bounding box.
    bounds: (DVec3, DVec3),
    light_at: &'a LightAt<'a>,
}

/// Where one instance's boundary samples come from.
#[derive(Clone, Copy)]
pub(super) enum Budget<'b> {
    /// Exactly what the instances before it left of the scene's budget (cutting in order).
    Left(usize),
    /// First come, first served from a count shared by the instances cut in parallel, up to
    /// `limit`: it keeps their work bounded, but who gets the last samples depends on timing,
    /// so the split checks each instance's share with [`ShadowWork::replays`].
    Shared {
        taken: &'b AtomicUsize,
        limit: usize,
    },
}

/// One instance's draw on the sample budget: every outline stretch it asked for, in order,
/// and whether it got the samples. Which stretches an instance asks for does not depend on the
/// budget, only which of them are tested, so two runs that got the same stretches cut alike.
pub(super) struct ShadowWork<'b> {
    budget: Budget<'b>,
    /// Per stretch asked for: its samples and whether they were taken.
    asked: Vec<(usize, bool)>,
    /// Boundary samples taken.
    pub(super) samples: usize,
    /// Stretches left untested (the budget was spent) and pieces left out (a patch had
    /// [`MAX_PATCH_CUTS`]).
    pub(super) skipped: usize,
}

impl<'b> ShadowWork<'b> {
    pub(super) fn new(budget: Budget<'b>) -> Self {
        ShadowWork {
            budget,
            asked: Vec::new(),
            samples: 0,
            skipped: 0,
        }
    }

    /// Takes `steps` samples for one stretch if the budget has them (else counts it skipped).
    fn take(&mut self, steps: usize) -> bool {
        let fits = match &mut self.budget {
            Budget::Left(left) => {
                let fits = steps <= *left;
                if fits {
                    *left -= steps;
                }
                fits
            }
            Budget::Shared { taken, limit } => {
                steps <= *limit && taken.fetch_add(steps, Ordering::Relaxed) + steps <= *limit
            }
        };
        self.asked.push((steps, fits));
        if fits {
            self.samples += steps;
        } else {
            self.skipped += 1;
        }
        fits
    }

    /// Whether cutting in order with `left` samples left would have taken exactly the
    /// stretches this run took (then its cuts are the in-order ones); if so, `left` becomes
    /// what remains after it.
    pub(super) fn replays(&self, left: &mut usize) -> bool {
        let mut remaining = *left;
        for &(steps, took) in &self.asked {
            let fits = steps <= remaining;
            if fits != took {
                return false;
            }
            if fits {
                remaining -= steps;
            }
        }
        *left = remaining;
        true
    }
}

/// One light as the cutter sees it.
struct Source {
    /// The direction light travels (a sun), or the light's position.
    kind: Toward,
    silhouette: Vec<[DVec3; 2]>,
    /// The silhouette edges binned by their bounding boxes.
    grid: BoxGrid,
}

#[derive(Clone, Copy)]
enum Toward {
    Direction(DVec3),
    Position(DVec3),
}

impl<'a> ShadowCutter<'a> {
    /// Finds every light's silhouette edges in `scene`; `light_at` answers the shadow rays.
    pub(crate) fn new(scene: &Scene, light_at: &'a LightAt<'a>) -> ShadowCutter<'a> {
        let edges = scene_edges(scene);
        let bounds = scene.bounds();
        let bounds = (bounds.0.as_dvec3(), bounds.1.as_dvec3());
        let lights = scene
            .lights
            .iter()
            .map(|light| {
                let kind = match light.kind {
                    LightKind::Directional => Toward::Direction(light.direction.as_dvec3()),
                    LightKind::Point | LightKind::Spot { .. } => {
                        Toward::Position(light.position.as_dvec3())
                    }
                };
                let silhouette = if light.intensity.max_element() > 0.0 {
                    silhouette(scene, &edges, kind)
                } else {
                    Vec::new()
                };
                let grid = edge_grid(&silhouette, bounds);
                Source {
                    kind,
                    silhouette,
                    grid,
                }
            })
            .collect();
        ShadowCutter {
            lights,
            bounds,
            light_at,
        }
    }

    /// The shadow cut pieces of the patch in `plane` (its triangles `corners` in plane
    /// coordinates, its box `low..high`, its corners within `touch` of the plane), in plane
    /// coordinates; the samples come from `work`'s budget.
    pub(super) fn patch_cuts(
        &self,
        plane: &Plane,
        corners: &Triangles2d,
        (low, high): (DVec3, DVec3),
        texel: f64,
        touch: f64,
        work: &mut ShadowWork,
    ) -> Vec<[DVec2; 2]> {
        let [lo, hi] = corners.bounds();
        let mut pieces = Vec::new();
        for (l, light) in self.lights.iter().enumerate() {
            // Height of the light above the plane (infinite for a sun in front of it).
            let height = match light.kind {
                Toward::Direction(d) if d.dot(plane.normal) < -1e-6 => f64::INFINITY,
                Toward::Position(p) if (p - plane.origin).dot(plane.normal) > touch => {
                    (p - plane.origin).dot(plane.normal)
                }
                _ => continue,
            };
            // Only edges in the box of the space between the patch (box `low..high`) and the
            // light can shadow it.
            let (from, to) = match light.kind {
                Toward::Direction(d) => {
                    let (lo, hi) = self.bounds;
                    let pick = |k: usize| match d[k] {
                        x if x > 0.0 => (lo[k], high[k]),
                        x if x < 0.0 => (low[k], hi[k]),
                        _ => (low[k], high[k]),
                    };
                    let [x, y, z] = [0, 1, 2].map(pick);
                    (DVec3::new(x.0, y.0, z.0), DVec3::new(x.1, y.1, z.1))
                }
                Toward::Position(p) => (low.min(p), high.max(p)),
            };
            for e in light.grid.query(from - touch, to + touch) {
                let [a, b] = light.silhouette[e as usize];
                let Some([a, b]) = project(plane, light.kind, height, a, b, touch) else {
                    continue;
                };
                let (p, q) = (plane.to_2d(a), plane.to_2d(b));
                let length = p.distance(q);
                if length < texel
                    || p.max(q).cmplt(lo - texel).any()
                    || p.min(q).cmpgt(hi + texel).any()
                {
                    continue;
                }
                for [s0, s1] in corners.inside_intervals(p, q, 0.25 * texel) {
                    if (s1 - s0) * length >= texel {
                        self.boundaries(
                            plane,
                            l,
                            [p.lerp(q, s0), p.lerp(q, s1)],
                            texel,
                            work,
                            &mut pieces,
                        );
                    }
                }
            }
        }
        if pieces.len() > MAX_PATCH_CUTS {
            work.skipped += pieces.len() - MAX_PATCH_CUTS;
            pieces.truncate(MAX_PATCH_CUTS);
        }
        pieces
    }

    /// The runs of stretch `[p, q]` (plane coordinates) where light `l`'s shadow ends, at least
    /// a texel long, appended to `pieces`; untested when `work`'s budget lacks the samples.
    fn boundaries(
        &self,
        plane: &Plane,
        l: usize,
        [p, q]: [DVec2; 2],
        texel: f64,
        work: &mut ShadowWork,
        pieces: &mut Vec<[DVec2; 2]>,
    ) {
        let steps = (p.distance(q) / texel).ceil().max(1.0) as usize;
        if !work.take(steps) {
            return;
        }
        let n = plane.normal.as_vec3();
        let side = (q - p).perp().normalize() * (0.5 * texel);
        let at = |s: DVec2| plane.to_3d(s).as_vec3();
        let boundary = |i: usize| {
            let s = p.lerp(q, (i as f64 + 0.5) / steps as f64);
            let (x, y) = (at(s + side), at(s - side));
            let (ex, ey) = ((self.light_at)(l, x, n), (self.light_at)(l, y, n));
            if (ex > 0.0) == (ey > 0.0) {
                return false;
            }
            let (lit, jump) = if ex > 0.0 { (x, ex) } else { (y, ey) };
            let total: f32 = (0..self.lights.len())
                .map(|k| {
                    if k == l {
                        jump
                    } else {
                        (self.light_at)(k, lit, n)
                    }
                })
                .sum();
            jump >= MIN_JUMP * total
        };
        let mut run: Option<usize> = None;
        for i in 0..=steps {
            let on = i < steps && boundary(i);
            match (run, on) {
                (None, true) => run = Some(i),
                (Some(start), false) => {
                    run = None;
                    let (a, b) = (
                        p.lerp(q, start as f64 / steps as f64),
                        p.lerp(q, i as f64 / steps as f64),
                    );
                    if a.distance(b) >= texel * (1.0 - 1e-9) {
                        pieces.push([a, b]);
                    }
                }
                _ => {}
            }
        }
    }
}

/// The part of edge `a`–`b` between the patch's plane and the light (`height` above the plane),
/// projected onto the plane from the light; `None` when none is, or the edge lies in the plane.
fn project(
    plane: &Plane,
    toward: Toward,
    height: f64,
    a: DVec3,
    b: DVec3,
    touch: f64,
) -> Option<[DVec3; 2]> {
    let (da, db) = (
        (a - plane.origin).dot(plane.normal),
        (b - plane.origin).dot(plane.normal),
    );
    if da.abs() <= touch && db.abs() <= touch {
        return None; // a junction
    }
    // Keep heights in [0, top]: below the plane casts nothing on it, at the light's height
    // projects to infinity.
    let top = height - touch.max(1e-6 * height);
    let (mut s0, mut s1) = (0.0f64, 1.0f64);
    for (bound, sign) in [(0.0, 1.0), (top, -1.0)] {
        // sign · (d(s) − bound) ≥ 0 with d(s) = da + s (db − da)
        let (num, den) = (sign * (da - bound), sign * (db - da));
        if den.abs() < 1e-300 {
            if num < 0.0 {
                return None;
            }
        } else if den > 0.0 {
            s0 = s0.max(-num / den);
        } else {
            s1 = s1.min(-num / den);
        }
    }
    if s1 <= s0 {
        return None;
    }
    let onto = |s: f64| {
        let x = a.lerp(b, s);
        let d = (x - plane.origin).dot(plane.normal);
        match toward {
            Toward::Direction(dir) => x - dir * (d / dir.dot(plane.normal)),
            Toward::Position(light) => light + (x - light) * (height / (height - d)),
        }
    };
    Some([onto(s0), onto(s1)])
}

/// Every edge of the scene's front instances as (welded end points ascending, triangle, its
/// vertices), sorted; positions weld across instances, so a solid made of several primitives
/// is closed.
fn scene_edges(scene: &Scene) -> Vec<([u32; 2], u32, [u32; 2])> {
    let weld = weld(&scene.positions);
    let mut edges = Vec::with_capacity(3 * scene.triangles.len());
    for (t, tri) in scene.triangles.iter().enumerate() {
        if scene.instances[scene.triangle_instance[t] as usize]
            .back_of
            .is_some()
        {
            continue; // the back face of a double-sided sheet: its front has the same outline
        }
        for k in 0..3 {
            let (a, b) = (weld[tri[k] as usize], weld[tri[(k + 1) % 3] as usize]);
            if a != b {
                edges.push(([a.min(b), a.max(b)], t as u32, [tri[k], tri[(k + 1) % 3]]));
            }
        }
    }
    edges.sort_unstable();
    edges
}

/// The edges of `edges` on the outline seen from the light: between a triangle facing it and
/// one facing away, or with one triangle only (an open boundary).
fn silhouette(
    scene: &Scene,
    edges: &[([u32; 2], u32, [u32; 2])],
    toward: Toward,
) -> Vec<[DVec3; 2]> {
    let pos = |v: u32| scene.positions[v as usize].as_dvec3();
    let facing = |t: u32| {
        let [a, b, c] = scene.triangles[t as usize].map(pos);
        let n = (b - a).cross(c - a);
        match toward {
            Toward::Direction(d) => n.dot(d) < 0.0,
            Toward::Position(p) => n.dot(p - a) > 0.0,
        }
    };
    let mut out = Vec::new();
    for same in edges.chunk_by(|x, y| x.0 == y.0) {
        let first = facing(same[0].1);
        if same.len() == 1 || same[1..].iter().any(|e| facing(e.1) != first) {
            out.push(same[0].2.map(pos));
        }
    }
    out
}

/// Grid cells per axis (of the longest) at most.
const GRID_CELLS: f64 = 32.0;

/// `edges` binned by their bounding boxes over the scene's box `(lo, hi)`.
fn edge_grid(edges: &[[DVec3; 2]], (lo, hi): (DVec3, DVec3)) -> BoxGrid {
    let extent = (hi - lo).max(DVec3::splat(1e-9));
    let dims = (extent / extent.max_element() * GRID_CELLS)
        .ceil()
        .clamp(DVec3::ONE, DVec3::splat(GRID_CELLS));
    let mut grid = BoxGrid::new(lo, extent, dims);
    for (e, [a, b]) in edges.iter().enumerate() {
        grid.insert(e as u32, a.min(*b), a.max(*b));
    }
    grid
}
