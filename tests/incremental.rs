//! Incremental re-bake (`bake --since`, `lightbake::incremental`).
//!
//! The yardstick of an incremental bake is the same bake with every row traced again on the
//! previous bake's layout and seeds (`Retrace::All`): a row the edit can change and the
//! incremental bake does not re-trace or patch shows up as a difference there. A fresh bake of
//! the edited scene (its own junction cuts, so its own atlas) agrees within noise.

use std::path::{Path, PathBuf};

use base64::Engine;
use glam::Vec3;
use lightbake::incremental::{Incremental, Retrace, Since, bake_since, compute_since};
use lightbake::{BakeConfig, Baked, NoProgress, bake, compute, kept};
use serde_json::{Value, json};

use crate::util::{fixture, list_files, quick, scratch};

fn kept_config() -> BakeConfig {
    let mut c = quick();
    c.output.keep_transport = true;
    c
}

/// A closed box `size` wide centred on x = z = 0, standing on y = 0 (24 vertices: flat
/// normals), as glTF accessors in a data-URI buffer appended to `doc`; returns its mesh index.
fn add_box(doc: &mut Value, size: f32, material: usize) -> usize {
    let h = size / 2.0;
    let faces: [(Vec3, Vec3, Vec3); 6] = [
        (Vec3::X, Vec3::Y, Vec3::Z),
        (Vec3::NEG_X, Vec3::Y, Vec3::NEG_Z),
        (Vec3::Y, Vec3::Z, Vec3::X),
        (Vec3::NEG_Y, Vec3::X, Vec3::Z),
        (Vec3::Z, Vec3::X, Vec3::Y),
        (Vec3::NEG_Z, Vec3::Y, Vec3::X),
    ];
    let (mut pos, mut nor, mut idx) = (Vec::new(), Vec::new(), Vec::<u16>::new());
    for (n, a, b) in faces {
        let base = pos.len() as u16;
        for (s, t) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            let p = n * h + a * (s * h) + b * (t * h) + Vec3::new(0.0, h, 0.0);
            pos.push(p);
            nor.push(n);
        }
        // Counter-clockwise seen from outside: a × b = n for every face above.
        idx.extend([base, base + 1, base + 2, base, base + 2, base + 3]);
    }
    let mut bytes = Vec::new();
    pos.iter()
        .chain(&nor)
        .flat_map(|v| v.to_array())
        .for_each(|f| bytes.extend(f.to_le_bytes()));
    idx.iter().for_each(|i| bytes.extend(i.to_le_bytes()));
    let uri = format!(
        "data:application/octet-stream;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(&bytes)
    );
    let buffers = doc["buffers"].as_array_mut().unwrap();
    buffers.push(json!({"uri": uri, "byteLength": bytes.len()}));
    let buffer = buffers.len() - 1;
    let views = doc["bufferViews"].as_array_mut().unwrap();
    let v0 = views.len();
    let vlen = pos.len() * 12;
    views.push(json!({"buffer": buffer, "byteOffset": 0, "byteLength": vlen}));
    views.push(json!({"buffer": buffer, "byteOffset": vlen, "byteLength": vlen}));
    views.push(json!({"buffer": buffer, "byteOffset": 2 * vlen, "byteLength": idx.len() * 2}));
    let accessors = doc["accessors"].as_array_mut().unwrap();
    let a0 = accessors.len();
    accessors.push(
        json!({"bufferView": v0, "componentType": 5126, "count": pos.len(), "type": "VEC3",
        "min": [-h, 0.0, -h], "max": [h, size, h]}),
    );
    accessors.push(
        json!({"bufferView": v0 + 1, "componentType": 5126, "count": nor.len(), "type": "VEC3"}),
    );
    accessors.push(
        json!({"bufferView": v0 + 2, "componentType": 5123, "count": idx.len(), "type": "SCALAR"}),
    );
    let meshes = doc["meshes"].as_array_mut().unwrap();
    meshes.push(
        json!({"name": "box", "primitives": [{"attributes": {"POSITION": a0, "NORMAL": a0 + 1},
        "indices": a0 + 2, "material": material}]}),
    );
    meshes.len() - 1
}

/// two_rooms.gltf with a 0.5 m box (node "box") standing at `x` (room A: x < 0, where the
/// panel is; room B: x > 0), written to `dir/two_rooms.gltf`.
fn two_rooms_with_box(dir: &Path, x: f32) -> PathBuf {
    let mut doc: Value =
        serde_json::from_slice(&std::fs::read(fixture("two_rooms.gltf")).unwrap()).unwrap();
    let mesh = add_box(&mut doc, 0.5, 2);
    let nodes = doc["nodes"].as_array_mut().unwrap();
    nodes.push(json!({"name": "box", "mesh": mesh, "translation": [x, 0.0, 0.0]}));
    let box_node = nodes.len() - 1;
    doc["scenes"][0]["nodes"]
        .as_array_mut()
        .unwrap()
        .push(json!(box_node));
    std::fs::create_dir_all(dir).unwrap();
    let path = dir.join("two_rooms.gltf");
    std::fs::write(&path, serde_json::to_vec_pretty(&doc).unwrap()).unwrap();
    path
}

/// Mean lightmap value (`H/π`, summed over RGB) of the upward-facing floor texels of `baked`
/// in room A (x < 0) and room B (x > 0), away from the partition.
fn room_floor_means(baked: &Baked) -> [f32; 2] {
    room_floor_means_but(baked, |_| false)
}

