//! Stored Monte Carlo rows as ray counts against the same rows as f32 weights: bytes per texel
//! and the time of each row solver on both, interleaved in one run, with the solutions checked
//! bit-identical.
//!
//! ```sh
//! nice -n 10 cargo run --release --example row_storage [-- REPEATS [FILTER]]
//! ```
//!
//! Bakes `cornell_box.gltf` and `two_rooms.gltf` at high and `furnished_interior.glb` at draft and medium with the
//! preset's settings (no automatic choice: Monte Carlo rows, K of the preset), then solves each
//! transport with Jacobi, Gauss–Seidel and Southwell, alternating the two storages `REPEATS`
//! times (default 3) and keeping each one's fastest run. `FILTER` keeps the cases whose
//! "scene preset" contains it.

use std::path::Path;
use std::time::Instant;

use lightbake::config::RowSolver;
use lightbake::transport::{Rows, Transport};
use lightbake::{BakeConfig, NoProgress, compute, solve};

fn main() {
    let repeats: usize = std::env::args()
        .nth(1)
        .map_or(3, |a| a.parse().expect("REPEATS"));
    let only = std::env::args().nth(2).unwrap_or_default();
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures");
    let cases = [
        ("cornell_box.gltf", "high", BakeConfig::high()),
        ("two_rooms.gltf", "high", BakeConfig::high()),
        ("furnished_interior.glb", "draft", BakeConfig::draft()),
        ("furnished_interior.glb", "medium", BakeConfig::medium()),
    ];
    println!(
        "| scene | preset | texels | K | entries/texel | bytes/texel f32 | bytes/texel counts | ratio | solver | sweeps | f32 s | counts s | counts/f32 |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for (scene, preset, mut config) in cases {
        if !format!("{scene} {preset}").contains(&only) {
            continue;
        }
        config.auto = None;
        config.transport.count_rows = true;
        let baked = compute(&fixtures.join(scene), &config, &NoProgress).expect("bake");
        let counts = &baked.transport;
        assert!(matches!(counts.rows, Rows::Counts(_)));
        let weights = Transport {
            rows: Rows::Weights(counts.rows.to_weights()),
            ..counts.clone()
        };
        let n = counts.len() as f64;
        let per_texel = |t: &Transport| t.rows.bytes() as f64 / n;
        for solver in [
            RowSolver::Jacobi,
            RowSolver::GaussSeidel,
            RowSolver::Southwell,
        ] {
            let (mut best, mut iterations) = ([f64::MAX; 2], 0);
            for _ in 0..repeats {
                let mut results = Vec::new();
                for (s, t) in [&weights, counts].into_iter().enumerate() {
                    let start = Instant::now();
                    let solution =
                        solve::solve(t, &baked.texels, solver, &config.solve, &NoProgress)
                            .expect("solve");
                    best[s] = best[s].min(start.elapsed().as_secs_f64());
                    iterations = solution.history.len();
                    results.push(solution.irradiance);
                }
                assert!(results[0] == results[1], "{scene}: solutions differ");
            }
            println!(
                "| {scene} | {preset} | {} | {} | {:.1} | {:.0} | {:.0} | {:.2} | {solver:?} | {iterations} | {:.3} | {:.3} | {:.2} |",
                counts.len(),
                config.transport.gather_rays,
                counts.rows.entries() as f64 / n,
                per_texel(&weights),
                per_texel(counts),
                per_texel(&weights) / per_texel(counts),
                best[0],
                best[1],
                best[1] / best[0],
            );
        }
    }
}
