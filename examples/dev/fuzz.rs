//! Structured mutation fuzzer (issue 14): damaged versions of the fixtures, through the loader
//! (in this process, behind `catch_unwind`) and through a whole draft bake (the `lightbake`
//! binary in a child process, so aborts and signals show too).
//!
//! Each case starts from a fixture and applies one to three mutations: JSON edits (delete,
//! replace with a wrong type or an absurd number, duplicate, out-of-range indices, huge counts,
//! negative numbers, numbers beyond f32, missing buffers, duplicate keys), byte damage to buffers
//! (flipped bits, damaged coordinates and indices, truncation, broken data URIs, external `.bin`
//! files missing or cut short) and to GLB containers (header, chunk lengths and types). A case
//! fails on
//! - a panic in the loader, or a loaded scene with a non-finite or absurd position;
//! - a bake that panics (exit 101), dies on a signal (abort, segfault) or runs past `--timeout`;
//! - a failed bake that leaves any file behind, or a successful one that leaves a temporary file;
//! - a non-finite value in an output file (EXR samples, float accessors of the output glTF), or
//!   an output glTF the loader refuses;
//! - an input file changed.
//!
//! Cases are reproducible from `--seed` and their number. Failing cases are copied to
//! `--keep` with a `failure.txt` (reason, mutations, options, stderr).
//!
//! ```text
//! cargo build --release && cargo run --release --example fuzz -- --seconds 3600
//! cargo run --release --example fuzz -- --seed 7 --first 1234 --cases 1   # one case again
//! ```
//!
//! Options: `--seconds S` (time bound), `--cases N` (case bound; both may be given, the first
//! reached ends the run), `--seed S` (default 0), `--first I` (first case number), `--timeout S`
//! per bake (default 120), `--threads N` of each bake (default 1), `--max-memory-mib M` of each
//! bake (default 1024; its address space is capped at 4× that), `--keep DIR` (default `target/fuzz-failures`), `--bin PATH` (default the
//! `lightbake` binary next to this example's target directory), `--verbose` (every case and
//! the last line the bake wrote to stderr).

use std::collections::BTreeMap;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use base64::Engine;
use base64::engine::general_purpose::STANDARD as BASE64;
use lightbake::sampling::Rng;
use serde_json::{Value, json};

const GLB_MAGIC: &[u8; 4] = b"glTF";
const CHUNK_JSON: u32 = 0x4E4F_534A;
const CHUNK_BIN: u32 = 0x004E_4942;
/// Largest coordinate the loader lets through (issue 14: |x| > 1e7 units is refused).
const MAX_COORDINATE: f32 = 1e7;

struct Args {
    seconds: Option<f64>,
    cases: Option<u64>,
    seed: u64,
    first: u64,
    timeout: f64,
    threads: u32,
    max_memory_mib: u64,
    keep: PathBuf,
    bin: PathBuf,
    verbose: bool,
}

fn parse_args() -> Args {
    let target = std::env::current_exe()
        .ok()
        .and_then(|p| Some(p.parent()?.parent()?.to_path_buf()))
        .unwrap_or_else(|| PathBuf::from("target/release"));
    let mut a = Args {
        seconds: None,
        cases: None,
        seed: 0,
        first: 0,
        timeout: 120.0,
        threads: 1,
        max_memory_mib: 1024,
        keep: PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/fuzz-failures"),
        bin: target.join("lightbake"),
        verbose: false,
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let mut value = || it.next().unwrap_or_else(|| panic!("{flag} needs a value"));
        match flag.as_str() {
            "--seconds" => a.seconds = Some(value().parse().expect("--seconds")),
            "--cases" => a.cases = Some(value().parse().expect("--cases")),
            "--seed" => a.seed = value().parse().expect("--seed"),
            "--first" => a.first = value().parse().expect("--first"),
            "--timeout" => a.timeout = value().parse().expect("--timeout"),
            "--threads" => a.threads = value().parse().expect("--threads"),
            "--max-memory-mib" => a.max_memory_mib = value().parse().expect("--max-memory-mib"),
            "--keep" => a.keep = value().into(),
            "--bin" => a.bin = value().into(),
            "--verbose" => a.verbose = true,
            other => panic!("unknown option {other} (see the file header)"),
        }
    }
    if a.seconds.is_none() && a.cases.is_none() {
        a.cases = Some(100);
    }
    a
}

/// A scene being damaged: its JSON and, for a GLB, the binary chunk.
#[derive(Clone)]
struct Model {
    json: Value,
    glb_bin: Option<Vec<u8>>,
}

/// A seed scene from `fixtures/`.
struct Seed {
    name: String,
    model: Model,
}

