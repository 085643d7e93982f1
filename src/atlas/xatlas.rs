//! xatlas unwrapping: each scene instance's planar regions go to xatlas as their convex outlines,
//! its other triangles in blocks; all are charted and packed together into pages of at most
//! `max_page_size`², each page then trimmed to the texels it uses.
//!
//! What we found in the xatlas (2019) vendored by xatlas-rs 0.1.3, and why this file looks the
//! way it does:
//! - Linking: the crate's bindings were generated on Windows and name MSVC-mangled symbols, so
//!   its `Xatlas` wrapper does not link on Linux or macOS. We declare the few entry points we use
//!   ourselves ([`ffi`]), with the mangled name of each C++ ABI; xatlas-rs still compiles and
//!   links the vendored C++.
//! - Printing: xatlas prints warnings with `printf` unless told otherwise; we pass a null print
//!   function (the library never prints).
//! - Threads: xatlas is built without its task scheduler (`XA_MULTITHREADED=0`, set for the
//!   cc build in `.cargo/config.toml`). Its 2019 scheduler loses the shutdown wake-up when a
//!   worker is between its "still running?" check and going to sleep, and `Destroy` then joins
//!   that worker forever: a benchmark bake hung so. After the planar-region pass below xatlas
//!   charts little, and one thread costs nothing measurable on the hall (0.17 s either way).
//!   Crates that depend on lightbake need the same `[env]` entry.
//! - Determinism: charting and parameterisation run one chart group after another, each with a
//!   fixed-seed random generator; packing uses a fixed-seed generator in a fresh packer, and the
//!   output is assembled in (mesh, chart group, chart) order. `unwrap_is_deterministic` checks
//!   it. Our own region pass is sequential.
//! - Order: output triangle `f` of a mesh is input triangle `f` (xatlas writes indices at
//!   `3·sourceFace`), same winding. An output vertex's `xref` may name a colocal twin of the
//!   input vertex (same position, other normal or UV), so the source vertex of each corner is
//!   taken from the input triangle instead, after checking the positions agree.
//! - Units: xatlas' epsilons are absolute (colocal vertices within 1e-4, faces of area
//!   ≤ FLT_EPSILON left out of every chart). Positions are fed in texel units (world × texels per
//!   unit, relative to the instance's bounding box) with `texelsPerUnit = 1`, so those epsilons
//!   are a ten-thousandth of a texel whatever the scene scale. Faces xatlas leaves out are then
//!   too small to reach a texel centre; they get a zero-area UV at the corner of page 0.
//! - Needles: xatlas merges vertices within 1e-4 of each other (per coordinate) only after its
//!   own zero-length test, so a triangle with a shorter, non-zero edge reaches the conformal map
//!   with two corners in one place: its angles are 0/0, the whole chart's UVs become NaN, and
//!   packing then rasterises that chart at 2³¹ texels, where `x += 1` in f32 stops moving — it
//!   never returns (a junction-split furnished interior at `--quality high` hung so). Triangles
//!   with an edge below [`NEEDLE_EDGE_TEXELS`] are therefore never given to xatlas; they are at
//!   most that wide, cover no texel centre a renderer could see, and are placed like the faces
//!   xatlas leaves out.
//! - Density: planar charts get exactly `texels_per_unit`. Curved (LSCM) charts come out denser,
//!   about 1.4× the texel area on a sphere: this xatlas scales a chart by the ratio of surface to
//!   parametric *area* where the square root would be right, and rounds chart extents up to whole
//!   texels. Charting dominates the time: a few seconds per 30k curved triangles, and quadratic
//!   in a chart's face count, hence the blocks ([`MAX_FACES_PER_XATLAS_MESH`]).
//! - Planar regions: xatlas charts a planar chart by orthogonal projection, and packing only
//!   sees the chart's outline (minimal bounding box of its convex hull, rasterised coverage).
//!   So a planar region is handed over as the fan of its convex outline, a few triangles
//!   instead of thousands, and its triangles are placed by the affine map xatlas gave the
//!   outline ([`placement`]) — the layout xatlas would give a convex region as one chart (a
//!   region with cut-outs is packed as that chart's hull), without the quadratic chart growing
//!   and without block cuts. Only regions xatlas would chart on
//!   their own qualify ([`planar_regions`]): bounded by open edges or creases of 60° or more
//!   (xatlas never grows a chart over those), within the chart limits, and covering at least
//!   [`MIN_HULL_COVER`] of their convex hull without lying over themselves: a region with
//!   cut-outs (a floor cut around what stands on it) is packed by its hull, the cut-outs left
//!   as unused page space (no texels). Regions covering less, gentle folds and curved
//!   surfaces go to xatlas as triangles. An outline
//!   xatlas does not return as one chart (slivers below its area epsilon) is charted again as
//!   triangles in a second run. On `testing::large_hall` at 3 texels per unit (116k triangles,
//!   floor and ceiling 51k each) the atlas stage went from 3.6 s to 0.16 s, with 194 charts
//!   instead of 368, 0 seam edges instead of 5995 (`lightmap::seams`), 27 950 patches instead of
//!   32 315 and 44 944 page texels instead of 63 504 (`examples/dev/atlas_speed.rs`, old and new
//!   interleaved in one session, shared machine).
//! - Padding: `PackOptions::padding` only applies with `conservative`. xatlas reserves the padded
//!   chart image but places the UVs `padding` texels up-left of it, so the gap to the next chart
//!   lies right of and below each chart: at least `padding` texels between charts, none at the
//!   page's left and top borders.
//! - Page size: xatlas places each chart at the best of random positions within the area used so
//!   far, so charts pack from the origin outwards. Packing at `max_page_size` and trimming each
//!   page to its used extent gives small pages for small scenes in one xatlas run.
//! - Dense meshes: an instance whose triangles are far below a texel is charted by smooth
//!   patches instead ([`dense`]), handed over like the planar regions (outline, then placement).

use std::collections::BTreeSet;

use glam::{DMat2, DVec2, DVec3, Vec2, Vec3};
use rayon::prelude::*;
// Only for the vendored C++ library (and libstdc++) it builds and links; see [`ffi`].
use xatlas_rs as _;

use super::{Atlas, InstanceUv, PageSize, page_side};
use crate::config::AtlasParams;
use crate::scene::{Instance, Scene, Source};
use crate::{Error, NoProgress, Progress, Result};

mod dense;

/// Refuse to unwrap beyond this many texels (the pipeline's memory check is coarser).
const MAX_TEXELS: f64 = 64.0 * 1024.0 * 1024.0;

/// Faces xatlas leaves out of every chart are accepted below this size (texels²).
const NEGLIGIBLE_TEXEL_AREA: f64 = 1e-3;

/// A triangle with an edge shorter than this (texels) is a needle xatlas must not see: ten times
/// xatlas' vertex-merging distance, far above f32 rounding of positions in texels.
const NEEDLE_EDGE_TEXELS: f64 = 1e-3;

/// Unwraps every instance with xatlas at `params.texels_per_unit` and packs the charts.
pub(crate) fn unwrap(scene: &Scene, source: &Source, params: &AtlasParams) -> Result<Atlas> {
    unwrap_with(scene, source, params, &NoProgress)
}

/// [`unwrap`], telling `progress` of the triangles charted (stage "atlas").
pub(crate) fn unwrap_with(
    scene: &Scene,
    source: &Source,
    params: &AtlasParams,
    progress: &dyn Progress,
) -> Result<Atlas> {
    unwrap_charted(scene, source, params, Charting::Xatlas, progress)
}

/// How the triangles outside planar regions are charted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Charting {
    /// Smooth patches for dense instances ([`dense`]), xatlas for the rest: the output atlas.
    Xatlas,
    /// Smooth patches for every instance of one density (`crate::atlas::build_quick`).
    Quick,
}

/// [`unwrap_with`], charting as `charting` says.
pub(crate) fn unwrap_charted(
    scene: &Scene,
    source: &Source,
    params: &AtlasParams,
    charting: Charting,
    progress: &dyn Progress,
) -> Result<Atlas> {
    let tpu = params.texels_per_unit;
    let tpus = triangle_densities(scene, params);
    let estimated_texels: f64 = (0..scene.triangles.len())
        .map(|t| scene.triangle_area(t) * f64::from(tpus[t]).powi(2))
        .sum();
    if estimated_texels > MAX_TEXELS {
        return Err(Error::Option(format!(
            "{} texels per unit would need about {:.0} M lightmap texels (at most {:.0} M): lower the texel density",
            tpu,
            estimated_texels / 1e6,
            MAX_TEXELS / 1e6
        )));
    }
    if scene.triangles.is_empty() {
        return Err(Error::invalid(
            &source.path,
            "the scene has no triangles to unwrap",
        ));
    }

    let resolution = params.max_page_size;
    // A region outline xatlas did not place as one planar chart is charted as triangles again;
    // charting is per chart group, so the second run places every remaining outline alike.
    let mut excluded = BTreeSet::new();
    progress.begin("atlas", scene.triangles.len() as u64);
    let mut shown = progress;
    let output = loop {
        let padding = params.padding;
        match run_xatlas(
            scene, &tpus, resolution, padding, &excluded, charting, shown,
        ) {
            Ok(output) => break output,
            Err(failed) => excluded.extend(failed),
        }
        shown = &NoProgress;
    };
    progress.end();
    if output.page_count == 0 {
        return Err(Error::invalid(
            &source.path,
            "xatlas produced no lightmap page",
        ));
    }

    // UVs in texels of a `resolution`² page first; pages are trimmed once all are known.
    let mut instances = Vec::with_capacity(scene.instances.len());
    for (i, inst) in scene.instances.iter().enumerate() {
        let uv = match &output.meshes[i] {
            Some(mesh) => {
                let tpus = &tpus[inst.triangles.start as usize..inst.triangles.end as usize];
                instance_uv(scene, source, inst, mesh, tpus, output.page_count)?
            }
            None => InstanceUv::default(),
        };
        instances.push(uv);
    }

    let mut extent = vec![Vec2::ZERO; output.page_count as usize];
    for inst in &instances {
        for (tri, &page) in inst.triangles.iter().zip(&inst.triangle_page) {
            for &a in tri {
                extent[page as usize] = extent[page as usize].max(inst.uv[a as usize]);
            }
        }
    }
    let padding = params.padding as f32;
    let pages: Vec<PageSize> = extent
        .iter()
        .map(|e| PageSize {
            width: page_side(e.x.ceil() + padding, resolution),
            height: page_side(e.y.ceil() + padding, resolution),
        })
        .collect();
    for inst in &mut instances {
        normalise(inst, &pages);
    }

    Ok(Atlas {
        pages,
        instances,
        texels_per_unit: tpu,
        reused_input_uvs: false,
        shared: Vec::new(),
    })
}

/// Texels per unit of each scene triangle: `texels_per_unit` times its instance's factor in
/// `instance_density` and its own in `triangle_density` (1 where there is none). xatlas is
/// given positions in texel units, so a triangle's density is the scale of its positions;
/// triangles of different densities go to xatlas in different meshes (no chart has two).
fn triangle_densities(scene: &Scene, params: &AtlasParams) -> Vec<f32> {
    let factor = |v: &[f32], i: usize| v.get(i).copied().unwrap_or(1.0);
    (0..scene.triangles.len())
        .map(|t| {
            let i = scene.triangle_instance[t] as usize;
            params.texels_per_unit
                * factor(&params.instance_density, i)
                * factor(&params.triangle_density, t)
        })
        .collect()
}

