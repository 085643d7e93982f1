//! Jacobi sweeps over one bake's Monte Carlo rows in one storage, for instruction counts under
//! callgrind (the machine is shared and noisy; instruction counts are repeatable):
//!
//! ```sh
//! cargo build --release --example sweep_profile
//! RAYON_NUM_THREADS=1 valgrind --tool=callgrind --collect-atstart=no \
//!   --toggle-collect='*solve*jacobi*' target/release/examples/sweep_profile \
//!   cornell_box.gltf draft 256 counts 10
//! ```
//!
//! Arguments: fixture, preset, gathering rays K, `f32` or `counts`, sweeps. Bakes the fixture
//! with the preset's settings, no automatic choice, rows built as counts, and (for `f32`)
//! converted to f32 weights: the same rows in either storage. Prints the entries swept, so
//! that instructions per entry follow from callgrind's total.

use std::path::Path;

use lightbake::config::RowSolver;
use lightbake::transport::{Rows, Transport};
use lightbake::{BakeConfig, NoProgress, compute, solve};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [scene, preset, rays, storage, sweeps] = &args[..] else {
        panic!("usage: sweep_profile FIXTURE PRESET RAYS f32|counts SWEEPS");
    };
    let (_, mut config) = BakeConfig::PRESETS
        .into_iter()
        .find(|(name, _)| name == preset)
        .expect("preset");
    config.auto = None;
    config.transport.gather_rays = rays.parse().expect("RAYS");
    config.transport.count_rows = true;
    config.solve.tolerance = 1e-9; // run all the sweeps asked for
    config.solve.max_iterations = sweeps.parse().expect("SWEEPS");
    let fixture = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fixtures")
        .join(scene);
    let baked = compute(&fixture, &config, &NoProgress).expect("bake");
    let transport = match storage.as_str() {
        "counts" => baked.transport,
        "f32" => Transport {
            rows: Rows::Weights(baked.transport.rows.to_weights()),
            ..baked.transport
        },
        other => panic!("storage {other:?}: expected f32 or counts"),
    };
    let solution = solve::solve(
        &transport,
        &baked.texels,
        RowSolver::Jacobi,
        &config.solve,
        &NoProgress,
    )
    .expect("solve");
    let sweeps = solution.history.len() as u64;
    println!(
        "{} texels, {} entries per sweep, {} bytes of rows, {sweeps} sweeps: {} entries swept",
        transport.len(),
        transport.rows.entries(),
        transport.rows.bytes(),
        transport.rows.entries() * sweeps
    );
}
