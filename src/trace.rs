//! Stage 4 — `Tracer`: an obvhs wide BVH (CWBVH) over every scene triangle, with closest-hit
//! and occlusion queries.
//!
//! A double-sided primitive's flipped back-face copy is not put in the BVH twice: a ray that
//! hits the front triangle from behind is reported as a hit on the back copy's triangle, so the
//! hit lands in the texels of the face the ray actually sees.
//!
//! obvhs' CWBVH node test ignores `Ray::tmin` and clamps entry distances to 1e-4, so hits closer
//! than that are lost. Ray origins are therefore offset by [`Tracer::epsilon`], a scale-aware
//! distance well above 1e-4 scene units.
//!
//! ## Speed
//!
//! Closest hits run obvhs' `traverse!` macro directly, keeping the best hit's barycentric
//! numerators (no second triangle test); occlusion stops at the first hit. Triangles are packed
//! to 36 bytes in BVH order (traversal of large scenes stalls on loading them), and the
//! traversal is compiled twice: for the baseline target and for x86-64-v3 (AVX2, BMI, LZCNT,
//! POPCNT), chosen at run time — bit-identical results, the v3 build 0–25% faster (hall
//! closest hits +7%, hall occlusion +15%).
//! `LIGHTBAKE_TRACE_ISA=baseline` forces the portable build.
//!
//! `cargo run --release --example ray_throughput`, incoherent rays (cosine-distributed from
//! random surface points; occlusion between two random surface points), Mrays per CPU-second,
//! 2 threads, before → after this module's tuning (own traversal loop, 36-byte triangles,
//! x86-64-v3 variant), old and new binaries interleaved in one session on a shared 2-core Xeon,
//! with the box padding at epsilon/16 (see below; it affected occlusion, not closest hits):
//!
//! | scene (triangles)    | closest hit  |
//! |----------------------|--------------|
//! | Cornell box (242)    | 3.37 → 3.60  |
//! | large hall (116 528) | 1.83 → 2.03  |
//!
//! With the full-epsilon padding restored, a later quiet run measured 3.77 and 2.20 closest,
//! 3.88 and 0.64 occlusion (Cornell, hall; Mrays per CPU-second).
//!
//! The hall's occlusion rays are slow because BVH boxes are padded by the full ray epsilon: a
//! ray between two floor points, lifted by epsilon, enters every floor leaf on its way. Padding
//! by epsilon/16 made them 4× faster but let rays out of a closed box (mean escape 4·10⁻⁵ per
//! ray in the furnace, a 0.8% error at ρ = 0.99; `closed_box_lets_no_ray_out` in
//! `tests/form_factors.rs`), so the full epsilon stays.

use std::time::Duration;

use glam::{UVec2, Vec2, Vec3, Vec3A};
use obvhs::{
    Boundable, BvhBuildParams,
    aabb::Aabb,
    cwbvh::{CwBvh, builder::build_cwbvh},
    ray::Ray,
    rt_triangle::RtTriangle,
    traverse,
    triangle::Triangle,
};

use crate::scene::{MAX_COORDINATE, Scene};

/// A triangle whose bounding box is padded: CWBVH nodes quantise child boxes relative to the
/// parent's extent, and a scene that is flat along an axis (a single floor) has zero extent
/// there, which made every ray miss. Padding by the ray epsilon keeps boxes non-degenerate
/// (and closed boxes closed: see the module docs).
struct Padded(Triangle, f32);

impl Boundable for Padded {
    fn aabb(&self) -> Aabb {
        let b = self.0.aabb();
        Aabb {
            min: b.min - Vec3A::splat(self.1),
            max: b.max + Vec3A::splat(self.1),
        }
    }
}

/// The smallest ray epsilon: 4× obvhs' fixed 1e-4 entry clamp.
pub(crate) const MIN_EPSILON: f32 = 4e-4;

