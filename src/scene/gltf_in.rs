//! glTF loader: reads a `.gltf` or `.glb` (told apart by the `glTF` magic, not the extension) and
//! resolves the default scene into world-space triangles, materials and lights.
//!
//! Buffers and images are read here rather than through `gltf::import`, so that a missing file
//! is reported by name and an undecodable image only costs a warning.

mod check;
mod textures;

use std::path::{Path, PathBuf};

use base64::Engine as _;
use glam::{Mat3, Mat4, Quat, Vec2, Vec3};
use gltf::mesh::{Mode, Semantic};

use super::{Camera, GltfCamera, Instance, Light, LightKind, MAX_COORDINATE, Scene, Source};
use crate::{Error, Result};

/// Extensions that may appear in `extensionsRequired`; anything else changes geometry or
/// shading in ways the baker would silently get wrong.
const SUPPORTED_REQUIRED_EXTENSIONS: &[&str] =
    &["KHR_lights_punctual", "KHR_materials_emissive_strength"];

/// Loads the default scene of the glTF file at `path` (the first scene if none is marked default).
///
/// Points and lines, skinned meshes and morphed primitives are skipped with a warning in
/// `scene.stats`; so are undecodable images (treated as white).
pub fn load(path: &Path) -> Result<(Scene, Source)> {
    load_edited(path, &|_| {})
}

/// [`load`] with the document's JSON changed by `edit` before it is read: how an incremental
/// bake (`bake::incremental`) places the nodes where the previous bake had them.
pub(crate) fn load_edited(
    path: &Path,
    edit: &dyn Fn(&mut serde_json::Value),
) -> Result<(Scene, Source)> {
    let (mut json, blob, is_glb) = read_document(path)?;
    edit(&mut json);
    check_version_and_extensions(path, &json)?;
    let files = Files {
        gltf_path: path,
        dir: path.parent().unwrap_or(Path::new("")),
    };
    check::mesh_references(&files, &json)?;
    check::image_sources(&files, &json)?;

    let root: gltf::json::Root = serde_json::from_value(json.clone())
        .map_err(|e| Error::invalid(path, format!("not a valid glTF document: {e}")))?;
    let document = guarded(&files, "validating the document", || {
        gltf::Document::from_json(root)
    })?
    .map_err(|e| invalid_gltf(path, e))?;
    check::byte_ranges(&files, &document)?;
    let buffers = load_buffers(&files, &document, blob)?;

    let mut loader = Loader {
        files: &files,
        json: &json,
        document: &document,
        buffers: &buffers,
        scene: Scene::default(),
        default_material: document.materials().len() as u32,
    };
    loader.load_scene()?;
    let mut scene = loader.scene;
    textures::add_materials(&files, &document, &json, &buffers, &mut scene)?;
    check::finite_floats(&files, &document, &buffers)?;
    if json_list_contains(&json, "extensionsUsed", "KHR_texture_transform") {
        warn(
            &mut scene,
            "KHR_texture_transform is ignored: textures are sampled untransformed",
        );
    }
    for problem in check::texture_transforms(&json) {
        warn(&mut scene, problem);
    }
    if let Some(problem) = far_nodes(&document, &scene) {
        warn(&mut scene, problem);
    }

    #[cfg(debug_assertions)]
    scene.validate();

    let source = Source {
        path: path.to_path_buf(),
        is_glb,
        json,
        buffers,
    };
    Ok((scene, source))
}

/// Where the glTF file is, for error messages and for resolving relative URIs.
struct Files<'a> {
    gltf_path: &'a Path,
    dir: &'a Path,
}

impl Files<'_> {
    fn invalid(&self, message: impl Into<String>) -> Error {
        Error::invalid(self.gltf_path, message)
    }

    /// Reads a buffer or image URI: a base64 data URI or a path relative to the glTF file.
    /// `what` names the referrer in messages, e.g. "buffer 0 'scene.bin'".
    fn read_uri(&self, uri: &str, what: &str) -> Result<Vec<u8>> {
        if let Some(data) = uri.strip_prefix("data:") {
            let (_, payload) = data
                .split_once(";base64,")
                .ok_or_else(|| self.invalid(format!("{what}: data URI is not base64")))?;
            return BASE64
                .decode(payload.trim())
                .map_err(|e| self.invalid(format!("{what}: bad base64 data URI: {e}")));
        }
        let file = self.resolve(uri, what)?;
        std::fs::read(&file).map_err(|e| {
            let problem = match e.kind() {
                std::io::ErrorKind::NotFound => "not found",
                _ => "cannot be read",
            };
            self.invalid(format!("{what} {problem}: {}: {e}", file.display()))
        })
    }
}

impl Files<'_> {
    /// The file a URI that is not a data URI names: a path relative to the glTF file, or a
    /// `file://` URI.
    fn resolve(&self, uri: &str, what: &str) -> Result<PathBuf> {
        if let Some(absolute) = uri.strip_prefix("file://") {
            Ok(PathBuf::from(percent_decode(absolute)))
        } else if uri.contains(':') {
            let message = format!("{what}: only relative paths and data URIs are supported");
            Err(Error::unsupported(self.gltf_path, message))
        } else {
            Ok(self.dir.join(percent_decode(uri)))
        }
    }
}

/// The glTF JSON of the file at `path`, a GLB's binary chunk, and whether it is a GLB.
pub(crate) fn read_document(path: &Path) -> Result<(serde_json::Value, Option<Vec<u8>>, bool)> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let is_glb = bytes.starts_with(b"glTF");
    Ok(if is_glb {
        let glb = parse_glb(path, &bytes)?;
        (
            parse_json(path, &glb.json)?,
            glb.bin.map(|bin| bin.into_owned()),
            true,
        )
    } else {
        (parse_json(path, &bytes)?, None, false)
    })
}

/// The files besides `path` that a scene is read from: its external buffers, then its external
/// images, in the order the glTF lists them (data URIs and a GLB's own chunk are inside the
/// file). For build tools that decide whether a scene changed.
pub fn external_files(path: &Path) -> Result<Vec<PathBuf>> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let json = if bytes.starts_with(b"glTF") {
        parse_json(path, &parse_glb(path, &bytes)?.json)?
    } else {
        parse_json(path, &bytes)?
    };
    let files = Files {
        gltf_path: path,
        dir: path.parent().unwrap_or(Path::new("")),
    };
    let uris = ["buffers", "images"].into_iter().flat_map(|list| {
        let items = json[list].as_array().map(Vec::as_slice).unwrap_or_default();
        items
            .iter()
            .enumerate()
            .filter_map(move |(k, item)| Some((list, k, item["uri"].as_str()?)))
    });
    uris.filter(|(_, _, uri)| !uri.starts_with("data:"))
        .map(|(list, k, uri)| files.resolve(uri, &format!("{list}[{k}]")))
        .collect()
}

/// Runs third-party code that the checks in [`check`] should have made safe. A panic that
/// slips past them becomes an error naming `what`, not the end of the build step (exit 101).
fn guarded<T>(files: &Files, what: &str, run: impl FnOnce() -> T) -> Result<T> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(run)).map_err(|panic| {
        let detail = panic
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| panic.downcast_ref::<String>().cloned())
            .unwrap_or_default();
        files.invalid(format!("{what}: the glTF reader failed ({detail})"))
    })
}

/// Standard base64, tolerant of missing padding (some exporters drop it).
const BASE64: base64::engine::GeneralPurpose = base64::engine::GeneralPurpose::new(
    &base64::alphabet::STANDARD,
    base64::engine::GeneralPurposeConfig::new()
        .with_decode_padding_mode(base64::engine::DecodePaddingMode::Indifferent),
);

/// Decodes `%XX` escapes of a URI path (glTF URIs are RFC 3986).
fn percent_decode(uri: &str) -> String {
    let bytes = uri.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let hex = bytes
            .get(i + 1..i + 3)
            .and_then(|h| std::str::from_utf8(h).ok());
        match (bytes[i], hex.and_then(|h| u8::from_str_radix(h, 16).ok())) {
            (b'%', Some(byte)) => {
                out.push(byte);
                i += 3;
            }
            (byte, _) => {
                out.push(byte);
                i += 1;
            }
        }
    }
    String::from_utf8(out).unwrap_or_else(|_| uri.to_string())
}

fn parse_glb<'a>(path: &Path, bytes: &'a [u8]) -> Result<gltf::binary::Glb<'a>> {
    // The gltf crate subtracts the header size from the declared length unchecked.
    let declared = bytes
        .get(8..12)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
    if declared.is_none_or(|length| length < 20) {
        return Err(Error::invalid(path, "truncated GLB header"));
    }
    gltf::binary::Glb::from_slice(bytes)
        .map_err(|e| Error::invalid(path, format!("not a valid GLB file: {e}")))
}

fn parse_json(path: &Path, bytes: &[u8]) -> Result<serde_json::Value> {
    serde_json::from_slice(bytes)
        .map_err(|e| Error::invalid(path, format!("not a glTF file (neither GLB nor JSON): {e}")))
}

