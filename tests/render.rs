//! `render`: lightmap lookup against an analytic answer, the mirror and its Fresnel factor, depth
//! limit and energy of the specular tree, finiteness, determinism, refusal of unbaked scenes.

use std::f32::consts::PI;
use std::path::{Path, PathBuf};

use base64::Engine;
use glam::Vec3;
use lightbake::reference::{self, ReferenceParams};
use lightbake::render::{Camera, RenderOptions, RenderScene};
use lightbake::sampling::Rng;
use lightbake::testing::{Face, Geometry, GltfBuilder, Light, Material};
use lightbake::{NoProgress, bake, metrics};
use serde_json::{Value, json};

use crate::util::{fixture, quick, scratch};

/// Writes `builder` as a self-contained .gltf after `edit` changed its JSON (materials the
/// builder cannot express: metallic, roughness, transmission), bakes it at draft settings into
/// `dir/baked/` and returns the baked glTF's path.
fn bake_scene(dir: &Path, builder: &GltfBuilder, edit: impl Fn(&mut Value)) -> PathBuf {
    let (mut json, bin) = builder.to_gltf_json();
    edit(&mut json);
    json["buffers"][0]["uri"] = json!(format!(
        "data:application/octet-stream;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(&bin)
    ));
    let input = dir.join("scene.gltf");
    std::fs::write(&input, serde_json::to_vec(&json).unwrap()).unwrap();
    let out = dir.join("baked");
    bake(&input, &out, &quick(), &NoProgress).unwrap();
    out.join("scene.gltf")
}

/// Sets metallic/roughness (and any extensions) of the material named `name`.
fn set_material(json: &mut Value, name: &str, metallic: f32, roughness: f32, extensions: Value) {
    let materials = json["materials"].as_array_mut().unwrap();
    let m = materials.iter_mut().find(|m| m["name"] == name).unwrap();
    m["pbrMetallicRoughness"]["metallicFactor"] = json!(metallic);
    m["pbrMetallicRoughness"]["roughnessFactor"] = json!(roughness);
    if extensions.is_object() {
        m["extensions"] = extensions;
    }
}

const MIRROR_F0: f32 = 0.8;

/// A grey wall (ρ 0.5) at z = 0 facing +z, lit by a point light; a mirror at z = 3 facing it
/// (baseColor 0.8, metallic 1, roughness 0); optionally a second mirror on the wall, so rays
/// bounce between the two until the depth limit.
fn mirror_scene(dir: &Path, facing_mirrors: bool) -> PathBuf {
    let mut g = GltfBuilder::new("mirror");
    let wall_m = g.add_material(Material::grey("wall", 0.5));
    let mirror_m = g.add_material(Material::grey("mirror", MIRROR_F0));
    let wall = Geometry::grid(
        Vec3::new(-2.0, 0.0, 0.0),
        Vec3::X * 4.0,
        Vec3::Y * 3.0,
        4,
        3,
    );
    let wall = g.add_mesh("wall", wall, wall_m);
    g.add_mesh_node("wall", wall);
    // Y × X = −Z: faces the wall.
    let mirror = Geometry::grid(
        Vec3::new(-1.0, 0.5, 3.0),
        Vec3::Y * 2.0,
        Vec3::X * 2.0,
        2,
        2,
    );
    let mirror = g.add_mesh("mirror", mirror, mirror_m);
    g.add_mesh_node("mirror", mirror);
    if facing_mirrors {
        let back = Geometry::grid(Vec3::new(-0.5, 1.0, 0.01), Vec3::X, Vec3::Y, 1, 1);
        let back = g.add_mesh("back_mirror", back, mirror_m);
        g.add_mesh_node("back_mirror", back);
    }
    g.add_light_node(
        Light::point("lamp", [1.0; 3], 10.0),
        Vec3::new(0.0, 2.5, 1.5),
        -Vec3::Y,
    );
    bake_scene(dir, &g, |json| {
        set_material(json, "mirror", 1.0, 0.0, Value::Null)
    })
}

/// Looks from between wall and mirror straight at the mirror.
fn mirror_camera() -> Camera {
    Camera::look_at(
        Vec3::new(0.0, 1.5, 1.0),
        Vec3::new(0.0, 1.5, 3.0),
        20f32.to_radians(),
    )
}

