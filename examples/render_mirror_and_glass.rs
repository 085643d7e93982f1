//! A room with a mirror panel, a polished metal floor strip and a glass block,
//! baked and rendered with and without the ray-traced specular layer, side by side.
//!
//!     cargo run --release --example render_mirror_and_glass [-- <output dir>]
//!
//! The scene is built with `lightbake::testing::GltfBuilder`; metallic, roughness and the glass
//! (KHR_materials_transmission, KHR_materials_ior, KHR_materials_volume) are added to the
//! glTF JSON afterwards, since the builder writes only Lambertian materials. Writes
//! `<dir>/mirror_and_glass/` (the bake) and `<dir>/mirror_and_glass.png` (left: lightmap only,
//! right: with `specular`); default dir `target/examples-out`. The gallery image
//! `examples/gallery/mirror_and_glass.png` is this render.

use std::path::{Path, PathBuf};
use std::time::Instant;

use base64::Engine;
use glam::Vec3;
use lightbake::render::{RenderOptions, RenderScene};
use lightbake::testing::{Camera, Face, Geometry, GltfBuilder, Light, Material};
use lightbake::{BakeConfig, NoProgress};
use serde_json::{Value, json};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out: PathBuf = std::env::args()
        .nth(1)
        .map_or_else(|| root.join("target/examples-out"), PathBuf::from);
    let work = out.join("mirror_and_glass");
    std::fs::create_dir_all(&work)?;

    let input = work.join("mirror_and_glass_input.gltf");
    std::fs::write(&input, scene_json()?)?;
    let t = Instant::now();
    let baked_dir = work.join("baked");
    let report = lightbake::bake(&input, &baked_dir, &BakeConfig::medium(), &NoProgress)?;
    println!(
        "bake: {} ({:.2}s)",
        report.summary(),
        t.elapsed().as_secs_f64()
    );

    let scene = RenderScene::load(&baked_dir.join("mirror_and_glass_input.gltf"))?;
    let camera = scene.camera(None, 1.0)?;
    let mut images = Vec::new();
    for specular in [false, true] {
        let options = RenderOptions {
            width: 320,
            height: 320,
            spp: 16,
            specular,
            ..RenderOptions::default()
        };
        let t = Instant::now();
        let image = scene.render(&camera, &options)?;
        println!(
            "render{}: 320x320, 16 spp, {:.2}s, {:.2} M rays, {} non-finite samples",
            if specular { " --specular" } else { "" },
            t.elapsed().as_secs_f64(),
            image.rays as f64 * 1e-6,
            image.nonfinite
        );
        images.push(image);
    }
    let png = out.join("mirror_and_glass.png");
    images[0].beside(&images[1]).save(&png, -0.7)?;
    println!(
        "wrote {} (left: lightmap only, right: --specular)",
        png.display()
    );
    Ok(())
}