/// The ray epsilon of geometry within `lo..hi`: 1e-5 of its size or of its largest coordinate
/// (f32 positions lose precision with both), never below [`MIN_EPSILON`].
pub(crate) fn epsilon_of(lo: Vec3, hi: Vec3) -> f32 {
    let extent = (hi - lo)
        .max_element()
        .max(hi.abs().max(lo.abs()).max_element())
        .min(2.0 * MAX_COORDINATE);
    (extent * 1e-5).max(MIN_EPSILON)
}

/// An obvhs ray. Adding +0.0 turns −0.0 direction components into +0.0: obvhs derives the
/// traversal octant from the sign bits, and a −0.0 component (as in `-Vec3::Y`) made rays
/// straight along an axis miss everything (found by `tests::axis_aligned_rays_hit`).
#[inline]
fn make_ray(origin: Vec3, dir: Vec3, tmax: f32) -> Ray {
    Ray::new(origin.into(), Vec3A::from(dir) + Vec3A::ZERO, 0.0, tmax)
}

/// Barycentric slack of [`intersect`]: a ray through an edge shared by two triangles must hit
/// one of them.
const EDGE_SLACK: f32 = 1e-6;

/// Ray–triangle distance (Möller–Trumbore in obvhs' `RtTriangle` layout), or infinity.
/// obvhs' own test rejects −0.0 barycentrics by their sign bit, so a ray through the exact
/// shared edge of two triangles (a floor grid hit at a grid line) missed both: light leaked
/// through seams (`tests::rays_through_shared_edges_hit`). Here edges get a little slack.
#[inline(always)]
fn intersect(tri: &Tri, ray: &Ray) -> f32 {
    intersect_full(tri, ray).0
}

/// A triangle packed for intersection: obvhs' `RtTriangle` (`v0`, `e1 = v0 − v1`,
/// `e2 = v2 − v0`) without its stored normal, 36 bytes instead of 64. Traversal of the 116k-
/// triangle hall stalled on loading triangles; the normal `e1 × e2` is recomputed per test,
/// bit for bit as `RtTriangle::new` computes it.
#[derive(Clone, Copy)]
struct Tri([f32; 9]);

impl Tri {
    fn new(t: &RtTriangle) -> Tri {
        Tri([
            t.v0.x, t.v0.y, t.v0.z, t.e1.x, t.e1.y, t.e1.z, t.e2.x, t.e2.y, t.e2.z,
        ])
    }
}

/// [`intersect`] that also returns the unscaled barycentric numerators `(r·e2, r·e1)` and the
/// determinant, so the closest hit's barycentrics need no second ray–triangle computation:
/// `(r·e2, r·e1) / det` is bit for bit `RtTriangle::compute_barycentric`.
#[inline(always)]
fn intersect_full(tri: &Tri, ray: &Ray) -> (f32, Vec2, f32) {
    let v = &tri.0;
    let v0 = Vec3A::new(v[0], v[1], v[2]);
    let e1 = Vec3A::new(v[3], v[4], v[5]);
    let e2 = Vec3A::new(v[6], v[7], v[8]);
    let ng = e1.cross(e2);
    let c = v0 - ray.origin;
    let r = ray.direction.cross(c);
    let det = ng.dot(ray.direction);
    if det == 0.0 {
        return (f32::INFINITY, Vec2::ZERO, det);
    }
    let inv_det = 1.0 / det;
    let (a, b) = (r.dot(e2), r.dot(e1));
    let u = a * inv_det;
    let v = b * inv_det;
    let w = 1.0 - u - v;
    if u >= -EDGE_SLACK && v >= -EDGE_SLACK && w >= -EDGE_SLACK {
        let t = ng.dot(c) * inv_det;
        if t >= ray.tmin && t <= ray.tmax {
            return (t, Vec2::new(a, b), det);
        }
    }
    (f32::INFINITY, Vec2::ZERO, det)
}

