//! Junction splitting: receivers are cut where other surfaces meet them, so no lightmap texel
//! straddles a junction.
//!
//! Why: a texel holds one value and a renderer filters bilinearly between neighbours. Where a
//! wall stands on a floor, a floor texel under the wall covers both rooms; the dark room's side
//! then shows the lit room's light as a bright line along every junction (the divided-texel cell
//! map of `texels::cuts` keeps the texel's value right for rays, not for a renderer's lookup).
//! Cut along the junction, each side of the wall gets its own chart and its own texels.
//!
//! What [`split`] does, per flat patch of an instance (connected triangles in one plane whose
//! neighbours in the mesh turn by 30° or more, so curved surfaces are left alone):
//! 1. **Find the junctions**: every other triangle (any instance; a uniform grid finds the
//!    candidates) that crosses the patch's plane or has an edge lying in it (a wall standing on
//!    the floor; corners within `TOUCH_TEXELS` of the plane count as on it) gives a segment,
//!    clipped to the patch's triangles. Coplanar triangles and single touching points give none.
//!    With near contacts (`AtlasParams::near_contacts`), the triangles facing the patch from
//!    less than a texel in front of it (a door's edge 3 mm from its lining) give the
//!    projection of their outline — their edges no other of them shares — as segments too:
//!    the slot under them and the open surface beside it get texels of their own (and, after
//!    the split, texels at the scale of the slot's gap: `crate::atlas::slots`, which also
//!    raises narrow faces near emitters to four texels across).
//! 2. **Make the cuts separate**: segment ends within `SNAP_TEXELS` merge, move onto the patch
//!    border's vertices and edges, and split segments they touch; inside the patch a cut point
//!    within `TOUCH_TEXELS` of a mesh vertex or edge moves onto it (walls meeting on a floor's
//!    diagonal: left a millionth of a texel beside it, it made needles). A segment end left free
//!    inside the patch (the jamb of a doorway: the floor runs on under the opening) is extended
//!    straight on to the next segment or the patch's border; that extension is a cut too, but an
//!    ordinary seam (stitched later), while junction edges are never stitched
//!    (`Split::junction_edges`).
//!    In a patch with shadow outlines extensions are never stitched either (see below).
//! 3. **Retriangulate**: each triangle a cut touches is triangulated again with spade's
//!    constrained Delaunay triangulation (robust predicates; crossing cuts split each other).
//!    Points on a mesh edge are shared by both triangles on it — the other one is cut too, in
//!    this patch or the next (no T-junctions) — and points on one edge closer than the snap
//!    distance merge, so no sliver below a quarter texel appears along an edge; a cut ending
//!    on an edge next to a corner ends at the corner. Which new edges are cuts comes from the
//!    triangulation's constraint edges (a cut bent onto a merged point is still a cut). A triangle
//!    whose pieces do not add up to its area is left uncut (counted in the report), keeping only
//!    the points on its edges, which its neighbours share.
//! 4. **Sides**: the instance's triangles are grouped into sides, connected across edges that are
//!    not cuts; the atlas never puts two sides into one chart.
//!
//! `split_with` cuts along the hard shadow outlines of punctual lights too
//! (`super::shadow_cuts`): they join step 2 as segments that are never stitched, and a patch
//! with such cuts is bounded by its border in step 4 as well. The extensions of such a patch
//! are never stitched either: a curved outline's free end is extended along its tangent, which
//! hugs the shadow's edge, and stitching there blurred the sphere's shadow (`sphere_on_floor`
//! draft point error 9.28% stitched against 2.81% unstitched; 2.79% now).
//!
//! New vertices are blends of at most three source vertices of the same primitive
//! ([`Blend`]); the output writer blends every attribute the same way, so the split exists only
//! in the baked copy.
//!
//! Instances are cut in parallel (largest first), each into its own split and report, which
//! are put together in instance order. The one thing instances share is the scene's budget of
//! shadow samples (`shadow_cuts::MAX_SAMPLES`), spent in instance order: it is
//! replayed in that order afterwards, and an instance the parallel run served differently is
//! cut again in order, so the result does not depend on the thread count.

use std::collections::{BTreeMap, HashMap};
use std::sync::atomic::AtomicUsize;

use glam::{DVec2, DVec3, Vec2, Vec3};
use rayon::prelude::*;
use spade::{ConstrainedDelaunayTriangulation, Point2, Triangulation};

use super::geometry::{BoxGrid, Plane, Triangles2d, clip_box, clip_interval, may_clip, weld};
use super::shadow_cuts::{Budget, MAX_SAMPLES, ShadowCutter, ShadowWork};
use super::{Blend, Instance, Scene, Split};

/// Cut end points closer than this merge, and move onto a patch vertex or edge this close
/// (texels).
pub(crate) const SNAP_TEXELS: f64 = 0.25;

/// A corner this close to a patch's plane lies in it (texels): a wall standing on a floor. A
/// cut point this close to a vertex or edge of the patch lies on it, likewise.
pub(crate) const TOUCH_TEXELS: f64 = 1.0 / 16.0;

/// With near contacts (`AtlasParams::near_contacts`), a surface facing a patch from no
/// farther than this in front of it (texels) is a near contact: the patch is cut along its
/// outline's projection. A gap narrower than a texel (a door's edge 3 mm from its lining, a
/// light's side 2 cm from its recess) is a slot the texels cannot resolve: without the cut,
/// the texel of the patch under the outline holds both the slot and the open surface beside
/// it, and the slot's faces read that average. Cut ends then snap at [`TOUCH_TEXELS`], not
/// [`SNAP_TEXELS`]: the lining's 1 cm proud of the wall beside the door's slot, a twelfth of a
/// draft texel, would otherwise be snapped into the slot.
const NEAR_TEXELS: f64 = 1.0;

/// How far in front of a receiver near contacts reach at a texel of `texel` (world units).
pub(crate) fn near_distance(texel: f32) -> f32 {
    (NEAR_TEXELS * f64::from(texel)) as f32
}

/// Normals opposed at least this much (cosine of 30°) face each other.
const FACING_DOT: f64 = 0.866;

/// A patch is a receiver only when no neighbour of the same mesh continues it more gently than
/// this (cosine of 30°): gentler folds belong to curved surfaces, which are left alone.
const SMOOTH_DOT: f64 = 0.866;

/// Grid cells per axis of the broad phase, at most.
const MAX_GRID_CELLS: f64 = 64.0;

/// An instance of at least this many triangles averaging at most [`DENSE_TEXELS`] texel², and
/// not planar, is no receiver (it still cuts others): a scanned or sculpted surface, curved at
/// the scale of its triangles, where no flat patch is a receiver anyway, but finding that out
/// took 16–19 s for the million triangles of `testing::height_field`. The atlas charts such
/// instances by smooth patches (`atlas::xatlas`, dense meshes), with the same thresholds.
const DENSE_TRIANGLES: usize = 4096;
const DENSE_TEXELS: f64 = 1.0 / 16.0;

/// What [`split`] did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct JunctionReport {
    /// Instances that were cut.
    pub receivers: usize,
    /// Junction segments inserted (after merging), and cuts extending free segment ends.
    pub(crate) segments: usize,
    pub(crate) extensions: usize,
    /// Triangles replaced by their pieces, and how many triangles the scene gained.
    pub(crate) triangles_split: usize,
    pub(crate) triangles_added: usize,
    /// Triangles left uncut because their pieces did not add up to their area (robustness
    /// fallback: they keep the points their neighbours share on their edges, so no T-junction;
    /// the cell map of divided texels covers them).
    pub(crate) fallback_triangles: usize,
    /// Junction edges whose two sides stayed connected around the junction (the cell map of
    /// divided texels covers them).
    pub(crate) unseparated_edges: usize,
    /// Shadow outline cuts inserted ([`super::shadow_cuts`]; counted among `segments` too),
    /// the boundary samples that chose them, and outline stretches left out (work bounds).
    pub(crate) shadow_segments: usize,
    pub(crate) shadow_samples: usize,
    pub(crate) shadow_skipped: usize,
    /// Cuts along the outlines of near contacts (counted among `segments` too).
    pub(crate) near_segments: usize,
    /// Instances left uncut because their mesh is shared by several nodes (`--instancing
    /// share`; the cell map of divided texels covers them).
    pub(crate) left_whole: usize,
    /// Slot faces raised to texels at their gap's scale (with near contacts) and narrow faces
    /// near emitters to four texels across (`atlas::slots`; the bake sets it after the split).
    pub(crate) slots: Option<crate::atlas::slots::SlotReport>,
}

impl JunctionReport {
    /// Adds the counts of `other` (one instance's).
    fn add(&mut self, other: &JunctionReport) {
        // Destructured so that a new count cannot be left out.
        let JunctionReport {
            receivers,
            segments,
            extensions,
            triangles_split,
            triangles_added,
            fallback_triangles,
            unseparated_edges,
            shadow_segments,
            shadow_samples,
            shadow_skipped,
            near_segments,
            left_whole,
            slots: _,
        } = other;
        self.receivers += receivers;
        self.segments += segments;
        self.extensions += extensions;
        self.triangles_split += triangles_split;
        self.triangles_added += triangles_added;
        self.fallback_triangles += fallback_triangles;
        self.unseparated_edges += unseparated_edges;
        self.shadow_segments += shadow_segments;
        self.shadow_samples += shadow_samples;
        self.shadow_skipped += shadow_skipped;
        self.near_segments += near_segments;
        self.left_whole += left_whole;
    }

    /// One phrase for the bake's summary line.
    pub fn brief(&self) -> String {
        format!(
            "junctions: {} receiver(s) split ({} segments{}, {} extensions, {} triangles → +{}){}{}{}{}",
            self.receivers,
            self.segments,
            if self.near_segments > 0 {
                format!(" ({} along near contacts)", self.near_segments)
            } else {
                String::new()
            },
            self.extensions,
            self.triangles_split,
            self.triangles_added,
            if self.shadow_samples > 0 {
                format!(
                    ", {} of the segments along shadow outlines ({} samples{})",
                    self.shadow_segments,
                    self.shadow_samples,
                    if self.shadow_skipped > 0 {
                        format!(", {} stretches left out", self.shadow_skipped)
                    } else {
                        String::new()
                    }
                )
            } else {
                String::new()
            },
            if self.left_whole > 0 {
                format!(
                    ", {} instance(s) of shared meshes left whole",
                    self.left_whole
                )
            } else {
                String::new()
            },
            if self.fallback_triangles + self.unseparated_edges > 0 {
                format!(
                    ", {} triangles left uncut, {} edges unseparated",
                    self.fallback_triangles, self.unseparated_edges
                )
            } else {
                String::new()
            },
            self.slots
                .map_or(String::new(), |s| format!("; {}", s.brief()))
        )
    }
}

/// Cuts every instance of `scene` where other surfaces meet it (see the module docs); `texel`
/// is the lightmap texel size in world units (snapping tolerances are fractions of it).
pub fn split(scene: Scene, texel: f32) -> (Scene, JunctionReport) {
    split_with(scene, texel, None)
}

/// [`split`], cutting along the shadow outlines `shadows` finds too (see
/// [`super::shadow_cuts`]).
pub(crate) fn split_with(
    scene: Scene,
    texel: f32,
    shadows: Option<&ShadowCutter>,
) -> (Scene, JunctionReport) {
    split_except(scene, texel, false, shadows, &[])
}

/// [`split_with`], cutting near contacts too when `near_contacts` (see [`NEAR_TEXELS`]), and
/// leaving the instances marked in `whole` (parallel to `Scene::instances`; shorter means
/// unmarked) uncut: the instances of a mesh shared by several nodes (`--instancing share`),
/// which cannot carry one node's cuts. They still cut the others.
pub(crate) fn split_except(
    scene: Scene,
    texel: f32,
    near_contacts: bool,
    shadows: Option<&ShadowCutter>,
    whole: &[bool],
) -> (Scene, JunctionReport) {
    let tol = Tolerances::of(texel, near_contacts);
    split_budgeted(scene, tol, shadows, whole, MAX_SAMPLES)
}

/// [`split_except`] with a budget of `max_samples` shadow samples (the tests spend small ones).
fn split_budgeted(
    scene: Scene,
    tol: Tolerances,
    shadows: Option<&ShadowCutter>,
    whole: &[bool],
    max_samples: usize,
) -> (Scene, JunctionReport) {
    cut_with(scene, tol, shadows, whole, |cutting| {
        let taken = AtomicUsize::new(0);
        let runs = cut_in_parallel(cutting, &taken, max_samples);
        replay_in_order(cutting, runs, max_samples)
    })
}

