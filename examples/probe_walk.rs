//! A ball walks from the lit room of `fixtures/two_rooms.gltf`, through the doorway, into the
//! room the first one lights: the ball is not in the bake, so only the bake's light probes
//! light it, as an engine lights what moves.
//!
//!     cargo run --release --example probe_walk [-- <output dir>]
//!
//! Bakes the fixture at `medium` with `--probes` (the default budget), then for each of six
//! positions writes a copy of the baked glTF with a grey ball added (a mesh without
//! `TEXCOORD_1` or a lightmap), renders it from a fixed camera in the second room, and prints
//! the probes' light at the ball's top and side. Writes `<dir>/probe_walk/` (the bake and the
//! frames' glTFs) and `<dir>/probe_walk.png` (the frames side by side); default dir
//! `target/examples-out`. The gallery image `examples/gallery/probe_walk.png` is this render.
//! The ball casts no shadow: the lightmaps were baked without it (what real-time shadows of
//! the moving object would add is the engine's).

use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::Vec3;
use lightbake::render::{Image, RenderOptions, RenderScene};
use lightbake::scene::Camera;
use lightbake::testing::{Geometry, GltfBuilder, Material};
use lightbake::{BakeConfig, NoProgress};
use serde_json::Value;

/// The ball's radius (m); it rolls along the floor at z = 0, through the doorway (x = 0,
/// |z| < 0.4, up to 1.6 m).
const RADIUS: f32 = 0.3;
const PATH_X: [f32; 6] = [-1.4, -0.9, -0.4, 0.1, 0.6, 1.1];

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out: PathBuf = std::env::args()
        .nth(1)
        .map_or_else(|| root.join("target/examples-out"), PathBuf::from);
    let work = out.join("probe_walk");
    let baked_dir = work.join("baked");
    std::fs::create_dir_all(&baked_dir)?;

    let mut config = BakeConfig::medium();
    config.output.probes = Some(lightbake::probes::ProbeParams::default());
    let t = Instant::now();
    let report = lightbake::bake(
        &root.join("fixtures/two_rooms.gltf"),
        &baked_dir,
        &config,
        &NoProgress,
    )?;
    println!(
        "bake: {} ({:.2}s)",
        report.summary(),
        t.elapsed().as_secs_f64()
    );

    let baked: Value = serde_json::from_slice(&std::fs::read(baked_dir.join("two_rooms.gltf"))?)?;
    let camera = Camera::look_at(Vec3::new(1.85, 1.0, 0.0), Vec3::new(-1.5, 0.45, 0.0), 1.0);
    let options = RenderOptions {
        width: 200,
        height: 200,
        spp: 16,
        ..RenderOptions::default()
    };
    println!("| ball at x | probes' H/π at its top | at its side facing the camera | render s |");
    println!("|---:|---:|---:|---:|");
    let mut strip: Option<Image> = None;
    for (k, x) in PATH_X.into_iter().enumerate() {
        let centre = Vec3::new(x, RADIUS, 0.0);
        // Beside the bake's files, so the frame's relative URIs (pages, probes) resolve.
        let frame = baked_dir.join(format!("frame_{k}.gltf"));
        std::fs::write(&frame, with_ball(&baked, centre)?)?;
        let scene = RenderScene::load(&frame)?;
        let probes = scene.probes.as_ref().ok_or("the bake has no probes")?;
        let grey = |v: Vec3| v.element_sum() / 3.0;
        let top =
            probes.irradiance_over_pi(centre + Vec3::Y * RADIUS, Vec3::Y, Some(&scene.tracer));
        let side =
            probes.irradiance_over_pi(centre + Vec3::X * RADIUS, Vec3::X, Some(&scene.tracer));
        let t = Instant::now();
        let image = scene.render(&camera, &options)?;
        println!(
            "| {x:.1} | {:.3} | {:.3} | {:.2} |",
            grey(top),
            grey(side),
            t.elapsed().as_secs_f64()
        );
        strip = Some(match strip {
            Some(s) => s.beside(&image),
            None => image,
        });
    }
    let png = out.join("probe_walk.png");
    strip.ok_or("no frames")?.save(&png, 0.0)?;
    println!("wrote {}", png.display());
    Ok(())
}

/// The baked glTF `baked` with a grey ball at `centre` added (`testing::add_to_gltf`).
fn with_ball(baked: &Value, centre: Vec3) -> Result<Vec<u8>, Box<dyn std::error::Error>> {
    let mut ball = GltfBuilder::new("ball");
    let grey = ball.add_material(Material::grey("ball", 0.7));
    let mesh = ball.add_mesh("ball", Geometry::uv_sphere(centre, RADIUS, 32, 16), grey);
    ball.add_mesh_node("ball", mesh);
    let mut json = baked.clone();
    lightbake::testing::add_to_gltf(&mut json, &ball)?;
    Ok(serde_json::to_vec_pretty(&json)?)
}