/// [`room_floor_means`] without the floor texels at which `skip` says yes.
fn room_floor_means_but(baked: &Baked, skip: impl Fn(Vec3) -> bool) -> [f32; 2] {
    let t = &baked.texels;
    let mut sums = [(0.0f64, 0usize); 2];
    for i in 0..t.len() {
        let (p, n) = (t.position[i], t.normal[i]);
        if p.y.abs() > 0.01 || n.y < 0.9 || p.x.abs() < 0.1 || skip(p) {
            continue;
        }
        let room = usize::from(p.x > 0.0);
        sums[room].0 += f64::from(baked.lightmap[i].element_sum());
        sums[room].1 += 1;
    }
    sums.map(|(s, n)| (s / n.max(1) as f64) as f32)
}

fn incremental(since: Since) -> (Baked, Incremental) {
    match since {
        Since::Incremental(baked, inc) => (*baked, inc),
        Since::Full(why) => panic!("baked in full: {why}"),
    }
}

/// Probes whose budget follows the bake, with few rays each, so that a small bake's rays afford
/// more than the least budget.
fn few_ray_probes() -> lightbake::probes::ProbeParams {
    lightbake::probes::ProbeParams {
        rays: 16,
        ..Default::default()
    }
}

/// Probes whose budget follows the bake keep the kept bake's budget when re-baked (the
/// incremental bake's own rays are those it re-traced: none here), so the probe file is the
/// same too. Few probe rays, so that this small bake's rays afford more than the least budget.
#[test]
fn probes_following_the_bake_rebake_to_the_same_bytes() {
    let dir = scratch();
    let input = two_rooms_with_box(&dir.path().join("in"), -1.0);
    let mut config = kept_config();
    config.transport.gather_rays = 256;
    config.output.probes = Some(few_ray_probes());
    let old = dir.path().join("old");
    let full = bake(&input, &old, &config, &NoProgress).unwrap();
    let budget = full.probes.expect("probes").budget;
    assert!(budget > lightbake::probes::DEFAULT_BUDGET, "{budget}");
    let new = dir.path().join("new");
    let since = old.join("two_rooms.gltf");
    let report = bake_since(&input, &since, &new, &config, &NoProgress).unwrap();
    let inc = report.incremental.expect("an incremental report");
    assert_eq!((inc.retraced, inc.patched), (0, 0), "{}", inc.brief());
    assert_eq!(report.probes.expect("probes").budget, budget);
    let probes = "two_rooms_probes.json";
    let read = |d: &Path| std::fs::read(d.join(probes)).unwrap();
    assert!(
        read(&old) == read(&new),
        "{probes} differs from the previous bake's"
    );
}

/// Probes asked of an incremental bake whose kept bake had none: the budget follows what a full
/// trace's rays afford (this bake re-traces nothing, so its own rays would give the least
/// budget), the budget a full bake with probes chooses.
#[test]
fn probes_new_to_an_incremental_bake_follow_a_full_trace() {
    let dir = scratch();
    let input = two_rooms_with_box(&dir.path().join("in"), -1.0);
    let mut config = kept_config();
    config.transport.gather_rays = 256;
    let old = dir.path().join("old");
    let kept = bake(&input, &old, &config, &NoProgress).unwrap();
    assert!(kept.probes.is_none());
    config.output.probes = Some(few_ray_probes());
    let full = bake(&input, &dir.path().join("full"), &config, &NoProgress).unwrap();
    let budget = full.probes.expect("probes").budget;
    assert!(budget > lightbake::probes::DEFAULT_BUDGET, "{budget}");
    let since = old.join("two_rooms.gltf");
    let report = bake_since(
        &input,
        &since,
        &dir.path().join("new"),
        &config,
        &NoProgress,
    )
    .unwrap();
    let inc = report.incremental.expect("an incremental report");
    assert_eq!((inc.retraced, inc.patched), (0, 0), "{}", inc.brief());
    assert_eq!(report.probes.expect("probes").budget, budget);
}

#[test]
fn an_unmoved_scene_rebakes_to_the_same_bytes() {
    let dir = scratch();
    let input = two_rooms_with_box(&dir.path().join("in"), -1.0);
    let config = kept_config();
    let old = dir.path().join("old");
    bake(&input, &old, &config, &NoProgress).unwrap();
    let new = dir.path().join("new");
    let report = bake_since(
        &input,
        &old.join("two_rooms.gltf"),
        &new,
        &config,
        &NoProgress,
    )
    .unwrap();
    let inc = report.incremental.expect("an incremental report");
    assert_eq!(inc.full, None);
    assert!(inc.moved_nodes.is_empty());
    assert_eq!((inc.retraced, inc.patched), (0, 0), "{}", inc.brief());
    let files = list_files(&old);
    assert_eq!(files, list_files(&new));
    assert!(files.iter().any(|f| f.ends_with(".exr")));
    for f in &files {
        let (a, b) = (
            std::fs::read(old.join(f)).unwrap(),
            std::fs::read(new.join(f)).unwrap(),
        );
        assert!(a == b, "{f} differs from the previous bake's");
    }
}

