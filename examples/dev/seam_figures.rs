//! The seam table of `lightmap::seams`' module docs, measured: per scene, the seam edges (and
//! the texels the stitch solves for), the
//! mean and maximum `|A − B|` along them before and after stitching, with the surface term
//! off (μ = 0, stitching as before it existed) and at the default μ, and the stitch's time.
//!
//! `cargo run --release --example seam_figures [μ]` (μ: the default's when left out)

use std::path::Path;
use std::time::Instant;

use lightbake::lightmap::seams::{self, SeamParams};
use lightbake::{BakeConfig, NoProgress, compute};

fn main() {
    let dir = tempfile::tempdir().unwrap();
    let sphere = dir.path().join("sphere_on_floor.gltf");
    lightbake::testing::sphere_on_floor()
        .write_gltf(&sphere)
        .unwrap();
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures");
    let mut medium = BakeConfig::medium();
    medium.output.seams = false;
    let mut draft = BakeConfig::draft();
    draft.output.seams = false;
    let pages = |size: u32| {
        let mut c = medium.clone();
        c.atlas.max_page_size = size;
        c
    };
    let runs = [
        (
            "`testing::sphere_on_floor` (medium)",
            sphere,
            medium.clone(),
        ),
        (
            "`point_light.gltf`, 32-texel pages (medium)",
            fixtures.join("point_light.gltf"),
            pages(32),
        ),
        (
            "`two_rooms.gltf`, 64-texel pages (medium)",
            fixtures.join("two_rooms.gltf"),
            pages(64),
        ),
        (
            "`furnished_interior.glb` (draft)",
            fixtures.join("furnished_interior.glb"),
            draft,
        ),
    ];
    let mut on = SeamParams::default();
    if let Some(mu) = std::env::args().nth(1) {
        on.surface_weight = mu.parse().expect("μ");
    }
    let off = SeamParams {
        surface_weight: 0.0,
        ..on.clone()
    };
    println!(
        "| scene | edges (texels solved) | mean before → μ = 0 / μ = {} | max before → μ = 0 / μ = {} | mean value | time μ = 0 / μ = {} |",
        on.surface_weight, on.surface_weight, on.surface_weight
    );
    println!("|---|---|---|---|---|---|");
    for (name, path, config) in runs {
        let baked = compute(&path, &config, &NoProgress).unwrap();
        let mut results = Vec::new();
        for params in [&off, &on] {
            let t = Instant::now();
            let found = seams::find(&baked.scene, &baked.atlas, params);
            let mut stitched = baked.pages.clone();
            let (texels, _) = seams::stitch(&found, &mut stitched, params);
            let seconds = t.elapsed().as_secs_f64();
            results.push((
                seams::measure(&found, &baked.pages),
                seams::measure(&found, &stitched),
                seconds,
                texels,
            ));
        }
        let before = results[0].0;
        println!(
            "| {name} | {} ({}) | {:.4} → {:.5} / {:.5} | {:.3} → {:.4} / {:.4} | {:.3} | {:.0} / {:.0} ms |",
            before.edges,
            results[1].3,
            before.mean_abs_diff,
            results[0].1.mean_abs_diff,
            results[1].1.mean_abs_diff,
            before.max_abs_diff,
            results[0].1.max_abs_diff,
            results[1].1.max_abs_diff,
            before.mean_value,
            results[0].2 * 1e3,
            results[1].2 * 1e3,
        );
    }
}
