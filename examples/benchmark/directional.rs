//! Directional overhead (issue 16): what `--directional` costs. Per scene, the same bake (the
//! automatic choice at the medium target, the scene's density) runs twice in child processes,
//! back to back — plain and with directional pages ([`lightbake::lightmap::directional`],
//! default rays) — and the table compares wall time, peak resident memory (VmHWM, the child's
//! own) and the bytes written. Also run alone: `-- --directional-only [--scene NAME]…`.

use std::fmt::Write as _;
use std::path::Path;
use std::process::Command;
use std::time::Instant;

use lightbake::config::{AutoParams, Keep};
use lightbake::lightmap::directional;
use lightbake::{BakeConfig, NoProgress};

/// The command-line flag of the child mode.
pub const CHILD: &str = "--child-directional";

/// One child's bake.
#[derive(Clone, Copy, Debug, Default)]
pub struct Run {
    pub seconds: f64,
    pub peak_mib: f64,
    pub bytes: u64,
    /// The directional gather and its pages (0 for the plain bake).
    pub gather_seconds: f64,
}

/// Child mode: `SCENE TPU RAYS OUT` (RAYS 0: no directional pages). Bakes and writes into OUT,
/// prints `ok seconds peak bytes gather_seconds`.
pub fn child(args: &[String], peak_mib: fn() -> f64) {
    let [scene, tpu, rays, out] = args else {
        panic!("child arguments: {args:?}")
    };
    let mut config = BakeConfig::medium();
    config.atlas.texels_per_unit = tpu.parse().unwrap();
    config.auto = Some(AutoParams {
        target_error: 0.04,
        keep: Keep {
            texels_per_unit: true,
            ..Keep::default()
        },
    });
    let rays: u32 = rays.parse().unwrap();
    config.output.directional = (rays > 0).then_some(rays);
    let _ = std::fs::remove_dir_all(out);
    let start = Instant::now();
    match lightbake::bake(Path::new(scene), Path::new(out), &config, &NoProgress) {
        Ok(report) => {
            let seconds = start.elapsed().as_secs_f64();
            let bytes: u64 = (report.files.iter())
                .map(|f| std::fs::metadata(f).map_or(0, |m| m.len()))
                .sum();
            let gather: f64 = (report.stages.iter())
                .filter(|s| s.stage.starts_with("directional"))
                .map(|s| s.seconds)
                .sum();
            println!("ok\t{seconds}\t{}\t{bytes}\t{gather}", peak_mib());
        }
        Err(e) => println!("error\t{e}"),
    }
}

fn run(scene: &Path, tpu: f32, rays: u32, out: &Path) -> Result<Run, String> {
    let output = Command::new(std::env::current_exe().unwrap())
        .arg(CHILD)
        .args([
            scene.to_str().unwrap(),
            &tpu.to_string(),
            &rays.to_string(),
            out.to_str().unwrap(),
        ])
        .output()
        .map_err(|e| e.to_string())?;
    let text = String::from_utf8_lossy(&output.stdout);
    let f: Vec<&str> = text.lines().last().unwrap_or("error").split('\t').collect();
    if f[0] != "ok" || f.len() < 5 {
        return Err(f.get(1).unwrap_or(&"crashed").to_string());
    }
    Ok(Run {
        seconds: f[1].parse().unwrap(),
        peak_mib: f[2].parse().unwrap(),
        bytes: f[3].parse().unwrap(),
        gather_seconds: f[4].parse().unwrap(),
    })
}

/// Plain and directional bakes of one scene, back to back: the table row and the CSV line.
pub fn overhead(name: &str, scene: &Path, tpu: f32, work: &Path) -> (String, String) {
    let out = work.join("directional_overhead");
    let plain = run(scene, tpu, 0, &out);
    let with = run(scene, tpu, directional::DEFAULT_RAYS, &out);
    let (Ok(p), Ok(d)) = (plain, with) else {
        return (format!("| {name} | failed | | | | | | |\n"), String::new());
    };
    let pct = |a: f64, b: f64| (b / a - 1.0) * 100.0;
    let row = format!(
        "| {name} | {:.2} → {:.2} s ({:+.0}%) | {:.2} s | {:.0} → {:.0} MiB ({:+.0}%) | {:.2} → {:.2} MB ({:+.0}%) |\n",
        p.seconds,
        d.seconds,
        pct(p.seconds, d.seconds),
        d.gather_seconds,
        p.peak_mib,
        d.peak_mib,
        pct(p.peak_mib, d.peak_mib),
        p.bytes as f64 * 1e-6,
        d.bytes as f64 * 1e-6,
        pct(p.bytes as f64, d.bytes as f64),
    );
    let csv = format!(
        "{name},{},{},{},{},{},{},{}\n",
        p.seconds, d.seconds, d.gather_seconds, p.peak_mib, d.peak_mib, p.bytes, d.bytes
    );
    (row, csv)
}

/// The table's header and the CSV's.
pub fn headers() -> (String, String) {
    let mut md = String::new();
    let _ = writeln!(
        md,
        "| scene | bake time, plain → directional | of which directional | peak memory | files written |\n|---|---:|---:|---:|---:|"
    );
    let csv = "scene,plain_seconds,directional_seconds,directional_stage_seconds,plain_peak_mib,directional_peak_mib,plain_bytes,directional_bytes\n".to_string();
    (md, csv)
}
