//! Point error, wall time and peak memory of two lightbake binaries (before and after a
//! change) baking the same scenes at each quality preset, interleaved in one run, and a chart.
//!
//! ```text
//! cargo run --release --example density_figures -- OUT REFS OLD_BIN NEW_BIN QUALITIES SCENE...
//! cargo run --release --example density_figures -- --from CSV CHART.png
//! ```
//!
//! `QUALITIES` is a comma-separated list of presets (`draft,medium,high`), each optionally with
//! its own target (`high@0.014`: `--quality high --target-error 0.014`, both binaries; a few
//! of them trace each binary's error-against-time front); `--seed N` bakes with that seed (the
//! plan is drawn from it: run several to see a change beside the seed spread).
//! For each scene the point reference `REFS/<stem>.csv` is read (written by `lightbake reference
//! SCENE --points N`); when missing it is computed (2048 points, to 1% noise or 4096 paths) and
//! stored there. Each binary bakes with `bake SCENE --quality Q` under `/usr/bin/time` (wall seconds, peak resident
//! memory); the output is read as a renderer reads it and compared with the reference
//! (`points::compare`): relative RMSE with the reference's noise taken out, p95, share of
//! lookups touching black texels. A camera view is the other yardstick: NEW_BIN path-traces
//! the scene's default view once (`reference --view`, stored as `REFS/<stem>_view.exr`), renders
//! each bake's view (`render`) and compares 4×4-pixel block means (`compare --view`, the
//! reference's noise taken out). The share of each bake's wall time spent planning on work the
//! result does not contain (density pilot, discarded pilot pairs, lookup-error samples) is
//! read from its summary line. Prints a Markdown table, writes `OUT/density_figures.csv`,
//! `OUT/density_before_after.png` (point error against time, one panel per scene) and
//! `OUT/density_before_after_p95.png` (the p95 alike). `--from CSV CHART.png` draws both again
//! from a CSV (the p95's beside it, `_p95` added to its name).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use lightbake::reference::ReferenceParams;
use lightbake::reference::points::{self, PointReference};
use lightbake::render::RenderScene;
use lightbake::{BakeConfig, NoProgress};
use plotters::prelude::*;

#[path = "../benchmark/font.rs"]
mod font;