/// Scene triangles of a BVH triangle, side by side so a hit costs one cache line.
#[derive(Clone, Copy)]
struct Prim {
    /// Scene triangle (front face).
    front: u32,
    /// Its back-face copy, or `u32::MAX`.
    back: u32,
}

/// A ray hit on a scene triangle.
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    /// Scene triangle of the face that was hit (the back-face copy when a double-sided
    /// surface was hit from behind).
    pub triangle: u32,
    pub(crate) t: f32,
    /// Barycentrics (u, v) on `triangle`: `p = (1−u−v)·p0 + u·p1 + v·p2`.
    pub bary: Vec2,
    /// The ray hit the side the triangle's normal points to. False only for single-sided
    /// surfaces seen from behind (inside closed geometry, under a floor).
    pub(crate) front: bool,
}

/// Ray queries against the scene.
pub struct Tracer {
    bvh: CwBvh,
    /// Triangles in BVH order.
    triangles: Vec<Tri>,
    /// Scene triangles of each BVH triangle.
    prims: Vec<Prim>,
    /// Scale-aware self-intersection offset (world units).
    pub epsilon: f32,
    /// Traverse with the x86-64-v3 build of the traversal ([`wide_isa`]).
    wide_isa: bool,
}

impl Tracer {
    /// Builds the BVH over the scene's triangles (front faces only; see the module docs).
    pub fn new(scene: &Scene) -> Tracer {
        Tracer::without(scene, &[])
    }

    /// [`Tracer::new`] with the instances `absent` (ascending; a front instance takes its
    /// back-face copy with it) left out of the BVH: a scene whose triangle and texel ids stay
    /// those of a layout that held them (an incremental bake after a removal).
    pub(crate) fn without(scene: &Scene, absent: &[usize]) -> Tracer {
        let mut back_copy = vec![u32::MAX; scene.triangles.len()];
        let mut ids = Vec::with_capacity(scene.triangles.len());
        for (k, inst) in scene.instances.iter().enumerate() {
            if inst.back_of.is_some() || absent.binary_search(&k).is_ok() {
                continue;
            }
            if let Some(b) = inst.back {
                let back = &scene.instances[b as usize];
                for (t, tb) in inst.triangles.clone().zip(back.triangles.clone()) {
                    back_copy[t as usize] = tb;
                }
            }
            ids.extend(inst.triangles.clone());
        }
        // The loader refuses coordinates beyond `MAX_COORDINATE`; a scene built by hand may
        // still hold them, and obvhs' builder panics on them: such triangles stay out of the BVH.
        let in_range = |v: &u32| scene.positions[*v as usize].abs().max_element() <= MAX_COORDINATE;
        ids.retain(|&t| scene.triangles[t as usize].iter().all(in_range));
        let tri = |t: u32| {
            let [a, b, c] = scene.triangles[t as usize];
            let p = |v: u32| Vec3A::from(scene.positions[v as usize]);
            Triangle {
                v0: p(a),
                v1: p(b),
                v2: p(c),
            }
        };
        let tris: Vec<Triangle> = ids.iter().map(|&t| tri(t)).collect();

        let epsilon = if scene.positions.is_empty() {
            MIN_EPSILON
        } else {
            let (lo, hi) = scene.bounds();
            epsilon_of(lo, hi)
        };

        if tris.is_empty() {
            return Tracer {
                bvh: CwBvh::default(),
                triangles: vec![],
                prims: vec![],
                epsilon,
                wide_isa: false,
            };
        }
        let mut build_time = Duration::ZERO;
        // Boxes are padded by the full ray epsilon. A sixteenth of it made occlusion rays that
        // graze a floor at the epsilon height 4x faster in `large_hall`, but let 4 rays in
        // 100 000 out of a closed box (`tests::closed_box_lets_no_ray_out`).
        let padded: Vec<Padded> = tris.iter().map(|t| Padded(*t, epsilon)).collect();
        let bvh = build_cwbvh(&padded, BvhBuildParams::medium_build(), &mut build_time);
        let triangles = bvh
            .primitive_indices
            .iter()
            .map(|&i| Tri::new(&RtTriangle::from(&tris[i as usize])))
            .collect();
        let prims = bvh
            .primitive_indices
            .iter()
            .map(|&i| {
                let front = ids[i as usize];
                Prim {
                    front,
                    back: back_copy[front as usize],
                }
            })
            .collect();
        Tracer {
            bvh,
            triangles,
            prims,
            epsilon,
            wide_isa: wide_isa(),
        }
    }

