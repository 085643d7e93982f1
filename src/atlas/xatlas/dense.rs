//! Dense meshes: charts on what the lightmap can resolve.
//!
//! A scanned prop, a sculpted terrain or a CAD part can carry far more triangles than the
//! lightmap has texels: the 1 × 1 m wavy height field of issue 28 has a million 1.4 mm
//! triangles for a few hundred texels. xatlas charts such a mesh at the granularity of its
//! triangles (quadratic chart growing, cut into blocks of [`super::MAX_FACES_PER_XATLAS_MESH`]
//! faces, single-threaded): six minutes there. Yet at a texel of 6 cm every texel holds a
//! hundred triangles, and a chart only has to map the surface without folds and with little
//! stretch; where the surface is smooth, its projection onto a plane does.
//!
//! So an instance is **dense** when it has at least [`MIN_TRIANGLES`] triangles averaging at
//! most [`MAX_MEAN_TRIANGLE_TEXELS`] texel² (16 or more triangles per texel), and its triangles
//! are charted here instead of by xatlas:
//!
//! 1. **Cells**: triangles are binned by centroid into cubes of [`CELL_TEXELS`] texels (fewer
//!    when the page is small), so every chart stays compact and within xatlas' chart limits.
//! 2. **Smooth patches**: within a cell, connected triangles (across manifold edges, same
//!    junction side) whose normals lie within [`CONE_DEGREES`] of a reference direction form
//!    one patch. The reference is the area-weighted mean normal of the cell's connected piece
//!    still unassigned (the patch grows from the first triangle inside that cone), so a gently
//!    curved piece is one patch; a piece that turns further is carved into several.
//!    Zero-area triangles join any patch that reaches them.
//! 3. **Projection**: each patch is projected onto the plane of its mean normal, scaled so its
//!    texel area equals its world area × tpu² (the projection shrinks a triangle turned by θ
//!    to cos θ of its area; within the cone no triangle's area is stretched by more than
//!    1/cos 30° = 1.15 against the patch's mean, a length by at most that along one axis).
//!    Every triangle keeps its orientation (checked), and a sampled test at a quarter texel
//!    checks that the patch does not fold over itself (a spiral ramp would).
//! 4. **Packing only**: the patch goes to xatlas as the fan of a convex outline — the hull of
//!    its vertices rounded outwards to a lattice of [`LATTICE_TEXELS`], a few dozen corners
//!    however many triangles it has — exactly like the planar regions of [`super`], and its
//!    triangles are placed by the affine map xatlas gave that outline. Charts thus never
//!    overlap (xatlas packs the outlines apart, with padding) and cover every triangle.
//!
//! Patches that fail a check (folds, a wrong orientation, beyond the chart limits) and
//! outlines xatlas does not place as one chart go to xatlas as triangles, as before; so does
//! a surface noisier than the cone at the scale of its triangles (each patch then a handful of
//! triangles, charted by xatlas in its blocks: correct, but as slow as before).
//!
//! Cost: linear in the triangles (one sort of the welded edges, breadth-first growth, one pass
//! per patch); instances are done in parallel (rayon, collected in instance order) and so are
//! the patches of an instance. Everything is a function of the input alone: the same bytes on
//! any thread count.

use std::collections::BTreeSet;

use glam::{DVec2, DVec3, Vec3};
use rayon::prelude::*;

use super::{Limits, Region, convex_hull, polygon_area};
use crate::scene::Scene;

/// Instances with fewer triangles are left to the planar-region pass and xatlas.
pub(super) const MIN_TRIANGLES: usize = 4096;

/// An instance is dense when its triangles average at most this area (texels²).
pub(super) const MAX_MEAN_TRIANGLE_TEXELS: f64 = 1.0 / 16.0;

/// A patch's triangles turn at most this far from its reference direction.
pub(super) const CONE_DEGREES: f64 = 30.0;

/// Side of the cells that bound a patch (texels).
pub(super) const CELL_TEXELS: f64 = 32.0;

/// Outline corners lie on a lattice of this step (texels) around the patch.
pub(super) const LATTICE_TEXELS: f64 = 0.25;

/// Pieces carved into more patches than this use each seed's own normal as the reference
/// (no more mean normals of what is left): keeps noisy pieces linear in their size.
const MAX_MEAN_REFERENCES: usize = 8;

