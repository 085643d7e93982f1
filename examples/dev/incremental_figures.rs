//! An incremental re-bake (`bake --since`) against a full bake of the same edit, in one run:
//! wall time, rows re-traced, rays, and the point error of both against a path-traced
//! reference of the edited scene.
//!
//! ```text
//! cargo run --release --example incremental_figures -- OUT [SCENE.glb] [NODE] [DX] [QUALITY] [--remove | --add] [--no-reference]
//! ```
//!
//! Defaults: `fixtures/furnished_interior.glb`, node `chair_0_0`, moved `0.5` m along x,
//! `medium`; with `--remove` the node is deleted from the document instead (the nodes after it
//! renumbered; `DX` unused); with `--add` a 40 cm box (a mesh of its own, its bytes appended to
//! the binary chunk, the `wood` material) is added on the floor at (0, 0, −1.5), between the
//! tables, as a new root node `NODE` (`NODE` and `DX` otherwise unused). Steps: bake the scene with `--keep-transport` (`OUT/old`); move the node
//! (`OUT/edited/<name>`); bake the edited scene in full with the same options (`OUT/full`) and
//! incrementally from the old bake (`OUT/incremental`), alternating, twice each (the machine's
//! load changes between runs: each round's ratio is reported); with a reference, compute the point
//! reference of the edited scene (1024 points, to 1% noise or 2048 paths, at most 300 s;
//! `OUT/reference.csv`, reused when present) and compare both bakes as a renderer reads them
//! (`points::compare`, the reference's noise taken out). Prints a Markdown table and writes
//! `OUT/incremental_figures.csv`.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use lightbake::reference::ReferenceParams;
use lightbake::reference::points::{self, PointReference};
use lightbake::render::RenderScene;
use lightbake::{BakeConfig, NoProgress, bake, incremental};

