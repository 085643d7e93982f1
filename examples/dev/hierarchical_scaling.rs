//! Hierarchical radiosity: link counts, rays and time against texel count, and error against
//! the Monte Carlo method and the furnace's analytic answer.
//!
//!     cargo run --release --example hierarchical_scaling [scene.gltf] [texels-per-unit...]

use std::path::PathBuf;
use std::time::Instant;

use glam::Vec3;
use lightbake::config::Technique;
use lightbake::solve::hierarchical;
use lightbake::trace::Tracer;
use lightbake::transport::Surfaces;
use lightbake::{BakeConfig, NoProgress, atlas, compute, metrics, scene, texels};

fn main() -> lightbake::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let path = PathBuf::from(
        args.first()
            .map_or("fixtures/cornell_box.gltf", |s| s.as_str()),
    );
    let densities: Vec<f32> = if args.len() > 1 {
        args[1..]
            .iter()
            .map(|s| s.parse().expect("texels per unit"))
            .collect()
    } else {
        vec![16.0, 32.0, 64.0]
    };
    println!(
        "| texels/unit | texels | nodes | links | links/texel | rays (M) | seconds | sweeps | rel. RMSE vs MC | mean vs MC |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for tpu in densities {
        let mut config = BakeConfig::medium();
        config.atlas.texels_per_unit = tpu;
        config.technique = Technique::Hierarchical;
        let (sc, source) = scene::load(&path)?;
        let at = atlas::build(&sc, &source, &config.atlas)?;
        let tx = texels::build(&sc, &at)?;
        let tracer = Tracer::new(&sc);
        let t = Instant::now();
        let surfaces = Surfaces {
            scene: &sc,
            texels: &tx,
            tracer: &tracer,
        };
        let (transport, solution, stats) = hierarchical::solve_with_stats(
            surfaces,
            &config.transport,
            &config.solve,
            &NoProgress,
        )?;
        let seconds = t.elapsed().as_secs_f64();
        // The Monte Carlo method at the same texels.
        config.technique = Technique::DEFAULT;
        let mc = compute(&path, &config, &NoProgress)?;
        let (h, m) = (&solution.irradiance, &mc.solution.irradiance);
        // Over the channel sums, as grey values (as tests/hierarchical.rs).
        let grey =
            |l: &[Vec3]| -> Vec<Vec3> { l.iter().map(|v| Vec3::splat(v.element_sum())).collect() };
        println!(
            "| {tpu} | {} | {} | {} | {:.1} | {:.2} | {:.2} | {} | {:.4} | {:+.4} |",
            tx.len(),
            stats.nodes,
            stats.links,
            stats.links as f64 / tx.len() as f64,
            transport.rays as f64 * 1e-6,
            seconds,
            solution.history.len(),
            metrics::rmse_over_rms(&grey(h), &grey(m), &[]),
            metrics::relative_bias(h, m, &[])
        );
    }
    Ok(())
}