struct Row {
    scene: String,
    quality: String,
    binary: &'static str,
    seconds: f64,
    peak_mb: f64,
    point: f32,
    p95: f32,
    black: f32,
    /// The default camera view's block error, the reference's noise out.
    view: f32,
    target: f32,
    /// Share of the wall time spent planning on work the result does not contain (the
    /// summary line's "of which planning": density pilot, discarded pilot pairs, samples).
    planning: f32,
}

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    // `--seed N` (anywhere): both binaries bake with that seed (their plans are drawn from it).
    let seed = args.iter().position(|a| a == "--seed").map(|i| {
        let n = args.remove(i + 1);
        args.remove(i);
        n
    });
    if let [from, csv, png] = &args[..]
        && from == "--from"
    {
        let rows = read_csv(&std::fs::read_to_string(csv).expect("CSV"));
        charts(Path::new(png), &rows);
        return;
    }
    let [out, refs, old, new, qualities, scenes @ ..] = &args[..] else {
        panic!("usage: density_figures OUT REFS OLD_BIN NEW_BIN QUALITIES SCENE...")
    };
    let (out, refs) = (Path::new(out), Path::new(refs));
    std::fs::create_dir_all(out).expect("OUT");
    std::fs::create_dir_all(refs).expect("REFS");
    let mut rows = Vec::new();
    println!(
        "| scene | quality | target | binary | time s | peak MB | point RMSE (noise out) | p95 | touching black | view (noise out) | planning |"
    );
    println!("|---|---|---:|---|---:|---:|---:|---:|---:|---:|---:|");
    for scene in scenes {
        let input = Path::new(scene);
        let stem = input.file_stem().unwrap().to_string_lossy().to_string();
        let reference = point_reference(input, &refs.join(format!("{stem}.csv")));
        let view_reference = view_reference(new, input, &refs.join(format!("{stem}_view.exr")));
        for entry in qualities.split(',') {
            let (quality, aim) = entry
                .split_once('@')
                .map_or((entry, None), |(q, t)| (q, Some(t)));
            let target = aim.map_or_else(
                || lightbake::config::AutoParams::for_preset(quality).expect("quality"),
                |t| t.parse().expect("a target error"),
            );
            for (binary, bin) in [("before", old), ("after", new)] {
                let dir = out.join(format!("{stem}_{entry}_{binary}"));
                let _ = std::fs::remove_dir_all(&dir);
                let (seconds, peak_mb, planning) =
                    bake(bin, input, &dir, quality, aim, seed.as_deref());
                let baked = baked_file(&dir, &stem);
                let render = RenderScene::load(&baked).expect("load the bake");
                let c = points::compare(&render, &reference);
                let view = view_error(new, &baked, &dir.join("view.exr"), &view_reference);
                let row = Row {
                    scene: stem.clone(),
                    quality: entry.to_string(),
                    binary,
                    seconds,
                    peak_mb,
                    point: c.rmse_without_noise,
                    p95: c.p95,
                    black: c.black_touch,
                    view,
                    target,
                    planning,
                };
                println!(
                    "| {} | {} | {:.1}% | {} | {:.2} | {:.0} | {:.2}%{} | {:.1}% | {:.2}% | {:.2}% | {:.0}% |",
                    row.scene,
                    row.quality,
                    target * 100.0,
                    binary,
                    seconds,
                    peak_mb,
                    row.point * 100.0,
                    if row.point > target { " (above)" } else { "" },
                    row.p95 * 100.0,
                    row.black * 100.0,
                    row.view * 100.0,
                    row.planning * 100.0
                );
                rows.push(row);
            }
        }
    }
    let mut csv = String::from(
        "scene,quality,target,binary,seconds,peak_mb,point_rmse,p95,black,view,planning\n",
    );
    for r in &rows {
        csv += &format!(
            "{},{},{},{},{:.3},{:.1},{},{},{},{},{}\n",
            r.scene,
            r.quality,
            r.target,
            r.binary,
            r.seconds,
            r.peak_mb,
            r.point,
            r.p95,
            r.black,
            r.view,
            r.planning
        );
    }
    std::fs::write(out.join("density_figures.csv"), csv).expect("write CSV");
    charts(&out.join("density_before_after.png"), &rows);
}

/// Point error against time at `png`, and the p95 alike beside it (`_p95` added to its name).
fn charts(png: &Path, rows: &[Row]) {
    chart(png, rows, Metric::Rmse).expect("chart");
    let p95 = png.with_file_name(format!(
        "{}_p95.png",
        png.file_stem().unwrap().to_string_lossy()
    ));
    chart(&p95, rows, Metric::P95).expect("chart");
}

/// Rows of a `density_figures.csv`.
fn read_csv(text: &str) -> Vec<Row> {
    text.lines()
        .skip(1)
        .filter(|l| !l.trim().is_empty())
        .map(|line| {
            let v: Vec<&str> = line.split(',').collect();
            let f = |i: usize| v[i].parse::<f32>().unwrap_or(f32::NAN);
            Row {
                scene: v[0].to_string(),
                quality: v[1].to_string(),
                binary: if v[3] == "before" { "before" } else { "after" },
                seconds: f64::from(f(4)),
                peak_mb: f64::from(f(5)),
                point: f(6),
                p95: f(7),
                black: f(8),
                view: f(9),
                target: f(2),
                // Older CSVs have no planning column.
                planning: v.get(10).and_then(|x| x.parse().ok()).unwrap_or(f32::NAN),
            }
        })
        .collect()
}

/// The stored point reference, or a new one (2048 points, 1% noise or 4096 paths) stored there.
fn point_reference(input: &Path, csv: &Path) -> PointReference {
    if let Ok(text) = std::fs::read_to_string(csv) {
        return PointReference::from_csv(&text, csv).expect("point reference");
    }
    let config = BakeConfig::medium();
    let params = ReferenceParams {
        samples_per_pass: 32,
        max_samples: 4096,
        target_rel_error: Some(0.01),
        time_limit: Some(Duration::from_secs(600)),
        ..ReferenceParams::like(&config)
    };
    let (reference, _) =
        points::compute(input, &config, &params, 2048, &NoProgress).expect("point reference");
    std::fs::write(csv, reference.to_csv()).expect("store the point reference");
    reference
}

