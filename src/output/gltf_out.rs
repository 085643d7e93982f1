//! glTF writer: the input document, edited in place, so everything the baker does not touch
//! (names, cameras, animations, skins, samplers, unknown extensions, extras) is kept.
//!
//! What changes:
//! - All input buffers are merged into buffer 0 (`<stem>.bin`, or the BIN chunk of `<stem>.glb`);
//!   new vertex and index data is appended to it.
//! - External images are copied next to the output (same relative path when it is a plain one,
//!   else `images/<file name>`).
//! - Every baked primitive is re-indexed through its atlas vertices (chart seams split vertices),
//!   gets the lightmap UVs as `TEXCOORD_1` (and as `TEXCOORD_0` when it has none: glTF wants
//!   contiguous sets), and is split into one primitive per lightmap page. Triangles the loader
//!   dropped as degenerate are not written. The back face of a double-sided primitive becomes an
//!   extra single-sided primitive (reversed winding, negated normals and tangent handedness).
//! - Each (material, page) pair gets a material with `FB_materials_lightmap` pointing at the
//!   page's PNG; each baked primitive gets `extras.lightmap = { exr, page }` (an `extras` that is
//!   not an object is replaced).
//! - A mesh placed by several nodes is duplicated per node: each placement has its own UVs.
//!   With `--instancing share` ([`Atlas::shared`]) a shared mesh is written once instead, its
//!   `TEXCOORD_1` the base layout in \[0,1\], and each node placing it gets
//!   `extras.lightmap = { exr, page, scale_offset: [sx, sy, ox, oy] }`
//!   (`uv_page = uv * scale + offset`). Its primitives carry no `extras.lightmap` and its
//!   materials no `FB_materials_lightmap` (the extension has one texture and no transform per
//!   node; a material naming one page would light every other node wrongly).
//!
//! Primitives the loader skipped (points, lines, skinned, morphed) are left as they are. The
//! accessors the re-indexed primitives no longer use stay in the file: extensions we do not know
//! may reference accessors by index, so renumbering them is not safe.

use std::collections::{BTreeMap, BTreeSet};
use std::fs;
use std::path::{Component, Path};

use serde_json::{Map, Value, json};

use super::gltf_out_accessor::{
    BlendKind, Elements, FLOAT, Layout, UNSIGNED_INT, UNSIGNED_SHORT, read_accessor,
};
use super::{Staging, glb};
use crate::atlas::{Atlas, InstanceUv};
use crate::scene::{Scene, Source};
use crate::{Error, Result};

/// `extras.lightmap.directional`: the L1 SH pages by coefficient name, and how to read them.
fn directional_extras(names: &[String; 4]) -> Value {
    let mut v = json!({"convention": crate::lightmap::directional::CONVENTION});
    for (name, file) in crate::lightmap::directional::NAMES.iter().zip(names) {
        v[*name] = json!(encode_uri(file));
    }
    v
}

/// `extras.lightmap` naming page `page`'s EXR (and its directional pages).
fn page_extras(files: &PageFiles, page: u32) -> Value {
    let mut lightmap = json!({"exr": encode_uri(&files.exr), "page": page});
    if let Some(names) = &files.directional {
        lightmap["directional"] = directional_extras(names);
    }
    lightmap
}

/// The material extension that carries the lightmap texture.
const LIGHTMAP_EXTENSION: &str = "FB_materials_lightmap";
const ARRAY_BUFFER: u64 = 34962;
const ELEMENT_ARRAY_BUFFER: u64 = 34963;
const LINEAR: u64 = 9729;
const CLAMP_TO_EDGE: u64 = 33071;

/// File names (relative to the output glTF) of one lightmap page.
#[derive(Clone, Debug)]
pub(crate) struct PageFiles {
    pub(crate) exr: String,
    pub(crate) png: String,
    /// The directional pages (`lightmap::directional::NAMES` order), when baked.
    pub(crate) directional: Option<[String; 4]>,
}

/// Writes `<stem>.gltf` + `<stem>.bin` (or `<stem>.glb` for .glb input) into `staging`, plus
/// copies of the input's external images.
pub(crate) fn write_gltf(
    scene: &Scene,
    source: &Source,
    atlas: &Atlas,
    pages: &[PageFiles],
    staging: &mut Staging,
    stem: &str,
) -> Result<()> {
    if atlas.instances.len() != scene.instances.len() {
        return Err(Error::Internal(
            "the atlas does not match the scene's instances".to_string(),
        ));
    }
    let mut doc = Document::merge_buffers(source)?;
    let mut reserved: Vec<String> = pages
        .iter()
        .flat_map(|p| [p.exr.clone(), p.png.clone()])
        .chain(
            pages
                .iter()
                .flat_map(|p| p.directional.iter().flatten().cloned()),
        )
        .collect();
    reserved.extend(["gltf", "bin", "glb"].map(|ext| format!("{stem}.{ext}")));
    doc.copy_images(source, &reserved, staging)?;
    let page_textures = doc.add_page_textures(pages);
    let target_meshes = doc.duplicate_meshes(scene, atlas)?;
    let paged = doc.bake_primitives(scene, source, atlas, pages, &page_textures, &target_meshes)?;
    doc.add_node_rects(atlas, pages)?;
    if paged {
        doc.mark_extension_used(LIGHTMAP_EXTENSION);
    }
    doc.append_generator();
    doc.finish(stem, source.is_glb, staging)
}

/// The output document being edited: JSON plus the single merged binary buffer.
struct Document<'a> {
    /// The input file, for error messages.
    path: &'a Path,
    json: Value,
    bin: Vec<u8>,
    /// `name` and `extras` of the input's first buffer, kept on the merged one.
    buffer_template: Map<String, Value>,
}

/// One baked (instance, page) pair: which atlas triangles go into the output primitive.
struct Part {
    instance: usize,
    /// `None` for a shared mesh's primitive: every node has its own page.
    page: Option<u32>,
    triangles: Vec<u32>,
}

/// What a lightmapped material depends on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
struct MaterialKey {
    /// glTF material (`None` = the default material).
    material: Option<usize>,
    /// Double-sided surfaces are baked as two single-sided primitives.
    single_sided: bool,
    /// `None`: a shared mesh's material, without `FB_materials_lightmap`.
    page: Option<u32>,
    /// Where the primitive's own `TEXCOORD_1` moved (textures sampling set 1 follow it).
    uv1_moved_to: Option<u32>,
}

