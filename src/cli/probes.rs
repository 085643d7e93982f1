//! `lightbake probes`: the light a bake's probes give at points off its surfaces.

use std::io::Write;
use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use glam::Vec3;
use lightbake::render::RenderScene;

/// Prints `r,g,b` per point: irradiance over π from the probes, interpolated as a renderer
/// does (`lightbake::probes::Probes::irradiance_over_pi`, visibility-tested).
#[derive(clap::Args)]
#[command(after_help = AFTER_HELP)]
pub struct Args {
    /// The baked scene (.gltf or .glb written by `lightbake bake --probes`).
    baked: PathBuf,
    /// Points, one per line: x,y,z,nx,ny,nz (world space; the normal need not be unit).
    /// Blank lines, lines starting with # and a header line are skipped.
    #[arg(long, value_name = "FILE.csv")]
    at: PathBuf,
}

const AFTER_HELP: &str = "\
Prints one line r,g,b per point: the irradiance over π about the point's normal from the
probes' interpolated L2 spherical harmonics — the lightmaps' unit, H/π — in the input's order.
  lightbake bake scene.gltf -o out --probes
  lightbake probes out/scene.gltf --at points.csv";

pub fn run(args: &Args) -> Result<()> {
    let text = std::fs::read_to_string(&args.at)
        .with_context(|| format!("reading {} failed", args.at.display()))?;
    let points = parse_points(&text).with_context(|| format!("in {}", args.at.display()))?;
    let baked = RenderScene::load(&args.baked)
        .with_context(|| format!("loading {} failed", args.baked.display()))?;
    let Some(probes) = &baked.probes else {
        bail!(
            "{} has no light probes (no extras.light_probes): bake it with --probes",
            args.baked.display()
        );
    };
    let mut out = std::io::BufWriter::new(std::io::stdout().lock());
    for (p, n) in points {
        let e = probes.irradiance_over_pi(p, n, Some(&baked.tracer));
        writeln!(out, "{},{},{}", e.x, e.y, e.z)?;
    }
    out.flush()?;
    Ok(())
}

/// The points of a CSV text: (position, unit normal) per line.
pub(super) fn parse_points(text: &str) -> Result<Vec<(Vec3, Vec3)>> {
    let mut points = Vec::new();
    for (k, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let fields: Result<Vec<f32>, _> = line.split(',').map(|f| f.trim().parse()).collect();
        let v = match fields {
            Ok(v) => v,
            // A header line (the first line that is not numbers) is skipped.
            Err(_) if points.is_empty() && k == 0 => continue,
            Err(e) => bail!("line {}: {e}: expected x,y,z,nx,ny,nz", k + 1),
        };
        let [x, y, z, nx, ny, nz] = v[..] else {
            bail!(
                "line {}: {} numbers, expected x,y,z,nx,ny,nz",
                k + 1,
                v.len()
            );
        };
        let n = Vec3::new(nx, ny, nz).normalize_or_zero();
        if !v.iter().all(|c| c.is_finite()) || n == Vec3::ZERO {
            bail!(
                "line {}: expected finite numbers and a non-zero normal",
                k + 1
            );
        }
        points.push((Vec3::new(x, y, z), n));
    }
    Ok(points)
}