#[test]
fn a_box_moved_between_rooms_relights_both_as_a_full_retrace_does() {
    let dir = scratch();
    let config = kept_config();
    let before = two_rooms_with_box(&dir.path().join("before"), -1.0);
    let old = dir.path().join("old");
    bake(&before, &old, &config, &NoProgress).unwrap();
    let since = old.join("two_rooms.gltf");
    let old_baked = compute(&before, &config, &NoProgress).unwrap();
    let after = two_rooms_with_box(&dir.path().join("after"), 1.0);

    let (inc_baked, inc) =
        incremental(compute_since(&after, &since, &config, Retrace::Edited, &NoProgress).unwrap());
    let (all_baked, all) =
        incremental(compute_since(&after, &since, &config, Retrace::All, &NoProgress).unwrap());
    assert_eq!(all.retraced, all.rows);
    assert_eq!(inc.moved_nodes.len(), 1, "{}", inc.brief());
    // The validity pass ran only near the box, where it was and where it is: the texels are
    // those of the full pass the yardstick ran, bit for bit.
    let bits = |t: &lightbake::texels::Texels| -> (Vec<[u32; 3]>, Vec<u32>, Vec<u32>) {
        (
            t.position
                .iter()
                .map(|p| p.to_array().map(f32::to_bits))
                .collect(),
            t.jitter.iter().map(|j| j.to_bits()).collect(),
            t.invalid.clone(),
        )
    };
    assert!(
        bits(&inc_baked.texels) == bits(&all_baked.texels),
        "the validity pass near the box differs from a full one"
    );
    assert!(inc.retraced > 0 && inc.patched > 0, "{}", inc.brief());
    // The box is a large object in a small scene: most rows have a ray through its bounds
    // and are patched, but few are traced whole and fewer rays are cast than by a full trace.
    assert!(
        inc.retraced < inc.rows / 4 && inc.rays < inc.full_rays,
        "{}",
        inc.brief()
    );

    // Rows on both sides of the partition were traced again or patched.
    let t = &inc_baked.texels;
    let sides = inc.touched_rows.iter().fold([0, 0], |mut s, &i| {
        let x = t.position[i as usize].x;
        if x.abs() > 0.05 {
            s[usize::from(x > 0.0)] += 1;
        }
        s
    });
    assert!(
        sides[0] > 0 && sides[1] > 0,
        "touched rows per room: {sides:?}"
    );

    // Same rows and seeds as tracing every row again: the same light, to float rounding. A row
    // the edit changed and the incremental bake kept would differ by at least one ray's share.
    assert_eq!(inc_baked.lightmap.len(), all_baked.lightmap.len());
    let mut worst = 0.0f32;
    for (a, b) in inc_baked.lightmap.iter().zip(&all_baked.lightmap) {
        let d = (*a - *b).abs().max_element() / (b.max_element() + 1e-3);
        worst = worst.max(d);
    }
    assert!(
        worst < 1e-4,
        "incremental vs every row re-traced: worst relative texel difference {worst:.2e}"
    );

    // Both rooms' floors changed, as in a fresh bake of the edited scene (its own cuts and
    // atlas, the same fixed settings): within that bake's noise.
    let fixed = kept::read(&since).unwrap().settings.config().unwrap();
    let fresh = compute(&after, &fixed, &NoProgress).unwrap();
    let [old_a, old_b] = room_floor_means(&old_baked);
    let [inc_a, inc_b] = room_floor_means(&inc_baked);
    let [fresh_a, fresh_b] = room_floor_means(&fresh);
    let change = |from: f32, to: f32| (to - from) / from;
    for (room, old, inc, fresh) in [("A", old_a, inc_a, fresh_a), ("B", old_b, inc_b, fresh_b)] {
        assert!(
            change(old, inc).abs() > 0.02,
            "room {room}: floor mean {old} before, {inc} after the move: unchanged"
        );
        assert!(
            (change(old, inc) - change(old, fresh)).abs() < 0.25 * change(old, fresh).abs(),
            "room {room}: floor mean {old} before; incremental {inc}, fresh {fresh}"
        );
    }
}

#[test]
fn an_edit_beyond_moves_bakes_in_full_and_says_why() {
    let dir = scratch();
    let config = kept_config();
    let input = two_rooms_with_box(&dir.path().join("in"), -1.0);
    let old = dir.path().join("old");
    bake(&input, &old, &config, &NoProgress).unwrap();
    // A material edit: not a move.
    let mut doc: Value = serde_json::from_slice(&std::fs::read(&input).unwrap()).unwrap();
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorFactor"] = json!([0.3, 0.3, 0.3, 1.0]);
    std::fs::write(&input, serde_json::to_vec(&doc).unwrap()).unwrap();
    let report = bake_since(
        &input,
        &old.join("two_rooms.gltf"),
        &dir.path().join("new"),
        &config,
        &NoProgress,
    )
    .unwrap();
    let why = report.incremental.unwrap().full.expect("a full bake");
    assert!(why.contains("more than node transforms"), "{why}");
}

#[test]
fn a_version_1_transport_is_refused_with_advice() {
    let dir = scratch();
    let config = kept_config();
    let old = dir.path().join("old");
    bake(&fixture("two_rooms.gltf"), &old, &config, &NoProgress).unwrap();
    let path = old.join("two_rooms.transport");
    let mut bytes = std::fs::read(&path).unwrap();
    bytes[20..24].copy_from_slice(&1u32.to_le_bytes());
    std::fs::write(&path, &bytes).unwrap();
    let err = kept::read(&old.join("two_rooms.gltf"))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("version 1") && err.contains("--keep-transport"),
        "{err}"
    );
}

