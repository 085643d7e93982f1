//! Where a bake's error against the reference sits: overall relative RMSE and mean bias, the
//! texels contributing most to the squared error (position, normal, bake vs reference), and for
//! `two_rooms` the mean of room B's floor away from the doorway (the leak criterion), and how
//! the bake's own error map (`--error-map`, `plan::error_map`) ranks the texels: the measured
//! error per decile of the estimate (texel values only: the map's resolution part, what a
//! lookup between texel centres misses, is not in a texel-level comparison).
//!
//!     cargo run --release --example error_map [scene.gltf] [texels-per-unit] [K] [ref samples] [hierarchical]
//!
//! `NO_VALIDITY=1` bakes (and traces the reference) without texel validity and divided texels.

use std::path::PathBuf;

use glam::Vec3;
use lightbake::reference::ReferenceParams;
use lightbake::{BakeConfig, NoProgress, compute, metrics};

fn main() -> lightbake::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let path = PathBuf::from(
        args.first()
            .map_or("fixtures/two_rooms.gltf", |s| s.as_str()),
    );
    let tpu: f32 = args.get(1).map_or(8.0, |s| s.parse().unwrap());
    let k: u32 = args.get(2).map_or(1024, |s| s.parse().unwrap());
    let samples: u32 = args.get(3).map_or(4096, |s| s.parse().unwrap());
    let mut config = BakeConfig::medium();
    config.atlas.texels_per_unit = tpu;
    config.transport.gather_rays = k;
    config.transport.light_samples = k / 8;
    config.solve.tolerance = 1e-5;
    if args.get(4).map(String::as_str) == Some("hierarchical") {
        config.technique = lightbake::config::Technique::Hierarchical;
    }
    config.transport.validity = std::env::var_os("NO_VALIDITY").is_none();
    config.output.error_map = true;
    let baked = compute(&path, &config, &NoProgress)?;
    let params = ReferenceParams {
        samples_per_pass: 32,
        max_samples: samples,
        ..Default::default()
    };
    let reference = lightbake::reference::compute(&path, &config, &params, &NoProgress)?.reference;
    let t = &baked.texels;
    let n = t.len();
    let (x, r, skip) = (&baked.lightmap, &reference.mean, &t.invalid);
    let valid = |i: usize| skip.binary_search(&(i as u32)).is_err();
    println!("{:?}; stages {:?}", baked.validity, baked.stages);
    println!(
        "{n} texels, rel RMSE {:.2}%, mean bias {:+.2}%, reference noise {:.2}%",
        100.0 * metrics::rmse_over_mean(x, r, skip),
        100.0 * metrics::relative_bias(x, r, skip),
        100.0 * metrics::noise_over_mean(&reference.std_error, r, skip)
    );
    // Room B's floor away from the doorway in `two_rooms` (lit only through the door).
    let far_b = |i: usize| {
        let p = t.position[i];
        valid(i) && p.x > 0.5 && p.z.abs() > 0.6 && p.y.abs() < 0.01
    };
    let outside: Vec<u32> = (0..n).filter(|&i| !far_b(i)).map(|i| i as u32).collect();
    if outside.len() < n {
        println!(
            "far B floor: {} texels, rel RMSE {:.2}%, mean bias {:+.2}%, reference noise {:.2}%",
            n - outside.len(),
            100.0 * metrics::rmse_over_mean(x, r, &outside),
            100.0 * metrics::relative_bias(x, r, &outside),
            100.0 * metrics::noise_over_mean(&reference.std_error, r, &outside)
        );
    }
    estimate_by_decile(&baked, r);
    // Each texel's share of the squared error.
    let sq: Vec<f64> = (0..n)
        .map(|i| {
            if valid(i) {
                (x[i] - r[i]).length_squared() as f64
            } else {
                0.0
            }
        })
        .collect();
    let total: f64 = sq.iter().sum();
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| sq[b].total_cmp(&sq[a]));
    let mut acc = 0.0;
    for (rank, &i) in order.iter().enumerate() {
        acc += sq[i];
        if rank < 40 || [100, 200, 400, 800].contains(&rank) {
            let p: Vec3 = t.position[i];
            println!(
                "#{rank:4} share {:5.1}% cum {:5.1}%  p ({:+.3},{:+.3},{:+.3}) n ({:+.0},{:+.0},{:+.0}) bake {:.4} ref {:.4} ± {:.4}",
                100.0 * sq[i] / total,
                100.0 * acc / total,
                p.x,
                p.y,
                p.z,
                t.normal[i].x,
                t.normal[i].y,
                t.normal[i].z,
                baked.lightmap[i].x,
                reference.mean[i].x,
                reference.std_error[i].x
            );
        }
    }
    Ok(())
}

/// The measured relative error of the texels (channel mean, floored as the map's: 5% of the
/// mean light), by decile of the map's estimated total (noise and resolution together) at the
/// texel.
fn estimate_by_decile(baked: &lightbake::Baked, reference: &[Vec3]) {
    let Some(map) = &baked.error_map else { return };
    let t = &baked.texels;
    let level = |v: Vec3| v.element_sum() / 3.0;
    let mean = reference.iter().map(|&v| level(v)).sum::<f32>() / reference.len() as f32;
    let mut pairs: Vec<(f32, f32)> = (0..t.len())
        .filter(|&i| t.invalid.binary_search(&(i as u32)).is_err())
        .map(|i| {
            let page = &map.pages[t.page[i] as usize];
            let [x, y] = t.xy[i];
            let estimate = page.rgb[(y * page.width + x) as usize];
            let measured = level((baked.lightmap[i] - reference[i]).abs())
                / (level(reference[i]) + 0.05 * mean);
            (estimate.z, measured)
        })
        .collect();
    pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
    println!("error map decile: mean estimated total, mean measured texel error");
    for (d, chunk) in pairs.chunks(pairs.len().div_ceil(10).max(1)).enumerate() {
        let n = chunk.len() as f32;
        let (e, m) = chunk
            .iter()
            .fold((0.0, 0.0), |(e, m), p| (e + p.0, m + p.1));
        println!("  {d}: {:6.2}% {:6.2}%", 100.0 * e / n, 100.0 * m / n);
    }
}
