//! Raw accessor data for the glTF writer: an accessor's elements as densely packed bytes (byte
//! strides, sparse substitution and accessors without a buffer view resolved), gathered through a
//! vertex map, edited in place (normals flipped), and measured (the `min`/`max` glTF requires).
//! Elements stay in their stored component type, so quantized and normalized data round-trip
//! bit for bit.

use serde_json::Value;

use crate::scene::Blend;

pub(super) const UNSIGNED_BYTE: u64 = 5121;
pub(super) const UNSIGNED_SHORT: u64 = 5123;
pub(super) const UNSIGNED_INT: u64 = 5125;
pub(super) const FLOAT: u64 = 5126;
const BYTE: u64 = 5120;
const SHORT: u64 = 5122;

/// Component type and shape of one accessor element.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Layout {
    pub(crate) component_type: u64,
    /// Rows of a column (the component count of a scalar or vector).
    rows: usize,
    /// 1 for scalars and vectors, n for MATn.
    columns: usize,
}

impl Layout {
    pub(crate) fn new(component_type: u64, type_name: &str) -> Result<Layout, String> {
        let (rows, columns) = match type_name {
            "SCALAR" => (1, 1),
            "VEC2" => (2, 1),
            "VEC3" => (3, 1),
            "VEC4" => (4, 1),
            "MAT2" => (2, 2),
            "MAT3" => (3, 3),
            "MAT4" => (4, 4),
            other => return Err(format!("unknown accessor type {other:?}")),
        };
        let layout = Layout {
            component_type,
            rows,
            columns,
        };
        if layout.component_size() == 0 {
            return Err(format!("unknown componentType {component_type}"));
        }
        Ok(layout)
    }

    pub(crate) fn of(accessor: &Value) -> Result<Layout, String> {
        let component_type = accessor
            .get("componentType")
            .and_then(Value::as_u64)
            .ok_or("no componentType")?;
        let type_name = accessor
            .get("type")
            .and_then(Value::as_str)
            .ok_or("no type")?;
        Layout::new(component_type, type_name)
    }

    pub(crate) fn component_size(&self) -> usize {
        match self.component_type {
            BYTE | UNSIGNED_BYTE => 1,
            SHORT | UNSIGNED_SHORT => 2,
            UNSIGNED_INT | FLOAT => 4,
            _ => 0,
        }
    }

    /// Matrix columns start on 4-byte boundaries (glTF's data alignment rule).
    fn column_stride(&self) -> usize {
        let bytes = self.rows * self.component_size();
        if self.columns > 1 {
            bytes.next_multiple_of(4)
        } else {
            bytes
        }
    }

    /// Bytes of one element, column padding included.
    pub(crate) fn element_size(&self) -> usize {
        self.column_stride() * self.columns
    }

    pub(crate) fn component_count(&self) -> usize {
        self.rows * self.columns
    }

    /// Byte offset of component `c` (column-major) inside an element.
    fn component_offset(&self, c: usize) -> usize {
        (c / self.rows) * self.column_stride() + (c % self.rows) * self.component_size()
    }

    /// Component `c` of the element starting at `element[0]`.
    pub(crate) fn component(&self, element: &[u8], c: usize) -> f64 {
        let o = self.component_offset(c);
        let b = |n: usize| -> [u8; 4] {
            let mut a = [0; 4];
            a[..n].copy_from_slice(&element[o..o + n]);
            a
        };
        match self.component_type {
            BYTE => element[o] as i8 as f64,
            UNSIGNED_BYTE => element[o] as f64,
            SHORT => i16::from_le_bytes([element[o], element[o + 1]]) as f64,
            UNSIGNED_SHORT => u16::from_le_bytes([element[o], element[o + 1]]) as f64,
            UNSIGNED_INT => u32::from_le_bytes(b(4)) as f64,
            _ => f32::from_le_bytes(b(4)) as f64,
        }
    }

    /// Largest magnitude of the type (what a normalized component is divided by); 1 for floats.
    fn unit(&self) -> f64 {
        match self.component_type {
            BYTE => 127.0,
            UNSIGNED_BYTE => 255.0,
            SHORT => 32767.0,
            UNSIGNED_SHORT => 65535.0,
            UNSIGNED_INT => u32::MAX as f64,
            _ => 1.0,
        }
    }