fn json_list_contains(json: &serde_json::Value, key: &str, item: &str) -> bool {
    json.get(key)
        .and_then(|list| list.as_array())
        .is_some_and(|list| list.iter().any(|v| v.as_str() == Some(item)))
}

fn check_version_and_extensions(path: &Path, json: &serde_json::Value) -> Result<()> {
    let version = json.pointer("/asset/version").and_then(|v| v.as_str());
    match version {
        Some(v) if v.split('.').next() == Some("2") => {}
        Some(v) => {
            let message = format!("glTF version {v}; only glTF 2.0 is supported");
            return Err(Error::unsupported(path, message));
        }
        None => return Err(Error::invalid(path, "not a glTF file: no asset.version")),
    }
    let required = json.get("extensionsRequired").and_then(|r| r.as_array());
    for extension in required.into_iter().flatten() {
        let name = extension.as_str().unwrap_or_default();
        if !SUPPORTED_REQUIRED_EXTENSIONS.contains(&name) {
            let message = format!("required extension {name} is not supported");
            return Err(Error::unsupported(path, message));
        }
    }
    Ok(())
}

fn invalid_gltf(path: &Path, error: gltf::Error) -> Error {
    let message = match error {
        gltf::Error::Validation(errors) => {
            let list: Vec<String> = errors.iter().map(|(at, e)| format!("{at}: {e}")).collect();
            format!("invalid glTF: {}", list.join("; "))
        }
        other => format!("invalid glTF: {other}"),
    };
    Error::invalid(path, message)
}

fn load_buffers(
    files: &Files,
    document: &gltf::Document,
    mut blob: Option<Vec<u8>>,
) -> Result<Vec<Vec<u8>>> {
    let mut buffers = Vec::with_capacity(document.buffers().len());
    for buffer in document.buffers() {
        let i = buffer.index();
        let data = match buffer.source() {
            gltf::buffer::Source::Uri(uri) => {
                files.read_uri(uri, &format!("buffer {i} '{uri}'"))?
            }
            gltf::buffer::Source::Bin => match blob.take() {
                Some(bin) if i == 0 => bin,
                _ => {
                    let message = format!("buffer {i} has no uri and there is no GLB BIN chunk");
                    return Err(files.invalid(message));
                }
            },
        };
        if data.len() < buffer.length() {
            let message = format!(
                "buffer {i} holds {} bytes, byteLength says {}",
                data.len(),
                buffer.length()
            );
            return Err(files.invalid(message));
        }
        buffers.push(data);
    }
    Ok(buffers)
}

fn warn(scene: &mut Scene, message: impl Into<String>) {
    let message = message.into();
    if !scene.stats.warnings.contains(&message) {
        scene.stats.warnings.push(message);
    }
}

/// Walks the scene graph and gathers geometry and lights.
struct Loader<'a> {
    files: &'a Files<'a>,
    /// The document as parsed, for what the gltf crate does not expose (`extras`).
    json: &'a serde_json::Value,
    document: &'a gltf::Document,
    buffers: &'a [Vec<u8>],
    scene: Scene,
    /// Material index of primitives without a material (appended by `textures::add_materials`).
    default_material: u32,
}

/// A node with its world transform, ready to place geometry.
struct Placement {
    world: Mat4,
    /// Transforms normals: the inverse transpose, up to a positive factor (normalise after).
    normal_matrix: Mat3,
    /// The transform mirrors, so triangle winding must be reversed to stay counter-clockwise.
    mirrors: bool,
}

impl Placement {
    fn new(world: Mat4) -> Self {
        let m = Mat3::from_mat4(world);
        // The cofactor matrix is det × inverse transpose and exists even for singular m.
        let cofactor = Mat3::from_cols(
            m.y_axis.cross(m.z_axis),
            m.z_axis.cross(m.x_axis),
            m.x_axis.cross(m.y_axis),
        );
        let mirrors = m.determinant() < 0.0;
        let normal_matrix = if mirrors { -cofactor } else { cofactor };
        Placement {
            world,
            normal_matrix,
            mirrors,
        }
    }
}

/// One primitive's triangle list after strip/fan conversion, with its vertex attributes.
struct PrimitiveData {
    positions: Vec<Vec3>,
    normals: Option<Vec<Vec3>>,
    uv0: Option<Vec<Vec2>>,
    uv1: Option<Vec<Vec2>>,
    triangles: Vec<[u32; 3]>,
}

