//! Procedural glTF test scenes with known answers, and the small glTF builder that writes them.
//!
//! Tests, examples and benches share these scenes; `cargo run --example make_fixtures` writes
//! them to `fixtures/` (see `fixtures/README.md` for what each one tests and its expected
//! answer). All units are metres, Y is up, front faces are counter-clockwise (glTF).
//!
//! The builder covers exactly what the scenes need and produces files that pass the Khronos
//! glTF-Validator with no errors: one buffer, one tightly packed bufferView per accessor
//! (4-byte aligned, with `target`), `POSITION` bounds, `u16` indices whenever they fit.

use std::f32::consts::{FRAC_PI_2, PI};
use std::path::Path;

use base64::Engine;
use glam::{Mat3, Mat4, Quat, Vec2, Vec3};
use serde_json::{Map, Value, json};

use crate::scene::LightKind;
use crate::{Error, Result};

/// Cornell box light: emitted radiance per channel, `emissiveFactor (1,1,1) × emissiveStrength`.
pub const CORNELL_LIGHT_RADIANCE: f32 = 17.0;
/// Cornell box light: size of the emitting quad along x and z (m).
pub const CORNELL_LIGHT_SIZE: Vec2 = Vec2::new(0.25, 0.2);
/// Cornell box light: height of the emitting quad (1 cm below the 1 m ceiling), facing down.
pub const CORNELL_LIGHT_HEIGHT: f32 = 0.99;
/// Cornell box light: emitted power per channel, `π · Le · area` (W).
#[cfg(test)]
const CORNELL_LIGHT_POWER: f32 =
    PI * CORNELL_LIGHT_RADIANCE * CORNELL_LIGHT_SIZE.x * CORNELL_LIGHT_SIZE.y;

/// Triangle mesh data of one primitive; every attribute has one entry per vertex.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Geometry {
    pub(crate) positions: Vec<Vec3>,
    pub(crate) normals: Option<Vec<Vec3>>,
    pub(crate) uv0: Option<Vec<Vec2>>,
    /// Triangle list, counter-clockwise seen from the front.
    pub(crate) indices: Vec<u32>,
}

impl Geometry {
    pub fn new(
        positions: &[Vec3],
        normals: Option<&[Vec3]>,
        uv0: Option<&[Vec2]>,
        indices: &[u32],
    ) -> Self {
        Geometry {
            positions: positions.to_vec(),
            normals: normals.map(<[Vec3]>::to_vec),
            uv0: uv0.map(<[Vec2]>::to_vec),
            indices: indices.to_vec(),
        }
    }

    /// A planar grid of `nu × nv` quads over `origin + s·edge_u + t·edge_v`, s, t ∈ [0, 1],
    /// with flat normals, `uv0 = (s, t)`, front face towards `edge_u × edge_v`.
    pub fn grid(origin: Vec3, edge_u: Vec3, edge_v: Vec3, nu: u32, nv: u32) -> Self {
        assert!(nu > 0 && nv > 0, "a grid needs at least one quad");
        let normal = edge_u.cross(edge_v).normalize();
        let uv0: Vec<Vec2> = (0..=nv)
            .flat_map(|j| {
                (0..=nu).map(move |i| Vec2::new(i as f32 / nu as f32, j as f32 / nv as f32))
            })
            .collect();
        let mut geometry = Geometry {
            positions: uv0
                .iter()
                .map(|st| origin + edge_u * st.x + edge_v * st.y)
                .collect(),
            normals: Some(vec![normal; uv0.len()]),
            uv0: Some(uv0),
            indices: Vec::new(),
        };
        let vertex = |i: u32, j: u32| j * (nu + 1) + i;
        for j in 0..nv {
            for i in 0..nu {
                let (a, b) = (vertex(i, j), vertex(i + 1, j));
                let (c, d) = (vertex(i + 1, j + 1), vertex(i, j + 1));
                geometry.indices.extend_from_slice(&[a, b, c, a, c, d]);
            }
        }
        geometry
    }

    /// The grid covering one face of the axis-aligned box `min..max`, facing outward.
    pub fn box_face(min: Vec3, max: Vec3, face: Face, nu: u32, nv: u32) -> Self {
        let size = max - min;
        let (x, y, z) = (Vec3::X * size.x, Vec3::Y * size.y, Vec3::Z * size.z);
        let (origin, edge_u, edge_v) = match face {
            Face::PosX => (Vec3::new(max.x, min.y, max.z), -z, y),
            Face::NegX => (min, z, y),
            Face::PosY => (Vec3::new(min.x, max.y, max.z), x, -z),
            Face::NegY => (min, x, z),
            Face::PosZ => (Vec3::new(min.x, min.y, max.z), x, y),
            Face::NegZ => (Vec3::new(max.x, min.y, min.z), -x, y),
        };
        Geometry::grid(origin, edge_u, edge_v, nu, nv)
    }

    /// The given faces of the box `min..max`, each an `n × n` grid, facing outward.
    pub fn box_faces(min: Vec3, max: Vec3, faces: &[Face], n: u32) -> Self {
        let mut geometry = Geometry::default();
        for &face in faces {
            geometry.append(&Geometry::box_face(min, max, face, n, n));
        }
        geometry
    }

    /// A UV sphere with smooth normals: `nu` segments around +Y, `nv` rings, `uv0 = (s, t)`
    /// (one column of vertices repeated where `s` wraps, as exporters write it).
    pub fn uv_sphere(center: Vec3, radius: f32, nu: u32, nv: u32) -> Self {
        assert!(
            nu >= 3 && nv >= 2,
            "a sphere needs at least 3 segments and 2 rings"
        );
        let mut geometry = Geometry {
            normals: Some(Vec::new()),
            uv0: Some(Vec::new()),
            ..Default::default()
        };
        for j in 0..=nv {
            for i in 0..=nu {
                let (s, t) = (i as f32 / nu as f32, j as f32 / nv as f32);
                let (phi, theta) = (s * std::f32::consts::TAU, t * std::f32::consts::PI);
                let n = Vec3::new(
                    theta.sin() * phi.cos(),
                    theta.cos(),
                    -theta.sin() * phi.sin(),
                );
                geometry.positions.push(center + n * radius);
                geometry.normals.as_mut().unwrap().push(n);
                geometry.uv0.as_mut().unwrap().push(Vec2::new(s, t));
            }
        }
        let vertex = |i: u32, j: u32| j * (nu + 1) + i;
        for j in 0..nv {
            for i in 0..nu {
                let (a, b) = (vertex(i, j), vertex(i + 1, j));
                let (c, d) = (vertex(i + 1, j + 1), vertex(i, j + 1));
                // Counter-clockwise seen from outside; the pole rows have one triangle per quad.
                if j > 0 {
                    geometry.indices.extend_from_slice(&[a, d, b]);
                }
                if j + 1 < nv {
                    geometry.indices.extend_from_slice(&[b, d, c]);
                }
            }
        }
        geometry
    }

    /// A closed cylinder along +Y standing on `base`: `segments` sides with smooth normals,
    /// flat top and bottom caps.
    pub(crate) fn cylinder(base: Vec3, radius: f32, height: f32, segments: u32) -> Self {
        assert!(segments >= 3, "a cylinder needs at least 3 sides");
        let mut g = Geometry {
            normals: Some(Vec::new()),
            uv0: Some(Vec::new()),
            ..Default::default()
        };
        let mut vertex = |p: Vec3, n: Vec3, uv: Vec2| {
            g.positions.push(p);
            g.normals.as_mut().unwrap().push(n);
            g.uv0.as_mut().unwrap().push(uv);
        };
        for i in 0..=segments {
            let s = i as f32 / segments as f32;
            let phi = s * std::f32::consts::TAU;
            let n = Vec3::new(phi.cos(), 0.0, -phi.sin());
            vertex(base + n * radius, n, Vec2::new(s, 1.0));
            vertex(base + n * radius + Vec3::Y * height, n, Vec2::new(s, 0.0));
        }
        let caps = 2 * (segments + 1);
        for (y, n) in [(0.0, Vec3::NEG_Y), (height, Vec3::Y)] {
            vertex(base + Vec3::Y * y, n, Vec2::splat(0.5));
            for i in 0..segments {
                let phi = i as f32 / segments as f32 * std::f32::consts::TAU;
                let d = Vec3::new(phi.cos(), 0.0, -phi.sin());
                vertex(
                    base + d * radius + Vec3::Y * y,
                    n,
                    Vec2::splat(0.5) + 0.5 * Vec2::new(d.x, d.z),
                );
            }
        }
        for i in 0..segments {
            let (a, b, c, d) = (2 * i, 2 * i + 2, 2 * i + 3, 2 * i + 1);
            g.indices.extend_from_slice(&[a, b, c, a, c, d]);
        }
        for (cap, up) in [(caps, false), (caps + segments + 1, true)] {
            for i in 0..segments {
                let (p, q) = (cap + 1 + i, cap + 1 + (i + 1) % segments);
                if up {
                    g.indices.extend_from_slice(&[cap, p, q]);
                } else {
                    g.indices.extend_from_slice(&[cap, q, p]);
                }
            }
        }
        g
    }

    /// Appends `other`'s vertices and triangles; both must carry the same attributes
    /// (an empty geometry takes on `other`'s).
    pub fn append(&mut self, other: &Geometry) {
        if self.positions.is_empty() {
            *self = other.clone();
            return;
        }
        assert_eq!(
            self.normals.is_some(),
            other.normals.is_some(),
            "normals differ"
        );
        assert_eq!(self.uv0.is_some(), other.uv0.is_some(), "uv0 differs");
        let base = self.positions.len() as u32;
        self.positions.extend_from_slice(&other.positions);
        if let (Some(mine), Some(theirs)) = (&mut self.normals, &other.normals) {
            mine.extend_from_slice(theirs);
        }
        if let (Some(mine), Some(theirs)) = (&mut self.uv0, &other.uv0) {
            mine.extend_from_slice(theirs);
        }
        self.indices.extend(other.indices.iter().map(|i| base + i));
    }

    /// The same surface facing the other way: reversed winding, negated normals.
    pub fn flipped(mut self) -> Self {
        for triangle in self.indices.chunks_exact_mut(3) {
            triangle.swap(1, 2);
        }
        if let Some(normals) = &mut self.normals {
            normals.iter_mut().for_each(|n| *n = -*n);
        }
        self
    }

    /// Drops the normals, so a loader has to generate flat ones (as glTF requires).
    pub(crate) fn without_normals(mut self) -> Self {
        self.normals = None;
        self
    }

    /// Drops `TEXCOORD_0`.
    pub fn without_uv0(mut self) -> Self {
        self.uv0 = None;
        self
    }

    pub(crate) fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }
}

/// A face of an axis-aligned box, named by its outward normal.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Face {
    PosX,
    NegX,
    PosY,
    NegY,
    PosZ,
    NegZ,
}

impl Face {
    pub const ALL: [Face; 6] = [
        Face::PosX,
        Face::NegX,
        Face::PosY,
        Face::NegY,
        Face::PosZ,
        Face::NegZ,
    ];
    /// A box standing on the ground: every face but the bottom one.
    pub const NO_BOTTOM: [Face; 5] = [Face::PosX, Face::NegX, Face::PosY, Face::PosZ, Face::NegZ];
}

/// A metal-free, fully rough glTF material.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    pub(crate) name: String,
    /// Linear `baseColorFactor`.
    pub(crate) base_color: [f32; 4],
    pub(crate) emissive: [f32; 3],
    /// Written as `KHR_materials_emissive_strength` only when it is not 1.
    pub(crate) emissive_strength: f32,
    pub(crate) double_sided: bool,
    /// Image index (each image is its own texture).
    pub(crate) base_color_texture: Option<usize>,
    /// Image index of the `normalTexture` (tangent space, linear).
    pub(crate) normal_texture: Option<usize>,
}

impl Material {
    pub fn diffuse(name: &str, rgb: [f32; 3]) -> Self {
        Material {
            name: name.to_owned(),
            base_color: [rgb[0], rgb[1], rgb[2], 1.0],
            emissive: [0.0; 3],
            emissive_strength: 1.0,
            double_sided: false,
            base_color_texture: None,
            normal_texture: None,
        }
    }

    pub fn grey(name: &str, rho: f32) -> Self {
        Material::diffuse(name, [rho; 3])
    }

    /// Emits radiance `emissive × strength` (W/(sr·m²) per channel).
    pub fn emitting(mut self, emissive: [f32; 3], strength: f32) -> Self {
        self.emissive = emissive;
        self.emissive_strength = strength;
        self
    }

    pub(crate) fn double_sided(mut self) -> Self {
        self.double_sided = true;
        self
    }

    pub(crate) fn with_texture(mut self, image: usize) -> Self {
        self.base_color_texture = Some(image);
        self
    }

    pub(crate) fn with_normal_texture(mut self, image: usize) -> Self {
        self.normal_texture = Some(image);
        self
    }
}

/// Where an image's PNG bytes go.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum ImageStorage {
    /// In the binary buffer, referenced through a bufferView.
    BufferView,
    /// As a `data:image/png;base64,` URI.
    #[cfg(test)]
    DataUri,
}

#[derive(Clone, Debug, PartialEq)]
struct Image {
    name: String,
    png: Vec<u8>,
    storage: ImageStorage,
}

#[derive(Clone, Debug, PartialEq)]
struct Mesh {
    name: String,
    primitives: Vec<(Geometry, usize)>,
}

/// A node's local transform.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Transform {
    Trs {
        translation: Vec3,
        rotation: Quat,
        scale: Vec3,
    },
    /// Written as `matrix`; must be decomposable into TRS (the validator checks).
    Matrix(Mat4),
}

#[derive(Clone, Debug, PartialEq)]
pub struct Node {
    pub(crate) name: String,
    pub(crate) transform: Transform,
    pub(crate) mesh: Option<usize>,
    pub(crate) light: Option<usize>,
    pub(crate) camera: Option<usize>,
    pub(crate) children: Vec<usize>,
}

impl Node {
    pub fn new(name: &str) -> Self {
        Node {
            name: name.to_owned(),
            transform: Transform::Trs {
                translation: Vec3::ZERO,
                rotation: Quat::IDENTITY,
                scale: Vec3::ONE,
            },
            mesh: None,
            light: None,
            camera: None,
            children: Vec::new(),
        }
    }

    pub fn trs(mut self, translation: Vec3, rotation: Quat, scale: Vec3) -> Self {
        self.transform = Transform::Trs {
            translation,
            rotation: rotation.normalize(),
            scale,
        };
        self
    }

    pub(crate) fn at(self, translation: Vec3) -> Self {
        self.trs(translation, Quat::IDENTITY, Vec3::ONE)
    }

    pub(crate) fn matrix(mut self, matrix: Mat4) -> Self {
        self.transform = Transform::Matrix(matrix);
        self
    }

    /// Placed at `eye` with its -Z axis (where cameras look and lights shine) towards `target`.
    pub(crate) fn looking_at(self, eye: Vec3, target: Vec3) -> Self {
        self.trs(eye, rotation_towards(target - eye), Vec3::ONE)
    }

    /// Placed at `position` with its -Z axis along `direction`.
    pub(crate) fn pointing(self, position: Vec3, direction: Vec3) -> Self {
        self.trs(position, rotation_towards(direction), Vec3::ONE)
    }

    pub fn with_mesh(mut self, mesh: usize) -> Self {
        self.mesh = Some(mesh);
        self
    }

    pub(crate) fn with_light(mut self, light: usize) -> Self {
        self.light = Some(light);
        self
    }

    pub(crate) fn with_camera(mut self, camera: usize) -> Self {
        self.camera = Some(camera);
        self
    }

    pub fn with_children(mut self, children: &[usize]) -> Self {
        self.children = children.to_vec();
        self
    }
}

/// The rotation taking -Z to `direction`, keeping +Y as up where possible.
fn rotation_towards(direction: Vec3) -> Quat {
    let forward = direction.normalize();
    let up_hint = if forward.cross(Vec3::Y).length() < 1e-3 {
        Vec3::Z
    } else {
        Vec3::Y
    };
    let right = forward.cross(up_hint).normalize();
    let up = right.cross(forward);
    Quat::from_mat3(&Mat3::from_cols(right, up, -forward)).normalize()
}