impl<'a> Document<'a> {
    /// Concatenates the input buffers (16-byte aligned) into one and points every buffer view
    /// at it.
    fn merge_buffers(source: &'a Source) -> Result<Document<'a>> {
        let path = source.path.as_path();
        let mut json = source.json.clone();
        if !json.is_object() {
            return Err(Error::invalid(path, "the glTF JSON is not an object"));
        }
        let declared = json
            .get("buffers")
            .and_then(Value::as_array)
            .map_or(0, Vec::len);
        if declared != source.buffers.len() {
            return Err(Error::invalid(
                path,
                format!(
                    "{declared} buffers declared but {} loaded",
                    source.buffers.len()
                ),
            ));
        }
        let mut bin = Vec::new();
        let mut bases = Vec::with_capacity(source.buffers.len());
        for buffer in &source.buffers {
            bin.resize(bin.len().next_multiple_of(16), 0);
            bases.push(bin.len());
            bin.extend_from_slice(buffer);
        }
        if let Some(views) = json.get_mut("bufferViews").and_then(Value::as_array_mut) {
            for (i, view) in views.iter_mut().enumerate() {
                let buffer = view
                    .get("buffer")
                    .and_then(Value::as_u64)
                    .unwrap_or(u64::MAX);
                let base = *bases.get(buffer as usize).ok_or_else(|| {
                    Error::invalid(path, format!("bufferView {i} refers to a missing buffer"))
                })?;
                let offset = view.get("byteOffset").and_then(Value::as_u64).unwrap_or(0) as usize;
                view["buffer"] = json!(0);
                if base > 0 || view.get("byteOffset").is_some() {
                    view["byteOffset"] = json!(offset + base);
                }
            }
        }
        let buffer_template = json
            .get("buffers")
            .and_then(|b| b.get(0))
            .and_then(Value::as_object)
            .map(|b| {
                b.iter()
                    .filter(|(k, _)| *k == "name" || *k == "extras")
                    .map(|(k, v)| (k.clone(), v.clone()))
                    .collect()
            })
            .unwrap_or_default();
        Ok(Document {
            path,
            json,
            bin,
            buffer_template,
        })
    }

    fn invalid(&self, message: impl Into<String>) -> Error {
        Error::invalid(self.path, message)
    }

    /// The root array `key`, created if missing.
    fn array(&mut self, key: &str) -> &mut Vec<Value> {
        let root = self.json.as_object_mut().expect("checked in merge_buffers");
        let value = root.entry(key).or_insert_with(|| json!([]));
        if !value.is_array() {
            *value = json!([]);
        }
        value.as_array_mut().expect("just made an array")
    }

    /// Appends `value` to the root array `key`; returns its index.
    fn push(&mut self, key: &str, value: Value) -> usize {
        let array = self.array(key);
        array.push(value);
        array.len() - 1
    }

    /// Copies every external image into the output and points its uri at the copy.
    fn copy_images(
        &mut self,
        source: &Source,
        reserved: &[String],
        staging: &mut Staging,
    ) -> Result<()> {
        let base = source.path.parent().unwrap_or(Path::new("."));
        // Output name → the file staged under it (images shared by several entries are copied once).
        let mut staged: BTreeMap<String, std::path::PathBuf> = BTreeMap::new();
        let count = self
            .json
            .get("images")
            .and_then(Value::as_array)
            .map_or(0, Vec::len);
        for i in 0..count {
            let Some(uri) = self.json["images"][i]
                .get("uri")
                .and_then(Value::as_str)
                .map(str::to_string)
            else {
                continue;
            };
            if uri.starts_with("data:") {
                continue;
            }
            let decoded = decode_uri(&uri).unwrap_or_else(|| uri.clone());
            let file = match decoded.strip_prefix("file://") {
                Some(absolute) => Path::new(absolute).to_path_buf(),
                None if has_scheme(&decoded) => {
                    return Err(Error::unsupported(
                        &source.path,
                        format!("image {i}: uri {uri:?} is not a local file"),
                    ));
                }
                None => base.join(&decoded),
            };
            let bytes = fs::read(&file).map_err(|e| match e.kind() {
                std::io::ErrorKind::NotFound => self.invalid(format!(
                    "image {i}: {uri:?} not found (looked for {})",
                    file.display()
                )),
                _ => Error::io(&file, e),
            })?;
            let file_name = file
                .file_name()
                .and_then(|n| n.to_str())
                .map_or_else(|| format!("image{i}"), str::to_string);
            let mut name = if is_plain_relative(&decoded) {
                decoded.clone()
            } else {
                format!("images/{file_name}")
            };
            let taken = |name: &String| {
                reserved.contains(name) || staged.get(name).is_some_and(|f| *f != file)
            };
            if taken(&name) {
                name = format!("images/{i}_{file_name}");
            }
            if !staged.contains_key(&name) {
                staging.write(&name, &bytes)?;
                staged.insert(name.clone(), file);
            }
            if name != decoded {
                self.json["images"][i]["uri"] = json!(encode_uri(&name));
            }
        }
        Ok(())
    }

    /// One image + texture per page (linear filtering, clamped); returns the texture indices.
    fn add_page_textures(&mut self, pages: &[PageFiles]) -> Vec<usize> {
        if pages.is_empty() {
            return Vec::new();
        }
        let sampler = self.push(
            "samplers",
            json!({"name": "lightmap", "magFilter": LINEAR, "minFilter": LINEAR, "wrapS": CLAMP_TO_EDGE, "wrapT": CLAMP_TO_EDGE}),
        );
        pages
            .iter()
            .enumerate()
            .map(|(k, page)| {
                let image = self.push(
                    "images",
                    json!({"name": format!("lightmap {k}"), "uri": encode_uri(&page.png)}),
                );
                self.push(
                    "textures",
                    json!({"name": format!("lightmap {k}"), "sampler": sampler, "source": image}),
                )
            })
            .collect()
    }

    /// Gives every node that places a baked mesh its own copy of the mesh (the first node keeps
    /// the original), except meshes the atlas shares. Returns the output mesh of each
    /// (node, mesh).
    fn duplicate_meshes(
        &mut self,
        scene: &Scene,
        atlas: &Atlas,
    ) -> Result<BTreeMap<(u32, u32), usize>> {
        let shared: BTreeSet<u32> = atlas.shared.iter().map(|s| s.mesh).collect();
        let mut nodes_of_mesh: BTreeMap<u32, BTreeSet<u32>> = BTreeMap::new();
        for inst in &scene.instances {
            nodes_of_mesh
                .entry(inst.mesh)
                .or_default()
                .insert(inst.node);
        }
        let mut targets = BTreeMap::new();
        for (&mesh, nodes) in &nodes_of_mesh {
            let original = self
                .json
                .get("meshes")
                .and_then(|m| m.get(mesh as usize))
                .cloned()
                .ok_or_else(|| self.invalid(format!("mesh {mesh} does not exist")))?;
            for (n, &node) in nodes.iter().enumerate() {
                let placed = self
                    .json
                    .get("nodes")
                    .and_then(|n| n.get(node as usize))
                    .and_then(|n| n.get("mesh"));
                if placed.and_then(Value::as_u64) != Some(mesh as u64) {
                    return Err(self.invalid(format!("node {node} does not place mesh {mesh}")));
                }
                let target = if n == 0 || shared.contains(&mesh) {
                    mesh as usize
                } else {
                    let mut copy = original.clone();
                    let name = original
                        .get("name")
                        .and_then(Value::as_str)
                        .map_or_else(|| format!("mesh {mesh}"), str::to_string);
                    copy["name"] = json!(format!("{name} (node {node})"));
                    let copy = self.push("meshes", copy);
                    self.json["nodes"][node as usize]["mesh"] = json!(copy);
                    copy
                };
                targets.insert((node, mesh), target);
            }
        }
        Ok(targets)
    }

    /// Replaces every baked primitive by its re-indexed, per-page, lightmapped versions.
    fn bake_primitives(
        &mut self,
        scene: &Scene,
        source: &Source,
        atlas: &Atlas,
        pages: &[PageFiles],
        page_textures: &[usize],
        target_meshes: &BTreeMap<(u32, u32), usize>,
    ) -> Result<bool> {
        // A shared mesh is written from its first node's instances, with the base layout.
        let mut base_of: BTreeMap<usize, &InstanceUv> = BTreeMap::new();
        let mut shared_copy = BTreeSet::new();
        for s in &atlas.shared {
            for (i, base) in &s.base {
                base_of.insert(*i as usize, base);
            }
            for rect in &s.nodes {
                shared_copy.extend(rect.instances.iter().map(|&i| i as usize));
            }
        }
        let original_primitive = |mesh: u32, primitive: u32| {
            source
                .json
                .get("meshes")
                .and_then(|m| m.get(mesh as usize))
                .and_then(|m| m.get("primitives"))
                .and_then(|p| p.get(primitive as usize))
        };
        let mut parts = Vec::new();
        for (i, (inst, uv)) in scene.instances.iter().zip(&atlas.instances).enumerate() {
            if original_primitive(inst.mesh, inst.primitive).is_none() {
                return Err(self.invalid(format!(
                    "mesh {} has no primitive {}",
                    inst.mesh, inst.primitive
                )));
            }
            if let Some(base) = base_of.get(&i) {
                parts.push(Part {
                    instance: i,
                    page: None,
                    triangles: (0..base.triangles.len() as u32).collect(),
                });
                continue;
            }
            if shared_copy.contains(&i) {
                continue;
            }
            let mut by_page: BTreeMap<u32, Vec<u32>> = BTreeMap::new();
            for (t, &page) in uv.triangle_page.iter().enumerate() {
                if page as usize >= pages.len() {
                    return Err(self.invalid(format!("atlas page {page} has no page files")));
                }
                by_page.entry(page).or_default().push(t as u32);
            }
            parts.extend(by_page.into_iter().map(|(page, triangles)| Part {
                instance: i,
                page: Some(page),
                triangles,
            }));
        }

        // Materials: one per key, in first-use order.
        let moved_uv1 = |atlas: &Atlas, inst: &crate::scene::Instance| {
            let primitive = original_primitive(inst.mesh, inst.primitive)?;
            moved_uv1(primitive, atlas.reused_input_uvs)
        };
        let material_key = |part: &Part| -> MaterialKey {
            let inst = &scene.instances[part.instance];
            let material = original_primitive(inst.mesh, inst.primitive)
                .and_then(|p| p.get("material"))
                .and_then(Value::as_u64);
            MaterialKey {
                material: material.map(|m| m as usize),
                single_sided: inst.back.is_some() || inst.back_of.is_some(),
                page: part.page,
                uv1_moved_to: moved_uv1(atlas, inst),
            }
        };
        let mut keys: Vec<MaterialKey> = Vec::new();
        for part in &parts {
            let key = material_key(part);
            if !keys.contains(&key) {
                keys.push(key);
            }
        }
        let materials = self.add_lightmap_materials(scene, source, &keys, page_textures)?;

        // Output primitives per (output mesh, primitive), fronts before backs, pages in order.
        let mut replaced: BTreeMap<(usize, usize), Vec<Value>> = BTreeMap::new();
        let mut i = 0;
        while i < parts.len() {
            let instance = parts[i].instance;
            let end = i + parts[i..]
                .iter()
                .take_while(|p| p.instance == instance)
                .count();
            let inst = &scene.instances[instance];
            let original = original_primitive(inst.mesh, inst.primitive).expect("checked above");
            let mut attributes =
                self.read_attributes(original, inst.back_of.is_some(), moved_uv1(atlas, inst))?;
            // Vertices a junction split added are blends of the primitive's own.
            if !inst.split.blends.is_empty() {
                for (name, _, elements) in &mut attributes {
                    *elements = elements.with_blends(&inst.split.blends, BlendKind::of(name));
                }
            }
            let target = (
                target_meshes[&(inst.node, inst.mesh)],
                inst.primitive as usize,
            );
            for part in &parts[i..end] {
                let material = materials[&material_key(part)];
                let lightmap = part
                    .page
                    .map(|page| page_extras(&pages[page as usize], page));
                let uv = base_of
                    .get(&instance)
                    .copied()
                    .unwrap_or(&atlas.instances[instance]);
                let primitive =
                    self.write_primitive(original, &attributes, uv, part, material, lightmap)?;
                replaced.entry(target).or_default().push(primitive);
            }
            i = end;
        }
        for ((mesh, primitive), mut new) in replaced.into_iter().rev() {
            let primitives = self.json["meshes"][mesh]["primitives"]
                .as_array_mut()
                .expect("primitive checked above");
            let tail = primitives.split_off(primitive + 1);
            primitives.pop();
            primitives.append(&mut new);
            primitives.extend(tail);
        }
        Ok(keys.iter().any(|k| k.page.is_some()))
    }

    /// `extras.lightmap` of every node placing a shared mesh: its page and rect.
    fn add_node_rects(&mut self, atlas: &Atlas, pages: &[PageFiles]) -> Result<()> {
        for rect in atlas.shared.iter().flat_map(|s| &s.nodes) {
            let files = pages.get(rect.page as usize).ok_or_else(|| {
                self.invalid(format!("atlas page {} has no page files", rect.page))
            })?;
            let mut lightmap = page_extras(files, rect.page);
            // f32 values as JSON numbers that read back to the same f32.
            lightmap["scale_offset"] =
                json!([rect.scale.x, rect.scale.y, rect.offset.x, rect.offset.y].map(f64::from));
            let node = self
                .json
                .get_mut("nodes")
                .and_then(|n| n.get_mut(rect.node as usize))
                .filter(|n| n.is_object())
                .ok_or_else(|| Error::Internal(format!("node {} does not exist", rect.node)))?;
            object_entry(node, "extras").insert("lightmap".to_string(), lightmap);
        }
        Ok(())
    }

    /// Creates the lightmapped materials: copies named "<name> (lightmap k)", except that the
    /// first key of a material only baked primitives use edits the original in place. Returns the material index of each key.
    fn add_lightmap_materials(
        &mut self,
        scene: &Scene,
        source: &Source,
        keys: &[MaterialKey],
        page_textures: &[usize],
    ) -> Result<BTreeMap<MaterialKey, usize>> {
        // Materials that untouched primitives still use must stay as they are.
        let baked: BTreeSet<(usize, usize)> = scene
            .instances
            .iter()
            .map(|inst| (inst.mesh as usize, inst.primitive as usize))
            .collect();
        let mut shared = BTreeSet::new();
        let meshes = source
            .json
            .get("meshes")
            .and_then(Value::as_array)
            .map_or(&[][..], Vec::as_slice);
        for (m, mesh) in meshes.iter().enumerate() {
            let primitives = mesh
                .get("primitives")
                .and_then(Value::as_array)
                .map_or(&[][..], Vec::as_slice);
            for (p, primitive) in primitives.iter().enumerate() {
                if let (false, Some(material)) = (
                    baked.contains(&(m, p)),
                    primitive.get("material").and_then(Value::as_u64),
                ) {
                    shared.insert(material as usize);
                }
            }
        }
        let mut indices = BTreeMap::new();
        for &key in keys {
            let MaterialKey {
                material,
                single_sided,
                page,
                uv1_moved_to,
            } = key;
            let lightmap = page.map(|page| {
                json!({
                    "lightmapTexture": {"index": page_textures[page as usize], "texCoord": 1},
                    "lightmapFactor": [1.0, 1.0, 1.0]
                })
            });
            // The first key of a material no untouched primitive uses takes over the original.
            let edit_in_place = material.is_some_and(|m| shared.insert(m));
            let mut value = match material {
                Some(m) => self
                    .json
                    .get("materials")
                    .and_then(|ms| ms.get(m))
                    .cloned()
                    .ok_or_else(|| self.invalid(format!("material {m} does not exist")))?,
                None => json!({}),
            };
            if !value.is_object() {
                return Err(self.invalid(format!("material {material:?} is not an object")));
            }
            if !edit_in_place {
                let name = match (value.get("name").and_then(Value::as_str), material) {
                    (Some(name), _) => name.to_string(),
                    (None, Some(m)) => format!("material {m}"),
                    (None, None) => "default".to_string(),
                };
                let suffix = match page {
                    Some(page) => format!("lightmap {page}"),
                    None => "shared lightmap".to_string(),
                };
                value["name"] = json!(format!("{name} ({suffix})"));
            }
            if single_sided {
                value["doubleSided"] = json!(false);
            }
            if let Some(set) = uv1_moved_to {
                retarget_texcoord_1(&mut value, set);
            }
            if let Some(lightmap) = lightmap {
                object_entry(&mut value, "extensions")
                    .insert(LIGHTMAP_EXTENSION.to_string(), lightmap);
            }
            let index = match (edit_in_place, material) {
                (true, Some(m)) => {
                    self.json["materials"][m] = value;
                    m
                }
                _ => self.push("materials", value),
            };
            indices.insert(key, index);
        }
        Ok(indices)
    }

    /// The attributes of `primitive` in document order, its own `TEXCOORD_1` renamed to
    /// `TEXCOORD_<uv1_moved_to>` or left out (the lightmap UVs take set 1); for a back face,
    /// normals negated and tangent handedness flipped.
    fn read_attributes(
        &self,
        primitive: &Value,
        back: bool,
        uv1_moved_to: Option<u32>,
    ) -> Result<Vec<(String, usize, Elements)>> {
        let attributes = primitive
            .get("attributes")
            .and_then(Value::as_object)
            .ok_or_else(|| self.invalid("primitive without attributes"))?;
        let mut read = Vec::new();
        for (name, accessor) in attributes {
            let name = match (name.as_str(), uv1_moved_to) {
                ("TEXCOORD_1", None) => continue,
                ("TEXCOORD_1", Some(set)) => format!("TEXCOORD_{set}"),
                _ => name.clone(),
            };
            let index = accessor
                .as_u64()
                .ok_or_else(|| self.invalid(format!("attribute {name} is not an accessor index")))?
                as usize;
            let mut elements = read_accessor(&self.json, &self.bin, index)
                .map_err(|e| self.invalid(format!("accessor {index} ({name}): {e}")))?;
            match (back, name.as_str()) {
                (true, "NORMAL") => elements.negate(0..3),
                (true, "TANGENT") => elements.negate(3..4),
                _ => {}
            }
            read.push((name, index, elements));
        }
        Ok(read)
    }

    /// The output primitive of one part: `original` with gathered attributes, lightmap UVs, new
    /// indices, the page material and the lightmap extras.
    fn write_primitive(
        &mut self,
        original: &Value,
        attributes: &[(String, usize, Elements)],
        uv: &InstanceUv,
        part: &Part,
        material: usize,
        lightmap: Option<Value>,
    ) -> Result<Value> {
        // Compact the atlas vertices this page uses, in order of first use.
        let mut local = vec![u32::MAX; uv.xref.len()];
        let mut used: Vec<u32> = Vec::new();
        let mut indices: Vec<u32> = Vec::with_capacity(part.triangles.len() * 3);
        for &t in &part.triangles {
            for a in uv.triangles[t as usize] {
                let slot = local
                    .get_mut(a as usize)
                    .ok_or_else(|| self.invalid("atlas triangle refers to a missing vertex"))?;
                if *slot == u32::MAX {
                    *slot = used.len() as u32;
                    used.push(a);
                }
                indices.push(*slot);
            }
        }
        let xref: Vec<u32> = used.iter().map(|&a| uv.xref[a as usize]).collect();

        let mut new_attributes = Map::new();
        for (name, index, elements) in attributes {
            if let Some(&bad) = xref.iter().find(|&&v| v as usize >= elements.len()) {
                return Err(self.invalid(format!(
                    "atlas vertex {bad} is outside accessor {index} ({name})"
                )));
            }
            let template = &self.json["accessors"][*index];
            let bounds = name == "POSITION"
                || template.get("min").is_some()
                || template.get("max").is_some();
            let template = template.clone();
            let accessor = self.push_vertex_accessor(&template, &elements.gather(&xref), bounds);
            new_attributes.insert(name.clone(), json!(accessor));
        }
        let uv_bytes: Vec<u8> = used
            .iter()
            .flat_map(|&a| {
                let p = uv.uv[a as usize];
                [p.x, p.y].map(|c| {
                    if c.is_finite() {
                        c.clamp(0.0, 1.0)
                    } else {
                        0.0
                    }
                })
            })
            .flat_map(f32::to_le_bytes)
            .collect();
        let uv_elements = Elements {
            layout: Layout::new(FLOAT, "VEC2").expect("valid layout"),
            bytes: uv_bytes,
        };
        let uv_accessor = self.push_vertex_accessor(&json!({}), &uv_elements, false);
        new_attributes.insert("TEXCOORD_1".to_string(), json!(uv_accessor));
        if !new_attributes.contains_key("TEXCOORD_0") {
            new_attributes.insert("TEXCOORD_0".to_string(), json!(uv_accessor));
        }
        let index_accessor = self.push_index_accessor(&indices, used.len());

        let mut primitive = original.clone();
        primitive["attributes"] = Value::Object(new_attributes);
        primitive["indices"] = json!(index_accessor);
        if primitive.get("mode").is_some() {
            primitive["mode"] = json!(4);
        }
        primitive["material"] = json!(material);
        if let Some(lightmap) = lightmap {
            object_entry(&mut primitive, "extras").insert("lightmap".to_string(), lightmap);
        }
        Ok(primitive)
    }

    /// Appends `bytes` as a new buffer view (4-byte aligned); returns its index.
    fn push_view(&mut self, bytes: &[u8], stride: Option<usize>, target: u64) -> usize {
        self.bin.resize(self.bin.len().next_multiple_of(4), 0);
        let mut view =
            json!({"buffer": 0, "byteOffset": self.bin.len(), "byteLength": bytes.len()});
        self.bin.extend_from_slice(bytes);
        if let Some(stride) = stride {
            view["byteStride"] = json!(stride);
        }
        view["target"] = json!(target);
        self.push("bufferViews", view)
    }

    /// A vertex attribute accessor over `elements`, keeping the template's componentType, type,
    /// normalized, name, extras and extensions.
    fn push_vertex_accessor(
        &mut self,
        template: &Value,
        elements: &Elements,
        bounds: bool,
    ) -> usize {
        let (bytes, stride) = elements.vertex_bytes();
        let padded = stride != elements.layout.element_size();
        let view = self.push_view(&bytes, padded.then_some(stride), ARRAY_BUFFER);
        let mut accessor = template.as_object().cloned().unwrap_or_default();
        for key in ["bufferView", "byteOffset", "sparse", "min", "max"] {
            accessor.remove(key);
        }
        accessor.insert("bufferView".to_string(), json!(view));
        accessor.insert(
            "componentType".to_string(),
            json!(elements.layout.component_type),
        );
        accessor.insert("count".to_string(), json!(elements.len()));
        if !accessor.contains_key("type") {
            accessor.insert("type".to_string(), json!("VEC2"));
        }
        if bounds {
            let (min, max) = elements.bounds();
            accessor.insert("min".to_string(), Value::Array(min));
            accessor.insert("max".to_string(), Value::Array(max));
        }
        self.push("accessors", Value::Object(accessor))
    }

    /// Triangle indices: u16 when every vertex fits (65535 is the restart value), else u32.
    fn push_index_accessor(&mut self, indices: &[u32], vertex_count: usize) -> usize {
        let (component_type, bytes): (u64, Vec<u8>) = if vertex_count <= u16::MAX as usize {
            (
                UNSIGNED_SHORT,
                indices
                    .iter()
                    .flat_map(|&i| (i as u16).to_le_bytes())
                    .collect(),
            )
        } else {
            (
                UNSIGNED_INT,
                indices.iter().flat_map(|&i| i.to_le_bytes()).collect(),
            )
        };
        let view = self.push_view(&bytes, None, ELEMENT_ARRAY_BUFFER);
        self.push(
            "accessors",
            json!({"bufferView": view, "componentType": component_type, "count": indices.len(), "type": "SCALAR"}),
        )
    }

    fn mark_extension_used(&mut self, extension: &str) {
        let used = self.array("extensionsUsed");
        if !used.iter().any(|e| e.as_str() == Some(extension)) {
            used.push(json!(extension));
        }
    }

    fn append_generator(&mut self) {
        let asset = object_entry(&mut self.json, "asset");
        let generator = match asset.get("generator").and_then(Value::as_str) {
            Some(g) => format!("{g} + lightbake"),
            None => "lightbake".to_string(),
        };
        asset.insert("generator".to_string(), json!(generator));
    }

    /// Stages `<stem>.gltf` + `<stem>.bin`, or `<stem>.glb`.
    fn finish(mut self, stem: &str, glb: bool, staging: &mut Staging) -> Result<()> {
        let bin_name = format!("{stem}.bin");
        if self.bin.is_empty() {
            self.json
                .as_object_mut()
                .expect("checked in merge_buffers")
                .remove("buffers");
        } else {
            let mut buffer = std::mem::take(&mut self.buffer_template);
            buffer.insert("byteLength".to_string(), json!(self.bin.len()));
            if !glb {
                buffer.insert("uri".to_string(), json!(encode_uri(&bin_name)));
            }
            self.json["buffers"] = json!([buffer]);
        }
        let serialize = |json: &Value, pretty: bool| {
            let bytes = if pretty {
                serde_json::to_vec_pretty(json)
            } else {
                serde_json::to_vec(json)
            };
            bytes.map_err(|e| Error::Internal(format!("cannot serialise the output glTF: {e}")))
        };
        if glb {
            let json = serialize(&self.json, false)?;
            staging.write(&format!("{stem}.glb"), &glb::container(json, self.bin))
        } else {
            if !self.bin.is_empty() {
                staging.write(&bin_name, &self.bin)?;
            }
            staging.write(&format!("{stem}.gltf"), &serialize(&self.json, true)?)
        }
    }
}

/// The free texture-coordinate set a primitive's own `TEXCOORD_1` moves to, so textures that
/// sample it (an occlusion map, say) keep working; `None` when it has none or the lightmap
/// reuses it.
fn moved_uv1(primitive: &Value, reused_input_uvs: bool) -> Option<u32> {
    let attributes = primitive.get("attributes")?.as_object()?;
    if reused_input_uvs || !attributes.contains_key("TEXCOORD_1") {
        return None;
    }
    (2..).find(|set| !attributes.contains_key(&format!("TEXCOORD_{set}")))
}

/// Points every texture reference of `material` that samples set 1 at set `set` (texture infos
/// are the objects with an `index`; `extras` are left alone).
fn retarget_texcoord_1(material: &mut Value, set: u32) {
    match material {
        Value::Object(object) => {
            if object.contains_key("index") && object.get("texCoord") == Some(&json!(1)) {
                object.insert("texCoord".to_string(), json!(set));
            }
            for (key, value) in object.iter_mut() {
                if key != "extras" {
                    retarget_texcoord_1(value, set);
                }
            }
        }
        Value::Array(items) => items
            .iter_mut()
            .for_each(|item| retarget_texcoord_1(item, set)),
        _ => {}
    }
}

/// The object under `key` of `value` (created, or replacing a non-object).
fn object_entry<'v>(value: &'v mut Value, key: &str) -> &'v mut Map<String, Value> {
    let object = value.as_object_mut().expect("callers pass objects");
    let entry = object.entry(key).or_insert_with(|| json!({}));
    if !entry.is_object() {
        *entry = json!({});
    }
    entry.as_object_mut().expect("just made an object")
}