    /// Writes `value` into component `c`, rounded and clamped for integer types.
    pub(crate) fn set_component(&self, element: &mut [u8], c: usize, value: f64) {
        let o = self.component_offset(c);
        let clamp = |lo: f64, hi: f64| value.round().clamp(lo, hi);
        match self.component_type {
            BYTE => element[o] = clamp(-128.0, 127.0) as i8 as u8,
            UNSIGNED_BYTE => element[o] = clamp(0.0, 255.0) as u8,
            SHORT => {
                element[o..o + 2].copy_from_slice(&(clamp(-32768.0, 32767.0) as i16).to_le_bytes())
            }
            UNSIGNED_SHORT => {
                element[o..o + 2].copy_from_slice(&(clamp(0.0, 65535.0) as u16).to_le_bytes())
            }
            UNSIGNED_INT => element[o..o + 4]
                .copy_from_slice(&(clamp(0.0, u32::MAX as f64) as u32).to_le_bytes()),
            _ => element[o..o + 4].copy_from_slice(&(value as f32).to_le_bytes()),
        }
    }

    /// Negates component `c` in place (signed types only; `-i8::MIN` saturates, which is the
    /// same normalized value).
    pub(crate) fn negate_component(&self, element: &mut [u8], c: usize) {
        let o = self.component_offset(c);
        match self.component_type {
            BYTE => element[o] = (element[o] as i8).saturating_neg() as u8,
            SHORT => {
                let v = i16::from_le_bytes([element[o], element[o + 1]]).saturating_neg();
                element[o..o + 2].copy_from_slice(&v.to_le_bytes());
            }
            FLOAT => {
                let v = -f32::from_le_bytes([
                    element[o],
                    element[o + 1],
                    element[o + 2],
                    element[o + 3],
                ]);
                element[o..o + 4].copy_from_slice(&v.to_le_bytes());
            }
            _ => {}
        }
    }
}

/// How an attribute's components blend (see [`Elements::with_blends`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum BlendKind {
    /// Interpolated.
    Linear,
    /// The first `n` components are a unit vector (normal, tangent); any others are taken
    /// from the vertex of largest weight.
    Direction(usize),
    /// Taken from the vertex of largest weight (joint indices).
    Index,
}

impl BlendKind {
    pub(crate) fn of(attribute: &str) -> BlendKind {
        match attribute {
            "NORMAL" | "TANGENT" => BlendKind::Direction(3),
            name if name.starts_with("JOINTS_") => BlendKind::Index,
            _ => BlendKind::Linear,
        }
    }
}

/// The elements of an accessor, densely packed (`layout.element_size()` bytes each).
#[derive(Clone, Debug)]
pub(super) struct Elements {
    pub(crate) layout: Layout,
    pub(crate) bytes: Vec<u8>,
}

impl Elements {
    pub(crate) fn len(&self) -> usize {
        self.bytes.len() / self.layout.element_size()
    }

    pub(crate) fn element(&self, i: usize) -> &[u8] {
        let size = self.layout.element_size();
        &self.bytes[i * size..(i + 1) * size]
    }

    /// `new[a] = self[map[a]]`; every entry of `map` must be in range.
    pub(crate) fn gather(&self, map: &[u32]) -> Elements {
        let mut bytes = Vec::with_capacity(map.len() * self.layout.element_size());
        for &i in map {
            bytes.extend_from_slice(self.element(i as usize));
        }
        Elements {
            layout: self.layout,
            bytes,
        }
    }