/// A KHR_lights_punctual light: point/spot `intensity` in W/sr, directional in W/m².
#[derive(Clone, Debug, PartialEq)]
pub struct Light {
    pub(crate) name: String,
    pub(crate) kind: LightKind,
    pub(crate) color: [f32; 3],
    pub(crate) intensity: f32,
    /// Not allowed on directional lights.
    pub(crate) range: Option<f32>,
}

impl Light {
    pub fn point(name: &str, color: [f32; 3], intensity: f32) -> Self {
        Light {
            name: name.to_owned(),
            kind: LightKind::Point,
            color,
            intensity,
            range: None,
        }
    }

    pub(crate) fn spot(
        name: &str,
        color: [f32; 3],
        intensity: f32,
        inner: f32,
        outer: f32,
    ) -> Self {
        let kind = LightKind::Spot {
            inner_cone_angle: inner,
            outer_cone_angle: outer,
        };
        Light {
            name: name.to_owned(),
            kind,
            color,
            intensity,
            range: None,
        }
    }

    pub fn directional(name: &str, color: [f32; 3], irradiance: f32) -> Self {
        let kind = LightKind::Directional;
        Light {
            name: name.to_owned(),
            kind,
            color,
            intensity: irradiance,
            range: None,
        }
    }

    pub(crate) fn with_range(mut self, range: f32) -> Self {
        self.range = Some(range);
        self
    }
}

/// A perspective camera.
#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    pub(crate) name: String,
    /// Vertical field of view (radians).
    pub yfov: f32,
    pub aspect_ratio: Option<f32>,
    pub(crate) znear: f32,
    pub(crate) zfar: Option<f32>,
}

impl Camera {
    pub fn perspective(name: &str, yfov: f32, aspect_ratio: Option<f32>) -> Self {
        Camera {
            name: name.to_owned(),
            yfov,
            aspect_ratio,
            znear: 0.01,
            zfar: Some(100.0),
        }
    }
}

/// Collects meshes, materials, images, nodes, lights and cameras of one glTF scene.
#[derive(Clone, Debug, PartialEq)]
pub struct GltfBuilder {
    scene_name: String,
    materials: Vec<Material>,
    images: Vec<Image>,
    meshes: Vec<Mesh>,
    nodes: Vec<Node>,
    lights: Vec<Light>,
    cameras: Vec<Camera>,
}

impl GltfBuilder {
    pub fn new(scene_name: &str) -> Self {
        GltfBuilder {
            scene_name: scene_name.to_owned(),
            materials: Vec::new(),
            images: Vec::new(),
            meshes: Vec::new(),
            nodes: Vec::new(),
            lights: Vec::new(),
            cameras: Vec::new(),
        }
    }

    pub fn add_material(&mut self, material: Material) -> usize {
        let unit = |x: &f32| (0.0..=1.0).contains(x);
        assert!(
            material.base_color.iter().all(unit),
            "baseColorFactor outside [0, 1]"
        );
        assert!(
            material.emissive.iter().all(unit),
            "emissiveFactor outside [0, 1]: use the strength"
        );
        assert!(
            material.emissive_strength >= 0.0,
            "negative emissive strength"
        );
        self.materials.push(material);
        self.materials.len() - 1
    }

    /// Encodes `image` as PNG (deterministic for a given `image` crate version).
    pub(crate) fn add_image(
        &mut self,
        name: &str,
        image: &image::DynamicImage,
        storage: ImageStorage,
    ) -> usize {
        let mut png = Vec::new();
        image
            .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
            .expect("PNG encoding into memory cannot fail");
        self.images.push(Image {
            name: name.to_owned(),
            png,
            storage,
        });
        self.images.len() - 1
    }

    /// A mesh with one primitive.
    pub fn add_mesh(&mut self, name: &str, geometry: Geometry, material: usize) -> usize {
        self.meshes.push(Mesh {
            name: name.to_owned(),
            primitives: Vec::new(),
        });
        let mesh = self.meshes.len() - 1;
        self.add_primitive(mesh, geometry, material);
        mesh
    }

    /// Adds one more primitive to `mesh`.
    pub fn add_primitive(&mut self, mesh: usize, geometry: Geometry, material: usize) {
        let vertices = geometry.positions.len();
        assert!(
            vertices > 0 && geometry.indices.len().is_multiple_of(3),
            "empty or ragged geometry"
        );
        assert!(
            geometry.indices.iter().all(|&i| (i as usize) < vertices),
            "index out of range"
        );
        assert!(
            geometry
                .normals
                .as_ref()
                .is_none_or(|n| n.len() == vertices),
            "normal count"
        );
        assert!(
            geometry.uv0.as_ref().is_none_or(|uv| uv.len() == vertices),
            "uv0 count"
        );
        assert!(material < self.materials.len(), "unknown material");
        self.meshes[mesh].primitives.push((geometry, material));
    }

    pub(crate) fn add_light(&mut self, light: Light) -> usize {
        self.lights.push(light);
        self.lights.len() - 1
    }

    pub(crate) fn add_camera(&mut self, camera: Camera) -> usize {
        self.cameras.push(camera);
        self.cameras.len() - 1
    }

    /// Adds a node; nodes that are nobody's child become the scene's roots.
    pub fn add_node(&mut self, node: Node) -> usize {
        self.nodes.push(node);
        self.nodes.len() - 1
    }

    /// Adds a mesh node at the origin.
    pub fn add_mesh_node(&mut self, name: &str, mesh: usize) -> usize {
        self.add_node(Node::new(name).with_mesh(mesh))
    }

    /// Adds a light on a node at `position` shining along `direction` (ignored by point lights).
    pub fn add_light_node(&mut self, light: Light, position: Vec3, direction: Vec3) -> usize {
        let name = light.name.clone();
        let light = self.add_light(light);
        self.add_node(
            Node::new(&name)
                .pointing(position, direction)
                .with_light(light),
        )
    }

    /// Adds a perspective camera on a node at `eye` looking at `target`.
    pub fn add_camera_node(&mut self, camera: Camera, eye: Vec3, target: Vec3) -> usize {
        let name = camera.name.clone();
        let camera = self.add_camera(camera);
        self.add_node(Node::new(&name).looking_at(eye, target).with_camera(camera))
    }

    /// Number of triangles summed over meshes (not over instances).
    pub fn mesh_triangle_count(&self) -> usize {
        self.meshes
            .iter()
            .flat_map(|m| &m.primitives)
            .map(|(g, _)| g.triangle_count())
            .sum()
    }

    /// The glTF JSON and its binary buffer. `buffers[0]` has no `uri` (as in a GLB);
    /// [`GltfBuilder::to_gltf_bytes`] embeds the buffer as a data URI.
    pub fn to_gltf_json(&self) -> (Value, Vec<u8>) {
        let mut packer = Packer::default();
        let meshes: Vec<Value> = self
            .meshes
            .iter()
            .map(|mesh| mesh_json(mesh, &mut packer))
            .collect();
        let images: Vec<Value> = self
            .images
            .iter()
            .map(|image| image_json(image, &mut packer))
            .collect();
        let buffer_length = packer.finish();

        let mut root = Map::new();
        root.insert(
            "asset".into(),
            json!({ "version": "2.0", "generator": "lightbake testing" }),
        );
        let mut extensions_used = Vec::new();
        if !self.lights.is_empty() {
            extensions_used.push("KHR_lights_punctual");
        }
        if self.materials.iter().any(|m| m.emissive_strength != 1.0) {
            extensions_used.push("KHR_materials_emissive_strength");
        }
        if !extensions_used.is_empty() {
            root.insert("extensionsUsed".into(), json!(extensions_used));
        }
        if !self.lights.is_empty() {
            let lights: Vec<Value> = self.lights.iter().map(light_json).collect();
            root.insert(
                "extensions".into(),
                json!({ "KHR_lights_punctual": { "lights": lights } }),
            );
        }
        let is_child: Vec<bool> = (0..self.nodes.len())
            .map(|i| self.nodes.iter().any(|n| n.children.contains(&i)))
            .collect();
        let roots: Vec<usize> = (0..self.nodes.len()).filter(|&i| !is_child[i]).collect();
        root.insert("scene".into(), json!(0));
        root.insert(
            "scenes".into(),
            json!([{ "name": self.scene_name, "nodes": roots }]),
        );
        insert_array(
            &mut root,
            "nodes",
            self.nodes.iter().map(node_json).collect(),
        );
        insert_array(&mut root, "meshes", meshes);
        insert_array(
            &mut root,
            "materials",
            self.materials.iter().map(material_json).collect(),
        );
        let textures: Vec<Value> = (0..self.images.len())
            .map(|i| json!({ "sampler": 0, "source": i }))
            .collect();
        if !textures.is_empty() {
            // Nearest filtering keeps the checker's squares crisp.
            root.insert(
                "samplers".into(),
                json!([{ "magFilter": 9728, "minFilter": 9728 }]),
            );
        }
        insert_array(&mut root, "textures", textures);
        insert_array(&mut root, "images", images);
        insert_array(
            &mut root,
            "cameras",
            self.cameras.iter().map(camera_json).collect(),
        );
        insert_array(
            &mut root,
            "accessors",
            std::mem::take(&mut packer.accessors),
        );
        insert_array(&mut root, "bufferViews", std::mem::take(&mut packer.views));
        root.insert("buffers".into(), json!([{ "byteLength": buffer_length }]));
        (Value::Object(root), packer.bin)
    }

    /// A self-contained `.gltf`: pretty-printed JSON, the buffer as a base64 data URI.
    pub fn to_gltf_bytes(&self) -> Vec<u8> {
        let (mut json, bin) = self.to_gltf_json();
        let uri = format!(
            "data:application/octet-stream;base64,{}",
            base64::engine::general_purpose::STANDARD.encode(&bin)
        );
        json["buffers"][0]["uri"] = Value::String(uri);
        let mut bytes = serde_json::to_vec_pretty(&json).expect("a JSON value always serialises");
        bytes.push(b'\n');
        bytes
    }

    /// A binary `.glb`: JSON chunk (space-padded) and BIN chunk (zero-padded).
    pub fn to_glb_bytes(&self) -> Vec<u8> {
        let (json, bin) = self.to_gltf_json();
        let json = serde_json::to_vec(&json).expect("a JSON value always serialises");
        crate::output::glb::container(json, bin)
    }

    pub fn write_gltf(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        std::fs::write(path, self.to_gltf_bytes()).map_err(|e| Error::io(path, e))
    }

    pub fn write_glb(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        std::fs::write(path, self.to_glb_bytes()).map_err(|e| Error::io(path, e))
    }
}

/// Adds `part`'s meshes (with their materials, its buffer as a data URI) and root nodes to
/// the glTF `json` (a baked scene, say), each node in `json`'s scene: how a test or an example
/// puts an object the bake never saw into a baked scene. Images, lights and cameras of `part`
/// are left out.
pub fn add_to_gltf(json: &mut Value, part: &GltfBuilder) -> Result<()> {
    let (part, bin) = part.to_gltf_json();
    let bad = |what: &str| Error::invalid(Path::new("<glTF JSON>"), what.to_owned());
    let len = |json: &Value, key: &str| json[key].as_array().map_or(0, Vec::len) as u64;
    let [buffer, views, accessors, materials, meshes, nodes] = [
        "buffers",
        "bufferViews",
        "accessors",
        "materials",
        "meshes",
        "nodes",
    ]
    .map(|key| len(json, key));
    let shifted = |v: &Value, by: u64| -> Result<Value> {
        Ok(json!(
            by + v.as_u64().ok_or_else(|| bad("an index is not a number"))?
        ))
    };
    let mut items: Vec<(&str, Value)> = vec![(
        "buffers",
        json!({
            "byteLength": bin.len(),
            "uri": format!(
                "data:application/octet-stream;base64,{}",
                base64::engine::general_purpose::STANDARD.encode(&bin)
            ),
        }),
    )];
    let array = |key: &str| part[key].as_array().cloned().unwrap_or_default();
    for mut view in array("bufferViews") {
        view["buffer"] = json!(buffer);
        items.push(("bufferViews", view));
    }
    for mut accessor in array("accessors") {
        accessor["bufferView"] = shifted(&accessor["bufferView"], views)?;
        items.push(("accessors", accessor));
    }
    for material in array("materials") {
        items.push(("materials", material));
    }
    for mut mesh in array("meshes") {
        for primitive in mesh["primitives"].as_array_mut().into_iter().flatten() {
            if let Some(attributes) = primitive["attributes"].as_object_mut() {
                for a in attributes.values_mut() {
                    *a = shifted(a, accessors)?;
                }
            }
            primitive["indices"] = shifted(&primitive["indices"], accessors)?;
            primitive["material"] = shifted(&primitive["material"], materials)?;
        }
        items.push(("meshes", mesh));
    }
    let roots = part["scenes"][0]["nodes"]
        .as_array()
        .cloned()
        .unwrap_or_default();
    for mut node in array("nodes") {
        if node.get("mesh").is_some() {
            node["mesh"] = shifted(&node["mesh"], meshes)?;
        }
        if let Some(children) = node["children"].as_array_mut() {
            for c in children {
                *c = shifted(c, nodes)?;
            }
        }
        node.as_object_mut().map(|n| n.remove("camera"));
        node.as_object_mut().map(|n| n.remove("extensions"));
        items.push(("nodes", node));
    }
    for (key, item) in items {
        match json[key].as_array_mut() {
            Some(a) => a.push(item),
            None => json[key] = json!([item]),
        }
    }
    let scene = json["scene"].as_u64().unwrap_or(0) as usize;
    let scene_nodes = json["scenes"][scene]["nodes"]
        .as_array_mut()
        .ok_or_else(|| bad("the glTF has no scene to add nodes to"))?;
    for r in roots {
        scene_nodes.push(shifted(&r, nodes)?);
    }
    Ok(())
}

fn mesh_json(mesh: &Mesh, packer: &mut Packer) -> Value {
    let primitives: Vec<Value> = mesh
        .primitives
        .iter()
        .map(|(geometry, material)| {
            let mut attributes = Map::new();
            attributes.insert(
                "POSITION".into(),
                json!(packer.positions(&geometry.positions)),
            );
            if let Some(normals) = &geometry.normals {
                let unit: Vec<Vec3> = normals.iter().map(|n| n.normalize()).collect();
                attributes.insert("NORMAL".into(), json!(packer.vec3(&unit)));
            }
            if let Some(uv0) = &geometry.uv0 {
                attributes.insert("TEXCOORD_0".into(), json!(packer.vec2(uv0)));
            }
            let indices = packer.indices(&geometry.indices, geometry.positions.len());
            json!({ "attributes": attributes, "indices": indices, "material": material })
        })
        .collect();
    json!({ "name": mesh.name, "primitives": primitives })
}

/// A finite f32 as a JSON number with its shortest decimal form (0.73, not 0.7300000190734863).
fn num(x: f32) -> Value {
    assert!(x.is_finite(), "non-finite number in a glTF");
    let shortest: f64 = x.to_string().parse().expect("f32 display parses as f64");
    Value::Number(serde_json::Number::from_f64(shortest).expect("finite"))
}

fn nums(xs: &[f32]) -> Value {
    Value::Array(xs.iter().copied().map(num).collect())
}

fn insert_array(root: &mut Map<String, Value>, key: &str, items: Vec<Value>) {
    // glTF forbids empty top-level arrays.
    if !items.is_empty() {
        root.insert(key.into(), Value::Array(items));
    }
}

fn material_json(material: &Material) -> Value {
    let mut pbr = Map::new();
    pbr.insert("baseColorFactor".into(), nums(&material.base_color));
    if let Some(image) = material.base_color_texture {
        pbr.insert("baseColorTexture".into(), json!({ "index": image }));
    }
    pbr.insert("metallicFactor".into(), num(0.0));
    pbr.insert("roughnessFactor".into(), num(1.0));
    let mut out = Map::new();
    out.insert("name".into(), json!(material.name));
    out.insert("pbrMetallicRoughness".into(), Value::Object(pbr));
    if material.emissive != [0.0; 3] {
        out.insert("emissiveFactor".into(), nums(&material.emissive));
    }
    if let Some(image) = material.normal_texture {
        out.insert("normalTexture".into(), json!({ "index": image }));
    }
    if material.double_sided {
        out.insert("doubleSided".into(), json!(true));
    }
    if material.emissive_strength != 1.0 {
        let strength = json!({ "emissiveStrength": num(material.emissive_strength) });
        out.insert(
            "extensions".into(),
            json!({ "KHR_materials_emissive_strength": strength }),
        );
    }
    Value::Object(out)
}