/// Whether scene triangle `t` has an edge below [`NEEDLE_EDGE_TEXELS`] at `tpu` texels per unit.
fn is_needle(scene: &Scene, t: usize, tpu: f32) -> bool {
    let [a, b, c] = scene.triangles[t].map(|v| scene.positions[v as usize].as_dvec3());
    let shortest = a.distance(b).min(b.distance(c)).min(c.distance(a));
    shortest * f64::from(tpu) < NEEDLE_EDGE_TEXELS
}

/// What xatlas returned, copied out before the atlas is destroyed.
struct XatlasOutput {
    page_count: u32,
    /// Per scene instance; `None` for instances without triangles (not given to xatlas).
    meshes: Vec<Option<MeshOutput>>,
}

struct MeshOutput {
    vertices: Vec<ffi::Vertex>,
    indices: Vec<u32>,
}

/// Triangles per xatlas mesh. xatlas 2019 grows a chart with a priority update over all its
/// candidate faces at every step — quadratic in the chart's face count: the 51k-triangle floor
/// of `testing::large_hall` ran for over ten minutes in `AtlasBuilder::updatePriorities`.
/// Triangles outside planar regions are cut into spatially coherent blocks of at most this many
/// (triangles in Morton order of their centroids); charts then end at block borders (a few more
/// seams) and unwrapping stays roughly linear in the triangle count.
const MAX_FACES_PER_XATLAS_MESH: usize = 1024;

/// Planar regions of fewer triangles are left to xatlas: they cost it little, and every proxy
/// is a chart group of its own, which xatlas looks up by a linear scan over all groups.
const MIN_REGION_TRIANGLES: usize = 16;

/// A triangle joins a region when its corners lie this close to the region's plane (texels).
const PLANE_TOLERANCE: f64 = 1e-3;

/// xatlas never grows a chart onto a face turned 60° or more from the chart's mean normal, so a
/// region whose neighbours all turn that far is a chart of its own in xatlas too.
const CREASE_DOT: f64 = 0.5;

/// A planar region is one chart, packed by its convex hull, when its triangles cover at least
/// this share of the hull. Before, only an exact cover (convex, no holes) was: the furnished
/// interior's floor, walls and ceiling (cut around what stands on them, 0.96–0.99 covered)
/// went to xatlas as 35,000 triangles, charted in blocks with seams at the blocks' borders.
const MIN_HULL_COVER: f64 = 0.75;

/// Hull corners closer than this to the line through their neighbours are dropped (texels), so
/// no proxy triangle is degenerate.
const HULL_TOLERANCE: f64 = 1e-6;

/// How far xatlas' placement of a proxy corner may stray from one affine map (texels).
const PLACEMENT_TOLERANCE: f64 = 1e-2;

/// Proxies per xatlas mesh: `createFaceGroups` rescans the mesh's faces for every new group.
const PROXIES_PER_MESH: usize = 64;

/// Proxies of one xatlas mesh are stacked this far apart in z so they never share an edge.
const PROXY_Z_STEP: f32 = 16.0;

/// A part of an instance given to xatlas as one mesh.
struct Block {
    /// Instance-local triangle indices, in block order.
    triangles: Vec<u32>,
    /// Instance-local vertex of each block vertex.
    vertices: Vec<u32>,
}

/// Cuts instance-local `triangles` into blocks of at most [`MAX_FACES_PER_XATLAS_MESH`].
fn blocks(scene: &Scene, inst: &Instance, mut triangles: Vec<u32>) -> Vec<Block> {
    let tris = &scene.triangles[inst.triangles.start as usize..inst.triangles.end as usize];
    if triangles.len() > MAX_FACES_PER_XATLAS_MESH {
        let centroid =
            |t: &[u32; 3]| t.iter().map(|&v| scene.positions[v as usize]).sum::<Vec3>() / 3.0;
        let (lo, hi) =
            triangles
                .iter()
                .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), &t| {
                    let c = centroid(&tris[t as usize]);
                    (lo.min(c), hi.max(c))
                });
        let scale = 1023.0 / (hi - lo).max(Vec3::splat(1e-12));
        let key = |t: &[u32; 3]| {
            morton(
                ((centroid(t) - lo) * scale)
                    .as_uvec3()
                    .min(glam::UVec3::splat(1023)),
            )
        };
        triangles.sort_by_key(|&t| (key(&tris[t as usize]), t));
    }
    triangles
        .chunks(MAX_FACES_PER_XATLAS_MESH)
        .map(|chunk| {
            let mut vertices: Vec<u32> = chunk
                .iter()
                .flat_map(|&t| tris[t as usize])
                .map(|v| v - inst.vertices.start)
                .collect();
            vertices.sort_unstable();
            vertices.dedup();
            Block {
                triangles: chunk.to_vec(),
                vertices,
            }
        })
        .collect()
}

/// [`blocks`] per group of a side of a junction split (`Split::sides`) and a density (`tpus`,
/// instance-local): groups go to xatlas as separate meshes, so no chart crosses a junction or
/// has two densities.
fn blocks_by_group(
    scene: &Scene,
    inst: &Instance,
    tpus: &[f32],
    triangles: Vec<u32>,
) -> Vec<Block> {
    let mut by_group: std::collections::BTreeMap<(u32, u32), Vec<u32>> = Default::default();
    for t in triangles {
        by_group.entry(group(inst, tpus, t)).or_default().push(t);
    }
    by_group
        .into_values()
        .flat_map(|group| blocks(scene, inst, group))
        .collect()
}

/// The chart group of instance-local triangle `t`: its side of a junction split and its
/// density's bits. Charts never join triangles of two groups.
fn group(inst: &Instance, tpus: &[f32], t: u32) -> (u32, u32) {
    let side = inst.split.sides.get(t as usize).copied().unwrap_or(0);
    (side, tpus[t as usize].to_bits())
}

/// Interleaves the low 10 bits of x, y, z.
fn morton(p: glam::UVec3) -> u32 {
    let spread = |mut v: u32| {
        v &= 0x3ff;
        v = (v | (v << 16)) & 0x030000ff;
        v = (v | (v << 8)) & 0x0300f00f;
        v = (v | (v << 4)) & 0x030c30c3;
        (v | (v << 2)) & 0x09249249
    };
    spread(p.x) | (spread(p.y) << 1) | (spread(p.z) << 2)
}

/// A planar region of an instance, bounded by open edges and creases. xatlas charts and
/// parameterises it as the fan of its convex outline, a few triangles however many the region
/// has; the region's triangles are then placed by the same affine map as the outline.
struct Region {
    instance: u32,
    /// Instance-local triangles, ascending; the first is the region's seed.
    triangles: Vec<u32>,
    /// Instance-local vertices of those triangles, ascending.
    vertices: Vec<u32>,
    /// Plane coordinates of each of `vertices` in texels, relative to the outline's low corner.
    plane: Vec<DVec2>,
    /// The convex outline, counter-clockwise, in the same coordinates.
    outline: Vec<DVec2>,
}

/// Chart limits a region must respect to stay one chart in xatlas.
#[derive(Clone, Copy)]
struct Limits {
    max_chart_area: f64,
    max_chart_size: f64,
}

/// Splits instance `index` into planar regions xatlas need not chart and the remaining
/// instance-local triangles (ascending). Regions named in `excluded` (instance, seed) are left
/// to xatlas.
fn planar_regions(
    scene: &Scene,
    index: u32,
    tpus: &[f32],
    limits: Limits,
    excluded: &BTreeSet<(u32, u32)>,
) -> (Vec<Region>, Vec<u32>) {
    let mesh = RegionMesh::new(scene, index, tpus);
    let mut region_of = vec![u32::MAX; mesh.tris.len()];
    let (mut regions, mut rest) = (Vec::new(), Vec::new());
    // Buffers reused from region to region.
    let mut stack = Vec::new();
    let mut members = Vec::new();
    let mut directed = Vec::new();
    for seed in 0..mesh.tris.len() as u32 {
        if region_of[seed as usize] != u32::MAX {
            continue;
        }
        mesh.grow(seed, &mut region_of, &mut members, &mut stack);
        let region = if members.len() < MIN_REGION_TRIANGLES || excluded.contains(&(index, seed)) {
            None
        } else {
            mesh.planar_region(seed, &members, &region_of, limits, &mut directed)
        };
        match region {
            Some(region) => regions.push(region),
            None => rest.extend_from_slice(&members),
        }
    }
    rest.sort_unstable();
    (regions, rest)
}

/// An instance's triangles welded by position, with their edges and normals: what
/// [`planar_regions`] grows regions over.
struct RegionMesh<'a> {
    scene: &'a Scene,
    index: u32,
    inst: &'a Instance,
    /// Texels per unit of each instance-local triangle.
    tpus: &'a [f32],
    tris: &'a [[u32; 3]],
    /// The welded vertex of each instance-local vertex (one per position).
    weld: Vec<u32>,
    /// Every edge as (welded end points, ascending; triangle), sorted: the faces on an edge
    /// are neighbours in the list.
    edges: Vec<([u32; 2], u32)>,
    /// Each triangle's unit normal (zero when degenerate).
    normal: Vec<DVec3>,
    /// Triangles xatlas leaves out of every chart; they neither join nor bound regions.
    ignored: Vec<bool>,
}

impl<'a> RegionMesh<'a> {
    fn new(scene: &'a Scene, index: u32, tpus: &'a [f32]) -> Self {
        let inst = &scene.instances[index as usize];
        let tris = &scene.triangles[inst.triangles.start as usize..inst.triangles.end as usize];
        let mut mesh = RegionMesh {
            scene,
            index,
            inst,
            tpus,
            tris,
            weld: Vec::new(),
            edges: Vec::with_capacity(3 * tris.len()),
            normal: Vec::with_capacity(tris.len()),
            ignored: Vec::with_capacity(tris.len()),
        };
        // Faces meet where their corners have the same position (+0.0 folds −0.0 into 0.0).
        let first_vertex = inst.vertices.start;
        let key = |v: u32| (scene.positions[(first_vertex + v) as usize] + Vec3::ZERO).to_array();
        let mut order: Vec<u32> = (0..inst.vertices.end - first_vertex).collect();
        order.sort_unstable_by_key(|&v| (key(v).map(f32::to_bits), v));
        mesh.weld = vec![0u32; order.len()];
        for (id, same) in order.chunk_by(|&a, &b| key(a) == key(b)).enumerate() {
            for &v in same {
                mesh.weld[v as usize] = id as u32;
            }
        }
        for t in 0..tris.len() as u32 {
            let w = mesh.welded(t);
            for k in 0..3 {
                let (a, b) = (w[k], w[(k + 1) % 3]);
                if a != b {
                    mesh.edges.push(([a.min(b), a.max(b)], t));
                }
            }
        }
        mesh.edges.sort_unstable();
        for t in 0..tris.len() as u32 {
            let [a, b, c] = mesh.local(t).map(|v| mesh.at(v, tpus[t as usize]));
            let n = (b - a).cross(c - a);
            mesh.normal.push(n.normalize_or_zero());
            // xatlas leaves faces this small out of every chart.
            mesh.ignored
                .push(0.5 * n.length() <= f64::from(f32::EPSILON));
        }
        mesh
    }