/// Marks a triangle no patch took yet.
const FREE: u32 = u32::MAX;

/// Marks a triangle left to xatlas.
const REST: u32 = u32::MAX - 1;

/// For a dense instance `index` (at `tpu` texels per unit): its smooth patches as regions for
/// xatlas to pack, and the instance-local triangles (ascending) left to xatlas to chart.
/// `None` when the instance is not dense (`any_size` charts it so anyway). Patches whose seed
/// (lowest triangle) is in `excluded` are left to xatlas.
pub(super) fn smooth_regions(
    scene: &Scene,
    index: u32,
    tpu: f32,
    limits: Limits,
    excluded: &BTreeSet<(u32, u32)>,
    any_size: bool,
) -> Option<(Vec<Region>, Vec<u32>)> {
    let inst = &scene.instances[index as usize];
    let tris = &scene.triangles[inst.triangles.start as usize..inst.triangles.end as usize];
    if tris.len() < MIN_TRIANGLES && !any_size {
        return None;
    }
    let mut mesh = Mesh::new(scene, index, tpu);
    let mean = mesh.area.iter().sum::<f64>() / tris.len() as f64;
    if mean > MAX_MEAN_TRIANGLE_TEXELS && !any_size {
        return None;
    }

    let cell = CELL_TEXELS.min(0.35 * limits.max_chart_size).max(1.0);
    let patches = mesh.patches(cell);
    let mut rest = Vec::new();
    let found: Vec<Option<Region>> = patches
        .par_iter()
        .map(|members| {
            if excluded.contains(&(index, members[0])) {
                return None;
            }
            mesh.project(members, limits)
        })
        .collect();
    let mut regions = Vec::with_capacity(found.len());
    for (members, region) in patches.into_iter().zip(found) {
        match region {
            Some(region) => regions.push(region),
            None => rest.extend(members),
        }
    }
    rest.extend(
        mesh.patch_of
            .iter()
            .enumerate()
            .filter(|&(_, &p)| p == REST)
            .map(|(t, _)| t as u32),
    );
    rest.sort_unstable();
    Some((regions, rest))
}

/// One instance's triangles as the patch search sees them, positions in texels.
struct Mesh<'a> {
    scene: &'a Scene,
    index: u32,
    tpu: f64,
    /// Instance-local corners of each triangle.
    local: Vec<[u32; 3]>,
    /// Unit normal (zero for zero-area triangles) and area (texels²) of each triangle.
    normal: Vec<DVec3>,
    area: Vec<f64>,
    /// The triangle across each edge (corner k to k + 1), `FREE` where the edge is open or
    /// shared by more than two triangles, or the junction split puts the two on other sides.
    neighbour: Vec<[u32; 3]>,
    /// Patch of each triangle (its index in the list `patches` returns), `FREE` or `REST`.
    patch_of: Vec<u32>,
}