/// The stored reference of the scene's default camera view, or a new one made by `bin`
/// (pixel noise to 3%, at most 1024 paths a pixel or 300 s) stored there.
fn view_reference(bin: &str, input: &Path, exr: &Path) -> PathBuf {
    if !exr.exists() {
        run(Command::new(bin)
            .arg("reference")
            .arg(input)
            .args([
                "--view",
                "--spp",
                "1024",
                "--target-error",
                "0.03",
                "--time",
                "300",
            ])
            .arg("-o")
            .arg(exr));
    }
    exr.to_path_buf()
}

/// The block error of `baked`'s default camera view, rendered by `bin` into `image`, against
/// `reference`, with the reference's noise out.
fn view_error(bin: &str, baked: &Path, image: &Path, reference: &Path) -> f32 {
    run(Command::new(bin)
        .arg("render")
        .arg(baked)
        .arg("-o")
        .arg(image));
    let out = run(Command::new(bin)
        .arg("compare")
        .arg(image)
        .arg("--view")
        .arg(reference));
    // "relative RMS diff.     2.10% (1.95% without the reference's noise)"
    out.lines()
        .find(|l| l.starts_with("relative RMS diff."))
        .and_then(|l| l.split('(').nth(1))
        .and_then(|l| l.split('%').next())
        .and_then(|v| v.trim().parse::<f32>().ok())
        .map_or(f32::NAN, |v| v / 100.0)
}

/// Runs `command`, panicking with its error output when it fails; its standard output.
fn run(command: &mut Command) -> String {
    let output = command.output().expect("run lightbake");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{command:?} failed: {stderr}");
    String::from_utf8_lossy(&output.stdout).into_owned()
}

/// Bakes with `bin` under `/usr/bin/time`; wall seconds, peak resident memory (MB) and the
/// share of the bake spent planning (from the summary line, printed when not `--quiet`; NaN
/// for a binary that does not print it).
fn bake(
    bin: &str,
    input: &Path,
    dir: &Path,
    quality: &str,
    target: Option<&str>,
    seed: Option<&str>,
) -> (f64, f64, f32) {
    let output = Command::new("/usr/bin/time")
        .args(["-f", "%e %M", bin, "bake"])
        .arg(input)
        .arg("-o")
        .arg(dir)
        .args(["--quality", quality])
        .args(target.map(|t| ["--target-error", t]).iter().flatten())
        .args(seed.map(|s| ["--seed", s]).iter().flatten())
        .output()
        .expect("run the bake");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{bin} failed: {stderr}");
    let last = stderr.lines().last().unwrap_or_default();
    let mut it = last
        .split_whitespace()
        .map(|v| v.parse::<f64>().unwrap_or(f64::NAN));
    let seconds = it.next().unwrap_or(f64::NAN);
    let kb = it.next().unwrap_or(f64::NAN);
    (
        seconds,
        kb / 1024.0,
        planning_share(&String::from_utf8_lossy(&output.stdout)),
    )
}

/// "… of which planning 0.18s (80%))" in a bake's summary line, as a share.
fn planning_share(stdout: &str) -> f32 {
    let Some((_, after)) = stdout.rsplit_once("of which planning ") else {
        return f32::NAN;
    };
    after
        .split_once('(')
        .and_then(|(_, p)| p.split_once('%'))
        .and_then(|(p, _)| p.parse::<f32>().ok())
        .map_or(f32::NAN, |p| p / 100.0)
}

/// The glTF or GLB a bake wrote into `dir`.
fn baked_file(dir: &Path, stem: &str) -> PathBuf {
    ["gltf", "glb"]
        .iter()
        .map(|ext| dir.join(format!("{stem}.{ext}")))
        .find(|p| p.exists())
        .expect("baked file")
}