/// Percent-encodes a relative file path for a glTF uri (RFC 3986 unreserved characters and `/`
/// are kept).
fn encode_uri(path: &str) -> String {
    let mut uri = String::with_capacity(path.len());
    for b in path.bytes() {
        if b.is_ascii_alphanumeric() || b"-._~/".contains(&b) {
            uri.push(b as char);
        } else {
            uri.push_str(&format!("%{b:02X}"));
        }
    }
    uri
}

/// Decodes `%XX` escapes; `None` when an escape is malformed or the result is not UTF-8.
pub(crate) fn decode_uri(uri: &str) -> Option<String> {
    let bytes = uri.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' {
            let hex = std::str::from_utf8(bytes.get(i + 1..i + 3)?).ok()?;
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    String::from_utf8(out).ok()
}

/// `scheme:` prefix (RFC 3986), e.g. `http:`; a single letter is a Windows drive, not a scheme.
fn has_scheme(uri: &str) -> bool {
    match uri.split_once(':') {
        Some((scheme, _)) => {
            scheme.len() > 1
                && scheme.starts_with(|c: char| c.is_ascii_alphabetic())
                && scheme
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || "+-.".contains(c))
        }
        None => false,
    }
}

/// A relative path that stays inside its directory (no `..`, no root, no drive).
fn is_plain_relative(path: &str) -> bool {
    !path.is_empty()
        && !path.contains(':')
        && Path::new(path)
            .components()
            .all(|c| matches!(c, Component::Normal(_)))
}

