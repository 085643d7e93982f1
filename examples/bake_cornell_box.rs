//! Bakes the Cornell box fixture and renders its camera view.
//!
//!     cargo run --release --example bake_cornell_box [-- <output dir>]
//!
//! Writes the baked scene to `<dir>/cornell/` and the render to `<dir>/cornell.png`
//! (default dir: `target/examples-out`). The gallery image `examples/gallery/cornell.png` is
//! this render.

use std::path::{Path, PathBuf};
use std::time::Instant;

use lightbake::render::{RenderOptions, RenderScene};
use lightbake::{BakeConfig, NoProgress};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out: PathBuf = std::env::args()
        .nth(1)
        .map_or_else(|| root.join("target/examples-out"), PathBuf::from);
    let baked_dir = out.join("cornell");

    let t = Instant::now();
    let input = root.join("fixtures/cornell_box.gltf");
    let report = lightbake::bake(&input, &baked_dir, &BakeConfig::high(), &NoProgress)?;
    println!(
        "bake: {} ({:.2}s)",
        report.summary(),
        t.elapsed().as_secs_f64()
    );

    let scene = RenderScene::load(&baked_dir.join("cornell_box.gltf"))?;
    let camera = scene.camera(None, 1.0)?;
    let options = RenderOptions {
        width: 320,
        height: 320,
        spp: 16,
        ..RenderOptions::default()
    };
    let t = Instant::now();
    let image = scene.render(&camera, &options)?;
    println!(
        "render: 320x320, 16 spp, {:.2}s, {:.2} M rays, {} non-finite samples",
        t.elapsed().as_secs_f64(),
        image.rays as f64 * 1e-6,
        image.nonfinite
    );
    let png = out.join("cornell.png");
    image.save(&png, 0.0)?;
    println!("wrote {}", png.display());
    Ok(())
}
