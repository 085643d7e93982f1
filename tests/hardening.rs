//! Bad input (issue 14): one regression test per case found by malformed files and a mutation
//! fuzzer. Each builds its input from an ordinary scene, edited, and runs the `lightbake` binary:
//! refused input gets an error naming the file and the element, an exit code that is neither 0
//! nor 101 (a panic), and leaves no output behind; input that can still be baked gets a warning.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use glam::{Quat, Vec3};
use lightbake::testing::Face;
use lightbake::trace::Tracer;
use serde_json::{Value, json};

use crate::util::{fixture, grey_floor, list_files, scratch};

/// A scene to edit: the point-light floor (mesh 0 'floor', 81 vertices, light 0, material 0),
/// its JSON and its external buffer `scene.bin`.
struct Case {
    json: Value,
    bin: Vec<u8>,
}

impl Case {
    fn floor() -> Case {
        let (mut json, bin) = lightbake::testing::point_light_floor(10.0, 2.0).to_gltf_json();
        json["buffers"][0]["uri"] = json!("scene.bin");
        Case { json, bin }
    }

    /// The first primitive of mesh 0.
    fn primitive(&mut self) -> &mut Value {
        &mut self.json["meshes"][0]["primitives"][0]
    }

    /// Byte offset in `scene.bin` of element `k` of the primitive's attribute `name` (a tightly
    /// packed float VEC3).
    fn vec3_offset(&self, name: &str, k: usize) -> usize {
        let json = &self.json;
        let accessor = &json["accessors"][json["meshes"][0]["primitives"][0]["attributes"][name]
            .as_u64()
            .unwrap() as usize];
        let view = &json["bufferViews"][accessor["bufferView"].as_u64().unwrap() as usize];
        let base =
            view["byteOffset"].as_u64().unwrap_or(0) + accessor["byteOffset"].as_u64().unwrap_or(0);
        base as usize + 12 * k
    }

    fn set_vec3(&mut self, name: &str, k: usize, value: [f32; 3]) {
        let offset = self.vec3_offset(name, k);
        let bytes: Vec<u8> = value.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.bin[offset..offset + 12].copy_from_slice(&bytes);
    }

    /// Writes `scene.gltf` and `scene.bin` into `dir`.
    fn write(&self, dir: &Path) -> PathBuf {
        let path = dir.join("scene.gltf");
        std::fs::write(&path, serde_json::to_vec_pretty(&self.json).unwrap()).unwrap();
        std::fs::write(dir.join("scene.bin"), &self.bin).unwrap();
        path
    }

    /// Bakes the case quickly into `<dir>/out`.
    fn bake(&self, dir: &Path) -> Output {
        let scene = self.write(dir);
        Command::new(env!("CARGO_BIN_EXE_lightbake"))
            .args(["bake", scene.to_str().unwrap(), "-o"])
            .arg(dir.join("out"))
            .args([
                "--texels-per-unit",
                "4",
                "--rays",
                "16",
                "--light-samples",
                "4",
            ])
            .output()
            .expect("run lightbake")
    }

    /// The bake must fail cleanly: exit code neither 0 nor 101, stderr naming the file and each
    /// of `needles`, and nothing written.
    fn refused(&self, needles: &[&str]) {
        let dir = scratch();
        let o = self.bake(dir.path());
        let err = String::from_utf8_lossy(&o.stderr);
        let code = o.status.code();
        assert!(
            code.is_some_and(|c| c != 0 && c != 101),
            "exit code {code:?}: {err}"
        );
        assert!(!err.contains("panicked"), "{err}");
        for needle in ["scene.gltf"].iter().chain(needles) {
            assert!(
                err.contains(needle),
                "stderr should mention {needle:?}: {err}"
            );
        }
        let out = dir.path().join("out");
        assert!(
            !out.exists() || list_files(&out).is_empty(),
            "left behind: {:?}",
            list_files(&out)
        );
    }

    /// The bake must succeed with a warning containing `needle`; returns the files written.
    fn warned(&self, needle: &str) -> Vec<String> {
        let dir = scratch();
        let o = self.bake(dir.path());
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.success(), "{err}");
        assert!(err.contains("warning") && err.contains(needle), "{err}");
        list_files(&dir.path().join("out"))
    }
}

#[test]
fn position_accessor_past_the_end_is_an_error() {
    let mut case = Case::floor();
    case.primitive()["attributes"]["POSITION"] = json!(99);
    let count = case.json["accessors"].as_array().unwrap().len();
    case.refused(&[
        "mesh 0 'floor' primitive 0",
        &format!("POSITION refers to accessor 99, but the file has {count} accessors"),
    ]);
}

