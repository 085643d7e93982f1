//! Seam stitching at T-junctions, measured: for each scene, the discontinuity along the seams
//! that only T-junction detection finds, and along all seams, with stitching of shared-end-point
//! seams only (as before T-junctions were detected) and with T-junctions, in one run.
//!
//! `cargo run --release --example t_junction_seams`

use std::path::Path;
use std::time::Instant;

use lightbake::lightmap::seams::{self, SeamParams, Seams};
use lightbake::{BakeConfig, NoProgress, compute, prepare};

fn main() {
    let dir = tempfile::tempdir().unwrap();
    let floor = dir.path().join("t_junction_floor.gltf");
    lightbake::testing::t_junction_floor()
        .write_gltf(&floor)
        .unwrap();
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures");
    let mut medium = BakeConfig::medium();
    medium.output.seams = false;
    let mut dense = medium.clone();
    dense.atlas.texels_per_unit = 16.0;
    let mut small_pages = medium.clone();
    small_pages.atlas.max_page_size = 64;
    let runs = [
        (
            "testing::t_junction_floor, 16 texels/m",
            floor.clone(),
            &dense,
        ),
        (
            "two_rooms.gltf (medium)",
            fixtures.join("two_rooms.gltf"),
            &medium,
        ),
        (
            "two_rooms.gltf, 64-texel pages",
            fixtures.join("two_rooms.gltf"),
            &small_pages,
        ),
        (
            "cornell_box.gltf (medium)",
            fixtures.join("cornell_box.gltf"),
            &medium,
        ),
        (
            "sphere_on_floor.gltf (medium)",
            fixtures.join("sphere_on_floor.gltf"),
            &medium,
        ),
    ];
    println!(
        "| scene | T edges | T mean before / shared-only / with T | T max before / shared-only / with T | all mean shared-only → with T | find time off / on |"
    );
    println!("|---|---|---|---|---|---|");
    for (name, path, config) in runs {
        let baked = compute(&path, config, &NoProgress).unwrap();
        let on = SeamParams::default();
        let off = SeamParams {
            t_junctions: false,
            ..on.clone()
        };
        let t = Instant::now();
        let shared = seams::find(&baked.scene, &baked.atlas, &off);
        let find_off = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let all = seams::find(&baked.scene, &baked.atlas, &on);
        let find_on = t.elapsed().as_secs_f64();
        // T-junction edges and their samples come after the shared ones.
        let t_only = Seams {
            edges: all.edges[shared.edges.len()..].to_vec(),
            samples: all.samples[shared.samples.len()..].to_vec(),
            surface_reads: all.surface_reads.clone(),
        };
        let mut shared_only = baked.pages.clone();
        seams::stitch(&shared, &mut shared_only, &on);
        let mut with_t = baked.pages.clone();
        seams::stitch(&all, &mut with_t, &on);
        let before = seams::measure(&t_only, &baked.pages);
        let [a, b] = [&shared_only, &with_t].map(|p| seams::measure(&t_only, p));
        let [c, d] = [&shared_only, &with_t].map(|p| seams::measure(&all, p));
        println!(
            "| {name} | {} | {:.4} / {:.4} / {:.5} | {:.4} / {:.4} / {:.4} | {:.5} → {:.5} | {:.1} / {:.1} ms |",
            t_only.edges.len(),
            before.mean_abs_diff,
            a.mean_abs_diff,
            b.mean_abs_diff,
            before.max_abs_diff,
            a.max_abs_diff,
            b.max_abs_diff,
            c.mean_abs_diff,
            d.mean_abs_diff,
            find_off * 1e3,
            find_on * 1e3,
        );
        if !t_only.edges.is_empty() {
            println!(
                "|   (mean value along T edges {:.4}) | | | | | |",
                before.mean_value
            );
        }
    }

    // Cost on a large scene: the 116k-triangle hall (finding only; its meshes are closed grids).
    let hall = dir.path().join("large_hall.gltf");
    lightbake::testing::large_hall().write_gltf(&hall).unwrap();
    let prepared = prepare(&hall, &BakeConfig::draft(), &NoProgress).unwrap();
    for t_junctions in [false, true] {
        let params = SeamParams {
            t_junctions,
            ..SeamParams::default()
        };
        let t = Instant::now();
        let found = seams::find(&prepared.scene, &prepared.atlas, &params);
        println!(
            "large_hall ({} triangles), t_junctions {t_junctions}: {} edges, find {:.0} ms",
            prepared.scene.triangles.len(),
            found.edges.len(),
            t.elapsed().as_secs_f64() * 1e3
        );
    }
}