#[test]
fn build_rebakes_a_moved_node_incrementally_and_says_so() {
    use lightbake::build;
    use lightbake::build::Status;
    let dir = scratch();
    let levels = dir.path().join("levels");
    two_rooms_with_box(&levels, -1.0);
    let load = draft_manifest(dir.path());
    let first = build(&load(), &NoProgress);
    assert_eq!(first.scenes[0].status, Status::Baked, "{first:?}");

    two_rooms_with_box(&levels, 1.0);
    let second = build(&load(), &NoProgress);
    let scene = &second.scenes[0];
    assert_eq!(scene.status, Status::Incremental, "{second:?}");
    let figures = scene.incremental.as_ref().expect("incremental figures");
    assert!(figures.retraced > 0 && figures.retraced + figures.patched < figures.rows);
    // The report still matches its schema.
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("src/build/report.schema.json");
    let schema: Value = serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap();
    let report: Value = serde_json::from_str(&second.to_json()).unwrap();
    let validator = jsonschema::validator_for(&schema).unwrap();
    assert!(validator.is_valid(&report), "{report}");

    // Moved again: incremental from the incremental bake's outputs.
    two_rooms_with_box(&levels, 1.4);
    let third = build(&load(), &NoProgress);
    assert_eq!(third.scenes[0].status, Status::Incremental, "{third:?}");

    // The record written after an incremental bake vouches for its outputs.
    let fourth = build(&load(), &NoProgress);
    assert_eq!(fourth.scenes[0].status, Status::Skipped, "{fourth:?}");
}

#[test]
fn an_incremental_bake_starts_from_an_incremental_bake() {
    let dir = scratch();
    let config = kept_config();
    let first = dir.path().join("first");
    bake(
        &two_rooms_with_box(&dir.path().join("a"), -1.0),
        &first,
        &config,
        &NoProgress,
    )
    .unwrap();
    // Moved once: the second bake keeps the first one's layout and records it.
    let second = dir.path().join("second");
    let moved = two_rooms_with_box(&dir.path().join("b"), 1.0);
    let report = bake_since(
        &moved,
        &first.join("two_rooms.gltf"),
        &second,
        &config,
        &NoProgress,
    )
    .unwrap();
    assert_eq!(report.incremental.unwrap().full, None);
    // Moved again, from the incremental bake: still incremental, and as a full re-trace.
    let again = two_rooms_with_box(&dir.path().join("c"), 1.4);
    let since = second.join("two_rooms.gltf");
    let (inc_baked, inc) =
        incremental(compute_since(&again, &since, &config, Retrace::Edited, &NoProgress).unwrap());
    let (all_baked, _) =
        incremental(compute_since(&again, &since, &config, Retrace::All, &NoProgress).unwrap());
    assert!(
        inc.retraced > 0 && inc.retraced < inc.rows / 4,
        "{}",
        inc.brief()
    );
    let worst = (inc_baked.lightmap.iter().zip(&all_baked.lightmap))
        .map(|(a, b)| (*a - *b).abs().max_element() / (b.max_element() + 1e-3))
        .fold(0.0f32, f32::max);
    assert!(worst < 1e-4, "worst relative texel difference {worst:.2e}");
}

#[test]
fn cli_bake_since_says_incremental() {
    let dir = scratch();
    let before = two_rooms_with_box(&dir.path().join("a"), -1.0);
    let old = dir.path().join("old");
    let bin = env!("CARGO_BIN_EXE_lightbake");
    let run = |args: &[&std::ffi::OsStr]| {
        let out = std::process::Command::new(bin).args(args).output().unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8(out.stdout).unwrap()
    };
    let os = |s: &str| std::ffi::OsString::from(s);
    run(&[
        &os("bake"),
        before.as_os_str(),
        &os("-o"),
        old.as_os_str(),
        &os("--quality"),
        &os("draft"),
        &os("--keep-transport"),
    ]);
    let after = two_rooms_with_box(&dir.path().join("b"), 1.0);
    let since = old.join("two_rooms.gltf");
    let new = dir.path().join("new");
    let stdout = run(&[
        &os("bake"),
        after.as_os_str(),
        &os("-o"),
        new.as_os_str(),
        &os("--since"),
        since.as_os_str(),
    ]);
    assert!(
        stdout.contains("incremental: 1 node(s) moved") && stdout.contains("rows re-traced"),
        "{stdout}"
    );
    assert!(new.join("two_rooms_lightmap0.exr").exists());
}

/// two_rooms.gltf with the box mesh of [`two_rooms_with_box`] and, when `x` is given, its node
/// ("box") *first* among the nodes (every other node's index one up: a removal renumbers
/// A draft manifest in `dir` keeping the transport of `levels/two_rooms.gltf` (baked to
/// `baked`), and how to load it again.
fn draft_manifest(dir: &Path) -> impl Fn() -> lightbake::Manifest {
    let manifest = "[defaults]\nquality = \"draft\"\ntexels-per-unit = 8\nkeep-transport = true\n\n\
                    [[scene]]\npath = \"levels/two_rooms.gltf\"\noutput = \"baked\"\n";
    let path = dir.join("lightbake.toml");
    std::fs::write(&path, manifest).unwrap();
    move || lightbake::Manifest::load(&path).unwrap()
}