#[test]
fn indices_accessor_past_the_end_is_an_error() {
    let mut case = Case::floor();
    case.primitive()["indices"] = json!(1000);
    case.refused(&[
        "mesh 0 'floor' primitive 0",
        "indices refers to accessor 1000",
    ]);
}

#[test]
fn missing_accessors_are_an_error() {
    let mut case = Case::floor();
    case.json.as_object_mut().unwrap().remove("accessors");
    case.refused(&["mesh 0 'floor' primitive 0", "but the file has 0 accessors"]);
}

#[test]
fn empty_accessors_are_an_error() {
    let mut case = Case::floor();
    case.json["accessors"] = json!([]);
    case.refused(&["mesh 0 'floor' primitive 0", "but the file has 0 accessors"]);
}

#[test]
fn mesh_without_primitives_is_an_error() {
    let mut case = Case::floor();
    case.json["meshes"][0]["primitives"] = json!([]);
    case.refused(&["mesh 0 'floor' has no primitives"]);
}

/// What flipped exponent bits make of a coordinate: infinity, NaN, or a huge finite value.
#[test]
fn damaged_positions_are_an_error() {
    for value in [f32::NAN, f32::INFINITY, 1e30, -3e37, 2e7] {
        let mut case = Case::floor();
        case.set_vec3("POSITION", 40, [value, 0.0, 0.5]);
        case.refused(&["mesh 0 'floor' primitive 0", "POSITION 40"]);
    }
}

/// A huge coordinate used to reach obvhs' builder, which panicked; the tracer now leaves such
/// triangles out (the loader refuses them first, but a scene can be built by hand).
#[test]
fn tracer_leaves_out_triangles_beyond_the_coordinate_limit() {
    let dir = scratch();
    let path = Case::floor().write(dir.path());
    let (mut scene, _) = lightbake::scene::load(&path).unwrap();
    let whole = Tracer::new(&scene).len();
    scene.positions[40].x = 1e30;
    let using_40 = scene.triangles.iter().filter(|t| t.contains(&40)).count();
    assert!(using_40 > 0);
    let tracer = Tracer::new(&scene);
    assert_eq!(tracer.len(), whole - using_40);
    assert!(tracer.epsilon.is_finite() && tracer.epsilon < 1e3);
}

/// A NaN normal used to be copied into the output, which the Khronos validator refuses.
#[test]
fn non_finite_normals_are_an_error() {
    let mut case = Case::floor();
    case.set_vec3("NORMAL", 7, [f32::NAN, 1.0, 0.0]);
    case.refused(&["mesh 0 'floor' primitive 0: NORMAL 7 is not finite"]);
}

#[test]
fn accessor_outside_its_buffer_view_is_an_error() {
    for (field, value) in [
        ("count", json!(1_000_000_000u64)),
        ("count", json!(u64::MAX / 2)),
        ("byteOffset", json!(1u64 << 62)),
    ] {
        let mut case = Case::floor();
        case.json["accessors"][0][field] = value;
        case.refused(&["accessor 0:", "do not fit in bufferView"]);
    }
}

#[test]
fn buffer_view_outside_its_buffer_is_an_error() {
    let mut case = Case::floor();
    case.json["bufferViews"][0]["byteLength"] = json!(u64::MAX - 4);
    case.refused(&["bufferView 0:", "lie outside buffer 0"]);
}

#[test]
fn stride_smaller_than_an_element_is_an_error() {
    let mut case = Case::floor();
    case.json["bufferViews"][0]["byteStride"] = json!(4);
    case.refused(&[
        "accessor 0:",
        "byteStride 4, smaller than one 12-byte element",
    ]);
}

#[test]
fn accessor_count_zero_is_an_error() {
    let mut case = Case::floor();
    case.json["accessors"][0]["count"] = json!(0);
    case.refused(&["accessor 0: count is 0"]);
}

#[test]
fn sparse_count_zero_is_an_error() {
    let mut case = Case::floor();
    case.json["accessors"][0]["sparse"] = json!({
        "count": 0,
        "indices": {"bufferView": 0, "componentType": 5125},
        "values": {"bufferView": 0},
    });
    case.refused(&["accessor 0: sparse count 0"]);
}

