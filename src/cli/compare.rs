//! `lightbake compare`: a baked scene, read as a renderer reads it, against a point reference.

use std::path::PathBuf;

use anyhow::{Context, Result};
use glam::Vec3;
use lightbake::reference::points::{self, PointReference, Strip};
use lightbake::render::RenderScene;

/// Prints the point figures of a bake in one block (or, with --view, a rendered image's error).
#[derive(clap::Args)]
#[command(after_help = AFTER_HELP)]
pub struct Args {
    /// The baked scene (.gltf or .glb written by `lightbake bake`); with --view, the image
    /// `lightbake render` drew (.exr).
    baked: PathBuf,
    /// The point reference (CSV written by `lightbake reference SCENE --points N -o FILE`).
    #[arg(long, required_unless_present = "view")]
    points: Option<PathBuf>,
    /// A camera reference (.exr written by `lightbake reference SCENE --view -o FILE`, with its
    /// `<stem>_stderr.exr` beside it): prints the relative RMS difference of 4×4-pixel block
    /// means `√(Σ‖a−r‖²/Σ‖r‖²)` and the reference's own noise on the same blocks.
    #[arg(long, conflicts_with_all = ["points", "strip"])]
    view: Option<PathBuf>,
    /// Only the points in a strip beside a plane: "x,y,z,nx,ny,nz,width" — a point of the
    /// plane, its normal towards the side measured, the strip's width; points on surfaces
    /// parallel to the plane are left out (the junction strip along a wall).
    #[arg(long, value_name = "X,Y,Z,NX,NY,NZ,W")]
    strip: Option<Strip>,
}

const AFTER_HELP: &str = "\
Reads the baked scene as `lightbake render` does (TEXCOORD_1 and the EXR page each primitive's
extras.lightmap names, or its node's with the node's scale_offset for a mesh baked with
--instancing share; bilinear lookup with texel centres, clamp-to-edge) at every reference
point and prints: relative RMSE √mean((x−r)²)/mean(r) over points and channels, also without
the reference's own noise; median and p95 of per-point relative errors (floored at 5% of the
mean); the fraction of lookups whose bilinear footprint touches a black texel where the
reference is not black; the overall bias; the reference's noise.
  lightbake reference scene.gltf --points 4096 --spp 4096 --target-error 0.01 -o points.csv
  lightbake compare baked/scene.gltf --points points.csv
  lightbake compare baked/two_rooms.gltf --points points.csv --strip 0,0,0,1,0,0,0.125
  lightbake compare view.exr --view reference.exr";

pub fn run(args: &Args) -> Result<()> {
    if let Some(view) = &args.view {
        return compare_view(&args.baked, view);
    }
    let points = args.points.as_ref().context("--points is required")?;
    let text = std::fs::read_to_string(points)
        .with_context(|| format!("reading {} failed", points.display()))?;
    let mut reference = PointReference::from_csv(&text, points)?;
    if let Some(strip) = &args.strip {
        reference = reference.in_strip(strip);
    }
    let baked = RenderScene::load(&args.baked)
        .with_context(|| format!("loading {} failed", args.baked.display()))?;
    let c = points::compare(&baked, &reference);
    println!("{}", c.summary());
    Ok(())
}

/// Side of the pixel blocks whose means are compared (averages out the render's anti-aliasing
/// and the reference's per-pixel noise).
const BLOCK: u32 = 4;

/// A rendered image against a camera reference (see `--view`).
fn compare_view(image: &std::path::Path, reference: &std::path::Path) -> Result<()> {
    let read = |p: &std::path::Path| {
        lightbake::output::read_exr(p).with_context(|| format!("reading {} failed", p.display()))
    };
    let stderr = reference.with_file_name(format!(
        "{}_stderr.exr",
        reference
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or("reference")
    ));
    let (a, r, se) = (read(image)?, read(reference)?, read(&stderr)?);
    if (a.width, a.height) != (r.width, r.height) || (se.width, se.height) != (r.width, r.height) {
        anyhow::bail!("the image and the reference differ in size");
    }
    let (mut x, mut m, mut s) = (Vec::new(), Vec::new(), Vec::new());
    for by in 0..r.height / BLOCK {
        for bx in 0..r.width / BLOCK {
            let pixels: Vec<usize> = (by * BLOCK..(by + 1) * BLOCK)
                .flat_map(|y| {
                    (bx * BLOCK..(bx + 1) * BLOCK).map(move |px| (y * r.width + px) as usize)
                })
                .collect();
            let k = pixels.len() as f32;
            let mean = |v: &[Vec3]| pixels.iter().map(|&i| v[i]).sum::<Vec3>() / k;
            x.push(mean(&a.rgb));
            m.push(mean(&r.rgb));
            // σ² of a block mean: Σσ² over the block / pixels².
            let var = pixels.iter().map(|&i| se.rgb[i] * se.rgb[i]).sum::<Vec3>() / (k * k);
            s.push(var.map(f32::sqrt));
        }
    }
    let error = lightbake::metrics::rmse_over_rms(&x, &m, &[]);
    let noise = lightbake::metrics::noise_over_rms(&s, &m, &[]);
    println!(
        "blocks compared        {} ({BLOCK}×{BLOCK} pixels)\n\
         relative RMS diff.     {:.2}% ({:.2}% without the reference's noise)\n\
         reference noise        {:.2}%",
        x.len(),
        error * 100.0,
        lightbake::metrics::without_noise(error, noise) * 100.0,
        noise * 100.0
    );
    Ok(())
}