/// A 3 × 2.5 × 3 m room open towards the camera (which stands in the opening), lit by a
/// point light; a mirror on the left
/// wall, a polished (roughness 0.25) metal strip on the floor, a glass block on a grey plinth.
fn scene_json() -> Result<Vec<u8>, Box<dyn std::error::Error>> {
    let mut g = GltfBuilder::new("mirror_and_glass");
    let white = g.add_material(Material::grey("white", 0.75));
    let blue = g.add_material(Material::diffuse("blue", [0.15, 0.25, 0.6]));
    let orange = g.add_material(Material::diffuse("orange", [0.8, 0.4, 0.1]));
    let mirror = g.add_material(Material::grey("mirror", 0.9));
    let metal = g.add_material(Material::diffuse("brushed_gold", [0.9, 0.7, 0.35]));
    let glass = g.add_material(Material::diffuse("glass", [0.92, 0.97, 0.95]));

    let (min, max) = (Vec3::new(-1.5, 0.0, -1.5), Vec3::new(1.5, 2.5, 1.5));
    let mut room = Geometry::box_face(min, max, Face::NegY, 6, 6).flipped();
    room.append(&Geometry::box_face(min, max, Face::PosY, 6, 6).flipped());
    room.append(&Geometry::box_face(min, max, Face::NegZ, 6, 5).flipped());
    let room_mesh = g.add_mesh("room", room, white);
    g.add_primitive(
        room_mesh,
        Geometry::box_face(min, max, Face::NegX, 6, 5).flipped(),
        blue,
    );
    g.add_primitive(
        room_mesh,
        Geometry::box_face(min, max, Face::PosX, 6, 5).flipped(),
        orange,
    );
    g.add_mesh_node("room", room_mesh);

    // Mirror on the left wall (faces +x), a hand's width off the wall.
    let m = Geometry::grid(
        Vec3::new(-1.49, 0.4, 0.6),
        Vec3::Z * -2.0,
        Vec3::Y * 1.7,
        1,
        1,
    );
    let m = g.add_mesh("mirror", m, mirror);
    g.add_mesh_node("mirror", m);
    // A glossy metal strip on the floor in front of the back wall.
    let strip = Geometry::grid(
        Vec3::new(-1.2, 0.005, -0.7),
        Vec3::X * 2.4,
        Vec3::Z * -0.6,
        4,
        1,
    );
    let strip = g.add_mesh("strip", strip, metal);
    g.add_mesh_node("strip", strip);
    // A plinth and a glass block on it.
    let plinth = Geometry::box_faces(
        Vec3::new(0.2, 0.0, -0.3),
        Vec3::new(0.9, 0.3, 0.4),
        &Face::NO_BOTTOM,
        2,
    );
    let plinth = g.add_mesh("plinth", plinth, white);
    g.add_mesh_node("plinth", plinth);
    let block = Geometry::box_faces(
        Vec3::new(0.3, 0.3, -0.2),
        Vec3::new(0.8, 1.0, 0.3),
        &Face::ALL,
        1,
    );
    let block = g.add_mesh("glass_block", block, glass);
    g.add_mesh_node("glass_block", block);
    // An orange-blue box behind the glass, to be seen through it.
    let boxy = Geometry::box_faces(
        Vec3::new(0.45, 0.0, -1.2),
        Vec3::new(0.75, 0.9, -0.9),
        &Face::NO_BOTTOM,
        2,
    );
    let boxy = g.add_mesh("box", boxy, orange);
    g.add_mesh_node("box", boxy);
    // A point light: direct light from punctual lights is exact in the bake, so the render shows
    // the specular layer rather than sampling noise of a large emitter.
    let lamp = Light::point("lamp", [1.0, 0.93, 0.8], 6.0);
    g.add_light_node(lamp, Vec3::new(-0.2, 2.2, 0.3), -Vec3::Y);
    let camera = Camera::perspective("camera", 70f32.to_radians(), Some(1.0));
    g.add_camera_node(
        camera,
        Vec3::new(0.9, 1.4, 1.45),
        Vec3::new(-0.1, 0.8, -0.8),
    );

    let (mut json, bin) = g.to_gltf_json();
    set_material(&mut json, "mirror", 1.0, 0.0, Value::Null);
    set_material(&mut json, "brushed_gold", 1.0, 0.25, Value::Null);
    let glass_ext = json!({
        "KHR_materials_transmission": { "transmissionFactor": 1.0 },
        "KHR_materials_ior": { "ior": 1.5 },
        "KHR_materials_volume": { "thicknessFactor": 0.5, "attenuationColor": [0.75, 0.92, 0.88], "attenuationDistance": 0.6 }
    });
    set_material(&mut json, "glass", 0.0, 0.0, glass_ext);
    let used = json["extensionsUsed"]
        .as_array()
        .cloned()
        .unwrap_or_default();
    let mut used: Vec<Value> = used;
    for e in [
        "KHR_materials_transmission",
        "KHR_materials_ior",
        "KHR_materials_volume",
    ] {
        used.push(json!(e));
    }
    json["extensionsUsed"] = Value::Array(used);
    json["buffers"][0]["uri"] = json!(format!(
        "data:application/octet-stream;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(&bin)
    ));
    Ok(serde_json::to_vec_pretty(&json)?)
}

fn set_material(json: &mut Value, name: &str, metallic: f32, roughness: f32, extensions: Value) {
    let materials = json["materials"].as_array_mut().expect("materials");
    let m = materials
        .iter_mut()
        .find(|m| m["name"] == name)
        .expect("material");
    m["pbrMetallicRoughness"]["metallicFactor"] = json!(metallic);
    m["pbrMetallicRoughness"]["roughnessFactor"] = json!(roughness);
    if extensions.is_object() {
        m["extensions"] = extensions;
    }
}