#[cfg(test)]
mod tests {
    use std::path::PathBuf;

    use base64::Engine;
    use glam::Vec2;

    use super::*;
    use crate::atlas::PageSize;
    use crate::scene::Instance;

    /// Quad corners, counter-clockwise seen from +Y.
    const CORNERS: [[f32; 3]; 4] = [
        [0.0, 0.0, 0.0],
        [0.0, 0.0, 1.0],
        [1.0, 0.0, 1.0],
        [1.0, 0.0, 0.0],
    ];
    const QUAD: [[u32; 3]; 2] = [[0, 1, 2], [0, 2, 3]];

    #[derive(Clone, Copy)]
    struct Variant {
        indexed: bool,
        /// The input has a `TEXCOORD_1` (a copy of set 0) and an occlusion map sampling it.
        uv1: bool,
        texcoord0: bool,
        double_sided: bool,
        glb: bool,
    }

    /// Indexed, with both texture coordinate sets, single-sided, written as `.gltf`.
    const FULL: Variant = Variant {
        indexed: true,
        uv1: true,
        texcoord0: true,
        double_sided: false,
        glb: false,
    };
    /// Every choice of [`FULL`] the other way.
    const BARE: Variant = Variant {
        indexed: false,
        uv1: false,
        texcoord0: false,
        double_sided: true,
        glb: true,
    };

