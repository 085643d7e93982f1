//! Iterations, wall time and rays per solver on the furnace (ρ = 0.9, 0.99) and the Cornell box.
//!
//!     cargo run --release --example compare_solvers
//!
//! Prints a Markdown table. Times are from the solver's own history (transport + solve for the
//! matrix-free gather solver, which builds no transport first; solve only for the others).

use std::path::{Path, PathBuf};

use lightbake::config::{FormFactors, RowSolver, Technique};
use lightbake::{BakeConfig, NoProgress, compute};

fn main() -> lightbake::Result<()> {
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures");
    let dir = std::env::temp_dir().join("lightbake_solver_comparison");
    std::fs::create_dir_all(&dir).map_err(|e| lightbake::Error::io(&dir, e))?;
    let furnace_099 = dir.join("furnace_099.gltf");
    lightbake::testing::furnace(0.99, 1.0).write_gltf(&furnace_099)?;

    let mut config = BakeConfig::draft();
    config.transport.gather_rays = 128;
    config.transport.light_samples = 16;
    config.solve.tolerance = 1e-5;
    let scenes: [(&str, PathBuf, f32); 3] = [
        ("furnace ρ=0.9", fixtures.join("furnace_09.gltf"), 10.0),
        ("furnace ρ=0.99", furnace_099, 100.0),
        ("cornell box", fixtures.join("cornell_box.gltf"), f32::NAN),
    ];
    println!(
        "| scene | texels | solver | iterations | solver s | rays (M) | mean H/π | converged |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for (name, path, _expected) in &scenes {
        for solver in [
            Technique::DEFAULT,
            Technique::stored(FormFactors::MonteCarlo, RowSolver::GaussSeidel),
            Technique::stored(FormFactors::MonteCarlo, RowSolver::Southwell),
            Technique::Gather,
        ] {
            config.technique = solver;
            let baked = compute(path, &config, &NoProgress)?;
            let s = &baked.solution;
            let mean = baked
                .lightmap
                .iter()
                .map(|v| v.element_sum() / 3.0)
                .sum::<f32>()
                / baked.lightmap.len() as f32;
            println!(
                "| {name} | {} | {} | {} | {:.3} | {:.2} | {mean:.4} | {} |",
                baked.texels.len(),
                solver.solver(),
                s.history.len(),
                s.history.last().map_or(0.0, |i| i.seconds),
                baked.transport.rays as f64 * 1e-6,
                s.converged
            );
        }
    }
    Ok(())
}
