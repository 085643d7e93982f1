//! Experiment: probes fitted to light gathered between them (least squares through the lookup's
//! own weights) against the probes as gathered at their positions.
//!
//! ```text
//! cargo run --release --example probe_fit -- SCENE [QUALITY] [TRAIN_POINTS] [TRAIN_PATHS] [LAMBDA...]
//! ```
//!
//! Bakes `SCENE` with its default probes, path-traces the L2 irradiance at `TRAIN_POINTS` random
//! free-space points (random normals, `TRAIN_PATHS` paths each), and solves for the probes'
//! coefficients that the lookup, read at those points, fits best, held towards the gathered
//! values by `LAMBDA` (per probe, in training rows' worth). Measures both at 1000 other
//! free-space points against 1024-path references.

use std::path::Path;

use glam::Vec3;
use lightbake::probes::measure::{self, SplitError};
use lightbake::probes::{ProbeParams, Probes, sh};
use lightbake::reference::ReferenceParams;
use lightbake::reference::points::{self, Normals, Point};
use lightbake::trace::Tracer;
use lightbake::{BakeConfig, NoProgress};

/// One training point: the lookup's linear weights on the flattened coefficients
/// (`probe·9 + k`) about its normal, and the path-traced L2 irradiance there.
struct Row {
    terms: Vec<(usize, f32)>,
    y: Vec3,
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let scene = &args[0];
    let mut config = match args.get(1).map_or("medium", String::as_str) {
        "draft" => BakeConfig::draft(),
        "high" => BakeConfig::high(),
        _ => BakeConfig::medium(),
    };
    let train: usize = args.get(2).map_or(8000, |s| s.parse().unwrap());
    let paths: u32 = args.get(3).map_or(64, |s| s.parse().unwrap());
    let lambdas: Vec<f32> = match args.get(4..) {
        Some(l) if !l.is_empty() => l.iter().map(|s| s.parse().unwrap()).collect(),
        _ => vec![1.0, 4.0, 16.0],
    };
    config.output.probes = Some(ProbeParams::default());
    let baked = lightbake::compute(Path::new(scene), &config, &NoProgress).expect("bake");
    let probes = baked.probes.clone().expect("probes");
    let tracer = Tracer::new(&baked.scene);
    let surfaces = (&baked.scene, &baked.texels, &tracer);
    let reference = |samples, seed| ReferenceParams {
        max_samples: samples,
        seed,
        ..ReferenceParams::like(&baked.config)
    };
    let t0 = std::time::Instant::now();
    let at = measure::free_space_points(&baked.scene, &tracer, 1000, 3);
    let pts: Vec<Point> = at.iter().map(|&(p, n)| Point::free(p, n)).collect();
    let truth = points::trace_about(
        surfaces,
        &pts,
        Normals::Shading,
        &reference(1024, 7),
        &NoProgress,
    )
    .expect("reference");
    let truth_l2 = lightbake::reference::trace_sh(surfaces, &at, &reference(1024, 7), &NoProgress)
        .expect("reference");
    let training = measure::free_space_points(&baked.scene, &tracer, train, 101);
    let y = lightbake::reference::trace_sh(surfaces, &training, &reference(paths, 11), &NoProgress)
        .expect("training");
    println!(
        "{} probes; references {:.1}s; training {} points × {} paths, noise {:.1}%",
        probes.len(),
        t0.elapsed().as_secs_f64(),
        training.len(),
        paths,
        100.0 * y.rms_rel_error
    );
    let rows: Vec<Row> = training
        .iter()
        .zip(&y.mean)
        .map(|(&(p, n), &y)| {
            let from = p + n * tracer.epsilon;
            // The lookup's linear part (before its clamp at zero): band weight × basis at n.
            let basis = sh::basis(n);
            let mut terms = Vec::new();
            probes.weights_at(
                p,
                |q| !tracer.occluded(from, q),
                |q, w| {
                    for (k, (b, c)) in basis.iter().zip(sh::COSINE_OVER_PI).enumerate() {
                        terms.push((9 * q + k, w * b * c));
                    }
                },
            );
            Row { terms, y }
        })
        .collect();
    let near_field = measure::near_field(&baked.scene, probes.budget);
    let positions: Vec<Vec3> = at.iter().map(|a| a.0).collect();
    let near = measure::near_emitters(&baked.scene, &baked.texels, &positions, near_field);
    let report = |name: &str, probes: &Probes| {
        let ours: Vec<Vec3> = at
            .iter()
            .map(|&(p, n)| probes.irradiance_over_pi(p, n, Some(&tracer)))
            .collect();
        let SplitError {
            all, far, near: ne, ..
        } = measure::split_error(&ours, &truth.mean, &truth.std_error, &near);
        let l2 = measure::split_error(&ours, &truth_l2.mean, &truth_l2.std_error, &near);
        println!(
            "{name}: vs irradiance all {:.2}% far {:.2}% near {:.2}%; vs L2 all {:.2}% far {:.2}% near {:.2}%",
            100.0 * all,
            100.0 * far,
            100.0 * ne,
            100.0 * l2.all,
            100.0 * l2.far,
            100.0 * l2.near
        );
    };
    report("gathered", &probes);
    // Per coefficient k, the rows' mean square weight on it: the prior's metric, so that λ = 1
    // holds a probe about as one training point would.
    let mut band = [0.0f32; 9];
    for r in &rows {
        for &(i, a) in &r.terms {
            band[i % 9] += a * a / rows.len() as f32;
        }
    }
    let metric: Vec<f32> = (0..9 * probes.len()).map(|i| band[i % 9]).collect();
    for &lambda in &lambdas {
        let fitted = fit(&probes, &rows, &metric, lambda);
        report(&format!("fitted λ={lambda}"), &fitted);
    }
}