    /// `self` with the blended vertices of a junction split appended (element `len() + k` is
    /// `blends[k]`), in the accessor's own component type. Components are interpolated;
    /// `kind` says which are unit vectors (renormalised) and which are indices (`JOINTS_n`,
    /// tangent handedness: taken from the vertex of largest weight).
    pub(crate) fn with_blends(&self, blends: &[Blend], kind: BlendKind) -> Elements {
        let size = self.layout.element_size();
        let n = self.layout.component_count();
        let mut bytes = Vec::with_capacity(self.bytes.len() + blends.len() * size);
        bytes.extend_from_slice(&self.bytes);
        let mut value = vec![0.0f64; n];
        for blend in blends {
            let dominant = (0..3)
                .max_by(|&a, &b| {
                    blend.weights[a]
                        .total_cmp(&blend.weights[b])
                        .then(b.cmp(&a))
                })
                .unwrap_or(0);
            let mut element = self.element(blend.vertices[dominant] as usize).to_vec();
            for (c, v) in value.iter_mut().enumerate() {
                *v = (0..3)
                    .map(|k| {
                        let source = self.element(blend.vertices[k] as usize);
                        f64::from(blend.weights[k]) * self.layout.component(source, c)
                    })
                    .sum();
            }
            let direction = match kind {
                BlendKind::Direction(components) => components.min(n),
                _ => 0,
            };
            // A unit vector stays one: in the decoded scale, renormalised, encoded again.
            let length = value[..direction].iter().map(|v| v * v).sum::<f64>().sqrt();
            let unit = self.layout.unit();
            for (c, &v) in value.iter().enumerate() {
                let v = if c < direction && length > 0.0 {
                    v / length * unit
                } else {
                    v
                };
                let keep = matches!(kind, BlendKind::Index) || (direction > 0 && c >= direction);
                if !keep {
                    self.layout.set_component(&mut element, c, v);
                }
            }
            bytes.extend_from_slice(&element);
        }
        Elements {
            layout: self.layout,
            bytes,
        }
    }

    /// Negates components `components` of every element.
    pub(crate) fn negate(&mut self, components: std::ops::Range<usize>) {
        let size = self.layout.element_size();
        for element in self.bytes.chunks_exact_mut(size) {
            for c in components.clone() {
                self.layout.negate_component(element, c);
            }
        }
    }

    /// Per-component minimum and maximum as glTF JSON numbers (integers for integer types,
    /// the exact single-precision value for floats; non-finite floats count as 0).
    pub(crate) fn bounds(&self) -> (Vec<Value>, Vec<Value>) {
        let n = self.layout.component_count();
        let mut min = vec![f64::INFINITY; n];
        let mut max = vec![f64::NEG_INFINITY; n];
        for i in 0..self.len() {
            let element = self.element(i);
            for c in 0..n {
                let v = self.layout.component(element, c);
                let v = if v.is_finite() { v } else { 0.0 };
                min[c] = min[c].min(v);
                max[c] = max[c].max(v);
            }
        }
        let float = self.layout.component_type == FLOAT;
        let json = |v: f64| {
            if float {
                Value::from(v)
            } else {
                Value::from(v as i64)
            }
        };
        (
            min.into_iter().map(json).collect(),
            max.into_iter().map(json).collect(),
        )
    }

    /// The elements laid out for a vertex buffer view: each element padded to a multiple of
    /// 4 bytes (glTF's vertex attribute alignment). Returns the bytes and the stride.
    pub(crate) fn vertex_bytes(&self) -> (Vec<u8>, usize) {
        let size = self.layout.element_size();
        let stride = size.next_multiple_of(4);
        if stride == size {
            return (self.bytes.clone(), stride);
        }
        let mut bytes = Vec::with_capacity(self.len() * stride);
        for element in self.bytes.chunks_exact(size) {
            bytes.extend_from_slice(element);
            bytes.resize(bytes.len() + stride - size, 0);
        }
        (bytes, stride)
    }
}

/// The bytes of buffer view `view` and its byte stride, from the merged buffer `bin`.
fn view_bytes<'a>(
    json: &Value,
    bin: &'a [u8],
    view: &Value,
) -> Result<(&'a [u8], Option<usize>), String> {
    let index = view.as_u64().ok_or("bufferView index is not an integer")? as usize;
    let v = json
        .get("bufferViews")
        .and_then(|views| views.get(index))
        .ok_or_else(|| format!("bufferView {index} does not exist"))?;
    let offset = v.get("byteOffset").and_then(Value::as_u64).unwrap_or(0) as usize;
    let length = v
        .get("byteLength")
        .and_then(Value::as_u64)
        .ok_or_else(|| format!("bufferView {index} has no byteLength"))? as usize;
    let bytes = bin
        .get(offset..offset.saturating_add(length))
        .ok_or_else(|| format!("bufferView {index} lies outside its buffer"))?;
    let stride = v
        .get("byteStride")
        .and_then(Value::as_u64)
        .map(|s| s as usize);
    Ok((bytes, stride))
}