fn image_json(image: &Image, packer: &mut Packer) -> Value {
    match image.storage {
        ImageStorage::BufferView => {
            let view = packer.view(&image.png, None);
            json!({ "name": image.name, "bufferView": view, "mimeType": "image/png" })
        }
        #[cfg(test)]
        ImageStorage::DataUri => {
            let base64 = base64::engine::general_purpose::STANDARD.encode(&image.png);
            json!({ "name": image.name, "uri": format!("data:image/png;base64,{base64}") })
        }
    }
}

fn node_json(node: &Node) -> Value {
    let mut out = Map::new();
    out.insert("name".into(), json!(node.name));
    match node.transform {
        Transform::Trs {
            translation,
            rotation,
            scale,
        } => {
            if translation != Vec3::ZERO {
                out.insert("translation".into(), nums(&translation.to_array()));
            }
            if rotation != Quat::IDENTITY {
                out.insert("rotation".into(), nums(&rotation.to_array()));
            }
            if scale != Vec3::ONE {
                out.insert("scale".into(), nums(&scale.to_array()));
            }
        }
        Transform::Matrix(matrix) => {
            out.insert("matrix".into(), nums(&matrix.to_cols_array()));
        }
    }
    if let Some(mesh) = node.mesh {
        out.insert("mesh".into(), json!(mesh));
    }
    if let Some(camera) = node.camera {
        out.insert("camera".into(), json!(camera));
    }
    if !node.children.is_empty() {
        out.insert("children".into(), json!(node.children));
    }
    if let Some(light) = node.light {
        out.insert(
            "extensions".into(),
            json!({ "KHR_lights_punctual": { "light": light } }),
        );
    }
    Value::Object(out)
}

fn light_json(light: &Light) -> Value {
    let mut out = Map::new();
    out.insert("name".into(), json!(light.name));
    let kind = match light.kind {
        LightKind::Point => "point",
        LightKind::Spot { .. } => "spot",
        LightKind::Directional => "directional",
    };
    out.insert("type".into(), json!(kind));
    out.insert("color".into(), nums(&light.color));
    out.insert("intensity".into(), num(light.intensity));
    if let Some(range) = light.range {
        assert!(
            light.kind != LightKind::Directional,
            "directional lights have no range"
        );
        out.insert("range".into(), num(range));
    }
    if let LightKind::Spot {
        inner_cone_angle,
        outer_cone_angle,
    } = light.kind
    {
        assert!(
            0.0 <= inner_cone_angle
                && inner_cone_angle < outer_cone_angle
                && outer_cone_angle <= FRAC_PI_2
        );
        let spot = json!({ "innerConeAngle": num(inner_cone_angle), "outerConeAngle": num(outer_cone_angle) });
        out.insert("spot".into(), spot);
    }
    Value::Object(out)
}

fn camera_json(camera: &Camera) -> Value {
    let mut perspective = Map::new();
    if let Some(aspect) = camera.aspect_ratio {
        perspective.insert("aspectRatio".into(), num(aspect));
    }
    perspective.insert("yfov".into(), num(camera.yfov));
    if let Some(zfar) = camera.zfar {
        perspective.insert("zfar".into(), num(zfar));
    }
    perspective.insert("znear".into(), num(camera.znear));
    json!({ "name": camera.name, "type": "perspective", "perspective": perspective })
}

const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;
const FLOAT: u32 = 5126;
const UNSIGNED_SHORT: u32 = 5123;
const UNSIGNED_INT: u32 = 5125;

/// Lays out the binary buffer: one 4-byte aligned bufferView per accessor or image.
#[derive(Default)]
struct Packer {
    bin: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl Packer {
    fn align(&mut self) {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
    }

    fn view(&mut self, bytes: &[u8], target: Option<u32>) -> usize {
        self.align();
        let mut view =
            json!({ "buffer": 0, "byteOffset": self.bin.len(), "byteLength": bytes.len() });
        if let Some(target) = target {
            view["target"] = json!(target);
        }
        self.bin.extend_from_slice(bytes);
        self.views.push(view);
        self.views.len() - 1
    }

    /// Stores `bytes` in a new bufferView and describes them with a new accessor.
    fn accessor(
        &mut self,
        bytes: &[u8],
        target: u32,
        component: u32,
        count: usize,
        kind: &str,
    ) -> usize {
        let view = self.view(bytes, Some(target));
        let accessor =
            json!({ "bufferView": view, "componentType": component, "count": count, "type": kind });
        self.accessors.push(accessor);
        self.accessors.len() - 1
    }

    fn floats(&mut self, floats: impl Iterator<Item = f32>, count: usize, kind: &str) -> usize {
        let bytes: Vec<u8> = floats.flat_map(f32::to_le_bytes).collect();
        self.accessor(&bytes, ARRAY_BUFFER, FLOAT, count, kind)
    }

    fn vec3(&mut self, data: &[Vec3]) -> usize {
        self.floats(data.iter().flat_map(|v| v.to_array()), data.len(), "VEC3")
    }

    /// POSITION accessors must carry their bounds.
    fn positions(&mut self, data: &[Vec3]) -> usize {
        let index = self.vec3(data);
        let min = data.iter().copied().fold(Vec3::INFINITY, Vec3::min);
        let max = data.iter().copied().fold(Vec3::NEG_INFINITY, Vec3::max);
        self.accessors[index]["min"] = nums(&min.to_array());
        self.accessors[index]["max"] = nums(&max.to_array());
        index
    }

    fn vec2(&mut self, data: &[Vec2]) -> usize {
        self.floats(data.iter().flat_map(|v| v.to_array()), data.len(), "VEC2")
    }

    /// u16 when every index fits below 65535 (the primitive-restart value glTF forbids).
    fn indices(&mut self, indices: &[u32], vertex_count: usize) -> usize {
        let (bytes, component): (Vec<u8>, _) = if vertex_count <= u16::MAX as usize {
            let bytes = indices
                .iter()
                .flat_map(|&i| (i as u16).to_le_bytes())
                .collect();
            (bytes, UNSIGNED_SHORT)
        } else {
            (
                indices.iter().flat_map(|&i| i.to_le_bytes()).collect(),
                UNSIGNED_INT,
            )
        };
        self.accessor(
            &bytes,
            ELEMENT_ARRAY_BUFFER,
            component,
            indices.len(),
            "SCALAR",
        )
    }

    /// Pads the buffer to a multiple of 4 bytes and returns its length.
    fn finish(&mut self) -> usize {
        self.align();
        self.bin.len()
    }
}

// ---------------------------------------------------------------------------------------------
// Scenes
// ---------------------------------------------------------------------------------------------

/// The Cornell box scaled to 1 m: interior x ∈ [−0.5, 0.5], y ∈ [0, 1], z ∈ [−0.5, 0.5], open
/// towards +z. White floor, ceiling and back wall (ρ = 0.73), red left wall (x = −0.5), green
/// right wall, a tall and a short block, and a 0.25 × 0.2 m light 1 cm below the ceiling facing
/// down with `Le` = [`CORNELL_LIGHT_RADIANCE`] (emitted power [`CORNELL_LIGHT_POWER`] ≈ 2.67 W
/// per channel). A camera looks in from the open side.
pub fn cornell_box() -> GltfBuilder {
    let mut gltf = GltfBuilder::new("cornell_box");
    let white = gltf.add_material(Material::grey("white", 0.73));
    let red = gltf.add_material(Material::diffuse("red", [0.63, 0.065, 0.05]));
    let green = gltf.add_material(Material::diffuse("green", [0.14, 0.45, 0.09]));
    let light =
        gltf.add_material(Material::grey("light", 0.78).emitting([1.0; 3], CORNELL_LIGHT_RADIANCE));

    let (min, max) = (Vec3::new(-0.5, 0.0, -0.5), Vec3::new(0.5, 1.0, 0.5));
    let wall = |face| Geometry::box_face(min, max, face, 4, 4).flipped();
    let mut white_walls = wall(Face::NegY);
    white_walls.append(&wall(Face::PosY));
    white_walls.append(&wall(Face::NegZ));
    let room = gltf.add_mesh("room", white_walls, white);
    gltf.add_primitive(room, wall(Face::NegX), red);
    gltf.add_primitive(room, wall(Face::PosX), green);
    gltf.add_mesh_node("room", room);

    let size = CORNELL_LIGHT_SIZE;
    let corner = Vec3::new(-size.x / 2.0, CORNELL_LIGHT_HEIGHT, -size.y / 2.0);
    let quad = Geometry::grid(corner, Vec3::X * size.x, Vec3::Z * size.y, 1, 1);
    let light_mesh = gltf.add_mesh("light", quad, light);
    gltf.add_mesh_node("light", light_mesh);

    // Blocks stand on the floor, modelled around their own base centre and placed by their node.
    let block = |height: f32| {
        Geometry::box_faces(
            Vec3::new(-0.15, 0.0, -0.15),
            Vec3::new(0.15, height, 0.15),
            &Face::NO_BOTTOM,
            2,
        )
    };
    let short = gltf.add_mesh("short_block", block(0.3), white);
    let tall = gltf.add_mesh("tall_block", block(0.6), white);
    let turn = |degrees: f32| Quat::from_rotation_y(degrees.to_radians());
    gltf.add_node(
        Node::new("short_block")
            .trs(Vec3::new(0.2, 0.0, 0.15), turn(-18.0), Vec3::ONE)
            .with_mesh(short),
    );
    gltf.add_node(
        Node::new("tall_block")
            .trs(Vec3::new(-0.17, 0.0, -0.15), turn(17.0), Vec3::ONE)
            .with_mesh(tall),
    );

    let camera = Camera::perspective("camera", 39.3f32.to_radians(), Some(1.0));
    gltf.add_camera_node(camera, Vec3::new(0.0, 0.5, 1.94), Vec3::new(0.0, 0.5, 0.0));
    gltf
}

/// A closed 1 m cube (x, z ∈ [−0.5, 0.5], y ∈ [0, 1]) facing inward, every face reflectance
/// `rho` and emitted radiance `le`. Expected lightmap everywhere: `le / (1 − rho)`.
pub fn furnace(rho: f32, le: f32) -> GltfBuilder {
    let mut gltf = GltfBuilder::new("furnace");
    let material = gltf.add_material(Material::grey("furnace", rho).emitting([1.0; 3], le));
    let cube = Geometry::box_faces(
        Vec3::new(-0.5, 0.0, -0.5),
        Vec3::new(0.5, 1.0, 0.5),
        &Face::ALL,
        4,
    )
    .flipped();
    let mesh = gltf.add_mesh("cube", cube.without_uv0(), material);
    gltf.add_mesh_node("cube", mesh);
    let camera = Camera::perspective("camera", 1.2, None);
    gltf.add_camera_node(camera, Vec3::new(0.0, 0.5, 0.45), Vec3::new(0.0, 0.5, 0.0));
    gltf
}

/// A black 4 × 4 m floor at y = 0 centred at the origin and a white point light of `intensity`
/// W/sr at (0, `height`, 0). Expected lightmap at angle θ from straight below:
/// `intensity · cos³θ / (π · height²)`.
pub fn point_light_floor(intensity: f32, height: f32) -> GltfBuilder {
    let mut gltf = GltfBuilder::new("point_light");
    let black = gltf.add_material(Material::grey("black", 0.0));
    let floor = floor(4.0, 8).without_uv0();
    let mesh = gltf.add_mesh("floor", floor, black);
    gltf.add_mesh_node("floor", mesh);
    gltf.add_light_node(
        Light::point("point", [1.0; 3], intensity),
        Vec3::new(0.0, height, 0.0),
        Vec3::NEG_Y,
    );
    let camera = Camera::perspective("camera", 0.8, None);
    gltf.add_camera_node(camera, Vec3::new(0.0, 3.0, 4.0), Vec3::ZERO);
    gltf
}

/// Spot light: position, direction, intensity (W/sr), colour, cone angles and range.
pub(crate) const SPOT_POSITION: Vec3 = Vec3::new(-0.8, 2.0, 0.2);
pub(crate) const SPOT_INTENSITY: f32 = 15.0;
pub(crate) const SPOT_COLOR: [f32; 3] = [1.0, 0.85, 0.6];
pub(crate) const SPOT_CONE: (f32, f32) = (0.3, 0.6);
pub(crate) const SPOT_RANGE: f32 = 6.0;
/// Directional light: travel direction (not normalised), irradiance (W/m²) and colour.
pub(crate) const SUN_DIRECTION: Vec3 = Vec3::new(0.5, -1.0, -0.6);
pub(crate) const SUN_IRRADIANCE: f32 = 1.5;
pub(crate) const SUN_COLOR: [f32; 3] = [0.9, 0.95, 1.0];

/// A grey 4 × 4 m floor, a back wall at z = −2 facing +z and a small blue box, lit by a spot
/// light pointing straight down (cone angles 0.3/0.6 rad, range 6 m) and a directional light.
pub(crate) fn spot_and_directional() -> GltfBuilder {
    let mut gltf = GltfBuilder::new("spot_and_directional");
    let grey = gltf.add_material(Material::grey("floor", 0.5));
    let wall_material = gltf.add_material(Material::grey("wall", 0.6));
    let blue = gltf.add_material(Material::diffuse("box", [0.2, 0.3, 0.7]));

    let floor_mesh = gltf.add_mesh("floor", floor(4.0, 8).without_uv0(), grey);
    gltf.add_mesh_node("floor", floor_mesh);
    let wall = Geometry::grid(
        Vec3::new(-2.0, 0.0, -2.0),
        Vec3::X * 4.0,
        Vec3::Y * 2.5,
        8,
        5,
    )
    .without_uv0();
    let wall_mesh = gltf.add_mesh("back_wall", wall, wall_material);
    gltf.add_mesh_node("back_wall", wall_mesh);
    let cube = Geometry::box_faces(
        Vec3::new(0.3, 0.0, -0.7),
        Vec3::new(0.9, 0.6, -0.1),
        &Face::NO_BOTTOM,
        2,
    );
    let box_mesh = gltf.add_mesh("box", cube.without_uv0(), blue);
    gltf.add_mesh_node("box", box_mesh);

    let (inner, outer) = SPOT_CONE;
    let spot = Light::spot("spot", SPOT_COLOR, SPOT_INTENSITY, inner, outer).with_range(SPOT_RANGE);
    gltf.add_light_node(spot, SPOT_POSITION, Vec3::NEG_Y);
    let sun = Light::directional("sun", SUN_COLOR, SUN_IRRADIANCE);
    gltf.add_light_node(sun, Vec3::new(0.0, 3.0, 0.0), SUN_DIRECTION);
    let camera = Camera::perspective("camera", 0.9, None);
    gltf.add_camera_node(camera, Vec3::new(0.0, 2.5, 4.5), Vec3::new(0.0, 0.5, -0.5));
    gltf
}

/// One 0.5 m box mesh (no bottom, no normals: the loader must make flat ones) placed twice —
/// through a parent node with a `matrix` and two children, one rotated and stretched — on a
/// grey floor, lit by a 10 W/sr point light.
pub(crate) fn instanced() -> GltfBuilder {
    let mut gltf = GltfBuilder::new("instanced");
    let grey = gltf.add_material(Material::grey("floor", 0.5));
    let white = gltf.add_material(Material::grey("box", 0.8));
    let floor_mesh = gltf.add_mesh("floor", floor(4.0, 8).without_uv0(), grey);
    gltf.add_mesh_node("floor", floor_mesh);

    let cube = Geometry::box_faces(
        Vec3::new(-0.25, 0.0, -0.25),
        Vec3::new(0.25, 0.5, 0.25),
        &Face::NO_BOTTOM,
        2,
    );
    let box_mesh = gltf.add_mesh("box", cube.without_normals().without_uv0(), white);
    let a = gltf.add_node(
        Node::new("box_a")
            .at(Vec3::new(-0.8, 0.0, 0.0))
            .with_mesh(box_mesh),
    );
    let rotation = Quat::from_rotation_y(30f32.to_radians());
    let b_node =
        Node::new("box_b").trs(Vec3::new(0.8, 0.0, 0.0), rotation, Vec3::new(1.0, 1.6, 1.0));
    let b = gltf.add_node(b_node.with_mesh(box_mesh));
    let parent = Node::new("boxes").matrix(Mat4::from_translation(Vec3::new(0.0, 0.0, -0.25)));
    gltf.add_node(parent.with_children(&[a, b]));

    gltf.add_light_node(
        Light::point("point", [1.0; 3], 10.0),
        Vec3::new(0.0, 2.5, 0.5),
        Vec3::NEG_Y,
    );
    let camera = Camera::perspective("camera", 0.8, None);
    gltf.add_camera_node(camera, Vec3::new(0.0, 2.5, 4.0), Vec3::ZERO);
    gltf
}

/// The two colours of the `textured` checker (sRGB bytes).
pub(crate) const CHECKER_COLORS: [[u8; 3]; 2] = [[220, 220, 220], [200, 60, 40]];

/// A 2 × 2 m floor whose base colour is a 4 × 4 checker texture (a 64 × 64 PNG in the buffer,
/// one square per grid quad), lit by a 5 W/sr point light 1.5 m above its centre. A lone plane
/// receives only direct light, so the lightmap is `5 cos³θ / (π · 1.5²)` whatever the texture.
pub fn textured() -> GltfBuilder {
    let mut gltf = GltfBuilder::new("textured");
    let image = gltf.add_image("checker", &checker(64, 4).into(), ImageStorage::BufferView);
    let material = gltf.add_material(Material::grey("checker", 1.0).with_texture(image));
    let mesh = gltf.add_mesh("floor", floor(2.0, 4), material);
    gltf.add_mesh_node("floor", mesh);
    gltf.add_light_node(
        Light::point("point", [1.0; 3], 5.0),
        Vec3::new(0.0, 1.5, 0.0),
        Vec3::NEG_Y,
    );
    let camera = Camera::perspective("camera", 0.8, None);
    gltf.add_camera_node(camera, Vec3::new(0.0, 2.0, 2.5), Vec3::ZERO);
    gltf
}

/// A 3 × 2 m wall (z = −1, facing +z) whose `normalTexture` ([`dome_normal_map`]) gives it
/// 6 × 4 hemispherical bumps, on a grey floor, lit at a grazing angle by a point light close
/// to its upper left and a dimmer one to its right: the bumps only show when a renderer shades
/// the perturbed normal, which a plain lightmap (one value per texel) cannot. For directional
/// lightmaps (`lightmap::directional`) and the renderer's normal maps.
pub fn normal_mapped_wall() -> GltfBuilder {
    let mut gltf = GltfBuilder::new("normal_mapped_wall");
    let image = gltf.add_image(
        "domes",
        &dome_normal_map(384, 256, 6, 4).into(),
        ImageStorage::BufferView,
    );
    let wall_material =
        gltf.add_material(Material::grey("bumpy wall", 0.8).with_normal_texture(image));
    let floor_material = gltf.add_material(Material::grey("floor", 0.5));
    let wall = Geometry::grid(
        Vec3::new(-1.5, 0.0, -1.0),
        Vec3::X * 3.0,
        Vec3::Y * 2.0,
        6,
        4,
    );
    let wall_mesh = gltf.add_mesh("wall", wall, wall_material);
    gltf.add_mesh_node("wall", wall_mesh);
    let floor_mesh = gltf.add_mesh("floor", floor(3.0, 6), floor_material);
    gltf.add_mesh_node("floor", floor_mesh);
    gltf.add_light_node(
        Light::point("grazing", [1.0, 0.95, 0.85], 3.0),
        Vec3::new(-1.3, 1.9, -0.75),
        Vec3::NEG_Y,
    );
    gltf.add_light_node(
        Light::point("fill", [0.7, 0.8, 1.0], 1.5),
        Vec3::new(1.4, 0.6, 0.2),
        Vec3::NEG_Y,
    );
    let camera = Camera::perspective("camera", 0.9, None);
    gltf.add_camera_node(camera, Vec3::new(0.0, 1.0, 2.2), Vec3::new(0.0, 0.9, -1.0));
    gltf
}

/// A `width × height` tangent-space normal map (glTF convention: +x right, +y up the image,
/// `rgb = (n + 1)/2`) of `across × down` hemispherical domes filling 90% of their cells, flat
/// between them.
pub(crate) fn dome_normal_map(width: u32, height: u32, across: u32, down: u32) -> image::RgbImage {
    let (cw, ch) = (width as f32 / across as f32, height as f32 / down as f32);
    let radius = 0.45 * cw.min(ch);
    image::RgbImage::from_fn(width, height, |x, y| {
        let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);
        let dx = (px - ((px / cw).floor() + 0.5) * cw) / radius;
        let dy = (py - ((py / ch).floor() + 0.5) * ch) / radius;
        let r2 = dx * dx + dy * dy;
        let n = if r2 < 1.0 {
            Vec3::new(dx, -dy, (1.0 - r2).sqrt()).normalize()
        } else {
            Vec3::Z
        };
        let byte = |c: f32| ((c * 0.5 + 0.5) * 255.0).round() as u8;
        image::Rgb([byte(n.x), byte(n.y), byte(n.z)])
    })
}

