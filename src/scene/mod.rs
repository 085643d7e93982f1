//! Stage 1 — `Scene`: the glTF input resolved into world-space triangles, materials, lights and
//! cameras.
//!
//! The loader ([`load`]) resolves every input quirk (node transforms, instancing, strips and fans,
//! missing normals, emissive strength, sRGB textures, double-sided materials) so later stages never
//! look at glTF. It resolves what the renderer needs too — each material's specular parameters
//! (`Surface`), each instance's lightmap page (`extras.lightmap` of a baked file; on the node
//! for a mesh baked with `--instancing share`, whose `scale_offset` rect is applied to the
//! instance's `TEXCOORD_1`) and the document's cameras — so `render` never reads glTF either. It also keeps the untouched input
//! document ([`Source`]) for the output writer.
//!
//! Double-sided surfaces: each face of a `doubleSided` primitive receives its own light (a wall
//! between a lit and a dark room), so the loader emits a second, flipped instance (`back_of`) with
//! reversed winding and negated normals. It gets its own lightmap charts and is written to the
//! output glTF as an extra single-sided primitive.

mod camera;
mod geometry;
mod gltf_in;
pub mod junctions;
pub(crate) mod shadow_cuts;

use std::ops::Range;
use std::path::PathBuf;

use glam::{Vec2, Vec3};

pub use camera::{Camera, GltfCamera, select};
pub use gltf_in::{external_files, load};
pub(crate) use gltf_in::{load_edited, read_document};

/// Reflectance is clamped to this: ρ = 1 (glTF's default white) in a closed room would make
/// the radiosity series diverge; 0.99 keeps it convergent (about 100 bounces carry the light).
pub const MAX_ALBEDO: f32 = 0.99;

/// Largest world coordinate magnitude the loader accepts (units). Real scenes stay far below
/// it; beyond it lies damaged data (a flipped exponent bit), which the BVH cannot take.
pub(crate) const MAX_COORDINATE: f32 = 1e7;

/// The keys of a baked primitive's `extras.lightmap.directional`: its directional pages'
/// coefficients (`lightmap::directional`), in storage order.
pub(crate) const DIRECTIONAL_PAGES: [&str; 4] = ["L0", "L1x", "L1y", "L1z"];

/// World-space geometry, materials and lights of the default scene.
#[derive(Clone, Debug, Default)]
pub struct Scene {
    /// World-space vertex positions of all instances, concatenated.
    pub positions: Vec<Vec3>,
    /// World-space unit normals, per vertex (generated from faces when the input has none).
    pub(crate) normals: Vec<Vec3>,
    /// `TEXCOORD_0` per vertex (zero when the primitive has none).
    pub(crate) uv0: Vec<Vec2>,
    /// The input's `TEXCOORD_1` per vertex (zero when the primitive has none).
    pub uv1: Vec<Vec2>,
    /// Triangles as global vertex indices, counter-clockwise seen from the front face.
    pub triangles: Vec<[u32; 3]>,
    /// Instance of each triangle.
    pub triangle_instance: Vec<u32>,
    /// One per baked (node, primitive) pair, plus one per back face of a double-sided primitive.
    pub instances: Vec<Instance>,
    /// The document's materials, resolved.
    pub materials: Vec<Material>,
    pub(crate) textures: Vec<Texture>,
    /// Punctual lights (`KHR_lights_punctual`), placed in world space.
    pub lights: Vec<Light>,
    /// Every perspective camera placed by a node of the scene, in node traversal order.
    pub cameras: Vec<GltfCamera>,
    /// Every node of the loaded scene, in traversal order: its name, world transform and
    /// children (for probes placed by a node, `probes::ProbeParams::from`).
    pub nodes: Vec<SceneNode>,
    /// Counts of what the loader skipped or changed (the CLI reports them).
    pub stats: LoadStats,
}

/// A node of the loaded scene.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneNode {
    /// The glTF node index.
    pub index: u32,
    /// The node's name (`None` without one).
    pub name: Option<String>,
    /// Its world transform (the parents' composed with its own).
    pub world: glam::Mat4,
    /// Its children's glTF node indices, in document order.
    pub children: Vec<u32>,
}