/// Sets up what cutting reads (the triangle grid), lets `cut` cut the instances,
/// and puts the scene together from their splits.
fn cut_with(
    scene: Scene,
    tol: Tolerances,
    shadows: Option<&ShadowCutter>,
    whole: &[bool],
    cut: impl FnOnce(Cutting) -> (Vec<Option<InstanceSplit>>, JunctionReport),
) -> (Scene, JunctionReport) {
    let grid = triangle_grid(&scene, tol.touch, tol.texel);
    let cutting = Cutting {
        scene: &scene,
        grid: &grid,
        tol,
        shadows,
        whole,
    };
    let (splits, report) = cut(cutting);
    finish(scene, splits, report)
}

/// What cutting any instance reads, shared read-only by the instances cut in parallel.
#[derive(Clone, Copy)]
struct Cutting<'a> {
    scene: &'a Scene,
    /// The broad phase over every triangle of the scene.
    grid: &'a BoxGrid,
    tol: Tolerances,
    shadows: Option<&'a ShadowCutter<'a>>,
    /// Instances left whole (see [`split_except`]).
    whole: &'a [bool],
}

/// One instance cut: its split (`None` when left as it is), its counts, and what it drew on
/// the shadow samples.
struct InstanceRun<'b> {
    split: Option<InstanceSplit>,
    report: JunctionReport,
    shadow: ShadowWork<'b>,
}

/// Cuts instance `i` (unless it is left whole, or dense and curved) with its shadow samples
/// from `budget`.
fn run_instance<'b>(cutting: Cutting, i: usize, budget: Budget<'b>) -> InstanceRun<'b> {
    let mut run = InstanceRun {
        split: None,
        report: JunctionReport::default(),
        shadow: ShadowWork::new(budget),
    };
    let whole = cutting.whole.get(i).copied().unwrap_or(false);
    if !whole && !dense_and_curved(cutting.scene, i, cutting.tol.texel) {
        let (shadow, report) = (&mut run.shadow, &mut run.report);
        run.split = split_instance(cutting, i as u32, shadow, report);
    }
    run.report.shadow_samples = run.shadow.samples;
    run.report.shadow_skipped = run.shadow.skipped;
    run
}

/// Every instance cut in parallel, returned in instance order. The largest start first (a big
/// mesh started last would finish alone); shadow samples come from the shared count `taken`,
/// which bounds the work to `max_samples` as cutting in order does.
fn cut_in_parallel<'b>(
    cutting: Cutting,
    taken: &'b AtomicUsize,
    max_samples: usize,
) -> Vec<InstanceRun<'b>> {
    let instances = &cutting.scene.instances;
    let mut order: Vec<usize> = (0..instances.len()).collect();
    order.sort_by_key(|&i| std::cmp::Reverse(instances[i].triangles.len()));
    let budget = Budget::Shared {
        taken,
        limit: max_samples,
    };
    let mut runs: Vec<(usize, InstanceRun)> = order
        .into_par_iter()
        // One instance per task: no big instance holds smaller ones back in its task.
        .with_max_len(1)
        .map(|i| (i, run_instance(cutting, i, budget)))
        .collect();
    runs.sort_unstable_by_key(|r| r.0);
    runs.into_iter().map(|r| r.1).collect()
}

/// The splits of `runs` (in instance order) and their summed report, with the shadow samples
/// replayed in instance order: an instance whose samples the shared count gave out otherwise
/// than cutting in order would have is cut again, in order (this happens only where the
/// scene's budget runs out).
fn replay_in_order(
    cutting: Cutting,
    runs: Vec<InstanceRun>,
    max_samples: usize,
) -> (Vec<Option<InstanceSplit>>, JunctionReport) {
    let mut report = JunctionReport {
        left_whole: cutting.whole.iter().filter(|&&w| w).count(),
        ..Default::default()
    };
    let mut left = max_samples;
    let splits = (runs.into_iter().enumerate())
        .map(|(i, mut run)| {
            if !run.shadow.replays(&mut left) {
                run = run_instance(cutting, i, Budget::Left(left));
                let replayed = run.shadow.replays(&mut left);
                debug_assert!(replayed, "a run in order replays itself");
            }
            report.add(&run.report);
            run.split
        })
        .collect();
    (splits, report)
}

/// The scene with `splits` put in (unchanged when there are none), and the final report.
fn finish(
    scene: Scene,
    splits: Vec<Option<InstanceSplit>>,
    mut report: JunctionReport,
) -> (Scene, JunctionReport) {
    if splits.iter().all(Option::is_none) {
        return (scene, report);
    }
    (assemble(scene, splits, &mut report), report)
}

/// Whether instance `i` is dense and curved at a texel of `texel` (see [`DENSE_TRIANGLES`]):
/// one pass over its triangles.
fn dense_and_curved(scene: &Scene, i: usize, texel: f64) -> bool {
    let inst = &scene.instances[i];
    let tris = &scene.triangles[inst.triangles.start as usize..inst.triangles.end as usize];
    if tris.len() < DENSE_TRIANGLES {
        return false;
    }
    let normal = |t: &[u32; 3]| {
        let [a, b, c] = t.map(|v| scene.positions[v as usize].as_dvec3());
        (b - a).cross(c - a)
    };
    let area: f64 = tris.iter().map(|t| 0.5 * normal(t).length()).sum();
    if area / tris.len() as f64 > DENSE_TEXELS * texel * texel {
        return false;
    }
    let Some(first) = tris
        .iter()
        .map(|t| normal(t).normalize_or_zero())
        .find(|n| *n != DVec3::ZERO)
    else {
        return false;
    };
    tris.iter().any(|t| {
        let n = normal(t).normalize_or_zero();
        n != DVec3::ZERO && n.dot(first) < 1.0 - 1e-9
    })
}

#[derive(Clone, Copy)]
struct Tolerances {
    texel: f64,
    snap: f64,
    touch: f64,
    /// Near contacts cut from no farther than this (0: they do not).
    near: f64,
}

impl Tolerances {
    /// The tolerances at a texel of `texel`; with `near_contacts`, near contacts cut too and
    /// cut ends snap at the touch distance, not the snap distance (see [`NEAR_TEXELS`]).
    fn of(texel: f32, near_contacts: bool) -> Self {
        let texel = f64::from(texel);
        Tolerances {
            texel,
            snap: if near_contacts {
                TOUCH_TEXELS
            } else {
                SNAP_TEXELS
            } * texel,
            touch: TOUCH_TEXELS * texel,
            near: if near_contacts {
                NEAR_TEXELS * texel
            } else {
                0.0
            },
        }
    }
}

/// The new triangulation of one instance, in instance-local vertices.
struct InstanceSplit {
    triangles: Vec<[u32; 3]>,
    source_triangle: Vec<u32>,
    split: Split,
}

/// Rebuilds the scene's vertex and triangle arrays with the split instances.
fn assemble(
    mut scene: Scene,
    splits: Vec<Option<InstanceSplit>>,
    report: &mut JunctionReport,
) -> Scene {
    let old_triangles = scene.triangles.len();
    let (mut positions, mut normals, mut uv0, mut uv1) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let (mut triangles, mut triangle_instance) = (Vec::new(), Vec::new());
    for (i, (inst, split)) in scene.instances.iter_mut().zip(splits).enumerate() {
        let range = inst.vertices.start as usize..inst.vertices.end as usize;
        let first_vertex = positions.len() as u32;
        positions.extend_from_slice(&scene.positions[range.clone()]);
        normals.extend_from_slice(&scene.normals[range.clone()]);
        uv0.extend_from_slice(&scene.uv0[range.clone()]);
        uv1.extend_from_slice(&scene.uv1[range.clone()]);
        let first_triangle = triangles.len() as u32;
        match split {
            None => triangles.extend(
                scene.triangles[inst.triangles.start as usize..inst.triangles.end as usize]
                    .iter()
                    .map(|t| t.map(|v| v - inst.vertices.start + first_vertex)),
            ),
            Some(split) => {
                let at = |v: u32| v as usize + range.start;
                for blend in &split.split.blends {
                    let mix3 = |a: &[Vec3]| {
                        (0..3).fold(DVec3::ZERO, |s, k| {
                            s + a[at(blend.vertices[k])].as_dvec3() * f64::from(blend.weights[k])
                        })
                    };
                    let mix2 = |a: &[Vec2]| {
                        (0..3).fold(DVec2::ZERO, |s, k| {
                            s + a[at(blend.vertices[k])].as_dvec2() * f64::from(blend.weights[k])
                        })
                    };
                    positions.push(mix3(&scene.positions).as_vec3());
                    normals.push(mix3(&scene.normals).normalize_or_zero().as_vec3());
                    uv0.push(mix2(&scene.uv0).as_vec2());
                    uv1.push(mix2(&scene.uv1).as_vec2());
                }
                triangles.extend(split.triangles.iter().map(|t| t.map(|v| v + first_vertex)));
                inst.source_triangle = split.source_triangle;
                inst.split = split.split;
            }
        }
        inst.vertices = first_vertex..positions.len() as u32;
        inst.triangles = first_triangle..triangles.len() as u32;
        triangle_instance.resize(triangles.len(), i as u32);
    }
    report.triangles_added = triangles.len() - old_triangles;
    scene.positions = positions;
    scene.normals = normals;
    scene.uv0 = uv0;
    scene.uv1 = uv1;
    scene.triangles = triangles;
    scene.triangle_instance = triangle_instance;
    #[cfg(debug_assertions)]
    scene.validate();
    scene
}

/// The broad phase that finds the triangles near a patch: their bounding boxes in a grid.
fn triangle_grid(scene: &Scene, margin: f64, texel: f64) -> BoxGrid {
    let (lo, hi) = scene.bounds();
    let (lo, hi) = (lo.as_dvec3() - margin, hi.as_dvec3() + margin);
    let extent = (hi - lo).max(DVec3::splat(texel));
    let dims = (extent / (4.0 * texel))
        .ceil()
        .clamp(DVec3::ONE, DVec3::splat(MAX_GRID_CELLS));
    let mut grid = BoxGrid::new(lo, extent, dims);
    for (t, tri) in scene.triangles.iter().enumerate() {
        let p = tri.map(|v| scene.positions[v as usize].as_dvec3());
        let (a, b) = (p[0].min(p[1]).min(p[2]), p[0].max(p[1]).max(p[2]));
        grid.insert(t as u32, a - margin, b + margin);
    }
    grid
}

/// A flat patch of an instance in its own plane coordinates.
struct Patch {
    /// Instance-local triangles.
    triangles: Vec<u32>,
    plane: Plane,
}

/// Where a cut piece ends inside one triangle.
#[derive(Clone, Copy, Debug)]
enum End {
    Corner(usize),
    /// On edge `k` (corner `k` to `k + 1`) at parameter `t` from corner `k`.
    Edge(usize, f64),
    Inside(DVec2),
}

/// The cuts of one patch: a planar straight-line graph in the patch's coordinates.
struct Cuts {
    points: Vec<DVec2>,
    on_border: Vec<bool>,
    /// Point pairs; `true` for an extension of a free segment end.
    segments: Vec<([u32; 2], bool)>,
    /// Some cuts follow shadow outlines: the patch's border bounds its sides too, as a shadow
    /// that ends at a crease (a wall's shadow climbing a box) is no closed cut of the instance.
    shadow: bool,
}

/// The patch's edges in plane coordinates, with their border flag (one patch face on them).
struct PatchEdges {
    edges: Vec<([DVec2; 2], bool)>,
    vertices: Vec<(DVec2, bool)>,
    /// Vertices by `x` ascending, and edges by their smaller `x`: a query scans only the
    /// stretch of `x` it can reach (cut points are placed one by one on patches of thousands
    /// of vertices).
    vertices_by_x: Vec<u32>,
    edges_by_x: Vec<u32>,
    /// The widest extent of an edge along `x`.
    edge_span: f64,
}

impl PatchEdges {
    fn new(edges: Vec<([DVec2; 2], bool)>, vertices: Vec<(DVec2, bool)>) -> Self {
        let mut vertices_by_x: Vec<u32> = (0..vertices.len() as u32).collect();
        vertices_by_x.sort_by(|&i, &j| {
            vertices[i as usize]
                .0
                .x
                .total_cmp(&vertices[j as usize].0.x)
        });
        let low = |i: u32| edges[i as usize].0[0].x.min(edges[i as usize].0[1].x);
        let mut edges_by_x: Vec<u32> = (0..edges.len() as u32).collect();
        edges_by_x.sort_by(|&i, &j| low(i).total_cmp(&low(j)));
        let edge_span = (edges.iter())
            .map(|e| (e.0[0].x - e.0[1].x).abs())
            .fold(0.0, f64::max);
        PatchEdges {
            edges,
            vertices,
            vertices_by_x,
            edges_by_x,
            edge_span,
        }
    }