/// them), standing at `x`; without `x`, the same document with the box node deleted.
fn two_rooms_box_first(dir: &Path, x: Option<f32>) -> PathBuf {
    let path = two_rooms_with_box(dir, x.unwrap_or(0.0));
    let mut doc: Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    let nodes = doc["nodes"].as_array_mut().unwrap();
    let node = nodes.pop().unwrap();
    let box_index = nodes.len() as u64;
    let shift = |v: &mut Value| *v = json!(v.as_u64().unwrap() + 1);
    if x.is_some() {
        for n in nodes.iter_mut() {
            n.get_mut("children")
                .and_then(Value::as_array_mut)
                .into_iter()
                .flatten()
                .for_each(shift);
        }
        nodes.insert(0, node);
    }
    let roots = doc["scenes"][0]["nodes"].as_array_mut().unwrap();
    roots.retain(|r| r.as_u64() != Some(box_index));
    if x.is_some() {
        roots.iter_mut().for_each(shift);
        roots.push(json!(0));
    }
    std::fs::write(&path, serde_json::to_vec_pretty(&doc).unwrap()).unwrap();
    path
}

#[test]
fn a_removed_box_relights_its_room_as_a_full_retrace_does() {
    let dir = scratch();
    let config = kept_config();
    let before = two_rooms_box_first(&dir.path().join("before"), Some(1.0));
    let old = dir.path().join("old");
    bake(&before, &old, &config, &NoProgress).unwrap();
    let since = old.join("two_rooms.gltf");
    let old_baked = compute(&before, &config, &NoProgress).unwrap();
    let after = two_rooms_box_first(&dir.path().join("after"), None);

    let (inc_baked, inc) =
        incremental(compute_since(&after, &since, &config, Retrace::Edited, &NoProgress).unwrap());
    let (all_baked, all) =
        incremental(compute_since(&after, &since, &config, Retrace::All, &NoProgress).unwrap());
    assert_eq!(inc.removed_nodes, vec![0], "{}", inc.brief());
    assert!(inc.moved_nodes.is_empty(), "{}", inc.brief());
    // Nothing moved: no row is traced whole; rows whose rays met the box are patched.
    assert!(inc.patched > 0 && inc.rays < all.rays, "{}", inc.brief());

    // The box's texels keep their places, unused: invalid, black, their rows empty.
    let t = &inc_baked.texels;
    let on_box = |p: Vec3, n: Vec3| {
        let inside = (p - Vec3::new(1.0, 0.25, 0.0)).abs().max_element() < 0.27;
        inside && !(n.y > 0.9 && p.y < 0.01) // the floor under it
    };
    let gone: Vec<usize> = (0..t.len())
        .filter(|&i| on_box(t.position[i], t.normal[i]))
        .collect();
    assert!(!gone.is_empty());
    let valid = t.valid_mask();
    for &i in &gone {
        assert!(!valid[i], "removed texel {i} valid");
        assert_eq!(
            inc_baked.transport.row(i).count(),
            0,
            "removed texel {i}'s row"
        );
    }

    // As every row traced again on the same layout, to float rounding.
    let worst = (inc_baked.lightmap.iter().zip(&all_baked.lightmap))
        .map(|(a, b)| (*a - *b).abs().max_element() / (b.max_element() + 1e-3))
        .fold(0.0f32, f32::max);
    assert!(worst < 1e-4, "worst relative texel difference {worst:.2e}");

    // The box stood in room B: its floor is lit where the box shadowed it, as in a fresh bake
    // of the edited scene (its own cuts and atlas, the same settings).
    // The floor around the box, not under it: the fresh bake cuts the floor along the box's
    // footprint, the incremental one keeps the old floor's texels (the validity pass moves
    // the sample points of those the box covers in part), so the two differ there by layout.
    let fixed = kept::read(&since).unwrap().settings.config().unwrap();
    let fresh = compute(&after, &fixed, &NoProgress).unwrap();
    let under = |p: Vec3| p.x.abs() < 0.45 && p.z.abs() < 0.45;
    let [old_a, old_b] = room_floor_means_but(&old_baked, under);
    let [inc_a, inc_b] = room_floor_means_but(&inc_baked, under);
    let [fresh_a, fresh_b] = room_floor_means_but(&fresh, under);
    let change = |from: f32, to: f32| (to - from) / from;
    eprintln!(
        "floor changes: A {} (fresh {}), B {} (fresh {})",
        change(old_a, inc_a),
        change(old_a, fresh_a),
        change(old_b, inc_b),
        change(old_b, fresh_b)
    );
    assert!(
        change(old_b, inc_b) > 0.02,
        "room B: floor mean {old_b} before, {inc_b} after the removal: not brighter"
    );
    assert!(
        (change(old_b, inc_b) - change(old_b, fresh_b)).abs() < 0.25 * change(old_b, fresh_b),
        "room B: floor mean {old_b} before; incremental {inc_b}, fresh {fresh_b}"
    );
    // Room A sees little of the box (through the doorway): as little change as the fresh
    // bake shows, within a percent.
    assert!(
        (change(old_a, inc_a) - change(old_a, fresh_a)).abs() < 0.01,
        "room A: floor mean {old_a} before; incremental {inc_a}, fresh {fresh_a}"
    );

    // Written: the input's nodes (one fewer), every primitive with its lightmap; and the next
    // bake from this one bakes in full, saying why (its layout holds the removed node).
    let new = dir.path().join("new");
    let report = bake_since(&after, &since, &new, &config, &NoProgress).unwrap();
    assert_eq!(report.incremental.as_ref().unwrap().full, None);
    let out: Value =
        serde_json::from_slice(&std::fs::read(new.join("two_rooms.gltf")).unwrap()).unwrap();
    let input: Value = serde_json::from_slice(&std::fs::read(&after).unwrap()).unwrap();
    assert_eq!(
        out["nodes"].as_array().unwrap().len(),
        input["nodes"].as_array().unwrap().len()
    );
    let baked = lightbake::scene::load(&new.join("two_rooms.gltf"))
        .unwrap()
        .0;
    assert!(baked.instances.iter().all(|i| i.lightmap.is_some()));
    let report = bake_since(
        &after,
        &new.join("two_rooms.gltf"),
        &dir.path().join("next"),
        &config,
        &NoProgress,
    )
    .unwrap();
    let why = report.incremental.unwrap().full.expect("a full bake");
    assert!(why.contains("removal"), "{why}");
}

