//! Relighting from a kept transport and per-light layers (`lightbake::relight`).
//!
//! The yardstick of a relight is a fresh bake of the edited scene with the same fixed settings
//! (the kept settings, no automatic choice): the rows are geometry only, so the two differ by
//! the solver's tolerance (and by float rounding of the scaled direct light).

use std::path::{Path, PathBuf};

use glam::Vec3;
use lightbake::config::LayerGroup;
use lightbake::lightmap::LightmapPages;
use lightbake::relight::{Edits, relight};
use lightbake::{BakeConfig, NoProgress, bake, compute, kept, metrics};
use serde_json::{Value, json};

use crate::util::{fixture, quick, scratch};

fn kept_config() -> BakeConfig {
    let mut c = quick();
    c.output.float = true; // compare pages without half-float rounding
    c.output.keep_transport = true;
    c
}

/// `name` from the fixtures with its JSON changed by `edit`, written into `dir`.
fn edited_fixture(name: &str, dir: &Path, edit: impl FnOnce(&mut Value)) -> PathBuf {
    let mut json: Value = serde_json::from_slice(&std::fs::read(fixture(name)).unwrap()).unwrap();
    edit(&mut json);
    let path = dir.join(name);
    std::fs::write(&path, serde_json::to_vec(&json).unwrap()).unwrap();
    path
}

/// The EXR pages `<stem>_lightmap<k>.exr` of a bake or relight in `dir`.
fn pages(dir: &Path, stem: &str) -> LightmapPages {
    let mut pages = LightmapPages::default();
    for k in 0.. {
        let path = dir.join(format!("{stem}_lightmap{k}.exr"));
        if !path.exists() {
            break;
        }
        pages
            .pages
            .push(lightbake::output::read_exr(&path).unwrap());
    }
    assert!(!pages.pages.is_empty(), "no pages in {}", dir.display());
    pages
}

/// Relative L1 difference of two sets of pages over the texels both cover.
fn page_difference(a: &LightmapPages, b: &LightmapPages) -> f32 {
    assert_eq!(a.pages.len(), b.pages.len());
    let (mut x, mut r) = (Vec::new(), Vec::new());
    for (p, q) in a.pages.iter().zip(&b.pages) {
        assert_eq!((p.width, p.height), (q.width, q.height));
        for k in 0..p.rgb.len() {
            if p.valid[k] && q.valid[k] {
                x.push(p.rgb[k]);
                r.push(q.rgb[k]);
            }
        }
    }
    metrics::relative_l1(&x, &r)
}

/// Bakes `name` keeping the transport, relights it with `edits`, bakes the edited scene
/// (`edit`) afresh with the kept settings; returns the pages' relative L1 difference and the
/// solver tolerance.
fn relit_against_fresh(
    name: &str,
    config: &BakeConfig,
    edits: &Edits,
    edit: impl FnOnce(&mut Value),
) -> (f32, f32) {
    let dir = scratch();
    let stem = name.trim_end_matches(".gltf");
    let kept_dir = dir.path().join("kept");
    bake(&fixture(name), &kept_dir, config, &NoProgress).unwrap();
    let gltf = kept_dir.join(name);
    let relit_dir = dir.path().join("relit");
    let report = relight(&gltf, &relit_dir, edits, None, &NoProgress).unwrap();
    assert!(report.converged);

    let settings = kept::read(&gltf).unwrap().settings;
    let mut fresh_config = settings.config().unwrap();
    fresh_config.output.float = true;
    let input_dir = dir.path().join("input");
    std::fs::create_dir_all(&input_dir).unwrap();
    let edited = edited_fixture(name, &input_dir, edit);
    let fresh_dir = dir.path().join("fresh");
    bake(&edited, &fresh_dir, &fresh_config, &NoProgress).unwrap();

    // The relit glTF carries the edited values as the fresh bake's input does.
    let relit: Value =
        serde_json::from_slice(&std::fs::read(relit_dir.join(name)).unwrap()).unwrap();
    let fresh: Value =
        serde_json::from_slice(&std::fs::read(fresh_dir.join(name)).unwrap()).unwrap();
    let radiant = |json: &Value| -> Vec<Vec3> {
        let lights = json["extensions"]["KHR_lights_punctual"]["lights"].as_array();
        (lights.map_or(&[][..], Vec::as_slice).iter())
            .map(|l| {
                let c = |k: usize| l["color"][k].as_f64().unwrap_or(1.0) as f32;
                Vec3::new(c(0), c(1), c(2)) * l["intensity"].as_f64().unwrap_or(1.0) as f32
            })
            .collect()
    };
    for (a, b) in radiant(&relit).iter().zip(&radiant(&fresh)) {
        assert!(
            (*a - *b).abs().max_element() <= 1e-5 * b.max_element(),
            "{a} vs {b}"
        );
    }
    for (a, b) in relit["materials"]
        .as_array()
        .unwrap()
        .iter()
        .zip(fresh["materials"].as_array().unwrap())
    {
        let close = |x: &Value, y: &Value| {
            let (x, y) = (x.as_f64().unwrap_or(1.0), y.as_f64().unwrap_or(1.0));
            (x - y).abs() <= 1e-6 * y.abs().max(1.0)
        };
        for k in 0..4 {
            let path = &["pbrMetallicRoughness", "baseColorFactor"];
            assert!(
                close(&a[path[0]][path[1]][k], &b[path[0]][path[1]][k]),
                "{a} vs {b}"
            );
        }
        let strength = |m: &Value| {
            m["extensions"]["KHR_materials_emissive_strength"]["emissiveStrength"].clone()
        };
        assert!(close(&strength(a), &strength(b)), "{a} vs {b}");
    }

    let diff = page_difference(&pages(&relit_dir, stem), &pages(&fresh_dir, stem));
    (diff, settings.tolerance)
}