/// A `size`-pixel square image of `squares × squares` alternating [`CHECKER_COLORS`].
pub fn checker(size: u32, squares: u32) -> image::RgbImage {
    image::RgbImage::from_fn(size, size, |x, y| {
        let square = size / squares;
        image::Rgb(CHECKER_COLORS[((x / square + y / square) % 2) as usize])
    })
}

/// User + system CPU seconds of this process so far (Linux `/proc/self/stat`; 0 elsewhere), for
/// the examples' CPU-utilisation figures.
pub fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    // Fields after the command name (which may hold spaces): utime is the 14th, stime the 15th.
    let rest = stat.rsplit_once(')').map_or("", |r| r.1);
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |k: usize| f.get(k).and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
    (ticks(11) + ticks(12)) / 100.0 // USER_HZ is 100 on Linux
}

/// Emissive ceiling panel of `two_rooms`: radiance per channel.
pub const TWO_ROOMS_PANEL_RADIANCE: f32 = 10.0;

/// Two 2 × 2 × 2 m rooms side by side (x ∈ [−2, 0] is room A, x ∈ [0, 2] room B; z ∈ [−1, 1],
/// y ∈ [0, 2]), separated by a zero-thickness double-sided wall at x = 0 with a 0.8 × 1.6 m
/// doorway. One floor and one ceiling span both rooms (their triangles cross under and over
/// the wall); the outer shell faces inward, single-sided. Room A is lit by an emissive ceiling
/// panel; room B receives light only through the doorway — light leaking under or through the
/// wall shows up as light on B's side of the wall and floor far from the door.
pub fn two_rooms() -> GltfBuilder {
    let mut gltf = GltfBuilder::new("two_rooms");
    let shell = gltf.add_material(Material::grey("shell", 0.7));
    let floor_material = gltf.add_material(Material::grey("floor", 0.5));
    let partition_material = gltf.add_material(Material::grey("partition", 0.7).double_sided());
    let panel_material = gltf
        .add_material(Material::grey("panel", 0.8).emitting([1.0; 3], TWO_ROOMS_PANEL_RADIANCE));

    let (min, max) = (Vec3::new(-2.0, 0.0, -1.0), Vec3::new(2.0, 2.0, 1.0));
    // 7 × 3 quads: no grid line at x = 0, so floor and ceiling triangles straddle the wall.
    let floor = Geometry::box_face(min, max, Face::NegY, 7, 3)
        .flipped()
        .without_uv0();
    let floor_mesh = gltf.add_mesh("floor", floor, floor_material);
    gltf.add_mesh_node("floor", floor_mesh);
    let mut walls = Geometry::box_face(min, max, Face::PosY, 7, 3).flipped();
    walls.append(&Geometry::box_face(min, max, Face::NegX, 4, 4).flipped());
    walls.append(&Geometry::box_face(min, max, Face::PosX, 4, 4).flipped());
    walls.append(&Geometry::box_face(min, max, Face::NegZ, 8, 4).flipped());
    walls.append(&Geometry::box_face(min, max, Face::PosZ, 8, 4).flipped());
    let shell_mesh = gltf.add_mesh("shell", walls.without_uv0(), shell);
    gltf.add_mesh_node("shell", shell_mesh);

    // The partition faces +x (room B); its material is double-sided.
    add_partition_panel_camera(
        &mut gltf,
        0.0,
        [partition_material, panel_material],
        [Vec3::new(1.9, 1.5, 0.9), Vec3::new(-1.0, 0.5, -0.2)],
    );
    gltf
}

/// The partition of the two-room scenes in the plane x = z·`slope` (facing room B, 2 m high,
/// doorway z ∈ [−0.4, 0.4], y ∈ [0, 1.6]), the emissive 1 × 0.8 m ceiling panel of room A and
/// the camera (`[eye, target]`).
fn add_partition_panel_camera(
    gltf: &mut GltfBuilder,
    slope: f32,
    [partition_material, panel_material]: [usize; 2],
    [eye, target]: [Vec3; 2],
) {
    // Written so that slope 0 gives the axis-aligned wall bit for bit (no −0.0 creeps in).
    let piece = |z0: f32, z1: f32, y0: f32, nz: u32, ny: u32| {
        Geometry::grid(
            Vec3::new(0.0, y0, z1) + Vec3::X * (z1 * slope),
            Vec3::NEG_Z * (z1 - z0) + Vec3::X * (slope * (z0 - z1)),
            Vec3::Y * (2.0 - y0),
            nz,
            ny,
        )
    };
    let mut partition = piece(-1.0, -0.4, 0.0, 2, 4);
    partition.append(&piece(0.4, 1.0, 0.0, 2, 4));
    partition.append(&piece(-0.4, 0.4, 1.6, 2, 1));
    let partition_mesh = gltf.add_mesh("partition", partition.without_uv0(), partition_material);
    gltf.add_mesh_node("partition", partition_mesh);

    let panel = Geometry::grid(Vec3::new(-1.5, 1.99, -0.4), Vec3::X, Vec3::Z * 0.8, 1, 1);
    let panel_mesh = gltf.add_mesh("panel", panel.without_uv0(), panel_material);
    gltf.add_mesh_node("panel", panel_mesh);

    let camera = Camera::perspective("camera", 1.2, None);
    gltf.add_camera_node(camera, eye, target);
}

/// `two_rooms` with a wall at an angle and a non-convex floor: the partition turned 20° about
/// the vertical (through the origin: x = z·tan 20°) and room B missing its (x > 1.2, z > 0.2)
/// corner, so floor and ceiling are L-shaped hexagons (each a fan of 4 triangles from the
/// inner corner) and the shell has six walls. Same materials, panel and doorway (z ∈ [−0.4,
/// 0.4] along the wall, 1.6 m high) as `two_rooms`; the camera looks from room B at the
/// wall's foot. Junctions that are not axis-aligned, cutting a non-convex receiver.
pub(crate) fn two_rooms_angled() -> GltfBuilder {
    let mut gltf = GltfBuilder::new("two_rooms_angled");
    let shell = gltf.add_material(Material::grey("shell", 0.7));
    let floor_material = gltf.add_material(Material::grey("floor", 0.5));
    let partition_material = gltf.add_material(Material::grey("partition", 0.7).double_sided());
    let panel_material = gltf
        .add_material(Material::grey("panel", 0.8).emitting([1.0; 3], TWO_ROOMS_PANEL_RADIANCE));

    let outline = [
        Vec2::new(-2.0, -1.0),
        Vec2::new(2.0, -1.0),
        Vec2::new(2.0, 0.2),
        Vec2::new(1.2, 0.2),
        Vec2::new(1.2, 1.0),
        Vec2::new(-2.0, 1.0),
    ];
    let inner_corner = 3;
    let at = |p: Vec2, y: f32| Vec3::new(p.x, y, p.y);
    // A triangle facing `up` (+y or −y), wound to face it.
    let facing = |a: Vec3, b: Vec3, c: Vec3, normal: Vec3| {
        let tri = if (b - a).cross(c - a).dot(normal) > 0.0 {
            [a, b, c]
        } else {
            [a, c, b]
        };
        Geometry::new(&tri, Some(&[normal; 3]), None, &[0, 1, 2])
    };
    let fan = |y: f32, normal: Vec3| {
        let mut g = Geometry::default();
        let n = outline.len();
        for k in 1..n - 1 {
            let (i, j) = ((inner_corner + k) % n, (inner_corner + k + 1) % n);
            g.append(&facing(
                at(outline[inner_corner], y),
                at(outline[i], y),
                at(outline[j], y),
                normal,
            ));
        }
        g
    };
    let floor_mesh = gltf.add_mesh("floor", fan(0.0, Vec3::Y), floor_material);
    gltf.add_mesh_node("floor", floor_mesh);
    let mut walls = fan(2.0, Vec3::NEG_Y);
    for k in 0..outline.len() {
        let (a, b) = (outline[k], outline[(k + 1) % outline.len()]);
        // The room lies left of each outline edge (x, z) → (−dz, dx).
        let wall = Geometry::grid(at(a, 0.0), at(b - a, 0.0), Vec3::Y * 2.0, 2, 2).without_uv0();
        let inward = Vec3::new(-(b - a).y, 0.0, (b - a).x).normalize();
        let outward_facing = at(b - a, 0.0).cross(Vec3::Y).dot(inward) < 0.0;
        walls.append(&if outward_facing { wall.flipped() } else { wall });
    }
    let shell_mesh = gltf.add_mesh("shell", walls, shell);
    gltf.add_mesh_node("shell", shell_mesh);

    add_partition_panel_camera(
        &mut gltf,
        20f32.to_radians().tan(),
        [partition_material, panel_material],
        [Vec3::new(1.6, 1.4, -0.6), Vec3::new(0.0, 0.2, -0.1)],
    );
    gltf
}

/// A `size × size` m floor at y = 0 centred at the origin, facing up, `n × n` quads.
fn floor(size: f32, n: u32) -> Geometry {
    let half = size / 2.0;
    Geometry::grid(
        Vec3::new(-half, 0.0, half),
        Vec3::X * size,
        Vec3::NEG_Z * size,
        n,
        n,
    )
}