/// Full and incremental bakes of the edited scene, alternating.
const ROUNDS: usize = 2;
use serde_json::Value;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let no_reference = args.iter().any(|a| a == "--no-reference");
    let remove = args.iter().any(|a| a == "--remove");
    let add = args.iter().any(|a| a == "--add");
    let args: Vec<&String> = args.iter().filter(|a| !a.starts_with("--")).collect();
    let out = PathBuf::from(args.first().expect(
        "usage: incremental_figures OUT [SCENE.glb] [NODE] [DX] [QUALITY] [--remove | --add] [--no-reference]",
    ));
    let scene = args.get(1).map_or_else(
        || Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/furnished_interior.glb"),
        PathBuf::from,
    );
    let node = args
        .get(2)
        .map_or(if add { "box" } else { "chair_0_0" }, |s| s.as_str());
    let dx: f32 = args.get(3).map_or(0.5, |s| s.parse().expect("DX"));
    let quality = args.get(4).map_or("medium", |s| s.as_str());
    let edit = if remove {
        "removed".to_string()
    } else if add {
        "added".to_string()
    } else {
        format!("moved {dx} m")
    };
    // As `lightbake bake SCENE --quality Q --keep-transport` configures it (automatic choice).
    let options = lightbake::build::options::Options {
        quality: Some(quality.to_string()),
        keep_transport: Some(true),
        ..Default::default()
    };
    let config = options.config().expect("options");
    let name = scene.file_name().unwrap().to_string_lossy().to_string();
    let stem = scene.file_stem().unwrap().to_string_lossy().to_string();

    let old = out.join("old");
    let _ = std::fs::remove_dir_all(&old);
    let t = Instant::now();
    let report = bake(&scene, &old, &config, &NoProgress).expect("bake");
    let old_seconds = t.elapsed().as_secs_f64();
    eprintln!("old bake: {old_seconds:.1}s; {}", report.summary());

    let edited = out.join("edited").join(&name);
    std::fs::create_dir_all(edited.parent().unwrap()).unwrap();
    if remove {
        edit_glb(&scene, &edited, |json, _| remove_node(json, node));
    } else if add {
        edit_glb(&scene, &edited, |json, bin| {
            add_box(json, bin, node, 0.4, [0.0, 0.0, -1.5])
        });
    } else {
        edit_glb(&scene, &edited, |json, _| move_node(json, node, dx));
    }

    // Full and incremental bakes alternate, `ROUNDS` times each: on a shared machine the load
    // changes between runs, and the ratio of neighbours is what it measures.
    let full = out.join("full");
    let inc = out.join("incremental");
    let since = old.join(&name);
    let (mut full_times, mut inc_times) = (Vec::new(), Vec::new());
    let mut figures = None;
    // The full bake's own texels: it plans the edited scene again.
    let mut full_texels = 0;
    for round in 0..ROUNDS {
        let _ = std::fs::remove_dir_all(&full);
        let t = Instant::now();
        let full_report = bake(&edited, &full, &config, &NoProgress).expect("full bake");
        full_texels = full_report.texels;
        full_times.push(t.elapsed().as_secs_f64());
        eprintln!(
            "round {round}, full bake: {:.1}s; {}",
            full_times[round],
            full_report.summary()
        );

        let _ = std::fs::remove_dir_all(&inc);
        let t = Instant::now();
        let inc_report = incremental::bake_since(&edited, &since, &inc, &config, &NoProgress)
            .expect("incremental bake");
        inc_times.push(t.elapsed().as_secs_f64());
        eprintln!(
            "round {round}, incremental bake: {:.1}s; {}",
            inc_times[round],
            inc_report.summary()
        );
        figures = inc_report.incremental;
    }
    let figures = figures.expect("an incremental report");
    let ratios: Vec<f64> = inc_times
        .iter()
        .zip(&full_times)
        .map(|(i, f)| i / f)
        .collect();
    let full_seconds = full_times.iter().sum::<f64>() / ROUNDS as f64;
    let inc_seconds = inc_times.iter().sum::<f64>() / ROUNDS as f64;
    eprintln!("incremental / full per round: {ratios:.3?}");

    // Point errors: the full and the incremental bake against a reference of the edited
    // scene, and the old bake (whose plan the incremental one keeps) against one of the
    // unedited scene.
    let error = |dir: &Path, reference: &PointReference| {
        let render = RenderScene::load(&dir.join(&name)).expect("load the bake");
        let c = points::compare(&render, reference);
        (c.rmse_without_noise, c.noise)
    };
    let errors = (!no_reference).then(|| {
        let reference = point_reference(&edited, &out.join("reference.csv"));
        let unedited = point_reference(&scene, &out.join("reference_unedited.csv"));
        [
            error(&full, &reference),
            error(&inc, &reference),
            error(&old, &unedited),
        ]
    });

    println!(
        "| bake | wall s (mean of {ROUNDS}) | ratio (per round) | rows re-traced | rows patched | rays | point RMSE (noise out) |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|");
    let point = |k: usize| {
        errors
            .map(|e| format!("{:.2}% (ref. noise {:.2}%)", e[k].0 * 100.0, e[k].1 * 100.0))
            .unwrap_or_else(|| "-".to_string())
    };
    println!(
        "| full ({quality}, planned again: {n} texels) | {full_seconds:.1} | 1 | {n} of {n} | 0 | (in its summary) | {} |",
        point(0),
        n = full_texels
    );
    println!(
        "| incremental | {inc_seconds:.1} | {:.3?} | {} of {} | {} | {:.1} M | {} |",
        ratios,
        figures.retraced,
        figures.rows,
        figures.patched,
        figures.rays as f64 * 1e-6,
        point(1)
    );
    println!(
        "| old bake, unedited scene (the plan kept) | {old_seconds:.1} | - | - | - | - | {} |",
        point(2)
    );
    if let Some(why) = &figures.full {
        println!("(the incremental bake baked in full: {why})");
    }
    let csv = format!(
        "scene,node,edit,quality,old_seconds,full_seconds,incremental_seconds,rows,retraced,patched,flagged_rays,incremental_rays,full_rays,full_texels,full_point_rmse,incremental_point_rmse\n{stem},{node},{edit},{quality},{old_seconds:.2},{full_seconds:.2},{inc_seconds:.2},{},{},{},{},{},{},{},{},{}\n",
        figures.rows,
        figures.retraced,
        figures.patched,
        figures.flagged_rays,
        figures.rays,
        figures.full_rays,
        full_texels,
        errors.map_or(String::new(), |e| e[0].0.to_string()),
        errors.map_or(String::new(), |e| e[1].0.to_string()),
    );
    std::fs::write(out.join("incremental_figures.csv"), csv).expect("write the CSV");
}