/// Each light scaled or tinted on its own and a new wall colour. The shadow cuts are off:
/// they follow the outlines of the lights' shadows that are at least a tenth of the light
/// there, so another balance of lights cuts other outlines and a fresh bake would lay out other
/// texels (a relight keeps the baked ones: see the next test).
#[test]
fn relit_lights_and_albedo_equal_a_fresh_bake_within_the_tolerance() {
    let mut config = kept_config();
    config.atlas.shadow_cuts = false;
    let edits = Edits {
        lights: vec![
            ("bulb".into(), Vec3::splat(2.0)),
            ("spot".into(), Vec3::new(1.0, 0.5, 0.25)),
        ],
        albedo: vec![("walls".into(), Vec3::new(0.3, 0.6, 0.3))],
        ..Default::default()
    };
    let (diff, tolerance) = relit_against_fresh("lamp_room.gltf", &config, &edits, |json| {
        let lights = &mut json["extensions"]["KHR_lights_punctual"]["lights"];
        lights[0]["intensity"] = json!(24.0);
        lights[1]["color"] = json!([0.9, 0.475, 0.25]);
        json["materials"][0]["pbrMetallicRoughness"]["baseColorFactor"] =
            json!([0.3, 0.6, 0.3, 1.0]);
    });
    println!("lamp_room relit vs fresh: relative L1 {diff:.2e} (tolerance {tolerance:.0e})");
    assert!(diff <= tolerance, "{diff} > {tolerance}");
}

/// With shadow cuts (the default): every light by one factor keeps the balance of lights, so
/// the cuts, texels and rays are the fresh bake's.
#[test]
fn relit_with_shadow_cuts_equals_a_fresh_bake_when_the_lights_keep_their_balance() {
    let edits = Edits {
        lights: vec![
            ("bulb".into(), Vec3::splat(0.5)),
            ("spot".into(), Vec3::splat(0.5)),
        ],
        albedo: vec![("floor".into(), Vec3::new(0.7, 0.5, 0.3))],
        ..Default::default()
    };
    let (diff, tolerance) = relit_against_fresh("lamp_room.gltf", &kept_config(), &edits, |json| {
        let lights = &mut json["extensions"]["KHR_lights_punctual"]["lights"];
        lights[0]["intensity"] = json!(6.0);
        lights[1]["intensity"] = json!(20.0);
        json["materials"][1]["pbrMetallicRoughness"]["baseColorFactor"] =
            json!([0.7, 0.5, 0.3, 1.0]);
    });
    println!("lamp_room (shadow cuts) relit vs fresh: relative L1 {diff:.2e}");
    assert!(diff <= tolerance, "{diff} > {tolerance}");
}

