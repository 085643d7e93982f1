//! Hierarchical radiosity diagnostics on the furnace: per-texel error of the solved lightmap, and
//! the per-texel row sums of the effective operator (every link reaching a texel, its
//! ancestors' included), split into estimate error, receiver variation and coverage against
//! exact contour integrals.
//!
//!     cargo run --release --example hierarchical_diagnose [scene.gltf] [texels-per-unit] [K]

use std::path::PathBuf;
use std::time::Instant;

use glam::Vec2;
use lightbake::config::Technique;
use lightbake::trace::Tracer;
use lightbake::transport::hierarchical::links::{self, Refiner};
use lightbake::transport::hierarchical::tree::Tree;
use lightbake::{BakeConfig, NoProgress, atlas, compute, metrics, scene, texels};

fn stats(name: &str, v: &[f64]) {
    let n = v.len().max(1) as f64;
    let mean = v.iter().sum::<f64>() / n;
    let rms = (v.iter().map(|x| x * x).sum::<f64>() / n).sqrt();
    let v: Vec<f32> = v.iter().map(|&x| x as f32).collect();
    let [p0, p5, p50, p95, p100] = metrics::percentiles(&v, [0.0, 0.05, 0.5, 0.95, 1.0]);
    println!(
        "{name:>28}: mean {mean:+.5} rms {rms:.5} min {:+.5} p5 {:+.5} p50 {:+.5} p95 {:+.5} max {:+.5}",
        p0, p5, p50, p95, p100
    );
}

