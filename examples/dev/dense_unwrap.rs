//! The dense-mesh benchmark of issue 28: a generated wavy height field (`testing::height_field`)
//! or a room of dense props (`testing::dense_room`), written as a .glb for `lightbake bake`, or
//! unwrapped alone with the layout's figures.
//!
//!     cargo run --release --example dense_unwrap -- write <triangles> <out.glb> [room]
//!     cargo run --release --example dense_unwrap -- atlas <triangles> <texels per unit> [room]
//!
//! `write` writes the scene. `atlas` times the junction split (with shadow cuts, as a bake runs
//! it) and the atlas stage on all cores and on one thread, and prints what the layout costs
//! downstream: pages, page texels, patches (`texels::build`), charts, texel centres claimed
//! twice, triangles without UV area, the stretch (texel area over world area × tpu², per
//! triangle, area-weighted percentiles) and a digest of the layout (equal on any thread count).
//! To time whole bakes: `write`, then `/usr/bin/time -v lightbake bake <file> -o <dir>`.

use std::time::Instant;

use lightbake::BakeConfig;
use lightbake::atlas::Atlas;
use lightbake::scene::Scene;

#[path = "atlas_figures.rs"]
mod atlas_figures;
use atlas_figures::{charts, digest, overlapping};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let triangles: usize = args.get(1).ok_or("triangles")?.parse()?;
    let room = args.iter().any(|a| a == "room");
    let gltf = if room {
        lightbake::testing::dense_room(triangles)
    } else {
        lightbake::testing::height_field(triangles)
    };
    match args.first().map(String::as_str) {
        Some("write") => {
            let path = args.get(2).ok_or("output path")?;
            gltf.write_glb(path)?;
            println!("{path}: {} triangles", gltf.mesh_triangle_count());
        }
        Some("atlas") => {
            let tpu: f32 = args.get(2).ok_or("texels per unit")?.parse()?;
            let dir = tempfile::tempdir()?;
            let path = dir.path().join("dense.glb");
            gltf.write_glb(&path)?;
            let (scene, source) = lightbake::scene::load(&path)?;
            let mut config = BakeConfig::default();
            config.atlas.texels_per_unit = tpu;
            config.atlas.uv = lightbake::config::UvMode::Unwrap;
            println!(
                "{} triangles, {} instances, {tpu} texels per unit",
                scene.triangles.len(),
                scene.instances.len()
            );
            let t = Instant::now();
            let (scene, report) = lightbake::split_junctions(scene, &source, &config);
            println!(
                "junction split + shadow cuts: {:.2} s ({})",
                t.elapsed().as_secs_f64(),
                report.map_or("off".into(), |r| r.brief())
            );
            let t = Instant::now();
            let atlas = lightbake::atlas::build(&scene, &source, &config.atlas)?;
            let wall = t.elapsed().as_secs_f64();
            let one = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
            let t = Instant::now();
            let single = one.install(|| lightbake::atlas::build(&scene, &source, &config.atlas))?;
            let wall_one = t.elapsed().as_secs_f64();
            report_layout(&scene, &atlas, tpu, wall, wall_one);
            println!(
                "digest {:016x}, on one thread {:016x} ({})",
                digest(&atlas),
                digest(&single),
                if digest(&atlas) == digest(&single) {
                    "equal"
                } else {
                    "DIFFERENT"
                }
            );
        }
        _ => return Err("usage: dense_unwrap write|atlas <triangles> ... [room]".into()),
    }
    Ok(())
}

fn report_layout(scene: &Scene, atlas: &Atlas, tpu: f32, wall: f64, wall_one: f64) {
    let page_texels: u64 = atlas
        .pages
        .iter()
        .map(|p| u64::from(p.width * p.height))
        .sum();
    let patches = lightbake::texels::build(scene, atlas).map_or(0, |t| t.len());
    // Per triangle: world area and texel area over world area × tpu².
    let mut stretch: Vec<(f64, f64)> = Vec::with_capacity(scene.triangles.len());
    let mut flat = 0;
    for t in 0..scene.triangles.len() as u32 {
        let ([a, b, c], page) = atlas.triangle_uv(scene, t);
        let size = atlas.pages[page as usize];
        let texels = 0.5
            * f64::from((b - a).perp_dot(c - a).abs())
            * f64::from(size.width)
            * f64::from(size.height);
        let [p, q, r] = scene.triangles[t as usize].map(|v| scene.positions[v as usize].as_dvec3());
        let world = 0.5 * (q - p).cross(r - p).length();
        if texels == 0.0 {
            flat += 1;
        }
        if world > 0.0 {
            stretch.push((world, texels / (world * f64::from(tpu).powi(2))));
        }
    }
    stretch.sort_by(|x, y| x.1.total_cmp(&y.1));
    let total: f64 = stretch.iter().map(|s| s.0).sum();
    let mean = stretch.iter().map(|s| s.0 * s.1).sum::<f64>() / total;
    let percentile = |p: f64| {
        let mut sum = 0.0;
        for s in &stretch {
            sum += s.0;
            if sum >= p * total {
                return s.1;
            }
        }
        stretch.last().map_or(0.0, |s| s.1)
    };
    println!(
        "atlas: {wall:.2} s ({wall_one:.2} s on one thread); {} pages, {page_texels} page texels, \
         {patches} patches, {} charts, {} texel centres claimed twice, {flat} triangles without UV area",
        atlas.pages.len(),
        charts(atlas),
        overlapping(scene, atlas),
    );
    println!(
        "texel area / (world area × tpu²), area-weighted: mean {mean:.3}, 1% {:.3}, 50% {:.3}, 99% {:.3}",
        percentile(0.01),
        percentile(0.5),
        percentile(0.99)
    );
}