/// One emissive material scaled: the light samples are drawn in proportion to the emitters'
/// power, which one factor on the only emitter leaves as it was, so the fresh bake casts the
/// same rays and the two agree within the tolerance, not only within the noise.
#[test]
fn relit_emission_equals_a_fresh_bake_within_the_tolerance() {
    let edits = Edits {
        emission: vec![("light".into(), 3.0)],
        ..Default::default()
    };
    let (diff, tolerance) = relit_against_fresh(
        "cornell_box.gltf",
        &kept_config(),
        &edits,
        |json| {
            let strength = &mut json["materials"][3]["extensions"]["KHR_materials_emissive_strength"]
                ["emissiveStrength"];
            *strength = json!(strength.as_f64().unwrap() * 3.0);
        },
    );
    println!("cornell_box relit vs fresh: relative L1 {diff:.2e} (tolerance {tolerance:.0e})");
    assert!(diff <= tolerance, "{diff} > {tolerance}");
}

/// Sums the layers' lightmaps of a bake and compares them with its lightmap (both denoised and
/// filled, before dilation): returns the relative L1 difference and the largest texel
/// difference relative to the largest value.
fn layer_sum_error(baked: &lightbake::Baked) -> (f32, f32) {
    let mut sum = vec![Vec3::ZERO; baked.lightmap.len()];
    for layer in &baked.layers {
        for (s, v) in sum.iter_mut().zip(&layer.lightmap) {
            *s += *v;
        }
    }
    let peak = baked
        .lightmap
        .iter()
        .map(|v| v.max_element())
        .fold(0.0, f32::max);
    let worst = (sum.iter().zip(&baked.lightmap))
        .map(|(s, v)| (*s - *v).abs().max_element())
        .fold(0.0, f32::max);
    (metrics::relative_l1(&sum, &baked.lightmap), worst / peak)
}

#[test]
fn layers_sum_to_the_lightmap_within_float_rounding() {
    // A sun and a sky (courtyard), two punctual lights in one group (lamp room), an emitter
    // and a sky (the Cornell box is open at the front).
    let cases: [(&str, Vec3, Option<Vec<LayerGroup>>, usize); 3] = [
        ("courtyard.gltf", Vec3::new(0.2, 0.3, 0.5), Some(vec![]), 2),
        (
            "lamp_room.gltf",
            Vec3::ZERO,
            Some(vec![LayerGroup {
                name: "lamps".into(),
                members: vec!["bulb".into(), "spot".into()],
            }]),
            1,
        ),
        ("cornell_box.gltf", Vec3::splat(0.1), Some(vec![]), 2),
    ];
    for (name, sky, layers, count) in cases {
        let mut config = quick();
        config.transport.sky = sky;
        config.output.layers = layers;
        let baked = compute(&fixture(name), &config, &NoProgress).unwrap();
        assert_eq!(baked.layers.len(), count, "{name}");
        let (l1, worst) = layer_sum_error(&baked);
        println!("{name}: layers sum to the lightmap within {l1:.1e} (L1), {worst:.1e} (max/peak)");
        // Denoised (the default): float rounding over the sweeps and the filter.
        assert!(l1 < 1e-5 && worst < 1e-4, "{name}: {l1} {worst}");
    }
}