fn load_seeds() -> Vec<Seed> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures");
    let mut seeds = Vec::new();
    let mut paths: Vec<PathBuf> = std::fs::read_dir(&dir)
        .expect("fixtures/")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .collect();
    paths.sort();
    for path in paths {
        let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
        let bytes = std::fs::read(&path).unwrap();
        let model = match ext {
            "gltf" => Model {
                json: serde_json::from_slice(&bytes).unwrap(),
                glb_bin: None,
            },
            "glb" => unpack_glb(&bytes).expect("a valid fixture GLB"),
            _ => continue,
        };
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        seeds.push(Seed { name, model });
    }
    seeds
}

fn unpack_glb(bytes: &[u8]) -> Option<Model> {
    let u32_at = |o: usize| Some(u32::from_le_bytes(bytes.get(o..o + 4)?.try_into().ok()?));
    let json_len = u32_at(12)? as usize;
    let json = serde_json::from_slice(bytes.get(20..20 + json_len)?).ok()?;
    let bin_at = 20 + json_len;
    let glb_bin = u32_at(bin_at).map(|len| bytes[bin_at + 8..bin_at + 8 + len as usize].to_vec());
    Some(Model { json, glb_bin })
}

fn pack_glb(json: &[u8], bin: Option<&[u8]>) -> Vec<u8> {
    let pad = |v: &mut Vec<u8>, byte: u8| {
        while !v.len().is_multiple_of(4) {
            v.push(byte);
        }
    };
    let mut j = json.to_vec();
    pad(&mut j, b' ');
    let mut out = Vec::new();
    out.extend_from_slice(GLB_MAGIC);
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&0u32.to_le_bytes());
    out.extend_from_slice(&(j.len() as u32).to_le_bytes());
    out.extend_from_slice(&CHUNK_JSON.to_le_bytes());
    out.extend_from_slice(&j);
    if let Some(bin) = bin {
        let mut b = bin.to_vec();
        pad(&mut b, 0);
        out.extend_from_slice(&(b.len() as u32).to_le_bytes());
        out.extend_from_slice(&CHUNK_BIN.to_le_bytes());
        out.extend_from_slice(&b);
    }
    let total = out.len() as u32;
    out[8..12].copy_from_slice(&total.to_le_bytes());
    out
}

/// A few helpers over the project's PCG32 stream.
struct Dice(Rng);

impl Dice {
    fn below(&mut self, n: usize) -> usize {
        if n == 0 {
            0
        } else {
            ((self.0.next_u32() as u64 * n as u64) >> 32) as usize
        }
    }
    fn chance(&mut self, p: f32) -> bool {
        self.0.next_f32() < p
    }
    fn pick<'a, T>(&mut self, items: &'a [T]) -> &'a T {
        &items[self.below(items.len())]
    }
}

/// Paths to every node of a JSON tree (keys and array indices), the root left out.
fn json_paths(v: &Value, prefix: &mut Vec<Value>, out: &mut Vec<Vec<Value>>) {
    match v {
        Value::Object(m) => {
            for (k, c) in m {
                prefix.push(json!(k));
                out.push(prefix.clone());
                json_paths(c, prefix, out);
                prefix.pop();
            }
        }
        Value::Array(a) => {
            // Long number arrays (matrices, data) need not each be a target.
            for (i, c) in a.iter().enumerate().take(24) {
                prefix.push(json!(i));
                out.push(prefix.clone());
                json_paths(c, prefix, out);
                prefix.pop();
            }
        }
        _ => {}
    }
}

fn node_mut<'a>(root: &'a mut Value, path: &[Value]) -> Option<&'a mut Value> {
    let mut v = root;
    for step in path {
        v = match step {
            Value::String(k) => v.get_mut(k.as_str())?,
            Value::Number(i) => v.get_mut(i.as_u64()? as usize)?,
            _ => return None,
        };
    }
    Some(v)
}

fn describe(path: &[Value]) -> String {
    path.iter()
        .map(|s| match s {
            Value::String(k) => k.clone(),
            other => other.to_string(),
        })
        .collect::<Vec<_>>()
        .join("/")
}

/// A wrong value for a JSON node: another type, an index just past an array, or an absurd number.
fn bad_value(d: &mut Dice, root: &Value) -> Value {
    let arrays = [
        "accessors",
        "bufferViews",
        "buffers",
        "meshes",
        "nodes",
        "materials",
        "textures",
        "images",
        "samplers",
    ];
    let len = |name: &str| root.get(name).and_then(Value::as_array).map_or(0, Vec::len);
    match d.below(22) {
        0 => Value::Null,
        1 => json!(true),
        2 => json!("x"),
        3 => json!([]),
        4 => json!({}),
        5 => json!(-1),
        6 => json!(0),
        7 => json!(1),
        8 => json!(1u64 << 31),
        9 => json!((1u64 << 32) + 1),
        10 => json!(1e300),
        11 => json!(-1e300),
        12 => json!(0.5),
        13 => json!(-0.0),
        14 => json!(u64::MAX),
        15 => json!(i64::MIN),
        16 => json!(1_000_000_000u64),
        17 => json!(1e39), // beyond f32: infinity once read as one
        18 => {
            let array = *d.pick(&arrays);
            json!(len(array))
        }
        19 => {
            let array = *d.pick(&arrays);
            json!(len(array).saturating_sub(1))
        }
        20 => json!([1e39, -1e39, 0.0]),
        _ => json!(-3.5),
    }
}

