//! `lightbake compare`: a baked scene, read as a renderer reads it, against a point reference.

use std::path::PathBuf;

use anyhow::{Context, Result};
use lightbake::reference::points::{self, PointReference};
use lightbake::render::RenderScene;

/// Prints the point figures of a bake in one block.
#[derive(clap::Args)]
#[command(after_help = AFTER_HELP)]
pub struct Args {
    /// The baked scene (.gltf or .glb written by `lightbake bake`).
    baked: PathBuf,
    /// The point reference (CSV written by `lightbake reference SCENE --points N -o FILE`).
    #[arg(long)]
    points: PathBuf,
}

const AFTER_HELP: &str = "\
Reads the baked scene as `lightbake render` does (TEXCOORD_1 and the EXR page each primitive's
extras.lightmap names, bilinear lookup with texel centres, clamp-to-edge) at every reference
point and prints: relative RMSE √mean((x−r)²)/mean(r) over points and channels, also without
the reference's own noise; median and p95 of per-point relative errors (floored at 5% of the
mean); the fraction of lookups whose bilinear footprint touches a black texel where the
reference is not black; the overall bias; the reference's noise.
  lightbake reference scene.gltf --points 4096 --spp 4096 --target-error 0.01 -o points.csv
  lightbake compare baked/scene.gltf --points points.csv";

pub fn run(args: &Args) -> Result<()> {
    let text = std::fs::read_to_string(&args.points)
        .with_context(|| format!("reading {} failed", args.points.display()))?;
    let reference = PointReference::from_csv(&text, &args.points)?;
    let baked = RenderScene::load(&args.baked)
        .with_context(|| format!("loading {} failed", args.baked.display()))?;
    let c = points::compare(&baked, &reference);
    println!("{}", c.summary());
    Ok(())
}