#[test]
fn bake_and_relight_write_layers_named_in_the_gltf() {
    let dir = scratch();
    let mut config = kept_config();
    config.output.layers = Some(vec![]);
    let out = dir.path().join("baked");
    bake(&fixture("lamp_room.gltf"), &out, &config, &NoProgress).unwrap();
    let json: Value =
        serde_json::from_slice(&std::fs::read(out.join("lamp_room.gltf")).unwrap()).unwrap();
    let layers = json["extras"]["lightmap_layers"].as_array().unwrap();
    let names: Vec<&str> = layers.iter().map(|l| l["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["bulb", "spot"]);
    for l in layers {
        let exr = l["pages"][0]["exr"].as_str().unwrap();
        assert!(out.join(exr).exists(), "{exr}");
    }
    // Relight with a group: the lamps together, the spot off.
    let relit = dir.path().join("relit");
    let edits = Edits {
        lights: vec![("spot".into(), Vec3::ZERO)],
        ..Default::default()
    };
    let groups = [LayerGroup {
        name: "all lamps".into(),
        members: vec!["bulb".into(), "spot".into()],
    }];
    let report = relight(
        &out.join("lamp_room.gltf"),
        &relit,
        &edits,
        Some(&groups),
        &NoProgress,
    )
    .unwrap();
    assert_eq!(report.layers, 1);
    let json: Value =
        serde_json::from_slice(&std::fs::read(relit.join("lamp_room.gltf")).unwrap()).unwrap();
    assert_eq!(json["extras"]["lightmap_layers"][0]["name"], "all_lamps");
    assert_eq!(
        json["extensions"]["KHR_lights_punctual"]["lights"][1]["intensity"],
        0.0
    );
    // One layer holding every light: it is the lightmap.
    let diff = page_difference(
        &pages(&relit, "lamp_room_all_lamps"),
        &pages(&relit, "lamp_room"),
    );
    assert!(diff < 1e-4, "{diff}");
}

#[test]
fn stale_foreign_truncated_and_damaged_transports_are_refused() {
    let dir = scratch();
    let a = dir.path().join("a");
    let b = dir.path().join("b");
    bake(&fixture("lamp_room.gltf"), &a, &kept_config(), &NoProgress).unwrap();
    bake(
        &fixture("cornell_box.gltf"),
        &b,
        &kept_config(),
        &NoProgress,
    )
    .unwrap();
    let gltf = a.join("lamp_room.gltf");
    let transport = a.join("lamp_room.transport");
    let good = std::fs::read(&transport).unwrap();
    let out = dir.path().join("out");
    let refused = |what: &str| {
        let e = relight(&gltf, &out, &Edits::default(), None, &NoProgress)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(what) && e.contains("lamp_room.transport"),
            "{what}: {e}"
        );
    };
    relight(&gltf, &out, &Edits::default(), None, &NoProgress).unwrap();

    std::fs::write(&transport, &good[..good.len() / 2]).unwrap();
    refused("truncated");
    let mut damaged = good.clone();
    damaged[good.len() / 2] ^= 1;
    std::fs::write(&transport, &damaged).unwrap();
    refused("damaged");
    let mut other_version = good.clone();
    other_version[20] = 9;
    std::fs::write(&transport, &other_version).unwrap();
    refused("version 9");
    std::fs::write(&transport, b"not a transport at all").unwrap();
    refused("not a lightbake transport");
    std::fs::copy(b.join("cornell_box.transport"), &transport).unwrap();
    refused("stale or foreign");
    // The glTF edited after the bake.
    std::fs::write(&transport, &good).unwrap();
    let text = std::fs::read_to_string(&gltf).unwrap();
    std::fs::write(&gltf, text.replace("\"bulb\"", "\"lamp\"")).unwrap();
    refused("stale or foreign");
    std::fs::write(&gltf, text).unwrap();
    relight(
        &gltf,
        &out.join("again"),
        &Edits::default(),
        None,
        &NoProgress,
    )
    .unwrap();
}

#[test]
fn unknown_names_are_errors_that_list_the_known_ones() {
    let dir = scratch();
    let a = dir.path().join("a");
    bake(&fixture("lamp_room.gltf"), &a, &kept_config(), &NoProgress).unwrap();
    let gltf = a.join("lamp_room.gltf");
    let error = |edits: Edits, groups: Option<&[LayerGroup]>| {
        relight(&gltf, &dir.path().join("out"), &edits, groups, &NoProgress)
            .unwrap_err()
            .to_string()
    };
    let e = error(
        Edits {
            lights: vec![("sun".into(), Vec3::ONE)],
            ..Default::default()
        },
        None,
    );
    assert!(
        e.contains("\"sun\"") && e.contains("\"bulb\", \"spot\""),
        "{e}"
    );
    let e = error(
        Edits {
            albedo: vec![("marble".into(), Vec3::ONE)],
            ..Default::default()
        },
        None,
    );
    assert!(
        e.contains("\"cabinet\", \"floor\", \"walls\", \"wood\""),
        "{e}"
    );
    let e = error(
        Edits {
            emission: vec![("walls".into(), 2.0)],
            ..Default::default()
        },
        None,
    );
    assert!(
        e.contains("emissive material") && e.contains("(none)"),
        "{e}"
    );
    let groups = [LayerGroup {
        name: "x".into(),
        members: vec!["moon".into()],
    }];
    let e = error(Edits::default(), Some(&groups));
    assert!(
        e.contains("\"moon\"") && e.contains("\"bulb\", \"spot\""),
        "{e}"
    );
}

#[test]
fn keeping_needs_stored_monte_carlo_rows() {
    let mut config = kept_config();
    config.technique = lightbake::config::Technique::Gather;
    let e = bake(
        &fixture("lamp_room.gltf"),
        &scratch().path().join("o"),
        &config,
        &NoProgress,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("stored Monte Carlo rows"), "{e}");
}

/// A closed 4 × 3 × 4 m room lit by two small ceiling panels of different emissive materials.
fn two_panel_room() -> lightbake::testing::GltfBuilder {
    use lightbake::testing::{Face, Geometry, GltfBuilder, Material};
    let mut g = GltfBuilder::new("two_panels");
    let room_m = g.add_material(Material::grey("room", 0.6));
    let warm = g.add_material(Material::grey("warm", 0.8).emitting([1.0, 0.8, 0.6], 15.0));
    let cool = g.add_material(Material::grey("cool", 0.8).emitting([0.6, 0.8, 1.0], 15.0));
    let (min, max) = (Vec3::new(-2.0, 0.0, -2.0), Vec3::new(2.0, 3.0, 2.0));
    let mut room = Geometry::box_face(min, max, Face::PosX, 4, 3).flipped();
    for face in [Face::NegX, Face::PosY, Face::NegY, Face::PosZ, Face::NegZ] {
        room.append(&Geometry::box_face(min, max, face, 4, 3).flipped());
    }
    let mesh = g.add_mesh("room", room, room_m);
    let panel = |x: f32| {
        Geometry::grid(
            Vec3::new(x, 2.99, -0.25),
            Vec3::X * 0.5,
            Vec3::Z * 0.5,
            1,
            1,
        )
    };
    g.add_primitive(mesh, panel(-1.25), warm);
    g.add_primitive(mesh, panel(0.75), cool);
    g.add_mesh_node("room", mesh);
    g
}

/// One emissive material scaled among two: a fresh bake draws its light samples by the
/// emitters' new power, so it casts other rays than the kept bake did. The two then differ by
/// the Monte Carlo noise, not by a bias: measured against the difference of two fresh bakes
/// with different seeds (the noise of a bake compared with a bake).
#[test]
fn relit_emission_among_several_emitters_is_within_the_noise() {
    let dir = scratch();
    let input = dir.path().join("two_panels.gltf");
    two_panel_room().write_gltf(&input).unwrap();
    let kept_dir = dir.path().join("kept");
    bake(&input, &kept_dir, &kept_config(), &NoProgress).unwrap();
    let gltf = kept_dir.join("two_panels.gltf");
    let edits = Edits {
        emission: vec![("warm".into(), 4.0)],
        ..Default::default()
    };
    let relit_dir = dir.path().join("relit");
    relight(&gltf, &relit_dir, &edits, None, &NoProgress).unwrap();

    let edited_dir = dir.path().join("edited");
    std::fs::create_dir_all(&edited_dir).unwrap();
    let mut json: Value = serde_json::from_slice(&std::fs::read(&input).unwrap()).unwrap();
    let strength = &mut json["materials"][1]["extensions"]["KHR_materials_emissive_strength"]["emissiveStrength"];
    *strength = json!(strength.as_f64().unwrap() * 4.0);
    let edited = edited_dir.join("two_panels.gltf");
    std::fs::write(&edited, serde_json::to_vec(&json).unwrap()).unwrap();
    let mut config = kept::read(&gltf).unwrap().settings.config().unwrap();
    config.output.float = true;
    let fresh = |seed: u64, name: &str| {
        let out = dir.path().join(name);
        let mut c = config.clone();
        c.transport.seed = seed;
        bake(&edited, &out, &c, &NoProgress).unwrap();
        pages(&out, "two_panels")
    };
    let (a, b) = (fresh(0, "fresh"), fresh(1, "fresh_other_seed"));
    let relit = pages(&relit_dir, "two_panels");
    let (against_fresh, noise) = (page_difference(&relit, &a), page_difference(&b, &a));
    println!(
        "two panels, warm ×4: relit vs fresh {against_fresh:.2e}, fresh vs fresh (another seed) {noise:.2e}"
    );
    assert!(against_fresh > 1e-6, "the sampling should have changed");
    assert!(against_fresh < noise, "{against_fresh} vs noise {noise}");
}