/// A 100k-triangle hall for speed measurements (not a committed fixture: it is generated on
/// demand). A 24 × 24 m room, 6 m high, finely tessellated floor and ceiling (as a scanned or
/// sculpted asset would be), a 6 × 6 grid of pillars, eight emissive ceiling panels
/// (Le = 20), and a sun through nothing (the hall is closed): all light is from the panels.
pub fn large_hall() -> GltfBuilder {
    let mut gltf = GltfBuilder::new("large_hall");
    let floor_m = gltf.add_material(Material::grey("floor", 0.5));
    let walls_m = gltf.add_material(Material::diffuse("walls", [0.7, 0.65, 0.55]));
    let pillar_m = gltf.add_material(Material::diffuse("pillars", [0.3, 0.4, 0.6]));
    let panel_m = gltf.add_material(Material::grey("panel", 0.8).emitting([1.0; 3], 20.0));
    let (half, height) = (12.0f32, 6.0f32);

    // Floor and ceiling: 160 × 160 quads each (51 200 triangles each).
    let floor = Geometry::grid(
        Vec3::new(-half, 0.0, half),
        Vec3::X * 2.0 * half,
        -Vec3::Z * 2.0 * half,
        160,
        160,
    );
    let ceiling = Geometry::grid(
        Vec3::new(-half, height, -half),
        Vec3::X * 2.0 * half,
        Vec3::Z * 2.0 * half,
        160,
        160,
    );
    let shell = gltf.add_mesh("floor", floor, floor_m);
    gltf.add_primitive(shell, ceiling, walls_m);
    let (min, max) = (Vec3::new(-half, 0.0, -half), Vec3::new(half, height, half));
    let mut walls = Geometry::box_face(min, max, Face::PosX, 24, 6).flipped();
    for face in [Face::NegX, Face::PosZ, Face::NegZ] {
        walls.append(&Geometry::box_face(min, max, face, 24, 6).flipped());
    }
    gltf.add_primitive(shell, walls, walls_m);
    gltf.add_mesh_node("hall", shell);

    // Pillars: one mesh, 36 nodes.
    let pillar = Geometry::box_faces(
        Vec3::new(-0.4, 0.0, -0.4),
        Vec3::new(0.4, height, 0.4),
        &Face::NO_BOTTOM,
        6,
    );
    let pillar_mesh = gltf.add_mesh("pillar", pillar, pillar_m);
    for i in 0..6 {
        for j in 0..6 {
            let at = Vec3::new(-8.75 + 3.5 * i as f32, 0.0, -8.75 + 3.5 * j as f32);
            gltf.add_node(
                Node::new(&format!("pillar_{i}_{j}"))
                    .at(at)
                    .with_mesh(pillar_mesh),
            );
        }
    }

    // Eight ceiling panels facing down, just below the ceiling.
    let panel = Geometry::grid(
        Vec3::new(-1.0, height - 0.01, -0.5),
        Vec3::X * 2.0,
        Vec3::Z * 1.0,
        1,
        1,
    );
    let panel_mesh = gltf.add_mesh("panel", panel, panel_m);
    for i in 0..4 {
        for j in 0..2 {
            let at = Vec3::new(-7.0 + 4.67 * i as f32, 0.0, -4.0 + 8.0 * j as f32);
            gltf.add_node(
                Node::new(&format!("panel_{i}_{j}"))
                    .at(at)
                    .with_mesh(panel_mesh),
            );
        }
    }
    let camera = Camera::perspective("camera", 60f32.to_radians(), Some(16.0 / 9.0));
    gltf.add_camera_node(
        camera,
        Vec3::new(-10.0, 2.0, 10.0),
        Vec3::new(2.0, 1.5, -2.0),
    );
    gltf
}

/// Height of the wavy field of [`height_field`] at (x, z) and its gradient (m, per m).
fn wave(x: f32, z: f32) -> (f32, Vec2) {
    use std::f32::consts::TAU;
    let (a, b) = (TAU * (1.5 * x + 0.3), TAU * 1.2 * z);
    let c = TAU * (4.0 * x + 3.0 * z);
    let h = 0.02 * a.sin() * b.cos() + 0.006 * c.sin();
    let dx = 0.02 * TAU * 1.5 * a.cos() * b.cos() + 0.006 * TAU * 4.0 * c.cos();
    let dz = -0.02 * TAU * 1.2 * a.sin() * b.sin() + 0.006 * TAU * 3.0 * c.cos();
    (h, Vec2::new(dx, dz))
}

/// A wavy 1 × 1 m height field of `quads × quads` squares cut into two triangles each (smooth
/// normals, connected), centred at `center`, facing +y; waves of ±2.6 cm, slopes up to about
/// 15°. 708 quads give 1 002 528 triangles of 1.4 mm: a scanned or sculpted surface.
pub(crate) fn wavy_field(center: Vec3, quads: u32) -> Geometry {
    let mut field = Geometry::grid(
        center + Vec3::new(-0.5, 0.0, 0.5),
        Vec3::X,
        Vec3::NEG_Z,
        quads,
        quads,
    )
    .without_uv0();
    let normals = field.normals.as_mut().expect("grid normals");
    for (p, n) in field.positions.iter_mut().zip(normals) {
        let (h, grad) = wave(p.x - center.x, p.z - center.z);
        p.y = center.y + h;
        *n = Vec3::new(-grad.x, 1.0, -grad.y).normalize();
    }
    field
}

/// The dense-mesh benchmark (not a committed fixture: generated on demand): a wavy 1 × 1 m
/// height field of at least `triangles` triangles ([`wavy_field`] with ⌈√(triangles/2)⌉ quads a
/// side; 1 000 000 gives the 1 002 528 of issue 28) under one point light 1 m above it.
pub fn height_field(triangles: usize) -> GltfBuilder {
    let quads = ((triangles as f64 / 2.0).sqrt().ceil() as u32).max(1);
    let mut gltf = GltfBuilder::new("height_field");
    let material = gltf.add_material(Material::grey("field", 0.6));
    let mesh = gltf.add_mesh("field", wavy_field(Vec3::ZERO, quads), material);
    gltf.add_mesh_node("field", mesh);
    gltf.add_light_node(
        Light::point("light", [1.0; 3], 2.0),
        Vec3::new(0.2, 1.0, 0.1),
        Vec3::NEG_Y,
    );
    let camera = Camera::perspective("camera", 0.8, None);
    gltf.add_camera_node(camera, Vec3::new(0.0, 1.0, 1.4), Vec3::ZERO);
    gltf
}

/// The dense-room benchmark (not a committed fixture): a 5 × 3 × 5 m room (coarse walls) under
/// a point light, holding four dense props of about `triangles / 4` triangles each — two wavy
/// 1 × 1 m fields ([`wavy_field`]) on the floor and two smooth spheres of radius 0.35 m.
pub fn dense_room(triangles: usize) -> GltfBuilder {
    let per_prop = triangles as f64 / 4.0;
    let mut gltf = GltfBuilder::new("dense_room");
    let walls_m = gltf.add_material(Material::grey("walls", 0.7));
    let field_m = gltf.add_material(Material::diffuse("field", [0.5, 0.6, 0.4]));
    let sphere_m = gltf.add_material(Material::diffuse("sphere", [0.8, 0.6, 0.5]));
    let (min, max) = (Vec3::new(-2.5, 0.0, -2.5), Vec3::new(2.5, 3.0, 2.5));
    let room = Geometry::box_faces(min, max, &Face::ALL, 10).flipped();
    let room_mesh = gltf.add_mesh("room", room, walls_m);
    gltf.add_mesh_node("room", room_mesh);
    let quads = ((per_prop / 2.0).sqrt().ceil() as u32).max(1);
    for (k, x) in [-1.2f32, 1.2].into_iter().enumerate() {
        let field = wavy_field(Vec3::new(x, 0.03, -1.0), quads);
        let mesh = gltf.add_mesh(&format!("field_{k}"), field, field_m);
        gltf.add_mesh_node(&format!("field_{k}"), mesh);
    }
    // nu = 2·nv segments: 4·nv² − 4·nv triangles.
    let rings = (((per_prop / 4.0).sqrt()).ceil() as u32 + 1).max(2);
    for (k, x) in [-1.0f32, 1.0].into_iter().enumerate() {
        let sphere = Geometry::uv_sphere(Vec3::new(x, 0.35, 1.0), 0.35, 2 * rings, rings);
        let mesh = gltf.add_mesh(&format!("sphere_{k}"), sphere.without_uv0(), sphere_m);
        gltf.add_mesh_node(&format!("sphere_{k}"), mesh);
    }
    gltf.add_light_node(
        Light::point("light", [1.0; 3], 30.0),
        Vec3::new(0.3, 2.8, 0.2),
        Vec3::NEG_Y,
    );
    let camera = Camera::perspective("camera", 1.0, None);
    gltf.add_camera_node(camera, Vec3::new(0.0, 2.0, 2.4), Vec3::new(0.0, 0.3, 0.0));
    gltf
}

/// A smooth sphere (radius 0.5, 24 × 12 segments) on a 3 × 3 m floor under a point light and
/// a dim sky: xatlas cuts the sphere into several charts, so its lightmap has UV seams across
/// a smooth surface (`lightmap::seams`). Not a committed fixture: generated on demand.
pub fn sphere_on_floor() -> GltfBuilder {
    let mut gltf = GltfBuilder::new("sphere_on_floor");
    let floor_m = gltf.add_material(Material::grey("floor", 0.5));
    let sphere_m = gltf.add_material(Material::diffuse("sphere", [0.8, 0.7, 0.6]));
    let floor_mesh = gltf.add_mesh("floor", floor(3.0, 4), floor_m);
    gltf.add_mesh_node("floor", floor_mesh);
    let sphere = Geometry::uv_sphere(Vec3::new(0.0, 0.5, 0.0), 0.5, 24, 12);
    let sphere_mesh = gltf.add_mesh("sphere", sphere, sphere_m);
    gltf.add_mesh_node("sphere", sphere_mesh);
    gltf.add_light_node(
        Light::point("light", [1.0; 3], 8.0),
        Vec3::new(0.8, 2.0, 0.6),
        Vec3::NEG_Y,
    );
    let camera = Camera::perspective("camera", 0.8, None);
    gltf.add_camera_node(camera, Vec3::new(0.0, 1.2, 2.6), Vec3::new(0.0, 0.4, 0.0));
    gltf
}

/// A 3 × 3 m floor of tiles whose edges meet in T-junctions, lit by a point light (not a
/// committed fixture). Row z ∈ [0, 1] is one quad; row z ∈ [1, 2] is three 1 m tiles in the
/// same primitive, so the long quad's edge meets two tile corners in its middle; row
/// z ∈ [2, 3] is another node with two 1.5 m tiles, overlapping the middle tile of row 1 half
/// each (edges sharing only a part, between instances).
pub fn t_junction_floor() -> GltfBuilder {
    let mut gltf = GltfBuilder::new("t_junction_floor");
    let material = gltf.add_material(Material::grey("floor", 0.5));
    // Tiles x ∈ [x0, x1], z ∈ [z0, z0 + 1], facing up.
    let tile = |x0: f32, x1: f32, z0: f32| {
        Geometry::grid(
            Vec3::new(x0, 0.0, z0 + 1.0),
            Vec3::X * (x1 - x0),
            Vec3::NEG_Z,
            1,
            1,
        )
    };
    let mut near = tile(0.0, 3.0, 0.0);
    for x in 0..3 {
        near.append(&tile(x as f32, x as f32 + 1.0, 1.0));
    }
    let near_mesh = gltf.add_mesh("near", near.without_uv0(), material);
    gltf.add_mesh_node("near", near_mesh);
    let mut far = tile(0.0, 1.5, 2.0);
    far.append(&tile(1.5, 3.0, 2.0));
    let far_mesh = gltf.add_mesh("far", far.without_uv0(), material);
    gltf.add_mesh_node("far", far_mesh);
    gltf.add_light_node(
        Light::point("light", [1.0; 3], 6.0),
        Vec3::new(1.2, 1.5, 1.7),
        Vec3::NEG_Y,
    );
    gltf
}

/// A sun-lit courtyard, directional light only (no sky): an 12 × 12 m paved ground, walls of
/// several heights (1.2, 2, 3 and 4 m, closed 0.3 m solids standing on it), and a pillar whose
/// node is rotated about two axes and scaled non-uniformly. Every shadow is a hard edge cast
/// by one parallel light: the case texel density matters most for.
pub(crate) fn courtyard() -> GltfBuilder {
    let mut gltf = GltfBuilder::new("courtyard");
    let ground_m = gltf.add_material(Material::grey("ground", 0.4));
    let wall_m = gltf.add_material(Material::diffuse("wall", [0.75, 0.68, 0.55]));
    let pillar_m = gltf.add_material(Material::diffuse("pillar", [0.55, 0.6, 0.7]));
    let ground = gltf.add_mesh("ground", floor(12.0, 12).without_uv0(), ground_m);
    gltf.add_mesh_node("ground", ground);
    // (min, max) of each wall: the courtyard is open towards +z; the sun, low from behind the
    // north wall, casts the walls' shadows across it.
    let walls = [
        (Vec3::new(-4.0, 0.0, -4.3), Vec3::new(4.0, 4.0, -4.0)),
        (Vec3::new(-4.3, 0.0, -4.0), Vec3::new(-4.0, 3.0, 3.0)),
        (Vec3::new(4.0, 0.0, -4.0), Vec3::new(4.3, 2.0, 1.5)),
        (Vec3::new(-1.5, 0.0, 1.2), Vec3::new(1.5, 1.2, 1.5)),
    ];
    for (k, (min, max)) in walls.into_iter().enumerate() {
        let n = ((max - min).max_element() * 0.5).ceil() as u32;
        let solid = Geometry::box_faces(min, max, &Face::ALL, n).without_uv0();
        let mesh = gltf.add_mesh(&format!("wall_{k}"), solid, wall_m);
        gltf.add_mesh_node(&format!("wall_{k}"), mesh);
    }
    let unit = Geometry::box_faces(
        Vec3::new(-0.5, 0.0, -0.5),
        Vec3::new(0.5, 1.0, 0.5),
        &Face::ALL,
        2,
    )
    .without_uv0();
    let pillar = gltf.add_mesh("pillar", unit, pillar_m);
    let turn = Quat::from_rotation_y(0.6) * Quat::from_rotation_z(0.12);
    gltf.add_node(
        Node::new("pillar")
            .trs(Vec3::new(1.2, -0.05, -1.0), turn, Vec3::new(0.35, 2.6, 0.7))
            .with_mesh(pillar),
    );
    let sun = Light::directional("sun", [1.0, 0.96, 0.9], 3.0);
    gltf.add_light_node(sun, Vec3::new(0.0, 6.0, 0.0), Vec3::new(0.5, -0.7, 0.55));
    let camera = Camera::perspective("camera", 1.0, Some(1.5));
    gltf.add_camera_node(camera, Vec3::new(3.0, 5.0, 9.0), Vec3::new(-0.5, 0.5, -1.0));
    gltf
}

/// A closed room (5 × 4 m, 2.8 m high, facing inward) lit only by a point light under the
/// ceiling and a spot light aimed at a table; a table (thin top, four thin legs) and a cabinet
/// (a closed box against a wall). Punctual lights only: hard shadows, a spot-cone edge, and
/// all the rest is interreflection.
pub(crate) fn lamp_room() -> GltfBuilder {
    let mut gltf = GltfBuilder::new("lamp_room");
    let walls_m = gltf.add_material(Material::diffuse("walls", [0.75, 0.72, 0.66]));
    let floor_m = gltf.add_material(Material::diffuse("floor", [0.45, 0.35, 0.25]));
    let wood_m = gltf.add_material(Material::diffuse("wood", [0.6, 0.42, 0.28]));
    let cabinet_m = gltf.add_material(Material::diffuse("cabinet", [0.3, 0.45, 0.4]));
    let (min, max) = (Vec3::new(-2.5, 0.0, -2.0), Vec3::new(2.5, 2.8, 2.0));
    let shell = gltf.add_mesh(
        "floor",
        Geometry::box_face(min, max, Face::NegY, 10, 8)
            .flipped()
            .without_uv0(),
        floor_m,
    );
    let mut walls = Geometry::box_face(min, max, Face::PosY, 10, 8).flipped();
    for face in [Face::NegX, Face::PosX, Face::NegZ, Face::PosZ] {
        walls.append(&Geometry::box_face(min, max, face, 8, 6).flipped());
    }
    gltf.add_primitive(shell, walls.without_uv0(), walls_m);
    gltf.add_mesh_node("room", shell);

    let mut table = Geometry::box_faces(
        Vec3::new(-0.7, 0.72, -0.4),
        Vec3::new(0.7, 0.76, 0.4),
        &Face::ALL,
        4,
    );
    for (x, z) in [(-0.65, -0.35), (0.61, -0.35), (-0.65, 0.31), (0.61, 0.31)] {
        table.append(&Geometry::box_faces(
            Vec3::new(x, 0.0, z),
            Vec3::new(x + 0.04, 0.72, z + 0.04),
            &Face::NO_BOTTOM,
            1,
        ));
    }
    let table = gltf.add_mesh("table", table.without_uv0(), wood_m);
    gltf.add_node(
        Node::new("table")
            .trs(
                Vec3::new(0.3, 0.0, 0.2),
                Quat::from_rotation_y(0.3),
                Vec3::ONE,
            )
            .with_mesh(table),
    );
    let cabinet = Geometry::box_faces(
        Vec3::new(-0.45, 0.0, -0.22),
        Vec3::new(0.45, 1.8, 0.22),
        &Face::ALL,
        4,
    );
    let cabinet = gltf.add_mesh("cabinet", cabinet.without_uv0(), cabinet_m);
    gltf.add_node(
        Node::new("cabinet")
            .at(Vec3::new(-1.6, 0.0, -1.75))
            .with_mesh(cabinet),
    );
    gltf.add_light_node(
        Light::point("bulb", [1.0, 0.9, 0.75], 12.0),
        Vec3::new(1.2, 2.5, -0.8),
        Vec3::NEG_Y,
    );
    let spot = Light::spot("spot", [0.9, 0.95, 1.0], 40.0, 0.2, 0.32).with_range(10.0);
    let spot_at = Vec3::new(-2.2, 2.6, 1.7);
    gltf.add_light_node(spot, spot_at, Vec3::new(0.3, 0.76, 0.2) - spot_at);
    let camera = Camera::perspective("camera", 1.1, Some(1.25));
    gltf.add_camera_node(camera, Vec3::new(2.2, 1.9, 1.8), Vec3::new(-0.6, 0.6, -0.6));
    gltf
}