/// One JSON edit; returns what it did.
fn mutate_json(d: &mut Dice, m: &mut Model) -> String {
    let mut paths = Vec::new();
    json_paths(&m.json, &mut Vec::new(), &mut paths);
    if paths.is_empty() {
        return "nothing to edit".into();
    }
    // Most of the interesting structure is in a few arrays: aim there half of the time.
    let hot = [
        "accessors",
        "bufferViews",
        "meshes",
        "buffers",
        "extensions",
        "nodes",
    ];
    let path = if d.chance(0.5) {
        let key = *d.pick(&hot);
        let under: Vec<&Vec<Value>> = paths.iter().filter(|p| p[0] == json!(key)).collect();
        if under.is_empty() {
            d.pick(&paths).clone()
        } else {
            (*d.pick(&under)).clone()
        }
    } else {
        d.pick(&paths).clone()
    };
    let (parent_path, last) = path.split_at(path.len() - 1);
    let what = describe(&path);
    match d.below(6) {
        0 => {
            let parent = node_mut(&mut m.json, parent_path).unwrap();
            match (&last[0], parent) {
                (Value::String(k), Value::Object(o)) => {
                    o.remove(k);
                }
                (Value::Number(i), Value::Array(a)) => {
                    a.remove(i.as_u64().unwrap() as usize);
                }
                _ => {}
            }
            format!("delete {what}")
        }
        1 => {
            let value = bad_value(d, &m.json);
            let text = value.to_string();
            *node_mut(&mut m.json, &path).unwrap() = value;
            format!("set {what} = {text}")
        }
        3 => {
            // Duplicate: an array element appended again, or a value copied to a sibling key.
            let value = node_mut(&mut m.json, &path).unwrap().clone();
            let parent = node_mut(&mut m.json, parent_path).unwrap();
            match parent {
                Value::Array(a) => {
                    a.push(value);
                    format!("duplicate {what} at the end")
                }
                Value::Object(o) => {
                    let keys: Vec<String> = o.keys().cloned().collect();
                    let to = keys[d.below(keys.len())].clone();
                    o.insert(to.clone(), value);
                    format!("copy {what} over {}/{to}", describe(parent_path))
                }
                _ => "nothing".into(),
            }
        }
        2 | 4 => {
            // A number nudged: negated, off by one, scaled far out.
            let node = node_mut(&mut m.json, &path).unwrap();
            match node.as_f64() {
                Some(x) => {
                    let y = match d.below(5) {
                        0 => -x,
                        1 => x + 1.0,
                        2 => x - 1.0,
                        3 => x * 1e6,
                        _ => x * 1e30,
                    };
                    *node = if y.fract() == 0.0 && y.abs() < 9e15 {
                        json!(y as i64)
                    } else {
                        json!(y)
                    };
                    format!("nudge {what}: {x} -> {y}")
                }
                None => {
                    *node = bad_value(d, &Value::Null);
                    format!("set {what} to a bad value")
                }
            }
        }
        _ => {
            // Buffers: removed, their uri removed or pointing nowhere.
            let buffers = m.json.get_mut("buffers").and_then(Value::as_array_mut);
            match (buffers, d.below(3)) {
                (Some(b), 0) => {
                    b.clear();
                    "no buffers".into()
                }
                (Some(b), 1) if !b.is_empty() => {
                    if let Some(o) = b[0].as_object_mut() {
                        o.remove("uri");
                    }
                    "buffer 0 without uri".into()
                }
                (Some(b), _) if !b.is_empty() => {
                    if let Some(o) = b[0].as_object_mut() {
                        o.insert("uri".into(), json!("missing.bin"));
                    }
                    "buffer 0 uri missing.bin".into()
                }
                _ => "no buffers to damage".into(),
            }
        }
    }
}

/// The binary blobs of a model: (label, bytes) of each data URI (buffers, images) and the GLB
/// chunk, decoded.
fn blobs(m: &Model) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    for key in ["buffers", "images"] {
        if let Some(items) = m.json.get(key).and_then(Value::as_array) {
            for (i, item) in items.iter().enumerate() {
                if let Some(data) = item.get("uri").and_then(Value::as_str).and_then(data_uri) {
                    out.push((format!("{key}/{i}"), data));
                }
            }
        }
    }
    if let Some(b) = &m.glb_bin {
        out.push(("glb".into(), b.clone()));
    }
    out
}