    /// Whether segment `p → q` lies along the border: its ends, middle and quarters each
    /// within `near` of a border edge.
    fn along_border(&self, p: DVec2, q: DVec2, near: f64) -> bool {
        let (lo, hi) = (p.min(q) - 2.0 * near, p.max(q) + 2.0 * near);
        let start = self
            .edges_by_x
            .partition_point(|&i| self.low_x(i) < lo.x - self.edge_span);
        let reach = self.edges_by_x[start..]
            .iter()
            .take_while(|&&i| self.low_x(i) <= hi.x)
            .map(|&i| self.edges[i as usize])
            .filter(|&([u, v], border)| {
                border && !(u.max(v).cmplt(lo).any() || u.min(v).cmpgt(hi).any())
            });
        [0.0, 0.25, 0.5, 0.75, 1.0].iter().all(|&s| {
            let x = p.lerp(q, s);
            (reach.clone()).any(|([u, v], _)| distance_to_segment(x, u, v).0 <= near)
        })
    }

    /// The smaller `x` of edge `i`.
    fn low_x(&self, i: u32) -> f64 {
        let [a, b] = self.edges[i as usize].0;
        a.x.min(b.x)
    }

    /// The patch vertex nearest to `p` within `within`, else the nearest point of a patch edge
    /// that close (only the border's when `border_only`), with its border flag. Ties go to
    /// the first in the lists' order.
    fn nearest(&self, p: DVec2, within: f64, border_only: bool) -> Option<(DVec2, bool)> {
        // The closest by (distance, index) among `order[from..]` until `x` passes `to`.
        fn closest<T>(
            order: &[u32],
            (from, to): (f64, f64),
            x: impl Fn(u32) -> f64,
            candidate: impl Fn(u32) -> Option<(f64, T)>,
        ) -> Option<T> {
            let start = order.partition_point(|&i| x(i) < from);
            let mut best: Option<(f64, u32, T)> = None;
            for &i in order[start..].iter().take_while(|&&i| x(i) <= to) {
                if let Some((d, found)) = candidate(i)
                    && best.as_ref().is_none_or(|b| (d, i) < (b.0, b.1))
                {
                    best = Some((d, i, found));
                }
            }
            best.map(|b| b.2)
        }
        let vertex = closest(
            &self.vertices_by_x,
            (p.x - within, p.x + within),
            |i| self.vertices[i as usize].0.x,
            |i| {
                let (v, border) = self.vertices[i as usize];
                let d = v.distance(p);
                ((border || !border_only) && d <= within).then_some((d, (v, border)))
            },
        );
        vertex.or_else(|| {
            closest(
                &self.edges_by_x,
                (p.x - within - self.edge_span, p.x + within),
                |i| self.low_x(i),
                |i| {
                    let ([a, b], border) = self.edges[i as usize];
                    let (d, t) = distance_to_segment(p, a, b);
                    ((border || !border_only) && d <= within).then_some((d, (a.lerp(b, t), border)))
                },
            )
        })
    }
}

fn distance_to_segment(p: DVec2, a: DVec2, b: DVec2) -> (f64, f64) {
    let d = b - a;
    let t = if d.length_squared() > 0.0 {
        ((p - a).dot(d) / d.length_squared()).clamp(0.0, 1.0)
    } else {
        0.0
    };
    ((a + d * t).distance(p), t)
}

impl Cuts {
    /// The index of the point at `p`: an existing point within the snap distance, else a border
    /// vertex or border edge point that close (a cut must end on the border), else a vertex or
    /// edge point of the patch within the touch distance, else a new point.
    ///
    /// Inside the patch a cut stays where the wall stands, up to the touch distance: a cut
    /// point lying on a mesh edge up to rounding (walls meeting on a floor's diagonal) would
    /// otherwise stay inside one triangle a millionth of a texel from that edge, and the
    /// retriangulation would make needles there.
    fn point(&mut self, p: DVec2, patch: &PatchEdges, tol: Tolerances) -> u32 {
        if let Some(i) = self.points.iter().position(|q| q.distance(p) <= tol.snap) {
            return i as u32;
        }
        let (q, border) = patch
            .nearest(p, tol.snap, true)
            .or_else(|| patch.nearest(p, tol.touch, false))
            .unwrap_or((p, false));
        self.points.push(q);
        self.on_border.push(border);
        (self.points.len() - 1) as u32
    }

    fn add(&mut self, a: u32, b: u32, extension: bool) {
        let key = [a.min(b), a.max(b)];
        if a != b
            && !self
                .segments
                .iter()
                .any(|(s, _)| [s[0].min(s[1]), s[0].max(s[1])] == key)
        {
            self.segments.push(([a, b], extension));
        }
    }

    /// Splits every segment at the points lying on it (within `snap`), so segments meeting in a
    /// T share a point. Each segment is cut once into a chain along its own line (pieces are not
    /// cut again: near-coincident points split each other's pieces for ever — a 64k-triangle
    /// interior ran out of memory there), and no piece is shorter than `snap` (no sliver).
    fn split_at_points(&mut self, snap: f64) {
        for ([a, b], ext) in std::mem::take(&mut self.segments) {
            let (pa, pb) = (self.points[a as usize], self.points[b as usize]);
            let mut on: Vec<(f64, u32)> = (0..self.points.len() as u32)
                .filter_map(|p| {
                    let q = self.points[p as usize];
                    let (d, t) = distance_to_segment(q, pa, pb);
                    (p != a
                        && p != b
                        && d <= snap
                        && t > 0.0
                        && t < 1.0
                        && q.distance(pa) > snap
                        && q.distance(pb) > snap)
                        .then_some((t, p))
                })
                .collect();
            on.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
            let mut from = a;
            for (_, p) in on {
                if self.points[p as usize].distance(self.points[from as usize]) > snap {
                    self.segments.push(([from, p], ext));
                    from = p;
                }
            }
            self.segments.push(([from, b], ext));
        }
    }

    fn degree(&self, p: u32) -> usize {
        self.segments.iter().filter(|(s, _)| s.contains(&p)).count()
    }

    /// Extends every free segment end (inside the patch, on no other segment) straight on to
    /// the nearest segment or patch border.
    fn extend_free_ends(&mut self, patch: &PatchEdges, tol: Tolerances) {
        let snap = tol.snap;
        let mut p = 0;
        while p < self.points.len() as u32 {
            if self.on_border[p as usize] || self.degree(p) != 1 {
                p += 1;
                continue;
            }
            let ([a, b], _) = *self
                .segments
                .iter()
                .find(|(s, _)| s.contains(&p))
                .expect("degree 1");
            let q = if a == p { b } else { a };
            let origin = self.points[p as usize];
            let dir = (origin - self.points[q as usize]).normalize_or_zero();
            let ray = |u: DVec2, v: DVec2| -> Option<f64> {
                // origin + s·dir = u + r·(v − u), s > snap/2, r ∈ [0, 1]
                let e = v - u;
                let den = dir.perp_dot(e);
                let w = u - origin;
                if den.abs() <= 1e-12 * e.length() {
                    // Parallel: a collinear segment (the other jamb of a doorway) is hit at
                    // its nearer end.
                    let collinear = w.perp_dot(dir).abs() <= 0.5 * snap;
                    let s = w.dot(dir).min((v - origin).dot(dir));
                    return (collinear && s > 0.5 * snap).then_some(s);
                }
                let s = w.perp_dot(e) / den;
                let r = w.perp_dot(dir) / den;
                (s > 0.5 * snap && (-1e-9..=1.0 + 1e-9).contains(&r)).then_some(s)
            };
            let mut best: Option<(f64, Option<usize>)> = None;
            for (k, ([u, v], _)) in self.segments.iter().enumerate() {
                if *u == p || *v == p {
                    continue;
                }
                if let Some(s) = ray(self.points[*u as usize], self.points[*v as usize])
                    && best.is_none_or(|b| s < b.0)
                {
                    best = Some((s, Some(k)));
                }
            }
            for &([u, v], border) in &patch.edges {
                if let Some(s) = ray(u, v).filter(|_| border)
                    && best.is_none_or(|b| s < b.0)
                {
                    best = Some((s, None));
                }
            }
            if let Some((s, _)) = best {
                let hit = self.point(origin + dir * s, patch, tol);
                self.add(p, hit, true);
                self.split_at_points(snap);
            }
            p += 1;
        }
    }
}

/// Cuts one instance (see the module docs), its shadow samples from `shadow`; `None` when
/// nothing meets it.
fn split_instance(
    cutting: Cutting,
    index: u32,
    shadow: &mut ShadowWork,
    report: &mut JunctionReport,
) -> Option<InstanceSplit> {
    let tol = cutting.tol;
    let inst = &cutting.scene.instances[index as usize];
    let mesh = LocalMesh::new(cutting.scene, inst)?;
    let patches = Patches::new(&mesh, tol);
    // Steps 1 and 2 of the module docs: each receiver patch's cuts.
    let patch_cuts: Vec<Option<Cuts>> = (patches.list.iter().enumerate())
        .map(|(id, patch)| {
            let cuts = patches
                .is_receiver(&mesh, id as u32)
                .then(|| {
                    let pos = |v: u32| mesh.pos(v);
                    let (tris, weld) = (&mesh.triangles, &mesh.weld);
                    patch_cuts_of(cutting, index, patch, tris, weld, pos, shadow, report)
                })
                .flatten();
            if let Some(cuts) = &cuts {
                report.segments += cuts.segments.iter().filter(|s| !s.1).count();
                report.extensions += cuts.segments.iter().filter(|s| s.1).count();
            }
            cuts
        })
        .collect();
    // Step 3: clipped into the triangles, which are triangulated again; step 4: sides.
    let cuts = InstanceCuts::clip(&mesh, &patches, patch_cuts, tol.snap)?;
    let retriangulated = Retriangulated::new(inst, &mesh, &patches, &cuts, tol.snap, report)?;
    report.receivers += 1;
    Some(retriangulated.into_split(&mesh, &cuts, report))
}

/// One instance's triangles in instance-local vertices, welded by position, with their edges
/// and normals: the mesh every step of [`split_instance`] walks.
struct LocalMesh<'a> {
    /// The instance's vertex positions.
    positions: &'a [Vec3],
    triangles: Vec<[u32; 3]>,
    /// The welded vertex of each vertex (one per position).
    weld: Vec<u32>,
    /// [`edge_list`] of the welded triangles.
    edges: Vec<([u32; 2], u32, u8)>,
    /// Each triangle's unit normal (zero when degenerate).
    normal: Vec<DVec3>,
}

impl<'a> LocalMesh<'a> {
    /// `None` for an instance without triangles.
    fn new(scene: &'a Scene, inst: &Instance) -> Option<Self> {
        let first = inst.vertices.start;
        let triangles: Vec<[u32; 3]> = scene.triangles
            [inst.triangles.start as usize..inst.triangles.end as usize]
            .iter()
            .map(|t| t.map(|v| v - first))
            .collect();
        if triangles.is_empty() {
            return None;
        }
        let positions = &scene.positions[inst.vertices.start as usize..inst.vertices.end as usize];
        let weld = weld(positions);
        let edges = edge_list(triangles.len(), |t| triangles[t].map(|v| weld[v as usize]));
        let pos = |v: u32| positions[v as usize].as_dvec3();
        let normal = triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(pos);
                (b - a).cross(c - a).normalize_or_zero()
            })
            .collect();
        Some(LocalMesh {
            positions,
            triangles,
            weld,
            edges,
            normal,
        })
    }

    fn pos(&self, v: u32) -> DVec3 {
        self.positions[v as usize].as_dvec3()
    }

    /// Source vertices (new ones are blends numbered after them).
    fn vertex_count(&self) -> u32 {
        self.positions.len() as u32
    }

    fn welded(&self, t: usize) -> [u32; 3] {
        self.triangles[t].map(|v| self.weld[v as usize])
    }

    /// The triangles on the edge between welded vertices `a` and `b`.
    fn faces_at(&self, a: u32, b: u32) -> &[([u32; 2], u32, u8)] {
        faces_on(&self.edges, a, b)
    }
}

/// An instance's flat patches; a patch a neighbour continues gently is part of a curved
/// surface, no receiver.
struct Patches {
    /// The patch of each triangle (`u32::MAX` for degenerate ones).
    of: Vec<u32>,
    list: Vec<Patch>,
}

