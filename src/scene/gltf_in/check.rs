//! Checks that run before the gltf crate reads anything: every index, count, offset, stride and
//! byte range it would trust. The crate indexes some of them unchecked (a POSITION accessor past
//! the end of `accessors` panics inside its validation) and computes byte ranges with plain
//! arithmetic (a zero or huge count overflows), so a damaged file must be refused here, with an
//! error that names the element.

use serde_json::Value;

use super::Files;
use crate::{Error, Result};

/// A view-less accessor (zeros plus sparse values) is materialised from nothing; its count is
/// capped so a damaged count cannot ask for unbounded memory (2^24 elements: 192 MiB of VEC3).
const MAX_VIEWLESS_COUNT: u64 = 1 << 24;

/// The JSON checks the gltf crate's validation relies on: every mesh has at least one
/// primitive (glTF 2.0 requires it), and every accessor a primitive names exists.
pub(super) fn mesh_references(files: &Files, json: &Value) -> Result<()> {
    let accessor_count = json
        .get("accessors")
        .and_then(Value::as_array)
        .map_or(0, Vec::len);
    let meshes = json.get("meshes").and_then(Value::as_array);
    for (m, mesh) in meshes.into_iter().flatten().enumerate() {
        let label = match mesh.get("name").and_then(Value::as_str) {
            Some(name) => format!("mesh {m} '{name}'"),
            None => format!("mesh {m}"),
        };
        let primitives = mesh.get("primitives").and_then(Value::as_array);
        let Some(primitives) = primitives.filter(|p| !p.is_empty()) else {
            let message = format!("{label} has no primitives (glTF requires at least one)");
            return Err(files.invalid(message));
        };
        for (p, primitive) in primitives.iter().enumerate() {
            let mut references: Vec<(String, &Value)> = Vec::new();
            let attributes = primitive.get("attributes").and_then(Value::as_object);
            references.extend(
                attributes
                    .into_iter()
                    .flatten()
                    .map(|(k, v)| (k.clone(), v)),
            );
            references.extend(primitive.get("indices").map(|v| ("indices".to_string(), v)));
            let targets = primitive.get("targets").and_then(Value::as_array);
            for (t, target) in targets.into_iter().flatten().enumerate() {
                let target = target.as_object().into_iter().flatten();
                references.extend(target.map(|(k, v)| (format!("target {t} {k}"), v)));
            }
            for (what, index) in references {
                if index.as_u64().is_none_or(|i| i >= accessor_count as u64) {
                    let message = format!(
                        "{label} primitive {p}: {what} refers to accessor {index}, but the file has {accessor_count} accessors"
                    );
                    return Err(files.invalid(message));
                }
            }
        }
    }
    Ok(())
}

/// Where each image's data comes from: glTF requires exactly one of `uri` and `bufferView`, and a
/// `mimeType` with a `bufferView` (the gltf crate unwraps both).
pub(super) fn image_sources(files: &Files, json: &Value) -> Result<()> {
    let images = json.get("images").and_then(Value::as_array);
    for (i, image) in images.into_iter().flatten().enumerate() {
        let has = |key: &str| image.get(key).is_some_and(|v| !v.is_null());
        let problem = match (has("uri"), has("bufferView")) {
            (false, false) => "has neither a uri nor a bufferView",
            (true, true) => "has both a uri and a bufferView (glTF allows one)",
            (false, true) if !has("mimeType") => {
                "has a bufferView but no mimeType (glTF requires one)"
            }
            _ => continue,
        };
        return Err(files.invalid(format!("image {i} {problem}")));
    }
    Ok(())
}