fn data_uri(uri: &str) -> Option<Vec<u8>> {
    let payload = uri.strip_prefix("data:")?.split_once(";base64,")?.1;
    BASE64.decode(payload).ok()
}

fn set_blob(m: &mut Model, label: &str, bytes: Vec<u8>) {
    if label == "glb" {
        m.glb_bin = Some(bytes);
        return;
    }
    let (key, i) = label.split_once('/').unwrap();
    let i: usize = i.parse().unwrap();
    let uri = m.json[key][i]["uri"].as_str().unwrap_or("");
    let mime = uri
        .strip_prefix("data:")
        .and_then(|u| u.split_once(';'))
        .map_or("application/octet-stream", |(mime, _)| mime)
        .to_string();
    m.json[key][i]["uri"] = json!(format!("data:{mime};base64,{}", BASE64.encode(bytes)));
}

/// Where an accessor's elements lie: (blob label, byte offset, stride, element size, count).
fn accessor_bytes(m: &Model, accessor: usize) -> Option<(String, usize, usize, usize, usize)> {
    let a = m.json.get("accessors")?.get(accessor)?;
    let view = m
        .json
        .get("bufferViews")?
        .get(a.get("bufferView")?.as_u64()? as usize)?;
    let buffer = view.get("buffer")?.as_u64()? as usize;
    let component = match a.get("componentType")?.as_u64()? {
        5120 | 5121 => 1,
        5122 | 5123 => 2,
        _ => 4,
    };
    let n = match a.get("type")?.as_str()? {
        "SCALAR" => 1,
        "VEC2" => 2,
        "VEC3" => 3,
        "VEC4" => 4,
        _ => 16,
    };
    let size = component * n;
    let stride = view
        .get("byteStride")
        .and_then(Value::as_u64)
        .unwrap_or(size as u64) as usize;
    let offset = view.get("byteOffset").and_then(Value::as_u64).unwrap_or(0) as usize
        + a.get("byteOffset").and_then(Value::as_u64).unwrap_or(0) as usize;
    let label = if m.json["buffers"][buffer].get("uri").is_none() {
        "glb".to_string()
    } else {
        format!("buffers/{buffer}")
    };
    Some((
        label,
        offset,
        stride,
        size,
        a.get("count")?.as_u64()? as usize,
    ))
}

/// Accessors a primitive uses for `attribute` (or "indices").
fn primitive_accessors(m: &Model, attribute: &str) -> Vec<usize> {
    let mut out = Vec::new();
    for mesh in m
        .json
        .get("meshes")
        .and_then(Value::as_array)
        .into_iter()
        .flatten()
    {
        for p in mesh
            .get("primitives")
            .and_then(Value::as_array)
            .into_iter()
            .flatten()
        {
            let a = if attribute == "indices" {
                p.get("indices")
            } else {
                p.get("attributes").and_then(|a| a.get(attribute))
            };
            if let Some(i) = a.and_then(Value::as_u64) {
                out.push(i as usize);
            }
        }
    }
    out
}