/// One baked primitive placed by one node.
#[derive(Clone, Debug)]
pub struct Instance {
    /// glTF node, mesh and primitive (within the mesh) indices.
    pub node: u32,
    pub(crate) mesh: u32,
    /// The glTF primitive index within the mesh (see `node`).
    pub primitive: u32,
    /// Index into [`Scene::materials`].
    pub(crate) material: u32,
    /// Global vertex range; local vertex `k` (= element `k` of the primitive's attribute
    /// accessors) is global vertex `vertices.start + k`.
    pub(crate) vertices: Range<u32>,
    /// Global triangle range of this instance.
    pub triangles: Range<u32>,
    /// For each triangle of the instance, its index in the primitive's own triangle list (after
    /// converting strips and fans); degenerate triangles are skipped, so this may have gaps.
    pub(crate) source_triangle: Vec<u32>,
    /// Set on the flipped back-face copy of a double-sided primitive: the front instance.
    pub(crate) back_of: Option<u32>,
    /// Set on the front instance of a double-sided primitive: its back-face copy.
    pub(crate) back: Option<u32>,
    /// The primitive has a `TEXCOORD_1` of its own.
    pub(crate) has_uv1: bool,
    /// The EXR page named by the primitive's `extras.lightmap.exr`, or the node's when it has
    /// one (a shared mesh; `uv1` then holds the node's page UVs), resolved against the glTF
    /// file's folder, for the renderer.
    pub lightmap: Option<PathBuf>,
    /// The directional pages named by `extras.lightmap.directional` (L0, L1x, L1y, L1z:
    /// `lightmap::directional`), resolved like `lightmap`.
    pub(crate) directional: Option<[PathBuf; 4]>,
    /// What [`junctions::split`] changed (empty for the input as loaded).
    pub split: Split,
}

/// How [`junctions::split`] cut an instance where other surfaces meet it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Split {
    /// The vertices it added, at the end of the instance's vertex range: local vertex
    /// `source_vertices + k` is `blends[k]`, where `source_vertices` is the range's length less
    /// `blends.len()`.
    pub blends: Vec<Blend>,
    /// Per triangle (empty when unsplit): triangles of different sides never share a chart,
    /// so the lightmap charts end where another surface meets this one.
    pub(crate) sides: Vec<u32>,
    /// Per triangle (empty when unsplit): bit `k` is set when edge `k` (corner `k` to `k + 1`)
    /// lies on a junction. The two sides of a junction see different light, so such an edge is
    /// never stitched as a seam.
    pub(crate) junction_edges: Vec<u8>,
}

/// A vertex blended from up to three source vertices (accessor elements) of its primitive:
/// `Σ weights[i] · element[vertices[i]]` (unused slots have weight 0).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Blend {
    pub(crate) vertices: [u32; 3],
    pub(crate) weights: [f32; 3],
}

/// A material as the light transport sees it (linear RGB).
#[derive(Clone, Debug)]
pub struct Material {
    pub(crate) name: Option<String>,
    /// glTF material index (`None` for the default material).
    pub(crate) source: Option<u32>,
    /// `baseColorFactor.rgb` (linear); multiplied by the texture where there is one.
    pub(crate) base_color: Vec3,
    /// Index into [`Scene::textures`], sampled through `TEXCOORD_0`.
    pub(crate) base_color_texture: Option<u32>,
    /// Emitted radiance `Le = emissiveFactor × emissiveStrength` (W/(sr·m²)).
    pub emission: Vec3,
    /// Index into [`Scene::textures`], sampled through `TEXCOORD_0`.
    pub(crate) emissive_texture: Option<u32>,
    /// `normalTexture`: index into [`Scene::textures`] (decoded linear, not sRGB), sampled
    /// through `TEXCOORD_0`; only the renderer reads it.
    pub(crate) normal_texture: Option<u32>,
    /// `normalTexture.scale`: scales the tangent-space x and y.
    pub(crate) normal_scale: f32,
    pub(crate) double_sided: bool,
    /// What the renderer's specular layer needs; the bake treats every surface as Lambertian.
    pub(crate) surface: Surface,
}

impl Default for Material {
    /// glTF's default material: white, not emissive, single-sided.
    fn default() -> Self {
        Material {
            name: None,
            source: None,
            base_color: Vec3::ONE,
            base_color_texture: None,
            emission: Vec3::ZERO,
            emissive_texture: None,
            normal_texture: None,
            normal_scale: 1.0,
            double_sided: false,
            surface: Surface::default(),
        }
    }
}