    /// Number of triangles in the BVH.
    pub fn len(&self) -> usize {
        self.triangles.len()
    }
    /// No triangles.
    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    /// Closest hit along `dir` (unit) from `origin`, up to `tmax`. The caller offsets the origin.
    #[inline]
    pub fn closest(&self, origin: Vec3, dir: Vec3, tmax: f32) -> Option<Hit> {
        if self.triangles.is_empty() {
            return None;
        }
        self.traverse(Closest { cull_back: &[] }, make_ray(origin, dir, tmax))
    }

    /// [`Tracer::closest`] for a viewer: a ray that meets single-sided triangle `t` from behind
    /// passes through it when `cull_back[t]` (indexed by scene triangle), as a rasteriser culls
    /// back faces. Triangles with a back-face copy are never culled (a hit from behind lands on
    /// the copy, seen from its front).
    #[inline]
    pub(crate) fn closest_culling(
        &self,
        origin: Vec3,
        dir: Vec3,
        tmax: f32,
        cull_back: &[bool],
    ) -> Option<Hit> {
        if self.triangles.is_empty() {
            return None;
        }
        self.traverse(Closest { cull_back }, make_ray(origin, dir, tmax))
    }

    /// Runs the traversal `T` on `ray`, compiled for x86-64-v3 when this CPU has it (see the
    /// module docs).
    #[inline(always)]
    fn traverse<T: Traversal>(&self, traversal: T, ray: Ray) -> T::Output {
        #[cfg(target_arch = "x86_64")]
        if self.wide_isa {
            // SAFETY: `Tracer::new` checked that this CPU has the enabled features.
            return unsafe { self.traverse_x86_64_v3(traversal, ray) };
        }
        traversal.run(self, ray)
    }

    /// [`Tracer::traverse`] compiled for x86-64-v3 (`T::run` is inlined here, always).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx,avx2,bmi1,bmi2,lzcnt,popcnt")]
    unsafe fn traverse_x86_64_v3<T: Traversal>(&self, traversal: T, ray: Ray) -> T::Output {
        traversal.run(self, ray)
    }

    #[inline(always)]
    fn closest_ray(&self, mut ray: Ray, cull_back: &[bool]) -> Option<Hit> {
        // obvhs' `ray_traverse`, written out so the hit keeps its barycentric numerators and
        // determinant (no second triangle test for the barycentrics).
        let tmax = ray.tmax;
        let (mut best, mut num, mut det) = (u32::MAX, Vec2::ZERO, 0.0f32);
        let mut state = self.bvh.new_traversal(ray.direction);
        let mut node;
        traverse!(
            self.bvh,
            node,
            state,
            node.intersect_ray(&ray, state.oct_inv4),
            {
                let id = state.primitive_id;
                let (t, n, d) = intersect_full(&self.triangles[id as usize], &ray);
                if t < ray.tmax && !(d < 0.0 && self.culled(id, cull_back)) {
                    (best, num, det) = (id, n, d);
                    ray.tmax = t;
                }
            }
        );
        if best == u32::MAX || ray.tmax >= tmax {
            return None;
        }
        let bary = num / det;
        // RtTriangle::ng = (v0 − v1) × (v2 − v0) points against the front normal.
        let front = det > 0.0;
        let prim = self.prims[best as usize];
        let (triangle, front_seen) = if front || prim.back == u32::MAX {
            (prim.front, front)
        } else {
            (prim.back, true)
        };
        Some(Hit {
            triangle,
            t: ray.tmax,
            bary,
            front: front_seen,
        })
    }