/// A furnished interior of over 50 000 triangles: a 8 × 6 m room, 3 m high, whose walls, floor
/// and ceiling are closed 0.2 m solids with finely tessellated inner faces (as a scanned or
/// sculpted asset comes), two tables with thin legs, eight chairs with slatted backs, a
/// bookcase of small books, cups and bottles (smooth cylinders), a rug (1 cm thick), picture
/// frames, two emissive ceiling panels and a point-lit lamp. Thin and small objects get few
/// texels at a uniform density; the walls' outer faces are seen by nothing.
pub(crate) fn furnished_interior() -> GltfBuilder {
    let mut gltf = GltfBuilder::new("furnished_interior");
    let materials = InteriorMaterials::add(&mut gltf);
    add_interior_shell(&mut gltf, &materials);
    add_dining_tables(&mut gltf, &materials);
    add_bookcase(&mut gltf, &materials);
    add_rug_sofa_and_frames(&mut gltf, &materials);
    add_lamp_and_panels(&mut gltf, &materials);
    let camera = Camera::perspective("camera", 1.2, Some(1.5));
    gltf.add_camera_node(camera, Vec3::new(3.6, 2.2, 2.7), Vec3::new(-1.0, 0.7, -0.8));
    gltf
}

/// [`furnished_interior`]'s room (metres): half its inner width (x) and depth (z), its inner
/// height, and the thickness of its walls, floor and ceiling.
const INTERIOR_HALF_X: f32 = 4.0;
const INTERIOR_HALF_Z: f32 = 3.0;
const INTERIOR_HEIGHT: f32 = 3.0;
const INTERIOR_WALL: f32 = 0.2;

/// [`furnished_interior`]'s materials, added first (their order is the file's).
struct InteriorMaterials {
    plaster: usize,
    boards: usize,
    wood: usize,
    fabric: usize,
    rug: usize,
    paper: usize,
    glaze: usize,
    glass: usize,
    panel: usize,
}

impl InteriorMaterials {
    fn add(gltf: &mut GltfBuilder) -> Self {
        InteriorMaterials {
            plaster: gltf.add_material(Material::diffuse("plaster", [0.78, 0.76, 0.72])),
            boards: gltf.add_material(Material::diffuse("boards", [0.5, 0.38, 0.26])),
            wood: gltf.add_material(Material::diffuse("wood", [0.55, 0.36, 0.22])),
            fabric: gltf.add_material(Material::diffuse("fabric", [0.25, 0.35, 0.6])),
            rug: gltf.add_material(Material::diffuse("rug", [0.6, 0.15, 0.12])),
            paper: gltf.add_material(Material::diffuse("paper", [0.8, 0.78, 0.7])),
            glaze: gltf.add_material(Material::diffuse("glaze", [0.85, 0.85, 0.9])),
            glass: gltf.add_material(Material::diffuse("bottle", [0.2, 0.45, 0.25])),
            panel: gltf.add_material(Material::grey("panel", 0.8).emitting([1.0, 0.97, 0.9], 12.0)),
        }
    }
}

/// The room's floor, ceiling and four walls: closed solids, each its own mesh and node.
fn add_interior_shell(gltf: &mut GltfBuilder, materials: &InteriorMaterials) {
    let (half_x, half_z, height, wall) = (
        INTERIOR_HALF_X,
        INTERIOR_HALF_Z,
        INTERIOR_HEIGHT,
        INTERIOR_WALL,
    );
    let (boards, plaster) = (materials.boards, materials.plaster);
    let solids = [
        (
            "floor",
            Vec3::new(-half_x, -wall, -half_z),
            Vec3::new(half_x, 0.0, half_z),
            Face::PosY,
            boards,
        ),
        (
            "ceiling",
            Vec3::new(-half_x, height, -half_z),
            Vec3::new(half_x, height + wall, half_z),
            Face::NegY,
            plaster,
        ),
        (
            "wall_north",
            Vec3::new(-half_x - wall, -wall, -half_z - wall),
            Vec3::new(half_x + wall, height + wall, -half_z),
            Face::PosZ,
            plaster,
        ),
        (
            "wall_south",
            Vec3::new(-half_x - wall, -wall, half_z),
            Vec3::new(half_x + wall, height + wall, half_z + wall),
            Face::NegZ,
            plaster,
        ),
        (
            "wall_west",
            Vec3::new(-half_x - wall, -wall, -half_z),
            Vec3::new(-half_x, height + wall, half_z),
            Face::PosX,
            plaster,
        ),
        (
            "wall_east",
            Vec3::new(half_x, -wall, -half_z),
            Vec3::new(half_x + wall, height + wall, half_z),
            Face::NegX,
            plaster,
        ),
    ];
    for (name, min, max, inner, material) in solids {
        let mesh = gltf.add_mesh(name, slab(min, max, inner), material);
        gltf.add_mesh_node(name, mesh);
    }
}

/// A closed box whose `inner` face is tessellated every 8 cm (what a scanned or sculpted asset
/// gives); its other faces (outside, and ends buried in the neighbouring solids) are one quad
/// each.
fn slab(min: Vec3, max: Vec3, inner: Face) -> Geometry {
    let size = max - min;
    let mut g = Geometry::default();
    for face in Face::ALL {
        let (nu, nv) = if face == inner {
            let [u, v] = match face {
                Face::PosY | Face::NegY => [size.x, size.z],
                Face::PosX | Face::NegX => [size.z, size.y],
                Face::PosZ | Face::NegZ => [size.x, size.y],
            };
            ((u * 12.5).round() as u32, (v * 12.5).round() as u32)
        } else {
            (1, 1)
        };
        g.append(&Geometry::box_face(min, max, face, nu.max(1), nv.max(1)));
    }
    g.without_uv0().without_normals()
}

/// A box of one quad per face, without base UVs: the furniture's building block.
fn cuboid(min: Vec3, max: Vec3) -> Geometry {
    Geometry::box_faces(min, max, &Face::ALL, 1).without_uv0()
}

/// A node placing `mesh` at `at`, turned by `turn` about +Y.
fn place(gltf: &mut GltfBuilder, name: &str, mesh: usize, at: Vec3, turn: f32) {
    gltf.add_node(
        Node::new(name)
            .trs(at, Quat::from_rotation_y(turn), Vec3::ONE)
            .with_mesh(mesh),
    );
}

/// Two tables, four chairs around each, and cups and bottles on them.
fn add_dining_tables(gltf: &mut GltfBuilder, materials: &InteriorMaterials) {
    // Tables: a 4 cm top, four 4 cm legs.
    let mut table = cuboid(Vec3::new(-0.8, 0.72, -0.45), Vec3::new(0.8, 0.76, 0.45));
    for (x, z) in [(-0.75, -0.4), (0.71, -0.4), (-0.75, 0.36), (0.71, 0.36)] {
        table.append(&cuboid(
            Vec3::new(x, 0.0, z),
            Vec3::new(x + 0.04, 0.72, z + 0.04),
        ));
    }
    let table = gltf.add_mesh("table", table, materials.wood);
    // Chairs: seat, 3 cm legs, a back of five 2 cm slats.
    let mut chair = cuboid(Vec3::new(-0.22, 0.44, -0.22), Vec3::new(0.22, 0.47, 0.22));
    for (x, z) in [(-0.21, -0.21), (0.18, -0.21), (-0.21, 0.18), (0.18, 0.18)] {
        chair.append(&cuboid(
            Vec3::new(x, 0.0, z),
            Vec3::new(x + 0.03, 0.44, z + 0.03),
        ));
    }
    for k in 0..5 {
        let x = -0.2 + 0.09 * k as f32;
        chair.append(&cuboid(
            Vec3::new(x, 0.47, 0.19),
            Vec3::new(x + 0.02, 0.9, 0.22),
        ));
    }
    let chair = gltf.add_mesh("chair", chair, materials.fabric);
    for (t, centre) in [Vec3::new(-1.6, 0.0, 0.2), Vec3::new(1.6, 0.0, -0.4)]
        .into_iter()
        .enumerate()
    {
        place(gltf, &format!("table_{t}"), table, centre, 0.0);
        for (c, (dx, dz, turn)) in [
            (-0.45, 0.6, 0.0),
            (0.45, 0.6, 0.0),
            (-0.45, -0.6, PI),
            (0.45, -0.6, PI),
        ]
        .into_iter()
        .enumerate()
        {
            let at = centre + Vec3::new(dx, 0.0, dz);
            place(
                gltf,
                &format!("chair_{t}_{c}"),
                chair,
                at,
                turn + 0.05 * c as f32,
            );
        }
    }
    // Cups and bottles on the tables: smooth cylinders.
    let cup = gltf.add_mesh(
        "cup",
        Geometry::cylinder(Vec3::ZERO, 0.04, 0.1, 24).without_uv0(),
        materials.glaze,
    );
    let bottle = gltf.add_mesh(
        "bottle",
        Geometry::cylinder(Vec3::ZERO, 0.035, 0.3, 24).without_uv0(),
        materials.glass,
    );
    for (k, (x, z)) in [
        (-1.9, 0.0),
        (-1.4, 0.35),
        (1.3, -0.6),
        (1.8, -0.2),
        (1.5, -0.15),
    ]
    .into_iter()
    .enumerate()
    {
        place(gltf, &format!("cup_{k}"), cup, Vec3::new(x, 0.76, z), 0.0);
    }
    for (k, (x, z)) in [(-1.6, 0.15), (1.7, -0.5)].into_iter().enumerate() {
        place(
            gltf,
            &format!("bottle_{k}"),
            bottle,
            Vec3::new(x, 0.76, z),
            0.0,
        );
    }
}

/// A bookcase against the west wall: a carcass of 2 cm boards, four shelves of books.
fn add_bookcase(gltf: &mut GltfBuilder, materials: &InteriorMaterials) {
    let mut case = Geometry::default();
    for (min, max) in [
        (Vec3::new(0.0, 0.0, -0.6), Vec3::new(0.3, 2.0, -0.58)),
        (Vec3::new(0.0, 0.0, 0.58), Vec3::new(0.3, 2.0, 0.6)),
        (Vec3::new(0.0, 0.0, -0.58), Vec3::new(0.02, 2.0, 0.58)),
    ] {
        case.append(&cuboid(min, max));
    }
    for s in 0..5 {
        let y = 0.02 + 0.48 * s as f32;
        case.append(&cuboid(
            Vec3::new(0.02, y - 0.02, -0.58),
            Vec3::new(0.3, y, 0.58),
        ));
    }
    let at = Vec3::new(-INTERIOR_HALF_X, 0.0, -1.2);
    let case = gltf.add_mesh("bookcase", case, materials.wood);
    place(gltf, "bookcase", case, at, 0.0);
    let mut books = Geometry::default();
    for s in 0..4 {
        let y = 0.02 + 0.48 * s as f32;
        let mut z = -0.56;
        let mut k = 0;
        while z < 0.5 {
            let width = 0.025 + 0.01 * ((k * 7 + s * 3) % 4) as f32;
            let tall = 0.22 + 0.03 * ((k * 5 + s) % 5) as f32;
            books.append(&cuboid(
                Vec3::new(0.05, y, z),
                Vec3::new(0.27, y + tall, z + width),
            ));
            z += width + 0.004;
            k += 1;
        }
    }
    let books = gltf.add_mesh("books", books, materials.paper);
    place(gltf, "books", books, at, 0.0);
}

/// A 1 cm rug, a sofa of boxes, picture frames 2 cm off the north wall.
fn add_rug_sofa_and_frames(gltf: &mut GltfBuilder, materials: &InteriorMaterials) {
    let rug = gltf.add_mesh(
        "rug",
        cuboid(Vec3::new(-1.2, 0.0, -0.9), Vec3::new(1.2, 0.01, 0.9)),
        materials.rug,
    );
    place(gltf, "rug", rug, Vec3::new(0.0, 0.0, 1.6), 0.0);
    let mut sofa = cuboid(Vec3::new(-1.0, 0.0, -0.4), Vec3::new(1.0, 0.42, 0.4));
    sofa.append(&cuboid(
        Vec3::new(-1.0, 0.42, 0.25),
        Vec3::new(1.0, 0.85, 0.4),
    ));
    sofa.append(&cuboid(
        Vec3::new(-1.0, 0.42, -0.4),
        Vec3::new(-0.85, 0.62, 0.25),
    ));
    sofa.append(&cuboid(
        Vec3::new(0.85, 0.42, -0.4),
        Vec3::new(1.0, 0.62, 0.25),
    ));
    let sofa = gltf.add_mesh("sofa", sofa, materials.fabric);
    place(gltf, "sofa", sofa, Vec3::new(0.2, 0.0, 2.5), 0.0);
    let frame = gltf.add_mesh(
        "frame",
        cuboid(Vec3::new(-0.4, -0.3, 0.0), Vec3::new(0.4, 0.3, 0.02)),
        materials.paper,
    );
    for (k, x) in [-2.0f32, 0.5, 2.6].into_iter().enumerate() {
        let at = Vec3::new(x, 1.7, -INTERIOR_HALF_Z);
        place(gltf, &format!("frame_{k}"), frame, at, 0.0);
    }
}

/// The lights: a floor lamp (a thin stand, a point light under a shade) and two emissive
/// ceiling panels.
fn add_lamp_and_panels(gltf: &mut GltfBuilder, materials: &InteriorMaterials) {
    let mut lamp = Geometry::cylinder(Vec3::ZERO, 0.015, 1.5, 12);
    lamp.append(&Geometry::cylinder(
        Vec3::new(0.0, 1.5, 0.0),
        0.18,
        0.22,
        32,
    ));
    let lamp = gltf.add_mesh("lamp", lamp.without_uv0(), materials.paper);
    place(gltf, "lamp", lamp, Vec3::new(3.3, 0.0, 2.3), 0.0);
    gltf.add_light_node(
        Light::point("lamp_bulb", [1.0, 0.85, 0.65], 4.0),
        Vec3::new(3.3, 1.4, 2.3),
        Vec3::NEG_Y,
    );
    let panel = Geometry::grid(
        Vec3::new(-0.6, INTERIOR_HEIGHT - 0.01, -0.3),
        Vec3::X * 1.2,
        Vec3::Z * 0.6,
        1,
        1,
    );
    let panel = gltf.add_mesh("panel", panel.without_uv0(), materials.panel);
    for (k, x) in [-1.6f32, 1.6].into_iter().enumerate() {
        place(
            gltf,
            &format!("panel_{k}"),
            panel,
            Vec3::new(x, 0.0, 0.0),
            0.0,
        );
    }
}