    /// Triangle `t` in instance-local vertices.
    fn local(&self, t: u32) -> [u32; 3] {
        self.tris[t as usize].map(|v| v - self.inst.vertices.start)
    }

    /// Instance-local vertex `v` in texels of a triangle's density (regions never mix
    /// densities).
    fn at(&self, v: u32, tpu: f32) -> DVec3 {
        self.scene.positions[(self.inst.vertices.start + v) as usize].as_dvec3() * f64::from(tpu)
    }

    fn welded(&self, t: u32) -> [u32; 3] {
        self.local(t).map(|v| self.weld[v as usize])
    }

    /// The triangles on the edge between welded vertices `a` and `b`.
    fn faces_on(&self, a: u32, b: u32) -> &[([u32; 2], u32)] {
        let e = [a.min(b), a.max(b)];
        let lo = self.edges.partition_point(|x| x.0 < e);
        let len = self.edges[lo..].partition_point(|x| x.0 == e);
        &self.edges[lo..lo + len]
    }

    /// Sides of a junction split and triangles of other densities never join one region.
    fn side(&self, t: u32) -> (u32, u32) {
        group(self.inst, self.tpus, t)
    }

    /// Grows the region of `seed` into `members` (ascending), marking them in `region_of`:
    /// over edges to faces facing the same way with all corners in the seed's plane (measured
    /// against the seed, so a gentle curve never creeps in).
    fn grow(&self, seed: u32, region_of: &mut [u32], members: &mut Vec<u32>, stack: &mut Vec<u32>) {
        region_of[seed as usize] = seed;
        members.clear();
        members.push(seed);
        let n = self.normal[seed as usize];
        let tpu = self.tpus[seed as usize];
        let d = n.dot(self.at(self.local(seed)[0], tpu));
        if !self.ignored[seed as usize] {
            stack.push(seed);
        }
        while let Some(t) = stack.pop() {
            let w = self.welded(t);
            for k in 0..3 {
                for &(_, u) in self.faces_on(w[k], w[(k + 1) % 3]) {
                    let joins = region_of[u as usize] == u32::MAX
                        && self.side(u) == self.side(seed)
                        && !self.ignored[u as usize]
                        && self.normal[u as usize].dot(n) > 0.0
                        && self
                            .local(u)
                            .iter()
                            .all(|&v| (n.dot(self.at(v, tpu)) - d).abs() <= PLANE_TOLERANCE);
                    if joins {
                        region_of[u as usize] = seed;
                        members.push(u);
                        stack.push(u);
                    }
                }
            }
        }
        members.sort_unstable();
    }

    /// The grown region of `seed` (`members`) as a [`Region`], when xatlas would chart it on its
    /// own as one planar chart: bounded by open edges and creases, manifold, covering at least
    /// [`MIN_HULL_COVER`] of its convex hull without lying over itself, and within the chart
    /// `limits`. `directed` is a reused buffer.
    fn planar_region(
        &self,
        seed: u32,
        members: &[u32],
        region_of: &[u32],
        limits: Limits,
        directed: &mut Vec<[u32; 2]>,
    ) -> Option<Region> {
        let n = self.normal[seed as usize];
        let tpu = self.tpus[seed as usize];
        // Bounded by open edges and creases, so xatlas would not chart it with others.
        directed.clear();
        for &t in members {
            let w = self.welded(t);
            for k in 0..3 {
                directed.push([w[k], w[(k + 1) % 3]]);
                let crossed = self.faces_on(w[k], w[(k + 1) % 3]).iter().any(|&(_, u)| {
                    region_of[u as usize] != seed
                        && self.side(u) == self.side(seed)
                        && !self.ignored[u as usize]
                        && self.normal[u as usize].dot(n) >= CREASE_DOT
                });
                if crossed {
                    return None;
                }
            }
        }
        // Manifold: no edge traversed twice the same way (no folds or duplicate faces).
        directed.sort_unstable();
        if directed.windows(2).any(|e| e[0] == e[1]) {
            return None;
        }
        // Plane coordinates, (u, v, n) right-handed: every member has positive area.
        let u_axis = n.any_orthonormal_vector();
        let v_axis = n.cross(u_axis);
        let mut vertices: Vec<u32> = members.iter().flat_map(|&t| self.local(t)).collect();
        vertices.sort_unstable();
        vertices.dedup();
        let mut plane: Vec<DVec2> = vertices
            .iter()
            .map(|&v| {
                let p = self.at(v, tpu);
                DVec2::new(p.dot(u_axis), p.dot(v_axis))
            })
            .collect();
        let mut area = 0.0;
        for &t in members {
            let [a, b, c] = self
                .local(t)
                .map(|v| plane[vertices.binary_search(&v).unwrap_or(0)]);
            let twice = (b - a).perp_dot(c - a);
            if twice <= 0.0 {
                return None;
            }
            area += 0.5 * twice;
        }
        // Packed by its convex hull: the triangles cover most of it (cut-outs such as a
        // floor's around what stands on it leave page space unused, no texels) and none
        // overlaps another (checked below where the hull is not covered exactly).
        let mut outline = convex_hull(&plane);
        let hull_area = polygon_area(&outline);
        let exact = (area - hull_area).abs() <= 1e-6 * hull_area;
        if outline.len() < 3 || !(exact || (MIN_HULL_COVER * hull_area..hull_area).contains(&area))
        {
            return None;
        }
        let lo = outline.iter().fold(DVec2::INFINITY, |m, p| m.min(*p));
        let hi = outline.iter().fold(DVec2::NEG_INFINITY, |m, p| m.max(*p));
        if hull_area > limits.max_chart_area || (hi - lo).length() > limits.max_chart_size {
            return None;
        }
        plane.iter_mut().for_each(|p| *p -= lo);
        outline.iter_mut().for_each(|p| *p -= lo);
        let corner = |t: u32| {
            self.local(t)
                .map(|v| plane[vertices.binary_search(&v).unwrap_or(0)])
        };
        if !exact && dense::folds(members.iter().map(|&t| corner(t)), hi - lo) {
            return None;
        }
        Some(Region {
            instance: self.index,
            triangles: members.to_vec(),
            vertices,
            plane,
            outline,
        })
    }
}

/// Convex hull, counter-clockwise, without corners on straight runs (Andrew's monotone chain).
fn convex_hull(points: &[DVec2]) -> Vec<DVec2> {
    let mut sorted = points.to_vec();
    sorted.sort_unstable_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    sorted.dedup();
    if sorted.len() < 3 {
        return sorted;
    }
    // a → b → c turns counter-clockwise, b more than HULL_TOLERANCE off the line a c.
    let turns_left =
        |a: DVec2, b: DVec2, c: DVec2| (c - a).perp_dot(b - a) < -HULL_TOLERANCE * (c - a).length();
    // Lower chain left to right, then upper chain back from the second-to-last point; a chain
    // never pops into the one before it.
    let mut hull: Vec<DVec2> = Vec::with_capacity(sorted.len() + 1);
    for &p in &sorted {
        while hull.len() >= 2 && !turns_left(hull[hull.len() - 2], hull[hull.len() - 1], p) {
            hull.pop();
        }
        hull.push(p);
    }
    let lower = hull.len();
    for &p in sorted[..sorted.len() - 1].iter().rev() {
        while hull.len() > lower && !turns_left(hull[hull.len() - 2], hull[hull.len() - 1], p) {
            hull.pop();
        }
        hull.push(p);
    }
    hull.pop();
    hull
}

/// Area of a counter-clockwise polygon.
fn polygon_area(polygon: &[DVec2]) -> f64 {
    let n = polygon.len();
    0.5 * (0..n)
        .map(|i| polygon[i].perp_dot(polygon[(i + 1) % n]))
        .sum::<f64>()
}

/// The affine map (page, linear part, offset) by which xatlas placed `region`'s outline, given
/// as fan triangles from `first_face` of `mesh`; `None` unless one map places every corner.
fn placement(
    region: &Region,
    mesh: &ffi::MeshView<'_>,
    first_face: usize,
) -> Option<(i32, DMat2, DVec2)> {
    let fan = region.outline.len() - 2;
    // Plane coordinates as xatlas saw them (f32), the page texel and page of each fan corner.
    let corner = |f: usize, c: usize| -> Option<(DVec2, DVec2, i32)> {
        let o = *mesh.indices.get(3 * (first_face + f) + c)?;
        let v = mesh.vertices.get(o as usize)?;
        let p = region.outline[[0, f + 1, f + 2][c]].as_vec2().as_dvec2();
        Some((p, Vec2::from(v.uv).as_dvec2(), v.atlas_index))
    };
    // Fitted on the largest fan triangle, checked on all.
    let twice_area = |f: usize| {
        let o = &region.outline;
        (o[f + 1] - o[0]).perp_dot(o[f + 2] - o[0])
    };
    let widest = (0..fan).max_by(|&a, &b| twice_area(a).total_cmp(&twice_area(b)))?;
    let [(p0, q0, page), (p1, q1, _), (p2, q2, _)] =
        [0, 1, 2].map(|c| corner(widest, c).unwrap_or_default());
    if page < 0 {
        return None;
    }
    let linear = DMat2::from_cols(q1 - q0, q2 - q0) * DMat2::from_cols(p1 - p0, p2 - p0).inverse();
    let offset = q0 - linear * p0;
    for f in 0..fan {
        for c in 0..3 {
            let (p, q, at) = corner(f, c)?;
            if at != page || (linear * p + offset).distance(q) > PLACEMENT_TOLERANCE {
                return None;
            }
        }
    }
    linear.is_finite().then_some((page, linear, offset))
}

