//! End to end through the library: round trips of the written files, coverage, determinism.

use lightbake::{NoProgress, compute, output, write};

use crate::util::{fixture, list_files, quick, scratch};

#[test]
fn exr_pages_read_back_to_the_computed_values() {
    let dir = scratch();
    let input = fixture("cornell_box.gltf");
    let config = quick();
    let baked = compute(&input, &config, &NoProgress).unwrap();
    let pages = baked.pages.clone();
    let report = write(baked, &input, dir.path(), &config, &NoProgress).unwrap();
    assert_eq!(report.pages, pages.pages.len());
    for (k, page) in pages.pages.iter().enumerate() {
        let back =
            output::read_exr(&dir.path().join(format!("cornell_box_lightmap{k}.exr"))).unwrap();
        assert_eq!((back.width, back.height), (page.width, page.height));
        for (a, b) in page.rgb.iter().zip(&back.rgb) {
            // Half floats keep 11 significant bits.
            assert!(
                (*a - *b).abs().max_element() <= a.abs().max_element() * 1e-3 + 1e-6,
                "{a} vs {b}"
            );
        }
    }
}

#[test]
fn float_pages_are_exact() {
    let dir = scratch();
    let input = fixture("point_light.gltf");
    let mut config = quick();
    config.output.float = true;
    let baked = compute(&input, &config, &NoProgress).unwrap();
    let page = baked.pages.pages[0].clone();
    write(baked, &input, dir.path(), &config, &NoProgress).unwrap();
    let back = output::read_exr(&dir.path().join("point_light_lightmap0.exr")).unwrap();
    assert_eq!(back.rgb, page.rgb);
}

#[test]
fn written_gltf_references_its_lightmaps() {
    for name in [
        "cornell_box.gltf",
        "cornell_box.glb",
        "instanced.gltf",
        "textured.gltf",
        "spot_and_directional.gltf",
    ] {
        let dir = scratch();
        let input = fixture(name);
        let report = lightbake::bake(&input, dir.path(), &quick(), &NoProgress).unwrap();
        let gltf_path = &report.files[0];
        let (doc, buffers, _) = gltf::import(gltf_path).unwrap_or_else(|e| panic!("{name}: {e}"));
        // The raw JSON: the gltf crate drops extensions it does not know.
        let bytes = std::fs::read(gltf_path).unwrap();
        let json: serde_json::Value = match gltf::Glb::from_slice(&bytes) {
            Ok(glb) => serde_json::from_slice(&glb.json).unwrap(),
            Err(_) => serde_json::from_slice(&bytes).unwrap(),
        };
        let mut baked_primitives = 0;
        for mesh in doc.meshes() {
            for prim in mesh.primitives() {
                let Some(extras) = prim.extras() else {
                    continue;
                };
                let extras: serde_json::Value = serde_json::from_str(extras.get()).unwrap();
                let Some(lightmap) = extras.get("lightmap") else {
                    continue;
                };
                baked_primitives += 1;
                let exr = lightmap["exr"].as_str().unwrap();
                assert!(dir.path().join(exr).exists(), "{name}: {exr} missing");
                let reader = prim.reader(|b| Some(&buffers[b.index()]));
                let uvs: Vec<[f32; 2]> = reader
                    .read_tex_coords(1)
                    .expect("TEXCOORD_1")
                    .into_f32()
                    .collect();
                assert!(!uvs.is_empty());
                assert!(
                    uvs.iter().flatten().all(|&c| (0.0..=1.0).contains(&c)),
                    "{name}: uv out of range"
                );
                let material = prim
                    .material()
                    .index()
                    .expect("baked primitives have a material");
                let ext = &json["materials"][material]["extensions"]["FB_materials_lightmap"];
                assert_eq!(
                    ext["lightmapTexture"]["texCoord"], 1,
                    "{name}: material {material} without FB_materials_lightmap"
                );
            }
        }
        assert!(baked_primitives > 0, "{name}: no baked primitive");
        assert!(doc.extensions_used().any(|e| e == "FB_materials_lightmap"));
    }
}

#[test]
fn no_texel_inside_a_chart_is_black_in_a_lit_closed_scene() {
    let baked = compute(&fixture("furnace.gltf"), &quick(), &NoProgress).unwrap();
    assert!(baked.lightmap.iter().all(|v| v.min_element() > 0.0));
    for page in &baked.pages.pages {
        for (v, ok) in page.rgb.iter().zip(&page.valid) {
            if *ok {
                assert!(v.min_element() > 0.0);
            }
        }
    }
}