impl Patches {
    /// Grows a patch from each triangle not yet in one, over edges to triangles facing the
    /// same way with every corner within the touch distance of the seed's plane.
    fn new(mesh: &LocalMesh, tol: Tolerances) -> Self {
        let tris = &mesh.triangles;
        let mut patch_of = vec![u32::MAX; tris.len()];
        let mut patches: Vec<Patch> = Vec::new();
        for seed in 0..tris.len() {
            if patch_of[seed] != u32::MAX || mesh.normal[seed] == DVec3::ZERO {
                continue;
            }
            let id = patches.len() as u32;
            let n = mesh.normal[seed];
            let origin = mesh.pos(tris[seed][0]);
            let mut members = vec![seed as u32];
            patch_of[seed] = id;
            let mut k = 0;
            while k < members.len() {
                let w = mesh.welded(members[k] as usize);
                k += 1;
                for e in 0..3 {
                    for &(_, u, _) in mesh.faces_at(w[e], w[(e + 1) % 3]) {
                        let u = u as usize;
                        if patch_of[u] == u32::MAX
                            && mesh.normal[u].dot(n) > 1.0 - 1e-9
                            && tris[u]
                                .iter()
                                .all(|&v| (mesh.pos(v) - origin).dot(n).abs() <= tol.touch)
                        {
                            patch_of[u] = id;
                            members.push(u as u32);
                        }
                    }
                }
            }
            members.sort_unstable();
            let u = n.any_orthonormal_vector();
            patches.push(Patch {
                triangles: members,
                plane: Plane {
                    origin,
                    axes: [u, n.cross(u)],
                    normal: n,
                },
            });
        }
        Patches {
            of: patch_of,
            list: patches,
        }
    }

    /// Whether patch `id` is a receiver: no neighbour across its border continues it more
    /// gently than [`SMOOTH_DOT`].
    fn is_receiver(&self, mesh: &LocalMesh, id: u32) -> bool {
        let p = &self.list[id as usize];
        p.triangles.iter().all(|&t| {
            let w = mesh.welded(t as usize);
            (0..3).all(|e| {
                mesh.faces_at(w[e], w[(e + 1) % 3])
                    .iter()
                    .all(|&(_, u, _)| {
                        self.of[u as usize] == id
                            || mesh.normal[u as usize].dot(p.plane.normal) < SMOOTH_DOT
                    })
            })
        })
    }
}

/// An instance's cuts: per patch, clipped into its triangles, and the points they put on mesh
/// edges, which both triangles on an edge share.
struct InstanceCuts {
    /// Per patch, its cuts (`None` for no receiver, or nothing meeting it).
    patches: Vec<Option<Cuts>>,
    /// Per triangle: the cut pieces inside it, each with its extension flag.
    pieces: BTreeMap<u32, Vec<([End; 2], bool)>>,
    /// Welded edge → (its length, parameters from the lower welded end).
    edge_points: BTreeMap<[u32; 2], (f64, Vec<f64>)>,
}

impl InstanceCuts {
    /// Clips each patch's cuts into its triangles and merges the points on each mesh edge;
    /// `None` when no cut touches a triangle.
    fn clip(
        mesh: &LocalMesh,
        patches: &Patches,
        patch_cuts: Vec<Option<Cuts>>,
        snap: f64,
    ) -> Option<Self> {
        let mut pieces: BTreeMap<u32, Vec<([End; 2], bool)>> = BTreeMap::new();
        let mut edge_points: BTreeMap<[u32; 2], (f64, Vec<f64>)> = BTreeMap::new();
        for (patch, cuts) in patches.list.iter().zip(&patch_cuts) {
            let Some(cuts) = cuts else { continue };
            for &t in &patch.triangles {
                let tri = mesh.triangles[t as usize];
                let corners = tri.map(|v| patch.plane.to_2d(mesh.pos(v)));
                let bounds = clip_box(corners, snap);
                let w = mesh.welded(t as usize);
                for &([a, b], extension) in &cuts.segments {
                    let (a, b) = (cuts.points[a as usize], cuts.points[b as usize]);
                    if !may_clip(bounds, a, b) {
                        continue;
                    }
                    let Some(ends) = clip(a, b, corners, snap) else {
                        continue;
                    };
                    for end in ends {
                        if let End::Edge(k, s) = end {
                            let key = [w[k], w[(k + 1) % 3]];
                            let s = if key[0] < key[1] { s } else { 1.0 - s };
                            let length = mesh.pos(tri[k]).distance(mesh.pos(tri[(k + 1) % 3]));
                            edge_points
                                .entry([key[0].min(key[1]), key[0].max(key[1])])
                                .or_insert_with(|| (length, Vec::new()))
                                .1
                                .push(s);
                        }
                    }
                    if !along_an_edge(ends) {
                        pieces.entry(t).or_default().push((ends, extension));
                    }
                }
            }
        }
        if pieces.is_empty() && edge_points.is_empty() {
            return None;
        }
        merge_edge_points(&mut edge_points, snap);
        Some(InstanceCuts {
            patches: patch_cuts,
            pieces,
            edge_points,
        })
    }

    /// The cuts of patch `id`, if any.
    fn of_patch(&self, id: u32) -> Option<&Cuts> {
        self.patches.get(id as usize).and_then(Option::as_ref)
    }

    /// The points on each edge of a triangle with welded corners `w`, as parameters from the
    /// edge's first corner, ascending.
    fn on_edges(&self, w: [u32; 3]) -> [Vec<f64>; 3] {
        std::array::from_fn(|k| {
            let key = [w[k].min(w[(k + 1) % 3]), w[k].max(w[(k + 1) % 3])];
            let ts = self
                .edge_points
                .get(&key)
                .map(|e| e.1.clone())
                .unwrap_or_default();
            if w[k] < w[(k + 1) % 3] {
                ts
            } else {
                ts.iter().rev().map(|t| 1.0 - t).collect()
            }
        })
    }
}

/// Points on one edge closer than the snap distance merge; none next to a corner.
fn merge_edge_points(edge_points: &mut BTreeMap<[u32; 2], (f64, Vec<f64>)>, snap: f64) {
    for (length, ts) in edge_points.values_mut() {
        let gap = snap / length.max(1e-300);
        ts.sort_by(f64::total_cmp);
        let mut merged: Vec<f64> = Vec::new();
        for &t in ts.iter() {
            if t > gap && t < 1.0 - gap && merged.last().is_none_or(|&m| t - m > gap) {
                merged.push(t);
            }
        }
        *ts = merged;
    }
    edge_points.retain(|_, (_, ts)| !ts.is_empty());
}

/// An instance retriangulated along its cuts, before its sides are known.
struct Retriangulated {
    out: InstanceSplit,
    /// Per output triangle: its edges along cuts, `[junction, any cut]` as in [`cut_bits_of`].
    cut_bits: Vec<[u8; 2]>,
    /// Per output triangle: the patch of its source triangle.
    patch: Vec<u32>,
}

impl Retriangulated {
    /// Retriangulates every triangle with a cut or an edge point; `None` when none was split.
    fn new(
        inst: &Instance,
        mesh: &LocalMesh,
        patches: &Patches,
        cuts: &InstanceCuts,
        snap: f64,
        report: &mut JunctionReport,
    ) -> Option<Self> {
        let tris = &mesh.triangles;
        let mut r = Retriangulated {
            out: InstanceSplit {
                triangles: Vec::with_capacity(tris.len()),
                source_triangle: Vec::with_capacity(tris.len()),
                split: Split::default(),
            },
            cut_bits: Vec::with_capacity(tris.len()),
            patch: Vec::with_capacity(tris.len()),
        };
        let mut blends: BTreeMap<Vec<(u32, u32)>, u32> = BTreeMap::new();
        let mut any_split = false;
        for (t, &tri) in tris.iter().enumerate() {
            let on_edges = cuts.on_edges(mesh.welded(t));
            let own = cuts.pieces.get(&(t as u32));
            let id = patches.of[t];
            let patch_cuts = cuts.of_patch(id);
            let source = inst.source_triangle[t];
            if own.is_none() && on_edges.iter().all(Vec::is_empty) {
                // Untouched, but its edges may lie along a cut (a wall on a grid line).
                let corners = tri.map(|v| {
                    (patches.list.get(id as usize))
                        .map_or(DVec2::ZERO, |p| p.plane.to_2d(mesh.pos(v)))
                });
                let bits = patch_cuts.map_or([0, 0], |c| cut_bits_of(corners, c, snap));
                r.push(tri, source, bits, id);
                continue;
            }
            let frame = match patch_cuts {
                Some(_) => &patches.list[id as usize],
                None => &own_frame(tri.map(|v| mesh.pos(v))),
            };
            let corners = tri.map(|v| frame.plane.to_2d(mesh.pos(v)));
            let pieces = own.map_or(&[][..], Vec::as_slice);
            let faces = retriangulate(corners, &on_edges, pieces).or_else(|| {
                report.fallback_triangles += 1;
                // Left uncut, but with the points its neighbours share on its edges: no
                // T-junction.
                (!pieces.is_empty())
                    .then(|| retriangulate(corners, &on_edges, &[]))
                    .flatten()
            });
            let Some(faces) = faces else {
                r.push(tri, source, [0, 0], id);
                continue;
            };
            any_split = true;
            report.triangles_split += usize::from(faces.len() > 1);
            for (face, along_pieces) in faces {
                let mut new_tri = [0u32; 3];
                for (c, (p, end)) in face.iter().enumerate() {
                    new_tri[c] = match end {
                        Some(End::Corner(k)) => tri[*k],
                        _ => {
                            let b = barycentric(*p, corners, *end);
                            let split = &mut r.out.split;
                            vertex_of(b, tri, mesh.vertex_count(), &mut blends, split)
                        }
                    };
                }
                let along_cuts =
                    patch_cuts.map_or([0, 0], |c| cut_bits_of(face.map(|f| f.0), c, snap));
                let bits = [0, 1].map(|k| along_cuts[k] | along_pieces[k]);
                r.push(new_tri, source, bits, id);
            }
        }
        any_split.then_some(r)
    }

    /// Appends one output triangle.
    fn push(&mut self, tri: [u32; 3], source: u32, cut_bits: [u8; 2], patch: u32) {
        self.out.triangles.push(tri);
        self.out.source_triangle.push(source);
        self.cut_bits.push(cut_bits);
        self.patch.push(patch);
    }

    /// The split with its sides (see [`Split::sides`]), counting junction edges whose two
    /// sides stayed connected.
    fn into_split(
        mut self,
        mesh: &LocalMesh,
        cuts: &InstanceCuts,
        report: &mut JunctionReport,
    ) -> InstanceSplit {
        let weld = self.weld(mesh);
        let edges = edge_list(self.out.triangles.len(), |t| self.welded(&weld, t));
        let sides = self.sides(&weld, &edges, cuts);
        for t in 0..self.out.triangles.len() {
            let w = self.welded(&weld, t);
            for k in 0..3 {
                if self.cut_bits[t][0] & (1 << k) != 0
                    && faces_on(&edges, w[k], w[(k + 1) % 3])
                        .iter()
                        .any(|&(_, u, _)| u as usize != t && sides[u as usize] == sides[t])
                {
                    report.unseparated_edges += 1;
                }
            }
        }
        self.out.split.sides = sides;
        self.out.split.junction_edges = self.cut_bits.iter().map(|b| b[0]).collect();
        self.out
    }

    /// The welded vertex of each output vertex, blends included: one per f32 position, as
    /// written out.
    fn weld(&self, mesh: &LocalMesh) -> Vec<u32> {
        let source_vertices = mesh.vertex_count();
        let blend_pos = |v: u32| -> [u64; 3] {
            let p = if v < source_vertices {
                mesh.pos(v)
            } else {
                let b = self.out.split.blends[(v - source_vertices) as usize];
                (0..3).fold(DVec3::ZERO, |s, k| {
                    s + mesh.pos(b.vertices[k]) * f64::from(b.weights[k])
                })
            };
            p.as_vec3()
                .to_array()
                .map(|c| u64::from((c + 0.0).to_bits()))
        };
        let mut keys: Vec<([u64; 3], u32)> = (0..source_vertices
            + self.out.split.blends.len() as u32)
            .map(|v| (blend_pos(v), v))
            .collect();
        keys.sort_unstable();
        let mut weld = vec![0u32; keys.len()];
        for (id, same) in keys.chunk_by(|a, b| a.0 == b.0).enumerate() {
            for &(_, v) in same {
                weld[v as usize] = id as u32;
            }
        }
        weld
    }

    fn welded(&self, weld: &[u32], t: usize) -> [u32; 3] {
        self.out.triangles[t].map(|v| weld[v as usize])
    }

