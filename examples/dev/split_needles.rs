//! Needles and slivers the junction split makes, per fixture and quality preset, and the atlas
//! time on its output.
//!
//!     cargo run --release --example split_needles [-- [--atlas] [SCENE:QUALITY ...]]
//!
//! Each scene is loaded and split as a bake splits it (the preset's automatic texel density,
//! shadow cuts on; `lightbake::split_junctions`). Per scene it prints the triangles the split made
//! (in the instances it cut) and, among them, those with an edge below 1e-3 texel (the atlas'
//! needle bound, `atlas::xatlas`), an edge below ¼ texel and an altitude below ¼ texel; the same
//! counts for the input's triangles of those instances, the split's wall time, and with
//! `--atlas` the wall time of `atlas::build` on the split scene (and on the unsplit one). It uses
//! only the public API, so the same file builds against an older checkout for before/after.

use std::time::Instant;

use lightbake::BakeConfig;
use lightbake::config::AutoParams;
use lightbake::scene::Scene;

const DEFAULT_RUNS: [&str; 12] = [
    "two_rooms.gltf:draft",
    "two_rooms.gltf:medium",
    "two_rooms_angled.gltf:draft",
    "two_rooms_angled.gltf:medium",
    "cornell_box.gltf:draft",
    "cornell_box.gltf:medium",
    "courtyard.gltf:draft",
    "courtyard.gltf:medium",
    "lamp_room.gltf:draft",
    "lamp_room.gltf:medium",
    "furnished_interior.glb:draft",
    "furnished_interior.glb:medium",
];

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let atlas = args.iter().any(|a| a == "--atlas");
    let mut runs: Vec<String> = args.into_iter().filter(|a| a != "--atlas").collect();
    if runs.is_empty() {
        runs = DEFAULT_RUNS.iter().map(|s| s.to_string()).collect();
    }
    println!(
        "{:<32} {:>7} {:>8} {:>8} {:>6} {:>6} {:>6}  {:>6} {:>6} {:>6} {:>8} {:>8} {:>8}",
        "scene:quality",
        "tpu",
        "in tris",
        "out tris",
        "<1e-3",
        "e<1/4",
        "h<1/4",
        "in:1e-3",
        "e<1/4",
        "h<1/4",
        "split s",
        "atlas s",
        "unsplit"
    );
    for run in &runs {
        let (file, quality) = run.split_once(':').unwrap_or((run, "medium"));
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("fixtures")
            .join(file);
        let (scene, source) = lightbake::scene::load(&path)?;
        let (_, mut config) = BakeConfig::PRESETS
            .into_iter()
            .find(|(name, _)| *name == quality)
            .ok_or("quality: draft, medium or high")?;
        let target_error = AutoParams::for_preset(quality).unwrap_or(0.04);
        let mut plan = lightbake::plan::Plan {
            target_error,
            ..Default::default()
        };
        lightbake::plan::choose_density(&scene, &mut config, &mut plan, &Default::default());
        let tpu = f64::from(config.atlas.texels_per_unit);

        let unsplit_atlas = atlas
            .then(|| {
                let t = Instant::now();
                lightbake::atlas::build(&scene, &source, &config.atlas).map(|_| t.elapsed())
            })
            .transpose()?;
        let input = scene.clone();
        let t = Instant::now();
        let (split, report) = lightbake::split_junctions(scene, &source, &config);
        let split_seconds = t.elapsed().as_secs_f64();
        let split_atlas = atlas
            .then(|| {
                let t = Instant::now();
                lightbake::atlas::build(&split, &source, &config.atlas).map(|_| t.elapsed())
            })
            .transpose()?;

        // Only the instances the split cut: their input and output triangles.
        let cut: Vec<usize> = (0..split.instances.len())
            .filter(|&i| !split.instances[i].split.blends.is_empty())
            .collect();
        let stats = |s: &Scene| -> [usize; 4] {
            let mut n = [0; 4];
            for &i in &cut {
                for t in s.instances[i].triangles.clone() {
                    let (edge, altitude) = shape(s, t as usize);
                    let (edge, altitude) = (edge * tpu, altitude * tpu);
                    n[0] += 1;
                    n[1] += usize::from(edge < 1e-3);
                    n[2] += usize::from(edge < 0.25);
                    n[3] += usize::from(altitude < 0.25);
                }
            }
            n
        };
        let (a, b) = (stats(&input), stats(&split));
        let secs = |d: Option<std::time::Duration>| {
            d.map_or("-".to_string(), |d| format!("{:.3}", d.as_secs_f64()))
        };
        println!(
            "{:<32} {:>7} {:>8} {:>8} {:>6} {:>6} {:>6}  {:>6} {:>6} {:>6} {:>8.3} {:>8} {:>8}",
            run,
            tpu,
            a[0],
            b[0],
            b[1],
            b[2],
            b[3],
            a[1],
            a[2],
            a[3],
            split_seconds,
            secs(split_atlas),
            secs(unsplit_atlas),
        );
        if let Some(report) = report {
            println!("    {}", report.brief());
        }
    }
    Ok(())
}

/// Shortest edge and smallest altitude of scene triangle `t` (world units).
fn shape(scene: &Scene, t: usize) -> (f64, f64) {
    let [a, b, c] = scene.triangles[t].map(|v| scene.positions[v as usize].as_dvec3());
    let edges = [a.distance(b), b.distance(c), c.distance(a)];
    let longest = edges.iter().copied().fold(0.0, f64::max);
    let double_area = (b - a).cross(c - a).length();
    let altitude = if longest > 0.0 {
        double_area / longest
    } else {
        0.0
    };
    (
        edges.iter().copied().fold(f64::INFINITY, f64::min),
        altitude,
    )
}