impl<'a> Mesh<'a> {
    fn new(scene: &'a Scene, index: u32, tpu: f32) -> Mesh<'a> {
        let inst = &scene.instances[index as usize];
        let first = inst.vertices.start;
        let local: Vec<[u32; 3]> = scene.triangles
            [inst.triangles.start as usize..inst.triangles.end as usize]
            .iter()
            .map(|t| t.map(|v| v - first))
            .collect();
        let mut mesh = Mesh {
            scene,
            index,
            tpu: f64::from(tpu),
            local,
            normal: Vec::new(),
            area: Vec::new(),
            neighbour: Vec::new(),
            patch_of: Vec::new(),
        };
        let (normal, area) = (0..mesh.local.len())
            .into_par_iter()
            .map(|t| {
                let [a, b, c] = mesh.corners(t);
                let n = (b - a).cross(c - a);
                (n.normalize_or_zero(), 0.5 * n.length())
            })
            .unzip();
        (mesh.normal, mesh.area) = (normal, area);
        mesh.neighbour = mesh.neighbours();
        mesh.patch_of = vec![FREE; mesh.local.len()];
        mesh
    }

    /// Position of instance-local vertex `v` in texels.
    fn at(&self, v: u32) -> DVec3 {
        let first = self.scene.instances[self.index as usize].vertices.start;
        self.scene.positions[(first + v) as usize].as_dvec3() * self.tpu
    }

    fn corners(&self, t: usize) -> [DVec3; 3] {
        self.local[t].map(|v| self.at(v))
    }

    /// The triangle across each edge: corners welded by position (+0.0 folds −0.0 into 0.0),
    /// every edge keyed by its welded ends, triangles on one key neighbours when exactly two.
    fn neighbours(&self) -> Vec<[u32; 3]> {
        let inst = &self.scene.instances[self.index as usize];
        let positions =
            &self.scene.positions[inst.vertices.start as usize..inst.vertices.end as usize];
        let key = |v: u32| {
            (positions[v as usize] + Vec3::ZERO)
                .to_array()
                .map(f32::to_bits)
        };
        let mut order: Vec<u32> = (0..positions.len() as u32).collect();
        order.par_sort_unstable_by_key(|&v| (key(v), v));
        let mut weld = vec![0u32; positions.len()];
        let mut id = 0;
        for (i, &v) in order.iter().enumerate() {
            if i > 0 && key(v) != key(order[i - 1]) {
                id += 1;
            }
            weld[v as usize] = id;
        }
        let mut edges: Vec<(u64, u32)> = (0..self.local.len())
            .into_par_iter()
            .flat_map_iter(|t| {
                let w = self.local[t].map(|v| weld[v as usize]);
                (0..3).filter_map(move |k| {
                    let (a, b) = (w[k], w[(k + 1) % 3]);
                    let key = (u64::from(a.min(b)) << 32) | u64::from(a.max(b));
                    (a != b).then_some((key, (3 * t + k) as u32))
                })
            })
            .collect();
        edges.par_sort_unstable();
        let sides = &inst.split.sides;
        let side = |t: u32| sides.get(t as usize).copied().unwrap_or(0);
        let mut neighbour = vec![[FREE; 3]; self.local.len()];
        for run in edges.chunk_by(|x, y| x.0 == y.0) {
            if let [(_, s), (_, o)] = *run {
                let (t, u) = (s / 3, o / 3);
                if t != u && side(t) == side(u) {
                    neighbour[t as usize][(s % 3) as usize] = u;
                    neighbour[u as usize][(o % 3) as usize] = t;
                }
            }
        }
        neighbour
    }

    /// Carves the triangles into smooth patches (module docs, steps 1 and 2): the members of
    /// each, ascending. Triangles of pieces with no area are marked `REST`.
    fn patches(&mut self, cell_texels: f64) -> Vec<Vec<u32>> {
        let n = self.local.len();
        let centroid = |t: usize| self.corners(t).iter().sum::<DVec3>() / 3.0;
        let lo = (0..n).fold(DVec3::INFINITY, |m, t| m.min(centroid(t)));
        let cells: Vec<[u32; 3]> = (0..n)
            .into_par_iter()
            .map(|t| {
                ((centroid(t) - lo) / cell_texels)
                    .floor()
                    .as_uvec3()
                    .to_array()
            })
            .collect();
        let cos_cone = CONE_DEGREES.to_radians().cos();
        let mut patches: Vec<Vec<u32>> = Vec::new();
        // Breadth-first search scratch: a stamp per search marks what it reached.
        let mut stamp = vec![0u32; n];
        let mut current = 0u32;
        let mut queue: Vec<u32> = Vec::new();
        let mut piece: Vec<u32> = Vec::new();
        let mut left: Vec<u32> = Vec::new();
        for start in 0..n as u32 {
            if self.patch_of[start as usize] != FREE {
                continue;
            }
            // The connected piece of free triangles in the start's cell.
            current += 1;
            let c = cells[start as usize];
            self.search(start, &mut stamp, current, &mut queue, |t| {
                cells[t as usize] == c
            });
            piece.clone_from(&queue);
            piece.sort_unstable();
            // Carve it into patches until every triangle is taken.
            let mut references = 0;
            let mut cursor = 0;
            loop {
                while cursor < piece.len() && self.patch_of[piece[cursor] as usize] != FREE {
                    cursor += 1;
                }
                let Some(&first) = piece.get(cursor) else {
                    break;
                };
                // The free connected remainder holding `first`, and its reference direction.
                current += 1;
                let in_piece = |t: u32| cells[t as usize] == c;
                let used_mean = references < MAX_MEAN_REFERENCES;
                let (seed, reference) = if used_mean {
                    references += 1;
                    self.search(first, &mut stamp, current, &mut queue, in_piece);
                    left.clone_from(&queue);
                    left.sort_unstable();
                    let mean = left
                        .iter()
                        .map(|&t| self.normal[t as usize] * self.area[t as usize])
                        .sum::<DVec3>()
                        .normalize_or_zero();
                    let inside = left
                        .iter()
                        .find(|&&t| self.normal[t as usize].dot(mean) >= cos_cone);
                    let some_area = left.iter().find(|&&t| self.area[t as usize] > 0.0);
                    match (inside, some_area) {
                        (Some(&t), _) => (t, mean),
                        (None, Some(&t)) => (t, self.normal[t as usize]),
                        (None, None) => (first, DVec3::ZERO),
                    }
                } else {
                    (first, self.normal[first as usize])
                };
                if reference == DVec3::ZERO {
                    // Zero-area triangles only: left to xatlas, which places them at a point.
                    let lonely = if used_mean { &left[..] } else { &[first][..] };
                    lonely
                        .iter()
                        .for_each(|&t| self.patch_of[t as usize] = REST);
                    continue;
                }
                current += 1;
                let (normal, area) = (&self.normal, &self.area);
                self.search(seed, &mut stamp, current, &mut queue, |t| {
                    cells[t as usize] == c
                        && (area[t as usize] == 0.0
                            || normal[t as usize].dot(reference) >= cos_cone)
                });
                let id = patches.len() as u32;
                queue.iter().for_each(|&t| self.patch_of[t as usize] = id);
                let mut members = queue.clone();
                members.sort_unstable();
                patches.push(members);
            }
        }
        patches
    }

    /// Breadth-first search from `start` over free triangles that `joins`, marking them with
    /// `current` in `stamp`; `queue` ends up holding what it reached, in search order.
    fn search(
        &self,
        start: u32,
        stamp: &mut [u32],
        current: u32,
        queue: &mut Vec<u32>,
        joins: impl Fn(u32) -> bool,
    ) {
        queue.clear();
        queue.push(start);
        stamp[start as usize] = current;
        let mut head = 0;
        while head < queue.len() {
            let t = queue[head] as usize;
            head += 1;
            for u in self.neighbour[t] {
                if u != FREE
                    && stamp[u as usize] != current
                    && self.patch_of[u as usize] == FREE
                    && joins(u)
                {
                    stamp[u as usize] = current;
                    queue.push(u);
                }
            }
        }
    }

    /// The patch `members` projected onto the plane of its mean normal (module docs, steps 3
    /// and 4); `None` when a triangle flips, the patch folds over itself or it exceeds the
    /// chart limits.
    fn project(&self, members: &[u32], limits: Limits) -> Option<Region> {
        let normal = members
            .iter()
            .map(|&t| self.normal[t as usize] * self.area[t as usize])
            .sum::<DVec3>()
            .normalize_or_zero();
        if normal == DVec3::ZERO {
            return None;
        }
        let u_axis = normal.any_orthonormal_vector();
        let v_axis = normal.cross(u_axis);
        let mut vertices: Vec<u32> = members
            .iter()
            .flat_map(|&t| self.local[t as usize])
            .collect();
        vertices.sort_unstable();
        vertices.dedup();
        let mut plane: Vec<DVec2> = vertices
            .iter()
            .map(|&v| {
                let p = self.at(v);
                DVec2::new(p.dot(u_axis), p.dot(v_axis))
            })
            .collect();
        let corner =
            |t: u32| self.local[t as usize].map(|v| vertices.binary_search(&v).unwrap_or_default());
        // Orientation kept, and the projected area.
        let (mut world, mut flat) = (0.0, 0.0);
        for &t in members {
            let [a, b, c] = corner(t).map(|i| plane[i]);
            let twice = (b - a).perp_dot(c - a);
            if self.area[t as usize] > 0.0 && twice <= 0.0 {
                return None;
            }
            world += self.area[t as usize];
            flat += 0.5 * twice.max(0.0);
        }
        // Texel area = world area × tpu².
        let scale = (world / flat).sqrt();
        plane.iter_mut().for_each(|p| *p *= scale);

        let mut outline = lattice_hull(&plane);
        if outline.len() < 3 {
            return None;
        }
        let lo = outline.iter().fold(DVec2::INFINITY, |m, p| m.min(*p));
        let hi = outline.iter().fold(DVec2::NEG_INFINITY, |m, p| m.max(*p));
        if polygon_area(&outline) > limits.max_chart_area
            || (hi - lo).length() > limits.max_chart_size
        {
            return None;
        }
        plane.iter_mut().for_each(|p| *p -= lo);
        outline.iter_mut().for_each(|p| *p -= lo);
        if folds(
            members.iter().map(|&t| corner(t).map(|i| plane[i])),
            hi - lo,
        ) {
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

/// The convex hull of `points` with its corners rounded outwards to the lattice of
/// [`LATTICE_TEXELS`]: it contains every point, and has few corners and no slivers.
fn lattice_hull(points: &[DVec2]) -> Vec<DVec2> {
    let step = LATTICE_TEXELS;
    let corners: Vec<DVec2> = convex_hull(points)
        .iter()
        .flat_map(|p| {
            let (lo, hi) = ((*p / step).floor() * step, (*p / step).ceil() * step);
            [lo, DVec2::new(hi.x, lo.y), hi, DVec2::new(lo.x, hi.y)]
        })
        .collect();
    convex_hull(&corners)
}

/// Whether counter-clockwise triangles `faces` inside `[0, extent]` cover one sample point
/// (a lattice of four per texel) twice: the patch folds over itself. Points on an edge count
/// for no triangle, so neighbours never clash.
pub(super) fn folds(faces: impl Iterator<Item = [DVec2; 3]>, extent: DVec2) -> bool {
    const PER_TEXEL: f64 = 4.0;
    let size = (extent * PER_TEXEL).ceil().as_uvec2() + 1;
    let mut covered = vec![false; (size.x * size.y) as usize];
    for [a, b, c] in faces {
        let (lo, hi) = (a.min(b).min(c) * PER_TEXEL, a.max(b).max(c) * PER_TEXEL);
        let (x0, y0) = (lo.x.ceil().max(0.0) as u32, lo.y.ceil().max(0.0) as u32);
        let (x1, y1) = (
            (hi.x.floor() as u32).min(size.x - 1),
            (hi.y.floor() as u32).min(size.y - 1),
        );
        for y in y0..=y1 {
            for x in x0..=x1 {
                let p = DVec2::new(f64::from(x), f64::from(y)) / PER_TEXEL;
                let inside = (b - a).perp_dot(p - a) > 0.0
                    && (c - b).perp_dot(p - b) > 0.0
                    && (a - c).perp_dot(p - c) > 0.0;
                if inside {
                    let k = (y * size.x + x) as usize;
                    if covered[k] {
                        return true;
                    }
                    covered[k] = true;
                }
            }
        }
    }
    false
}

#[cfg(test)]
mod tests {
    use std::f32::consts::TAU;

    use glam::{Vec2, Vec3};

    use super::super::tests::{Part, params, scene_of, source, sphere};
    use super::super::{Limits, unwrap};
    use super::*;
    use crate::atlas::{Atlas, Overlaps};

    fn limits() -> Limits {
        Limits {
            max_chart_area: 0.25 * 1024.0 * 1024.0,
            max_chart_size: 1020.0,
        }
    }

    /// A 1 × 1 m wavy field of `n × n` quads in the z = 0 plane (heights along z), facing +z.
    fn wavy(n: u32) -> Part {
        let mut part = Part::default();
        for j in 0..=n {
            for i in 0..=n {
                let (x, y) = (i as f32 / n as f32, j as f32 / n as f32);
                let z = 0.02 * (TAU * 1.5 * x).sin() * (TAU * 1.2 * y).cos();
                part.positions.push(Vec3::new(x, y, z));
            }
        }
        for j in 0..n {
            for i in 0..n {
                let a = j * (n + 1) + i;
                part.triangles.push([a, a + 1, a + n + 2]);
                part.triangles.push([a, a + n + 2, a + n + 1]);
            }
        }
        part
    }

    /// Texel centres claimed twice over all pages, and triangles without UV area.
    fn overlaps_and_flat(scene: &Scene, atlas: &Atlas) -> (u64, usize) {
        let uv = |t: u32| atlas.triangle_uv(scene, t);
        let overlapping = (0..atlas.pages.len() as u32)
            .map(|page| {
                let on_page = (0..scene.triangles.len() as u32)
                    .map(uv)
                    .filter(|&(_, p)| p == page)
                    .map(|(uv, _)| uv);
                Overlaps::find(atlas.pages[page as usize], on_page).overlapping
            })
            .sum();
        let flat = (0..scene.triangles.len() as u32)
            .filter(|&t| {
                let ([a, b, c], _) = uv(t);
                (b - a).perp_dot(c - a) == 0.0
            })
            .count();
        (overlapping, flat)
    }

    /// Texel area over world area × tpu², whole atlas.
    fn texel_area_ratio(scene: &Scene, atlas: &Atlas) -> f64 {
        let (mut texels, mut world) = (0.0, 0.0);
        for t in 0..scene.triangles.len() as u32 {
            let ([a, b, c], page) = atlas.triangle_uv(scene, t);
            let size = atlas.pages[page as usize];
            texels += 0.5
                * f64::from((b - a).perp_dot(c - a).abs())
                * f64::from(size.width * size.height);
            let [p, q, r] = scene.triangles[t as usize].map(|v| scene.positions[v as usize]);
            world += 0.5 * f64::from((q - p).cross(r - p).length());
        }
        texels / (world * f64::from(atlas.texels_per_unit).powi(2))
    }

    #[test]
    fn a_dense_wavy_field_is_charted_in_smooth_patches() {
        // 80 000 triangles of 0.003 texel² at 16 texels per unit.
        let scene = scene_of(&[wavy(200)], &[]);
        let (regions, rest) =
            smooth_regions(&scene, 0, 16.0, limits(), &BTreeSet::new(), false).unwrap();
        assert!(rest.is_empty(), "{} triangles left to xatlas", rest.len());
        assert!(regions.len() < 30, "{} patches", regions.len());
        let atlas = unwrap(&scene, &source(), &params(16.0, 1024)).unwrap();
        atlas.validate(&scene);
        assert_eq!(overlaps_and_flat(&scene, &atlas), (0, 0));
        // Each patch at exactly tpu; xatlas only rounds a chart's extents up to whole texels.
        let ratio = texel_area_ratio(&scene, &atlas);
        assert!(
            (0.99..1.1).contains(&ratio),
            "texel area / expected = {ratio}"
        );
        // The same bytes again, and on one thread.
        let again = unwrap(&scene, &source(), &params(16.0, 1024)).unwrap();
        assert!(again.layout_bits() == atlas.layout_bits());
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let single = one.install(|| unwrap(&scene, &source(), &params(16.0, 1024)).unwrap());
        assert!(single.layout_bits() == atlas.layout_bits());
    }

    #[test]
    fn coarse_or_small_meshes_are_not_dense() {
        let sphere = scene_of(&[sphere(Vec3::ZERO, 1.0, 48, 48)], &[]);
        assert!(smooth_regions(&sphere, 0, 16.0, limits(), &BTreeSet::new(), false).is_none());
        let small = scene_of(&[wavy(40)], &[]);
        assert!(small.triangles.len() < MIN_TRIANGLES);
        assert!(smooth_regions(&small, 0, 16.0, limits(), &BTreeSet::new(), false).is_none());
    }

    #[test]
    fn a_patch_that_folds_over_itself_goes_to_xatlas() {
        // Two turns of a spiral ramp 0.2 m a turn: every normal within 7° of +z, but the
        // projection lays the second turn onto the first.
        let (rings, steps) = (8u32, 512u32);
        let mut ramp = Part::default();
        for s in 0..=steps {
            let a = 2.0 * TAU * s as f32 / steps as f32;
            for r in 0..=rings {
                let radius = 0.3 + 0.7 * r as f32 / rings as f32;
                let p = Vec2::from_angle(a) * radius;
                ramp.positions.push(p.extend(0.2 * a / TAU));
            }
        }
        for s in 0..steps {
            for r in 0..rings {
                let a = s * (rings + 1) + r;
                let b = a + rings + 1;
                ramp.triangles.push([a, b, b + 1]);
                ramp.triangles.push([a, b + 1, a + 1]);
            }
        }
        let scene = scene_of(&[ramp], &[]);
        let (regions, rest) =
            smooth_regions(&scene, 0, 8.0, limits(), &BTreeSet::new(), false).unwrap();
        assert!(!rest.is_empty(), "{} patches", regions.len());
        let atlas = unwrap(&scene, &source(), &params(8.0, 1024)).unwrap();
        atlas.validate(&scene);
        assert_eq!(overlaps_and_flat(&scene, &atlas).0, 0);
    }
}