/// Charts and packs the scene in one xatlas atlas, triangle `t` at `tpus[t]` texels per unit.
/// `Err` lists the regions (instance, seed)
/// whose outline xatlas did not place as one planar chart; run again with them excluded.
fn run_xatlas(
    scene: &Scene,
    tpus: &[f32],
    resolution: u32,
    padding: u32,
    excluded: &BTreeSet<(u32, u32)>,
    charting: Charting,
    progress: &dyn Progress,
) -> std::result::Result<XatlasOutput, Vec<(u32, u32)>> {
    // Big charts are split while growing (`max_chart_area`) and, as a last resort, scaled down
    // to fit an empty page (`max_chart_size`), so no chart is ever left unplaced.
    let side = resolution as f32;
    let chart_options = ffi::ChartOptions {
        max_chart_area: 0.25 * side * side,
        ..ffi::ChartOptions::default()
    };
    let pack_options = ffi::PackOptions {
        attempts: 4096,
        texels_per_unit: 1.0,
        resolution,
        max_chart_size: resolution.saturating_sub(padding + 2).max(1),
        block_align: false,
        conservative: true,
        padding,
    };
    let limits = Limits {
        max_chart_area: f64::from(chart_options.max_chart_area),
        max_chart_size: f64::from(pack_options.max_chart_size),
    };
    let found = find_regions(scene, tpus, limits, excluded, charting, progress);
    if charting == Charting::Quick
        && let Some(output) = pack_quick(scene, &found, resolution, padding)
    {
        return Ok(output);
    }

    let atlas = ffi::Handle::create();
    let (given, regions) = add_blocks(&atlas, scene, tpus, found);
    add_region_outlines(&atlas, &regions);
    atlas.generate(chart_options, pack_options);

    // Reassemble each instance's blocks and regions into one mesh in the instance's triangle
    // order, with `xref` local to the instance. xatlas returns the meshes as given: every
    // block, then the region outlines.
    let raw = atlas.output();
    let (block_meshes, outline_meshes) = raw.meshes.split_at(given.iter().map(Vec::len).sum());
    let mut meshes = block_outputs(scene, &given, block_meshes);
    let placements = regions
        .chunks(PROXIES_PER_MESH)
        .zip(outline_meshes)
        .flat_map(|(chunk, mesh)| {
            let mut first_face = 0;
            chunk.iter().map(move |region| {
                let placed = placement(region, mesh, first_face);
                first_face += region.outline.len() - 2;
                placed
            })
        });
    let failed = place_regions(scene, &regions, placements, &mut meshes);
    if !failed.is_empty() {
        return Err(failed);
    }
    Ok(XatlasOutput {
        page_count: raw.page_count,
        meshes,
    })
}

/// Each instance's regions and remaining triangles, found in parallel and collected in instance
/// order: smooth patches of dense instances ([`dense`]), planar regions of the others.
fn find_regions(
    scene: &Scene,
    tpus: &[f32],
    limits: Limits,
    excluded: &BTreeSet<(u32, u32)>,
    charting: Charting,
    progress: &dyn Progress,
) -> Vec<(Vec<Region>, Vec<u32>)> {
    (0..scene.instances.len())
        .into_par_iter()
        .map(|index| {
            let count = scene.instances[index].triangles.len();
            if count == 0 {
                return Default::default();
            }
            let inst = &scene.instances[index];
            let tpus = &tpus[inst.triangles.start as usize..inst.triangles.end as usize];
            let i = index as u32;
            // The dense path charts one density; an instance the plan gave several (regions
            // of other densities) goes the planar-region way.
            let one_density = tpus.iter().all(|&t| t == tpus[0]);
            let found = match charting {
                Charting::Xatlas => one_density
                    .then(|| dense::smooth_regions(scene, i, tpus[0], limits, excluded, false))
                    .flatten()
                    .unwrap_or_else(|| planar_regions(scene, i, tpus, limits, excluded)),
                // Planar regions where they cover the instance (walls, boxes: the same charts
                // as the output's), smooth patches where anything is left for xatlas.
                Charting::Quick => {
                    let planar = planar_regions(scene, i, tpus, limits, excluded);
                    match planar.1.is_empty() || !one_density {
                        true => planar,
                        false => dense::smooth_regions(scene, i, tpus[0], limits, excluded, true)
                            .unwrap_or(planar),
                    }
                }
            };
            progress.advance(count as u64);
            found
        })
        .collect()
}

/// Gives `atlas` every instance's triangles outside its regions, in blocks (one xatlas mesh
/// each); returns each instance's blocks and all the regions, in instance order.
fn add_blocks(
    atlas: &ffi::Handle,
    scene: &Scene,
    tpus: &[f32],
    found: Vec<(Vec<Region>, Vec<u32>)>,
) -> (Vec<Vec<Block>>, Vec<Region>) {
    let mut given: Vec<Vec<Block>> = Vec::with_capacity(scene.instances.len());
    let mut regions = Vec::new();
    for (inst, (inst_regions, rest)) in scene.instances.iter().zip(found) {
        if inst.triangles.is_empty() {
            given.push(Vec::new());
            continue;
        }
        let tpus = &tpus[inst.triangles.start as usize..inst.triangles.end as usize];
        regions.extend(inst_regions);
        let inst_blocks = blocks_by_group(scene, inst, tpus, rest);
        for block in &inst_blocks {
            let tpu = tpus[block.triangles[0] as usize];
            let (positions, normals, indices) = mesh_input(scene, inst, block, tpu);
            let needles: Vec<bool> = block
                .triangles
                .iter()
                .map(|&t| is_needle(scene, (inst.triangles.start + t) as usize, tpu))
                .collect();
            add_mesh(atlas, &positions, &normals, &indices, Some(&needles));
        }
        given.push(inst_blocks);
    }
    (given, regions)
}

/// Gives `atlas` the regions' outlines, after all blocks and several to an xatlas mesh: plane
/// coordinates at a z of their own, facing +z.
fn add_region_outlines(atlas: &ffi::Handle, regions: &[Region]) {
    for chunk in regions.chunks(PROXIES_PER_MESH) {
        let (mut positions, mut indices) = (Vec::new(), Vec::new());
        for (k, region) in chunk.iter().enumerate() {
            let base = positions.len() as u32;
            let z = k as f32 * PROXY_Z_STEP;
            positions.extend(region.outline.iter().map(|p| [p.x as f32, p.y as f32, z]));
            for i in 1..region.outline.len() as u32 - 1 {
                indices.extend([base, base + i, base + i + 1]);
            }
        }
        add_mesh(
            atlas,
            &positions,
            &vec![[0.0, 0.0, 1.0]; positions.len()],
            &indices,
            None,
        );
    }
}

/// Each instance's output mesh with its blocks' triangles filled in from xatlas' `meshes` (one
/// per block, in order); `None` for instances without triangles.
fn block_outputs(
    scene: &Scene,
    given: &[Vec<Block>],
    meshes: &[ffi::MeshView<'_>],
) -> Vec<Option<MeshOutput>> {
    let mut outputs: Vec<Option<MeshOutput>> = scene
        .instances
        .iter()
        .map(|inst| {
            (!inst.triangles.is_empty()).then(|| MeshOutput {
                vertices: Vec::new(),
                indices: vec![u32::MAX; 3 * inst.triangles.len()],
            })
        })
        .collect();
    let mut next = 0;
    for (inst_blocks, out) in given.iter().zip(&mut outputs) {
        let Some(out) = out else { continue };
        for block in inst_blocks {
            let mesh = &meshes[next];
            next += 1;
            let base = out.vertices.len() as u32;
            out.vertices.extend(mesh.vertices.iter().map(|v| {
                ffi::Vertex {
                    xref: block
                        .vertices
                        .get(v.xref as usize)
                        .copied()
                        .unwrap_or(u32::MAX),
                    ..*v
                }
            }));
            for (k, &t) in block.triangles.iter().enumerate() {
                for c in 0..3 {
                    out.indices[3 * t as usize + c] =
                        mesh.indices.get(3 * k + c).map_or(u32::MAX, |i| i + base);
                }
            }
        }
    }
    outputs
}

/// The density pilot's atlas when it is all region outlines (no block left for xatlas):
/// their own shelf packing ([`super::pack`]), without xatlas' per-chart memory. `None` when
/// xatlas has to chart something, or an outline does not fit a page.
fn pack_quick(
    scene: &Scene,
    found: &[(Vec<Region>, Vec<u32>)],
    resolution: u32,
    padding: u32,
) -> Option<XatlasOutput> {
    if found.iter().any(|(_, rest)| !rest.is_empty()) {
        return None;
    }
    let regions: Vec<&Region> = found.iter().flat_map(|(r, _)| r).collect();
    let outlines: Vec<&[DVec2]> = regions.iter().map(|r| r.outline.as_slice()).collect();
    let placed = super::pack::pack_outlines(&outlines, resolution, padding)?;
    let page_count = placed.iter().map(|p| p.0 + 1).max().unwrap_or(0) as u32;
    let no_blocks: Vec<Vec<Block>> = scene.instances.iter().map(|_| Vec::new()).collect();
    let mut meshes = block_outputs(scene, &no_blocks, &[]);
    let failed = place_regions(scene, regions, placed.into_iter().map(Some), &mut meshes);
    debug_assert!(failed.is_empty());
    Some(XatlasOutput { page_count, meshes })
}

/// Places each region's triangles by its outline's map (`placements`, one per region in
/// order: page, linear part, offset; `None` where xatlas did not place the outline as one
/// planar chart), adding them to their instance's output mesh; returns the regions
/// (instance, seed) left unplaced.
fn place_regions<'r>(
    scene: &Scene,
    regions: impl IntoIterator<Item = &'r Region>,
    placements: impl Iterator<Item = Option<(i32, DMat2, DVec2)>>,
    outputs: &mut [Option<MeshOutput>],
) -> Vec<(u32, u32)> {
    let mut failed = Vec::new();
    for (region, placed) in regions.into_iter().zip(placements) {
        let Some((page, linear, offset)) = placed else {
            failed.push((region.instance, region.triangles[0]));
            continue;
        };
        let inst = &scene.instances[region.instance as usize];
        let Some(out) = &mut outputs[region.instance as usize] else {
            continue;
        };
        let base = out.vertices.len() as u32;
        out.vertices
            .extend(region.vertices.iter().zip(&region.plane).map(|(&v, &p)| {
                let uv = (linear * p + offset).max(DVec2::ZERO).as_vec2();
                ffi::Vertex {
                    atlas_index: page,
                    uv: uv.to_array(),
                    xref: v,
                }
            }));
        for &t in &region.triangles {
            let tri = scene.triangles[(inst.triangles.start + t) as usize];
            for (c, &v) in tri.iter().enumerate() {
                let at = region.vertices.binary_search(&(v - inst.vertices.start));
                out.indices[3 * t as usize + c] = at.map_or(u32::MAX, |i| base + i as u32);
            }
        }
    }
    failed
}

/// Adds one mesh (positions in texels, unit normals, triangles, triangles to leave out) to
/// `atlas`.
fn add_mesh(
    atlas: &ffi::Handle,
    positions: &[[f32; 3]],
    normals: &[[f32; 3]],
    indices: &[u32],
    ignore: Option<&[bool]>,
) {
    debug_assert!(ignore.is_none_or(|i| 3 * i.len() == indices.len()));
    let decl = ffi::MeshDecl {
        vertex_count: positions.len() as u32,
        vertex_position_data: positions.as_ptr().cast(),
        vertex_position_stride: 12,
        vertex_normal_data: normals.as_ptr().cast(),
        vertex_normal_stride: 12,
        vertex_uv_data: std::ptr::null(),
        vertex_uv_stride: 0,
        index_count: indices.len() as u32,
        index_data: indices.as_ptr().cast(),
        index_offset: 0,
        index_format: ffi::INDEX_FORMAT_U32,
        face_ignore_data: ignore.map_or(std::ptr::null(), <[bool]>::as_ptr),
    };
    // The indices are local and in range, and a multiple of three: AddMesh cannot fail.
    let status = atlas.add_mesh(&decl);
    debug_assert_eq!(status, 0, "xatlas AddMesh failed");
}

