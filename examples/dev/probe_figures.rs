//! Light probes against the path tracer: the figures of the guide's "Light probes" section.
//!
//! ```text
//! cargo run --release --example probe_figures -- SCENE [QUALITY] [BUDGET] [POINTS] [SAMPLES] [RAYS]
//! ```
//!
//! Bakes `SCENE` at `QUALITY` (draft, medium or high; default medium) with `BUDGET` probes
//! (default the library's) of `RAYS` rays each (default the library's), then draws `POINTS` (default 500) random free-space points between
//! the probes with random normals (`Probes::points_between`, over all cells and over whole
//! cells) and path-traces `H/π` there about the normal with `SAMPLES` paths (default 1024).
//! Prints the probe count, the probe stage's seconds against the bake's, and the relative
//! RMSE of the interpolated probes with the reference's noise taken out.

use std::path::Path;

use glam::Vec3;
use lightbake::probes::ProbeParams;
use lightbake::reference::ReferenceParams;
use lightbake::reference::points::{self, Normals, Point};
use lightbake::trace::Tracer;
use lightbake::{BakeConfig, NoProgress, metrics};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [scene, rest @ ..] = &args[..] else {
        panic!("usage: probe_figures SCENE [QUALITY] [BUDGET] [POINTS] [SAMPLES] [RAYS]")
    };
    let quality = rest.first().map_or("medium", String::as_str);
    let mut config = match quality {
        "draft" => BakeConfig::draft(),
        "high" => BakeConfig::high(),
        _ => BakeConfig::medium(),
    };
    let mut params = ProbeParams::default();
    if let Some(b) = rest.get(1) {
        params.budget = b.parse().expect("BUDGET");
    }
    let n: usize = rest.get(2).map_or(500, |s| s.parse().expect("POINTS"));
    let samples: u32 = rest.get(3).map_or(1024, |s| s.parse().expect("SAMPLES"));
    if let Some(r) = rest.get(4) {
        params.rays = r.parse().expect("RAYS");
    }
    config.output.probes = Some(params);
    let baked = lightbake::compute(Path::new(scene), &config, &NoProgress).expect("bake");
    let total: f64 = baked.stages.iter().map(|s| s.seconds).sum();
    let probe_seconds: f64 = (baked.stages.iter())
        .filter(|s| s.stage == "probes")
        .map(|s| s.seconds)
        .sum();
    let probes = baked.probes.as_ref().expect("probes");
    let grid = probes.grid.expect("the automatic grid");
    println!(
        "{scene} ({quality}): {} probes ({} valid, {} moved), grid {:?} step {:.3}, {:.2} M rays; probes {probe_seconds:.2}s of {total:.2}s computing ({:.1}%)",
        probes.len(),
        probes.valid_count(),
        probes.moved,
        grid.count,
        grid.step.x,
        probes.rays as f64 * 1e-6,
        100.0 * probe_seconds / total
    );
    let tracer = Tracer::new(&baked.scene);
    // At the valid probes themselves (no interpolation: SH truncation and gather noise only),
    // then between them.
    let at_probes: Vec<(Vec3, Vec3)> = (0..probes.len())
        .filter(|&i| probes.valid[i])
        .step_by((probes.valid_count() / n).max(1))
        .map(|i| {
            let u = (i as f32 * 0.618_034).fract();
            let v = (i as f32 * 0.414_214).fract();
            let z = 1.0 - 2.0 * u;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let phi = std::f32::consts::TAU * v;
            (
                probes.position[i],
                Vec3::new(r * phi.cos(), r * phi.sin(), z),
            )
        })
        .collect();
    for mode in 0..3 {
        let at = match mode {
            0 => at_probes.clone(),
            m => probes.points_between(&tracer, n, 3, m == 2),
        };
        let pts: Vec<Point> = (at.iter())
            .map(|&(position, normal)| Point {
                position,
                normal,
                shading_normal: normal,
            })
            .collect();
        let reference = ReferenceParams {
            max_samples: samples,
            seed: 7,
            ..ReferenceParams::like(&baked.config)
        };
        let r = points::trace_about(
            (&baked.scene, &baked.texels, &tracer),
            &pts,
            Normals::Shading,
            &reference,
            &NoProgress,
        )
        .expect("reference");
        let ours: Vec<Vec3> = (at.iter())
            .map(|&(p, n)| probes.irradiance_over_pi(p, n, Some(&tracer)))
            .collect();
        let rmse = metrics::rmse_over_mean(&ours, &r.mean, &[]);
        let noise = metrics::noise_over_mean(&r.std_error, &r.mean, &[]);
        let bias = metrics::relative_bias(&ours, &r.mean, &[]);
        println!(
            "  {} points ({}): relative RMSE {:.2}% without the reference's noise ({:.2}% raw, noise {:.2}%), bias {:+.2}%",
            at.len(),
            ["at the probes", "all free space", "whole cells"][mode],
            100.0 * metrics::without_noise(rmse, noise),
            100.0 * rmse,
            100.0 * noise,
            100.0 * bias
        );
        let mut worst: Vec<(f32, usize)> = (0..at.len())
            .map(|k| ((ours[k] - r.mean[k]).length_squared(), k))
            .collect();
        worst.sort_by(|a, b| b.0.total_cmp(&a.0));
        let all: f32 = worst.iter().map(|w| w.0).sum();
        let top: f32 = worst.iter().take(at.len() / 10).map(|w| w.0).sum();
        println!(
            "    worst tenth of the points: {:.0}% of the squared error",
            100.0 * top / all
        );
        for &(_, k) in worst.iter().take(6) {
            println!(
                "    p {:.3} n {:.2}: probes {:.4}, reference {:.4} ± {:.4}",
                at[k].0, at[k].1, ours[k].x, r.mean[k].x, r.std_error[k].x
            );
        }
    }
}