/// The gltf crate's index reader reaches `unreachable!` on float indices.
#[test]
fn float_indices_are_an_error() {
    let mut case = Case::floor();
    let indices = case.primitive()["indices"].as_u64().unwrap() as usize;
    case.json["accessors"][indices]["componentType"] = json!(5126);
    case.json["accessors"][indices]["count"] = json!(1);
    case.refused(&["mesh 0 'floor' primitive 0 indices are F32 Scalar"]);
}

#[test]
fn light_intensity_beyond_f32_is_an_error() {
    let mut case = Case::floor();
    case.json["extensions"]["KHR_lights_punctual"]["lights"][0]["intensity"] = json!(1e39);
    case.refused(&["light 0: a value is not finite"]);
}

#[test]
fn spot_cone_angles_out_of_order_are_clamped_with_a_warning() {
    let mut case = Case::floor();
    let light = &mut case.json["extensions"]["KHR_lights_punctual"]["lights"][0];
    light["type"] = json!("spot");
    light["spot"] = json!({"innerConeAngle": 0.6, "outerConeAngle": 0.3});
    case.warned("light 0: spot cone angles inner 0.6, outer 0.3 break 0 ≤ inner < outer ≤ π/2; clamped to inner 0.3, outer 0.3");
    let light = &mut case.json["extensions"]["KHR_lights_punctual"]["lights"][0];
    light["spot"] = json!({"innerConeAngle": -0.1, "outerConeAngle": 2.0});
    case.warned("clamped to inner 0, outer 1.5707");
}

#[test]
fn negative_emissive_strength_is_clamped_with_a_warning() {
    let mut case = Case::floor();
    let material = &mut case.json["materials"][0];
    material["emissiveFactor"] = json!([1.0, 1.0, 1.0]);
    material["extensions"] = json!({"KHR_materials_emissive_strength": {"emissiveStrength": -2.0}});
    case.warned("material 0: KHR_materials_emissive_strength -2 is negative; clamped to 0");
}

#[test]
fn malformed_texture_transform_is_a_warning() {
    let text = std::fs::read_to_string(fixture("textured.gltf")).unwrap();
    let mut json: Value = serde_json::from_str(&text).unwrap();
    json["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]["extensions"] =
        json!({"KHR_texture_transform": {"scale": [2.0]}});
    let case = Case {
        json,
        bin: Vec::new(),
    };
    case.warned("material 0/pbrMetallicRoughness/baseColorTexture/extensions/KHR_texture_transform: scale is not two numbers");
}

/// Nothing to bake is not an error: the glTF is written through with its buffer, no lightmaps.
#[test]
fn scene_with_nothing_to_bake_is_written_through() {
    let mut points = Case::floor();
    points.primitive()["mode"] = json!(0);
    let mut flat = Case::floor();
    for k in 0..81 {
        flat.set_vec3("POSITION", k, [1.0, 0.0, 1.0]);
    }
    flat.json["accessors"][0]["min"] = json!([1.0, 0.0, 1.0]);
    flat.json["accessors"][0]["max"] = json!([1.0, 0.0, 1.0]);
    for case in [points, flat] {
        let dir = scratch();
        let o = case.bake(dir.path());
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.success(), "{err}");
        assert!(err.contains("nothing to bake"), "{err}");
        let out = dir.path().join("out");
        assert_eq!(list_files(&out), ["scene.bin", "scene.gltf"]);
        let written: Value =
            serde_json::from_slice(&std::fs::read(out.join("scene.gltf")).unwrap()).unwrap();
        assert_eq!(written["meshes"], case.json["meshes"]);
        assert_eq!(written["accessors"], case.json["accessors"]);
        assert!(!written.to_string().contains("FB_materials_lightmap"));
        let (scene, _) = lightbake::scene::load(&out.join("scene.gltf")).unwrap();
        assert!(scene.triangles.is_empty());
    }
}

/// Runs `lightbake bake` on a fixture into `<dir>/out` with `extra` options.
fn bake_fixture(name: &str, dir: &Path, extra: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_lightbake"))
        .args(["bake", fixture(name).to_str().unwrap(), "-o"])
        .arg(dir.join("out"))
        .args(extra)
        .output()
        .expect("run lightbake")
}