/// Every float accessor holds finite numbers (the glTF validator requires it), also those the
/// bake does not read: the output copies them, and must stay valid. Runs after the scene is
/// loaded, so a primitive's own data is reported with the primitive's name first; buffers
/// already match their `byteLength` and accessors their views ([`byte_ranges`]). Sparse
/// accessors are left to the reader.
pub(super) fn finite_floats(
    files: &Files,
    document: &gltf::Document,
    buffers: &[Vec<u8>],
) -> Result<()> {
    for accessor in document.accessors() {
        let (Some(view), None) = (accessor.view(), accessor.sparse()) else {
            continue;
        };
        if accessor.data_type() != gltf::accessor::DataType::F32 {
            continue;
        }
        let size = accessor.size();
        let stride = view.stride().unwrap_or(size);
        let data = &buffers[view.buffer().index()];
        let start = view.offset() + accessor.offset();
        for e in 0..accessor.count() {
            let at = start + e * stride;
            let element = data.get(at..at + size).unwrap_or(&[]);
            let finite = (element.chunks_exact(4))
                .all(|w| f32::from_le_bytes([w[0], w[1], w[2], w[3]]).is_finite());
            if !finite {
                let message = format!(
                    "accessor {}: element {e} is not finite (glTF requires finite floats)",
                    accessor.index()
                );
                return Err(files.invalid(message));
            }
        }
    }
    Ok(())
}

/// Byte ranges: every buffer view lies inside its buffer, every accessor (and its sparse
/// storage) inside its buffer view, with a stride no smaller than an element and a count of at
/// least one. All in checked u64 arithmetic.
pub(super) fn byte_ranges(files: &Files, document: &gltf::Document) -> Result<()> {
    for view in document.views() {
        let (offset, length) = (view.offset() as u64, view.length() as u64);
        let buffer = view.buffer();
        let end = offset.checked_add(length);
        if end.is_none_or(|end| end > buffer.length() as u64) {
            let message = format!(
                "bufferView {}: {length} bytes at offset {offset} lie outside buffer {} ({} bytes)",
                view.index(),
                buffer.index(),
                buffer.length()
            );
            return Err(files.invalid(message));
        }
    }
    for accessor in document.accessors() {
        let label = format!("accessor {}", accessor.index());
        let count = accessor.count() as u64;
        let element = accessor.size() as u64;
        if count == 0 {
            let message = format!("{label}: count is 0 (glTF requires at least 1)");
            return Err(files.invalid(message));
        }
        match accessor.view() {
            Some(view) => {
                let stride = view.stride().map_or(element, |s| s as u64);
                if stride < element {
                    let message = format!(
                        "{label}: bufferView {} has byteStride {stride}, smaller than one {element}-byte element",
                        view.index()
                    );
                    return Err(files.invalid(message));
                }
                let range = Range {
                    offset: accessor.offset() as u64,
                    stride,
                    count,
                    element,
                };
                range.check(files, &label, &view)?;
            }
            None if count > MAX_VIEWLESS_COUNT => {
                let message = format!(
                    "{label}: count {count} without a bufferView (more than {MAX_VIEWLESS_COUNT} zeros)"
                );
                return Err(files.invalid(message));
            }
            None => {}
        }
        if let Some(sparse) = accessor.sparse() {
            let sparse_count = sparse.count() as u64;
            if sparse_count == 0 || sparse_count > count {
                let message = format!(
                    "{label}: sparse count {sparse_count} is not in 1..={count} (the accessor's count)"
                );
                return Err(files.invalid(message));
            }
            let indices = sparse.indices();
            let index_size = indices.index_type().size() as u64;
            let view = indices.view();
            let range = Range {
                offset: indices.offset() as u64,
                stride: view
                    .stride()
                    .map_or(index_size, |s| s as u64)
                    .max(index_size),
                count: sparse_count,
                element: index_size,
            };
            range.check(files, &format!("{label} sparse indices"), &view)?;
            let values = sparse.values();
            let view = values.view();
            let range = Range {
                offset: values.offset() as u64,
                stride: view.stride().map_or(element, |s| s as u64).max(element),
                count: sparse_count,
                element,
            };
            range.check(files, &format!("{label} sparse values"), &view)?;
        }
    }
    Ok(())
}

/// `count` elements of `element` bytes, `stride` apart, from `offset` in a buffer view.
struct Range {
    offset: u64,
    stride: u64,
    count: u64,
    element: u64,
}

impl Range {
    /// The last byte read, as the gltf crate computes it: `offset + stride·(count−1) + element`.
    fn end(&self) -> Option<u64> {
        self.stride
            .checked_mul(self.count - 1)?
            .checked_add(self.offset)?
            .checked_add(self.element)
    }