/// One damage to binary data; returns what it did.
fn mutate_bytes(d: &mut Dice, m: &mut Model) -> String {
    match d.below(5) {
        0 | 1 => {
            // A coordinate (or normal, or texture coordinate) made NaN, infinite, huge or tiny.
            let attribute =
                *d.pick(&["POSITION", "POSITION", "NORMAL", "TEXCOORD_0", "TEXCOORD_1"]);
            let accessors = primitive_accessors(m, attribute);
            let Some(&a) = accessors.get(d.below(accessors.len())) else {
                return format!("no {attribute} to damage");
            };
            let Some((label, offset, stride, size, count)) = accessor_bytes(m, a) else {
                return format!("accessor {a} has no data");
            };
            let Some((_, mut data)) = blobs(m).into_iter().find(|(l, _)| *l == label) else {
                return format!("accessor {a}: no blob {label}");
            };
            let element = d.below(count.max(1));
            let component = d.below(size / 4);
            let at = offset + element * stride + component * 4;
            let Some(word) = data.get_mut(at..at + 4) else {
                return format!("accessor {a} element {element} outside its blob");
            };
            let old = f32::from_le_bytes(word.try_into().unwrap());
            let bits = old.to_bits();
            let new = match d.below(6) {
                0 => f32::NAN,
                1 => f32::INFINITY,
                2 => -f32::MAX,
                3 => f32::from_bits(bits ^ (1 << (23 + d.below(8)))), // an exponent bit
                4 => f32::from_bits(bits ^ (1 << d.below(32))),
                _ => 1e-40, // subnormal
            };
            word.copy_from_slice(&new.to_le_bytes());
            set_blob(m, &label, data);
            format!("{attribute} accessor {a} element {element}.{component}: {old} -> {new}")
        }
        2 => {
            // Indices pointing past the vertices, or all alike.
            let accessors = primitive_accessors(m, "indices");
            let Some(&a) = accessors.get(d.below(accessors.len())) else {
                return "no indices to damage".into();
            };
            let Some((label, offset, stride, size, count)) = accessor_bytes(m, a) else {
                return format!("accessor {a} has no data");
            };
            let Some((_, mut data)) = blobs(m).into_iter().find(|(l, _)| *l == label) else {
                return format!("accessor {a}: no blob {label}");
            };
            let element = d.below(count.max(1));
            let at = offset + element * stride;
            let value = *d.pick(&[u32::MAX, 65535, 65536, 1 << 31, 0]);
            let Some(bytes) = data.get_mut(at..at + size) else {
                return format!("indices {a} element {element} outside its blob");
            };
            for (k, b) in bytes.iter_mut().enumerate() {
                *b = value.to_le_bytes()[k % 4];
            }
            set_blob(m, &label, data);
            format!("indices accessor {a} element {element} = {value}")
        }
        3 => {
            // Random bits flipped anywhere in a blob.
            let mut all = blobs(m);
            if all.is_empty() {
                return "no blob".into();
            }
            let (label, mut data) = all.swap_remove(d.below(all.len()));
            let flips = 1 + d.below(8);
            for _ in 0..flips {
                let at = d.below(data.len());
                if let Some(b) = data.get_mut(at) {
                    *b ^= 1 << d.below(8);
                }
            }
            set_blob(m, &label, data);
            format!("{flips} bits flipped in {label}")
        }
        _ => {
            // A blob cut short or grown.
            let mut all = blobs(m);
            if all.is_empty() {
                return "no blob".into();
            }
            let (label, mut data) = all.swap_remove(d.below(all.len()));
            let len = if d.chance(0.7) {
                d.below(data.len())
            } else {
                data.len() + 1 + d.below(64)
            };
            data.resize(len, 0xAB);
            set_blob(m, &label, data);
            format!("{label} resized to {len} bytes")
        }
    }
}

/// How a case is written to disk, and damage done to the files themselves.
fn write_case(d: &mut Dice, m: &Model, dir: &Path, log: &mut Vec<String>) -> PathBuf {
    let mut m = m.clone();
    let form = if m.glb_bin.is_some() {
        *d.pick(&["glb", "glb", "gltf"])
    } else {
        *d.pick(&["gltf", "gltf", "bin", "glb"])
    };
    log.push(format!("written as {form}"));
    // External .bin files: every data-URI buffer moves to its own file.
    let mut externals = Vec::new();
    if form == "bin" {
        let n = m
            .json
            .get("buffers")
            .and_then(Value::as_array)
            .map_or(0, Vec::len);
        for i in 0..n {
            let Some(buffer) = m.json["buffers"][i].as_object_mut() else {
                continue;
            };
            if let Some(data) = buffer.get("uri").and_then(Value::as_str).and_then(data_uri) {
                let name = format!("scene{i}.bin");
                buffer.insert("uri".into(), json!(name.clone()));
                externals.push((name, data));
            }
        }
    }
    if form == "gltf"
        && let Some(bin) = m.glb_bin.take()
        && let Some(buffer) = m
            .json
            .pointer_mut("/buffers/0")
            .and_then(Value::as_object_mut)
    {
        let uri = format!(
            "data:application/octet-stream;base64,{}",
            BASE64.encode(bin)
        );
        buffer.insert("uri".into(), json!(uri));
    }
    let mut glb_bin = m.glb_bin.clone();
    if form == "glb" && glb_bin.is_none() {
        // The first buffer becomes the binary chunk.
        if let Some(data) = m.json["buffers"][0]["uri"].as_str().and_then(data_uri) {
            m.json["buffers"][0].as_object_mut().unwrap().remove("uri");
            glb_bin = Some(data);
        }
    }
    let mut text = serde_json::to_vec(&m.json).unwrap();
    if d.chance(0.08) {
        // A duplicate key at the root: what a hand edit or a bad merge leaves.
        let key = *d.pick(&["accessors", "meshes", "buffers", "asset", "nodes", "scene"]);
        let value = bad_value(d, &m.json).to_string();
        let dup = format!("{{\"{key}\":{value},");
        text.splice(0..1, dup.bytes());
        log.push(format!("duplicate root key {key}: {value}"));
    }
    if d.chance(0.05) {
        let at = d.below(text.len());
        text[at] = *d.pick(b"{}[]\",:0\\\x00\xff");
        log.push(format!("JSON byte {at} replaced"));
    }
    let path = if form == "glb" {
        let mut bytes = pack_glb(&text, glb_bin.as_deref());
        if d.chance(0.3) {
            let (at, what) = *d.pick(&[
                (0usize, "magic"),
                (4, "version"),
                (8, "total length"),
                (12, "JSON chunk length"),
                (16, "JSON chunk type"),
            ]);
            let value = *d.pick(&[0u32, 1, 3, u32::MAX, 0x7FFF_FFFF, bytes.len() as u32 + 8]);
            bytes[at..at + 4].copy_from_slice(&value.to_le_bytes());
            log.push(format!("GLB {what} = {value}"));
        } else if d.chance(0.15) {
            let len = d.below(bytes.len());
            bytes.truncate(len);
            log.push(format!("GLB cut to {len} bytes"));
        }
        let path = dir.join("scene.glb");
        std::fs::write(&path, bytes).unwrap();
        path
    } else {
        let path = dir.join("scene.gltf");
        std::fs::write(&path, &text).unwrap();
        path
    };
    for (k, (name, mut data)) in externals.into_iter().enumerate() {
        if k == 0 && d.chance(0.3) {
            if d.chance(0.4) {
                log.push(format!("{name} missing"));
                continue;
            }
            let len = d.below(data.len());
            data.truncate(len);
            log.push(format!("{name} cut to {len} bytes"));
        }
        std::fs::write(dir.join(name), data).unwrap();
    }
    path
}

