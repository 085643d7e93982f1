//! The texel figure and the point figure of one bake per scene, side by side.
//!
//! ```text
//! cargo run --release --example point_figures -- QUALITY POINTS SCENE.gltf...
//! ```
//!
//! For each scene: a bake at the `--quality` preset with its automatic choice (as `lightbake
//! bake --quality QUALITY`); the texel figure — relative RMSE `√mean((x−r)²)/mean(r)` of the
//! bake's texels against the path-traced reference at the same texels, valid texels only, with
//! the reference's noise taken out — and the point figure: the written bake read as a renderer
//! reads it, against `POINTS` path-traced points on the input's visible surfaces
//! (`lightbake::reference::points`). Both references trace to 1% relative RMS standard error
//! (`√Σσ²/Σr²`) or 4096 paths or 5 minutes, whichever comes first.

use std::path::Path;
use std::time::{Duration, Instant};

use lightbake::config::{AutoParams, Keep};
use lightbake::reference::{self, ReferenceParams, points};
use lightbake::render::RenderScene;
use lightbake::trace::Tracer;
use lightbake::{BakeConfig, NoProgress, metrics};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [quality, n, scenes @ ..] = &args[..] else {
        panic!("usage: point_figures QUALITY POINTS SCENE...")
    };
    let n: usize = n.parse().expect("POINTS");
    let mut config = match quality.as_str() {
        "draft" => BakeConfig::draft(),
        "medium" => BakeConfig::medium(),
        "high" => BakeConfig::high(),
        q => panic!("quality {q}: draft, medium or high"),
    };
    let target = AutoParams::for_preset(quality).unwrap();
    config.auto = Some(AutoParams {
        target_error: target,
        keep: Keep::default(),
    });
    let params = ReferenceParams {
        samples_per_pass: 32,
        max_samples: 4096,
        target_rel_error: Some(0.01),
        time_limit: Some(Duration::from_secs(300)),
        ..ReferenceParams::like(&config)
    };
    println!(
        "| scene | bake s | texel RMSE | texel noise | point RMSE | (noise out) | median | p95 | black | point noise | hidden | paths |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for scene in scenes {
        let input = Path::new(scene);
        let start = Instant::now();
        let baked = lightbake::compute(input, &config, &NoProgress).expect("bake");
        let bake_seconds = start.elapsed().as_secs_f64();

        let tracer = Tracer::new(&baked.scene);
        let texel_ref =
            reference::trace(&baked.scene, &baked.texels, &tracer, &params, &NoProgress)
                .expect("texel reference");
        let invalid = &baked.texels.invalid;
        let texel_rmse = metrics::rmse_over_mean(&baked.lightmap, &texel_ref.mean, invalid);
        let texel_noise = metrics::noise_over_mean(&texel_ref.std_error, &texel_ref.mean, invalid);

        let out = tempfile::tempdir().expect("temp dir");
        let used = baked.config.clone();
        let report = lightbake::write(baked, input, out.path(), &used, &NoProgress).expect("write");
        let render = RenderScene::load(&report.files[0]).expect("load the bake");
        let (point_ref, traced) =
            points::compute(input, &config, &params, n, &NoProgress).expect("point reference");
        let c = points::compare(&render, &point_ref);
        println!(
            "| {} | {:.1} | {:.2}% | {:.2}% | {:.2}% | {:.2}% | {:.2}% | {:.2}% | {:.2}% | {:.2}% | {} | {} |",
            input.file_stem().unwrap().to_string_lossy(),
            bake_seconds,
            metrics::without_noise(texel_rmse, texel_noise) * 100.0,
            texel_noise * 100.0,
            c.rmse * 100.0,
            c.rmse_without_noise * 100.0,
            c.median * 100.0,
            c.p95 * 100.0,
            c.black_touch * 100.0,
            c.noise * 100.0,
            point_ref.hidden,
            traced.samples,
        );
        if c.unmatched > 0 {
            println!("  ({} points found no baked surface)", c.unmatched);
        }
    }
}