/// A bake that needs more memory than `--max-memory` is refused before any heavy work, with
/// the estimate and the limit in the message, and leaves nothing behind.
#[test]
fn bake_beyond_the_memory_limit_is_refused() {
    let dir = scratch();
    let start = std::time::Instant::now();
    let options = ["--no-auto", "--quality", "high", "--max-memory", "16M"];
    let o = bake_fixture("cornell_box.gltf", dir.path(), &options);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    for needle in [
        "cornell_box.gltf: the bake would need about",
        "above the memory limit 16.0 MiB",
        "rows ",
        "use --solver gather",
    ] {
        assert!(
            err.contains(needle),
            "stderr should mention {needle:?}: {err}"
        );
    }
    // High quality stores 1024 rays for each of about 7 700 texels: 7.5 MiB even as ray counts
    // (a byte per ray), and about 2.5 times that while they are built.
    let estimate: f64 = err
        .split("need about ")
        .nth(1)
        .and_then(|s| s.split(" MiB").next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("no estimate in MiB: {err}"));
    assert!(estimate > 20.0, "{err}");
    // Refused before the transport (after loading, 0.03 s): the whole bake takes about 3 s.
    assert!(start.elapsed().as_secs_f64() < 1.0, "{:?}", start.elapsed());
    let out = dir.path().join("out");
    assert!(!out.exists() || list_files(&out).is_empty());
}

/// The estimated peak in MiB that `--explain` gives after `before`.
fn explained_peak(stdout: &str, before: &str) -> f64 {
    stdout
        .split(before)
        .nth(1)
        .and_then(|s| s.split(" MiB").next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("no {before:?} in --explain: {stdout}"))
}

/// With room, rows are f32 (`--explain` gives both storages' estimates); below the f32 rows'
/// estimate they are stored as ray counts, with the same output byte for byte; below the
/// counts' estimate the automatic choice switches to the matrix-free gather solver (a warning
/// and `--explain` say so); far below, the bake is refused.
#[test]
fn automatic_choice_stores_counts_then_gathers_when_rows_do_not_fit() {
    // A 0.5% target at draft density: a final bake at K = 1664 follows the pilot (its f32
    // pilot runs peak at about 17.5 MiB, below the final counts' 28.6 MiB: room for the
    // gatherer; a pilot run's rows go once it is solved, so a 1% target leaves none).
    let options = ["--quality", "draft", "--target-error", "0.005", "--explain"];
    let f32_dir = scratch();
    let o = bake_fixture("cornell_box.gltf", f32_dir.path(), &options);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.contains("montecarlo/jacobi"), "{out}");
    assert!(out.contains("  - rows f32: estimated peak"), "{out}");
    let peak = explained_peak(&out, "memory: estimated peak ");
    assert_eq!(peak, explained_peak(&out, "rows f32: estimated peak "));
    let counts_peak = explained_peak(&out, "(as ray counts ");
    assert!(counts_peak < peak - 0.5, "{out}");

    // Between the two estimates: ray counts, the same files byte for byte.
    // A bake within `limit` MiB, in `dir`: its --explain and warnings.
    let limited = |limit: f64, dir: &Path| {
        let limit = format!("{}K", (limit * 1024.0) as u64);
        let o = bake_fixture(
            "cornell_box.gltf",
            dir,
            &[&options[..], &["--max-memory", &limit]].concat(),
        );
        let err = String::from_utf8_lossy(&o.stderr).into_owned();
        assert!(o.status.success(), "{err}");
        (String::from_utf8_lossy(&o.stdout).into_owned(), err)
    };
    let dir = scratch();
    let (out, _) = limited((peak + counts_peak) / 2.0, dir.path());
    assert!(
        out.contains("  - rows as exact ray counts: the estimated peak with f32 rows"),
        "{out}"
    );
    assert!(out.contains("montecarlo/jacobi"), "{out}");
    let files = list_files(&f32_dir.path().join("out"));
    assert_eq!(files, list_files(&dir.path().join("out")));
    for f in &files {
        let read = |d: &Path| std::fs::read(d.join("out").join(f)).unwrap();
        assert!(read(f32_dir.path()) == read(dir.path()), "{f} differs");
    }

    // Just below the counts' peak (above the pilot's).
    let dir = scratch();
    let (out, err) = limited(counts_peak - 0.1, dir.path());
    assert!(
        err.contains("warning") && err.contains("solver gather: the estimated peak"),
        "{err}"
    );
    assert!(
        out.contains("  - solver gather: the estimated peak"),
        "{out}"
    );
    assert!(out.contains("montecarlo/gather"), "{out}");

    let dir = scratch();
    let o = bake_fixture(
        "cornell_box.gltf",
        dir.path(),
        &[&options[..], &["--max-memory", "4M"]].concat(),
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("above the memory limit 4.00 MiB"), "{err}");
}