/// Positions in texel units relative to the instance's bounding box, normals, and indices into
/// the block's vertices.
fn mesh_input(
    scene: &Scene,
    inst: &Instance,
    block: &Block,
    tpu: f32,
) -> (Vec<[f32; 3]>, Vec<[f32; 3]>, Vec<u32>) {
    let range = inst.vertices.start as usize..inst.vertices.end as usize;
    let origin = scene.positions[range]
        .iter()
        .fold(Vec3::INFINITY, |m, p| m.min(*p));
    let global = |local: u32| (inst.vertices.start + local) as usize;
    let positions = block
        .vertices
        .iter()
        .map(|&v| ((scene.positions[global(v)] - origin) * tpu).to_array())
        .collect();
    let normals = block
        .vertices
        .iter()
        .map(|&v| scene.normals[global(v)].to_array())
        .collect();
    let indices = block
        .triangles
        .iter()
        .flat_map(|&t| scene.triangles[(inst.triangles.start + t) as usize])
        .map(|v| {
            block
                .vertices
                .binary_search(&(v - inst.vertices.start))
                .expect("vertex in block") as u32
        })
        .collect();
    (positions, normals, indices)
}

/// Maps one xatlas output mesh back onto the instance's triangles (UVs still in texels).
fn instance_uv(
    scene: &Scene,
    source: &Source,
    inst: &Instance,
    mesh: &MeshOutput,
    tpus: &[f32],
    page_count: u32,
) -> Result<InstanceUv> {
    let fail = |what: String| {
        Error::invalid(
            &source.path,
            format!(
                "mesh {} primitive {} (node {}): xatlas {what}",
                inst.mesh, inst.primitive, inst.node
            ),
        )
    };
    let triangles = &scene.triangles[inst.triangles.start as usize..inst.triangles.end as usize];
    if mesh.indices.len() != 3 * triangles.len() {
        return Err(fail(format!(
            "returned {} indices for {} triangles",
            mesh.indices.len(),
            triangles.len()
        )));
    }
    let scaled =
        |global: u32, tpu: f32| scene.positions[global as usize].as_dvec3() * f64::from(tpu);

    let mut uv = InstanceUv::default();
    // Atlas vertex of each (xatlas vertex, local source vertex) pair, in first-seen order.
    let mut atlas_vertex = std::collections::BTreeMap::new();
    for (local_t, (tri, out)) in triangles
        .iter()
        .zip(mesh.indices.chunks_exact(3))
        .enumerate()
    {
        let out_vertices = [out[0], out[1], out[2]].map(|o| mesh.vertices.get(o as usize));
        let [Some(a), Some(b), Some(c)] = out_vertices else {
            return Err(fail(format!(
                "returned an out-of-range index for triangle {local_t}"
            )));
        };
        let page = a.atlas_index;
        if b.atlas_index != page || c.atlas_index != page || page >= page_count as i32 {
            return Err(fail(format!("split triangle {local_t} across pages")));
        }
        let charted = page >= 0;
        let global_t = inst.triangles.start as usize + local_t;
        let tpu = tpus[local_t];
        if !charted
            && scene.triangle_area(global_t) * f64::from(tpu).powi(2) > NEGLIGIBLE_TEXEL_AREA
            && !is_needle(scene, global_t, tpu)
        {
            return Err(fail(format!("left triangle {local_t} out of every chart")));
        }
        let mut corners = [0u32; 3];
        for (corner, (&global, (&o, v))) in tri.iter().zip(out.iter().zip([a, b, c])).enumerate() {
            let xref_global = inst.vertices.start + v.xref;
            if v.xref >= inst.vertices.end - inst.vertices.start
                || DVec3::distance(scaled(xref_global, tpu), scaled(global, tpu)) > 1e-3
            {
                return Err(fail(format!("reordered the corners of triangle {local_t}")));
            }
            let local = global - inst.vertices.start;
            corners[corner] = *atlas_vertex.entry((o, local)).or_insert_with(|| {
                uv.xref.push(local);
                uv.uv.push(if charted {
                    Vec2::from(v.uv)
                } else {
                    Vec2::ZERO
                });
                uv.xref.len() as u32 - 1
            });
        }
        uv.triangles.push(corners);
        uv.triangle_page.push(page.max(0) as u32);
    }
    Ok(uv)
}

/// Texel UVs → [0,1] of each vertex's page (a vertex only ever belongs to one page).
fn normalise(inst: &mut InstanceUv, pages: &[PageSize]) {
    let mut page_of = vec![0u32; inst.uv.len()];
    for (tri, &page) in inst.triangles.iter().zip(&inst.triangle_page) {
        for &a in tri {
            page_of[a as usize] = page;
        }
    }
    for (uv, page) in inst.uv.iter_mut().zip(page_of) {
        let size = pages[page as usize];
        *uv = (*uv / Vec2::new(size.width as f32, size.height as f32)).clamp(Vec2::ZERO, Vec2::ONE);
    }
}

/// The xatlas C++ entry points we use, declared here because xatlas-rs 0.1.3's bindings only
/// carry MSVC symbol names (see the module comment). Layouts follow the vendored `xatlas.h`.
mod ffi {
    use std::ffi::{c_char, c_int, c_void};

    #[repr(C)]
    #[allow(dead_code, reason = "C layout: not every field is read")]
    pub(crate) struct Atlas {
        pub(crate) width: u32,
        pub(crate) height: u32,
        pub(crate) atlas_count: u32,
        pub(crate) chart_count: u32,
        pub(crate) mesh_count: u32,
        pub(crate) meshes: *const Mesh,
        pub(crate) utilization: *const f32,
        pub texels_per_unit: f32,
    }

    #[repr(C)]
    #[allow(dead_code, reason = "C layout: not every field is read")]
    pub(crate) struct Chart {
        pub(crate) atlas_index: u32,
        pub(crate) index_array: *const u32,
        pub(crate) index_count: u32,
    }

    #[repr(C)]
    #[allow(dead_code, reason = "C layout: not every field is read")]
    pub(crate) struct Mesh {
        pub(crate) chart_array: *const Chart,
        pub(crate) chart_count: u32,
        pub(crate) index_array: *const u32,
        pub(crate) index_count: u32,
        pub(crate) vertex_array: *const Vertex,
        pub(crate) vertex_count: u32,
    }

    /// Output vertex: `uv` in texels of the page, `atlas_index` −1 when in no chart.
    #[repr(C)]
    #[derive(Clone, Copy, Debug, PartialEq)]
    pub(crate) struct Vertex {
        pub(crate) atlas_index: i32,
        pub(crate) uv: [f32; 2],
        pub(crate) xref: u32,
    }

    pub(crate) const INDEX_FORMAT_U32: c_int = 1;

    #[repr(C)]
    pub(crate) struct MeshDecl {
        pub(crate) vertex_count: u32,
        pub(crate) vertex_position_data: *const c_void,
        pub(crate) vertex_position_stride: u32,
        pub(crate) vertex_normal_data: *const c_void,
        pub(crate) vertex_normal_stride: u32,
        pub(crate) vertex_uv_data: *const c_void,
        pub(crate) vertex_uv_stride: u32,
        pub(crate) index_count: u32,
        pub(crate) index_data: *const c_void,
        pub(crate) index_offset: i32,
        pub(crate) index_format: c_int,
        pub(crate) face_ignore_data: *const bool,
    }

    #[repr(C)]
    pub(crate) struct ChartOptions {
        pub(crate) max_chart_area: f32,
        pub(crate) max_boundary_length: f32,
        pub(crate) proxy_fit_metric_weight: f32,
        pub(crate) roundness_metric_weight: f32,
        pub(crate) straightness_metric_weight: f32,
        pub(crate) normal_seam_metric_weight: f32,
        pub(crate) texture_seam_metric_weight: f32,
        pub(crate) max_threshold: f32,
        pub(crate) grow_face_count: u32,
        pub(crate) max_iterations: u32,
    }

    impl Default for ChartOptions {
        /// xatlas' own defaults.
        fn default() -> Self {
            ChartOptions {
                max_chart_area: 0.0,
                max_boundary_length: 0.0,
                proxy_fit_metric_weight: 2.0,
                roundness_metric_weight: 0.01,
                straightness_metric_weight: 6.0,
                normal_seam_metric_weight: 4.0,
                texture_seam_metric_weight: 0.5,
                max_threshold: 2.0,
                grow_face_count: 32,
                max_iterations: 1,
            }
        }
    }

    #[repr(C)]
    pub(crate) struct PackOptions {
        pub(crate) attempts: c_int,
        pub(crate) texels_per_unit: f32,
        pub(crate) resolution: u32,
        pub(crate) max_chart_size: u32,
        pub(crate) block_align: bool,
        pub(crate) conservative: bool,
        pub(crate) padding: u32,
    }

    type ParameterizeFunc = unsafe extern "C" fn(*const f32, *mut f32, u32, *const u32, u32, bool);
    type ProgressFunc = unsafe extern "C" fn(c_int, c_int, *mut c_void);
    type PrintFunc = unsafe extern "C" fn(*const c_char, ...) -> c_int;

