//! A normal-mapped wall (`testing::normal_mapped_wall`: 6 × 4 domes in its `normalTexture`)
//! baked with directional lightmaps, rendered without and with them, side by side.
//!
//!     cargo run --release --example normal_mapped_wall [-- <output dir>]
//!
//! Writes `<dir>/normal_mapped_wall/` (the bake) and `<dir>/normal_mapped_wall.png` (left: the
//! lightmap alone — one value per texel, the bumps vanish; right: the L1 reconstruction at the
//! normal-mapped normal); default dir `target/examples-out`. The gallery image
//! `examples/gallery/normal_mapped_wall.png` is this render.

use std::path::{Path, PathBuf};
use std::time::Instant;

use lightbake::lightmap::directional;
use lightbake::render::{RenderOptions, RenderScene};
use lightbake::{BakeConfig, NoProgress};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out: PathBuf = std::env::args()
        .nth(1)
        .map_or_else(|| root.join("target/examples-out"), PathBuf::from);
    let work = out.join("normal_mapped_wall");
    std::fs::create_dir_all(&work)?;
    let input = work.join("normal_mapped_wall.gltf");
    lightbake::testing::normal_mapped_wall().write_gltf(&input)?;

    let mut config = BakeConfig::medium();
    config.output.directional = Some(directional::DEFAULT_RAYS);
    let t = Instant::now();
    let baked_dir = work.join("baked");
    let report = lightbake::bake(&input, &baked_dir, &config, &NoProgress)?;
    println!(
        "bake: {} ({:.2}s)",
        report.summary(),
        t.elapsed().as_secs_f64()
    );

    let mut scene = RenderScene::load(&baked_dir.join("normal_mapped_wall.gltf"))?;
    let camera = scene.camera(None, 1.0)?;
    let options = RenderOptions {
        width: 320,
        height: 320,
        spp: 16,
        ..RenderOptions::default()
    };
    let with = scene.render(&camera, &options)?;
    scene.ignore_directional();
    let without = scene.render(&camera, &options)?;
    let png = out.join("normal_mapped_wall.png");
    without.beside(&with).save(&png, 0.0)?;
    println!(
        "wrote {} (left: lightmap only, right: directional pages at the normal-mapped normal)",
        png.display()
    );
    Ok(())
}