    /// Source vertex `v` of the quad primitive (non-indexed: the triangles' corners in order).
    fn corner_of(variant: Variant, v: usize) -> usize {
        if variant.indexed {
            v
        } else {
            QUAD[v / 3][v % 3] as usize
        }
    }
    fn texcoord0(v: usize) -> [u16; 2] {
        [v as u16 * 1000, 65535 - v as u16 * 1000]
    }
    fn color(v: usize) -> [u8; 3] {
        [v as u8 * 10, 20 + v as u8, 255]
    }

    /// A quad mesh placed by two nodes, with interleaved positions/normals, u16-normalized
    /// `TEXCOORD_0`, 3-byte `COLOR_0` and a custom `_ID` in strided views, u8 indices, an unknown
    /// extension, extras, a camera and two external images.
    fn quad_source(dir: &Path, variant: Variant) -> Source {
        let vertices = if variant.indexed { 4 } else { 6 };
        let mut bin = Vec::new();
        for v in 0..vertices {
            CORNERS[corner_of(variant, v)]
                .iter()
                .chain(&[0.0, 1.0, 0.0])
                .for_each(|c| bin.extend_from_slice(&c.to_le_bytes()));
        }
        let views = [0, bin.len()];
        (0..vertices).for_each(|v| {
            texcoord0(v)
                .iter()
                .for_each(|c| bin.extend_from_slice(&c.to_le_bytes()))
        });
        let color_at = bin.len();
        (0..vertices)
            .for_each(|v| bin.extend_from_slice(&[color(v)[0], color(v)[1], color(v)[2], 0]));
        let id_at = bin.len();
        (0..vertices).for_each(|v| bin.extend_from_slice(&[100 + v as u8, 0, 0, 0]));
        let index_at = bin.len();
        bin.extend(QUAD.iter().flatten().map(|&i| i as u8));
        let mut json = json!({
            "asset": {"version": "2.0", "generator": "hand"},
            "extensionsUsed": ["VENDOR_unknown"],
            "extras": {"keep": "me"},
            "scene": 0,
            "scenes": [{"nodes": [0, 1, 2]}],
            "nodes": [
                {"name": "A", "mesh": 0, "extras": {"n": 1}},
                {"name": "B", "mesh": 0, "translation": [3.0, 0.0, 0.0]},
                {"name": "Cam", "camera": 0}
            ],
            "cameras": [{"type": "perspective", "perspective": {"yfov": 1.0, "znear": 0.1}}],
            "meshes": [{"name": "Quad", "primitives": [{
                "attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2, "COLOR_0": 3, "_ID": 4},
                "indices": 5, "material": 0, "extras": {"p": 2}
            }]}],
            "materials": [{
                "name": "Wall",
                "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1.0], "baseColorTexture": {"index": 0}},
                "doubleSided": variant.double_sided,
                "extensions": {"VENDOR_unknown": {"x": 1}}
            }],
            "textures": [{"source": 0}, {"source": 1}],
            "images": [{"uri": "tex/brick%20wall.png"}, {"uri": "../shared/other.png"}],
            "buffers": [{"byteLength": bin.len(), "name": "geometry"}],
            "bufferViews": [
                {"buffer": 0, "byteOffset": views[0], "byteLength": views[1], "byteStride": 24},
                {"buffer": 0, "byteOffset": views[1], "byteLength": color_at - views[1]},
                {"buffer": 0, "byteOffset": color_at, "byteLength": id_at - color_at, "byteStride": 4},
                {"buffer": 0, "byteOffset": id_at, "byteLength": index_at - id_at, "byteStride": 4},
                {"buffer": 0, "byteOffset": index_at, "byteLength": 6}
            ],
            "accessors": [
                {"bufferView": 0, "componentType": 5126, "type": "VEC3", "count": vertices, "min": [0.0, 0.0, 0.0], "max": [1.0, 0.0, 1.0]},
                {"bufferView": 0, "byteOffset": 12, "componentType": 5126, "type": "VEC3", "count": vertices},
                {"bufferView": 1, "componentType": 5123, "normalized": true, "type": "VEC2", "count": vertices},
                {"bufferView": 2, "componentType": 5121, "normalized": true, "type": "VEC3", "count": vertices, "name": "colours"},
                {"bufferView": 3, "componentType": 5123, "type": "SCALAR", "count": vertices},
                {"bufferView": 4, "componentType": 5121, "type": "SCALAR", "count": 6}
            ]
        });
        let primitive = &mut json["meshes"][0]["primitives"][0];
        if !variant.indexed {
            primitive.as_object_mut().unwrap().remove("indices");
        }
        if variant.uv1 {
            primitive["attributes"]["TEXCOORD_1"] = json!(2);
        }
        if !variant.texcoord0 {
            primitive["attributes"]
                .as_object_mut()
                .unwrap()
                .remove("TEXCOORD_0");
        }
        if variant.uv1 {
            json["materials"][0]["occlusionTexture"] = json!({"index": 0, "texCoord": 1});
        }
        if !variant.glb {
            let data = base64::engine::general_purpose::STANDARD.encode(&bin);
            json["buffers"][0]["uri"] =
                json!(format!("data:application/octet-stream;base64,{data}"));
        }
        let input = dir.join("in");
        fs::create_dir_all(input.join("tex")).unwrap();
        fs::create_dir_all(dir.join("shared")).unwrap();
        fs::write(input.join("tex/brick wall.png"), png(1)).unwrap();
        fs::write(dir.join("shared/other.png"), png(2)).unwrap();
        let path = input.join(if variant.glb { "quad.glb" } else { "quad.gltf" });
        Source {
            path,
            is_glb: variant.glb,
            json,
            buffers: vec![bin],
        }
    }