#[test]
fn build_rebakes_a_removed_node_incrementally_and_says_so() {
    use lightbake::build;
    use lightbake::build::Status;
    let dir = scratch();
    let levels = dir.path().join("levels");
    two_rooms_box_first(&levels, Some(1.0));
    let load = draft_manifest(dir.path());
    let first = build(&load(), &NoProgress);
    assert_eq!(first.scenes[0].status, Status::Baked, "{first:?}");

    two_rooms_box_first(&levels, None);
    let second = build(&load(), &NoProgress);
    let scene = &second.scenes[0];
    assert_eq!(scene.status, Status::Incremental, "{second:?}");
    let figures = scene.incremental.as_ref().expect("incremental figures");
    assert!(figures.patched > 0 && figures.retraced + figures.patched < figures.rows);
    let fourth = build(&load(), &NoProgress);
    assert_eq!(fourth.scenes[0].status, Status::Skipped, "{fourth:?}");
}

#[test]
fn a_removal_and_a_move_in_one_edit_match_a_full_retrace() {
    // Two boxes: node 0 in room B, the last node in room A at `x`; `first` keeps node 0.
    let scene = |dir: &Path, first: bool, x: f32| {
        let path = two_rooms_box_first(dir, first.then_some(1.0));
        let mut doc: Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
        let mesh = doc["meshes"].as_array().unwrap().len() - 1;
        let nodes = doc["nodes"].as_array_mut().unwrap();
        nodes.push(json!({"name": "box A", "mesh": mesh, "translation": [x, 0.0, 0.0]}));
        let last = nodes.len() - 1;
        doc["scenes"][0]["nodes"]
            .as_array_mut()
            .unwrap()
            .push(json!(last));
        std::fs::write(&path, serde_json::to_vec_pretty(&doc).unwrap()).unwrap();
        path
    };
    let dir = scratch();
    let config = kept_config();
    let old = dir.path().join("old");
    bake(
        &scene(&dir.path().join("a"), true, -1.0),
        &old,
        &config,
        &NoProgress,
    )
    .unwrap();
    let since = old.join("two_rooms.gltf");
    let after = scene(&dir.path().join("b"), false, -1.5);
    let (inc_baked, inc) =
        incremental(compute_since(&after, &since, &config, Retrace::Edited, &NoProgress).unwrap());
    let (all_baked, _) =
        incremental(compute_since(&after, &since, &config, Retrace::All, &NoProgress).unwrap());
    assert_eq!(inc.removed_nodes, vec![0], "{}", inc.brief());
    assert_eq!(inc.moved_nodes.len(), 1, "{}", inc.brief());
    assert!(inc.retraced > 0 && inc.patched > 0, "{}", inc.brief());
    let worst = (inc_baked.lightmap.iter().zip(&all_baked.lightmap))
        .map(|(a, b)| (*a - *b).abs().max_element() / (b.max_element() + 1e-3))
        .fold(0.0f32, f32::max);
    assert!(worst < 1e-4, "worst relative texel difference {worst:.2e}");
}

/// two_rooms.gltf with, for each `(x, size)`, a box of that size standing at `x` (its own mesh,
/// appended to the document as an editor appends it), written to `dir/two_rooms.gltf`.
fn two_rooms_with_boxes(dir: &Path, boxes: &[(f32, f32)]) -> PathBuf {
    let mut doc: Value =
        serde_json::from_slice(&std::fs::read(fixture("two_rooms.gltf")).unwrap()).unwrap();
    for (k, &(x, size)) in boxes.iter().enumerate() {
        let mesh = add_box(&mut doc, size, 2);
        let nodes = doc["nodes"].as_array_mut().unwrap();
        nodes.push(
            json!({"name": format!("added {k}"), "mesh": mesh, "translation": [x, 0.0, 0.0]}),
        );
        let node = nodes.len() - 1;
        doc["scenes"][0]["nodes"]
            .as_array_mut()
            .unwrap()
            .push(json!(node));
    }
    std::fs::create_dir_all(dir).unwrap();
    let path = dir.join("two_rooms.gltf");
    std::fs::write(&path, serde_json::to_vec_pretty(&doc).unwrap()).unwrap();
    path
}