/// The specular parameters of a material (glTF metallic-roughness and extensions). Textures of
/// these factors (metallicRoughnessTexture, …) are not sampled.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Surface {
    pub(crate) metallic: f32,
    pub(crate) roughness: f32,
    /// KHR_materials_transmission `transmissionFactor`.
    pub(crate) transmission: f32,
    /// KHR_materials_ior (1.5 by default).
    pub(crate) ior: f32,
    /// KHR_materials_specular `specularFactor` and `specularColorFactor`.
    pub(crate) specular: f32,
    pub(crate) specular_color: Vec3,
    /// Absorption coefficient σ per world unit (KHR_materials_volume), zero when clear.
    pub(crate) attenuation: Vec3,
}

impl Default for Surface {
    /// glTF's defaults: metallic 1, roughness 1 (fully rough, so no specular layer).
    fn default() -> Self {
        Surface {
            metallic: 1.0,
            roughness: 1.0,
            transmission: 0.0,
            ior: 1.5,
            specular: 1.0,
            specular_color: Vec3::ONE,
            attenuation: Vec3::ZERO,
        }
    }
}

/// Texture addressing outside \[0,1\].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Wrap {
    Repeat,
    MirroredRepeat,
    ClampToEdge,
}

/// A decoded texture in linear RGB (sRGB-decoded: both base colour and emissive textures are
/// sRGB in glTF).
#[derive(Clone, Debug)]
pub(crate) struct Texture {
    pub(crate) width: u32,
    pub(crate) height: u32,
    /// Row-major, row 0 at the top (v = 0).
    pub(crate) texels: Vec<Vec3>,
    pub(crate) wrap_s: Wrap,
    pub(crate) wrap_t: Wrap,
}

impl Texture {
    /// Bilinear lookup at `uv` (glTF convention: v grows downward).
    pub(crate) fn sample(&self, uv: Vec2) -> Vec3 {
        let (w, h) = (self.width as i64, self.height as i64);
        let x = uv.x * w as f32 - 0.5;
        let y = uv.y * h as f32 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let fetch = |xi: i64, yi: i64| {
            let xi = wrap(xi, w, self.wrap_s);
            let yi = wrap(yi, h, self.wrap_t);
            self.texels[(yi * w + xi) as usize]
        };
        let (x0, y0) = (x0 as i64, y0 as i64);
        let top = fetch(x0, y0).lerp(fetch(x0 + 1, y0), fx);
        let bottom = fetch(x0, y0 + 1).lerp(fetch(x0 + 1, y0 + 1), fx);
        top.lerp(bottom, fy)
    }
}

fn wrap(i: i64, n: i64, mode: Wrap) -> i64 {
    match mode {
        Wrap::Repeat => i.rem_euclid(n),
        Wrap::ClampToEdge => i.clamp(0, n - 1),
        Wrap::MirroredRepeat => {
            let m = i.rem_euclid(2 * n);
            if m < n { m } else { 2 * n - 1 - m }
        }
    }
}

