//! Speed and quality of the atlas stage alone on the 116k-triangle test hall, at the texel
//! density the benchmark bakes it at.
//!
//!     cargo run --release --example atlas_speed [-- <runs> [<texels per unit>]]
//!
//! Prints one row per run: wall time, CPU time (user + sys of the whole process) over wall time,
//! and what the layout costs downstream — pages, page texels, patches (`texels::build`), charts
//! (edge-connected triangles sharing lightmap UVs), seam edges (`lightmap::seams::find`) and
//! texel centres claimed twice. It uses only the public API, so the same file builds against an
//! older checkout for an interleaved before/after comparison.

use std::time::Instant;

use lightbake::BakeConfig;
use lightbake::testing::cpu_seconds;

#[path = "atlas_figures.rs"]
mod atlas_figures;
use atlas_figures::{charts, digest, overlapping};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let runs: usize = args.next().map_or(Ok(3), |a| a.parse())?;
    let tpu: f32 = args.next().map_or(Ok(3.0), |a| a.parse())?;

    let dir = tempfile::tempdir()?;
    let path = dir.path().join("large_hall.glb");
    std::fs::write(&path, lightbake::testing::large_hall().to_glb_bytes())?;
    let (scene, source) = lightbake::scene::load(&path)?;
    let mut params = BakeConfig::draft().atlas;
    params.texels_per_unit = tpu;
    params.uv = lightbake::config::UvMode::Unwrap;

    println!(
        "large_hall: {} triangles, {} instances, {tpu} texels per unit",
        scene.triangles.len(),
        scene.instances.len()
    );
    println!(
        "{:>4} {:>8} {:>6} {:>6} {:>10} {:>8} {:>7} {:>6} {:>8} {:>17}",
        "run",
        "wall s",
        "cpu/w",
        "pages",
        "page tx",
        "patches",
        "charts",
        "seams",
        "overlap",
        "digest"
    );
    for run in 0..runs {
        let cpu = cpu_seconds();
        let start = Instant::now();
        let atlas = lightbake::atlas::build(&scene, &source, &params)?;
        let wall = start.elapsed().as_secs_f64();
        let cpu = cpu_seconds() - cpu;
        let page_texels: u64 = atlas
            .pages
            .iter()
            .map(|p| u64::from(p.width * p.height))
            .sum();
        let patches = lightbake::texels::build(&scene, &atlas)?.len();
        let seams = lightbake::lightmap::seams::find(&scene, &atlas, &Default::default());
        println!(
            "{run:>4} {wall:>8.3} {:>6.2} {:>6} {page_texels:>10} {patches:>8} {:>7} {:>6} {:>8} {:016x}",
            cpu / wall,
            atlas.pages.len(),
            charts(&atlas),
            seams.edges.len(),
            overlapping(&scene, &atlas),
            digest(&atlas),
        );
    }
    Ok(())
}