impl Loader<'_> {
    fn load_scene(&mut self) -> Result<()> {
        let document = self.document;
        let gltf_scene = document
            .default_scene()
            .or_else(|| document.scenes().next())
            .ok_or_else(|| self.files.invalid("the document has no scenes"))?;

        let mut visited = vec![false; document.nodes().len()];
        // Depth-first, children in document order; a stack rather than recursion so deep
        // hierarchies cannot overflow.
        // Each entry carries the parent's world transform twice: as the gltf crate composes it
        // (geometry, lights) and as glam composes it (cameras, see `camera_matrix`).
        let mut stack: Vec<(gltf::Node, Mat4, Mat4)> = gltf_scene
            .nodes()
            .map(|node| (node, Mat4::IDENTITY, Mat4::IDENTITY))
            .collect();
        stack.reverse();
        while let Some((node, parent, camera_parent)) = stack.pop() {
            if std::mem::replace(&mut visited[node.index()], true) {
                let message = format!(
                    "{} is reached twice from the scene (a cycle or a node with two parents)",
                    node_label(&node)
                );
                return Err(self.files.invalid(message));
            }
            let local = Mat4::from_cols_array_2d(&node.transform().matrix());
            let world = parent * local;
            if !world.is_finite() {
                let message = format!("{} has a non-finite transform", node_label(&node));
                return Err(self.files.invalid(message));
            }
            self.scene.nodes.push(super::SceneNode {
                index: node.index() as u32,
                name: node.name().map(str::to_string),
                world,
                children: node.children().map(|c| c.index() as u32).collect(),
            });
            let placement = Placement::new(world);
            if let Some(mesh) = node.mesh() {
                self.add_mesh(&node, &mesh, &placement)?;
            }
            if let Some(light) = node.light() {
                self.add_light(&light, &placement)?;
            }
            let camera_world = camera_parent * camera_matrix(node.transform());
            if let Some(camera) = node.camera() {
                self.add_camera(&node, &camera, camera_world);
            }
            let first_child = stack.len();
            stack.extend(node.children().map(|child| (child, world, camera_world)));
            stack[first_child..].reverse();
        }
        Ok(())
    }

    fn add_mesh(
        &mut self,
        node: &gltf::Node,
        mesh: &gltf::Mesh,
        placement: &Placement,
    ) -> Result<()> {
        let stats = &mut self.scene.stats;
        if node.skin().is_some() {
            stats.skipped_primitives += mesh.primitives().len() as u32;
            let message = format!(
                "{}: skinned {} skipped (skinning is not baked)",
                node_label(node),
                mesh_label(mesh)
            );
            warn(&mut self.scene, message);
            return Ok(());
        }
        for primitive in mesh.primitives() {
            let label = format!("{} primitive {}", mesh_label(mesh), primitive.index());
            let skip_reason = match primitive.mode() {
                Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan => None,
                other => Some(format!(
                    "{other:?} primitive skipped (only triangles are baked)"
                )),
            }
            .or_else(|| {
                (primitive.morph_targets().len() > 0)
                    .then(|| "skipped: morph targets are not baked".to_string())
            })
            .or_else(|| {
                primitive
                    .get(&Semantic::Positions)
                    .is_none()
                    .then(|| "skipped: no POSITION".into())
            });
            if let Some(reason) = skip_reason {
                self.scene.stats.skipped_primitives += 1;
                warn(&mut self.scene, format!("{label}: {reason}"));
                continue;
            }
            let data = guarded(self.files, &label, || {
                self.read_primitive(&primitive, &label)
            })??;
            let material = primitive
                .material()
                .index()
                .map_or(self.default_material, |i| i as u32);
            let front =
                self.add_instance(node, mesh, &primitive, material, data, placement, &label)?;
            if primitive.material().double_sided() {
                self.add_back_instance(front);
            }
        }
        Ok(())
    }

    fn read_primitive(&self, primitive: &gltf::Primitive, label: &str) -> Result<PrimitiveData> {
        let buffers = self.buffers;
        let reader = primitive.reader(|buffer| buffers.get(buffer.index()).map(Vec::as_slice));
        let out_of_bounds = |what: &str| {
            self.files
                .invalid(format!("{label}: {what} reads outside its buffer"))
        };

        check::attribute_types(self.files, primitive, label)?;

        let positions: Vec<Vec3> = reader
            .read_positions()
            .ok_or_else(|| out_of_bounds("POSITION"))?
            .map(Vec3::from)
            .collect();
        if let Some(bad) = positions.iter().position(|p| !p.is_finite()) {
            let message = format!("{label}: POSITION {bad} is not finite");
            return Err(self.files.invalid(message));
        }
        let n = positions.len();
        let same_length = |len: usize, what: &str| {
            if len == n {
                Ok(())
            } else {
                let message = format!("{label}: {what} has {len} elements, POSITION has {n}");
                Err(self.files.invalid(message))
            }
        };

        let normals = match primitive.get(&Semantic::Normals) {
            None => None,
            Some(_) => {
                let normals: Vec<Vec3> = reader
                    .read_normals()
                    .ok_or_else(|| out_of_bounds("NORMAL"))?
                    .map(Vec3::from)
                    .collect();
                same_length(normals.len(), "NORMAL")?;
                // Passed on, a NaN normal would reach the output file (the validator refuses it).
                if let Some(bad) = normals.iter().position(|n| !n.is_finite()) {
                    let message = format!("{label}: NORMAL {bad} is not finite");
                    return Err(self.files.invalid(message));
                }
                Some(normals)
            }
        };
        let mut tex_coords = [None, None];
        for (set, slot) in tex_coords.iter_mut().enumerate() {
            if primitive.get(&Semantic::TexCoords(set as u32)).is_none() {
                continue;
            }
            let name = format!("TEXCOORD_{set}");
            let uv: Vec<Vec2> = reader
                .read_tex_coords(set as u32)
                .ok_or_else(|| out_of_bounds(&name))?
                .into_f32()
                .map(Vec2::from)
                .collect();
            same_length(uv.len(), &name)?;
            if uv.iter().any(|uv| !uv.is_finite()) {
                return Err(self.files.invalid(format!("{label}: {name} is not finite")));
            }
            *slot = Some(uv);
        }
        let [uv0, uv1] = tex_coords;

        let indices: Vec<u32> = match primitive.indices() {
            Some(_) => reader
                .read_indices()
                .ok_or_else(|| out_of_bounds("indices"))?
                .into_u32()
                .collect(),
            None => (0..n as u32).collect(),
        };
        if let Some(bad) = indices.iter().find(|&&i| i as usize >= n) {
            let message = format!("{label}: index {bad} is out of range ({n} vertices)");
            return Err(self.files.invalid(message));
        }
        let triangles = triangle_list(primitive.mode(), &indices);
        Ok(PrimitiveData {
            positions,
            normals,
            uv0,
            uv1,
            triangles,
        })
    }

    #[allow(clippy::too_many_arguments)]
    fn add_instance(
        &mut self,
        node: &gltf::Node,
        mesh: &gltf::Mesh,
        primitive: &gltf::Primitive,
        material: u32,
        data: PrimitiveData,
        placement: &Placement,
        label: &str,
    ) -> Result<u32> {
        let world_positions: Vec<Vec3> = data
            .positions
            .iter()
            .map(|&p| placement.world.transform_point3(p))
            .collect();
        // Flipped bits in a float's exponent give coordinates far outside any scene; the atlas
        // and the BVH builder cannot take them (obvhs panics), so they are refused here.
        let beyond = |p: &Vec3| !p.is_finite() || p.abs().max_element() > MAX_COORDINATE;
        if let Some(k) = world_positions.iter().position(beyond) {
            let message = format!(
                "{label}: POSITION {k} is at {} under {}, beyond ±{MAX_COORDINATE:e} units (damaged data?)",
                world_positions[k],
                node_label(node)
            );
            return Err(self.files.invalid(message));
        }

        let scene = &mut self.scene;
        let first_vertex = scene.positions.len() as u32;
        let first_triangle = scene.triangles.len() as u32;
        let instance = scene.instances.len() as u32;
        let mut source_triangle = Vec::with_capacity(data.triangles.len());
        let mut kept = Vec::with_capacity(data.triangles.len());
        for (source, &[a, b, c]) in data.triangles.iter().enumerate() {
            let corners = [a, b, c].map(|v| world_positions[v as usize]);
            if a == b || b == c || a == c || is_degenerate(corners) {
                scene.stats.degenerate_triangles += 1;
                continue;
            }
            kept.push(if placement.mirrors {
                [a, c, b]
            } else {
                [a, b, c]
            });
            source_triangle.push(source as u32);
        }

        let normals = vertex_normals(&world_positions, &kept, data.normals.as_deref(), placement);
        if data.normals.is_none() {
            scene.stats.generated_normals += 1;
        }
        let n = world_positions.len();
        scene.positions.extend(world_positions);
        scene.normals.extend(normals);
        scene
            .uv0
            .extend(data.uv0.unwrap_or_else(|| vec![Vec2::ZERO; n]));
        let has_uv1 = data.uv1.is_some();
        scene
            .uv1
            .extend(data.uv1.unwrap_or_else(|| vec![Vec2::ZERO; n]));
        scene
            .triangles
            .extend(kept.iter().map(|t| t.map(|v| first_vertex + v)));
        scene
            .triangle_instance
            .extend(std::iter::repeat_n(instance, kept.len()));
        // A baked file names each primitive's EXR page; the renderer reads it. A shared mesh
        // (`--instancing share`) names it on each node instead, with the node's rect.
        let node_extras = &self.json["nodes"][node.index()]["extras"];
        let extras = match node_extras["lightmap"]["exr"].is_string() {
            true => node_extras,
            false => &self.json["meshes"][mesh.index()]["primitives"][primitive.index()]["extras"],
        };
        if let Some(rect) = scale_offset(&extras["lightmap"]) {
            let uv1 = &mut scene.uv1[first_vertex as usize..];
            uv1.iter_mut().for_each(|uv| *uv = page_uv(*uv, rect));
        }
        let lightmap = extras["lightmap"]["exr"]
            .as_str()
            .map(|uri| self.files.dir.join(percent_decode(uri)));
        let pages = super::DIRECTIONAL_PAGES.map(|name| {
            let uri = extras["lightmap"]["directional"][name].as_str()?;
            Some(self.files.dir.join(percent_decode(uri)))
        });
        let directional = pages
            .iter()
            .all(Option::is_some)
            .then(|| pages.map(Option::unwrap));
        scene.instances.push(Instance {
            node: node.index() as u32,
            mesh: mesh.index() as u32,
            primitive: primitive.index() as u32,
            material,
            vertices: first_vertex..scene.positions.len() as u32,
            triangles: first_triangle..scene.triangles.len() as u32,
            source_triangle,
            back_of: None,
            back: None,
            has_uv1,
            lightmap,
            directional,
            split: Default::default(),
        });
        Ok(instance)
    }

    /// Appends the flipped copy of a double-sided instance: same positions and UVs, negated
    /// normals, reversed winding.
    fn add_back_instance(&mut self, front: u32) {
        let scene = &mut self.scene;
        let back = scene.instances.len() as u32;
        let mut instance = scene.instances[front as usize].clone();
        let first_vertex = scene.positions.len() as u32;
        let first_triangle = scene.triangles.len() as u32;
        let vertices = instance.vertices.start as usize..instance.vertices.end as usize;
        scene.positions.extend_from_within(vertices.clone());
        scene.uv0.extend_from_within(vertices.clone());
        scene.uv1.extend_from_within(vertices.clone());
        let flipped: Vec<Vec3> = scene.normals[vertices].iter().map(|&n| -n).collect();
        scene.normals.extend(flipped);
        let shift = |v: u32| v - instance.vertices.start + first_vertex;
        let triangles = instance.triangles.start as usize..instance.triangles.end as usize;
        let reversed: Vec<[u32; 3]> = scene.triangles[triangles]
            .iter()
            .map(|&[a, b, c]| [shift(a), shift(c), shift(b)])
            .collect();
        scene
            .triangle_instance
            .extend(std::iter::repeat_n(back, reversed.len()));
        scene.triangles.extend(reversed);

        instance.vertices = first_vertex..scene.positions.len() as u32;
        instance.triangles = first_triangle..scene.triangles.len() as u32;
        instance.back_of = Some(front);
        scene.instances.push(instance);
        scene.instances[front as usize].back = Some(back);
    }

    /// A KHR_lights_punctual light. Values outside the extension's "must" ranges are clamped
    /// with a warning (baking can go on); numbers too large for f32 are errors.
    fn add_light(
        &mut self,
        light: &gltf::khr_lights_punctual::Light,
        placement: &Placement,
    ) -> Result<()> {
        use gltf::khr_lights_punctual::Kind;
        let label = format!("light {}", light.index());
        let color = Vec3::from(light.color());
        let numbers = [light.intensity(), light.range().unwrap_or(1.0)];
        let cone = match light.kind() {
            Kind::Spot {
                inner_cone_angle,
                outer_cone_angle,
            } => [inner_cone_angle, outer_cone_angle],
            _ => [0.0; 2],
        };
        if !color.is_finite() || numbers.iter().chain(&cone).any(|x| !x.is_finite()) {
            return Err(self
                .files
                .invalid(format!("{label}: a value is not finite")));
        }
        let kind = match light.kind() {
            Kind::Point => LightKind::Point,
            Kind::Directional => LightKind::Directional,
            Kind::Spot { .. } => {
                let [inner, outer] = cone;
                let outer_cone_angle = outer.clamp(0.0, std::f32::consts::FRAC_PI_2);
                let inner_cone_angle = inner.clamp(0.0, outer_cone_angle);
                if !(0.0 <= inner && inner < outer && outer <= std::f32::consts::FRAC_PI_2) {
                    let message = format!(
                        "{label}: spot cone angles inner {inner}, outer {outer} break 0 ≤ inner < outer ≤ π/2; clamped to inner {inner_cone_angle}, outer {outer_cone_angle}"
                    );
                    warn(&mut self.scene, message);
                }
                LightKind::Spot {
                    inner_cone_angle,
                    outer_cone_angle,
                }
            }
        };
        if color.min_element() < 0.0 || color.max_element() > 1.0 {
            let message = format!("{label}: color {color} is outside [0, 1]; clamped");
            warn(&mut self.scene, message);
        }
        if light.intensity() < 0.0 {
            warn(
                &mut self.scene,
                format!("{label}: negative intensity clamped to zero"),
            );
        }
        let range = light.range();
        if range.is_some_and(|r| r <= 0.0) {
            let message = format!("{label}: range must be positive; the light has no range limit");
            warn(&mut self.scene, message);
        }
        let direction = placement
            .world
            .transform_vector3(Vec3::NEG_Z)
            .normalize_or(Vec3::NEG_Z);
        self.scene.lights.push(Light {
            name: light.name().map(str::to_string),
            source: Some(light.index() as u32),
            kind,
            position: placement.world.transform_point3(Vec3::ZERO),
            direction,
            intensity: color.clamp(Vec3::ZERO, Vec3::ONE) * light.intensity().max(0.0),
            range: range.filter(|r| *r > 0.0),
        });
        Ok(())
    }

    /// A perspective camera placed by `node`; orthographic ones are skipped (a pinhole renderer
    /// cannot show them).
    fn add_camera(&mut self, node: &gltf::Node, camera: &gltf::Camera, world: Mat4) {
        let gltf::camera::Projection::Perspective(perspective) = camera.projection() else {
            return;
        };
        let name = camera.name().or(node.name());
        self.scene.cameras.push(GltfCamera {
            name: name.map(str::to_owned),
            index: camera.index(),
            camera: Camera::from_world(world, perspective.yfov(), perspective.aspect_ratio()),
        });
    }
}