/// A KHR_lights_punctual light in world space.
#[derive(Clone, Debug)]
pub struct Light {
    pub(crate) name: Option<String>,
    /// Index in the glTF's `KHR_lights_punctual.lights` (`None` for a light made in code).
    pub(crate) source: Option<u32>,
    pub(crate) kind: LightKind,
    /// World position (unused for directional lights).
    pub(crate) position: Vec3,
    /// Unit direction the light travels (the node's −Z; unused for point lights).
    pub direction: Vec3,
    /// `color × intensity`: radiant intensity (W/sr) for point and spot lights, irradiance
    /// (W/m²) on a surface facing the light for directional lights.
    pub(crate) intensity: Vec3,
    /// Distance beyond which the light has no effect (`None` = infinite).
    pub(crate) range: Option<f32>,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum LightKind {
    Point,
    /// Cone angles in radians, as in KHR_lights_punctual.
    Spot {
        inner_cone_angle: f32,
        outer_cone_angle: f32,
    },
    Directional,
}

/// What the loader skipped or changed.
#[derive(Clone, Debug, Default)]
pub struct LoadStats {
    pub(crate) degenerate_triangles: u32,
    pub(crate) skipped_primitives: u32,
    pub(crate) generated_normals: u32,
    /// Human-readable warnings (points and lines skipped, skinned meshes passed through, …).
    pub warnings: Vec<String>,
}

/// The input document as read, for the output writer (which keeps everything it does not change).
#[derive(Clone, Debug)]
pub struct Source {
    pub(crate) path: PathBuf,
    pub(crate) is_glb: bool,
    /// The glTF JSON exactly as parsed (unknown extensions and extras included).
    pub(crate) json: serde_json::Value,
    /// The bytes of every buffer, in document order.
    pub(crate) buffers: Vec<Vec<u8>>,
}

/// A point of a scene triangle, interpolated at a hit's barycentrics.
#[derive(Clone, Copy, Debug)]
pub struct SurfacePoint {
    pub(crate) p: Vec3,
    /// Unit geometric normal of the face (its front side); zero for a degenerate triangle.
    pub(crate) n_geo: Vec3,
    /// Unit interpolated vertex normal, turned to the side of `n_geo`.
    pub(crate) n: Vec3,
    pub(crate) uv0: Vec2,
    pub(crate) uv1: Vec2,
    pub(crate) instance: u32,
    pub(crate) material: u32,
}

impl Scene {
    /// The point of triangle `t` at barycentrics `b` (`p = (1−u−v)·p0 + u·p1 + v·p2`).
    /// World-space area of triangle `t` (in f64: sums over many small triangles stay exact).
    pub(crate) fn triangle_area(&self, t: usize) -> f64 {
        let [a, b, c] = self.triangles[t].map(|v| self.positions[v as usize].as_dvec3());
        0.5 * (b - a).cross(c - a).length()
    }

    /// The surface at barycentrics `b` of triangle `t` (the weights of its second and third vertices): position, normals, texture coordinates.
    pub fn surface_point(&self, t: u32, b: Vec2) -> SurfacePoint {
        let [i0, i1, i2] = self.triangles[t as usize].map(|v| v as usize);
        let w = Vec3::new(1.0 - b.x - b.y, b.x, b.y);
        let lerp3 = |a: &[Vec3]| a[i0] * w.x + a[i1] * w.y + a[i2] * w.z;
        let lerp2 = |a: &[Vec2]| a[i0] * w.x + a[i1] * w.y + a[i2] * w.z;
        let n_geo = (self.positions[i1] - self.positions[i0])
            .cross(self.positions[i2] - self.positions[i0])
            .normalize_or_zero();
        let n = lerp3(&self.normals).normalize_or_zero();
        let instance = self.triangle_instance[t as usize];
        SurfacePoint {
            p: lerp3(&self.positions),
            n_geo,
            n: if n.dot(n_geo) > 0.0 { n } else { n_geo },
            uv0: lerp2(&self.uv0),
            uv1: lerp2(&self.uv1),
            instance,
            material: self.instances[instance as usize].material,
        }
    }

    /// The shading normal at `sp` (a point of triangle `t`): the material's `normalTexture`
    /// applied to the interpolated normal, or that normal when there is none. The tangent
    /// frame is the triangle's own, from its `TEXCOORD_0` derivatives (`∂p/∂u`, `∂p/∂v`,
    /// Gram–Schmidt against the normal, handedness from the UV winding): MikkTSpace's result on
    /// planar, uniformly mapped triangles (the TANGENT attribute is not read). Turned to the
    /// side of the face like `SurfacePoint::n`.
    pub fn shading_normal(&self, t: u32, sp: &SurfacePoint) -> Vec3 {
        let m = &self.materials[sp.material as usize];
        let Some(texture) = m.normal_texture else {
            return sp.n;
        };
        let [i0, i1, i2] = self.triangles[t as usize].map(|v| v as usize);
        let (e1, e2) = (
            self.positions[i1] - self.positions[i0],
            self.positions[i2] - self.positions[i0],
        );
        let (d1, d2) = (self.uv0[i1] - self.uv0[i0], self.uv0[i2] - self.uv0[i0]);
        let det = d1.x * d2.y - d2.x * d1.y;
        if det == 0.0 || !det.is_finite() {
            return sp.n;
        }
        let dp_du = (e1 * d2.y - e2 * d1.y) / det;
        let dp_dv = (e2 * d1.x - e1 * d2.x) / det;
        let tangent = (dp_du - sp.n * sp.n.dot(dp_du)).normalize_or_zero();
        // The map's +y (green) points up the image, towards decreasing v (glTF's v grows
        // downward): n × t there, unless the UVs are mirrored.
        let mirrored = sp.n.cross(dp_du).dot(-dp_dv) < 0.0;
        let bitangent = sp.n.cross(tangent) * if mirrored { -1.0 } else { 1.0 };
        if tangent == Vec3::ZERO {
            return sp.n;
        }
        let c = self.textures[texture as usize].sample(sp.uv0) * 2.0 - Vec3::ONE;
        let local = Vec3::new(c.x * m.normal_scale, c.y * m.normal_scale, c.z);
        let n = (tangent * local.x + bitangent * local.y + sp.n * local.z).normalize_or_zero();
        if n.dot(sp.n_geo) > 0.0 { n } else { sp.n }
    }