/// Reads accessor `index` of `json` (whose buffer views all point into `bin`).
pub(super) fn read_accessor(json: &Value, bin: &[u8], index: usize) -> Result<Elements, String> {
    let accessor = json
        .get("accessors")
        .and_then(|a| a.get(index))
        .ok_or_else(|| format!("accessor {index} does not exist"))?;
    let layout = Layout::of(accessor)?;
    let count = accessor
        .get("count")
        .and_then(Value::as_u64)
        .ok_or("no count")? as usize;
    let size = layout.element_size();
    let mut bytes = vec![0u8; count * size];
    if let Some(view) = accessor.get("bufferView") {
        let (data, stride) = view_bytes(json, bin, view)?;
        let stride = stride.unwrap_or(size);
        let offset = accessor
            .get("byteOffset")
            .and_then(Value::as_u64)
            .unwrap_or(0) as usize;
        for (i, element) in bytes.chunks_exact_mut(size).enumerate() {
            let start = offset + i * stride;
            let src = data
                .get(start..start + size)
                .ok_or("elements run past the end of the bufferView")?;
            element.copy_from_slice(src);
        }
    }
    if let Some(sparse) = accessor.get("sparse") {
        apply_sparse(json, bin, sparse, layout, &mut bytes)?;
    }
    Ok(Elements { layout, bytes })
}