    /// Each output triangle's side: connected across edges that are not cuts, nor borders of
    /// a patch with shadow cuts.
    fn sides(&self, weld: &[u32], edges: &[([u32; 2], u32, u8)], cuts: &InstanceCuts) -> Vec<u32> {
        let shadowed = |id: u32| cuts.of_patch(id).is_some_and(|c| c.shadow);
        let edge_index = |t: usize, a: u32, b: u32| {
            let w = self.welded(weld, t);
            (0..3)
                .find(|&k| {
                    let (x, y) = (w[k], w[(k + 1) % 3]);
                    (x, y) == (a, b) || (x, y) == (b, a)
                })
                .unwrap_or(0)
        };
        let (cut_bits, patch) = (&self.cut_bits, &self.patch);
        let mut sides = vec![u32::MAX; self.out.triangles.len()];
        let mut next_side = 0;
        let mut stack = Vec::new();
        for seed in 0..self.out.triangles.len() {
            if sides[seed] != u32::MAX {
                continue;
            }
            sides[seed] = next_side;
            stack.push(seed);
            while let Some(t) = stack.pop() {
                let w = self.welded(weld, t);
                for k in 0..3 {
                    if cut_bits[t][1] & (1 << k) != 0 {
                        continue;
                    }
                    for &(_, u, _) in faces_on(edges, w[k], w[(k + 1) % 3]) {
                        let u = u as usize;
                        let blocked = cut_bits[u][1] & (1 << edge_index(u, w[k], w[(k + 1) % 3]))
                            != 0
                            || (patch[u] != patch[t] && (shadowed(patch[u]) || shadowed(patch[t])));
                        if sides[u] == u32::MAX && !blocked {
                            sides[u] = next_side;
                            stack.push(u);
                        }
                    }
                }
            }
            next_side += 1;
        }
        sides
    }
}

/// Which edges of `face` (plane coordinates) lie along cuts: `[junction, any cut]`, bit `k`
/// for edge `k`. In a patch with shadow outlines extensions count as junctions (never
/// stitched): the straight continuation of a curved outline's free end runs along the shadow's
/// edge, where stitching pulls the lit and the shadowed side together (on the sphere's shadow a
/// renderer read 0.35 against a reference 0.02).
fn cut_bits_of(face: [DVec2; 3], cuts: &Cuts, snap: f64) -> [u8; 2] {
    const AT: [f64; 5] = [0.0, 0.25, 0.5, 0.75, 1.0];
    let eps = 1e-3 * snap;
    let samples: [[DVec2; 5]; 3] =
        std::array::from_fn(|k| AT.map(|s| face[k].lerp(face[(k + 1) % 3], s)));
    // Per kind (junction cuts, any cut), per edge and sample: on such a cut. Only cuts whose
    // box (widened past `eps`) meets the face's can hold a sample.
    let mut on = [[[false; 5]; 3]; 2];
    let margin = DVec2::splat(2.0 * eps);
    let (lo, hi) = (
        face[0].min(face[1]).min(face[2]),
        face[0].max(face[1]).max(face[2]),
    );
    for &([a, b], ext) in &cuts.segments {
        let (p, q) = (cuts.points[a as usize], cuts.points[b as usize]);
        if p.min(q).cmpgt(hi + margin).any() || p.max(q).cmplt(lo - margin).any() {
            continue;
        }
        let junction = !ext || cuts.shadow;
        for (k, edge) in samples.iter().enumerate() {
            for (j, &x) in edge.iter().enumerate() {
                if distance_to_segment(x, p, q).0 <= eps {
                    on[1][k][j] = true;
                    on[0][k][j] |= junction;
                }
            }
        }
    }
    let mut bits = [0u8; 2];
    for (kind, on) in on.iter().enumerate() {
        for (k, edge) in on.iter().enumerate() {
            if edge.iter().all(|&x| x) {
                bits[kind] |= 1 << k;
            }
        }
    }
    bits
}

/// Every edge as (welded end points ascending, triangle, corner it starts at), sorted.
fn edge_list(triangles: usize, welded: impl Fn(usize) -> [u32; 3]) -> Vec<([u32; 2], u32, u8)> {
    let mut edges = Vec::with_capacity(3 * triangles);
    for t in 0..triangles {
        let w = welded(t);
        for k in 0..3 {
            let (a, b) = (w[k], w[(k + 1) % 3]);
            if a != b {
                edges.push(([a.min(b), a.max(b)], t as u32, k as u8));
            }
        }
    }
    edges.sort_unstable();
    edges
}

fn faces_on(edges: &[([u32; 2], u32, u8)], a: u32, b: u32) -> &[([u32; 2], u32, u8)] {
    let e = [a.min(b), a.max(b)];
    let lo = edges.partition_point(|x| x.0 < e);
    let len = edges[lo..].partition_point(|x| x.0 == e);
    &edges[lo..lo + len]
}

/// A one-triangle frame (for triangles outside any receiver that only get edge points).
fn own_frame(p: [DVec3; 3]) -> Patch {
    let n = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
    let u = n.any_orthonormal_vector();
    Patch {
        triangles: Vec::new(),
        plane: Plane {
            origin: p[0],
            axes: [u, n.cross(u)],
            normal: n,
        },
    }
}

/// The junction segments of a receiver patch, snapped, split and with free ends extended.
#[allow(clippy::too_many_arguments)]
fn patch_cuts_of(
    cutting: Cutting,
    index: u32,
    patch: &Patch,
    tris: &[[u32; 3]],
    weld: &[u32],
    pos: impl Fn(u32) -> DVec3 + Copy,
    shadow: &mut ShadowWork,
    report: &mut JunctionReport,
) -> Option<Cuts> {
    let Cutting {
        scene,
        grid,
        tol,
        shadows,
        ..
    } = cutting;
    // The patch's edges and vertices in plane coordinates.
    let mut counted: BTreeMap<[u32; 2], (usize, [DVec2; 2])> = BTreeMap::new();
    let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
    let mut corners2d = Vec::with_capacity(patch.triangles.len());
    for &t in &patch.triangles {
        let tri = tris[t as usize];
        let c = tri.map(|v| patch.plane.to_2d(pos(v)));
        corners2d.push(c);
        for k in 0..3 {
            let p = pos(tri[k]);
            (lo, hi) = (lo.min(p), hi.max(p));
            let (a, b) = (weld[tri[k] as usize], weld[tri[(k + 1) % 3] as usize]);
            let entry = counted
                .entry([a.min(b), a.max(b)])
                .or_insert((0, [c[k], c[(k + 1) % 3]]));
            entry.0 += 1;
        }
    }
    let corners2d = Triangles2d::new(corners2d, tol.snap);
    let edges: Vec<([DVec2; 2], bool)> = counted.values().map(|&(n, e)| (e, n == 1)).collect();
    let mut vertices: Vec<(DVec2, bool)> = Vec::new();
    // Equal positions are one vertex (`+ 0.0`: -0 is 0), in the order edges first meet them.
    let mut vertex_at: HashMap<[u64; 2], usize> = HashMap::new();
    for &([a, b], border) in &edges {
        for p in [a, b] {
            let key = [(p.x + 0.0).to_bits(), (p.y + 0.0).to_bits()];
            let k = *vertex_at.entry(key).or_insert_with(|| {
                vertices.push((p, false));
                vertices.len() - 1
            });
            vertices[k].1 |= border;
        }
    }
    let patch_edges = PatchEdges::new(edges, vertices);

    // Segments where other triangles cross the plane or stand on it, clipped to the patch.
    let mut cuts = Cuts {
        points: Vec::new(),
        on_border: Vec::new(),
        segments: Vec::new(),
        shadow: false,
    };
    let inst = &scene.instances[index as usize];
    let own = |g: u32| {
        inst.triangles.contains(&g)
            && patch
                .triangles
                .binary_search(&(g - inst.triangles.start))
                .is_ok()
    };
    // The segment a–b (world space, in the patch's plane) as cuts, clipped to the patch.
    let cut_along = |cuts: &mut Cuts, a: DVec3, b: DVec3| {
        let (a, b) = (patch.plane.to_2d(a), patch.plane.to_2d(b));
        let length = a.distance(b);
        if length <= tol.snap {
            return;
        }
        for [s0, s1] in corners2d.inside_intervals(a, b, tol.snap) {
            if (s1 - s0) * length > tol.snap {
                let i = cuts.point(a.lerp(b, s0), &patch_edges, tol);
                let j = cuts.point(a.lerp(b, s1), &patch_edges, tol);
                cuts.add(i, j, false);
            }
        }
    };
    // Near contacts: the triangles facing the patch from less than `tol.near` in front of it.
    let mut facing: Vec<u32> = Vec::new();
    let reach = tol.touch.max(tol.near);
    for g in grid.query(lo - reach, hi + reach) {
        if own(g) {
            continue;
        }
        let p = scene.triangles[g as usize].map(|v| scene.positions[v as usize].as_dvec3());
        if tol.near > 0.0 && faces_near(p, patch, tol) {
            facing.push(g);
        }
        if let Some([a, b]) = plane_segment(p, patch, tol.touch) {
            cut_along(&mut cuts, a, b);
        }
    }
    // The outline of the near surfaces, projected: junctions too (the slot between a door's
    // edge and its lining is dark, the lining beside it in the room is not).
    for [a, b] in outline(scene, &facing) {
        let before = cuts.segments.len();
        cut_along(&mut cuts, a, b);
        report.near_segments += cuts.segments.len() - before;
    }
    // Shadow outlines of punctual lights: cuts never stitched, as junctions are.
    if let Some(shadows) = shadows {
        let (plane, texel, touch) = (&patch.plane, tol.texel, tol.touch);
        for [a, b] in shadows.patch_cuts(plane, &corners2d, (lo, hi), texel, touch, shadow) {
            let i = cuts.point(a, &patch_edges, tol);
            let j = cuts.point(b, &patch_edges, tol);
            let before = cuts.segments.len();
            cuts.add(i, j, false);
            report.shadow_segments += cuts.segments.len() - before;
            cuts.shadow = true;
        }
    }
    // Segments lying along the patch border change nothing: leave them out.
    cuts.segments.retain(|&([a, b], _)| {
        let (p, q) = (cuts.points[a as usize], cuts.points[b as usize]);
        !patch_edges.along_border(p, q, 1e-6 * tol.snap)
    });
    if cuts.segments.is_empty() {
        return None;
    }
    cuts.split_at_points(tol.snap);
    cuts.extend_free_ends(&patch_edges, tol);
    Some(cuts)
}

/// Whether triangle `p` faces the patch (normals opposed within [`FACING_DOT`]) from in front
/// of it, every corner farther than the touch distance and no farther than the near distance:
/// a near contact.
fn faces_near(p: [DVec3; 3], patch: &Patch, tol: Tolerances) -> bool {
    let n = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
    n.dot(patch.plane.normal) <= -FACING_DOT
        && p.iter().all(|&q| {
            let d = (q - patch.plane.origin).dot(patch.plane.normal);
            d > tol.touch && d <= tol.near
        })
}

/// The outline of the triangles `set` (scene triangle indices): their edges that no other
/// triangle of the set shares (vertices matched by position), in world space, in a fixed
/// order.
fn outline(scene: &Scene, set: &[u32]) -> Vec<[DVec3; 2]> {
    let key = |v: u32| {
        (scene.positions[v as usize] + Vec3::ZERO)
            .to_array()
            .map(f32::to_bits)
    };
    let mut edges: Vec<([[u32; 3]; 2], [u32; 2])> = Vec::with_capacity(3 * set.len());
    for &g in set {
        let t = scene.triangles[g as usize];
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            let (ka, kb) = (key(a), key(b));
            if ka != kb {
                edges.push(if ka < kb {
                    ([ka, kb], [a, b])
                } else {
                    ([kb, ka], [b, a])
                });
            }
        }
    }
    edges.sort_unstable();
    edges
        .chunk_by(|x, y| x.0 == y.0)
        .filter(|same| same.len() == 1)
        .map(|e| e[0].1.map(|v| scene.positions[v as usize].as_dvec3()))
        .collect()
}

/// Where triangle `p` meets the patch's plane: a segment when it crosses the plane or has an
/// edge in it (corners within `touch` count as in it); nothing when coplanar or touching at a
/// point.
fn plane_segment(p: [DVec3; 3], patch: &Patch, touch: f64) -> Option<[DVec3; 2]> {
    let d = p.map(|q| (q - patch.plane.origin).dot(patch.plane.normal));
    let side = d.map(|x| {
        if x.abs() <= touch {
            0
        } else {
            x.signum() as i32
        }
    });
    if side.iter().all(|&s| s == 0) {
        return None;
    }
    let mut points = Vec::with_capacity(3);
    for k in 0..3 {
        let j = (k + 1) % 3;
        if side[k] == 0 {
            points.push(p[k] - patch.plane.normal * d[k]);
        }
        if side[k] * side[j] < 0 {
            let s = d[k] / (d[k] - d[j]);
            points.push(p[k].lerp(p[j], s));
        }
    }
    match points[..] {
        [a, b] => Some([a, b]),
        _ => None,
    }
}