    /// BVH triangle `id` is single-sided and `cull_back` culls its back face.
    #[inline(always)]
    fn culled(&self, id: u32, cull_back: &[bool]) -> bool {
        !cull_back.is_empty() && {
            let prim = self.prims[id as usize];
            prim.back == u32::MAX && cull_back[prim.front as usize]
        }
    }

    /// True when the ray hits anything (stops at the first hit found).
    #[inline]
    fn any_hit(&self, ray: Ray) -> bool {
        self.traverse(AnyHit, ray)
    }

    /// obvhs' `ray_traverse_miss` (negated), written out so it inlines into both variants.
    #[inline(always)]
    fn any_hit_ray(&self, ray: Ray) -> bool {
        let mut state = self.bvh.new_traversal(ray.direction);
        let mut node;
        let mut hit = false;
        'found: {
            traverse!(
                self.bvh,
                node,
                state,
                node.intersect_ray(&ray, state.oct_inv4),
                {
                    if intersect(&self.triangles[state.primitive_id as usize], &ray) < ray.tmax {
                        hit = true;
                        break 'found;
                    }
                }
            );
        }
        hit
    }

    /// True when something blocks the open segment from `a` to `b` (both already offset by the
    /// caller; the last `epsilon` before `b` is not tested so `b`'s own surface does not count).
    #[inline]
    pub fn occluded(&self, a: Vec3, b: Vec3) -> bool {
        if self.triangles.is_empty() {
            return false;
        }
        let d = b - a;
        let len = d.length();
        if len <= self.epsilon {
            return false;
        }
        self.any_hit(make_ray(a, d / len, len - self.epsilon))
    }

    /// True when the ray from `origin` along unit `dir` hits nothing (escapes to the sky).
    #[inline]
    pub(crate) fn escapes(&self, origin: Vec3, dir: Vec3, tmax: f32) -> bool {
        if self.triangles.is_empty() {
            return true;
        }
        !self.any_hit(make_ray(origin, dir, tmax))
    }
}

/// A BVH traversal, compiled twice by [`Tracer::traverse`]. A static `#[inline(always)]` call,
/// unlike a closure, is inlined into the x86-64-v3 build whatever the traversal's size.
trait Traversal {
    type Output;
    fn run(self, tracer: &Tracer, ray: Ray) -> Self::Output;
}

/// [`Tracer::closest_ray`]; back faces culled as [`Tracer::closest_culling`] says (none when
/// `cull_back` is empty).
struct Closest<'a> {
    cull_back: &'a [bool],
}

impl Traversal for Closest<'_> {
    type Output = Option<Hit>;
    #[inline(always)]
    fn run(self, tracer: &Tracer, ray: Ray) -> Option<Hit> {
        tracer.closest_ray(ray, self.cull_back)
    }
}

/// [`Tracer::any_hit_ray`].
struct AnyHit;

impl Traversal for AnyHit {
    type Output = bool;
    #[inline(always)]
    fn run(self, tracer: &Tracer, ray: Ray) -> bool {
        tracer.any_hit_ray(ray)
    }
}