    /// Reflectance `baseColorFactor × baseColorTexture(uv0)` of material `m`.
    pub(crate) fn base_color(&self, m: u32, uv0: Vec2) -> Vec3 {
        let m = &self.materials[m as usize];
        self.textured(m.base_color, m.base_color_texture, uv0)
    }

    /// Emitted radiance `emission × emissiveTexture(uv0)` of material `m`.
    pub(crate) fn emission(&self, m: u32, uv0: Vec2) -> Vec3 {
        let m = &self.materials[m as usize];
        self.textured(m.emission, m.emissive_texture, uv0)
    }

    fn textured(&self, factor: Vec3, texture: Option<u32>, uv: Vec2) -> Vec3 {
        match texture {
            Some(t) => factor * self.textures[t as usize].sample(uv),
            None => factor,
        }
    }

    /// World bounding box `(lo, hi)` of all vertices (`(Vec3::MAX, Vec3::MIN)` when empty).
    pub fn bounds(&self) -> (Vec3, Vec3) {
        self.positions
            .iter()
            .fold((Vec3::MAX, Vec3::MIN), |(lo, hi), &p| {
                (lo.min(p), hi.max(p))
            })
    }

    /// Emission is anywhere in the scene (an emissive material or a light).
    pub(crate) fn has_light_sources(&self) -> bool {
        !self.lights.is_empty()
            || self
                .materials
                .iter()
                .any(|m| m.emission.max_element() > 0.0)
    }

    /// Edge `k` of scene triangle `t` lies on a junction (see [`Split::junction_edges`]).
    pub(crate) fn is_junction_edge(&self, t: u32, k: usize) -> bool {
        let inst = &self.instances[self.triangle_instance[t as usize] as usize];
        let local = (t - inst.triangles.start) as usize;
        inst.split
            .junction_edges
            .get(local)
            .is_some_and(|bits| bits & (1 << k) != 0)
    }

    /// Debug-build consistency check, run at the end of the loader.
    #[cfg(any(debug_assertions, test))]
    pub(crate) fn validate(&self) {
        let n = self.positions.len();
        assert_eq!(self.normals.len(), n);
        assert_eq!(self.uv0.len(), n);
        assert_eq!(self.uv1.len(), n);
        assert_eq!(self.triangle_instance.len(), self.triangles.len());
        for t in &self.triangles {
            assert!(t.iter().all(|&v| (v as usize) < n));
        }
        assert!(self.positions.iter().all(|p| p.is_finite()));
        for (i, inst) in self.instances.iter().enumerate() {
            assert!((inst.material as usize) < self.materials.len());
            assert_eq!(inst.source_triangle.len(), inst.triangles.len());
            for t in inst.triangles.clone() {
                assert_eq!(self.triangle_instance[t as usize], i as u32);
            }
            let triangles = inst.triangles.len();
            assert!(inst.split.sides.is_empty() || inst.split.sides.len() == triangles);
            assert!(
                inst.split.junction_edges.is_empty()
                    || inst.split.junction_edges.len() == triangles
            );
            let source_vertices = inst.vertices.len() - inst.split.blends.len();
            for blend in &inst.split.blends {
                assert!(
                    blend
                        .vertices
                        .iter()
                        .all(|&v| (v as usize) < source_vertices)
                );
            }
        }
    }
}