/// Writes `scene` (a .glb) to `to` with its JSON and binary chunk changed by `edit` (which
/// may append to the binary chunk: buffer 0's `byteLength` follows it).
fn edit_glb(scene: &Path, to: &Path, edit: impl FnOnce(&mut Value, &mut Vec<u8>)) {
    let bytes = std::fs::read(scene).expect("read the scene");
    assert!(bytes.starts_with(b"glTF"), "a .glb scene");
    let json_len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    let mut json: Value = serde_json::from_slice(&bytes[20..20 + json_len]).expect("JSON");
    let rest = &bytes[20 + json_len..];
    let bin_len = u32::from_le_bytes(rest[0..4].try_into().unwrap()) as usize;
    assert_eq!(&rest[4..8], b"BIN\0", "a binary chunk after the JSON");
    let mut bin = rest[8..8 + bin_len].to_vec();
    edit(&mut json, &mut bin);
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    if bin.len() != bin_len {
        json["buffers"][0]["byteLength"] = serde_json::json!(bin.len());
    }
    let mut text = serde_json::to_vec(&json).unwrap();
    while !text.len().is_multiple_of(4) {
        text.push(b' ');
    }
    let mut glb = Vec::new();
    glb.extend(b"glTF");
    glb.extend(2u32.to_le_bytes());
    glb.extend(((12 + 8 + text.len() + 8 + bin.len()) as u32).to_le_bytes());
    glb.extend((text.len() as u32).to_le_bytes());
    glb.extend(b"JSON");
    glb.extend(&text);
    glb.extend((bin.len() as u32).to_le_bytes());
    glb.extend(b"BIN\0");
    glb.extend(&bin);
    std::fs::write(to, glb).expect("write the edited scene");
}

/// A closed box `size` wide standing on the floor at `at`, added as a new root node `name`:
/// its positions, normals and indices appended to the binary chunk `bin` (after the old
/// bytes, which stay where they were), three buffer views, three accessors and a mesh
/// appended, material `wood`.
fn add_box(json: &mut Value, bin: &mut Vec<u8>, name: &str, size: f32, at: [f32; 3]) {
    use serde_json::json;
    let h = size / 2.0;
    // (normal, a, b) with a × b = normal: counter-clockwise seen from outside.
    let faces: [([f32; 3], [f32; 3], [f32; 3]); 6] = [
        ([1., 0., 0.], [0., 1., 0.], [0., 0., 1.]),
        ([-1., 0., 0.], [0., 1., 0.], [0., 0., -1.]),
        ([0., 1., 0.], [0., 0., 1.], [1., 0., 0.]),
        ([0., -1., 0.], [1., 0., 0.], [0., 0., 1.]),
        ([0., 0., 1.], [1., 0., 0.], [0., 1., 0.]),
        ([0., 0., -1.], [0., 1., 0.], [1., 0., 0.]),
    ];
    let (mut pos, mut nor, mut idx) = (Vec::new(), Vec::new(), Vec::<u16>::new());
    for (n, a, b) in faces {
        let base = pos.len() as u16;
        for (s, t) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            let p: [f32; 3] =
                std::array::from_fn(|k| (n[k] + a[k] * s + b[k] * t) * h + [0.0, h, 0.0][k]);
            pos.push(p);
            nor.push(n);
        }
        idx.extend([base, base + 1, base + 2, base, base + 2, base + 3]);
    }
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let start = bin.len();
    pos.iter()
        .chain(&nor)
        .flatten()
        .for_each(|f| bin.extend(f.to_le_bytes()));
    idx.iter().for_each(|i| bin.extend(i.to_le_bytes()));
    let vlen = pos.len() * 12;
    let views = json["bufferViews"].as_array_mut().expect("bufferViews");
    let v0 = views.len();
    views.push(json!({"buffer": 0, "byteOffset": start, "byteLength": vlen}));
    views.push(json!({"buffer": 0, "byteOffset": start + vlen, "byteLength": vlen}));
    views.push(json!({"buffer": 0, "byteOffset": start + 2 * vlen, "byteLength": idx.len() * 2}));
    let accessors = json["accessors"].as_array_mut().expect("accessors");
    let a0 = accessors.len();
    accessors.push(
        json!({"bufferView": v0, "componentType": 5126, "count": pos.len(),
        "type": "VEC3", "min": [-h, 0.0, -h], "max": [h, size, h]}),
    );
    accessors.push(
        json!({"bufferView": v0 + 1, "componentType": 5126, "count": nor.len(), "type": "VEC3"}),
    );
    accessors.push(
        json!({"bufferView": v0 + 2, "componentType": 5123, "count": idx.len(), "type": "SCALAR"}),
    );
    let wood = (json["materials"].as_array().expect("materials").iter())
        .position(|m| m["name"] == "wood")
        .expect("a material `wood`");
    let meshes = json["meshes"].as_array_mut().expect("meshes");
    meshes.push(
        json!({"name": name, "primitives": [{"attributes": {"POSITION": a0, "NORMAL": a0 + 1},
        "indices": a0 + 2, "material": wood}]}),
    );
    let mesh = meshes.len() - 1;
    let nodes = json["nodes"].as_array_mut().expect("nodes");
    nodes.push(json!({"name": name, "mesh": mesh, "translation": at}));
    let node = nodes.len() - 1;
    json["scenes"][0]["nodes"]
        .as_array_mut()
        .expect("scene roots")
        .push(json!(node));
}