fn options(size: u32, specular: bool) -> RenderOptions {
    RenderOptions {
        width: size,
        height: size,
        spp: 16,
        specular,
        ..RenderOptions::default()
    }
}

#[test]
fn lightmap_lookup_matches_the_analytic_point_light() {
    // A lone grey floor under a point light: lightmap = I cos³θ/(π d²), radiance = ρ × that.
    let dir = scratch();
    let mut g = GltfBuilder::new("floor");
    let m = g.add_material(Material::grey("floor", 0.5));
    let floor = Geometry::grid(
        Vec3::new(-2.0, 0.0, 2.0),
        Vec3::X * 4.0,
        -Vec3::Z * 4.0,
        8,
        8,
    );
    let floor = g.add_mesh("floor", floor, m);
    g.add_mesh_node("floor", floor);
    g.add_light_node(
        Light::point("lamp", [1.0; 3], 10.0),
        Vec3::Y * 2.0,
        -Vec3::Y,
    );
    let scene = RenderScene::load(&bake_scene(dir.path(), &g, |_| {})).unwrap();
    let eye = Vec3::new(0.3, 1.0, 0.8);
    let mut rng = Rng::new(0, 0, 0);
    // Targets off the triangle edges (rays through shared edges can miss; see the report).
    for target in [
        Vec3::new(0.1, 0.0, 0.1),
        Vec3::new(0.7, 0.0, 0.3),
        Vec3::new(-1.2, 0.0, -0.9),
    ] {
        let l = scene.radiance(
            eye,
            (target - eye).normalize(),
            &options(1, false),
            &mut rng,
        );
        let d2 = 4.0 + target.length_squared();
        let expected = 0.5 * 10.0 * (2.0 / d2.sqrt()).powi(3) / (PI * 4.0);
        let error = (l.x - expected).abs() / expected;
        assert!(error < 0.02, "at {target}: {l} vs {expected} ({error:.4})");
    }
}

#[test]
fn a_mirror_shows_the_wall_times_its_reflectance() {
    let dir = scratch();
    let scene = RenderScene::load(&mirror_scene(dir.path(), false)).unwrap();
    let camera = mirror_camera();
    let size = 65; // The centre pixel is centred on the optical axis.
    let image = scene.render(&camera, &options(size, true)).unwrap();
    let centre = image.rgb[(size / 2 * size + size / 2) as usize];
    // The wall point seen through the mirror: straight back along the axis, at z = 0.
    let mut rng = Rng::new(0, 0, 0);
    let wall = scene.radiance(
        Vec3::new(0.0, 1.5, 2.9),
        -Vec3::Z,
        &options(1, false),
        &mut rng,
    );
    assert!(wall.x > 0.01, "the wall is lit: {wall}");
    let expected = wall * MIRROR_F0; // Schlick at normal incidence is F0.
    let error = ((centre - expected).abs() / expected).max_element();
    println!("mirror: centre pixel {centre}, wall {wall} × {MIRROR_F0}: relative error {error:.5}");
    assert!(error < 0.01, "{centre} vs {expected} ({error:.4})");

    // Without the specular layer the mirror is just its baked Lambertian self.
    let flat = scene.render(&camera, &options(size, false)).unwrap();
    let flat_centre = flat.rgb[(size / 2 * size + size / 2) as usize];
    assert!((flat_centre - centre).abs().max_element() > 0.05 * expected.x);
}

