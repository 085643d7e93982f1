//! The hierarchical method against the Monte Carlo method at K = 1024 on the same texels
//! (the Monte Carlo lightmap is cached in `target/`): relative RMSE over texels and channels
//! (`metrics::rmse_over_mean`, as the benchmark), mean ratio, time and link counts.
//!
//!     cargo run --release --example hierarchical_compare [scene.gltf] [texels-per-unit] [K...]

use std::path::PathBuf;
use std::time::Instant;

use glam::Vec3;
use lightbake::config::Technique;
use lightbake::testing::cpu_seconds;
use lightbake::{BakeConfig, NoProgress, compute, metrics};

fn config(tpu: f32, method: Technique, k: u32) -> BakeConfig {
    let mut c = BakeConfig::medium();
    c.atlas.texels_per_unit = tpu;
    c.technique = method;
    c.transport.gather_rays = k;
    c.transport.light_samples = (k / 4).max(4);
    c
}

fn main() -> lightbake::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let path = PathBuf::from(
        args.first()
            .map_or("fixtures/cornell_box.gltf", |s| s.as_str()),
    );
    let tpu: f32 = args.get(1).map_or(32.0, |s| s.parse().unwrap());
    let ks: Vec<u32> = if args.len() > 2 {
        args[2..].iter().map(|s| s.parse().unwrap()).collect()
    } else {
        vec![256, 1024]
    };
    let stem = path.file_stem().unwrap().to_string_lossy().into_owned();
    let cache = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("target")
        .join(format!("mc1024_{stem}_{tpu}.bin"));
    let flat: Vec<f32> = if let Ok(bytes) = std::fs::read(&cache) {
        bytes
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
            .collect()
    } else {
        let t = Instant::now();
        let mc = compute(&path, &config(tpu, Technique::DEFAULT, 1024), &NoProgress)?;
        eprintln!("Monte Carlo K=1024: {:.1}s", t.elapsed().as_secs_f64());
        let v: Vec<f32> = mc.lightmap.iter().flat_map(|v| v.to_array()).collect();
        std::fs::write(
            &cache,
            v.iter().flat_map(|f| f.to_le_bytes()).collect::<Vec<u8>>(),
        )
        .unwrap();
        v
    };
    let reference: Vec<Vec3> = flat.chunks_exact(3).map(Vec3::from_slice).collect();
    for k in ks {
        let t = Instant::now();
        let cpu = cpu_seconds();
        let method = if std::env::var("LB_METHOD").is_ok_and(|m| m == "mc") {
            Technique::DEFAULT
        } else {
            Technique::Hierarchical
        };
        let h = compute(&path, &config(tpu, method, k), &NoProgress)?;
        let (wall, cpu) = (t.elapsed().as_secs_f64(), cpu_seconds() - cpu);
        let x = &h.lightmap;
        assert_eq!(x.len(), reference.len());
        let stages: Vec<String> = h
            .stages
            .iter()
            .map(|s| format!("{} {:.2}", s.stage, s.seconds))
            .collect();
        println!(
            "{stem} tpu {tpu} K {k}: {} texels, rel. RMSE vs MC1024 {:.2}%, mean {:+.2}%, wall {wall:.2}s cpu {cpu:.2}s, rays {:.1}M [{}]",
            h.texels.len(),
            metrics::rmse_over_mean(x, &reference, &[]) * 100.0,
            metrics::relative_bias(x, &reference, &[]) * 100.0,
            h.transport.rays as f64 * 1e-6,
            stages.join(", ")
        );
    }
    Ok(())
}