/// Narrow faces of [`narrow_faces`]: a name, a world box (min, max) around the face and its
/// outward normal (zero: any horizontal normal). Faces narrower than two texels at every
/// preset, in slots or beside bright surfaces, where a texel that reads light from beyond the
/// face's edge shows (issue 27).
pub(crate) const NARROW_FACES: [(&str, Vec3, Vec3, Vec3); 9] = [
    // The door's top: 4 cm deep, 4 mm under the head of its lining.
    (
        "door top",
        Vec3::new(-1.43, 2.075, -1.54),
        Vec3::new(-0.573, 2.077, -1.5),
        Vec3::Y,
    ),
    // The door's bottom: 4 cm deep, 8 mm over the threshold.
    (
        "door bottom",
        Vec3::new(-1.43, 0.007, -1.54),
        Vec3::new(-0.573, 0.009, -1.5),
        Vec3::NEG_Y,
    ),
    // The door's latch edge: 4 cm deep, 3 mm from the jamb.
    (
        "door edge",
        Vec3::new(-0.574, 0.008, -1.54),
        Vec3::new(-0.572, 2.076, -1.5),
        Vec3::X,
    ),
    // The shelf board's front edge: 2 cm tall, 1 cm proud of the wall.
    (
        "shelf front",
        Vec3::new(1.989, 1.18, -0.4),
        Vec3::new(1.991, 1.2, 0.4),
        Vec3::NEG_X,
    ),
    // The ceiling light's border: 1.5 cm of white round its emitting face, four strips.
    (
        "light border",
        Vec3::new(-0.431, 2.619, -0.331),
        Vec3::new(-0.415, 2.621, 0.331),
        Vec3::NEG_Y,
    ),
    (
        "light border",
        Vec3::new(0.415, 2.619, -0.331),
        Vec3::new(0.431, 2.621, 0.331),
        Vec3::NEG_Y,
    ),
    (
        "light border",
        Vec3::new(-0.415, 2.619, -0.331),
        Vec3::new(0.415, 2.621, -0.315),
        Vec3::NEG_Y,
    ),
    (
        "light border",
        Vec3::new(-0.415, 2.619, 0.315),
        Vec3::new(0.415, 2.621, 0.331),
        Vec3::NEG_Y,
    ),
    // The light's sides (4 cm) and the recess's walls (6 cm), 2 cm apart.
    (
        "light recess",
        Vec3::new(-0.451, 2.6, -0.351),
        Vec3::new(0.451, 2.66, 0.351),
        Vec3::ZERO,
    ),
];

/// Whether a point at `position` on a face with unit normal `normal` lies on one of the
/// [`NARROW_FACES`]; its name if so.
pub fn narrow_face(position: Vec3, normal: Vec3) -> Option<&'static str> {
    NARROW_FACES.iter().find_map(|&(name, min, max, n)| {
        let facing = if n == Vec3::ZERO {
            normal.y.abs() < 0.1
        } else {
            normal.dot(n) > 0.99
        };
        (facing && position.cmpge(min).all() && position.cmple(max).all()).then_some(name)
    })
}

/// `n` visible points on the [`NARROW_FACES`] of a scene loaded from [`narrow_faces`]: points
/// drawn area-weighted over the whole scene ([`crate::reference::points::draw`], batches of
/// 16384 with seeds `seed`, `seed + 1`, …), those on a narrow face kept in draw order.
pub fn narrow_face_points(
    scene: &crate::scene::Scene,
    tracer: &crate::trace::Tracer,
    n: usize,
    seed: u64,
) -> Result<crate::reference::points::PointSet> {
    use crate::reference::points::{PointSet, draw};
    let mut set = PointSet::default();
    for batch in 0..256 {
        let drawn = draw(scene, tracer, 16384, seed + batch)?;
        set.hidden += drawn.hidden;
        for p in drawn.points {
            if set.points.len() < n && narrow_face(p.position, p.normal).is_some() {
                set.points.push(p);
            }
        }
        if set.points.len() == n {
            return Ok(set);
        }
    }
    Err(Error::Option(format!(
        "only {} points on narrow faces",
        set.points.len()
    )))
}

/// A closed room (4 × 3 m, 2.6 m high) built as a modeller exports one: every wall, slab, frame
/// and fitting a closed, single-sided box facing outward, boxes meeting or overlapping where
/// they join. In the north wall a door leaf (4 cm thick) sits in a lined opening, 4 mm under
/// the head, 8 mm over the threshold and 3 mm from the latch-side jamb, its hinge end 1 cm inside
/// the other jamb; in the east wall a
/// shelf board (2 cm) spans a 12 cm recess, its ends 1 cm inside the recess's sides; a light
/// panel (Le 10, a 1.5 cm white border round it) sits in a 6 cm recess of the ceiling, 2 cm from
/// the recess's walls; a window pane (Le 2, cool) in the west wall. Its narrow faces
/// ([`NARROW_FACES`]) are narrower than two texels at every preset: the door's top, bottom and
/// edge in their slots (dark), the shelf's front edge, the panel's border and sides (next to
/// the light).
pub(crate) fn narrow_faces() -> GltfBuilder {
    let mut gltf = GltfBuilder::new("narrow_faces");
    let plaster = gltf.add_material(Material::diffuse("plaster", [0.78, 0.76, 0.72]));
    let boards = gltf.add_material(Material::diffuse("boards", [0.5, 0.38, 0.26]));
    let wood = gltf.add_material(Material::diffuse("wood", [0.62, 0.45, 0.3]));
    let paint = gltf.add_material(Material::grey("frame", 0.8));
    let light = gltf.add_material(Material::grey("light", 0.8).emitting([1.0, 0.96, 0.88], 10.0));
    let sky = gltf.add_material(Material::grey("window", 0.1).emitting([0.8, 0.9, 1.0], 2.0));
    let solid = |boxes: &[(Vec3, Vec3)]| {
        let mut g = Geometry::default();
        for &(min, max) in boxes {
            g.append(&Geometry::box_faces(min, max, &Face::ALL, 1));
        }
        g.without_uv0()
    };
    let v = Vec3::new;
    let (t, h) = (0.15f32, 2.6f32); // wall and slab thickness, room height
    let floor = solid(&[(v(-2.0, -t, -1.5), v(2.0, 0.0, 1.5))]);
    // The ceiling slab around a 0.9 × 0.7 m recess, 6 cm deep.
    let ceiling = solid(&[
        (v(-2.0, h, -1.5), v(-0.45, h + t, 1.5)),
        (v(0.45, h, -1.5), v(2.0, h + t, 1.5)),
        (v(-0.45, h, -1.5), v(0.45, h + t, -0.35)),
        (v(-0.45, h, 0.35), v(0.45, h + t, 1.5)),
        (v(-0.45, h + 0.06, -0.35), v(0.45, h + t, 0.35)),
    ]);
    // North wall around a 0.9 × 2.1 m door opening; south wall plain.
    let (nz0, nz1) = (-1.5 - t, -1.5);
    let mut walls = solid(&[
        (v(-2.0 - t, -t, nz0), v(-1.45, h + t, nz1)),
        (v(-0.55, -t, nz0), v(2.0 + t, h + t, nz1)),
        (v(-1.45, 2.1, nz0), v(-0.55, h + t, nz1)),
        (v(-1.45, -t, nz0), v(-0.55, 0.0, nz1)),
        (v(-2.0 - t, -t, 1.5), v(2.0 + t, h + t, 1.5 + t)),
    ]);
    // West wall around a 1.2 × 1.1 m window opening.
    walls.append(&solid(&[
        (v(-2.0 - t, -t, -1.5), v(-2.0, h + t, -0.6)),
        (v(-2.0 - t, -t, 0.6), v(-2.0, h + t, 1.5)),
        (v(-2.0 - t, -t, -0.6), v(-2.0, 0.9, 0.6)),
        (v(-2.0 - t, 2.0, -0.6), v(-2.0, h + t, 0.6)),
    ]));
    // East wall around a 0.8 × 0.6 m recess, 12 cm deep.
    walls.append(&solid(&[
        (v(2.0, -t, -1.5), v(2.0 + t, h + t, -0.4)),
        (v(2.0, -t, 0.4), v(2.0 + t, h + t, 1.5)),
        (v(2.0, -t, -0.4), v(2.0 + t, 0.9, 0.4)),
        (v(2.0, 1.5, -0.4), v(2.0 + t, h + t, 0.4)),
        (v(2.12, 0.9, -0.4), v(2.0 + t, 1.5, 0.4)),
    ]));
    let shell = gltf.add_mesh("floor", floor, boards);
    gltf.add_primitive(shell, walls, plaster);
    gltf.add_primitive(shell, ceiling, plaster);
    gltf.add_mesh_node("room", shell);
    // The door's lining (2 cm, 1 cm proud of the wall) and its leaf.
    let lining = solid(&[
        (v(-1.45, 0.0, nz0), v(-1.43, 2.1, nz1 + 0.01)),
        (v(-0.57, 0.0, nz0), v(-0.55, 2.1, nz1 + 0.01)),
        (v(-1.43, 2.08, nz0), v(-0.57, 2.1, nz1 + 0.01)),
    ]);
    let lining = gltf.add_mesh("door_lining", lining, paint);
    gltf.add_mesh_node("door_lining", lining);
    let leaf = solid(&[(v(-1.44, 0.008, -1.54), v(-0.573, 2.076, -1.5))]);
    let leaf = gltf.add_mesh("door", leaf, wood);
    gltf.add_mesh_node("door", leaf);
    let shelf = solid(&[(v(1.99, 1.18, -0.41), v(2.12, 1.2, 0.41))]);
    let shelf = gltf.add_mesh("shelf", shelf, wood);
    gltf.add_mesh_node("shelf", shelf);
    // The ceiling light: a 4 cm box against the recess's back, its underside an emitting face
    // framed by a 1.5 cm border.
    let (lx, lz, ly) = (0.43f32, 0.33f32, h + 0.02);
    let (ex, ez) = (lx - 0.015, lz - 0.015);
    let mut body = Geometry::box_faces(
        v(-lx, ly, -lz),
        v(lx, h + 0.06, lz),
        &[Face::PosX, Face::NegX, Face::PosY, Face::PosZ, Face::NegZ],
        1,
    );
    for (min, max) in [
        (v(-lx, ly, -lz), v(-ex, ly, lz)),
        (v(ex, ly, -lz), v(lx, ly, lz)),
        (v(-ex, ly, -lz), v(ex, ly, -ez)),
        (v(-ex, ly, ez), v(ex, ly, lz)),
    ] {
        body.append(&Geometry::box_face(min, max, Face::NegY, 1, 1));
    }
    let panel = gltf.add_mesh("light", body.without_uv0(), paint);
    let face = Geometry::box_face(v(-ex, ly, -ez), v(ex, ly, ez), Face::NegY, 1, 1);
    gltf.add_primitive(panel, face.without_uv0(), light);
    gltf.add_mesh_node("light", panel);
    // The window pane, 2 cm, in the middle of the west wall.
    let pane = solid(&[(v(-2.085, 0.9, -0.6), v(-2.065, 2.0, 0.6))]);
    let pane = gltf.add_mesh("window", pane, sky);
    gltf.add_mesh_node("window", pane);
    let camera = Camera::perspective("camera", 1.0, Some(1.5));
    gltf.add_camera_node(camera, v(1.2, 1.5, 1.2), v(-1.0, 1.6, -1.5));
    gltf
}

/// Every committed fixture: file name in `fixtures/` and its bytes.
pub fn fixture_files() -> Vec<(&'static str, Vec<u8>)> {
    vec![
        ("cornell_box.gltf", cornell_box().to_gltf_bytes()),
        ("cornell_box.glb", cornell_box().to_glb_bytes()),
        ("furnace.gltf", furnace(0.5, 1.0).to_gltf_bytes()),
        ("furnace_09.gltf", furnace(0.9, 1.0).to_gltf_bytes()),
        (
            "point_light.gltf",
            point_light_floor(10.0, 2.0).to_gltf_bytes(),
        ),
        (
            "spot_and_directional.gltf",
            spot_and_directional().to_gltf_bytes(),
        ),
        ("instanced.gltf", instanced().to_gltf_bytes()),
        ("textured.gltf", textured().to_gltf_bytes()),
        ("two_rooms.gltf", two_rooms().to_gltf_bytes()),
        ("two_rooms_angled.gltf", two_rooms_angled().to_gltf_bytes()),
        ("sphere_on_floor.gltf", sphere_on_floor().to_gltf_bytes()),
        ("courtyard.gltf", courtyard().to_gltf_bytes()),
        ("lamp_room.gltf", lamp_room().to_gltf_bytes()),
        (
            "furnished_interior.glb",
            furnished_interior().to_glb_bytes(),
        ),
        ("narrow_faces.gltf", narrow_faces().to_gltf_bytes()),
    ]
}