#[test]
fn deeper_trees_add_less_and_never_exceed_the_energy_bound() {
    let dir = scratch();
    let scene = RenderScene::load(&mirror_scene(dir.path(), true)).unwrap();
    // Every tree value is a convex combination of leaf values L_d + Le (no emitters here):
    // the brightest baked radiance bounds every pixel at every depth.
    let max_lightmap = scene
        .pages
        .iter()
        .flat_map(|p| &p.rgb)
        .fold(0.0f32, |m, v| m.max(v.max_element()));
    let max_base_color = MIRROR_F0.max(0.5); // mirror and wall
    let bound = max_lightmap * max_base_color;
    let camera = mirror_camera();
    let images: Vec<Vec<Vec3>> = (0..=8)
        .map(|depth| {
            let o = RenderOptions {
                max_depth: depth,
                spp: 4,
                ..options(24, true)
            };
            let image = scene.render(&camera, &o).unwrap();
            assert_eq!(image.nonfinite, 0);
            image.rgb
        })
        .collect();
    for (depth, image) in images.iter().enumerate() {
        let max = image.iter().fold(0.0f32, |m, v| m.max(v.max_element()));
        assert!(max <= bound * 1.0001, "depth {depth}: {max} > {bound}");
    }
    let change = |d: usize| {
        images[d]
            .iter()
            .zip(&images[d + 1])
            .fold(0.0f32, |m, (a, b)| m.max((*a - *b).abs().max_element()))
    };
    let changes: Vec<f32> = (0..8).map(change).collect();
    println!("largest pixel change from depth d to d+1: {changes:?}");
    assert!(changes[2] > 0.0, "the facing mirrors must make deep trees");
    for (d, &change) in changes.iter().enumerate() {
        // What depth d + 1 adds is seen through d mirror reflections (Schlick ≈ F0 = 0.8 at
        // these near-normal angles), and the leaves alternate between the two mirrors, so the
        // change also shrinks from d − 2 to d by about F0².
        let through_mirrors = 0.81f32.powi(d as i32) * bound;
        assert!(change <= through_mirrors, "depth {d}: {changes:?}");
        if d >= 2 {
            assert!(change <= changes[d - 2] * 0.8, "depth {d}: {changes:?}");
        }
    }
}

/// A grey room with a glossy metal floor and a glass block: every branch of the tree.
fn glass_scene(dir: &Path) -> PathBuf {
    let mut g = GltfBuilder::new("glass");
    let walls_m = g.add_material(Material::diffuse("walls", [0.7, 0.6, 0.5]));
    let floor_m = g.add_material(Material::grey("floor", 0.6));
    let glass_m = g.add_material(Material::diffuse("glass", [0.95, 0.97, 1.0]));
    let light_m = g.add_material(Material::grey("light", 0.5).emitting([1.0; 3], 10.0));
    let (min, max) = (Vec3::new(-1.0, 0.0, -1.0), Vec3::new(1.0, 2.0, 1.0));
    let mut room = Geometry::box_face(min, max, Face::PosY, 2, 2).flipped();
    for face in [Face::PosX, Face::NegX, Face::NegZ] {
        room.append(&Geometry::box_face(min, max, face, 2, 2).flipped());
    }
    let room = g.add_mesh("room", room, walls_m);
    g.add_mesh_node("room", room);
    let floor = Geometry::box_face(min, max, Face::NegY, 4, 4).flipped();
    let floor = g.add_mesh("floor", floor, floor_m);
    g.add_mesh_node("floor", floor);
    let block = Geometry::box_faces(
        Vec3::new(-0.3, 0.0, -0.3),
        Vec3::new(0.3, 0.6, 0.3),
        &Face::ALL,
        1,
    );
    let block = g.add_mesh("block", block, glass_m);
    g.add_mesh_node("block", block);
    let light = Geometry::grid(
        Vec3::new(-0.25, 1.99, -0.25),
        Vec3::Z * 0.5,
        Vec3::X * 0.5,
        1,
        1,
    );
    let light = g.add_mesh("light", light, light_m);
    g.add_mesh_node("light", light);
    bake_scene(dir, &g, |json| {
        set_material(json, "floor", 1.0, 0.3, Value::Null);
        let glass = json!({
            "KHR_materials_transmission": { "transmissionFactor": 1.0 },
            "KHR_materials_ior": { "ior": 1.5 },
            "KHR_materials_volume": { "attenuationColor": [0.8, 0.9, 1.0], "attenuationDistance": 0.5 }
        });
        set_material(json, "glass", 0.0, 0.0, glass);
    })
}