/// Bake options of a case: automatic or fixed settings at draft, a low density, and one of the
/// techniques or output options now and then.
fn bake_options(d: &mut Dice) -> Vec<String> {
    let density = *d.pick(&["1", "2", "4"]);
    let mut o: Vec<&str> = vec!["--quality", "draft", "--texels-per-unit", density];
    if d.chance(0.5) {
        o.extend(["--no-auto", "--rays", "16", "--light-samples", "4"]);
    }
    if d.chance(0.4) {
        o.extend(*d.pick(&[
            &["--method", "point"][..],
            &["--method", "polygon"],
            &["--method", "hierarchical"],
            &["--solver", "gather"],
            &["--solver", "southwell"],
            &["--solver", "gauss-seidel"],
            &["--uv", "unwrap"],
            &["--uv", "existing"],
            &["--float", "--rgbm"],
            &["--indirect-only"],
            &["--no-validity"],
            &["--no-seams", "--no-denoise"],
            &["--sky", "0.5"],
        ]));
    }
    o.into_iter().map(String::from).collect()
}

/// Every file under `dir` with its bytes.
fn snapshot(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).into_iter().flatten().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.insert(p.clone(), std::fs::read(&p).unwrap_or_default());
            }
        }
    }
    out
}

/// Everything under `dir`, directories included (a temporary directory left behind counts).
fn entries(dir: &Path) -> Vec<String> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).into_iter().flatten().flatten() {
            let p = e.path();
            out.push(p.strip_prefix(dir).unwrap().display().to_string());
            if p.is_dir() {
                stack.push(p);
            }
        }
    }
    out.sort();
    out
}

/// Non-finite values in the output files, described; empty when all are finite.
fn non_finite_outputs(out: &Path) -> Vec<String> {
    let mut bad = Vec::new();
    for name in entries(out) {
        let path = out.join(&name);
        if name.ends_with(".exr") {
            match exr::prelude::read_all_flat_layers_from_file(&path) {
                Ok(image) => {
                    for layer in &image.layer_data {
                        for channel in &layer.channel_data.list {
                            let finite = match &channel.sample_data {
                                exr::prelude::FlatSamples::F16(s) => {
                                    s.iter().all(|x| x.to_f32().is_finite())
                                }
                                exr::prelude::FlatSamples::F32(s) => {
                                    s.iter().all(|x| x.is_finite())
                                }
                                exr::prelude::FlatSamples::U32(_) => true,
                            };
                            if !finite {
                                bad.push(format!("{name}: channel {} not finite", channel.name));
                            }
                        }
                    }
                }
                Err(e) => bad.push(format!("{name}: unreadable EXR: {e}")),
            }
        }
        if name.ends_with(".gltf") || name.ends_with(".glb") {
            // Buffers only: images are copied from the input as they are, damaged or not.
            let imported = gltf::Gltf::open(&path).and_then(|g| {
                let buffers = gltf::import_buffers(&g.document, Some(out), g.blob.clone())?;
                Ok((g.document, buffers))
            });
            match imported {
                Ok((doc, buffers)) => {
                    for a in doc.accessors() {
                        if a.data_type() != gltf::accessor::DataType::F32 || a.sparse().is_some() {
                            continue;
                        }
                        let Some(view) = a.view() else { continue };
                        let data = &buffers[view.buffer().index()].0;
                        let size = a.size();
                        let stride = view.stride().unwrap_or(size);
                        let start = view.offset() + a.offset();
                        for e in 0..a.count() {
                            let at = start + e * stride;
                            let floats = data.get(at..at + size).unwrap_or(&[]);
                            if floats
                                .chunks_exact(4)
                                .any(|w| !f32::from_le_bytes(w.try_into().unwrap()).is_finite())
                            {
                                bad.push(format!(
                                    "{name}: accessor {} element {e} not finite",
                                    a.index()
                                ));
                                break;
                            }
                        }
                    }
                }
                Err(e) => bad.push(format!("{name}: the gltf crate cannot read it: {e}")),
            }
            if let Err(e) = lightbake::scene::load(&path) {
                bad.push(format!("{name}: lightbake cannot read its own output: {e}"));
            }
        }
    }
    bad
}