/// Whether this CPU runs the x86-64-v3 traversal (AVX2, BMI1/2, LZCNT, POPCNT).
/// `LIGHTBAKE_TRACE_ISA=baseline` forces the portable one (for comparisons).
fn wide_isa() -> bool {
    if std::env::var("LIGHTBAKE_TRACE_ISA").as_deref() == Ok("baseline") {
        return false;
    }
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("bmi1")
            && std::arch::is_x86_feature_detected!("bmi2")
            && std::arch::is_x86_feature_detected!("lzcnt")
            && std::arch::is_x86_feature_detected!("popcnt")
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Instance, Material};

    /// One triangle in the z = 0 plane facing +z; optionally double-sided (with a back copy).
    fn scene(double_sided: bool) -> Scene {
        let p = [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
        ];
        let mut s = Scene::default();
        let mut add = |normal: Vec3, tri: [u32; 3], back_of: Option<u32>| {
            let base = s.positions.len() as u32;
            s.positions.extend(p);
            s.normals.extend([normal; 3]);
            s.uv0.extend([Vec2::ZERO; 3]);
            s.uv1.extend([Vec2::ZERO; 3]);
            let t = s.triangles.len() as u32;
            s.triangles.push(tri.map(|v| v + base));
            s.triangle_instance.push(s.instances.len() as u32);
            s.instances.push(Instance {
                node: 0,
                mesh: 0,
                primitive: 0,
                material: 0,
                vertices: base..base + 3,
                triangles: t..t + 1,
                source_triangle: vec![0],
                back_of,
                back: None,
                has_uv1: false,
                lightmap: None,
                directional: None,
                split: Default::default(),
            });
        };
        add(Vec3::Z, [0, 1, 2], None);
        if double_sided {
            add(-Vec3::Z, [0, 2, 1], Some(0));
            s.instances[0].back = Some(1);
        }
        s.materials.push(Material::default());
        s
    }

    #[test]
    fn barycentrics_reconstruct_the_hit_point() {
        let s = scene(false);
        let tracer = Tracer::new(&s);
        let hit = tracer
            .closest(Vec3::new(0.2, 0.3, 1.0), -Vec3::Z, f32::INFINITY)
            .unwrap();
        assert!((hit.t - 1.0).abs() < 1e-5);
        // p = (1−u−v)·p0 + u·p1 + v·p2 with p1 = +x, p2 = +y.
        assert!(
            (hit.bary - Vec2::new(0.2, 0.3)).length() < 1e-5,
            "{}",
            hit.bary
        );
        assert!(hit.front && hit.triangle == 0);
    }

    #[test]
    fn back_hits_map_to_the_back_copy_or_report_the_back() {
        let single = Tracer::new(&scene(false));
        let hit = single
            .closest(Vec3::new(0.2, 0.3, -1.0), Vec3::Z, f32::INFINITY)
            .unwrap();
        assert!(!hit.front && hit.triangle == 0);

        let double = Tracer::new(&scene(true));
        assert_eq!(double.len(), 1, "the back copy must not be traced twice");
        let hit = double
            .closest(Vec3::new(0.2, 0.3, -1.0), Vec3::Z, f32::INFINITY)
            .unwrap();
        assert!(hit.front && hit.triangle == 1);
    }

    #[test]
    fn culled_back_faces_are_passed_through() {
        let from_front = (Vec3::new(0.2, 0.3, 1.0), -Vec3::Z);
        let from_behind = (Vec3::new(0.2, 0.3, -1.0), Vec3::Z);
        let closest = |tracer: &Tracer, (o, d): (Vec3, Vec3), cull: &[bool]| {
            tracer
                .closest_culling(o, d, f32::INFINITY, cull)
                .map(|hit| (hit.triangle, hit.front))
        };
        let single = Tracer::new(&scene(false));
        assert_eq!(closest(&single, from_behind, &[true]), None);
        assert_eq!(closest(&single, from_behind, &[false]), Some((0, false)));
        assert_eq!(closest(&single, from_front, &[true]), Some((0, true)));

        // A linked back copy is never culled: the hit from behind lands on it.
        let linked = Tracer::new(&scene(true));
        assert_eq!(closest(&linked, from_behind, &[true; 2]), Some((1, true)));

        // Two unlinked single-sided triangles back to back (a baked double-sided wall): each
        // side sees its own, whichever of the coplanar pair the traversal meets first.
        let mut s = scene(true);
        s.instances[0].back = None;
        s.instances[1].back_of = None;
        let split = Tracer::new(&s);
        assert_eq!(split.len(), 2);
        assert_eq!(closest(&split, from_front, &[true; 2]), Some((0, true)));
        assert_eq!(closest(&split, from_behind, &[true; 2]), Some((1, true)));
    }

    #[test]
    fn occlusion_and_escape() {
        let tracer = Tracer::new(&scene(false));
        assert!(tracer.occluded(Vec3::new(0.2, 0.2, 1.0), Vec3::new(0.2, 0.2, -1.0)));
        assert!(!tracer.occluded(Vec3::new(2.0, 2.0, 1.0), Vec3::new(2.0, 2.0, -1.0)));
        assert!(!tracer.escapes(Vec3::new(0.2, 0.2, 1.0), -Vec3::Z, f32::INFINITY));
        assert!(tracer.escapes(Vec3::new(0.2, 0.2, 1.0), Vec3::Z, f32::INFINITY));
    }

    #[test]
    fn rays_through_shared_edges_hit() {
        // A 2 × 2 grid of quads (8 triangles) on z = 0; rays straight down onto every grid
        // line and vertex, and onto the diagonals.
        let mut s = Scene::default();
        for i in 0..3 {
            for j in 0..3 {
                s.positions
                    .push(Vec3::new(i as f32 * 0.5, j as f32 * 0.5, 0.0));
            }
        }
        let n = s.positions.len() as u32;
        s.normals = vec![Vec3::Z; n as usize];
        s.uv0 = vec![Vec2::ZERO; n as usize];
        s.uv1 = vec![Vec2::ZERO; n as usize];
        for i in 0..2u32 {
            for j in 0..2u32 {
                let v = |a: u32, b: u32| (i + a) * 3 + j + b;
                s.triangles.push([v(0, 0), v(1, 0), v(1, 1)]);
                s.triangles.push([v(0, 0), v(1, 1), v(0, 1)]);
            }
        }
        s.triangle_instance = vec![0; 8];
        s.instances.push(Instance {
            node: 0,
            mesh: 0,
            primitive: 0,
            material: 0,
            vertices: 0..n,
            triangles: 0..8,
            source_triangle: (0..8).collect(),
            back_of: None,
            back: None,
            has_uv1: false,
            lightmap: None,
            directional: None,
            split: Default::default(),
        });
        s.materials.push(Material::default());
        let tracer = Tracer::new(&s);
        let mut missed = Vec::new();
        for eye in [
            Vec3::new(0.5, 0.5, 1.0),
            Vec3::new(-0.7, 0.3, 1.3),
            Vec3::new(1.9, -0.4, 0.6),
        ] {
            // Interior points only: the outer border is an edge of a single triangle.
            for k in 1..16 {
                for l in 1..16 {
                    let target = Vec3::new(k as f32 / 16.0, l as f32 / 16.0, 0.0);
                    let dir = (target - eye).normalize();
                    if tracer.closest(eye, dir, f32::INFINITY).is_none()
                        || !tracer.occluded(eye, target + dir)
                    {
                        missed.push(target);
                    }
                }
            }
        }
        assert!(
            missed.is_empty(),
            "{} rays got through, first at {:?}",
            missed.len(),
            missed.first()
        );
    }

    #[test]
    fn axis_aligned_rays_hit() {
        let tracer = Tracer::new(&scene(false));
        for dir in [-Vec3::Z, Vec3::new(-0.0, -0.0, -1.0)] {
            assert!(
                tracer
                    .closest(Vec3::new(0.2, 0.3, 1.0), dir, f32::INFINITY)
                    .is_some()
            );
        }
    }

    #[test]
    fn epsilon_stays_above_the_bvh_clamp_for_tiny_scenes() {
        let mut s = scene(false);
        for p in &mut s.positions {
            *p *= 1e-3;
        }
        assert!(Tracer::new(&s).epsilon >= 4e-4);
    }
}