#[test]
fn glass_and_glossy_renders_are_finite_and_deterministic() {
    let dir = scratch();
    let scene = RenderScene::load(&glass_scene(dir.path())).unwrap();
    let camera = Camera::look_at(
        Vec3::new(0.4, 1.0, 2.5),
        Vec3::new(0.0, 0.3, 0.0),
        50f32.to_radians(),
    );
    let o = RenderOptions {
        spp: 4,
        ..options(40, true)
    };
    let a = scene.render(&camera, &o).unwrap();
    let b = scene.render(&camera, &o).unwrap();
    assert_eq!(a.nonfinite, 0);
    assert!(
        a.rgb
            .iter()
            .all(|v| v.is_finite() && v.min_element() >= 0.0)
    );
    assert_eq!(a.rgb, b.rgb, "same seed, same image");
    let c = scene
        .render(
            &camera,
            &RenderOptions {
                seed: 1,
                ..o.clone()
            },
        )
        .unwrap();
    assert_ne!(a.rgb, c.rgb, "glossy sampling and jitter follow the seed");
    // The glass block changes the picture only through the specular layer.
    let flat = scene
        .render(
            &camera,
            &RenderOptions {
                specular: false,
                ..o
            },
        )
        .unwrap();
    assert_ne!(a.rgb, flat.rgb);
    let png = dir.path().join("glass.png");
    a.save(&png, 0.0).unwrap();
    let exr = dir.path().join("glass.exr");
    a.save(&exr, 0.0).unwrap();
    let back = lightbake::output::read_exr(&exr).unwrap();
    assert_eq!(back.rgb, a.rgb);
}

#[test]
fn unbaked_scenes_are_refused() {
    let error = RenderScene::load(&fixture("cornell_box.gltf"))
        .err()
        .expect("an unbaked scene must be refused")
        .to_string();
    assert!(error.contains("lightbake bake"), "{error}");
}

/// The path tracer's `size × size` image of `camera`'s view of a prepared scene, `paths` per
/// pixel (64 per pass), with the sky and seed of `config`.
fn reference_view(
    prepared: &reference::Prepared,
    config: &lightbake::BakeConfig,
    camera: &Camera,
    size: u32,
    paths: u32,
) -> reference::View {
    let params = ReferenceParams {
        max_samples: paths,
        samples_per_pass: 64,
        ..ReferenceParams::like(config)
    };
    let view = reference::trace_view(
        &prepared.scene,
        &prepared.texels,
        &prepared.tracer,
        camera,
        size,
        size,
        &params,
        &NoProgress,
    )
    .unwrap();
    println!("reference view: {}", view.summary());
    view
}

/// Relative RMS difference `√(Σ‖a−r‖²/Σ‖r‖²)` and relative reference noise `√(Σ‖σ‖²/Σ‖r‖²)`
/// over the pixels not in `skip`, after averaging `block × block` pixel blocks (blocks with a
/// skipped pixel are left out; σ² of a block mean is Σσ² over the block / pixels²).
fn image_error(
    size: u32,
    render: &[Vec3],
    reference: &[Vec3],
    std_error: &[Vec3],
    skip: &[bool],
    block: u32,
) -> (f64, f64) {
    let (mut a, mut r, mut se) = (Vec::new(), Vec::new(), Vec::new());
    for by in 0..size / block {
        for bx in 0..size / block {
            let pixels: Vec<usize> = (by * block..(by + 1) * block)
                .flat_map(|y| (bx * block..(bx + 1) * block).map(move |x| (y * size + x) as usize))
                .collect();
            if pixels.iter().any(|&i| skip[i]) {
                continue;
            }
            let k = pixels.len() as f32;
            let mean = |v: &[Vec3]| pixels.iter().map(|&i| v[i]).sum::<Vec3>() / k;
            a.push(mean(render));
            r.push(mean(reference));
            let var: Vec3 = pixels
                .iter()
                .map(|&i| std_error[i] * std_error[i])
                .sum::<Vec3>()
                / (k * k);
            se.push(var.map(f32::sqrt));
        }
    }
    (
        metrics::rmse_over_rms(&a, &r, &[]) as f64,
        metrics::noise_over_rms(&se, &r, &[]) as f64,
    )
}