/// Found by the fuzzer (seed 100, case 4779): an image in a bufferView without its mimeType
/// reached an `unwrap` in the gltf crate (exit 101). glTF requires the mimeType there, and
/// exactly one of uri and bufferView.
#[test]
fn image_without_a_source_or_mime_type_is_an_error() {
    let text = std::fs::read_to_string(fixture("textured.gltf")).unwrap();
    let json: Value = serde_json::from_str(&text).unwrap();
    assert!(json["images"][0]["bufferView"].is_u64());
    let refused = |edit: &dyn Fn(&mut serde_json::Map<String, Value>), needle: &str| {
        let mut case = Case {
            json: json.clone(),
            bin: Vec::new(),
        };
        edit(case.json["images"][0].as_object_mut().unwrap());
        case.refused(&[needle]);
    };
    refused(
        &|image| {
            image.remove("mimeType");
        },
        "image 0 has a bufferView but no mimeType",
    );
    refused(
        &|image| {
            image.remove("bufferView");
        },
        "image 0 has neither a uri nor a bufferView",
    );
    refused(
        &|image| {
            image.insert("uri".into(), json!("checker.png"));
        },
        "image 0 has both a uri and a bufferView",
    );
}

/// Found by the fuzzer (seed 0, case 777: a node moved to another mesh, leaving a mesh with an
/// infinite coordinate unused): data the bake does not read is copied to the output, where a
/// non-finite float breaks the glTF validator. Every float accessor is checked.
#[test]
fn non_finite_float_in_an_unused_accessor_is_an_error() {
    let mut case = Case::floor();
    let offset = case.bin.len();
    case.bin.extend(
        [1.0f32, f32::INFINITY, 0.0]
            .iter()
            .flat_map(|v| v.to_le_bytes()),
    );
    case.json["buffers"][0]["byteLength"] = json!(case.bin.len());
    let views = case.json["bufferViews"].as_array_mut().unwrap();
    views.push(json!({"buffer": 0, "byteOffset": offset, "byteLength": 12}));
    let view = views.len() - 1;
    let accessors = case.json["accessors"].as_array_mut().unwrap();
    accessors.push(json!({"bufferView": view, "componentType": 5126, "count": 1, "type": "VEC3"}));
    let accessor = accessors.len() - 1;
    case.refused(&[&format!(
        "accessor {accessor}: element 0 is not finite (glTF requires finite floats)"
    )]);
}

/// A node moved far from the rest (the fuzzer moved a chair 400 km) widens the ray epsilon to
/// 4 m, which blurs every contact and made a draft bake take minutes: the load names it in a
/// warning. The fixtures, rooms and yards as authored, get none.
#[test]
fn a_node_far_from_the_rest_of_the_scene_is_named_in_a_warning() {
    let far = |scene: &lightbake::scene::Scene| {
        (scene.stats.warnings.iter())
            .filter(|w| w.contains("far from the rest"))
            .cloned()
            .collect::<Vec<_>>()
    };
    for name in std::fs::read_dir(fixture("")).unwrap() {
        let path = name.unwrap().path();
        if matches!(
            path.extension().and_then(|e| e.to_str()),
            Some("gltf" | "glb")
        ) {
            let (scene, _) = lightbake::scene::load(&path).unwrap();
            assert!(
                far(&scene).is_empty(),
                "{}: {:?}",
                path.display(),
                far(&scene)
            );
        }
    }
    use lightbake::testing::{Geometry, GltfBuilder, Node};
    let mut gltf = GltfBuilder::new("far_box");
    let grey = grey_floor(&mut gltf);
    let (lo, hi) = (Vec3::ZERO, Vec3::splat(0.5));
    let cube = gltf.add_mesh("cube", Geometry::box_faces(lo, hi, &Face::ALL, 1), grey);
    gltf.add_node(Node::new("near box").with_mesh(cube));
    let moved = Vec3::new(0.0, 0.0, -4.0e5);
    gltf.add_node((Node::new("lost box").with_mesh(cube)).trs(moved, Quat::IDENTITY, Vec3::ONE));
    let dir = scratch();
    let input = dir.path().join("far_box.gltf");
    gltf.write_gltf(&input).unwrap();
    let (scene, _) = lightbake::scene::load(&input).unwrap();
    let warned = far(&scene);
    assert_eq!(warned.len(), 1, "{warned:?}");
    assert!(
        warned[0].starts_with("node 2 'lost box' lies far") && !warned[0].contains("near box"),
        "{}",
        warned[0]
    );
}
