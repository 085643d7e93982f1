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

use std::collections::HashMap;
use std::time::Instant;

use lightbake::BakeConfig;
use lightbake::atlas::{Atlas, Overlaps};
use lightbake::scene::Scene;
use lightbake::testing::cpu_seconds;

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

/// FNV-1a over every page size, xref, UV bit pattern, triangle and page: equal digests mean
/// byte-identical layouts.
fn digest(atlas: &Atlas) -> u64 {
    let mut words: Vec<u32> = atlas
        .pages
        .iter()
        .flat_map(|p| [p.width, p.height])
        .collect();
    for inst in &atlas.instances {
        words.extend(&inst.xref);
        words.extend(
            inst.uv
                .iter()
                .flat_map(|uv| [uv.x.to_bits(), uv.y.to_bits()]),
        );
        words.extend(inst.triangles.iter().flatten());
        words.extend(&inst.triangle_page);
    }
    words.iter().fold(0xcbf29ce484222325, |h, &w| {
        (h ^ u64::from(w)).wrapping_mul(0x100000001b3)
    })
}

/// Charts: triangles joined through shared atlas vertex pairs (edges inside a chart), per
/// instance.
fn charts(atlas: &Atlas) -> usize {
    let mut total = 0;
    for inst in &atlas.instances {
        let n = inst.triangles.len();
        let mut parent: Vec<usize> = (0..n).collect();
        fn root(parent: &mut [usize], mut i: usize) -> usize {
            while parent[i] != i {
                parent[i] = parent[parent[i]];
                i = parent[i];
            }
            i
        }
        let mut first_with_edge: HashMap<(u32, u32), usize> = HashMap::new();
        for (t, tri) in inst.triangles.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                let other = *first_with_edge.entry((a.min(b), a.max(b))).or_insert(t);
                let (ra, rb) = (root(&mut parent, t), root(&mut parent, other));
                parent[ra] = rb;
            }
        }
        total += (0..n).filter(|&t| root(&mut parent, t) == t).count();
    }
    total
}

/// Texel centres strictly inside more than one triangle of the same page.
fn overlapping(scene: &Scene, atlas: &Atlas) -> u64 {
    (0..atlas.pages.len() as u32)
        .map(|page| {
            let triangles = (0..scene.triangles.len() as u32)
                .map(|t| atlas.triangle_uv(scene, t))
                .filter(|&(_, p)| p == page)
                .map(|(uv, _)| uv);
            Overlaps::find(atlas.pages[page as usize], triangles).overlapping
        })
        .sum()
}