/// The largest row sum of the raw point-to-point kernel over all texel pairs, with no
/// visibility (right for a convex enclosure, where every pair sees each other): the documented
/// failure of that kernel, whose rows exceed 1 where walls touch.
pub fn raw_point_kernel_max_row_sum(t: &crate::texels::Texels) -> f32 {
    use crate::transport::kernel::point_to_point;
    (0..t.len())
        .map(|i| {
            (0..t.len())
                .filter(|&j| j != i)
                .map(|j| {
                    point_to_point(
                        t.position[i],
                        t.normal[i],
                        t.position[j],
                        t.normal[j],
                        t.area[j],
                    )
                })
                .sum::<f32>()
        })
        .fold(0.0f32, f32::max)
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use gltf::khr_lights_punctual::Kind;

    #[test]
    fn large_hall_has_over_100k_placed_triangles() {
        let hall = large_hall();
        let (json, _) = hall.to_gltf_json();
        let doc = gltf::Gltf::from_slice(&hall.to_glb_bytes()).expect("valid glTF");
        let placed: usize = doc
            .nodes()
            .filter_map(|n| n.mesh())
            .map(|m| {
                m.primitives()
                    .map(|p| p.indices().unwrap().count() / 3)
                    .sum::<usize>()
            })
            .sum();
        assert!(placed > 100_000, "{placed} triangles");
        assert_eq!(json["nodes"].as_array().unwrap().len(), 1 + 36 + 8 + 1);
    }

    use super::*;

    /// A world-space triangle with its glTF material index.
    type Triangle = ([Vec3; 3], Option<usize>);

    fn import(
        bytes: &[u8],
    ) -> (
        gltf::Document,
        Vec<gltf::buffer::Data>,
        Vec<gltf::image::Data>,
    ) {
        gltf::import_slice(bytes).expect("the glTF imports")
    }

    /// World-space triangles of the default scene, walking the node hierarchy.
    fn world_triangles(document: &gltf::Document, buffers: &[gltf::buffer::Data]) -> Vec<Triangle> {
        fn visit(
            node: gltf::Node,
            parent: Mat4,
            buffers: &[gltf::buffer::Data],
            out: &mut Vec<Triangle>,
        ) {
            let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
            for primitive in node.mesh().iter().flat_map(|mesh| mesh.primitives()) {
                let reader = primitive.reader(|buffer| Some(&buffers[buffer.index()]));
                let positions: Vec<Vec3> = reader
                    .read_positions()
                    .unwrap()
                    .map(|p| world.transform_point3(Vec3::from(p)))
                    .collect();
                let indices: Vec<u32> = reader.read_indices().unwrap().into_u32().collect();
                for t in indices.chunks_exact(3) {
                    let corners = [0, 1, 2].map(|k| positions[t[k] as usize]);
                    out.push((corners, primitive.material().index()));
                }
            }
            for child in node.children() {
                visit(child, world, buffers, out);
            }
        }
        let mut out = Vec::new();
        for node in document.default_scene().unwrap().nodes() {
            visit(node, Mat4::IDENTITY, buffers, &mut out);
        }
        out
    }

    /// World transform of the node named `name`.
    fn node_world(document: &gltf::Document, name: &str) -> Mat4 {
        fn find(node: gltf::Node, parent: Mat4, name: &str) -> Option<Mat4> {
            let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
            if node.name() == Some(name) {
                return Some(world);
            }
            node.children().find_map(|child| find(child, world, name))
        }
        let scene = document.default_scene().unwrap();
        scene
            .nodes()
            .find_map(|node| find(node, Mat4::IDENTITY, name))
            .expect("node exists")
    }

    fn normal([a, b, c]: [Vec3; 3]) -> Vec3 {
        (b - a).cross(c - a).normalize()
    }

    fn area([a, b, c]: [Vec3; 3]) -> f32 {
        (b - a).cross(c - a).length() / 2.0
    }

    fn assert_close(actual: f32, expected: f32, tolerance: f32, what: &str) {
        assert!(
            (actual - expected).abs() <= tolerance,
            "{what}: {actual} != {expected}"
        );
    }

    #[test]
    fn every_scene_parses_and_has_the_expected_triangles() {
        // (scene, triangles summed over meshes, triangles summed over instances)
        let scenes = [
            (cornell_box(), 242, 242),
            (furnace(0.5, 1.0), 192, 192),
            (point_light_floor(10.0, 2.0), 128, 128),
            (spot_and_directional(), 248, 248),
            (instanced(), 168, 208),
            (textured(), 32, 32),
            (two_rooms(), 314, 314),
        ];
        for (scene, mesh_triangles, world_triangle_count) in scenes {
            let (json, bin) = scene.to_gltf_json();
            assert_eq!(json["buffers"][0]["byteLength"], bin.len());
            assert_eq!(bin.len() % 4, 0);
            gltf::Gltf::from_slice(&serde_json::to_vec(&json).unwrap()).expect("valid glTF JSON");
            assert_eq!(
                scene.mesh_triangle_count(),
                mesh_triangles,
                "{}",
                scene.scene_name
            );
            for bytes in [scene.to_gltf_bytes(), scene.to_glb_bytes()] {
                let (document, buffers, _) = import(&bytes);
                let triangles = world_triangles(&document, &buffers);
                assert_eq!(
                    triangles.len(),
                    world_triangle_count,
                    "{}",
                    scene.scene_name
                );
                assert!(
                    triangles.iter().all(|&(t, _)| area(t) > 1e-6),
                    "degenerate triangle"
                );
            }
        }
    }

    #[test]
    fn written_gltf_and_glb_import_identically() {
        let dir = tempfile::tempdir().unwrap();
        let (gltf_path, glb_path) = (dir.path().join("box.gltf"), dir.path().join("box.glb"));
        cornell_box().write_gltf(&gltf_path).unwrap();
        cornell_box().write_glb(&glb_path).unwrap();
        let (document, buffers, _) = gltf::import(&gltf_path).unwrap();
        let from_gltf = world_triangles(&document, &buffers);
        let (document, buffers, _) = gltf::import(&glb_path).unwrap();
        assert_eq!(from_gltf, world_triangles(&document, &buffers));
        assert!(matches!(
            cornell_box().write_gltf(dir.path()),
            Err(Error::Io { .. })
        ));
    }

    #[test]
    fn furnace_is_closed_faces_inward_and_emits_le() {
        let (document, buffers, _) = import(&furnace(0.5, 3.0).to_gltf_bytes());
        let triangles = world_triangles(&document, &buffers);

        // Weld positions to a 1 µm grid, then every directed edge must appear exactly once and
        // its reverse exactly once: closed, manifold and consistently wound.
        let mut welded = BTreeMap::new();
        let mut vertex = |p: Vec3| {
            let key = (p * 1e6).round().as_ivec3().to_array();
            let next = welded.len();
            *welded.entry(key).or_insert(next)
        };
        let mut directed_edges = BTreeMap::new();
        for &(corners, _) in &triangles {
            let ids = corners.map(&mut vertex);
            for k in 0..3 {
                *directed_edges
                    .entry((ids[k], ids[(k + 1) % 3]))
                    .or_insert(0) += 1;
            }
        }
        for (&(a, b), &count) in &directed_edges {
            assert_eq!(count, 1, "edge {a}-{b} used {count} times in one direction");
            assert_eq!(
                directed_edges.get(&(b, a)),
                Some(&1),
                "edge {a}-{b} is open"
            );
        }
        assert_eq!(welded.len(), 6 * 4 * 4 + 2); // Euler: V = E − F + 2 = 288 − 192 + 2

        let centre = Vec3::new(0.0, 0.5, 0.0);
        for &(corners, _) in &triangles {
            let centroid = (corners[0] + corners[1] + corners[2]) / 3.0;
            assert!(
                normal(corners).dot(centre - centroid) > 0.0,
                "face looks outward"
            );
        }
        let total_area: f32 = triangles.iter().map(|&(t, _)| area(t)).sum();
        assert_close(total_area, 6.0, 1e-4, "cube area");

        let material = document.materials().next().unwrap();
        assert_eq!(material.emissive_factor(), [1.0; 3]);
        assert_eq!(material.emissive_strength(), Some(3.0));
        assert_eq!(
            material.pbr_metallic_roughness().base_color_factor(),
            [0.5, 0.5, 0.5, 1.0]
        );

        // Strength 1 is the default: no extension at all.
        let (json, _) = furnace(0.5, 1.0).to_gltf_json();
        assert!(json.get("extensionsUsed").is_none());
        assert!(json["materials"][0].get("extensions").is_none());
    }

    #[test]
    fn cornell_light_emits_the_documented_power() {
        let (document, buffers, _) = import(&cornell_box().to_glb_bytes());
        let materials: Vec<gltf::Material> = document.materials().collect();
        let mut power = Vec3::ZERO;
        for (corners, material) in world_triangles(&document, &buffers) {
            let material = &materials[material.unwrap()];
            let radiance = Vec3::from(material.emissive_factor())
                * material.emissive_strength().unwrap_or(1.0);
            if radiance != Vec3::ZERO {
                assert_close(normal(corners).y, -1.0, 1e-6, "the light faces down");
                assert!(
                    corners.iter().all(|p| p.y == CORNELL_LIGHT_HEIGHT),
                    "light height"
                );
                power += PI * radiance * area(corners);
            }
        }
        assert_close(CORNELL_LIGHT_POWER, 2.670354, 1e-5, "documented power");
        for channel in power.to_array() {
            assert_close(channel, CORNELL_LIGHT_POWER, 1e-5, "emitted power");
        }
    }

    #[test]
    fn cornell_walls_blocks_and_camera_are_where_the_docs_say() {
        let (document, buffers, _) = import(&cornell_box().to_gltf_bytes());
        let materials: Vec<_> = document
            .materials()
            .map(|m| m.name().unwrap().to_owned())
            .collect();
        let mut block_top = 0.0f32;
        for (corners, material) in world_triangles(&document, &buffers) {
            let centroid = (corners[0] + corners[1] + corners[2]) / 3.0;
            let n = normal(corners);
            match materials[material.unwrap()].as_str() {
                "red" => assert!(
                    centroid.x == -0.5 && n.x > 0.999,
                    "red wall on the left, facing in"
                ),
                "green" => assert!(centroid.x == 0.5 && n.x < -0.999, "green wall on the right"),
                "white"
                    if centroid.x.abs().max(centroid.z.abs()) < 0.499
                        && centroid.y > 0.001
                        && centroid.y < 0.999 =>
                {
                    // A block: inside the room, facing out of its own vertical axis or up.
                    block_top = block_top.max(centroid.y);
                }
                "white" => assert!(
                    n.dot(Vec3::new(0.0, 0.5, 0.0) - centroid) > 0.0,
                    "wall faces in"
                ),
                "light" => {}
                other => panic!("unexpected material {other}"),
            }
        }
        assert_close(block_top, 0.6, 1e-5, "tall block height");

        let camera_node = document.nodes().find(|n| n.camera().is_some()).unwrap();
        let camera = camera_node.camera().unwrap();
        let gltf::camera::Projection::Perspective(perspective) = camera.projection() else {
            panic!("perspective camera expected");
        };
        assert_close(perspective.yfov(), 39.3f32.to_radians(), 1e-6, "yfov");
        let world = node_world(&document, "camera");
        assert_close(
            world.transform_vector3(Vec3::NEG_Z).z,
            -1.0,
            1e-6,
            "camera looks into the box",
        );
        assert!(world.w_axis.z > 0.5, "camera outside the open side");
    }

    #[test]
    fn punctual_lights_round_trip() {
        let (document, _, _) = import(&point_light_floor(10.0, 2.0).to_gltf_bytes());
        let light = document.lights().unwrap().next().unwrap();
        assert!(matches!(light.kind(), Kind::Point));
        assert_eq!(
            (light.intensity(), light.color(), light.range()),
            (10.0, [1.0; 3], None)
        );
        assert_eq!(
            node_world(&document, "point").w_axis.truncate(),
            Vec3::new(0.0, 2.0, 0.0)
        );
        let floor = document.materials().next().unwrap();
        assert_eq!(
            floor.pbr_metallic_roughness().base_color_factor(),
            [0.0, 0.0, 0.0, 1.0]
        );

        let (document, _, _) = import(&spot_and_directional().to_gltf_bytes());
        let lights: Vec<_> = document.lights().unwrap().collect();
        let Kind::Spot {
            inner_cone_angle,
            outer_cone_angle,
        } = lights[0].kind()
        else {
            panic!("the first light is the spot");
        };
        assert_eq!((inner_cone_angle, outer_cone_angle), SPOT_CONE);
        assert_eq!(lights[0].range(), Some(SPOT_RANGE));
        assert!(matches!(lights[1].kind(), Kind::Directional) && lights[1].range().is_none());
        let spot = node_world(&document, "spot");
        assert!(
            spot.transform_vector3(Vec3::NEG_Z)
                .abs_diff_eq(Vec3::NEG_Y, 1e-6)
        );
        assert!(spot.w_axis.truncate().abs_diff_eq(SPOT_POSITION, 1e-6));
        let sun = node_world(&document, "sun").transform_vector3(Vec3::NEG_Z);
        assert!(
            sun.abs_diff_eq(SUN_DIRECTION.normalize(), 1e-6),
            "sun shines along {sun}"
        );
    }

    #[test]
    fn instanced_box_is_placed_twice_without_normals() {
        let (json, _) = instanced().to_gltf_json();
        let box_mesh = json["meshes"]
            .as_array()
            .unwrap()
            .iter()
            .position(|m| m["name"] == "box")
            .unwrap();
        let users = json["nodes"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|n| n["mesh"] == box_mesh)
            .count();
        assert_eq!(users, 2);
        assert!(
            json["meshes"][box_mesh]["primitives"][0]["attributes"]
                .get("NORMAL")
                .is_none()
        );
        assert!(
            json["nodes"]
                .as_array()
                .unwrap()
                .iter()
                .any(|n| n.get("matrix").is_some())
        );

        let (document, _, _) = import(&instanced().to_gltf_bytes());
        let a = node_world(&document, "box_a").w_axis.truncate();
        let b = node_world(&document, "box_b");
        assert!(
            a.abs_diff_eq(Vec3::new(-0.8, 0.0, -0.25), 1e-6),
            "parent matrix applies: {a}"
        );
        assert!(
            b.transform_point3(Vec3::new(0.0, 0.5, 0.0))
                .abs_diff_eq(Vec3::new(0.8, 0.8, -0.25), 1e-5)
        );
    }

    #[test]
    fn textured_floor_carries_the_checker() {
        let (document, buffers, images) = import(&textured().to_gltf_bytes());
        let material = document.materials().next().unwrap();
        let texture = material
            .pbr_metallic_roughness()
            .base_color_texture()
            .unwrap();
        assert_eq!(texture.tex_coord(), 0);
        let image = &images[texture.texture().source().index()];
        assert_eq!(
            (image.width, image.height, image.format),
            (64, 64, gltf::image::Format::R8G8B8)
        );
        let pixel = |x: usize, y: usize| &image.pixels[(y * 64 + x) * 3..][..3];
        assert_eq!(pixel(0, 0), CHECKER_COLORS[0]);
        assert_eq!(pixel(16, 0), CHECKER_COLORS[1]);
        assert_eq!(pixel(63, 63), CHECKER_COLORS[0]);

        let mesh = document.meshes().next().unwrap();
        let primitive = mesh.primitives().next().unwrap();
        let reader = primitive.reader(|buffer| Some(&buffers[buffer.index()]));
        let uvs: Vec<[f32; 2]> = reader.read_tex_coords(0).unwrap().into_f32().collect();
        assert!(uvs.contains(&[0.0, 0.0]) && uvs.contains(&[1.0, 1.0]));
    }

    #[test]
    fn two_rooms_share_a_zero_thickness_double_sided_wall() {
        let (document, buffers, _) = import(&two_rooms().to_gltf_bytes());
        let materials: Vec<gltf::Material> = document.materials().collect();
        let name = |index: Option<usize>| materials[index.unwrap()].name().unwrap();
        let triangles = world_triangles(&document, &buffers);
        let partition: Vec<_> = triangles
            .iter()
            .filter(|t| name(t.1) == "partition")
            .collect();
        assert!(
            partition.iter().all(|(t, _)| t.iter().all(|p| p.x == 0.0)),
            "zero thickness"
        );
        assert!(
            materials
                .iter()
                .filter(|m| m.double_sided())
                .all(|m| m.name() == Some("partition"))
        );
        assert!(materials.iter().any(|m| m.double_sided()));

        // The doorway is open: no partition triangle contains (0, 0.8, 0); the wall beside it is shut.
        let covers = |y: f32, z: f32| {
            partition.iter().any(|(t, _)| {
                let [a, b, c] = t.map(|p| Vec2::new(p.z, p.y));
                let p = Vec2::new(z, y);
                let side = |u: Vec2, v: Vec2| (v - u).perp_dot(p - u);
                let s = [side(a, b), side(b, c), side(c, a)];
                s.iter().all(|&x| x >= 0.0) || s.iter().all(|&x| x <= 0.0)
            })
        };
        assert!(!covers(0.8, 0.0) && covers(0.8, 0.7) && covers(1.8, 0.0));

        let floor: Vec<_> = triangles.iter().filter(|t| name(t.1) == "floor").collect();
        let straddles = floor
            .iter()
            .filter(|(t, _)| t.iter().any(|p| p.x < 0.0) && t.iter().any(|p| p.x > 0.0));
        assert!(straddles.count() > 0, "floor triangles pass under the wall");
        assert!(floor.iter().all(|(t, _)| normal(*t).y > 0.999));

        let panel: Vec<_> = triangles.iter().filter(|t| name(t.1) == "panel").collect();
        assert!(
            panel
                .iter()
                .all(|(t, _)| t.iter().all(|p| p.x < 0.0 && p.y < 2.0)),
            "panel lights room A"
        );
    }

    #[test]
    fn index_width_and_image_storage_follow_the_data() {
        let mut gltf = GltfBuilder::new("big");
        let material = gltf.add_material(Material::grey("grey", 0.5));
        let image = gltf.add_image("checker", &checker(8, 2).into(), ImageStorage::DataUri);
        gltf.materials[material].base_color_texture = Some(image);
        let small = Geometry::grid(Vec3::ZERO, Vec3::X, Vec3::NEG_Z, 1, 1);
        let big = Geometry::grid(Vec3::ZERO, Vec3::X, Vec3::NEG_Z, 256, 256); // 66 049 vertices
        let small_mesh = gltf.add_mesh("small", small, material);
        let big_mesh = gltf.add_mesh("big", big, material);
        gltf.add_mesh_node("small", small_mesh);
        gltf.add_mesh_node("big", big_mesh);
        let (json, _) = gltf.to_gltf_json();
        let component = |mesh: usize| {
            let accessor = json["meshes"][mesh]["primitives"][0]["indices"]
                .as_u64()
                .unwrap() as usize;
            json["accessors"][accessor]["componentType"]
                .as_u64()
                .unwrap() as u32
        };
        assert_eq!(
            (component(small_mesh), component(big_mesh)),
            (UNSIGNED_SHORT, UNSIGNED_INT)
        );
        assert!(
            json["images"][0]["uri"]
                .as_str()
                .unwrap()
                .starts_with("data:image/png;base64,")
        );
        for view in json["bufferViews"].as_array().unwrap() {
            assert_eq!(view["byteOffset"].as_u64().unwrap() % 4, 0);
            assert!(view.get("target").is_some());
        }
        // gltf 1.4's import_slice rejects data-URI images; importing from a path works.
        let dir = tempfile::tempdir().unwrap();
        gltf.write_glb(dir.path().join("big.glb")).unwrap();
        let (document, buffers, images) = gltf::import(dir.path().join("big.glb")).unwrap();
        assert_eq!(
            world_triangles(&document, &buffers).len(),
            2 + 2 * 256 * 256
        );
        assert_eq!(
            (images[0].width, images[0].pixels[0]),
            (8, CHECKER_COLORS[0][0])
        );
    }

    #[test]
    fn committed_fixtures_are_up_to_date() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures");
        for (name, bytes) in fixture_files() {
            let committed = std::fs::read(dir.join(name)).unwrap_or_default();
            assert!(
                committed == bytes,
                "fixtures/{name} is stale or hand-edited: run `cargo run --example make_fixtures`"
            );
        }
    }
}