    unsafe extern "C" {
        #[cfg_attr(
            target_env = "msvc",
            link_name = "\u{1}?Create@xatlas@@YAPEAUAtlas@1@XZ"
        )]
        #[cfg_attr(not(target_env = "msvc"), link_name = "_ZN6xatlas6CreateEv")]
        fn xatlas_create() -> *mut Atlas;

        #[cfg_attr(
            target_env = "msvc",
            link_name = "\u{1}?Destroy@xatlas@@YAXPEAUAtlas@1@@Z"
        )]
        #[cfg_attr(not(target_env = "msvc"), link_name = "_ZN6xatlas7DestroyEPNS_5AtlasE")]
        fn xatlas_destroy(atlas: *mut Atlas);

        #[cfg_attr(
            target_env = "msvc",
            link_name = "\u{1}?AddMesh@xatlas@@YA?AW4Enum@AddMeshError@1@PEAUAtlas@1@AEBUMeshDecl@1@@Z"
        )]
        #[cfg_attr(
            not(target_env = "msvc"),
            link_name = "_ZN6xatlas7AddMeshEPNS_5AtlasERKNS_8MeshDeclE"
        )]
        fn xatlas_add_mesh(atlas: *mut Atlas, decl: *const MeshDecl) -> c_int;

        #[cfg_attr(
            target_env = "msvc",
            link_name = "\u{1}?Generate@xatlas@@YAXPEAUAtlas@1@UChartOptions@1@P6AXPEBMPEAMIPEBII_N@ZUPackOptions@1@P6AXW4Enum@ProgressCategory@1@HPEAX@Z9@Z"
        )]
        #[cfg_attr(
            not(target_env = "msvc"),
            link_name = "_ZN6xatlas8GenerateEPNS_5AtlasENS_12ChartOptionsEPFvPKfPfjPKjjbENS_11PackOptionsEPFvNS_16ProgressCategory4EnumEiPvESD_"
        )]
        fn xatlas_generate(
            atlas: *mut Atlas,
            chart_options: ChartOptions,
            parameterize: Option<ParameterizeFunc>,
            pack_options: PackOptions,
            progress: Option<ProgressFunc>,
            progress_user_data: *mut c_void,
        );

        #[cfg_attr(
            target_env = "msvc",
            link_name = "\u{1}?SetPrint@xatlas@@YAXP6AHPEBDZZ_N@Z"
        )]
        #[cfg_attr(not(target_env = "msvc"), link_name = "_ZN6xatlas8SetPrintEPFiPKczEb")]
        fn xatlas_set_print(print: Option<PrintFunc>, verbose: bool);
    }

    /// One xatlas atlas, destroyed on drop.
    pub(crate) struct Handle(*mut Atlas);

    /// Borrowed views of the output, valid while the handle lives and is not regenerated.
    pub(crate) struct Output<'a> {
        pub(crate) page_count: u32,
        pub(crate) meshes: Vec<MeshView<'a>>,
    }

    pub(crate) struct MeshView<'a> {
        pub(crate) indices: &'a [u32],
        pub(crate) vertices: &'a [Vertex],
    }

    impl Handle {
        pub(crate) fn create() -> Self {
            // SAFETY: plain calls without preconditions; a null print function silences xatlas.
            unsafe {
                xatlas_set_print(None, false);
                Handle(xatlas_create())
            }
        }

        /// Returns xatlas' `AddMeshError` (0 = success). The data is copied by xatlas.
        pub(crate) fn add_mesh(&self, decl: &MeshDecl) -> c_int {
            // SAFETY: `decl` points at live buffers of the declared sizes for this call.
            unsafe { xatlas_add_mesh(self.0, decl) }
        }

        pub(crate) fn generate(&self, chart_options: ChartOptions, pack_options: PackOptions) {
            // SAFETY: a live atlas; no callbacks are passed.
            unsafe {
                xatlas_generate(
                    self.0,
                    chart_options,
                    None,
                    pack_options,
                    None,
                    std::ptr::null_mut(),
                )
            }
        }

        pub(crate) fn output(&self) -> Output<'_> {
            // SAFETY: after `generate`, `meshes` holds `mesh_count` meshes whose arrays have the
            // stated lengths; they live until the atlas is destroyed, which `&self` prevents.
            unsafe {
                let atlas = &*self.0;
                let meshes = slice(atlas.meshes, atlas.mesh_count)
                    .iter()
                    .map(|m| MeshView {
                        indices: slice(m.index_array, m.index_count),
                        vertices: slice(m.vertex_array, m.vertex_count),
                    })
                    .collect();
                Output {
                    page_count: atlas.atlas_count,
                    meshes,
                }
            }
        }
    }

    /// A slice from an xatlas array (which may be null when empty).
    unsafe fn slice<'a, T>(data: *const T, len: u32) -> &'a [T] {
        if data.is_null() || len == 0 {
            &[]
        } else {
            unsafe { std::slice::from_raw_parts(data, len as usize) }
        }
    }

    impl Drop for Handle {
        fn drop(&mut self) {
            // SAFETY: created by `xatlas_create`, destroyed once.
            unsafe { xatlas_destroy(self.0) }
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use glam::{Vec2, Vec3};

    use super::super::existing::Overlaps;
    use super::*;
    use crate::atlas::for_each_touched_texel;
    use crate::config::UvMode;
    use crate::scene::{Material, Scene};

    /// One instance to put in a test scene.
    #[derive(Clone, Default)]
    pub(crate) struct Part {
        pub(crate) positions: Vec<Vec3>,
        pub(crate) triangles: Vec<[u32; 3]>,
        pub(crate) uv1: Option<Vec<Vec2>>,
        pub(crate) mesh: u32,
        pub(crate) node: u32,
    }

    impl Part {
        pub(crate) fn new(positions: Vec<Vec3>, triangles: Vec<[u32; 3]>) -> Part {
            Part {
                positions,
                triangles,
                ..Part::default()
            }
        }
        pub(crate) fn with_uv1(mut self, uv1: Vec<Vec2>) -> Part {
            self.uv1 = Some(uv1);
            self
        }
        pub(crate) fn moved(mut self, offset: Vec3, node: u32) -> Part {
            self.positions.iter_mut().for_each(|p| *p += offset);
            self.node = node;
            self
        }
    }

    /// A `w × h` quad in the z = 0 plane facing +z, its corner at `origin`; TEXCOORD_1 = [0,1]².
    pub(crate) fn quad(origin: Vec3, w: f32, h: f32) -> Part {
        let positions = vec![
            origin,
            origin + Vec3::new(w, 0.0, 0.0),
            origin + Vec3::new(w, h, 0.0),
            origin + Vec3::new(0.0, h, 0.0),
        ];
        Part::new(positions, vec![[0, 1, 2], [0, 2, 3]]).with_uv1(vec![
            Vec2::new(0.0, 1.0),
            Vec2::ONE,
            Vec2::X,
            Vec2::ZERO,
        ])
    }

    /// An axis-aligned cube of side `size`, each face an `n × n` grid with its own vertices.
    pub(crate) fn cube(size: f32, n: u32) -> Part {
        let mut part = Part::default();
        let axes = [Vec3::X, Vec3::Y, Vec3::Z];
        for (k, &normal) in axes.iter().chain(&axes.map(|a| -a)).enumerate() {
            let u = axes[(k + 1) % 3];
            let v = normal.cross(u);
            let base = part.positions.len() as u32;
            for j in 0..=n {
                for i in 0..=n {
                    let (s, t) = (i as f32 / n as f32 - 0.5, j as f32 / n as f32 - 0.5);
                    part.positions.push((normal * 0.5 + u * s + v * t) * size);
                }
            }
            for j in 0..n {
                for i in 0..n {
                    let a = base + j * (n + 1) + i;
                    part.triangles.push([a, a + 1, a + n + 2]);
                    part.triangles.push([a, a + n + 2, a + n + 1]);
                }
            }
        }
        part
    }

    /// A latitude-longitude sphere (shared vertices, poles split per segment).
    pub(crate) fn sphere(center: Vec3, radius: f32, rings: u32, segments: u32) -> Part {
        let mut part = Part::default();
        for r in 0..=rings {
            let theta = std::f32::consts::PI * r as f32 / rings as f32;
            for s in 0..=segments {
                let phi = std::f32::consts::TAU * s as f32 / segments as f32;
                let d = Vec3::new(
                    theta.sin() * phi.cos(),
                    theta.cos(),
                    theta.sin() * phi.sin(),
                );
                part.positions.push(center + d * radius);
            }
        }
        for r in 0..rings {
            for s in 0..segments {
                let a = r * (segments + 1) + s;
                let b = a + segments + 1;
                if r != 0 {
                    part.triangles.push([a, a + 1, b]);
                }
                if r != rings - 1 {
                    part.triangles.push([a + 1, b + 1, b]);
                }
            }
        }
        part
    }

    /// A scene with one instance per part (default material, face-averaged normals); `backs`
    /// lists parts that get a flipped back-face copy, appended after all parts.
    pub(crate) fn scene_of(parts: &[Part], backs: &[usize]) -> Scene {
        let mut scene = Scene {
            materials: vec![Material::default()],
            ..Scene::default()
        };
        let add = |scene: &mut Scene, part: &Part, flip: bool| {
            let start = scene.positions.len() as u32;
            let first_triangle = scene.triangles.len() as u32;
            let mut normals = vec![Vec3::ZERO; part.positions.len()];
            for t in &part.triangles {
                let [a, b, c] = t.map(|v| part.positions[v as usize]);
                t.iter()
                    .for_each(|&v| normals[v as usize] += (b - a).cross(c - a));
            }
            let sign = if flip { -1.0 } else { 1.0 };
            scene.positions.extend(&part.positions);
            scene
                .normals
                .extend(normals.iter().map(|n| n.normalize_or(Vec3::Z) * sign));
            scene.uv0.extend(part.positions.iter().map(|_| Vec2::ZERO));
            match &part.uv1 {
                Some(uv1) => scene.uv1.extend(uv1),
                None => scene.uv1.extend(part.positions.iter().map(|_| Vec2::ZERO)),
            }
            let index = scene.instances.len() as u32;
            for t in &part.triangles {
                let t = if flip { [t[0], t[2], t[1]] } else { *t };
                scene.triangles.push(t.map(|v| v + start));
                scene.triangle_instance.push(index);
            }
            scene.instances.push(Instance {
                node: part.node,
                mesh: part.mesh,
                primitive: 0,
                material: 0,
                vertices: start..scene.positions.len() as u32,
                triangles: first_triangle..scene.triangles.len() as u32,
                source_triangle: (0..part.triangles.len() as u32).collect(),
                back_of: None,
                back: None,
                has_uv1: part.uv1.is_some(),
                lightmap: None,
                directional: None,
                split: Default::default(),
            });
        };
        for part in parts {
            add(&mut scene, part, false);
        }
        for &front in backs {
            add(&mut scene, &parts[front], true);
            let back = scene.instances.len() as u32 - 1;
            scene.instances[back as usize].back_of = Some(front as u32);
            scene.instances[front].back = Some(back);
        }
        scene.validate();
        scene
    }

    pub(crate) fn source() -> Source {
        Source {
            path: "test.gltf".into(),
            is_glb: false,
            json: serde_json::json!({}),
            buffers: Vec::new(),
        }
    }

    pub(crate) fn params(texels_per_unit: f32, max_page_size: u32) -> AtlasParams {
        AtlasParams {
            uv: UvMode::Unwrap,
            texels_per_unit,
            instance_density: Vec::new(),
            triangle_density: Vec::new(),
            max_page_size,
            padding: 2,
            split_junctions: true,
            shadow_cuts: true,
            near_contacts: false,
            slot_faces: true,
            narrow_faces: true,
            instancing: Default::default(),
        }
    }

    /// A box of 192 triangles next to a sphere of 448.
    fn box_and_sphere() -> Scene {
        scene_of(
            &[cube(1.0, 4), sphere(Vec3::new(2.0, 0.0, 0.0), 0.5, 16, 16)],
            &[],
        )
    }

    /// Unwraps and runs the atlas' own consistency check.
    fn unwrap_ok(scene: &Scene, params: &AtlasParams) -> Atlas {
        let atlas = unwrap(scene, &source(), params).unwrap();
        atlas.validate(scene);
        atlas
    }

    /// Triangle UVs of each page, in [0,1].
    fn page_triangles(scene: &Scene, atlas: &Atlas, page: u32) -> Vec<[Vec2; 3]> {
        (0..scene.triangles.len() as u32)
            .map(|t| atlas.triangle_uv(scene, t))
            .filter(|(_, p)| *p == page)
            .map(|(uv, _)| uv)
            .collect()
    }

    /// Texel centres claimed by more than one triangle (and covered) on page 0.
    fn first_page_overlaps(scene: &Scene, atlas: &Atlas) -> Overlaps {
        Overlaps::find(atlas.pages[0], page_triangles(scene, atlas, 0).into_iter())
    }

    /// Asserts that the atlas's texel area over the expected one is in `range`.
    fn assert_texel_area(scene: &Scene, atlas: &Atlas, range: std::ops::Range<f64>) {
        let ratio = texel_area_ratio(scene, atlas);
        assert!(range.contains(&ratio), "texel area / expected = {ratio}");
    }

    /// Texel area of every triangle over world area × tpu².
    fn texel_area_ratio(scene: &Scene, atlas: &Atlas) -> f64 {
        let mut texels = 0.0;
        for t in 0..scene.triangles.len() as u32 {
            let ([a, b, c], page) = atlas.triangle_uv(scene, t);
            let size = atlas.pages[page as usize];
            texels += 0.5
                * f64::from((b - a).perp_dot(c - a).abs())
                * f64::from(size.width * size.height);
        }
        let world: f64 = (0..scene.triangles.len())
            .map(|t| scene.triangle_area(t))
            .sum();
        texels / (world * f64::from(atlas.texels_per_unit).powi(2))
    }

    /// Texels of the triangles of instance `i` over its world area (texels² per m²).
    fn instance_texel_density(scene: &Scene, atlas: &Atlas, i: usize) -> f64 {
        let (mut texels, mut world) = (0.0, 0.0);
        for t in scene.instances[i].triangles.clone() {
            let ([a, b, c], page) = atlas.triangle_uv(scene, t);
            let size = atlas.pages[page as usize];
            texels += 0.5
                * f64::from((b - a).perp_dot(c - a).abs())
                * f64::from(size.width * size.height);
            world += scene.triangle_area(t as usize);
        }
        texels / world
    }

    #[test]
    fn instance_density_scales_each_instance() {
        let scene = scene_of(
            &[
                quad(Vec3::ZERO, 1.0, 1.0),
                quad(Vec3::new(3.0, 0.0, 0.0), 1.0, 1.0),
            ],
            &[],
        );
        let atlas = unwrap_ok(
            &scene,
            &AtlasParams {
                instance_density: vec![1.0, 2.5],
                ..params(8.0, 1024)
            },
        );
        let [a, b] = [0, 1].map(|i| instance_texel_density(&scene, &atlas, i));
        assert!((a - 64.0).abs() < 0.5, "{a}");
        assert!((b - 400.0).abs() < 2.0, "{b}");
        assert_eq!(first_page_overlaps(&scene, &atlas).overlapping, 0);
    }

    #[test]
    fn triangle_density_scales_each_face_of_a_cube_without_shared_charts() {
        // A cube of 8 × 8 quads a face (large enough for the planar-region path) with its
        // top face at ×2 and its bottom at ×⅛ (a face nobody sees), on one instance.
        let scene = scene_of(&[cube(1.0, 8)], &[]);
        let up = |t: u32| {
            let [a, b, c] = scene.triangles[t as usize].map(|v| scene.positions[v as usize]);
            (b - a).cross(c - a).normalize().y
        };
        let factor = |t: u32| match up(t) {
            y if y > 0.9 => 2.0,
            y if y < -0.9 => 0.125,
            _ => 1.0,
        };
        let triangle_density: Vec<f32> = (0..scene.triangles.len() as u32).map(factor).collect();
        let atlas = unwrap_ok(
            &scene,
            &AtlasParams {
                triangle_density,
                ..params(16.0, 1024)
            },
        );
        // Texel area over world area per face group.
        let mut texels = [0.0f64; 3];
        let mut world = [0.0f64; 3];
        for t in 0..scene.triangles.len() as u32 {
            let ([a, b, c], page) = atlas.triangle_uv(&scene, t);
            let size = atlas.pages[page as usize];
            let g = match factor(t) {
                2.0 => 0,
                1.0 => 1,
                _ => 2,
            };
            texels[g] += 0.5
                * f64::from((b - a).perp_dot(c - a).abs())
                * f64::from(size.width * size.height);
            world[g] += scene.triangle_area(t as usize);
        }
        let density = [0, 1, 2].map(|g| texels[g] / world[g]);
        assert!((density[0] - 1024.0).abs() < 8.0, "{density:?}");
        assert!((density[1] - 256.0).abs() < 2.0, "{density:?}");
        assert!((density[2] - 4.0).abs() < 0.5, "{density:?}");
        assert_eq!(first_page_overlaps(&scene, &atlas).overlapping, 0);
        // Same input, same layout.
        let again = unwrap_ok(&scene, &atlas_params_of(&scene, factor));
        assert_eq!(atlas.layout_bits(), again.layout_bits());
    }

    fn atlas_params_of(scene: &Scene, factor: impl Fn(u32) -> f32) -> AtlasParams {
        AtlasParams {
            triangle_density: (0..scene.triangles.len() as u32).map(factor).collect(),
            ..params(16.0, 1024)
        }
    }

    #[test]
    fn small_scene_gets_one_small_page() {
        let scene = scene_of(&[quad(Vec3::ZERO, 1.0, 1.0)], &[]);
        let atlas = unwrap_ok(&scene, &params(16.0, 1024));
        assert_eq!(atlas.pages.len(), 1);
        let page = atlas.pages[0];
        // 16×16 texels of quad plus padding, rounded to a multiple of 4.
        assert!(
            (16..=28).contains(&page.width) && (16..=28).contains(&page.height),
            "{page:?}"
        );
        assert_eq!(page.width % 4, 0);
        assert!(!atlas.reused_input_uvs);
    }

    #[test]
    fn dense_scene_spreads_over_several_pages() {
        let scene = box_and_sphere();
        let atlas = unwrap_ok(&scene, &params(64.0, 64));
        assert!(atlas.pages.len() >= 4, "{} pages", atlas.pages.len());
        assert!(
            atlas
                .pages
                .iter()
                .all(|p| p.width <= 64 && p.height <= 64 && p.width % 4 == 0)
        );
        for page in 0..atlas.pages.len() as u32 {
            assert!(
                !page_triangles(&scene, &atlas, page).is_empty(),
                "page {page} is empty"
            );
        }
        assert_texel_area(&scene, &atlas, 0.7..1.6);
    }

    #[test]
    fn large_curved_instances_are_unwrapped_in_blocks_without_overlaps() {
        // 4512 triangles without a planar region: five blocks of MAX_FACES_PER_XATLAS_MESH.
        let scene = scene_of(&[sphere(Vec3::ZERO, 1.0, 48, 48)], &[]);
        assert!(scene.triangles.len() > 4 * MAX_FACES_PER_XATLAS_MESH);
        let atlas = unwrap_ok(&scene, &params(16.0, 1024));
        let overlaps = first_page_overlaps(&scene, &atlas);
        assert_eq!(atlas.pages.len(), 1);
        assert_eq!(overlaps.overlapping, 0, "{overlaps:?}");
        // 4π m² at 16 texels per unit: 3217 texels, less the centres on chart borders.
        assert!(overlaps.covered > 2800, "{overlaps:?}");
        assert_texel_area(&scene, &atlas, 0.9..1.6);
    }

    /// An `n × n` grid of `size`-sided squares in the z = 0 plane facing +z, vertices shared;
    /// the squares listed in `holes` (x, y) are left out.
    fn grid(size: f32, n: u32, holes: &[(u32, u32)]) -> Part {
        let mut part = Part::default();
        for j in 0..=n {
            for i in 0..=n {
                part.positions
                    .push(Vec3::new(i as f32 * size, j as f32 * size, 0.0));
            }
        }
        for j in 0..n {
            for i in 0..n {
                if holes.contains(&(i, j)) {
                    continue;
                }
                let a = j * (n + 1) + i;
                part.triangles.push([a, a + 1, a + n + 2]);
                part.triangles.push([a, a + n + 2, a + n + 1]);
            }
        }
        part
    }

    fn regions_of(scene: &Scene, tpu: f32) -> (Vec<Region>, Vec<u32>) {
        let limits = Limits {
            max_chart_area: 0.25 * 1024.0 * 1024.0,
            max_chart_size: 1020.0,
        };
        let tpus = vec![tpu; scene.instances[0].triangles.len()];
        planar_regions(scene, 0, &tpus, limits, &BTreeSet::new())
    }

    #[test]
    fn large_planar_instances_are_one_chart_at_exact_density() {
        // 8192 triangles, eight blocks' worth, but one convex planar region: no block cuts.
        let scene = scene_of(&[grid(1.0 / 16.0, 64, &[])], &[]);
        let (regions, rest) = regions_of(&scene, 16.0);
        assert_eq!((regions.len(), rest.len()), (1, 0));
        assert_eq!(regions[0].outline.len(), 4);
        let atlas = unwrap_ok(&scene, &params(16.0, 1024));
        assert_eq!(atlas.instances[0].chart_count(), 1);
        let overlaps = first_page_overlaps(&scene, &atlas);
        assert_eq!(overlaps.overlapping, 0, "{overlaps:?}");
        // 64 × 64 texels; xatlas only rounds the chart's extents up to whole texels.
        assert!(overlaps.covered >= 63 * 63, "{overlaps:?}");
        assert_texel_area(&scene, &atlas, 0.999..1.04);
    }

    #[test]
    fn only_convex_crease_bounded_planar_regions_skip_charting() {
        // A cube's faces meet at 90°: six regions of 32 triangles.
        let (regions, rest) = regions_of(&scene_of(&[cube(1.0, 4)], &[]), 16.0);
        assert_eq!((regions.len(), rest.len()), (6, 0));
        // Covering less than `MIN_HULL_COVER` of its hull (a thin L, 28 of 64 squares), too
        // small: left to xatlas.
        let l_shape: Vec<(u32, u32)> = (2..8).flat_map(|i| (2..8).map(move |j| (i, j))).collect();
        for part in [grid(0.1, 8, &l_shape), grid(0.1, 2, &[])] {
            let scene = scene_of(&[part], &[]);
            let (regions, rest) = regions_of(&scene, 16.0);
            assert!(regions.is_empty());
            assert_eq!(rest.len(), scene.triangles.len());
        }
        // With a hole (63 of 64 squares) or a corner cut (48 of 64): one region, packed by its
        // hull, its triangles apart from every other chart's.
        let corner: Vec<(u32, u32)> = (4..8).flat_map(|i| (4..8).map(move |j| (i, j))).collect();
        for holes in [vec![(3, 3)], corner] {
            let scene = scene_of(&[grid(0.1, 8, &holes)], &[]);
            let (regions, rest) = regions_of(&scene, 16.0);
            assert_eq!((regions.len(), rest.len()), (1, 0), "holes {holes:?}");
            let atlas = unwrap_ok(&scene, &params(16.0, 256));
            assert_eq!(atlas.instances[0].chart_count(), 1);
            let overlaps = first_page_overlaps(&scene, &atlas);
            assert_eq!(overlaps.overlapping, 0, "{overlaps:?}");
        }
        // Two flat halves folded by 10°: xatlas may chart across the fold, so neither is taken.
        let mut roof = grid(0.1, 8, &[]);
        let fold = glam::Quat::from_rotation_y(10f32.to_radians());
        for p in roof.positions.iter_mut().filter(|p| p.x > 0.45) {
            *p = Vec3::new(0.4, p.y, 0.0) + fold * Vec3::new(p.x - 0.4, 0.0, 0.0);
        }
        let (regions, _) = regions_of(&scene_of(&[roof], &[]), 16.0);
        assert!(regions.is_empty());
        // A curved surface has no planar region.
        let (regions, _) = regions_of(&scene_of(&[sphere(Vec3::ZERO, 1.0, 16, 16)], &[]), 16.0);
        assert!(regions.is_empty());
    }

    /// A region that covers most of its hull but lies over itself (a fan turning 380° about
    /// one vertex, a notch cut from it) is no planar chart: the fold test sends it to xatlas.
    #[test]
    fn a_planar_region_over_itself_is_left_to_xatlas() {
        let (n, turn) = (32u32, 380f32.to_radians());
        let mut part = Part::default();
        part.positions.push(Vec3::ZERO);
        for k in 0..=n {
            let notch = if (8..=17).contains(&k) { 0.3 } else { 1.0 };
            let r = notch * (1.0 + 0.002 * k as f32); // no rim vertex welds onto another
            let a = turn * k as f32 / n as f32;
            part.positions
                .push(Vec3::new(r * a.cos(), r * a.sin(), 0.0));
        }
        part.triangles = (0..n).map(|k| [0, k + 1, k + 2]).collect();
        // Its triangles cover 0.97 of the hull: only the fold test tells.
        let flat: Vec<DVec2> = part
            .positions
            .iter()
            .map(|p| p.truncate().as_dvec2())
            .collect();
        let area: f64 = (part.triangles.iter())
            .map(|t| 0.5 * (flat[t[1] as usize] - flat[0]).perp_dot(flat[t[2] as usize] - flat[0]))
            .sum();
        let cover = area / polygon_area(&convex_hull(&flat));
        assert!((MIN_HULL_COVER..1.0).contains(&cover), "covers {cover}");
        let scene = scene_of(&[part], &[]);
        let (regions, rest) = regions_of(&scene, 16.0);
        assert!(regions.is_empty());
        assert_eq!(rest.len(), scene.triangles.len());
    }

    #[test]
    fn convex_hull_drops_corners_on_straight_runs() {
        let square: Vec<DVec2> = (0..=4)
            .flat_map(|i| (0..=4).map(move |j| DVec2::new(f64::from(i), f64::from(j))))
            .collect();
        let hull = convex_hull(&square);
        assert_eq!(
            hull,
            [
                DVec2::ZERO,
                DVec2::new(4.0, 0.0),
                DVec2::new(4.0, 4.0),
                DVec2::new(0.0, 4.0)
            ]
        );
        assert_eq!(polygon_area(&hull), 16.0);
    }

    #[test]
    fn a_region_xatlas_does_not_place_whole_is_charted_again() {
        // A 1024-gon 0.8 texels across: the fan of its outline has slivers below xatlas' area
        // epsilon, left out of every chart, so the outline is not placed as one chart.
        let mut disc = Part::new(vec![Vec3::ZERO], Vec::new());
        for s in 0..1024u32 {
            let a = std::f32::consts::TAU * s as f32 / 1024.0;
            disc.positions.push(Vec3::new(a.cos(), a.sin(), 0.0) * 0.05);
            disc.triangles.push([0, 1 + s, 1 + (s + 1) % 1024]);
        }
        let scene = scene_of(&[disc], &[]);
        let tpus = [16.0; 1024];
        assert!(
            run_xatlas(
                &scene,
                &tpus,
                1024,
                2,
                &BTreeSet::new(),
                Charting::Xatlas,
                &NoProgress
            )
            .is_err()
        );
        let atlas = unwrap_ok(&scene, &params(16.0, 1024));
        let overlaps = first_page_overlaps(&scene, &atlas);
        assert_eq!(overlaps.overlapping, 0, "{overlaps:?}");
        assert!(overlaps.covered > 0, "{overlaps:?}");
    }

    #[test]
    fn charts_do_not_overlap_and_keep_their_density() {
        let scene = box_and_sphere();
        let atlas = unwrap_ok(&scene, &params(32.0, 1024));
        assert_eq!(atlas.pages.len(), 1);
        let overlaps = first_page_overlaps(&scene, &atlas);
        assert!(overlaps.covered > 6 * 32 * 32, "{overlaps:?}");
        assert_eq!(overlaps.overlapping, 0, "{overlaps:?}");
        assert_texel_area(&scene, &atlas, 0.7..1.6);
        // Packed tightly: the page is not much bigger than the charts.
        let page = atlas.pages[0];
        let fill = overlaps.covered as f64 / f64::from(page.width * page.height);
        assert!(fill > 0.3, "page {page:?} is {:.0}% covered", fill * 100.0);
    }

    /// Instance owning each texel a triangle touches (sampled every quarter texel), per page.
    fn touched_texels(scene: &Scene, atlas: &Atlas) -> Vec<Vec<u32>> {
        let mut owner: Vec<Vec<u32>> = atlas
            .pages
            .iter()
            .map(|p| vec![u32::MAX; (p.width * p.height) as usize])
            .collect();
        for t in 0..scene.triangles.len() as u32 {
            let (uv, page) = atlas.triangle_uv(scene, t);
            for_each_touched_texel(uv, atlas.pages[page as usize], |k| {
                owner[page as usize][k] = scene.triangle_instance[t as usize];
            });
        }
        owner
    }

    #[test]
    fn instances_are_padded_apart() {
        let parts: Vec<Part> = (0..12)
            .map(|k| cube(0.5, 2).moved(Vec3::new(k as f32, 0.0, 0.0), k))
            .collect();
        let scene = scene_of(&parts, &[]);
        for padding in [1, 2, 4] {
            let atlas = unwrap_ok(
                &scene,
                &AtlasParams {
                    padding,
                    ..params(16.0, 256)
                },
            );
            for (owner, size) in touched_texels(&scene, &atlas).iter().zip(&atlas.pages) {
                let (w, h) = (size.width as i64, size.height as i64);
                let reach = i64::from(padding);
                for y in 0..h {
                    for x in 0..w {
                        let me = owner[(y * w + x) as usize];
                        if me == u32::MAX {
                            continue;
                        }
                        for ny in (y - reach).max(0)..=(y + reach).min(h - 1) {
                            for nx in (x - reach).max(0)..=(x + reach).min(w - 1) {
                                let other = owner[(ny * w + nx) as usize];
                                assert!(
                                    other == u32::MAX || other == me,
                                    "padding {padding}: instances {me} at ({x}, {y}) and {other} at ({nx}, {ny})"
                                );
                            }
                        }
                    }
                }
            }
        }
    }

    /// A triangle whose shortest edge (5e-5 texels) lies below xatlas' vertex merging is never
    /// given to xatlas: two of its corners would be one vertex there, and a chart with such
    /// triangles got NaN UVs, which xatlas' packer rasterises for ever (a junction-split furnished
    /// interior at `--quality high` hung so). It is placed like the faces xatlas leaves out.
    #[test]
    fn a_needle_is_left_out_of_xatlas() {
        let tpu = 24.0;
        let needle = Part::new(
            vec![
                Vec3::ZERO,
                Vec3::new(5e-5 / tpu, 0.0, 0.0),
                Vec3::new(0.0, 10.0 / tpu, 0.0),
            ],
            vec![[0, 1, 2]],
        );
        let scene = scene_of(&[sphere(Vec3::new(2.0, 0.0, 0.0), 0.5, 8, 8), needle], &[]);
        let atlas = unwrap_ok(&scene, &params(tpu, 256));
        let uv_area = |t: u32| {
            let ([a, b, c], _) = atlas.triangle_uv(&scene, t);
            (b - a).perp_dot(c - a).abs()
        };
        let last = scene.triangles.len() as u32 - 1;
        assert!(is_needle(&scene, last as usize, tpu));
        assert_eq!(uv_area(last), 0.0, "the needle was charted");
        assert!((0..last).all(|t| uv_area(t) > 0.0 && !is_needle(&scene, t as usize, tpu)));
        assert!(
            atlas
                .instances
                .iter()
                .flat_map(|i| &i.uv)
                .all(|uv| uv.is_finite())
        );
    }

    #[test]
    fn unwrap_is_deterministic() {
        let scene = box_and_sphere();
        let first = unwrap_ok(&scene, &params(24.0, 128)).layout_bits();
        for _ in 0..4 {
            assert!(
                unwrap_ok(&scene, &params(24.0, 128)).layout_bits() == first,
                "xatlas output changed between runs"
            );
        }
    }

    #[test]
    fn corners_keep_their_source_vertex_and_order() {
        // Split cube faces: 24 vertices share 8 positions, xatlas sees colocal twins.
        let scene = scene_of(
            &[cube(2.0, 1), quad(Vec3::new(3.0, 0.0, 0.0), 1.0, 1.0)],
            &[],
        );
        let atlas = unwrap_ok(&scene, &params(8.0, 256));
        for (inst, si) in atlas.instances.iter().zip(&scene.instances) {
            for (tri, source) in inst
                .triangles
                .iter()
                .zip(&scene.triangles[si.triangles.start as usize..si.triangles.end as usize])
            {
                assert_eq!(
                    tri.map(|a| inst.xref[a as usize] + si.vertices.start),
                    *source
                );
            }
        }
        // Each xref appears with one UV per chart it borders: at most 3 copies of a cube corner.
        assert!(atlas.instances[0].xref.len() <= 24 * 3);
    }

    #[test]
    fn back_faces_get_their_own_charts() {
        let scene = scene_of(&[quad(Vec3::ZERO, 1.0, 1.0)], &[0]);
        let atlas = unwrap_ok(&scene, &params(16.0, 1024));
        let overlaps = first_page_overlaps(&scene, &atlas);
        assert_eq!(atlas.pages.len(), 1);
        assert_eq!(overlaps.overlapping, 0);
        // Each 16×16-texel chart starts half a texel into its first texel; centres on the
        // boundary or on the diagonal belong to no triangle, so at least 14² per chart.
        assert!(overlaps.covered >= 2 * 14 * 14, "{overlaps:?}");
    }

    #[test]
    fn instance_without_triangles_is_empty() {
        let mut scene = scene_of(
            &[quad(Vec3::ZERO, 1.0, 1.0), quad(Vec3::ONE, 1.0, 1.0)],
            &[],
        );
        // Drop the second instance's triangles (as the loader does for all-degenerate ones).
        scene.triangles.truncate(2);
        scene.triangle_instance.truncate(2);
        scene.instances[1].triangles = 2..2;
        scene.instances[1].source_triangle.clear();
        let atlas = unwrap_ok(&scene, &params(16.0, 1024));
        assert!(atlas.instances[1].triangles.is_empty());
        assert_eq!(atlas.instances[0].triangles.len(), 2);
    }

    #[test]
    fn tiny_scenes_still_unwrap() {
        // A millimetre-sized cube at 10000 texels per unit: 10×10 texels a face; in world units
        // every triangle is below xatlas' absolute area epsilon.
        let scene = scene_of(&[cube(1e-3, 2)], &[]);
        let atlas = unwrap_ok(&scene, &params(10_000.0, 256));
        assert_texel_area(&scene, &atlas, 0.7..1.8);
    }

    #[test]
    fn absurd_density_is_refused_before_unwrapping() {
        let scene = scene_of(&[quad(Vec3::ZERO, 100.0, 100.0)], &[]);
        assert!(matches!(
            unwrap(&scene, &source(), &params(1000.0, 1024)),
            Err(Error::Option(_))
        ));
    }
}