/// Node `node` moved by `dx` along x.
fn move_node(json: &mut Value, node: &str, dx: f32) {
    let nodes = json["nodes"].as_array_mut().expect("nodes");
    let n = nodes
        .iter_mut()
        .find(|n| n["name"] == node)
        .unwrap_or_else(|| panic!("no node {node}"));
    assert!(n.get("matrix").is_none(), "a node placed by TRS");
    let mut t: Vec<f64> = (n.get("translation").and_then(Value::as_array))
        .map(|a| a.iter().map(|v| v.as_f64().unwrap()).collect())
        .unwrap_or_else(|| vec![0.0; 3]);
    t[0] += f64::from(dx);
    n["translation"] = serde_json::json!(t);
}

/// Node `node` (a leaf) deleted: dropped from its parent's children or the scenes' roots, the
/// nodes after it renumbered, as an editor exports it.
fn remove_node(json: &mut Value, node: &str) {
    let nodes = json["nodes"].as_array_mut().expect("nodes");
    let k = nodes
        .iter()
        .position(|n| n["name"] == node)
        .unwrap_or_else(|| panic!("no node {node}"));
    assert!(nodes[k].get("children").is_none(), "a leaf node");
    nodes.remove(k);
    let renumber = |list: &mut Value| {
        if let Some(a) = list.as_array_mut() {
            a.retain(|i| i.as_u64() != Some(k as u64));
            for i in a.iter_mut() {
                let v = i.as_u64().unwrap();
                if v > k as u64 {
                    *i = serde_json::json!(v - 1);
                }
            }
        }
    };
    for n in json["nodes"].as_array_mut().unwrap() {
        if let Some(c) = n.get_mut("children") {
            renumber(c);
        }
    }
    for s in json["scenes"].as_array_mut().expect("scenes") {
        if let Some(roots) = s.get_mut("nodes") {
            renumber(roots);
        }
    }
}

/// The stored point reference at `csv`, or a new one of `input` stored there.
fn point_reference(input: &Path, csv: &Path) -> PointReference {
    if let Ok(text) = std::fs::read_to_string(csv) {
        return PointReference::from_csv(&text, csv).expect("point reference");
    }
    let config = BakeConfig::medium();
    let params = ReferenceParams {
        samples_per_pass: 32,
        max_samples: 2048,
        target_rel_error: Some(0.01),
        time_limit: Some(Duration::from_secs(300)),
        ..ReferenceParams::like(&config)
    };
    let t = Instant::now();
    let (reference, _) =
        points::compute(input, &config, &params, 1024, &NoProgress).expect("point reference");
    eprintln!("point reference: {:.1}s", t.elapsed().as_secs_f64());
    std::fs::write(csv, reference.to_csv()).expect("store the point reference");
    reference
}