/// A node's local transform for placing cameras: glam's composition of the unit rotation, or
/// the matrix. It rounds differently from the gltf crate's `matrix()` (which places geometry);
/// cameras have always been placed this way, and rendered views stay bit-identical with it.
/// `extras.lightmap.scale_offset` of a node placing a shared mesh: `[sx, sy, ox, oy]`.
fn scale_offset(lightmap: &serde_json::Value) -> Option<[f32; 4]> {
    let values = lightmap.get("scale_offset")?.as_array()?;
    let mut rect = [0.0; 4];
    if values.len() != 4 {
        return None;
    }
    for (r, v) in rect.iter_mut().zip(values) {
        *r = v.as_f64()? as f32;
    }
    rect.iter().all(|v| v.is_finite()).then_some(rect)
}

/// A base-layout lightmap UV on the node's page, as the writer computed it
/// (`atlas::share::page_uv`): a multiply, then an add, in f32.
fn page_uv(uv: Vec2, [sx, sy, ox, oy]: [f32; 4]) -> Vec2 {
    let scaled = uv * Vec2::new(sx, sy);
    scaled + Vec2::new(ox, oy)
}

fn camera_matrix(transform: gltf::scene::Transform) -> Mat4 {
    match transform {
        gltf::scene::Transform::Matrix { matrix } => Mat4::from_cols_array_2d(&matrix),
        gltf::scene::Transform::Decomposed {
            translation,
            rotation,
            scale,
        } => Mat4::from_scale_rotation_translation(
            Vec3::from(scale),
            Quat::from_array(rotation).normalize(),
            Vec3::from(translation),
        ),
    }
}

/// Geometry this many times farther out than the rest of the scene spans is named in a warning:
/// the ray epsilon grows with the whole scene's span ([`crate::trace::epsilon_of`]), so a node
/// moved far away by mistake blurs every contact of the rest and slows its rays.
const FAR_SPAN: f32 = 100.0;

/// A warning naming the nodes that lie far from the rest of the scene ([`FAR_SPAN`]), if any:
/// nodes are taken nearest first from the median of their boxes' centres, and the first that
/// widens the ray epsilon of those before it by [`FAR_SPAN`]× starts the far ones.
fn far_nodes(document: &gltf::Document, scene: &Scene) -> Option<String> {
    let mut boxes: std::collections::BTreeMap<u32, (Vec3, Vec3)> = Default::default();
    for inst in &scene.instances {
        let vertices = &scene.positions[inst.vertices.start as usize..inst.vertices.end as usize];
        let b = boxes.entry(inst.node).or_insert((Vec3::MAX, Vec3::MIN));
        for &p in vertices {
            *b = (b.0.min(p), b.1.max(p));
        }
    }
    let boxes: Vec<(u32, (Vec3, Vec3))> =
        boxes.into_iter().filter(|(_, b)| b.0.x <= b.1.x).collect();
    if boxes.len() < 2 {
        return None;
    }
    let median = |axis: usize| {
        let mut c: Vec<f32> = boxes
            .iter()
            .map(|(_, b)| (b.0[axis] + b.1[axis]) * 0.5)
            .collect();
        c.sort_by(f32::total_cmp);
        c[c.len() / 2]
    };
    let centre = Vec3::new(median(0), median(1), median(2));
    let reach = |b: &(Vec3, Vec3)| (b.0 - centre).abs().max((b.1 - centre).abs()).max_element();
    let mut order: Vec<&(u32, (Vec3, Vec3))> = boxes.iter().collect();
    order.sort_by(|a, b| reach(&a.1).total_cmp(&reach(&b.1)).then(a.0.cmp(&b.0)));
    let mut bulk = order[0].1;
    for (k, (_, b)) in order.iter().enumerate().skip(1) {
        let wider = (bulk.0.min(b.0), bulk.1.max(b.1));
        let (near, all) = (
            crate::trace::epsilon_of(bulk.0, bulk.1),
            crate::trace::epsilon_of(wider.0, wider.1),
        );
        if all < FAR_SPAN * near {
            bulk = wider;
            continue;
        }
        let (lo, hi) = scene.bounds();
        let far = &order[k..];
        let mut names: Vec<String> = (far.iter().take(3))
            .filter_map(|(n, _)| document.nodes().nth(*n as usize))
            .map(|n| node_label(&n))
            .collect();
        if far.len() > 3 {
            names.push(format!("{} more", far.len() - 3));
        }
        return Some(format!(
            "{} {} far from the rest of the scene: with them it spans {:.1} units, without them \
             {:.1}; the ray offset (a 100 000th of the span) grows from {:.2e} to {:.2e} units, \
             which blurs contact shadows everywhere and slows the rays. Moved by mistake?",
            names.join(", "),
            if far.len() == 1 { "lies" } else { "lie" },
            (hi - lo).max_element(),
            (bulk.1 - bulk.0).max_element(),
            near,
            crate::trace::epsilon_of(lo, hi),
        ));
    }
    None
}

fn node_label(node: &gltf::Node) -> String {
    match node.name() {
        Some(name) => format!("node {} '{name}'", node.index()),
        None => format!("node {}", node.index()),
    }
}

fn mesh_label(mesh: &gltf::Mesh) -> String {
    match mesh.name() {
        Some(name) => format!("mesh {} '{name}'", mesh.index()),
        None => format!("mesh {}", mesh.index()),
    }
}

/// Converts an index sequence to a triangle list, as the glTF spec (§3.7.2.1) orders strips
/// and fans; the position of a triangle in this list is its `source_triangle`.
fn triangle_list(mode: Mode, indices: &[u32]) -> Vec<[u32; 3]> {
    let fan_or_strip_count = indices.len().saturating_sub(2);
    match mode {
        Mode::TriangleStrip => (0..fan_or_strip_count)
            .map(|i| {
                let odd = i % 2;
                [indices[i], indices[i + 1 + odd], indices[i + 2 - odd]]
            })
            .collect(),
        Mode::TriangleFan => (0..fan_or_strip_count)
            .map(|i| [indices[i + 1], indices[i + 2], indices[0]])
            .collect(),
        _ => indices
            .chunks_exact(3)
            .map(|t| [t[0], t[1], t[2]])
            .collect(),
    }
}

/// Zero area, relative to the triangle's size (f32 cannot resolve anything thinner).
fn is_degenerate([a, b, c]: [Vec3; 3]) -> bool {
    let twice_area = (b - a).cross(c - a).length();
    let size = (b - a).length_squared() + (c - b).length_squared() + (a - c).length_squared();
    !twice_area.is_finite() || twice_area <= 1e-7 * size
}