/// Issue 5: the lightmapped view of the Cornell box (no `--specular`) against a path-traced
/// image of the same view from the reference's camera mode ([`reference::trace_view`]).
///
/// Bake at the high preset (32 texels/m, 1024 gathering rays: the lightmap's own error is small),
/// render 48×48 at 64 stratified spp (anti-aliasing converged), path-trace the same camera at
/// 1024 paths per pixel. Pixels that see the ceiling light are left out (20 of 2304: both images
/// add the same `Le` there, which is ~20× the walls and would swamp the norm; their anti-aliased
/// edges are pure sampling noise of a bright emitter). On the others, relative RMS difference
/// `√(Σ‖render−ref‖²/Σ‖ref‖²)` and the reference's relative noise `√(Σσ²/Σ‖ref‖²)`:
///
/// | compared at           | relative RMSE | reference noise | bias √(RMSE²−noise²) |
/// |-----------------------|---------------|-----------------|----------------------|
/// | pixels                | 2.79 %        | 2.25 %          | 1.65 %               |
/// | 2×2 pixel blocks      | 1.60 %        | 1.14 %          | 1.12 %               |
/// | 4×4 pixel blocks      | 0.93 %        | 0.57 %          | 0.73 %               |
/// | (medium preset, pixels) | 4.08 %      | 2.25 %          | 3.40 %               |
///
/// The bias that remains is the lightmap's: texel-sized discretisation and bilinear lookup at
/// shadow edges, corners and the light's rim (it halves from pixels to 4×4 blocks, so it sits on
/// edges, not on flat walls) and the bake's own transport error. The check is
/// `RMSE² ≤ 1.5·noise² + tol²` with `tol` 2.5 % at pixel level and 2 % on 2×2 blocks (the 1.5
/// allows for the estimated σ's own scatter); the same check fails for the render of a lightmap
/// scaled by 1.2 (19.6 % RMSE) and by 1.05 (≈5 %). Runtime ≈ 3 s bake + 7 s reference in release.
#[test]
fn renders_match_the_reference_path_tracer() {
    const SIZE: u32 = 48;
    let dir = scratch();
    let input = fixture("cornell_box.gltf");
    let config = lightbake::BakeConfig::high();
    bake(&input, dir.path(), &config, &NoProgress).unwrap();
    let mut scene = RenderScene::load(&dir.path().join("cornell_box.gltf")).unwrap();
    let camera = scene.camera(None, 1.0).unwrap(); // the fixture's glTF camera
    let o = RenderOptions {
        spp: 64,
        ..options(SIZE, false)
    };
    let image = scene.render(&camera, &o).unwrap();

    let prepared = reference::prepare(&input, &config, &NoProgress).unwrap();
    let view = reference_view(&prepared, &config, &camera, SIZE, 1024);

    // Pixels that see the emitter: those the render shows lit with every lightmap black.
    let pages = scene.pages.clone();
    let with_lightmaps = |scene: &mut RenderScene, scale: f32| {
        for (page, original) in scene.pages.iter_mut().zip(&pages) {
            for (v, o) in page.rgb.iter_mut().zip(&original.rgb) {
                *v = *o * scale;
            }
        }
    };
    with_lightmaps(&mut scene, 0.0);
    let emission = scene.render(&camera, &o).unwrap();
    let skip: Vec<bool> = emission.rgb.iter().map(|e| e.max_element() > 0.0).collect();
    let skipped = skip.iter().filter(|&&s| s).count();
    assert!(skipped > 0 && skipped < 100, "{skipped} emitter pixels");

    let check = |rgb: &[Vec3], label: &str| -> bool {
        let mut ok = true;
        for (block, tol) in [(1u32, 0.025f64), (2, 0.02)] {
            let (rmse, noise) = image_error(
                SIZE,
                rgb,
                &view.pixels.mean,
                &view.pixels.std_error,
                &skip,
                block,
            );
            let bound = (1.5 * noise * noise + tol * tol).sqrt();
            println!(
                "{label}, {block}×{block} blocks: relative RMSE {:.2}%, reference noise {:.2}%, bound {:.2}%",
                rmse * 100.0,
                noise * 100.0,
                bound * 100.0
            );
            ok &= rmse <= bound;
        }
        ok
    };
    assert!(
        check(&image.rgb, "render"),
        "the render does not match the reference"
    );
    assert!(view.pixels.rms_rel_error < 0.03, "reference too noisy");
    for scale in [1.2, 1.05] {
        with_lightmaps(&mut scene, scale);
        let wrong = scene.render(&camera, &o).unwrap();
        let label = format!("control: lightmap × {scale}");
        assert!(!check(&wrong.rgb, &label), "{label} passed the check");
    }
}