/// The outcome of one case.
enum Verdict {
    Pass { loaded: bool, baked: bool },
    Fail(String),
    Slow,
}

struct Checked {
    verdict: Verdict,
    stderr: String,
}

/// The message of the last panic caught in this process.
static PANIC: Mutex<String> = Mutex::new(String::new());

thread_local! {
    /// Set while the loader runs: its panics are findings, the fuzzer's own are bugs.
    static IN_LOADER: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

fn run_case(args: &Args, input: &Path, dir: &Path, options: &[String]) -> Checked {
    let before = snapshot(input.parent().unwrap());
    // The loader, in this process.
    IN_LOADER.set(true);
    let loaded = std::panic::catch_unwind(|| lightbake::scene::load(input));
    IN_LOADER.set(false);
    let loaded = match loaded {
        Err(_) => {
            let msg = PANIC.lock().unwrap().clone();
            return Checked {
                verdict: Verdict::Fail(format!("the loader panicked: {msg}")),
                stderr: String::new(),
            };
        }
        Ok(Ok((scene, _))) => {
            let bad = scene
                .positions
                .iter()
                .position(|p| !p.is_finite() || p.abs().max_element() > MAX_COORDINATE);
            if let Some(k) = bad {
                return Checked {
                    verdict: Verdict::Fail(format!(
                        "the loader let position {k} = {} through",
                        scene.positions[k]
                    )),
                    stderr: String::new(),
                };
            }
            true
        }
        Ok(Err(_)) => false,
    };
    // The whole bake, in a child process.
    let out = dir.join("out");
    let mut command = Command::new(&args.bin);
    // The bake's address space is capped at 4× its --max-memory: a bake the memory estimate
    // lets through but that needs far more aborts here instead of crowding the machine.
    let address_space = (args.max_memory_mib << 20) * 4;
    // SAFETY: setrlimit is async-signal-safe and touches no memory of the parent.
    unsafe {
        command.pre_exec(move || {
            let limit = libc::rlimit {
                rlim_cur: address_space,
                rlim_max: address_space,
            };
            if libc::setrlimit(libc::RLIMIT_AS, &limit) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    let mut child = command
        .arg("bake")
        .arg(input)
        .arg("-o")
        .arg(&out)
        .args(options)
        .args(["--quiet", "--threads", &args.threads.to_string()])
        .args(["--max-memory", &format!("{}M", args.max_memory_mib)])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run lightbake (build it first: cargo build --release)");
    let mut pipe = child.stderr.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        std::io::Read::read_to_string(&mut pipe, &mut s).ok();
        s
    });
    let start = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break Some(s);
        }
        if start.elapsed().as_secs_f64() > args.timeout {
            child.kill().ok();
            child.wait().ok();
            break None;
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    let stderr = reader.join().unwrap_or_default();
    let Some(status) = status else {
        return Checked {
            verdict: Verdict::Slow,
            stderr,
        };
    };
    let fail = |why: String| Checked {
        verdict: Verdict::Fail(why),
        stderr: stderr.clone(),
    };
    let after = snapshot(input.parent().unwrap());
    if before != after {
        return fail("an input file changed".into());
    }
    let left = entries(&out);
    match status.code() {
        Some(0) => {
            if let Some(tmp) = left.iter().find(|e| e.contains("lightbake-tmp")) {
                return fail(format!("a temporary file left behind: {tmp}"));
            }
            let bad = non_finite_outputs(&out);
            if !bad.is_empty() {
                return fail(bad.join("; "));
            }
        }
        Some(1) => {
            if !left.is_empty() {
                return fail(format!("a failed bake left {left:?}"));
            }
        }
        Some(101) => return fail("the bake panicked".into()),
        code => return fail(format!("the bake ended with {code:?} ({status})")),
    }
    if stderr.contains("panicked") {
        return fail("a panic message on stderr".into());
    }
    Checked {
        verdict: Verdict::Pass {
            loaded,
            baked: status.success(),
        },
        stderr,
    }
}

fn main() {
    let args = parse_args();
    if !args.bin.exists() {
        eprintln!(
            "no lightbake binary at {} (cargo build --release, or --bin PATH)",
            args.bin.display()
        );
        std::process::exit(2);
    }
    let default_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        if IN_LOADER.get() {
            *PANIC.lock().unwrap() = info.to_string();
        } else {
            default_hook(info);
        }
    }));
    let seeds = load_seeds();
    let started = Instant::now();
    let scratch = tempfile::tempdir().unwrap();
    let (mut cases, mut loaded, mut baked, mut slow, mut skipped) = (0u64, 0, 0, 0, 0);
    let failures = Arc::new(Mutex::new(Vec::<String>::new()));
    let mut last_report = Instant::now();
    let mut case = args.first;
    loop {
        if args.cases.is_some_and(|n| cases >= n)
            || args
                .seconds
                .is_some_and(|s| started.elapsed().as_secs_f64() >= s)
        {
            break;
        }
        let dir = scratch.path().join(format!("case{case}"));
        let input_dir = dir.join("in");
        std::fs::create_dir_all(&input_dir).unwrap();
        let made = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            let mut d = Dice(Rng::new(args.seed, case, 0xF022));
            let seed = &seeds[d.below(seeds.len())];
            let mut model = seed.model.clone();
            let mut log = vec![format!("seed {}", seed.name)];
            let edits = *d.pick(&[1, 1, 1, 2, 2, 3]);
            for _ in 0..edits {
                let what = if d.chance(0.55) {
                    mutate_json(&mut d, &mut model)
                } else {
                    mutate_bytes(&mut d, &mut model)
                };
                log.push(what);
            }
            let input = write_case(&mut d, &model, &input_dir, &mut log);
            (input, log, bake_options(&mut d))
        }));
        // A bug of the fuzzer's own mutations (its panic is printed) skips the case, not the run.
        let Ok((input, log, options)) = made else {
            eprintln!("case {case}: skipped (the fuzzer's mutation panicked)");
            skipped += 1;
            std::fs::remove_dir_all(&dir).ok();
            case += 1;
            continue;
        };
        let checked = run_case(&args, &input, &dir, &options);
        cases += 1;
        if args.verbose {
            let last = checked.stderr.lines().last().unwrap_or("");
            eprintln!(
                "case {case}: {} [{}] -> {last}",
                log.join("; "),
                options.join(" ")
            );
        }
        match &checked.verdict {
            Verdict::Pass {
                loaded: l,
                baked: b,
            } => {
                loaded += *l as u64;
                baked += *b as u64;
            }
            Verdict::Slow => {
                slow += 1;
                eprintln!(
                    "case {case}: slower than {}s (not a failure): {}",
                    args.timeout,
                    log.join("; ")
                );
            }
            Verdict::Fail(why) => {
                let keep = args.keep.join(format!("seed{}-case{case}", args.seed));
                std::fs::create_dir_all(&keep).unwrap();
                for (path, bytes) in snapshot(&input_dir) {
                    std::fs::write(keep.join(path.file_name().unwrap()), bytes).unwrap();
                }
                let note = format!(
                    "{why}\nmutations: {}\noptions: {}\nstderr:\n{}",
                    log.join("; "),
                    options.join(" "),
                    checked.stderr
                );
                std::fs::write(keep.join("failure.txt"), &note).unwrap();
                eprintln!(
                    "case {case}: FAIL {why}\n  {}\n  kept in {}",
                    log.join("; "),
                    keep.display()
                );
                failures.lock().unwrap().push(format!("case {case}: {why}"));
            }
        }
        std::fs::remove_dir_all(&dir).ok();
        if last_report.elapsed() > Duration::from_secs(60) {
            last_report = Instant::now();
            eprintln!(
                "{:.0}s: {cases} cases ({loaded} loaded, {baked} baked), {} failures",
                started.elapsed().as_secs_f64(),
                failures.lock().unwrap().len()
            );
        }
        case += 1;
    }
    let failures = failures.lock().unwrap();
    println!(
        "fuzz seed {} cases {}..{}: {cases} cases in {:.0}s ({loaded} loaded, {baked} baked, {slow} slower than {}s, {skipped} skipped), {} failures",
        args.seed,
        args.first,
        case,
        started.elapsed().as_secs_f64(),
        args.timeout,
        failures.len()
    );
    for f in failures.iter() {
        println!("  {f}");
    }
    if !failures.is_empty() {
        std::process::exit(1);
    }
}