#[test]
fn presets_all_validate() {
    for (name, config) in lightbake::BakeConfig::PRESETS {
        config.validate().unwrap_or_else(|e| panic!("{name}: {e}"));
    }
}

/// Same input and options → same bytes, on 1 and on 2 threads.
#[test]
fn output_is_identical_across_thread_counts() {
    let input = fixture("cornell_box.gltf");
    let run = |threads: usize| {
        let dir = scratch();
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| lightbake::bake(&input, dir.path(), &quick(), &NoProgress))
            .unwrap();
        let files = list_files(dir.path());
        let bytes: Vec<Vec<u8>> = files
            .iter()
            .map(|f| std::fs::read(dir.path().join(f)).unwrap())
            .collect();
        (files, bytes)
    };
    let (files1, bytes1) = run(1);
    let (files2, bytes2) = run(2);
    assert_eq!(files1, files2);
    for ((f, a), b) in files1.iter().zip(&bytes1).zip(&bytes2) {
        assert!(a == b, "{f} differs between 1 and 2 threads");
    }
}

#[test]
fn a_failed_bake_leaves_nothing_behind() {
    let dir = scratch();
    let out = dir.path().join("out");
    std::fs::create_dir(&out).unwrap();
    // A progress that cancels as soon as the transport starts.
    struct Cancel(std::sync::atomic::AtomicBool);
    impl lightbake::Progress for Cancel {
        fn begin(&self, stage: &str, _: u64) {
            if stage == "transport" {
                self.0.store(true, std::sync::atomic::Ordering::Relaxed);
            }
        }
        fn aborted(&self) -> bool {
            self.0.load(std::sync::atomic::Ordering::Relaxed)
        }
    }
    let r = lightbake::bake(
        &fixture("cornell_box.gltf"),
        &out,
        &quick(),
        &Cancel(false.into()),
    );
    assert!(matches!(r, Err(lightbake::Error::Aborted)), "{r:?}");
    assert!(list_files(&out).is_empty());
}

/// A caller that has cancelled: every check point sees it.
struct Cancelled;

impl lightbake::Progress for Cancelled {
    fn aborted(&self) -> bool {
        true
    }
}

/// Validity and the denoiser, the long per-texel stages outside transport, stop on a cancelled
/// run (a SIGINT or SIGTERM in the CLI) instead of finishing their loop; values stay unchanged.
#[test]
fn validity_and_denoise_stop_when_cancelled() {
    use lightbake::lightmap::denoise::{DenoiseParams, denoise};
    use lightbake::texels::validity::{ValidityParams, fix};
    let mut config = quick();
    config.transport.validity = false;
    let mut p = lightbake::prepare(
        &fixture("cornell_box.gltf"),
        &config,
        &lightbake::NoProgress,
    )
    .unwrap();
    let before = p.texels.position.clone();
    let r = fix(
        &mut p.texels,
        &p.scene,
        &p.tracer,
        &ValidityParams::default(),
        &Cancelled,
    );
    assert!(matches!(r, Err(lightbake::Error::Aborted)), "{r:?}");
    assert_eq!(p.texels.position, before);
    let r = fix(
        &mut p.texels,
        &p.scene,
        &p.tracer,
        &ValidityParams::default(),
        &lightbake::NoProgress,
    );
    assert!(r.unwrap().moved > 0, "the control moves sample points");

    let mut values: Vec<glam::Vec3> = (0..p.texels.len())
        .map(|i| glam::Vec3::splat((i % 7) as f32))
        .collect();
    let original = values.clone();
    let noise = vec![1.0; values.len()];
    let r = denoise(
        &p.texels,
        &mut values,
        &noise,
        &DenoiseParams::default(),
        &Cancelled,
    );
    assert!(matches!(r, Err(lightbake::Error::Aborted)), "{r:?}");
    assert_eq!(values, original);
    denoise(
        &p.texels,
        &mut values,
        &noise,
        &DenoiseParams::default(),
        &lightbake::NoProgress,
    )
    .unwrap();
    assert_ne!(values, original, "the control filters");
}