    fn png(size: u32) -> Vec<u8> {
        let mut bytes = std::io::Cursor::new(Vec::new());
        image::RgbImage::new(size, size)
            .write_to(&mut bytes, image::ImageFormat::Png)
            .unwrap();
        bytes.into_inner()
    }

    /// Triangle `t` of the quad as source vertices (local accessor elements).
    fn source_triangle(variant: Variant, t: usize) -> [u32; 3] {
        if variant.indexed {
            QUAD[t]
        } else {
            [3 * t as u32, 3 * t as u32 + 1, 3 * t as u32 + 2]
        }
    }

    /// One atlas vertex per triangle corner (every edge a seam), distinct UVs (`salt` separates
    /// instances), triangles on `pages`; `reversed` for a back face.
    fn instance_uv(variant: Variant, pages: [u32; 2], salt: f32, reversed: bool) -> InstanceUv {
        let mut uv = InstanceUv::default();
        for (t, page) in pages.into_iter().enumerate() {
            let corners = source_triangle(variant, t);
            let order = if reversed { [0, 2, 1] } else { [0, 1, 2] };
            let mut tri = [0; 3];
            for (j, &k) in order.iter().enumerate() {
                tri[j] = uv.xref.len() as u32;
                uv.xref.push(corners[k]);
                uv.uv.push(Vec2::new(0.05 + 0.1 * uv.uv.len() as f32, salt));
            }
            uv.triangles.push(tri);
            uv.triangle_page.push(page);
        }
        uv
    }

    fn instance(node: u32, vertices: u32, index: u32) -> Instance {
        Instance {
            node,
            mesh: 0,
            primitive: 0,
            material: 0,
            vertices: index * vertices..(index + 1) * vertices,
            triangles: index * 2..index * 2 + 2,
            source_triangle: vec![0, 1],
            back_of: None,
            back: None,
            has_uv1: false,
            lightmap: None,
            directional: None,
            split: Default::default(),
        }
    }

    /// Instances per node (A, then B): the front face, then for a double-sided material its
    /// back face. A's front is on pages 0 and 1, its back on page 1; B is on page 0.
    fn quad_scene(variant: Variant) -> (Scene, Atlas) {
        let vertices = if variant.indexed { 4 } else { 6 };
        let mut scene = Scene::default();
        let mut uvs = Vec::new();
        for (node, front_pages, back_pages) in [(0, [0, 1], [1, 1]), (1, [0, 0], [0, 0])] {
            let front = scene.instances.len() as u32;
            scene.instances.push(instance(node, vertices, front));
            uvs.push(instance_uv(
                variant,
                front_pages,
                0.1 + 0.2 * node as f32,
                false,
            ));
            if variant.double_sided {
                scene.instances[front as usize].back = Some(front + 1);
                let mut back = instance(node, vertices, front + 1);
                back.back_of = Some(front);
                scene.instances.push(back);
                uvs.push(instance_uv(
                    variant,
                    back_pages,
                    0.2 + 0.2 * node as f32,
                    true,
                ));
            }
        }
        let page = PageSize {
            width: 8,
            height: 8,
        };
        let atlas = Atlas {
            pages: vec![page, page],
            instances: uvs,
            texels_per_unit: 8.0,
            reused_input_uvs: false,
            shared: Vec::new(),
        };
        (scene, atlas)
    }