/// The worst texel of `a` against `b`, relative.
fn worst_difference(a: &Baked, b: &Baked) -> f32 {
    assert_eq!(a.lightmap.len(), b.lightmap.len());
    (a.lightmap.iter().zip(&b.lightmap))
        .map(|(a, b)| (*a - *b).abs().max_element() / (b.max_element() + 1e-3))
        .fold(0.0f32, f32::max)
}

#[test]
fn an_added_box_bakes_as_a_full_retrace_of_the_same_layout() {
    let dir = scratch();
    let config = kept_config();
    let before = two_rooms_with_boxes(&dir.path().join("before"), &[]);
    let old = dir.path().join("old");
    bake(&before, &old, &config, &NoProgress).unwrap();
    let since = old.join("two_rooms.gltf");
    let old_baked = compute(&before, &config, &NoProgress).unwrap();
    // A box in room B: a mesh, accessors and a buffer of its own, appended.
    let after = two_rooms_with_boxes(&dir.path().join("after"), &[(1.0, 0.5)]);

    let (inc_baked, inc) =
        incremental(compute_since(&after, &since, &config, Retrace::Edited, &NoProgress).unwrap());
    let (all_baked, _) =
        incremental(compute_since(&after, &since, &config, Retrace::All, &NoProgress).unwrap());
    assert_eq!(inc.added_nodes, vec![5], "{}", inc.brief());
    assert!(inc.moved_nodes.is_empty() && inc.removed_nodes.is_empty());
    assert!(inc.brief().contains("1 added"), "{}", inc.brief());

    // Every old texel kept its id, page and place; the box's texels come after, on pages of
    // their own.
    let (t_old, t) = (&old_baked.texels, &inc_baked.texels);
    let n_old = t_old.len();
    assert!(t.len() > n_old);
    assert_eq!(t.page[..n_old], t_old.page[..]);
    assert_eq!(t.xy[..n_old], t_old.xy[..]);
    let old_pages = old_baked.pages.pages.len() as u32;
    assert!((n_old..t.len()).all(|i| t.page[i] >= old_pages));
    // The box's rows traced whole, some old rows patched, far fewer rays than a full trace.
    assert!(inc.retraced >= t.len() - n_old, "{}", inc.brief());
    assert!(
        inc.patched > 0 && inc.rays < inc.full_rays / 2,
        "{}",
        inc.brief()
    );

    // As every row traced again on the same layout and seeds, to float rounding.
    let worst = worst_difference(&inc_baked, &all_baked);
    assert!(worst < 1e-4, "worst relative texel difference {worst:.2e}");

    // The box shades room B's floor, as in a fresh bake of the edited scene.
    let fixed = kept::read(&since).unwrap().settings.config().unwrap();
    let fresh = compute(&after, &fixed, &NoProgress).unwrap();
    let [_, old_b] = room_floor_means(&old_baked);
    let [_, inc_b] = room_floor_means(&inc_baked);
    let [_, fresh_b] = room_floor_means(&fresh);
    let change = |from: f32, to: f32| (to - from) / from;
    assert!(
        change(old_b, inc_b) < -0.02,
        "room B: floor mean {old_b} before, {inc_b} after the addition: not darker"
    );
    assert!(
        (change(old_b, inc_b) - change(old_b, fresh_b)).abs() < 0.25 * change(old_b, fresh_b).abs(),
        "room B: floor mean {old_b} before; incremental {inc_b}, fresh {fresh_b}"
    );

    // Written: the input's nodes, every primitive (the box's too) with its lightmap on a page
    // written; the next bake from this one bakes in full, saying why.
    let new = dir.path().join("new");
    let report = bake_since(&after, &since, &new, &config, &NoProgress).unwrap();
    assert_eq!(report.incremental.as_ref().unwrap().full, None);
    assert_eq!(report.pages, inc_baked.atlas.pages.len());
    let baked = lightbake::scene::load(&new.join("two_rooms.gltf"))
        .unwrap()
        .0;
    assert_eq!(baked.instances.len(), inc_baked.scene.instances.len());
    assert!(
        baked
            .instances
            .iter()
            .all(|i| i.lightmap.as_ref().is_some_and(|p| p.exists()))
    );
    let report = bake_since(
        &after,
        &new.join("two_rooms.gltf"),
        &dir.path().join("next"),
        &config,
        &NoProgress,
    )
    .unwrap();
    let why = report.incremental.unwrap().full.expect("a full bake");
    assert!(why.contains("addition"), "{why}");
}