/// The piece of cut `a → b` inside triangle `c`, its ends classified; `None` when it misses or
/// only touches it.
fn clip(a: DVec2, b: DVec2, c: [DVec2; 3], snap: f64) -> Option<[End; 2]> {
    let [s0, s1] = clip_interval(a, b, c, 1e-9 * snap)?;
    if (s1 - s0) * a.distance(b) <= 1e-6 * snap {
        return None;
    }
    // Clipped ends lie on the triangle's edges up to rounding; cut points inside stay put.
    let near = 1e-6 * snap;
    let classify = |p: DVec2| {
        if let Some(k) = (0..3).find(|&k| c[k].distance(p) <= near) {
            return End::Corner(k);
        }
        let faces_at = (0..3)
            .map(|k| (k, distance_to_segment(p, c[k], c[(k + 1) % 3])))
            .filter(|(_, (d, _))| *d <= near)
            .min_by(|x, y| x.1.0.total_cmp(&y.1.0));
        match faces_at {
            Some((k, (_, t))) => End::Edge(k, t),
            None => End::Inside(p),
        }
    };
    Some([classify(a.lerp(b, s0)), classify(a.lerp(b, s1))])
}

/// Both ends on one edge of the triangle (its corners included): the piece runs along it.
fn along_an_edge(ends: [End; 2]) -> bool {
    let edges_of = |e: End| -> u8 {
        match e {
            End::Corner(k) => (1 << k) | (1 << ((k + 2) % 3)),
            End::Edge(k, _) => 1 << k,
            End::Inside(_) => 0,
        }
    };
    edges_of(ends[0]) & edges_of(ends[1]) != 0
}

/// A new face: its corners in plane coordinates, with what each is (`None`: a crossing of
/// two cuts).
type Face = [(DVec2, Option<End>); 3];

/// Triangulates triangle `c` again with the points on its edges (parameters from corner `k`,
/// ascending) and the cut pieces inside it (with their extension flags); `None` when the faces
/// do not add up to its area (one face, the triangle itself, when every piece runs along its
/// edges). Each face comes with the edges that lie along a piece,
/// `[junction, any cut]` as in [`cut_bits_of`]: a piece ending at a merged edge point or a corner
/// runs where its cut nearly does, so the constraint edges say what is cut, not the geometry.
fn retriangulate(
    c: [DVec2; 3],
    on_edges: &[Vec<f64>; 3],
    pieces: &[([End; 2], bool)],
) -> Option<Vec<(Face, [u8; 2])>> {
    let mut cdt: ConstrainedDelaunayTriangulation<Point2<f64>> =
        ConstrainedDelaunayTriangulation::new();
    let mut what: BTreeMap<usize, End> = BTreeMap::new();
    let mut insert = |cdt: &mut ConstrainedDelaunayTriangulation<Point2<f64>>, p: DVec2, e: End| {
        let h = cdt.insert(Point2::new(p.x, p.y)).ok()?;
        what.entry(h.index()).or_insert(e);
        Some(h)
    };
    let corner = [0, 1, 2].map(|k| insert(&mut cdt, c[k], End::Corner(k)));
    let [Some(c0), Some(c1), Some(c2)] = corner else {
        return None;
    };
    let corner = [c0, c1, c2];
    let mut on_edge_handles: [Vec<(f64, spade::handles::FixedVertexHandle)>; 3] =
        Default::default();
    for k in 0..3 {
        let mut chain = vec![corner[k]];
        for &t in &on_edges[k] {
            let h = insert(&mut cdt, c[k].lerp(c[(k + 1) % 3], t), End::Edge(k, t))?;
            on_edge_handles[k].push((t, h));
            chain.push(h);
        }
        chain.push(corner[(k + 1) % 3]);
        for pair in chain.windows(2) {
            cdt.add_constraint_and_split(pair[0], pair[1], |p| p);
        }
    }
    // Each piece as inserted: its end handles and whether it is a junction.
    let mut inserted: Vec<([spade::handles::FixedVertexHandle; 2], bool)> = Vec::new();
    for (piece, extension) in pieces {
        let mut handles = [corner[0]; 2];
        for (h, end) in handles.iter_mut().zip(piece) {
            *h = match *end {
                End::Corner(k) => corner[k],
                // The merged edge point nearest to where the cut meets the edge, or the corner
                // when that is nearer (points next to a corner were merged into it).
                End::Edge(k, t) => on_edge_handles[k]
                    .iter()
                    .copied()
                    .chain([(0.0, corner[k]), (1.0, corner[(k + 1) % 3])])
                    .min_by(|x, y| (x.0 - t).abs().total_cmp(&(y.0 - t).abs()))
                    .map(|x| x.1)?,
                End::Inside(p) => insert(&mut cdt, p, End::Inside(p))?,
            };
        }
        if handles[0] != handles[1] {
            cdt.add_constraint_and_split(handles[0], handles[1], |p| p);
            inserted.push((handles, !extension));
        }
    }
    let at = |h: spade::handles::FixedVertexHandle| {
        let q = cdt.vertex(h).position();
        DVec2::new(q.x, q.y)
    };
    let lines: Vec<([DVec2; 2], bool)> = inserted
        .iter()
        .map(|&([a, b], junction)| ([at(a), at(b)], junction))
        .collect();
    // A constraint edge along an inserted piece (split where pieces cross: its crossing points
    // lie on it up to rounding).
    let scale = (c[1] - c[0]).length() + (c[2] - c[1]).length() + (c[0] - c[2]).length();
    let on_piece = |p: DVec2, q: DVec2| -> Option<bool> {
        let near = |x: DVec2, [a, b]: [DVec2; 2]| distance_to_segment(x, a, b).0 <= 1e-7 * scale;
        let along = |line| near(p, line) && near(q, line) && near(0.5 * (p + q), line);
        let mut hits = lines.iter().filter(|(line, _)| along(*line));
        let first = hits.next()?;
        Some(first.1 || hits.any(|h| h.1))
    };
    let area = 0.5 * (c[1] - c[0]).perp_dot(c[2] - c[0]);
    let mut faces = Vec::new();
    let mut total = 0.0;
    for face in cdt.inner_faces() {
        let v = face.vertices();
        let p = v.map(|h| {
            let q = h.position();
            DVec2::new(q.x, q.y)
        });
        let a = 0.5 * (p[1] - p[0]).perp_dot(p[2] - p[0]);
        if a <= 1e-9 * area {
            continue;
        }
        total += a;
        let mut bits = [0u8; 2];
        for k in 0..3 {
            let constraint = cdt.exists_constraint(v[k].fix(), v[(k + 1) % 3].fix());
            if constraint && let Some(junction) = on_piece(p[k], p[(k + 1) % 3]) {
                bits[1] |= 1 << k;
                bits[0] |= u8::from(junction) << k;
            }
        }
        faces.push((
            [0, 1, 2].map(|k| (p[k], what.get(&v[k].fix().index()).copied())),
            bits,
        ));
    }
    // One face: every piece runs along the triangle's edges (ends merged into its corners).
    ((total - area).abs() <= 1e-6 * area).then_some(faces)
}

/// Barycentric weights of `p` in triangle `c`; points on an edge get exactly two weights.
fn barycentric(p: DVec2, c: [DVec2; 3], end: Option<End>) -> [f64; 3] {
    if let Some(End::Edge(k, t)) = end {
        let mut w = [0.0; 3];
        w[k] = 1.0 - t;
        w[(k + 1) % 3] = t;
        return w;
    }
    let area = (c[1] - c[0]).perp_dot(c[2] - c[0]);
    let w1 = (p - c[0]).perp_dot(c[2] - c[0]) / area;
    let w2 = (c[1] - c[0]).perp_dot(p - c[0]) / area;
    let w = [1.0 - w1 - w2, w1, w2].map(|x: f64| x.max(0.0));
    let sum: f64 = w.iter().sum();
    w.map(|x| x / sum)
}