/// Conjugate gradients on `(AᵀA + λD) x = Aᵀy + λD x0` over the flattened coefficients, `D`
/// the prior's metric, `x0` the gathered coefficients.
fn fit(probes: &Probes, rows: &[Row], metric: &[f32], lambda: f32) -> Probes {
    let x0: Vec<Vec3> = probes.sh.iter().flatten().copied().collect();
    let apply = |x: &[Vec3]| -> Vec<Vec3> {
        let mut out: Vec<Vec3> = (x.iter().zip(metric))
            .map(|(&v, &d)| v * (lambda * d))
            .collect();
        for r in rows {
            let pred: Vec3 = r.terms.iter().map(|&(i, a)| x[i] * a).sum();
            for &(i, a) in &r.terms {
                out[i] += pred * a;
            }
        }
        out
    };
    let mut b: Vec<Vec3> = (x0.iter().zip(metric))
        .map(|(&v, &d)| v * (lambda * d))
        .collect();
    for r in rows {
        for &(i, a) in &r.terms {
            b[i] += r.y * a;
        }
    }
    let dot = |u: &[Vec3], v: &[Vec3]| -> Vec3 { u.iter().zip(v).map(|(&a, &b)| a * b).sum() };
    let mut x = x0.clone();
    let mut r: Vec<Vec3> = b.iter().zip(apply(&x)).map(|(&b, ax)| b - ax).collect();
    let mut p = r.clone();
    let mut rr = dot(&r, &r);
    for _ in 0..200 {
        let ap = apply(&p);
        let alpha = rr / dot(&p, &ap).max(Vec3::splat(1e-30));
        for i in 0..x.len() {
            x[i] += p[i] * alpha;
            r[i] -= ap[i] * alpha;
        }
        let rr_new = dot(&r, &r);
        let beta = rr_new / rr.max(Vec3::splat(1e-30));
        for (p, &r) in p.iter_mut().zip(&r) {
            *p = r + *p * beta;
        }
        rr = rr_new;
    }
    Probes {
        sh: x
            .chunks_exact(9)
            .map(|c| std::array::from_fn(|k| c[k]))
            .collect(),
        ..probes.clone()
    }
}