fn main() -> lightbake::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let path = PathBuf::from(args.first().map_or("fixtures/furnace.gltf", |s| s.as_str()));
    let tpu: f32 = args.get(1).map_or(8.0, |s| s.parse().unwrap());
    let k: u32 = args.get(2).map_or(256, |s| s.parse().unwrap());
    let mut config = BakeConfig::draft();
    config.atlas.texels_per_unit = tpu;
    config.transport.gather_rays = k;
    config.transport.light_samples = 16;
    config.technique = Technique::Hierarchical;
    config.solve.tolerance = 1e-5;

    // 1. The solved lightmap against the furnace answer (ρ and Le from the first texel).
    let t = Instant::now();
    let baked = compute(&path, &config, &NoProgress)?;
    let seconds = t.elapsed().as_secs_f64();
    let rho = baked.texels.albedo[0].x as f64;
    let le = baked.texels.emission[0].x as f64;
    let want = le / (1.0 - rho);
    let err: Vec<f64> = baked
        .lightmap
        .iter()
        .map(|v| v.x as f64 / want - 1.0)
        .collect();
    println!(
        "{} texels, ρ {rho}, answer {want}, {seconds:.2}s, {} sweeps",
        baked.texels.len(),
        baked.solution.history.len()
    );
    stats("lightmap rel. error", &err);

    // 2. Links for uniform radiosity, as the second refinement pass sees the furnace.
    let (sc, source) = scene::load(&path)?;
    let at = atlas::build(&sc, &source, &config.atlas)?;
    let tx = texels::build(&sc, &at)?;
    let tracer = Tracer::new(&sc);
    let tree = Tree::build(&tx);
    let feet = links::footprints(&sc, &tx);
    let n = tx.len();
    let b_uniform = (std::f64::consts::PI * want) as f32;
    let b = vec![b_uniform; tree.len()];
    let area: f64 = tree
        .roots
        .iter()
        .map(|&r| tree.area[r as usize] as f64)
        .sum();
    let eta = 1.0 / (k as f64).sqrt();
    let epsilon = (eta * b_uniform as f64 * area / n as f64) as f32;
    let refiner = Refiner {
        texels: &tx,
        tracer: &tracer,
        tree: &tree,
        footprints: &feet,
        b: &b,
        epsilon,
        seed: 1,
    };
    let t = Instant::now();
    let l = refiner.refine(&|| false).unwrap();
    println!(
        "{} nodes, {} links ({:.1}/texel), {} rays, refine {:.2}s",
        tree.len(),
        l.len(),
        l.len() as f64 / n as f64,
        l.rays,
        t.elapsed().as_secs_f64()
    );

    let effective: f64 = (0..tree.len())
        .map(|p| {
            let [lo, hi] = tree.range[p];
            (l.start[p + 1] - l.start[p]) as f64 * (hi - lo) as f64
        })
        .sum::<f64>()
        / n as f64;
    println!("effective row length (links reaching a texel, inherited included): {effective:.1}");
    if n > 5000 {
        return Ok(());
    }
    // Texels of a node.
    let texels_of = |k: u32| {
        let [lo, hi] = tree.range[k as usize];
        tree.order[lo as usize..hi as usize].to_vec()
    };
    // Exact F from texel i (4×4 midpoints) to node q: Σ over q's texels of the contour integral.
    let exact = |i: u32, q: &[u32]| -> f64 {
        let mut sum = 0.0f64;
        for s in 0..16u32 {
            let u = (Vec2::new((s % 4) as f32, (s / 4) as f32) + 0.5) * 0.25;
            let x = links::footprint_point(&tx, &tracer, i as usize, u);
            for &j in q {
                if j != i {
                    sum += links::texel_form_factor(
                        &tx,
                        &feet[j as usize],
                        x,
                        tx.normal[i as usize],
                        j as usize,
                    ) as f64;
                }
            }
        }
        sum / 16.0
    };
    // Per texel: R (links' F), Rbar (area-mean exact F per link), Rstar (per-texel exact F).
    let mut r = vec![0.0f64; n];
    let mut rbar = vec![0.0f64; n];
    let mut rstar = vec![0.0f64; n];
    let mut by_kind = [[0.0f64; 3]; 4]; // [leaf←leaf, leaf←node, node←leaf, node←node] × (count, Σ A·(F − F̄), Σ A·F)
    for p in 0..tree.len() as u32 {
        let rp = l.start[p as usize] as usize..l.start[p as usize + 1] as usize;
        if rp.is_empty() {
            continue;
        }
        let recv = texels_of(p);
        for e in rp {
            let (q, f) = (l.source[e], l.f[e] as f64);
            let src = texels_of(q);
            let per: Vec<f64> = recv.iter().map(|&i| exact(i, &src)).collect();
            let ap: f64 = recv.iter().map(|&i| tx.area[i as usize] as f64).sum();
            let mean = recv
                .iter()
                .zip(&per)
                .map(|(&i, v)| tx.area[i as usize] as f64 * v)
                .sum::<f64>()
                / ap;
            for (&i, &v) in recv.iter().zip(&per) {
                r[i as usize] += f;
                rbar[i as usize] += mean;
                rstar[i as usize] += v;
            }
            let kind = (!tree.is_leaf(p) as usize) * 2 + !tree.is_leaf(q) as usize;
            by_kind[kind][0] += 1.0;
            by_kind[kind][1] += ap * (f - mean);
            by_kind[kind][2] += ap * f;
        }
    }
    // Exact row sum of each texel over all texels (the footprints' own closure).
    let all: Vec<u32> = (0..n as u32).collect();
    let closure: Vec<f64> = (0..n as u32).map(|i| exact(i, &all) - 1.0).collect();
    stats("exact closure Σ_j F_ij − 1", &closure);
    let mut worst: Vec<usize> = (0..n).collect();
    worst.sort_by(|&a, &b| closure[a].total_cmp(&closure[b]));
    for &i in worst.iter().take(6) {
        let full = tx.du[i].cross(tx.dv[i]).length();
        println!(
            "  texel {i}: closure {:+.4} lightmap {:+.4} pos {:.3} n {:.2} cover {:.3} xy {:?}",
            closure[i],
            err[i],
            tx.position[i],
            tx.normal[i],
            tx.area[i] / full,
            tx.xy[i]
        );
    }
    stats(
        "row sum R − 1",
        &r.iter().map(|v| v - 1.0).collect::<Vec<_>>(),
    );
    stats(
        "estimate R − R̄",
        &r.iter().zip(&rbar).map(|(a, b)| a - b).collect::<Vec<_>>(),
    );
    stats(
        "variation R̄ − R*",
        &rbar
            .iter()
            .zip(&rstar)
            .map(|(a, b)| a - b)
            .collect::<Vec<_>>(),
    );
    let scale = refiner.row_scale(&l);
    stats(
        "corrected R·s − 1",
        &r.iter()
            .zip(&scale)
            .map(|(a, s)| a * *s as f64 - 1.0)
            .collect::<Vec<_>>(),
    );
    stats(
        "coverage R* − 1",
        &rstar.iter().map(|v| v - 1.0).collect::<Vec<_>>(),
    );
    let total_area: f64 = tx.area.iter().map(|&a| a as f64).sum();
    for (name, k) in ["leaf←leaf", "leaf←node", "node←leaf", "node←node"]
        .iter()
        .zip(by_kind)
    {
        println!(
            "{name:>10}: {:>7} links, share of transfer {:.4}, area-weighted estimate bias {:+.5}",
            k[0],
            k[2] / total_area,
            k[1] / total_area
        );
    }
    Ok(())
}