    fn page_files() -> Vec<PageFiles> {
        (0..2)
            .map(|k| PageFiles {
                exr: format!("quad_lightmap{k}.exr"),
                png: format!("quad lightmap{k}.png"),
                directional: None,
            })
            .collect()
    }

    /// Bakes the quad into `dir/out`; returns the output file.
    fn write_quad(dir: &Path, variant: Variant) -> (PathBuf, Source, Scene, Atlas) {
        let source = quad_source(dir, variant);
        let (scene, atlas) = quad_scene(variant);
        let pages = page_files();
        let mut staging = Staging::new(&dir.join("out"), &[]).unwrap();
        for page in &pages {
            staging.write(&page.png, &png(8)).unwrap();
        }
        write_gltf(&scene, &source, &atlas, &pages, &mut staging, "quad").unwrap();
        staging.commit().unwrap();
        let out = dir
            .join("out")
            .join(if variant.glb { "quad.glb" } else { "quad.gltf" });
        (out, source, scene, atlas)
    }

    /// The output parsed by the gltf crate, its buffers and its raw JSON.
    fn open(file: &Path) -> (gltf::Document, Vec<gltf::buffer::Data>, Value) {
        let bytes = fs::read(file).unwrap();
        let gltf = gltf::Gltf::from_slice(&bytes).expect("gltf crate parses the output");
        // The raw JSON: the gltf crate drops extensions it does not know.
        let text = if bytes.starts_with(b"glTF") {
            gltf::Glb::from_slice(&bytes).unwrap().json.into_owned()
        } else {
            bytes
        };
        let json: Value = serde_json::from_slice(&text).unwrap();
        let buffers =
            gltf::import_buffers(&gltf.document, file.parent(), gltf.blob.clone()).unwrap();
        (gltf.document, buffers, json)
    }

    /// Checks every attribute of every baked primitive of `node` against the source through the
    /// atlas; returns the pages seen, in order.
    fn check_node(
        variant: Variant,
        document: &gltf::Document,
        buffers: &[gltf::buffer::Data],
        json: &Value,
        node: usize,
        uvs: &[&InstanceUv],
    ) -> Vec<u64> {
        let mesh = document.nodes().nth(node).unwrap().mesh().unwrap();
        let mut pages = Vec::new();
        for primitive in mesh.primitives() {
            let raw = &json["meshes"][mesh.index()]["primitives"][primitive.index()];
            let page = raw["extras"]["lightmap"]["page"].as_u64().unwrap();
            assert_eq!(
                raw["extras"]["lightmap"]["exr"],
                json!(format!("quad_lightmap{page}.exr"))
            );
            assert_eq!(raw["extras"]["p"], json!(2), "existing extras are kept");
            pages.push(page);

            let reader = primitive.reader(|b| Some(&buffers[b.index()].0[..]));
            let uv1: Vec<[f32; 2]> = reader.read_tex_coords(1).unwrap().into_f32().collect();
            assert!(uv1.iter().flatten().all(|c| (0.0..=1.0).contains(c)));
            // The atlas instance and vertex behind each output vertex, found by its unique UV.
            let atlas_vertex: Vec<(usize, usize)> = uv1
                .iter()
                .map(|uv| {
                    uvs.iter()
                        .enumerate()
                        .find_map(|(i, inst)| {
                            inst.uv
                                .iter()
                                .position(|p| p.to_array() == *uv)
                                .map(|a| (i, a))
                        })
                        .expect("output UV is an atlas UV")
                })
                .collect();
            let back = atlas_vertex[0].0 == 1;
            let source: Vec<usize> = atlas_vertex
                .iter()
                .map(|&(i, a)| uvs[i].xref[a] as usize)
                .collect();
            let positions: Vec<[f32; 3]> = reader.read_positions().unwrap().collect();
            let normals: Vec<[f32; 3]> = reader.read_normals().unwrap().collect();
            let colors: Vec<[u8; 3]> = reader.read_colors(0).unwrap().into_rgb_u8().collect();
            let uv0: Vec<[f32; 2]> = reader.read_tex_coords(0).unwrap().into_f32().collect();
            for (v, &s) in source.iter().enumerate() {
                assert_eq!(positions[v], CORNERS[corner_of(variant, s)]);
                assert_eq!(
                    normals[v],
                    if back {
                        [-0.0, -1.0, -0.0]
                    } else {
                        [0.0, 1.0, 0.0]
                    }
                );
                assert_eq!(colors[v], color(s));
                let expected_uv0 = if variant.texcoord0 {
                    texcoord0(s).map(|c| c as f32 / 65535.0)
                } else {
                    uv1[v]
                };
                assert_eq!(uv0[v], expected_uv0);
            }
            if variant.uv1 {
                let moved: Vec<[f32; 2]> = reader.read_tex_coords(2).unwrap().into_f32().collect();
                for (v, &s) in source.iter().enumerate() {
                    assert_eq!(
                        moved[v],
                        texcoord0(s).map(|c| c as f32 / 65535.0),
                        "own TEXCOORD_1 kept as set 2"
                    );
                }
            }
            let ids = read_accessor(
                json,
                &buffers[0].0,
                raw["attributes"]["_ID"].as_u64().unwrap() as usize,
            )
            .unwrap();
            for (v, &s) in source.iter().enumerate() {
                assert_eq!(
                    ids.layout.component(ids.element(v), 0),
                    100.0 + s as f64,
                    "custom attribute gathered"
                );
            }
            // Triangles: the atlas triangles of this page, same winding.
            let indices: Vec<u32> = reader.read_indices().unwrap().into_u32().collect();
            let (i, _) = atlas_vertex[0];
            let expected: Vec<u32> = uvs[i]
                .triangles
                .iter()
                .zip(&uvs[i].triangle_page)
                .filter(|(_, p)| **p as u64 == page)
                .flat_map(|(t, _)| t.map(|a| uvs[i].xref[a as usize]))
                .collect();
            let written: Vec<u32> = indices.iter().map(|&k| source[k as usize] as u32).collect();
            assert_eq!(written, expected);
            assert!(
                source.len() <= 6 && indices.iter().all(|&k| (k as usize) < source.len()),
                "vertices compacted per page"
            );

            // The material carries this page's lightmap.
            let material = &json["materials"][primitive.material().index().unwrap()];
            let extension = &material["extensions"][LIGHTMAP_EXTENSION];
            assert_eq!(extension["lightmapTexture"]["texCoord"], json!(1));
            let texture =
                &json["textures"][extension["lightmapTexture"]["index"].as_u64().unwrap() as usize];
            let image = &json["images"][texture["source"].as_u64().unwrap() as usize];
            assert_eq!(image["uri"], json!(format!("quad%20lightmap{page}.png")));
            assert_eq!(
                material["extensions"]["VENDOR_unknown"],
                json!({"x": 1}),
                "unknown extension kept"
            );
            assert_eq!(material["doubleSided"].as_bool(), Some(false));
            let occlusion = material
                .get("occlusionTexture")
                .map(|o| o["texCoord"].clone());
            assert_eq!(
                occlusion,
                variant.uv1.then(|| json!(2)),
                "occlusion map follows its UVs"
            );
        }
        pages
    }

