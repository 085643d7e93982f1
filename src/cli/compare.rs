//! `lightbake compare`: a baked scene, read as a renderer reads it, against a point reference.

use std::path::PathBuf;

use anyhow::{Context, Result};
use glam::Vec3;
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
    /// Only the points in a strip beside a plane: "x,y,z,nx,ny,nz,width" — a point of the
    /// plane, its normal towards the side measured, the strip's width; points on surfaces
    /// parallel to the plane are left out (the junction strip along a wall).
    #[arg(long, value_name = "X,Y,Z,NX,NY,NZ,W")]
    strip: Option<String>,
}

const AFTER_HELP: &str = "\
Reads the baked scene as `lightbake render` does (TEXCOORD_1 and the EXR page each primitive's
extras.lightmap names, bilinear lookup with texel centres, clamp-to-edge) at every reference
point and prints: relative RMSE √mean((x−r)²)/mean(r) over points and channels, also without
the reference's own noise; median and p95 of per-point relative errors (floored at 5% of the
mean); the fraction of lookups whose bilinear footprint touches a black texel where the
reference is not black; the overall bias; the reference's noise.
  lightbake reference scene.gltf --points 4096 --spp 4096 --target-error 0.01 -o points.csv
  lightbake compare baked/scene.gltf --points points.csv
  lightbake compare baked/two_rooms.gltf --points points.csv --strip 0,0,0,1,0,0,0.125";

pub fn run(args: &Args) -> Result<()> {
    let text = std::fs::read_to_string(&args.points)
        .with_context(|| format!("reading {} failed", args.points.display()))?;
    let mut reference = PointReference::from_csv(&text, &args.points)?;
    if let Some(strip) = &args.strip {
        let v: Vec<f32> = strip
            .split(',')
            .map(|x| x.trim().parse::<f32>())
            .collect::<std::result::Result<_, _>>()
            .context("--strip takes seven numbers: x,y,z,nx,ny,nz,width")?;
        let [x, y, z, nx, ny, nz, width] = v[..] else {
            anyhow::bail!("--strip takes seven numbers: x,y,z,nx,ny,nz,width");
        };
        reference = reference.in_strip(Vec3::new(x, y, z), Vec3::new(nx, ny, nz), width);
    }
    let baked = RenderScene::load(&args.baked)
        .with_context(|| format!("loading {} failed", args.baked.display()))?;
    let c = points::compare(&baked, &reference);
    println!("{}", c.summary());
    Ok(())
}