/// The local vertex for weights `w` over `tri`'s vertices: a source vertex, or the blend with
/// these exact weights (created once, so triangles on both sides of an edge share it).
fn vertex_of(
    w: [f64; 3],
    tri: [u32; 3],
    source_vertices: u32,
    blends: &mut BTreeMap<Vec<(u32, u32)>, u32>,
    split: &mut Split,
) -> u32 {
    let mut parts: Vec<(u32, f32)> = (0..3)
        .filter(|&k| w[k] > 0.0)
        .map(|k| (tri[k], w[k] as f32))
        .filter(|p| p.1 > 0.0)
        .collect();
    parts.sort_by_key(|p| p.0);
    if let [(v, _)] = parts[..] {
        return v;
    }
    let key: Vec<(u32, u32)> = parts.iter().map(|&(v, w)| (v, w.to_bits())).collect();
    *blends.entry(key).or_insert_with(|| {
        let mut blend = Blend {
            vertices: [parts[0].0; 3],
            weights: [0.0; 3],
        };
        for (k, &(v, w)) in parts.iter().enumerate() {
            blend.vertices[k] = v;
            blend.weights[k] = w;
        }
        split.blends.push(blend);
        source_vertices + split.blends.len() as u32 - 1
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Instance, LightKind, Material};

    /// The queries sorted by `x` find what scanning every vertex and edge finds (ties to the
    /// first listed), and `along_border` agrees with testing every border edge.
    #[test]
    fn patch_edge_queries_match_scanning_every_edge() {
        let mut rng = crate::sampling::Rng::new(3, 0, 0);
        let mut point = || {
            // On a coarse lattice now and then, so that distances tie.
            let p = DVec2::new(rng.next_f32() as f64, rng.next_f32() as f64) * 2.0;
            if rng.next_f32() < 0.3 {
                (p * 8.0).round() / 8.0
            } else {
                p
            }
        };
        let mut edges: Vec<([DVec2; 2], bool)> = Vec::new();
        for k in 0..400 {
            let a = point();
            let b = if k % 5 == 0 {
                a
            } else {
                a + (point() - 1.0) * 0.3
            };
            edges.push(([a, b], k % 3 != 0));
        }
        edges.push(([DVec2::ZERO, DVec2::new(2.0, 2.0)], true)); // spans the whole patch
        let mut vertices: Vec<(DVec2, bool)> = Vec::new();
        for &([a, b], border) in &edges {
            for p in [a, b] {
                match vertices.iter_mut().find(|(q, _)| *q == p) {
                    Some(v) => v.1 |= border,
                    None => vertices.push((p, border)),
                }
            }
        }
        let brute_nearest = |p: DVec2, within: f64, border_only: bool| {
            let vertex = (vertices.iter())
                .filter(|v| v.1 || !border_only)
                .map(|&(v, border)| (v.distance(p), v, border))
                .filter(|x| x.0 <= within)
                .min_by(|x, y| x.0.total_cmp(&y.0));
            vertex
                .or_else(|| {
                    (edges.iter())
                        .filter(|e| e.1 || !border_only)
                        .map(|&([a, b], border)| {
                            let (d, t) = distance_to_segment(p, a, b);
                            (d, a.lerp(b, t), border)
                        })
                        .filter(|x| x.0 <= within)
                        .min_by(|x, y| x.0.total_cmp(&y.0))
                })
                .map(|(_, q, border)| (q, border))
        };
        let brute_along = |p: DVec2, q: DVec2, near: f64| {
            [0.0, 0.25, 0.5, 0.75, 1.0].iter().all(|&s| {
                let x = p.lerp(q, s);
                (edges.iter())
                    .any(|&([u, v], border)| border && distance_to_segment(x, u, v).0 <= near)
            })
        };
        let patch = PatchEdges::new(edges.clone(), vertices.clone());
        let (mut found, mut along) = (0, 0);
        for k in 0..3000 {
            let p = point();
            let within = [0.01, 0.05, 0.2][k % 3];
            let expected = brute_nearest(p, within, k % 2 == 0);
            found += usize::from(expected.is_some());
            assert_eq!(patch.nearest(p, within, k % 2 == 0), expected, "at {p}");
            let ([a, b], _) = edges[k % edges.len()];
            let (p, q) = match k % 4 {
                0 => (a, b),
                1 => (a.lerp(b, 0.25), a.lerp(b, 0.75)),
                _ => (p, point()),
            };
            let expected = brute_along(p, q, 1e-6);
            along += usize::from(expected);
            assert_eq!(patch.along_border(p, q, 1e-6), expected, "{p} → {q}");
        }
        assert!(
            found > 1000 && along > 100,
            "{found} found, {along} along the border"
        );
    }

    /// Points near a segment's ends or near each other split it into no sliver (the fuzzer's
    /// out-of-memory case was pieces splitting each other without end).
    #[test]
    fn segments_are_not_split_into_slivers() {
        let snap = 0.01;
        let mut cuts = Cuts {
            points: vec![
                DVec2::ZERO,
                DVec2::X,
                DVec2::new(0.995, 0.002),
                DVec2::new(0.5, 0.003),
                DVec2::new(0.5004, -0.003),
            ],
            on_border: vec![false; 5],
            segments: vec![([0, 1], false)],
            shadow: false,
        };
        cuts.split_at_points(snap);
        assert_eq!(cuts.segments.len(), 2, "{:?}", cuts.segments);
        for ([a, b], _) in &cuts.segments {
            let length = cuts.points[*a as usize].distance(cuts.points[*b as usize]);
            assert!(length > snap, "{:?}", cuts.segments);
        }
    }

    /// A scene of one instance per mesh (positions, triangles), normals from the first face.
    fn scene_of(meshes: &[(Vec<Vec3>, Vec<[u32; 3]>)]) -> Scene {
        let mut scene = Scene {
            materials: vec![Material::default()],
            ..Scene::default()
        };
        for (i, (positions, triangles)) in meshes.iter().enumerate() {
            let first = scene.positions.len() as u32;
            let first_triangle = scene.triangles.len() as u32;
            let [a, b, c] = triangles[0].map(|v| positions[v as usize]);
            let n = (b - a).cross(c - a).normalize();
            scene.positions.extend(positions);
            scene
                .normals
                .extend(std::iter::repeat_n(n, positions.len()));
            scene
                .uv0
                .extend(positions.iter().map(|p| Vec2::new(p.x, p.z)));
            scene
                .uv1
                .extend(std::iter::repeat_n(Vec2::ZERO, positions.len()));
            scene
                .triangles
                .extend(triangles.iter().map(|t| t.map(|v| v + first)));
            scene
                .triangle_instance
                .extend(std::iter::repeat_n(i as u32, triangles.len()));
            scene.instances.push(Instance {
                node: i as u32,
                mesh: i as u32,
                primitive: 0,
                material: 0,
                vertices: first..scene.positions.len() as u32,
                triangles: first_triangle..scene.triangles.len() as u32,
                source_triangle: (0..triangles.len() as u32).collect(),
                back_of: None,
                back: None,
                has_uv1: false,
                lightmap: None,
                directional: None,
                split: Split::default(),
            });
        }
        scene.validate();
        scene
    }

    /// A 4 × 4 floor in y = 0 facing +y, as two triangles.
    fn floor() -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let p = vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(0.0, 0.0, 4.0),
            Vec3::new(4.0, 0.0, 4.0),
            Vec3::new(4.0, 0.0, 0.0),
        ];
        (p, vec![[0, 1, 2], [0, 2, 3]])
    }

    /// A wall in the plane x = `x` over z in `z0..z1`, 3 high, standing on the floor.
    fn wall(x: f32, z0: f32, z1: f32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let p = vec![
            Vec3::new(x, 0.0, z0),
            Vec3::new(x, 0.0, z1),
            Vec3::new(x, 3.0, z1),
            Vec3::new(x, 3.0, z0),
        ];
        (p, vec![[0, 1, 2], [0, 2, 3]])
    }

    /// No vertex the split added lies strictly inside an edge of the instance's triangles.
    fn assert_no_t_junctions(scene: &Scene, i: usize) {
        let inst = &scene.instances[i];
        let added = inst.vertices.end as usize - inst.split.blends.len();
        let vertices = &scene.positions[added..inst.vertices.end as usize];
        for t in inst.triangles.clone() {
            let tri = scene.triangles[t as usize];
            for k in 0..3 {
                let (a, b) = (
                    scene.positions[tri[k] as usize].as_dvec3(),
                    scene.positions[tri[(k + 1) % 3] as usize].as_dvec3(),
                );
                for p in vertices {
                    let p = p.as_dvec3();
                    let s = (p - a).dot(b - a) / (b - a).length_squared();
                    let off = (a + (b - a) * s).distance(p);
                    assert!(
                        !(off < 1e-5 && s > 1e-4 && s < 1.0 - 1e-4),
                        "vertex {p} lies inside edge {a} – {b}"
                    );
                }
            }
        }
    }

    /// The floor's triangles lie on one side of x = 2 each (none straddles the wall).
    fn assert_sides_of_wall(scene: &Scene, x: f32) {
        let inst = &scene.instances[0];
        let mut sides = [BTreeMap::new(), BTreeMap::new()];
        for (local, t) in inst.triangles.clone().enumerate() {
            let xs = scene.triangles[t as usize].map(|v| scene.positions[v as usize].x);
            let west = xs.iter().all(|&v| v <= x + 1e-6);
            let east = xs.iter().all(|&v| v >= x - 1e-6);
            assert!(west != east, "triangle {t} straddles the wall: {xs:?}");
            *sides[usize::from(east)]
                .entry(inst.split.sides[local])
                .or_insert(0) += 1;
        }
        // Each side of the wall is its own set of sides.
        assert!(sides[0].keys().all(|s| !sides[1].contains_key(s)));
    }

    #[test]
    fn a_wall_standing_on_a_floor_cuts_it_along_its_base() {
        let scene = scene_of(&[floor(), wall(2.0, 0.0, 4.0)]);
        let (split, report) = split(scene, 0.1);
        assert_eq!(report.receivers, 1, "{report:?}");
        assert_eq!(report.segments, 1);
        assert_eq!(report.extensions, 0);
        assert_eq!(report.unseparated_edges, 0);
        let floor = &split.instances[0];
        assert!(floor.triangles.len() > 2);
        let area: f64 = floor
            .triangles
            .clone()
            .map(|t| split.triangle_area(t as usize))
            .sum();
        assert!((area - 16.0).abs() < 1e-5, "area {area}");
        assert_sides_of_wall(&split, 2.0);
        assert_no_t_junctions(&split, 0);
        // The wall itself is untouched (the floor only meets its border).
        assert_eq!(split.instances[1].triangles.len(), 2);
        assert!(split.instances[1].split.blends.is_empty());
        // New vertices are blends of the floor's own vertices, and junction edges are marked.
        let blends = &floor.split.blends;
        assert_eq!(
            blends.len() + 4,
            (floor.vertices.end - floor.vertices.start) as usize
        );
        for (k, b) in blends.iter().enumerate() {
            let p = split.positions[floor.vertices.start as usize + 4 + k];
            assert!((p.x - 2.0).abs() < 1e-6, "new vertex {p} off the wall");
            assert!(b.vertices.iter().all(|&v| v < 4));
            assert!((b.weights.iter().sum::<f32>() - 1.0).abs() < 1e-6);
        }
        let marked = floor
            .triangles
            .clone()
            .flat_map(|t| (0..3).map(move |k| (t, k)))
            .filter(|&(t, k)| split.is_junction_edge(t, k))
            .count();
        assert_eq!(
            marked, 4,
            "two triangles on each side of the base have it as an edge"
        );
    }

    /// Shortest edge and smallest altitude of scene triangle `t`.
    fn triangle_shape(scene: &Scene, t: usize) -> (f64, f64) {
        let p = scene.triangles[t].map(|v| scene.positions[v as usize].as_dvec3());
        let edges = [0, 1, 2].map(|k| p[k].distance(p[(k + 1) % 3]));
        let longest = edges.iter().copied().fold(0.0, f64::max);
        let shortest = edges.iter().copied().fold(f64::INFINITY, f64::min);
        (shortest, 2.0 * scene.triangle_area(t) / longest)
    }

    /// Two_rooms' ceiling at 16 texels per unit, reduced to one cell: a wall of two quads
    /// meets the cell's diagonal where its quads meet, (−1, −2). In f32 the diagonal runs
    /// 4e-7 texel past that cut point, which was left inside one triangle: two needles with an
    /// edge of 6e-7 texel (the atlas must hide such triangles from xatlas). The point now lies
    /// on the diagonal, shared by the triangles on both sides.
    #[test]
    fn walls_meeting_on_a_diagonal_make_no_needle() {
        let (x0, x1, z0, z1) = (-4.0 / 3.0, -2.0 / 3.0, -16.0 / 7.0, -12.0 / 7.0);
        let cell = (
            vec![
                Vec3::new(x0, 0.0, z0),
                Vec3::new(x0, 0.0, z1),
                Vec3::new(x1, 0.0, z1),
                Vec3::new(x1, 0.0, z0),
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        );
        let wall = (
            [-2.0, -1.0, 0.0]
                .into_iter()
                .flat_map(|x| [Vec3::new(x, 0.0, -2.0), Vec3::new(x, 3.0, -2.0)])
                .collect(),
            vec![[0, 2, 3], [0, 3, 1], [2, 4, 5], [2, 5, 3]],
        );
        let texel = 1.0 / 16.0;
        let (split, report) = split(scene_of(&[cell, wall]), texel);
        assert_eq!(report.receivers, 1, "{report:?}");
        assert_eq!(report.fallback_triangles, 0, "{report:?}");
        assert_eq!(report.unseparated_edges, 0, "{report:?}");
        let cell = &split.instances[0];
        let area: f64 = cell
            .triangles
            .clone()
            .map(|t| split.triangle_area(t as usize))
            .sum();
        assert!((area - 2.0 / 3.0 * 4.0 / 7.0).abs() < 1e-6, "area {area}");
        assert_no_t_junctions(&split, 0);
        for t in cell.triangles.clone() {
            let (edge, altitude) = triangle_shape(&split, t as usize);
            let texel = f64::from(texel);
            assert!(
                edge > 0.25 * texel && altitude > 0.25 * texel,
                "triangle {t}: shortest edge {:.1e}, altitude {:.1e} texel",
                edge / texel,
                altitude / texel
            );
            // Every triangle on one side of the wall, and the cut on the wall's line.
            let zs = split.triangles[t as usize].map(|v| split.positions[v as usize].z);
            assert!(zs.iter().all(|&z| z <= -2.0 + 1e-6) || zs.iter().all(|&z| z >= -2.0 - 1e-6));
        }
        for k in cell.vertices.start + 4..cell.vertices.end {
            let p = split.positions[k as usize];
            assert!((p.z + 2.0).abs() < 1e-6, "new vertex {p} off the wall");
        }
    }

    #[test]
    fn a_doorway_is_closed_by_an_extension_that_is_no_junction() {
        let scene = scene_of(&[floor(), wall(2.0, 0.0, 1.5), wall(2.0, 2.5, 4.0)]);
        let (split, report) = split(scene, 0.1);
        assert_eq!(report.receivers, 1, "{report:?}");
        assert_eq!(report.segments, 2);
        assert_eq!(
            report.extensions, 1,
            "the two free ends meet: one extension"
        );
        assert_eq!(report.unseparated_edges, 0);
        assert_sides_of_wall(&split, 2.0);
        assert_no_t_junctions(&split, 0);
        // Under the doorway (z in 1.5..2.5) no edge is a junction.
        let floor = &split.instances[0];
        for t in floor.triangles.clone() {
            let tri = split.triangles[t as usize];
            for k in 0..3 {
                let (a, b) = (
                    split.positions[tri[k] as usize],
                    split.positions[tri[(k + 1) % 3] as usize],
                );
                let mid = 0.5 * (a + b);
                let in_doorway = (mid.x - 2.0).abs() < 1e-6 && mid.z > 1.5 && mid.z < 2.5;
                if in_doorway {
                    assert!(!split.is_junction_edge(t, k));
                }
            }
        }
    }

    #[test]
    fn a_wall_beside_the_floor_or_a_touching_point_cuts_nothing() {
        // Off the floor (x = 5) and a tetrahedron touching it at one corner.
        let tip = (
            vec![
                Vec3::new(2.0, 0.0, 2.0),
                Vec3::new(1.0, 1.0, 1.0),
                Vec3::new(3.0, 1.0, 1.0),
                Vec3::new(2.0, 1.0, 3.0),
            ],
            vec![[0, 1, 2], [0, 2, 3], [0, 3, 1]],
        );
        let scene = scene_of(&[floor(), wall(5.0, 0.0, 4.0), tip]);
        let triangles = scene.triangles.clone();
        let (split, report) = split(scene, 0.1);
        assert_eq!(report, JunctionReport::default());
        assert_eq!(split.triangles, triangles);
    }

    #[test]
    fn two_rooms_is_cut_along_every_junction_of_its_partition() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/fixtures/two_rooms.gltf");
        let (scene, _) = crate::scene::load(std::path::Path::new(path)).expect("fixture loads");
        let area = |s: &Scene| -> f64 { (0..s.triangles.len()).map(|t| s.triangle_area(t)).sum() };
        let before = area(&scene);
        let (split, report) = split(scene, 1.0 / 16.0);
        // Floor, and the shell's ceiling and side walls; nothing left whole or connected.
        let cut: Vec<(u32, bool)> = split
            .instances
            .iter()
            .filter(|i| !i.split.blends.is_empty())
            .map(|i| (i.mesh, i.back_of.is_some()))
            .collect();
        assert_eq!(cut, [(0, false), (1, false)], "{report:?}");
        assert_eq!(report.fallback_triangles, 0, "{report:?}");
        assert_eq!(report.unseparated_edges, 0, "{report:?}");
        assert_eq!(report.extensions, 1, "the doorway: {report:?}");
        assert!((area(&split) - before).abs() < 1e-4 * before);
        for i in 0..split.instances.len() {
            assert_no_t_junctions(&split, i);
        }
        // Every floor triangle lies on one side of the wall at x = 0.
        let floor = split
            .instances
            .iter()
            .position(|i| i.mesh == 0)
            .expect("floor");
        for t in split.instances[floor].triangles.clone() {
            let xs = split.triangles[t as usize].map(|v| split.positions[v as usize].x);
            assert!(xs.iter().all(|&x| x <= 1e-6) || xs.iter().all(|&x| x >= -1e-6));
        }
    }

    /// A closed box from `lo` to `hi`, faces counter-clockwise seen from outside.
    fn cuboid(lo: Vec3, hi: Vec3) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let mut p = Vec::new();
        let mut t = Vec::new();
        for axis in 0..3 {
            for high in [false, true] {
                let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
                let corner = |a: bool, b: bool| {
                    let mut c = lo;
                    c[axis] = if high { hi[axis] } else { lo[axis] };
                    c[u] = if a { hi[u] } else { lo[u] };
                    c[v] = if b { hi[v] } else { lo[v] };
                    c
                };
                let first = p.len() as u32;
                p.extend([
                    corner(false, false),
                    corner(true, false),
                    corner(true, true),
                ]);
                p.push(corner(false, true));
                // (u, v, axis) is right-handed: counter-clockwise in (u, v) faces +axis.
                let quad = [[0, 1, 2], [0, 2, 3]].map(|q: [u32; 3]| q.map(|k| k + first));
                t.extend(if high {
                    quad
                } else {
                    quad.map(|q| [q[0], q[2], q[1]])
                });
            }
        }
        (p, t)
    }

    /// A box floating 2 cm over the floor (a fifth of a texel), one side 1 cm short of the
    /// floor's edge: with near contacts the floor is cut along the box's outline, and the 1 cm
    /// strip beside it (a tenth of a texel) stays out of the side under the box; without, nothing
    /// is cut.
    #[test]
    fn a_box_floating_over_a_floor_cuts_it_along_its_outline_with_near_contacts() {
        let scene = scene_of(&[
            floor(),
            cuboid(Vec3::new(1.0, 0.02, 1.0), Vec3::new(3.99, 1.0, 3.0)),
        ]);
        let (whole, report) = split(scene.clone(), 0.1);
        assert_eq!(report.segments, 0, "{report:?}");
        assert_eq!(whole.triangles, scene.triangles);

        let (split, report) =
            split_budgeted(scene, Tolerances::of(0.1, true), None, &[], MAX_SAMPLES);
        assert_eq!(report.receivers, 1, "{report:?}");
        assert_eq!(report.near_segments, 4, "{report:?}");
        assert_eq!(report.unseparated_edges, 0, "{report:?}");
        assert_no_t_junctions(&split, 0);
        // Every floor triangle lies under the box or outside it, and the two are different
        // sides.
        let inst = &split.instances[0];
        let mut sides = [BTreeMap::new(), BTreeMap::new()];
        for (local, t) in inst.triangles.clone().enumerate() {
            let p = split.triangles[t as usize].map(|v| split.positions[v as usize]);
            let inside = |q: Vec3| {
                q.x >= 1.0 - 1e-6 && q.x <= 3.99 + 1e-6 && q.z >= 1.0 - 1e-6 && q.z <= 3.0 + 1e-6
            };
            let under = p.iter().all(|&q| inside(q));
            let centre = p.iter().fold(Vec3::ZERO, |s, &q| s + q / 3.0);
            assert!(
                under || !inside(centre),
                "triangle {t} straddles the outline: {p:?}"
            );
            *sides[usize::from(under)]
                .entry(inst.split.sides[local])
                .or_insert(0) += 1;
        }
        assert!(!sides[1].is_empty());
        assert!(sides[0].keys().all(|s| !sides[1].contains_key(s)));
    }

    /// Whether the segment from `o` along `d` (unit) hits a triangle of `scene`.
    fn blocked(scene: &Scene, o: Vec3, d: Vec3) -> bool {
        scene.triangles.iter().any(|t| {
            let [a, b, c] = t.map(|v| scene.positions[v as usize]);
            let (e1, e2) = (b - a, c - a);
            let q = d.cross(e2);
            let det = e1.dot(q);
            if det.abs() < 1e-9 {
                return false;
            }
            let s = (o - a) / det;
            let (u, r) = (s.dot(q), d.dot(s.cross(e1)));
            u >= 0.0 && r >= 0.0 && u + r <= 1.0 && e2.dot(s.cross(e1)) > 1e-5
        })
    }

    /// Total length of the floor's (instance 0) never-stitched cut edges on the line x = `x`.
    fn cut_length_at(scene: &Scene, x: f32) -> f32 {
        let inst = &scene.instances[0];
        let mut length = 0.0;
        for t in inst.triangles.clone() {
            let tri = scene.triangles[t as usize].map(|v| scene.positions[v as usize]);
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                if scene.is_junction_edge(t, k) && (a.x - x).abs() < 1e-4 && (b.x - x).abs() < 1e-4
                {
                    length += a.distance(b);
                }
            }
        }
        length / 2.0 // each edge from both of its triangles
    }

    /// A 1 m box on the floor under a sun travelling along (1, −2, 0) casts a shadow reaching
    /// 0.5 m past its side x = 2: the floor is cut along that outline (x = 2.5, 1 m long). With
    /// a roof at 3 m whose shadow covers x = 2..3.5, the box's outline lies in shadow and is
    /// not cut; the roof's own outline (x = 3.5, across the floor) is.
    #[test]
    fn a_box_on_a_floor_under_a_sun_is_cut_along_its_shadow_outline() {
        let sun = crate::scene::Light {
            name: None,
            source: None,
            kind: LightKind::Directional,
            position: Vec3::ZERO,
            direction: Vec3::new(1.0, -2.0, 0.0).normalize(),
            intensity: Vec3::ONE,
            range: None,
        };
        let roof = (
            vec![
                Vec3::new(0.5, 3.0, 0.0),
                Vec3::new(2.0, 3.0, 0.0),
                Vec3::new(2.0, 3.0, 4.0),
                Vec3::new(0.5, 3.0, 4.0),
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        );
        let cube = cuboid(Vec3::new(1.0, 0.0, 1.0), Vec3::new(2.0, 1.0, 2.0));
        for with_roof in [false, true] {
            let mut meshes = vec![floor(), cube.clone()];
            if with_roof {
                meshes.push(roof.clone());
            }
            let mut scene = scene_of(&meshes);
            scene.lights.push(sun.clone());
            let shadows_of = scene.clone();
            let light_at = |_: usize, p: Vec3, n: Vec3| {
                let l = -sun.direction;
                let lit = n.dot(l) > 0.0 && !blocked(&shadows_of, p + n * 1e-4, l);
                if lit { n.dot(l) } else { 0.0 }
            };
            let cutter = ShadowCutter::new(&scene, &light_at);
            let (split, report) = split_with(scene, 0.1, Some(&cutter));
            assert_eq!(report.fallback_triangles, 0, "{report:?}");
            let (outline, roof_outline) = (cut_length_at(&split, 2.5), cut_length_at(&split, 3.5));
            if with_roof {
                assert!(
                    outline < 1e-3,
                    "{outline} m cut in the roof's shadow: {report:?}"
                );
                assert!(
                    (roof_outline - 4.0).abs() < 1e-3,
                    "{roof_outline}: {report:?}"
                );
            } else {
                assert!((outline - 1.0).abs() < 1e-3, "{outline}: {report:?}");
                assert_eq!(roof_outline, 0.0);
                // The sides of the cut do not meet: the shadow is a side of its own.
                let inst = &split.instances[0];
                let side_at = |x: f32| {
                    let p = Vec2::new(x, 1.5);
                    inst.triangles.clone().find_map(|t| {
                        let c = split.triangles[t as usize].map(|v| {
                            Vec2::new(split.positions[v as usize].x, split.positions[v as usize].z)
                        });
                        let inside = (0..3)
                            .all(|k| (c[(k + 1) % 3] - c[k]).perp_dot(p - c[k]) <= 0.0)
                            || (0..3).all(|k| (c[(k + 1) % 3] - c[k]).perp_dot(p - c[k]) >= 0.0);
                        inside.then(|| inst.split.sides[(t - inst.triangles.start) as usize])
                    })
                };
                assert!(side_at(2.45).is_some());
                assert_ne!(side_at(2.45), side_at(2.55));
            }
        }
    }

    /// The split in instance order, as it ran before instances were cut in parallel: each
    /// instance's shadow samples are what the instances before it left of `max_samples`.
    fn split_in_order(
        scene: Scene,
        texel: f32,
        shadows: Option<&ShadowCutter>,
        max_samples: usize,
    ) -> (Scene, JunctionReport) {
        cut_with(
            scene,
            Tolerances::of(texel, false),
            shadows,
            &[],
            |cutting| {
                let mut left = max_samples;
                let mut report = JunctionReport::default();
                let splits: Vec<Option<InstanceSplit>> = (0..cutting.scene.instances.len())
                    .map(|i| {
                        let run = run_instance(cutting, i, Budget::Left(left));
                        assert!(run.shadow.replays(&mut left));
                        report.add(&run.report);
                        run.split
                    })
                    .collect();
                (splits, report)
            },
        )
    }

    /// Cutting instances in parallel gives exactly what cutting them in order does, whatever
    /// the thread count, also when the shadow samples run out part way (the shared count then
    /// serves some instances otherwise, and the replay cuts them again in order).
    #[test]
    fn cutting_in_parallel_equals_cutting_in_order() {
        let roof = (
            vec![
                Vec3::new(0.5, 3.0, 0.0),
                Vec3::new(2.0, 3.0, 0.0),
                Vec3::new(2.0, 3.0, 4.0),
                Vec3::new(0.5, 3.0, 4.0),
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        );
        // Sizes out of order, so that largest first differs from instance order.
        let mut scene = scene_of(&[
            floor(),
            wall(2.0, 0.0, 1.5),
            cuboid(Vec3::new(0.5, 0.0, 2.5), Vec3::new(1.5, 1.0, 3.5)),
            wall(2.0, 2.5, 4.0),
            cuboid(Vec3::new(2.0, 0.0, 0.5), Vec3::new(3.0, 0.5, 1.5)),
            roof,
            cuboid(Vec3::new(2.5, 0.0, 2.5), Vec3::new(3.5, 1.5, 3.0)),
        ]);
        let direction = Vec3::new(1.0, -2.0, 0.5).normalize();
        scene.lights.push(crate::scene::Light {
            name: None,
            source: None,
            kind: LightKind::Directional,
            position: Vec3::ZERO,
            direction,
            intensity: Vec3::ONE,
            range: None,
        });
        let shadows_of = scene.clone();
        let light_at = |_: usize, p: Vec3, n: Vec3| {
            let l = -direction;
            let lit = n.dot(l) > 0.0 && !blocked(&shadows_of, p + n * 1e-4, l);
            if lit { n.dot(l) } else { 0.0 }
        };
        let cutter = ShadowCutter::new(&scene, &light_at);
        let texel = 0.1;
        let (_, all) = split_in_order(scene.clone(), texel, Some(&cutter), MAX_SAMPLES);
        assert!(all.receivers >= 4 && all.shadow_segments > 0, "{all:?}");
        let budgets = [
            MAX_SAMPLES,
            all.shadow_samples / 2,
            all.shadow_samples / 5,
            0,
        ];
        for max_samples in budgets {
            let in_order = split_in_order(scene.clone(), texel, Some(&cutter), max_samples);
            assert!(max_samples >= all.shadow_samples || in_order.1.shadow_skipped > 0);
            // Debug prints every float exactly (shortest round trip): equal text, equal bits.
            let expected = format!("{in_order:?}");
            for threads in [1, 2, 3] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .expect("thread pool");
                let parallel = pool.install(|| {
                    let tol = Tolerances::of(texel, false);
                    split_budgeted(scene.clone(), tol, Some(&cutter), &[], max_samples)
                });
                assert!(
                    format!("{parallel:?}") == expected,
                    "{threads} threads, {max_samples} samples: {:?} against {:?} in order",
                    parallel.1,
                    in_order.1
                );
            }
        }
    }
}