/// Issue 13: the bake writes a double-sided wall as two coplanar single-sided primitives (front
/// and back). `render` must cull the one seen from behind, as glTF's `"doubleSided": false`
/// asks; without culling the two z-fight and whole triangles of the wall show the other room.
///
/// The two-room scene's wall is seen from each room (the frame holds only wall, no doorway) and
/// compared with a path-traced image of the same camera: each side shows its own lightmap (the
/// means agree), the lit side has no dark pixel and the dark side no bright one.
#[test]
fn a_split_double_sided_wall_shows_each_side_its_own_lightmap() {
    const SIZE: u32 = 24;
    let dir = scratch();
    let baked = bake_scene(dir.path(), &lightbake::testing::two_rooms(), |_| {});
    let scene = RenderScene::load(&baked).unwrap();
    let prepared =
        reference::prepare(&dir.path().join("scene.gltf"), &quick(), &NoProgress).unwrap();
    let target = Vec3::new(0.0, 1.0, 0.7);
    let mut means = Vec::new();
    for (side, eye_x) in [("lit side (room A)", -1.0f32), ("dark side (room B)", 1.0)] {
        let camera = Camera::look_at(Vec3::new(eye_x, 1.0, 0.7), target, 30f32.to_radians());
        let image = scene.render(&camera, &options(SIZE, false)).unwrap();
        let view = reference_view(&prepared, &quick(), &camera, SIZE, 256);
        let luminance = |v: &Vec3| v.dot(Vec3::splat(1.0 / 3.0));
        let mean = |rgb: &[Vec3]| rgb.iter().map(luminance).sum::<f32>() / rgb.len() as f32;
        let (render_mean, reference_mean) = (mean(&image.rgb), mean(&view.pixels.mean));
        let (lo, hi) = image
            .rgb
            .iter()
            .map(luminance)
            .fold((f32::MAX, 0f32), |(lo, hi), l| (lo.min(l), hi.max(l)));
        println!(
            "{side}: render mean {render_mean:.4} (pixels {lo:.4}..{hi:.4}), reference mean {reference_mean:.4}"
        );
        assert!(
            (render_mean / reference_mean - 1.0).abs() < 0.15,
            "{side}: the render's mean is not the path-traced one"
        );
        assert!(
            lo > 0.5 * reference_mean && hi < 2.0 * reference_mean,
            "{side}: pixels from {lo} to {hi} around a mean of {reference_mean}"
        );
        means.push(render_mean);
    }
    assert!(
        means[0] > 4.0 * means[1],
        "the lit side is not brighter: {means:?}"
    );
}

