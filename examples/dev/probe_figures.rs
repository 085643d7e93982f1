//! Light probes against the path tracer: the figures of the guide's "Light probes" section.
//!
//! ```text
//! cargo run --release --example probe_figures -- SCENE [QUALITY] [BUDGET] [POINTS] [SAMPLES] [RAYS] [REFINE...]
//! ```
//!
//! Bakes `SCENE` at `QUALITY` (draft, medium or high; default medium) with `BUDGET` probes
//! (default the library's) of `RAYS` rays each (default the library's), once per `REFINE` share
//! of the budget kept for refinement (default: 0, the uniform grid, then the library's default).
//! Then draws `POINTS` (default 500) random free-space points between the first bake's probes
//! with random normals (`Probes::points_between`, over all cells and over whole cells) and
//! path-traces `H/π` there about the normal with `SAMPLES` paths (default 1024): every bake is
//! measured at the same points against the same reference. Prints the probe count, the probe
//! stage's seconds against the bake's, and the relative RMSE of the interpolated probes with the
//! reference's noise taken out, at each bake's own probes and at the shared points.

use std::path::Path;

use glam::Vec3;
use lightbake::probes::{DEFAULT_REFINE, ProbeParams, Probes};
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
    let shares: Vec<f32> = match rest.get(5..) {
        Some(r) if !r.is_empty() => r.iter().map(|s| s.parse().expect("REFINE")).collect(),
        _ => vec![0.0, DEFAULT_REFINE],
    };
    let mut bakes = Vec::new();
    for &refine in &shares {
        config.output.probes = Some(ProbeParams {
            refine,
            ..params.clone()
        });
        let baked = lightbake::compute(Path::new(scene), &config, &NoProgress).expect("bake");
        let total: f64 = baked.stages.iter().map(|s| s.seconds).sum();
        let probe_seconds: f64 = (baked.stages.iter())
            .filter(|s| s.stage == "probes")
            .map(|s| s.seconds)
            .sum();
        let probes = baked.probes.clone().expect("probes");
        let grid = probes.grid.expect("the automatic grid");
        println!(
            "{scene} ({quality}), refine {refine}: {} probes ({} valid, {} moved, {} refined cells), grid {:?} step {:.3}, {:.2} M rays; probes {probe_seconds:.2}s of {total:.2}s computing ({:.1}%)",
            probes.len(),
            probes.valid_count(),
            probes.moved,
            probes.refinement.cells.len(),
            grid.count,
            grid.step.x,
            probes.rays as f64 * 1e-6,
            100.0 * probe_seconds / total
        );
        bakes.push((refine, baked, probes));
    }
    let baked = &bakes[0].1;
    let tracer = Tracer::new(&baked.scene);
    let emitters: Vec<Vec3> = (0..baked.texels.position.len())
        .filter(|&i| baked.texels.emission[i].max_element() > 0.0)
        .map(|i| baked.texels.position[i])
        .collect();
    let reference = ReferenceParams {
        max_samples: samples,
        seed: 7,
        ..ReferenceParams::like(&baked.config)
    };
    let trace = |at: &[(Vec3, Vec3)]| {
        let pts: Vec<Point> = (at.iter())
            .map(|&(position, normal)| Point {
                position,
                normal,
                shading_normal: normal,
            })
            .collect();
        points::trace_about(
            (&baked.scene, &baked.texels, &tracer),
            &pts,
            Normals::Shading,
            &reference,
            &NoProgress,
        )
        .expect("reference")
    };
    // Between the probes: the same points for every bake, from the first's cells.
    let first = &bakes[0].2;
    let shared: Vec<Vec<(Vec3, Vec3)>> = (1..3)
        .map(|m| first.points_between(&tracer, n, 3, m == 2))
        .collect();
    let shared_ref: Vec<_> = shared.iter().map(|at| trace(at)).collect();
    for (refine, _, probes) in &bakes {
        // At the bake's own valid probes (no interpolation: SH truncation and gather noise).
        let at_probes = at_probes(probes, n);
        let own = trace(&at_probes);
        for mode in 0..3 {
            let (at, r) = match mode {
                0 => (&at_probes, &own),
                m => (&shared[m - 1], &shared_ref[m - 1]),
            };
            report(*refine, mode, probes, (&tracer, &emitters), at, r);
        }
    }
}

/// Up to `n` of the valid probes, each with a normal of its own.
fn at_probes(probes: &Probes, n: usize) -> Vec<(Vec3, Vec3)> {
    (0..probes.len())
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
        .collect()
}

/// Points closer than this to an emissive texel are reported apart.
const NEAR: f32 = 0.25;

/// Prints the probes' error at `at` against the reference `r`.
fn report(
    refine: f32,
    mode: usize,
    probes: &Probes,
    (tracer, emitters): (&Tracer, &[Vec3]),
    at: &[(Vec3, Vec3)],
    r: &lightbake::reference::Reference,
) {
    let ours: Vec<Vec3> = (at.iter())
        .map(|&(p, n)| probes.irradiance_over_pi(p, n, Some(tracer)))
        .collect();
    let rmse = metrics::rmse_over_mean(&ours, &r.mean, &[]);
    let noise = metrics::noise_over_mean(&r.std_error, &r.mean, &[]);
    let bias = metrics::relative_bias(&ours, &r.mean, &[]);
    println!(
        "  refine {refine}: {} points ({}): relative RMSE {:.2}% without the reference's noise ({:.2}% raw, noise {:.2}%), bias {:+.2}%",
        at.len(),
        ["at the probes", "all free space", "whole cells"][mode],
        100.0 * metrics::without_noise(rmse, noise),
        100.0 * rmse,
        100.0 * noise,
        100.0 * bias
    );
    // The same without the points near an emitter (whose light is near-singular and dominates
    // the squared error).
    let near: Vec<u32> = (0..at.len() as u32)
        .filter(|&k| {
            let p = at[k as usize].0;
            emitters.iter().any(|e| e.distance(p) < NEAR)
        })
        .collect();
    let rmse = metrics::rmse_over_mean(&ours, &r.mean, &near);
    let noise = metrics::noise_over_mean(&r.std_error, &r.mean, &near);
    println!(
        "    without the {} points within {NEAR} of an emitter texel: {:.2}% ({:.2}% raw)",
        near.len(),
        100.0 * metrics::without_noise(rmse, noise),
        100.0 * rmse,
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
    for &(_, k) in worst.iter().take(3) {
        println!(
            "    p {:.3} n {:.2}: probes {:.4}, reference {:.4} ± {:.4}",
            at[k].0, at[k].1, ours[k].x, r.mean[k].x, r.std_error[k].x
        );
    }
}