/// World-space unit normals: the input's, transformed by the inverse transpose, or where they
/// are missing or zero, the area-weighted average of the adjacent faces.
fn vertex_normals(
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    input: Option<&[Vec3]>,
    placement: &Placement,
) -> Vec<Vec3> {
    let transformed: Option<Vec<Vec3>> = input.map(|normals| {
        normals
            .iter()
            .map(|&n| (placement.normal_matrix * n).normalize_or_zero())
            .collect()
    });
    if let Some(normals) = &transformed
        && normals.iter().all(|n| *n != Vec3::ZERO)
    {
        return normals.clone();
    }
    // The cross product's length is twice the area: summing it weights faces by area.
    let mut face_sums = vec![Vec3::ZERO; positions.len()];
    for &[a, b, c] in triangles {
        let [pa, pb, pc] = [a, b, c].map(|v| positions[v as usize]);
        let face = (pb - pa).cross(pc - pa);
        for v in [a, b, c] {
            face_sums[v as usize] += face;
        }
    }
    let mut normals = transformed.unwrap_or_else(|| vec![Vec3::ZERO; positions.len()]);
    for (normal, face_sum) in normals.iter_mut().zip(face_sums) {
        if *normal == Vec3::ZERO {
            // Unreferenced vertices (and cancelling faces) still need a finite unit normal.
            *normal = face_sum.normalize_or(Vec3::Z);
        }
    }
    normals
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Surface, Wrap, select};
    use serde_json::{Value, json};
    use std::f32::consts::FRAC_1_SQRT_2;

    /// Builds buffer 0 of a test document: each added array gets a view and an accessor.
    #[derive(Default)]
    struct Bin {
        bytes: Vec<u8>,
        views: Vec<Value>,
        accessors: Vec<Value>,
    }

    impl Bin {
        fn view(&mut self, data: &[u8]) -> usize {
            let offset = self.bytes.len();
            self.bytes.extend_from_slice(data);
            while !self.bytes.len().is_multiple_of(4) {
                self.bytes.push(0);
            }
            self.views
                .push(json!({"buffer": 0, "byteOffset": offset, "byteLength": data.len()}));
            self.views.len() - 1
        }

        fn accessor(&mut self, data: &[u8], accessor: Value) -> usize {
            let view = self.view(data);
            let mut accessor = accessor;
            accessor["bufferView"] = json!(view);
            self.accessors.push(accessor);
            self.accessors.len() - 1
        }

        /// A float VEC3 accessor, with the min/max that POSITION needs.
        fn vec3(&mut self, values: &[[f32; 3]]) -> usize {
            let data: Vec<u8> = values
                .iter()
                .flatten()
                .flat_map(|v| v.to_le_bytes())
                .collect();
            let bound = |pick: fn(f32, f32) -> f32, start: f32| {
                (0..3)
                    .map(|k| values.iter().map(|v| v[k]).fold(start, pick))
                    .collect::<Vec<_>>()
            };
            let accessor = json!({
                "componentType": 5126, "type": "VEC3", "count": values.len(),
                "min": bound(f32::min, f32::INFINITY), "max": bound(f32::max, f32::NEG_INFINITY),
            });
            self.accessor(&data, accessor)
        }

        fn vec2(&mut self, values: &[[f32; 2]]) -> usize {
            let data: Vec<u8> = values
                .iter()
                .flatten()
                .flat_map(|v| v.to_le_bytes())
                .collect();
            let accessor = json!({"componentType": 5126, "type": "VEC2", "count": values.len()});
            self.accessor(&data, accessor)
        }

        fn indices(&mut self, indices: &[u16]) -> usize {
            let data: Vec<u8> = indices.iter().flat_map(|i| i.to_le_bytes()).collect();
            let accessor = json!({"componentType": 5123, "type": "SCALAR", "count": indices.len()});
            self.accessor(&data, accessor)
        }

        /// Completes `doc` (nodes, meshes, scenes, …) with asset, buffer 0 as a data URI, views
        /// and accessors.
        fn document(&self, doc: Value) -> Value {
            let mut doc = doc;
            let uri = format!(
                "data:application/octet-stream;base64,{}",
                base64::engine::general_purpose::STANDARD.encode(&self.bytes)
            );
            doc["asset"] = json!({"version": "2.0"});
            doc["buffers"] = json!([{"uri": uri, "byteLength": self.bytes.len()}]);
            doc["bufferViews"] = json!(self.views);
            doc["accessors"] = json!(self.accessors);
            doc
        }
    }

    fn load_json(doc: &Value) -> Result<(Scene, Source)> {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("scene.gltf");
        std::fs::write(&path, serde_json::to_vec_pretty(doc).unwrap()).unwrap();
        load(&path)
    }

    fn load_ok(doc: &Value) -> Scene {
        load_json(doc).unwrap().0
    }

    fn message(error: Error) -> String {
        error.to_string()
    }

    const UNIT_TRIANGLE: [[f32; 3]; 3] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];

    /// One indexed triangle mesh (mesh 0) and the bin holding it.
    fn triangle_mesh(material: Option<usize>) -> (Bin, Value) {
        let mut bin = Bin::default();
        let position = bin.vec3(&UNIT_TRIANGLE);
        let normal = bin.vec3(&[[0.0, 0.0, 1.0]; 3]);
        let indices = bin.indices(&[0, 1, 2]);
        let mut primitive =
            json!({"attributes": {"POSITION": position, "NORMAL": normal}, "indices": indices});
        if let Some(m) = material {
            primitive["material"] = json!(m);
        }
        (bin, json!([{"primitives": [primitive]}]))
    }

    fn face_normal(scene: &Scene, t: usize) -> Vec3 {
        let [a, b, c] = scene.triangles[t].map(|v| scene.positions[v as usize]);
        (b - a).cross(c - a).normalize()
    }

    fn assert_close(a: Vec3, b: Vec3) {
        assert!(a.abs_diff_eq(b, 1e-5), "{a} != {b}");
    }

    #[test]
    fn node_transforms_compose_trs_and_matrices() {
        let (bin, meshes) = triangle_mesh(None);
        let (s, c) = (FRAC_1_SQRT_2, FRAC_1_SQRT_2);
        let doc = bin.document(json!({
            "scenes": [{"nodes": [0, 1, 3]}],
            "nodes": [
                {"mesh": 0, "translation": [1, 2, 3], "rotation": [0, 0, s, c], "scale": [2, 2, 2]},
                {"matrix": [1,0,0,0, 0,1,0,0, 0,0,1,0, 10,0,0,1], "children": [2]},
                {"mesh": 0, "scale": [2, 2, 2]},
                {"mesh": 0, "scale": [-1, 1, 1]},
            ],
            "meshes": meshes,
        }));
        let scene = load_ok(&doc);
        assert_eq!(scene.instances.len(), 3);
        let world = |instance: usize, k: u32| {
            scene.positions[(scene.instances[instance].vertices.start + k) as usize]
        };
        // (1,0,0) scaled by 2, turned 90° about Z, moved by (1,2,3).
        assert_close(world(0, 1), Vec3::new(1.0, 4.0, 3.0));
        assert_close(world(0, 2), Vec3::new(-1.0, 2.0, 3.0));
        // Parent matrix × child scale.
        assert_eq!(scene.instances[1].node, 2);
        assert_close(world(1, 1), Vec3::new(12.0, 0.0, 0.0));
        // Mirrored instance: winding is reversed so the face still agrees with its normal.
        assert_close(world(2, 1), Vec3::new(-1.0, 0.0, 0.0));
        for t in 0..scene.triangles.len() {
            let vertex_normal = scene.normals[scene.triangles[t][0] as usize];
            assert_close(face_normal(&scene, t), vertex_normal);
            assert_close(vertex_normal, Vec3::Z);
        }
    }

    #[test]
    fn non_uniform_scale_transforms_normals_by_inverse_transpose() {
        let mut bin = Bin::default();
        // A 45° slope in x/z: normal (-1, 0, 1)/√2.
        let position = bin.vec3(&[[0.0, 0.0, 0.0], [1.0, 0.0, 1.0], [0.0, 1.0, 0.0]]);
        let normal = bin.vec3(&[[-FRAC_1_SQRT_2, 0.0, FRAC_1_SQRT_2]; 3]);
        let doc = bin.document(json!({
            "scenes": [{"nodes": [0]}],
            "nodes": [{"mesh": 0, "scale": [2, 1, 1]}],
            "meshes": [{"primitives": [{"attributes": {"POSITION": position, "NORMAL": normal}}]}],
        }));
        let scene = load_ok(&doc);
        assert_close(scene.normals[0], face_normal(&scene, 0));
        assert_close(scene.normals[0], Vec3::new(-1.0, 0.0, 2.0).normalize());
    }

    #[test]
    fn a_mesh_used_by_two_nodes_gives_two_instances() {
        let (bin, meshes) = triangle_mesh(None);
        let doc = bin.document(json!({
            "scene": 0,
            "scenes": [{"nodes": [0, 1]}],
            "nodes": [{"mesh": 0}, {"mesh": 0, "translation": [0, 0, 5]}],
            "meshes": meshes,
        }));
        let scene = load_ok(&doc);
        assert_eq!(scene.instances.len(), 2);
        assert_eq!(scene.positions.len(), 6);
        assert_eq!(scene.triangles, vec![[0, 1, 2], [3, 4, 5]]);
        assert_eq!(scene.triangle_instance, vec![0, 1]);
        let [a, b] = [&scene.instances[0], &scene.instances[1]];
        assert_eq!((a.node, b.node, a.mesh, b.mesh), (0, 1, 0, 0));
        assert_eq!((a.vertices.clone(), b.vertices.clone()), (0..3, 3..6));
        assert_close(scene.positions[4], Vec3::new(1.0, 0.0, 5.0));
        // Both use glTF's default material, appended after the (no) glTF materials.
        assert_eq!(scene.materials.len(), 1);
        assert_eq!(scene.materials[0].source, None);
    }

    #[test]
    fn strips_and_fans_become_counter_clockwise_lists() {
        let mut bin = Bin::default();
        let strip = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 2.0, 0.0],
        ];
        let fan = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
        ];
        let strip = bin.vec3(&strip);
        let fan_positions = bin.vec3(&fan);
        let fan_indices = bin.indices(&[0, 1, 2, 3]);
        let doc = bin.document(json!({
            "scenes": [{"nodes": [0]}],
            "nodes": [{"mesh": 0}],
            "meshes": [{"primitives": [
                {"attributes": {"POSITION": strip}, "mode": 5},
                {"attributes": {"POSITION": fan_positions}, "indices": fan_indices, "mode": 6},
            ]}],
        }));
        let scene = load_ok(&doc);
        assert_eq!(
            scene.triangles,
            vec![[0, 1, 2], [1, 3, 2], [2, 3, 4], [6, 7, 5], [7, 8, 5]]
        );
        assert_eq!(scene.instances[0].source_triangle, vec![0, 1, 2]);
        assert_eq!(scene.instances[1].source_triangle, vec![0, 1]);
        for t in 0..scene.triangles.len() {
            assert_close(face_normal(&scene, t), Vec3::Z);
        }
        assert_eq!(scene.stats.generated_normals, 2);
    }

    #[test]
    fn missing_normals_are_area_weighted_and_zero_normals_replaced() {
        let mut bin = Bin::default();
        let positions = [
            [0.0, 0.0, 0.0],
            [2.0, 0.0, 0.0],
            [0.0, 2.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ];
        let position = bin.vec3(&positions);
        let indices = bin.indices(&[0, 1, 2, 0, 3, 4]);
        let second_position = bin.vec3(&UNIT_TRIANGLE);
        let zero_normal = bin.vec3(&[[0.0, 0.0, 1.0], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]);
        let doc = bin.document(json!({
            "scenes": [{"nodes": [0]}],
            "nodes": [{"mesh": 0}],
            "meshes": [{"primitives": [
                {"attributes": {"POSITION": position}, "indices": indices},
                {"attributes": {"POSITION": second_position, "NORMAL": zero_normal}},
            ]}],
        }));
        let scene = load_ok(&doc);
        assert_eq!(scene.stats.generated_normals, 1);
        // Vertex 0 touches a +Z face of area 2 and a +X face of area 0.5.
        assert_close(scene.normals[0], Vec3::new(1.0, 0.0, 4.0).normalize());
        assert_close(scene.normals[1], Vec3::Z);
        assert_close(scene.normals[3], Vec3::X);
        assert_close(scene.normals[6], Vec3::Z);
        assert!(
            scene
                .normals
                .iter()
                .all(|n| (n.length() - 1.0).abs() < 1e-5)
        );
    }

    #[test]
    fn texcoords_are_read_and_has_uv1_set() {
        let mut bin = Bin::default();
        let position = bin.vec3(&UNIT_TRIANGLE);
        let uv0 = bin.vec2(&[[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]);
        let uv1 = bin.vec2(&[[0.5, 0.5], [0.75, 0.5], [0.5, 0.75]]);
        let doc = bin.document(json!({
            "scenes": [{"nodes": [0]}],
            "nodes": [{"mesh": 0}],
            "meshes": [{"primitives": [
                {"attributes": {"POSITION": position, "TEXCOORD_0": uv0, "TEXCOORD_1": uv1}},
                {"attributes": {"POSITION": position}},
            ]}],
        }));
        let scene = load_ok(&doc);
        assert!(scene.instances[0].has_uv1 && !scene.instances[1].has_uv1);
        assert_eq!(scene.uv0[1], Vec2::new(1.0, 0.0));
        assert_eq!(scene.uv1[2], Vec2::new(0.5, 0.75));
        assert_eq!(scene.uv0[4], Vec2::ZERO);
    }

    #[test]
    fn u8_and_u32_indices_and_normalized_texcoords_are_decoded() {
        let mut bin = Bin::default();
        let position = bin.vec3(&UNIT_TRIANGLE);
        let u8_indices = bin.accessor(
            &[0, 1, 2],
            json!({"componentType": 5121, "type": "SCALAR", "count": 3}),
        );
        let u32_bytes: Vec<u8> = [2u32, 0, 1].iter().flat_map(|i| i.to_le_bytes()).collect();
        let u32_indices = bin.accessor(
            &u32_bytes,
            json!({"componentType": 5125, "type": "SCALAR", "count": 3}),
        );
        let uv_bytes = [0u8, 255, 255, 0, 51, 102];
        let uv = bin.accessor(
            &uv_bytes,
            json!({"componentType": 5121, "normalized": true, "type": "VEC2", "count": 3}),
        );
        let doc = bin.document(json!({
            "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
            "meshes": [{"primitives": [
                {"attributes": {"POSITION": position, "TEXCOORD_0": uv}, "indices": u8_indices},
                {"attributes": {"POSITION": position}, "indices": u32_indices},
            ]}],
        }));
        let scene = load_ok(&doc);
        assert_eq!(scene.triangles, vec![[0, 1, 2], [5, 3, 4]]);
        let expected = [
            Vec2::new(0.0, 1.0),
            Vec2::new(1.0, 0.0),
            Vec2::new(0.2, 0.4),
        ];
        for (uv, expected) in scene.uv0.iter().zip(expected) {
            assert!(uv.abs_diff_eq(expected, 1e-6), "{uv} != {expected}");
        }
    }

    #[test]
    fn double_sided_material_adds_a_flipped_back_instance() {
        let (bin, meshes) = triangle_mesh(Some(0));
        let doc = bin.document(json!({
            "scenes": [{"nodes": [0]}],
            "nodes": [{"mesh": 0, "translation": [0, 0, 1]}],
            "meshes": meshes,
            "materials": [{"doubleSided": true}],
        }));
        let scene = load_ok(&doc);
        assert_eq!(scene.instances.len(), 2);
        let [front, back] = [&scene.instances[0], &scene.instances[1]];
        assert_eq!(
            (front.back, front.back_of, back.back, back.back_of),
            (Some(1), None, None, Some(0))
        );
        assert_eq!(back.source_triangle, front.source_triangle);
        assert_eq!(
            (back.node, back.mesh, back.primitive, back.material),
            (0, 0, 0, 0)
        );
        assert_eq!(back.vertices, 3..6);
        assert_eq!(scene.triangles, vec![[0, 1, 2], [3, 5, 4]]);
        assert_eq!(scene.triangle_instance, vec![0, 1]);
        assert_eq!(scene.positions[..3], scene.positions[3..]);
        assert_eq!(scene.uv0[..3], scene.uv0[3..]);
        assert_close(scene.normals[4], -Vec3::Z);
        assert_close(face_normal(&scene, 1), -Vec3::Z);
        assert!(scene.materials[0].double_sided);
    }

    #[test]
    fn materials_carry_base_color_and_emissive_strength() {
        let (bin, _) = triangle_mesh(None);
        let doc = bin.document(json!({
            "extensionsUsed": ["KHR_materials_emissive_strength"],
            "extensionsRequired": ["KHR_materials_emissive_strength"],
            "scenes": [{"nodes": [0]}],
            "nodes": [{"mesh": 0}],
            "meshes": [{"primitives": [
                {"attributes": {"POSITION": 0}, "material": 1},
                {"attributes": {"POSITION": 0}},
            ]}],
            "materials": [
                {"name": "unused"},
                {
                    "name": "lamp",
                    "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.25, 1.0, 1.0]},
                    "emissiveFactor": [1.0, 0.5, 0.25],
                    "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 4.0}},
                },
            ],
        }));
        let scene = load_ok(&doc);
        assert_eq!(scene.materials.len(), 3);
        let lamp = &scene.materials[1];
        assert_eq!((lamp.name.as_deref(), lamp.source), (Some("lamp"), Some(1)));
        assert_eq!(lamp.emission, Vec3::new(4.0, 2.0, 1.0));
        assert_eq!(lamp.base_color, Vec3::new(0.5, 0.25, 1.0));
        assert_eq!(scene.materials[2].source, None);
        assert_eq!(scene.instances[0].material, 1);
        assert_eq!(scene.instances[1].material, 2);
        assert!(scene.has_light_sources());
    }

    #[test]
    fn surfaces_read_the_extensions() {
        let (bin, _) = triangle_mesh(None);
        let doc = bin.document(json!({
            "scenes": [{"nodes": [0]}],
            "nodes": [{"mesh": 0}],
            "meshes": [{"primitives": [
                {"attributes": {"POSITION": 0}, "material": 0},
                {"attributes": {"POSITION": 0}},
            ]}],
            "materials": [{
                "pbrMetallicRoughness": { "metallicFactor": 0.0, "roughnessFactor": 0.1 },
                "extensions": {
                    "KHR_materials_transmission": { "transmissionFactor": 0.9 },
                    "KHR_materials_ior": { "ior": 1.33 },
                    "KHR_materials_volume": { "attenuationColor": [0.5, 1.0, 1.0], "attenuationDistance": 2.0 }
                }
            }],
        }));
        let scene = load_ok(&doc);
        let s = &scene.materials[0].surface;
        assert_eq!((s.metallic, s.roughness, s.transmission), (0.0, 0.1, 0.9));
        assert!((s.ior - 1.33).abs() < 1e-6);
        assert!((s.attenuation.x - 0.5f32.ln().abs() / 2.0).abs() < 1e-6);
        assert_eq!(s.attenuation.y, 0.0);
        // glTF's default material.
        assert_eq!(scene.materials[1].source, None);
        assert_eq!(scene.materials[1].surface, Surface::default());
    }

    #[test]
    fn node_transforms_place_cameras() {
        let (bin, _) = triangle_mesh(None);
        let doc = bin.document(json!({
            "scene": 0,
            "scenes": [{ "nodes": [0] }],
            "nodes": [
                { "translation": [1.0, 0.0, 0.0], "children": [1, 2] },
                { "name": "cam", "translation": [0.0, 2.0, 0.0], "camera": 0 },
                { "camera": 1 }
            ],
            "cameras": [
                { "type": "perspective", "perspective": { "yfov": 0.5, "znear": 0.1 } },
                { "type": "orthographic", "orthographic": { "xmag": 1.0, "ymag": 1.0, "znear": 0.1, "zfar": 10.0 } }
            ]
        }));
        let cameras = load_ok(&doc).cameras;
        assert_eq!(cameras.len(), 1, "orthographic cameras are skipped");
        let c = &select(&cameras, "cam").unwrap().camera;
        assert!((c.eye - Vec3::new(1.0, 2.0, 0.0)).length() < 1e-6);
        assert!((c.forward + Vec3::Z).length() < 1e-6);
        assert!(select(&cameras, "0").is_ok() && select(&cameras, "7").is_err());
    }

    #[test]
    fn lightmap_references_of_a_baked_file_are_resolved() {
        let (bin, _) = triangle_mesh(None);
        let lightmap = json!({"lightmap": {"exr": "my%20scene_lightmap0.exr", "page": 0}});
        let doc = bin.document(json!({
            "scenes": [{"nodes": [0]}],
            "nodes": [{"mesh": 0}],
            "meshes": [{"primitives": [
                {"attributes": {"POSITION": 0}, "extras": lightmap, "material": 0},
                {"attributes": {"POSITION": 0}},
            ]}],
            "materials": [{"doubleSided": true}],
        }));
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("scene.gltf");
        std::fs::write(&path, serde_json::to_vec(&doc).unwrap()).unwrap();
        let scene = load(&path).unwrap().0;
        let expected = Some(dir.path().join("my scene_lightmap0.exr"));
        assert_eq!(scene.instances[0].lightmap, expected);
        assert_eq!(
            scene.instances[1].lightmap, expected,
            "the back face shares the page"
        );
        assert_eq!(scene.instances[2].lightmap, None);
    }

    #[test]
    fn punctual_lights_are_placed_in_world_space() {
        let (bin, meshes) = triangle_mesh(None);
        let s = FRAC_1_SQRT_2;
        let doc = bin.document(json!({
            "extensionsUsed": ["KHR_lights_punctual"],
            "extensions": {"KHR_lights_punctual": {"lights": [
                {"type": "point", "color": [1.0, 0.5, 0.25], "intensity": 8.0, "range": 10.0, "name": "bulb"},
                {"type": "spot", "intensity": 2.0, "spot": {}},
                {"type": "directional", "intensity": 3.0},
                {"type": "spot", "spot": {"innerConeAngle": 0.1, "outerConeAngle": 0.5}},
            ]}},
            "scenes": [{"nodes": [0, 1]}],
            "nodes": [
                {"translation": [1, 2, 3], "extensions": {"KHR_lights_punctual": {"light": 0}}, "children": [2]},
                {"rotation": [-s, 0, 0, s], "extensions": {"KHR_lights_punctual": {"light": 2}}},
                {"translation": [0, 0, 1], "extensions": {"KHR_lights_punctual": {"light": 1}}, "children": [3]},
                {"rotation": [-s, 0, 0, s], "extensions": {"KHR_lights_punctual": {"light": 3}}},
                {"mesh": 0, "extensions": {"KHR_lights_punctual": {"light": 0}}},
            ],
            "meshes": meshes,
        }));
        let scene = load_ok(&doc);
        // Node 4 is not in the scene: its light and mesh are not loaded.
        assert!(scene.instances.is_empty());
        let lights = &scene.lights;
        assert_eq!(lights.len(), 4);
        assert_eq!(lights[0].kind, LightKind::Point);
        assert_eq!(lights[0].name.as_deref(), Some("bulb"));
        assert_eq!(lights[0].position, Vec3::new(1.0, 2.0, 3.0));
        assert_eq!(lights[0].intensity, Vec3::new(8.0, 4.0, 2.0));
        assert_eq!(lights[0].range, Some(10.0));
        let default_cone = LightKind::Spot {
            inner_cone_angle: 0.0,
            outer_cone_angle: std::f32::consts::FRAC_PI_4,
        };
        assert_eq!(lights[1].kind, default_cone);
        assert_eq!(lights[1].position, Vec3::new(1.0, 2.0, 4.0));
        assert_close(lights[1].direction, Vec3::NEG_Z);
        assert_eq!(lights[1].range, None);
        assert_eq!(
            lights[2].kind,
            LightKind::Spot {
                inner_cone_angle: 0.1,
                outer_cone_angle: 0.5
            }
        );
        assert_close(lights[2].direction, Vec3::NEG_Y);
        assert_eq!(lights[2].intensity, Vec3::ONE);
        assert_eq!(lights[3].kind, LightKind::Directional);
        assert_close(lights[3].direction, Vec3::NEG_Y);
        assert_eq!(lights[3].intensity, Vec3::splat(3.0));
    }

    #[test]
    fn missing_buffer_file_is_named() {
        let (bin, meshes) = triangle_mesh(None);
        let mut doc = bin.document(json!({
            "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}], "meshes": meshes,
        }));
        doc["buffers"][0]["uri"] = json!("scene%20data.bin");
        let error = load_json(&doc).unwrap_err();
        assert!(matches!(error, Error::Invalid { .. }), "{error:?}");
        let text = message(error);
        assert!(
            text.contains("buffer 0 'scene%20data.bin' not found")
                && text.contains("scene data.bin"),
            "{text}"
        );
    }

    #[test]
    fn external_buffer_file_is_read() {
        let (bin, meshes) = triangle_mesh(None);
        let mut doc = bin.document(json!({
            "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}], "meshes": meshes,
        }));
        doc["buffers"][0]["uri"] = json!("scene.bin");
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("scene.bin"), &bin.bytes).unwrap();
        let path = dir.path().join("scene.gltf");
        std::fs::write(&path, serde_json::to_vec(&doc).unwrap()).unwrap();
        let (scene, source) = load(&path).unwrap();
        assert_eq!(scene.triangles.len(), 1);
        assert_eq!(source.buffers, vec![bin.bytes.clone()]);
        assert_eq!(source.json, doc);
        assert!(!source.is_glb);
    }

    #[test]
    fn bad_input_gives_clear_errors() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("nothing.gltf");
        assert!(matches!(load(&missing), Err(Error::Io { .. })));

        let garbage = dir.path().join("garbage.gltf");
        std::fs::write(&garbage, b"\x89PNG not json").unwrap();
        let text = message(load(&garbage).unwrap_err());
        assert!(
            text.contains("garbage.gltf") && text.contains("not a glTF file"),
            "{text}"
        );

        let truncated = dir.path().join("truncated.glb");
        std::fs::write(&truncated, b"glTF\x02\0\0\0\x04\0\0\0").unwrap();
        assert!(matches!(load(&truncated), Err(Error::Invalid { .. })));

        let (bin, meshes) = triangle_mesh(None);
        let mut draco = bin.document(json!({
            "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}], "meshes": meshes,
        }));
        draco["extensionsUsed"] = json!(["KHR_draco_mesh_compression"]);
        draco["extensionsRequired"] = json!(["KHR_draco_mesh_compression"]);
        let error = load_json(&draco).unwrap_err();
        assert!(matches!(error, Error::Unsupported { .. }), "{error:?}");
        assert!(message(error).contains("KHR_draco_mesh_compression"));

        let mut no_scene = draco.clone();
        no_scene
            .as_object_mut()
            .unwrap()
            .remove("extensionsRequired");
        no_scene.as_object_mut().unwrap().remove("scenes");
        assert!(message(load_json(&no_scene).unwrap_err()).contains("no scenes"));

        let bad_index = bin.document(json!({
            "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
            "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 7}]}],
        }));
        assert!(matches!(load_json(&bad_index), Err(Error::Invalid { .. })));
    }

    #[test]
    fn out_of_range_index_and_non_finite_positions_are_errors() {
        let mut bin = Bin::default();
        let position = bin.vec3(&UNIT_TRIANGLE);
        let indices = bin.indices(&[0, 1, 5]);
        let nan = bin.vec3(&[[0.0, 0.0, 0.0], [f32::NAN, 0.0, 0.0], [0.0, 1.0, 0.0]]);
        let doc = |primitive: Value| {
            bin.document(json!({
                "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
                "meshes": [{"name": "wall", "primitives": [primitive]}],
            }))
        };
        let text = message(
            load_json(&doc(
                json!({"attributes": {"POSITION": position}, "indices": indices}),
            ))
            .unwrap_err(),
        );
        assert!(
            text.contains("mesh 0 'wall'") && text.contains("index 5"),
            "{text}"
        );
        let text = message(load_json(&doc(json!({"attributes": {"POSITION": nan}}))).unwrap_err());
        assert!(
            text.contains("mesh 0 'wall'") && text.contains("not finite"),
            "{text}"
        );
    }

    #[test]
    fn degenerate_triangles_are_skipped_and_counted() {
        let mut bin = Bin::default();
        let positions = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [2.0, 0.0, 0.0],
        ];
        let position = bin.vec3(&positions);
        // A good triangle, a repeated index, a collinear one, then another good one.
        let indices = bin.indices(&[0, 1, 2, 0, 0, 1, 0, 1, 3, 1, 3, 2]);
        let doc = bin.document(json!({
            "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
            "meshes": [{"primitives": [{"attributes": {"POSITION": position}, "indices": indices}]}],
        }));
        let scene = load_ok(&doc);
        assert_eq!(scene.stats.degenerate_triangles, 2);
        assert_eq!(scene.triangles, vec![[0, 1, 2], [1, 3, 2]]);
        assert_eq!(scene.instances[0].source_triangle, vec![0, 3]);
    }

    #[test]
    fn points_lines_skins_and_morph_targets_are_skipped_with_warnings() {
        let mut bin = Bin::default();
        let position = bin.vec3(&UNIT_TRIANGLE);
        let doc = bin.document(json!({
            "scenes": [{"nodes": [0, 1]}],
            "nodes": [{"mesh": 0}, {"mesh": 1, "skin": 0}],
            "skins": [{"joints": [0]}],
            "meshes": [
                {"primitives": [
                    {"attributes": {"POSITION": position}, "mode": 0},
                    {"attributes": {"POSITION": position}, "mode": 1},
                    {"attributes": {"POSITION": position}, "targets": [{"POSITION": position}]},
                    {"attributes": {"POSITION": position}},
                ]},
                {"primitives": [{"attributes": {"POSITION": position}}]},
            ],
        }));
        let scene = load_ok(&doc);
        assert_eq!(scene.stats.skipped_primitives, 4);
        assert_eq!(scene.instances.len(), 1);
        assert_eq!(scene.instances[0].primitive, 3);
        let warnings = scene.stats.warnings.join("\n");
        for word in ["Points", "Lines", "morph", "skinned"] {
            assert!(warnings.contains(word), "{warnings}");
        }
    }

    #[test]
    fn glb_loads_like_gltf() {
        let (bin, meshes) = triangle_mesh(None);
        let doc = bin.document(json!({
            "scenes": [{"nodes": [0, 1]}],
            "nodes": [{"mesh": 0}, {"mesh": 0, "translation": [3, 0, 0]}],
            "meshes": meshes,
        }));
        let gltf = load_ok(&doc);

        let mut glb_doc = doc.clone();
        glb_doc["buffers"][0].as_object_mut().unwrap().remove("uri");
        let dir = tempfile::tempdir().unwrap();
        // Detected by magic, not by extension.
        let path = dir.path().join("scene.gltf");
        let json = serde_json::to_vec(&glb_doc).unwrap();
        std::fs::write(
            &path,
            crate::output::glb::container(json, bin.bytes.clone()),
        )
        .unwrap();
        let (scene, source) = load(&path).unwrap();
        assert!(source.is_glb);
        assert_eq!(source.json, glb_doc);
        assert_eq!(source.buffers, vec![bin.bytes.clone()]);
        assert_eq!(scene.positions, gltf.positions);
        assert_eq!(scene.normals, gltf.normals);
        assert_eq!(scene.triangles, gltf.triangles);
        assert_eq!(scene.instances.len(), 2);
    }

    fn png(pixels: &[[u8; 3]], width: u32) -> Vec<u8> {
        let raw = pixels.iter().flatten().copied().collect();
        let image = image::RgbImage::from_raw(width, pixels.len() as u32 / width, raw).unwrap();
        let mut bytes = std::io::Cursor::new(Vec::new());
        image.write_to(&mut bytes, image::ImageFormat::Png).unwrap();
        bytes.into_inner()
    }

    #[test]
    fn textures_are_srgb_decoded_and_shared() {
        let (mut bin, _) = triangle_mesh(None);
        let image_view = bin.view(&png(&[[255, 188, 0], [0, 0, 0]], 2));
        let data_uri = format!(
            "data:image/png;base64,{}",
            base64::engine::general_purpose::STANDARD.encode(png(&[[10, 20, 30]], 1))
        );
        let doc = bin.document(json!({
            "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
            "meshes": [{"primitives": [
                {"attributes": {"POSITION": 0}, "material": 0},
                {"attributes": {"POSITION": 0}, "material": 1},
            ]}],
            "materials": [
                {"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}, "emissiveTexture": {"index": 2}},
                {"pbrMetallicRoughness": {"baseColorTexture": {"index": 1, "texCoord": 1}}, "emissiveTexture": {"index": 3}},
            ],
            "textures": [
                {"source": 0, "sampler": 0},
                {"source": 0, "sampler": 0},
                {"source": 1},
                {"source": 2},
            ],
            "samplers": [{"wrapS": 33071, "wrapT": 33648}],
            "images": [
                {"bufferView": image_view, "mimeType": "image/png"},
                {"uri": data_uri},
                {"uri": "data:image/ktx2;base64,AAAA"},
            ],
        }));
        let scene = load_ok(&doc);
        assert_eq!(scene.textures.len(), 2);
        let [a, b] = [&scene.materials[0], &scene.materials[1]];
        assert_eq!(
            (a.base_color_texture, b.base_color_texture),
            (Some(0), Some(0))
        );
        assert_eq!((a.emissive_texture, b.emissive_texture), (Some(1), None));
        let texture = &scene.textures[0];
        assert_eq!((texture.width, texture.height), (2, 1));
        assert_eq!(
            (texture.wrap_s, texture.wrap_t),
            (Wrap::ClampToEdge, Wrap::MirroredRepeat)
        );
        // sRGB 188/255 is linear 0.5.
        assert!(
            texture.texels[0].abs_diff_eq(Vec3::new(1.0, 0.5029, 0.0), 1e-3),
            "{}",
            texture.texels[0]
        );
        assert_eq!(scene.textures[1].wrap_s, Wrap::Repeat);
        let warnings = scene.stats.warnings.join("\n");
        assert!(warnings.contains("image 2 cannot be decoded"), "{warnings}");
        assert!(warnings.contains("TEXCOORD_1"), "{warnings}");
    }

    #[test]
    fn a_panic_in_the_gltf_crate_becomes_an_error_naming_the_element() {
        let files = Files {
            gltf_path: Path::new("scene.gltf"),
            dir: Path::new(""),
        };
        let panics = || -> u32 { panic!("index out of bounds") };
        let text = message(guarded(&files, "mesh 0 primitive 0", panics).unwrap_err());
        assert!(
            text.contains("scene.gltf: mesh 0 primitive 0") && text.contains("index out of bounds"),
            "{text}"
        );
    }

    #[test]
    fn missing_image_file_is_named() {
        let (bin, _) = triangle_mesh(None);
        let doc = bin.document(json!({
            "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
            "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "material": 0}]}],
            "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
            "textures": [{"source": 0}],
            "images": [{"uri": "wood.png"}],
        }));
        let text = message(load_json(&doc).unwrap_err());
        assert!(text.contains("image 0 'wood.png' not found"), "{text}");
    }
}