fn apply_sparse(
    json: &Value,
    bin: &[u8],
    sparse: &Value,
    layout: Layout,
    bytes: &mut [u8],
) -> Result<(), String> {
    let count = sparse
        .get("count")
        .and_then(Value::as_u64)
        .ok_or("sparse without count")? as usize;
    let (indices, values) = match (sparse.get("indices"), sparse.get("values")) {
        (Some(i), Some(v)) => (i, v),
        _ => return Err("sparse without indices or values".into()),
    };
    let index_layout = Layout::new(
        indices
            .get("componentType")
            .and_then(Value::as_u64)
            .unwrap_or(0),
        "SCALAR",
    )?;
    let section = |part: &Value, element: usize| -> Result<&[u8], String> {
        let (data, _) = view_bytes(
            json,
            bin,
            part.get("bufferView")
                .ok_or("sparse part without bufferView")?,
        )?;
        let offset = part.get("byteOffset").and_then(Value::as_u64).unwrap_or(0) as usize;
        data.get(offset..offset + count * element)
            .ok_or_else(|| "sparse data runs past its bufferView".to_string())
    };
    let index_bytes = section(indices, index_layout.component_size())?;
    let size = layout.element_size();
    let value_bytes = section(values, size)?;
    for s in 0..count {
        let target =
            index_layout.component(&index_bytes[s * index_layout.component_size()..], 0) as usize;
        let dst = bytes
            .get_mut(target * size..(target + 1) * size)
            .ok_or("sparse index out of range")?;
        dst.copy_from_slice(&value_bytes[s * size..(s + 1) * size]);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn strided_and_sparse_reads_resolve_to_dense_elements() {
        // Interleaved: 3 elements of (u16 VEC3 = 6 bytes) at stride 8, offset 2 in the view.
        let mut bin = vec![0u8; 2];
        for e in 0..3u16 {
            for c in 0..3u16 {
                bin.extend_from_slice(&(e * 10 + c).to_le_bytes());
            }
            bin.extend_from_slice(&[0xAA, 0xAA]);
        }
        // Sparse: replace element 1 with (7, 8, 9); indices are u8.
        let sparse_at = bin.len();
        bin.push(1);
        bin.extend_from_slice(&[0, 0, 0]);
        for v in [7u16, 8, 9] {
            bin.extend_from_slice(&v.to_le_bytes());
        }
        let doc = json!({
            "bufferViews": [
                {"buffer": 0, "byteLength": sparse_at, "byteStride": 8},
                {"buffer": 0, "byteOffset": sparse_at, "byteLength": 1},
                {"buffer": 0, "byteOffset": sparse_at + 4, "byteLength": 6},
            ],
            "accessors": [
                {"bufferView": 0, "byteOffset": 2, "componentType": 5123, "type": "VEC3", "count": 3},
                {"bufferView": 0, "byteOffset": 2, "componentType": 5123, "type": "VEC3", "count": 3,
                 "sparse": {"count": 1, "indices": {"bufferView": 1, "componentType": 5121},
                            "values": {"bufferView": 2}}},
                {"componentType": 5126, "type": "VEC2", "count": 2},
            ]
        });
        let plain = read_accessor(&doc, &bin, 0).unwrap();
        let values: Vec<f64> = (0..3)
            .flat_map(|e| (0..3).map(move |c| (e, c)))
            .map(|(e, c)| plain.layout.component(plain.element(e), c))
            .collect();
        assert_eq!(values, [0.0, 1.0, 2.0, 10.0, 11.0, 12.0, 20.0, 21.0, 22.0]);

        let sparse = read_accessor(&doc, &bin, 1).unwrap();
        assert_eq!(sparse.element(0), plain.element(0));
        assert_eq!(sparse.element(1), [7, 0, 8, 0, 9, 0]);
        assert_eq!(sparse.element(2), plain.element(2));

        let zeros = read_accessor(&doc, &bin, 2).unwrap();
        assert_eq!(zeros.bytes, vec![0u8; 16]);

        let (padded, stride) = plain.gather(&[2, 0]).vertex_bytes();
        assert_eq!(stride, 8);
        assert_eq!(&padded[..6], plain.element(2));
        assert_eq!(&padded[8..14], plain.element(0));
        assert_eq!(padded.len(), 16);
    }

    #[test]
    fn out_of_range_views_are_errors_not_panics() {
        let doc = json!({
            "bufferViews": [{"buffer": 0, "byteLength": 8}],
            "accessors": [{"bufferView": 0, "componentType": 5126, "type": "VEC3", "count": 1}]
        });
        assert!(
            read_accessor(&doc, &[0u8; 4], 0).is_err(),
            "view longer than the buffer"
        );
        assert!(
            read_accessor(&doc, &[0u8; 8], 0).is_err(),
            "element longer than the view"
        );
        assert!(
            read_accessor(&doc, &[0u8; 8], 1).is_err(),
            "missing accessor"
        );
    }

    #[test]
    fn bounds_negation_and_matrix_padding() {
        let layout = Layout::new(BYTE, "VEC3").unwrap();
        let mut e = Elements {
            layout,
            bytes: vec![0x80, 5, 0, 0x7f, 0xfb, 1],
        };
        e.negate(0..3);
        assert_eq!(e.bytes, vec![0x7f, 0xfb, 0, 0x81, 5, 0xff]);
        let (min, max) = e.bounds();
        assert_eq!(min, vec![json!(-127), json!(-5), json!(-1)]);
        assert_eq!(max, vec![json!(127), json!(5), json!(0)]);

        let floats = Elements {
            layout: Layout::new(FLOAT, "SCALAR").unwrap(),
            bytes: [0.1f32, -2.5]
                .iter()
                .flat_map(|f| f.to_le_bytes())
                .collect(),
        };
        let (min, max) = floats.bounds();
        assert_eq!(min[0].as_f64().unwrap() as f32, -2.5);
        assert_eq!(
            max[0].as_f64().unwrap(),
            0.1f32 as f64,
            "exact single-precision value"
        );

        // MAT3 of bytes: columns of 3 bytes padded to 4.
        let mat = Layout::new(UNSIGNED_BYTE, "MAT3").unwrap();
        assert_eq!(mat.element_size(), 12);
        let element = [1, 2, 3, 0, 4, 5, 6, 0, 7, 8, 9, 0];
        let read: Vec<f64> = (0..9).map(|c| mat.component(&element, c)).collect();
        assert_eq!(read, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]);
    }
}