    fn check(&self, files: &Files, label: &str, view: &gltf::buffer::View) -> Result<()> {
        let length = view.length() as u64;
        if self.end().is_some_and(|end| end <= length) {
            return Ok(());
        }
        let message = format!(
            "{label}: {} elements of {} bytes (stride {}) from offset {} do not fit in bufferView {} ({length} bytes)",
            self.count,
            self.element,
            self.stride,
            self.offset,
            view.index()
        );
        Err(files.invalid(message))
    }
}

/// The accessor types a primitive's attributes must have, as the gltf crate's readers assume
/// (anything else reaches an `unreachable!` or is misread): float VEC3 POSITION and NORMAL
/// (quantized ones, KHR_mesh_quantization, are not supported), VEC2 TEXCOORD of float or
/// normalized unsigned byte/short, and SCALAR unsigned indices.
pub(super) fn attribute_types(
    files: &Files,
    primitive: &gltf::Primitive,
    label: &str,
) -> Result<()> {
    use gltf::accessor::{DataType, Dimensions};
    use gltf::mesh::Semantic;
    for (semantic, accessor) in primitive.attributes() {
        let (data, dims) = (accessor.data_type(), accessor.dimensions());
        let name = semantic.to_string();
        let texcoord_data = matches!(data, DataType::F32 | DataType::U8 | DataType::U16);
        match semantic {
            Semantic::Positions | Semantic::Normals
                if data != DataType::F32 || dims != Dimensions::Vec3 =>
            {
                let message = format!(
                    "{label} {name} is {data:?} {dims:?}; only float VEC3 is supported (no KHR_mesh_quantization)"
                );
                return Err(Error::unsupported(files.gltf_path, message));
            }
            Semantic::TexCoords(_) if !texcoord_data || dims != Dimensions::Vec2 => {
                let message = format!(
                    "{label} {name} is {data:?} {dims:?}; glTF requires VEC2 of float, unsigned byte or unsigned short"
                );
                return Err(files.invalid(message));
            }
            _ => {}
        }
    }
    if let Some(indices) = primitive.indices() {
        let (data, dims) = (indices.data_type(), indices.dimensions());
        let data_ok = matches!(data, DataType::U8 | DataType::U16 | DataType::U32);
        if !data_ok || dims != Dimensions::Scalar {
            let message = format!(
                "{label} indices are {data:?} {dims:?}; glTF requires SCALAR unsigned byte, short or int"
            );
            return Err(files.invalid(message));
        }
    }
    Ok(())
}

/// KHR_texture_transform objects in materials that break the extension's schema (`offset` and
/// `scale`: two numbers; `rotation`: a number; `texCoord`: an integer ≥ 0), one message each.
/// lightbake ignores the transform, so these are warnings; the output keeps them as they are.
pub(super) fn texture_transforms(json: &Value) -> Vec<String> {
    let mut problems = Vec::new();
    let materials = json.get("materials").and_then(Value::as_array);
    for (m, material) in materials.into_iter().flatten().enumerate() {
        let mut stack = vec![(String::new(), material)];
        while let Some((path, value)) = stack.pop() {
            let Some(object) = value.as_object() else {
                continue;
            };
            for (key, child) in object {
                let child_path = format!("{path}/{key}");
                if key == "KHR_texture_transform" && path.ends_with("/extensions") {
                    if let Some(problem) = texture_transform_problem(child) {
                        problems.push(format!(
                            "material {m}{child_path}: {problem}; ignored like every texture transform"
                        ));
                    }
                } else {
                    stack.push((child_path, child));
                }
            }
        }
    }
    problems.sort();
    problems
}

fn texture_transform_problem(transform: &Value) -> Option<&'static str> {
    let pair = |v: &Value| {
        v.as_array()
            .is_some_and(|a| a.len() == 2 && a.iter().all(Value::is_number))
    };
    let Some(t) = transform.as_object() else {
        return Some("not an object");
    };
    if t.get("offset").is_some_and(|v| !pair(v)) {
        Some("offset is not two numbers")
    } else if t.get("scale").is_some_and(|v| !pair(v)) {
        Some("scale is not two numbers")
    } else if t.get("rotation").is_some_and(|v| !v.is_number()) {
        Some("rotation is not a number")
    } else if t.get("texCoord").is_some_and(|v| v.as_u64().is_none()) {
        Some("texCoord is not an integer ≥ 0")
    } else {
        None
    }
}