/// Issue 13: adaptive sampling against uniform sampling at the same mean samples per pixel, on
/// the Cornell view (emitter included) against a path-traced image (512 paths per pixel), over
/// 4×4 pixel blocks; most of the uniform render's error is aliasing at edges and at the
/// emitter's outline. Measured at 64×64 (this test) and once at 256×256 (256 paths):
///
/// | 16 spp     | 64×64: RMSE, rays     | 256×256: RMSE, rays, seconds |
/// |------------|-----------------------|------------------------------|
/// | uniform    | 2.94 %, 65 536        | 0.91 %, 1.05 M, 0.27         |
/// | adaptive   | 1.92 %, 65 536        | 0.47 %, 0.75 M, 0.19         |
/// | reference noise | 0.65 %           | 0.38 %                       |
///
/// (uniform 64 spp: 0.98 % and 0.50 %; uniform 256 spp at 256×256: 0.38 %, 4.2 s.)
#[test]
fn adaptive_sampling_beats_uniform_sampling_at_equal_cost() {
    const SIZE: u32 = 64;
    let dir = scratch();
    let input = fixture("cornell_box.gltf");
    let config = lightbake::BakeConfig::high();
    bake(&input, dir.path(), &config, &NoProgress).unwrap();
    let scene = RenderScene::load(&dir.path().join("cornell_box.gltf")).unwrap();
    let camera = scene.camera(None, 1.0).unwrap();
    let prepared = reference::prepare(&input, &config, &NoProgress).unwrap();
    let view = reference_view(&prepared, &config, &camera, SIZE, 512);
    let everything = vec![false; (SIZE * SIZE) as usize];
    let mut results = Vec::new();
    for (label, spp, adaptive) in [
        ("uniform, 16 spp", 16, false),
        ("adaptive, 16 spp", 16, true),
        ("uniform, 64 spp", 64, false),
    ] {
        let o = RenderOptions {
            spp,
            adaptive,
            ..options(SIZE, false)
        };
        let start = std::time::Instant::now();
        let image = scene.render(&camera, &o).unwrap();
        let seconds = start.elapsed().as_secs_f64();
        let (rmse, noise) = image_error(
            SIZE,
            &image.rgb,
            &view.pixels.mean,
            &view.pixels.std_error,
            &everything,
            4,
        );
        println!(
            "{label}: relative RMSE {:.2}% over 4×4 blocks (reference noise {:.2}%), {} rays, {seconds:.3}s",
            rmse * 100.0,
            noise * 100.0,
            image.rays
        );
        results.push((rmse, image.rays));
    }
    let (uniform, adaptive) = (results[0], results[1]);
    assert!(adaptive.1 <= uniform.1, "adaptive sampling cast more rays");
    assert!(
        adaptive.0 < 0.75 * uniform.0,
        "adaptive sampling is not clearly better"
    );
}

/// A mesh lit by the probes reads them for itself, not through itself: a ball the bake never
/// saw, put into the baked two rooms, shades smoothly across its front. When each point's
/// visibility test counted the ball, every point lost the probes the ball hid from it (those
/// inside and behind it), and the shading jumped where one went behind.
#[test]
fn a_mesh_lit_by_probes_does_not_hide_them_from_itself() {
    let dir = scratch();
    let mut config = lightbake::BakeConfig::draft();
    config.output.probes = Some(lightbake::probes::ProbeParams::default());
    bake(&fixture("two_rooms.gltf"), dir.path(), &config, &NoProgress).unwrap();
    let baked = dir.path().join("two_rooms.gltf");
    let mut json: Value = serde_json::from_slice(&std::fs::read(&baked).unwrap()).unwrap();
    let (centre, radius) = (Vec3::new(-0.9, 0.6, 0.0), 0.3);
    let mut ball = GltfBuilder::new("ball");
    let grey = ball.add_material(Material::grey("ball", 0.7));
    let mesh = ball.add_mesh("ball", Geometry::uv_sphere(centre, radius, 32, 16), grey);
    ball.add_mesh_node("ball", mesh);
    lightbake::testing::add_to_gltf(&mut json, &ball).unwrap();
    let frame = dir.path().join("with_ball.gltf");
    std::fs::write(&frame, serde_json::to_vec(&json).unwrap()).unwrap();
    let scene = RenderScene::load(&frame).unwrap();
    assert!(scene.unlit_instances() >= 1, "the ball has no lightmap");

    // Down the ball's front, facing the second room (+x), from just above its bottom to just
    // below its top.
    let options = RenderOptions::default();
    let values: Vec<f32> = (0..=64)
        .map(|k| {
            let mut rng = Rng::new(0, 0, 0);
            let y = centre.y + radius * (0.9 - 1.8 * k as f32 / 64.0);
            let v = scene.radiance(Vec3::new(1.5, y, 0.01), Vec3::NEG_X, &options, &mut rng);
            v.element_sum() / 3.0
        })
        .collect();
    // The light falls steeply down the ball's front, so a jump is a kink in that fall: the
    // largest second difference, measured 0.8% of the peak with the ball ignored and 2.7%
    // when it hid probes from itself.
    let peak = values.iter().copied().fold(0.0f32, f32::max);
    let kink = values
        .windows(3)
        .map(|w| (w[2] - 2.0 * w[1] + w[0]).abs())
        .fold(0.0f32, f32::max);
    assert!(peak > 0.0, "the probes light the ball: {values:?}");
    assert!(
        kink < 0.015 * peak,
        "the shading kinks by {kink} (peak {peak}) between neighbouring points: {values:?}"
    );
}