    fn check_untouched(json: &Value) {
        assert_eq!(json["extras"], json!({"keep": "me"}));
        assert_eq!(json["nodes"][0]["extras"], json!({"n": 1}));
        assert_eq!(json["cameras"][0]["type"], json!("perspective"));
        assert_eq!(json["asset"]["generator"], json!("hand + lightbake"));
        assert_eq!(
            json["extensionsUsed"],
            json!(["VENDOR_unknown", LIGHTMAP_EXTENSION])
        );
        assert_eq!(json["buffers"].as_array().unwrap().len(), 1);
        assert_eq!(json["buffers"][0]["name"], json!("geometry"));
    }

    #[test]
    fn pages_split_primitives_and_instanced_meshes_are_duplicated() {
        let dir = tempfile::tempdir().unwrap();
        let variant = FULL;
        let (file, _, _, atlas) = write_quad(dir.path(), variant);
        let (document, buffers, json) = open(&file);
        check_untouched(&json);

        // Node k places instance k.
        let pages_of_node = |k: usize| {
            check_node(
                variant,
                &document,
                &buffers,
                &json,
                k,
                &[&atlas.instances[k]],
            )
        };
        assert_eq!(pages_of_node(0), [0, 1], "one primitive per page");
        assert_eq!(pages_of_node(1), [0]);
        assert_eq!(json["nodes"][0]["mesh"], json!(0));
        assert_eq!(json["nodes"][1]["mesh"], json!(1));
        assert_eq!(json["meshes"][1]["name"], json!("Quad (node 1)"));

        // Node A page 0 and node B page 0 share one material; page 1 has its own.
        let material =
            |node: usize, p: usize| json["meshes"][node]["primitives"][p]["material"].clone();
        assert_eq!(material(0, 0), material(1, 0));
        assert_ne!(material(0, 0), material(0, 1));
        let names: Vec<&Value> = json["materials"]
            .as_array()
            .unwrap()
            .iter()
            .map(|m| &m["name"])
            .collect();
        assert_eq!(
            names,
            [&json!("Wall"), &json!("Wall (lightmap 1)")],
            "no material left unused"
        );

        // 3-byte colours are written with a 4-byte stride; positions carry exact bounds.
        let raw = &json["meshes"][0]["primitives"][0];
        let color_view = json["accessors"][raw["attributes"]["COLOR_0"].as_u64().unwrap() as usize]
            ["bufferView"]
            .as_u64()
            .unwrap();
        assert_eq!(
            json["bufferViews"][color_view as usize]["byteStride"],
            json!(4)
        );
        let position = &json["accessors"][raw["attributes"]["POSITION"].as_u64().unwrap() as usize];
        assert_eq!(position["min"], json!([0.0, 0.0, 0.0]));
        assert_eq!(
            position["max"],
            json!([1.0, 0.0, 1.0]),
            "page 0 holds triangle 0,1,2"
        );

        // External images copied: a plain relative path as is, a `..` path under images/.
        assert_eq!(json["images"][0]["uri"], json!("tex/brick%20wall.png"));
        assert_eq!(json["images"][1]["uri"], json!("images/other.png"));
        assert_eq!(
            fs::read(dir.path().join("out/tex/brick wall.png")).unwrap(),
            png(1)
        );
        assert_eq!(
            fs::read(dir.path().join("out/images/other.png")).unwrap(),
            png(2)
        );
        assert!(dir.path().join("out/quad.bin").exists());
    }

    #[test]
    fn glb_double_sided_non_indexed_without_texcoord0() {
        let dir = tempfile::tempdir().unwrap();
        let variant = BARE;
        let (file, source, _, atlas) = write_quad(dir.path(), variant);
        let bytes = fs::read(&file).unwrap();
        assert_eq!(&bytes[..4], b"glTF");
        assert_eq!(
            u32::from_le_bytes(bytes[8..12].try_into().unwrap()) as usize,
            bytes.len()
        );
        let (document, buffers, json) = open(&file);
        check_untouched(&json);
        assert!(json["buffers"][0].get("uri").is_none());

        // Node A: front pages 0 and 1, then the back face on page 1 with reversed winding.
        // Node k places instances 2k (front) and 2k + 1 (back).
        let pages_of_node = |k: usize| {
            let uvs = [&atlas.instances[2 * k], &atlas.instances[2 * k + 1]];
            check_node(variant, &document, &buffers, &json, k, &uvs)
        };
        assert_eq!(pages_of_node(0), [0, 1, 1]);
        assert_eq!(pages_of_node(1), [0, 0]);
        let material = |p: usize| json["meshes"][0]["primitives"][p]["material"].clone();
        assert_eq!(
            material(1),
            material(2),
            "front and back on one page share the single-sided copy"
        );
        assert_eq!(source.json["materials"][0]["doubleSided"], json!(true));
    }

    #[test]
    fn missing_images_and_bad_atlases_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        let variant = FULL;
        let mut source = quad_source(dir.path(), variant);
        let (scene, mut atlas) = quad_scene(variant);
        let mut staging = Staging::new(&dir.path().join("out"), &[]).unwrap();
        source.json["images"][0]["uri"] = json!("tex/missing.png");
        let error =
            write_gltf(&scene, &source, &atlas, &page_files(), &mut staging, "quad").unwrap_err();
        assert!(
            matches!(error, Error::Invalid { .. }) && error.to_string().contains("tex/missing.png"),
            "{error}"
        );

        let source = quad_source(dir.path(), variant);
        atlas.instances[0].xref[0] = 9;
        let mut staging = Staging::new(&dir.path().join("out2"), &[]).unwrap();
        let error =
            write_gltf(&scene, &source, &atlas, &page_files(), &mut staging, "quad").unwrap_err();
        assert!(error.to_string().contains("atlas vertex 9"), "{error}");
    }

    #[test]
    fn uri_encoding_round_trips() {
        assert_eq!(encode_uri("a b/c%d.png"), "a%20b/c%25d.png");
        assert_eq!(
            decode_uri("a%20b/c%25d.png").as_deref(),
            Some("a b/c%d.png")
        );
        assert_eq!(decode_uri("bad%2"), None);
        assert!(has_scheme("http://x") && !has_scheme("C:/x") && !has_scheme("a/b.png"));
        assert!(
            is_plain_relative("tex/a.png")
                && !is_plain_relative("../a.png")
                && !is_plain_relative("/a.png")
        );
    }

    /// Runs the Khronos glTF-Validator (.ci/validate.js) when node and the package are installed.
    #[test]
    fn khronos_validator_reports_no_errors() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let node_path = [
            root.join("node_modules"),
            PathBuf::from("/tmp/node_modules"),
        ]
        .into_iter()
        .chain(std::env::var_os("NODE_PATH").map(PathBuf::from))
        .find(|p| p.join("gltf-validator").exists());
        let (Some(node_path), true) = (
            node_path,
            std::process::Command::new("node")
                .arg("--version")
                .output()
                .is_ok(),
        ) else {
            eprintln!("note: node or gltf-validator missing, validator test skipped");
            return;
        };
        let dir = tempfile::tempdir().unwrap();
        for (k, variant) in [FULL, BARE].into_iter().enumerate() {
            let (file, ..) = write_quad(&dir.path().join(k.to_string()), variant);
            let run = std::process::Command::new("node")
                .arg(root.join(".ci/validate.js"))
                .arg(&file)
                .env("NODE_PATH", &node_path)
                .output()
                .unwrap();
            let report = String::from_utf8_lossy(&run.stdout);
            assert!(
                run.status.success(),
                "validator errors for {}:\n{report}\n{}",
                file.display(),
                String::from_utf8_lossy(&run.stderr)
            );
        }
    }
}