#[test]
fn an_occluder_added_in_the_doorway_relights_both_rooms_as_a_full_bake_does() {
    let dir = scratch();
    let config = kept_config();
    let before = two_rooms_with_boxes(&dir.path().join("before"), &[]);
    let old = dir.path().join("old");
    bake(&before, &old, &config, &NoProgress).unwrap();
    let since = old.join("two_rooms.gltf");
    let old_baked = compute(&before, &config, &NoProgress).unwrap();
    // A 0.7 m box astride the doorway (z ∈ [−0.4, 0.4], 1.6 m high), clear of the wall.
    let after = two_rooms_with_boxes(&dir.path().join("after"), &[(0.0, 0.7)]);
    let (inc_baked, inc) =
        incremental(compute_since(&after, &since, &config, Retrace::Edited, &NoProgress).unwrap());
    let (all_baked, _) =
        incremental(compute_since(&after, &since, &config, Retrace::All, &NoProgress).unwrap());
    assert_eq!(inc.added_nodes.len(), 1, "{}", inc.brief());
    let worst = worst_difference(&inc_baked, &all_baked);
    assert!(worst < 1e-4, "worst relative texel difference {worst:.2e}");
    // Rows on both sides of the partition were patched or traced again.
    let t = &inc_baked.texels;
    let sides = inc.touched_rows.iter().fold([0, 0], |mut s, &i| {
        let x = t.position[i as usize].x;
        if x.abs() > 0.5 {
            s[usize::from(x > 0.0)] += 1;
        }
        s
    });
    assert!(
        sides[0] > 0 && sides[1] > 0,
        "touched rows per room: {sides:?}"
    );

    // The floor around the box, not under it: the fresh bake cuts the floor along the box's
    // footprint, the incremental one keeps the old floor's texels (the validity pass moves
    // the sample points of those the box covers in part), so the two differ there by layout.
    let fixed = kept::read(&since).unwrap().settings.config().unwrap();
    let fresh = compute(&after, &fixed, &NoProgress).unwrap();
    let under = |p: Vec3| p.x.abs() < 0.45 && p.z.abs() < 0.45;
    let [old_a, old_b] = room_floor_means_but(&old_baked, under);
    let [inc_a, inc_b] = room_floor_means_but(&inc_baked, under);
    let [fresh_a, fresh_b] = room_floor_means_but(&fresh, under);
    let change = |from: f32, to: f32| (to - from) / from;
    eprintln!(
        "floor changes: A {} (fresh {}), B {} (fresh {})",
        change(old_a, inc_a),
        change(old_a, fresh_a),
        change(old_b, inc_b),
        change(old_b, fresh_b)
    );
    for (room, old, inc, fresh) in [("A", old_a, inc_a, fresh_a), ("B", old_b, inc_b, fresh_b)] {
        assert!(
            change(old, inc).abs() > 0.02,
            "room {room}: floor mean {old} before, {inc} after the addition: unchanged"
        );
        assert!(
            (change(old, inc) - change(old, fresh)).abs() < 0.25 * change(old, fresh).abs(),
            "room {room}: floor mean {old} before; incremental {inc}, fresh {fresh}"
        );
    }
}

#[test]
fn an_addition_and_a_move_in_one_edit_match_a_full_retrace() {
    let dir = scratch();
    let config = kept_config();
    let old = dir.path().join("old");
    bake(
        &two_rooms_with_box(&dir.path().join("a"), -1.0),
        &old,
        &config,
        &NoProgress,
    )
    .unwrap();
    let since = old.join("two_rooms.gltf");
    // The box moved in room A, and a second node placing the same mesh added in room B (the
    // document's content unchanged: only the node graph grew).
    let after = two_rooms_with_box(&dir.path().join("b"), -1.5);
    let mut doc: Value = serde_json::from_slice(&std::fs::read(&after).unwrap()).unwrap();
    let mesh = doc["meshes"].as_array().unwrap().len() - 1;
    let nodes = doc["nodes"].as_array_mut().unwrap();
    nodes.push(json!({"name": "box B", "mesh": mesh, "translation": [1.0, 0.0, 0.3]}));
    let last = nodes.len() - 1;
    doc["scenes"][0]["nodes"]
        .as_array_mut()
        .unwrap()
        .push(json!(last));
    std::fs::write(&after, serde_json::to_vec_pretty(&doc).unwrap()).unwrap();

    let (inc_baked, inc) =
        incremental(compute_since(&after, &since, &config, Retrace::Edited, &NoProgress).unwrap());
    let (all_baked, _) =
        incremental(compute_since(&after, &since, &config, Retrace::All, &NoProgress).unwrap());
    assert_eq!(inc.moved_nodes, vec![5], "{}", inc.brief());
    assert_eq!(inc.added_nodes, vec![6], "{}", inc.brief());
    assert!(inc.retraced > 0 && inc.patched > 0, "{}", inc.brief());
    let worst = worst_difference(&inc_baked, &all_baked);
    assert!(worst < 1e-4, "worst relative texel difference {worst:.2e}");
}

#[test]
fn build_rebakes_an_added_node_incrementally_and_says_so() {
    use lightbake::build;
    use lightbake::build::Status;
    let dir = scratch();
    let levels = dir.path().join("levels");
    two_rooms_with_boxes(&levels, &[]);
    let load = draft_manifest(dir.path());
    let first = build(&load(), &NoProgress);
    assert_eq!(first.scenes[0].status, Status::Baked, "{first:?}");

    two_rooms_with_boxes(&levels, &[(1.0, 0.5)]);
    let second = build(&load(), &NoProgress);
    let scene = &second.scenes[0];
    assert_eq!(scene.status, Status::Incremental, "{second:?}");
    let figures = scene.incremental.as_ref().expect("incremental figures");
    assert!(figures.retraced > 0 && figures.retraced + figures.patched < figures.rows);
    let third = build(&load(), &NoProgress);
    assert_eq!(third.scenes[0].status, Status::Skipped, "{third:?}");
}