/// What a chart plots against wall time.
#[derive(Clone, Copy)]
enum Metric {
    /// Relative RMSE at the points, the reference's noise out (the target's measure).
    Rmse,
    /// The 95th percentile of the points' relative errors.
    P95,
}

impl Metric {
    fn of(self, row: &Row) -> f64 {
        f64::from(match self {
            Metric::Rmse => row.point,
            Metric::P95 => row.p95,
        })
    }
}

/// `metric` against wall time, one panel per scene: before and after, one point per preset
/// (or per target), joined in order of time.
fn chart(path: &Path, rows: &[Row], metric: Metric) -> Result<(), Box<dyn std::error::Error>> {
    font::register();
    let mut scenes: Vec<&str> = rows.iter().map(|r| r.scene.as_str()).collect();
    scenes.dedup();
    let columns = 3;
    let lines = scenes.len().div_ceil(columns).max(1);
    let root = BitMapBackend::new(path, (1200, 380 * lines as u32)).into_drawing_area();
    root.fill(&WHITE)?;
    let panels = root.split_evenly((lines, columns));
    for (scene, panel) in scenes.iter().zip(panels.iter()) {
        let mine: Vec<&Row> = rows.iter().filter(|r| r.scene == *scene).collect();
        let (t0, t1) = mine.iter().fold((f64::MAX, f64::MIN), |(a, b), r| {
            (a.min(r.seconds), b.max(r.seconds))
        });
        let (e0, e1) = mine.iter().fold((f64::MAX, f64::MIN), |(a, b), r| {
            let e = metric.of(r).max(1e-4);
            let t = match metric {
                Metric::Rmse => f64::from(r.target),
                Metric::P95 => e,
            };
            (a.min(e.min(t)), b.max(e.max(t)))
        });
        let mut chart = ChartBuilder::on(panel)
            .caption(*scene, ("sans-serif", 18))
            .margin(8)
            .x_label_area_size(32)
            .y_label_area_size(52)
            .build_cartesian_2d(
                (t0 * 0.7..t1 * 1.4).log_scale().base(2.0),
                (e0 * 0.85)..(e1 * 1.1),
            )?;
        chart
            .configure_mesh()
            .x_desc("wall time (s)")
            .y_desc(match metric {
                Metric::Rmse => "point RMSE",
                Metric::P95 => "p95 point error",
            })
            .x_labels(12)
            .y_labels(8)
            .x_label_formatter(&|v| format!("{}", (v * 100.0).round() / 100.0))
            .y_label_formatter(&|v| format!("{:.1}%", v * 100.0))
            .draw()?;
        for (binary, color) in [
            ("before", RGBColor(150, 150, 150)),
            ("after", RGBColor(31, 119, 180)),
        ] {
            let mut pts: Vec<(f64, f64)> = mine
                .iter()
                .filter(|r| r.binary == binary)
                .map(|r| (r.seconds, metric.of(r)))
                .collect();
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            chart
                .draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))?
                .label(binary)
                .legend(move |(x, y)| {
                    PathElement::new([(x, y), (x + 18, y)], color.stroke_width(2))
                });
            chart.draw_series(pts.iter().map(|&p| Circle::new(p, 4, color.filled())))?;
            // A preset at its own target (no `@`): ringed, so the front shows where it stops.
            chart.draw_series(
                mine.iter()
                    .filter(|r| r.binary == binary && !r.quality.contains('@'))
                    .map(|r| Circle::new((r.seconds, metric.of(r)), 8, color.stroke_width(2))),
            )?;
        }
        // The targets (of the RMSE: the p95 has none), as dashed lines across.
        for r in mine
            .iter()
            .filter(|r| r.binary == "after" && matches!(metric, Metric::Rmse))
        {
            let y = f64::from(r.target);
            chart.draw_series(DashedLineSeries::new(
                [(t0 * 0.7, y), (t1 * 1.4, y)],
                4,
                4,
                RGBColor(200, 80, 80).stroke_width(1),
            ))?;
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()?;
    }
    root.present()?;
    Ok(())
}
