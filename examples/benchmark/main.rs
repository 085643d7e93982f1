//! Speed against accuracy: every form-factor method and solver at several settings on the
//! fixture scenes, measured against the built-in path-traced reference.
//!
//! ```sh
//! cargo run --release --example benchmark               # full run (about 20 minutes on 2 cores)
//! cargo run --release --example benchmark -- --quick    # fewer settings, smaller reference
//! cargo run --release --example benchmark -- --scene cornell_box --scene furnace
//! cargo run --release --example benchmark -- --scene furnace --method hierarchical
//! cargo run --release --example benchmark -- --relight  # only the relight table (large hall)
//! cargo run --release --example benchmark -- --probes   # only probe error against probe count
//! cargo run --release --example benchmark -- --directional-only --scene cornell_box
//! ```
//!
//! Writes `examples/gallery/bench.csv`, `bench.md` and the charts `error_vs_time_<scene>.png`
//! and `residual_vs_iteration.png` (and `bench_directional.csv`: the directional overhead,
//! `directional.rs`). Each bake runs in a child process (this program run with
//! `--child`), so its peak memory (VmHWM) is its own.
//!
//! Error metrics over all valid texels and channels, against the reference `r` (`x` = bake), from
//! `lightbake::metrics`:
//! - relative RMSE `sqrt(mean((x−r)²)) / mean(r)` (`rmse_over_mean`);
//! - p95 and max of `|x−r| / (r + 0.05·mean(r))` (the floor keeps dark texels from dominating).
//!
//! The point figure (`point_rmse`, issue 12) is what a renderer shows: each bake is written, read
//! back as `lightbake render` reads it (`TEXCOORD_1`, bilinear lookup in the EXR pages) and
//! compared with path-traced `H/π` at random points on visible surfaces
//! (`lightbake::reference::points`, one point reference per scene): the same relative RMSE,
//! but between texel centres too, so it includes resolution error the texel figure cannot see.
//!
//! The reference's own noise (its RMS standard error, relative to `mean(r)`: `noise_over_mean`)
//! is drawn as a dashed line: errors below it cannot be told apart from zero. The headline table
//! ("time to reach 5%, 2%, 1%") subtracts it in quadrature, `sqrt(rmse² − noise²)`
//! (`without_noise`): the expected squared error against a noisy reference is the true squared
//! error plus the reference's variance.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use glam::Vec3;
use lightbake::config::{AutoParams, FormFactors, Keep, RowSolver, Technique};
use lightbake::reference::points::{self, PointReference};
use lightbake::render::RenderScene;
use lightbake::{BakeConfig, NoProgress, metrics};
use plotters::prelude::*;

mod directional;
mod font;
mod probes;
mod relight;
mod stability;

/// One bake configuration of the sweep.
#[derive(Clone, Debug)]
struct Setting {
    technique: Technique,
    rays: u32,
    light_samples: u32,
    tolerance: f32,
    /// Automatic choice (`lightbake::plan`) for this target error; the fields above are then
    /// what it chose (filled in from the child's report).
    auto: Option<f32>,
}

impl Setting {
    fn label(&self) -> String {
        match self.auto {
            Some(_) => "automatic choice".into(),
            None => self.technique.to_string(),
        }
    }
}

/// What a child process reports about one bake.
#[derive(Clone, Debug, Default)]
struct Measured {
    seconds: f64,
    stages: String,
    rays: u64,
    iterations: usize,
    residual: f32,
    converged: bool,
    peak_mib: f64,
    history: Vec<f32>,
    /// For automatic runs: method, solver, rays and light samples chosen.
    chosen: Option<(Technique, u32, u32)>,
    /// Relative RMSE of the written bake at the scene's reference points (NaN if not measured).
    point_rmse: f32,
    error: Option<String>,
}

/// One row of the results table.
#[derive(Clone, Debug)]
struct Row {
    scene: String,
    setting: Setting,
    measured: Measured,
    rmse: f32,
    p95: f32,
    max: f32,
}

/// A fixture scene and the texel density it is measured at (fixed per scene, so every run and
/// the reference share the same texels).
struct Scene {
    name: &'static str,
    path: PathBuf,
    texels_per_unit: f32,
    /// All-pairs methods are only run where the texel count allows.
    all_pairs: bool,
    /// Only Monte Carlo + Jacobi and the automatic choice (the scene is there for its size).
    montecarlo_only: bool,
    /// Sample counts of the path tracer's own curve.
    pt_counts: &'static [u32],
    /// The reference stops after this long (or at 0.4% noise).
    reference_seconds: u64,
}

fn scenes(out: &Path, quick: bool) -> Vec<Scene> {
    let fixture = |f: &str| {
        PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("fixtures")
            .join(f)
    };
    let large = out.join("large_hall.glb");
    if !large.exists() {
        std::fs::write(&large, lightbake::testing::large_hall().to_glb_bytes())
            .expect("write large_hall.glb");
    }
    vec![
        Scene {
            name: "cornell_box",
            path: fixture("cornell_box.gltf"),
            texels_per_unit: 32.0,
            all_pairs: true,
            ..Scene::default()
        },
        Scene {
            name: "furnace",
            path: fixture("furnace_09.gltf"),
            texels_per_unit: 16.0,
            all_pairs: true,
            ..Scene::default()
        },
        Scene {
            name: "two_rooms",
            path: fixture("two_rooms.gltf"),
            texels_per_unit: 8.0,
            all_pairs: true,
            ..Scene::default()
        },
        Scene {
            name: "large_hall",
            path: large,
            texels_per_unit: if quick { 2.0 } else { 3.0 },
            all_pairs: false,
            ..Scene::default()
        },
        // The point-error corpus (issue 12): hard sun shadows, punctual lights only, and a
        // 64k-triangle furnished interior. Monte Carlo and the automatic choice only.
        Scene {
            name: "courtyard",
            path: fixture("courtyard.gltf"),
            texels_per_unit: 8.0,
            montecarlo_only: true,
            ..Scene::default()
        },
        Scene {
            name: "lamp_room",
            path: fixture("lamp_room.gltf"),
            texels_per_unit: 16.0,
            montecarlo_only: true,
            ..Scene::default()
        },
        Scene {
            name: "furnished_interior",
            path: fixture("furnished_interior.glb"),
            texels_per_unit: 8.0,
            montecarlo_only: true,
            ..Scene::default()
        },
        // The issue's large case: the Cornell box at about 167k texels (161 texels/m), where a
        // CPU path-tracing baker needs about 15 minutes for 1%. Its path tracer curve stops at
        // 64 paths per texel; the time to each error is scaled from there as 1/error².
        Scene {
            name: "cornell_box_167k",
            path: fixture("cornell_box.gltf"),
            texels_per_unit: if quick { 64.0 } else { 161.0 },
            all_pairs: false,
            montecarlo_only: true,
            pt_counts: &[16, 64],
            reference_seconds: if quick { 60 } else { 420 },
        },
    ]
}

impl Default for Scene {
    fn default() -> Self {
        Scene {
            name: "",
            path: PathBuf::new(),
            texels_per_unit: 16.0,
            all_pairs: false,
            montecarlo_only: false,
            pt_counts: &[16, 64, 256, 1024],
            reference_seconds: 240,
        }
    }
}

fn settings(scene: &Scene, quick: bool) -> Vec<Setting> {
    let mut out = Vec::new();
    let rays: &[u32] = if quick {
        &[32, 128, 512]
    } else {
        &[16, 64, 256, 1024]
    };
    let s = |technique, rays: u32| Setting {
        technique,
        rays,
        light_samples: (rays / 4).max(4),
        tolerance: 1e-4,
        auto: None,
    };
    for &k in rays {
        if !(scene.montecarlo_only && k < 64) {
            out.push(s(Technique::DEFAULT, k));
        }
    }
    if scene.montecarlo_only {
        for target in [0.04, 0.02] {
            out.push(Setting {
                auto: Some(target),
                ..s(Technique::DEFAULT, 256)
            });
        }
        return out;
    }
    for solver in [RowSolver::GaussSeidel, RowSolver::Southwell] {
        out.push(s(Technique::stored(FormFactors::MonteCarlo, solver), 256));
    }
    for &k in &rays[..rays.len() - 1] {
        out.push(s(Technique::Gather, k));
    }
    for &k in rays {
        out.push(s(Technique::Hierarchical, k));
    }
    if scene.all_pairs {
        for &k in &rays[..2] {
            out.push(s(
                Technique::stored(FormFactors::Polygon, RowSolver::Jacobi),
                k,
            ));
        }
        out.push(s(
            Technique::stored(FormFactors::Point, RowSolver::Jacobi),
            64,
        ));
    }
    // The automatic choice at the presets' targets (draft 8%, medium 4%, high 2%).
    for target in [0.08, 0.04, 0.02] {
        out.push(Setting {
            auto: Some(target),
            ..s(Technique::DEFAULT, 256)
        });
    }
    out
}

fn config(scene_tpu: f32, setting: &Setting) -> BakeConfig {
    let mut c = BakeConfig::medium();
    c.atlas.texels_per_unit = scene_tpu;
    c.technique = setting.technique;
    c.transport.gather_rays = setting.rays;
    c.transport.light_samples = setting.light_samples;
    c.solve.tolerance = setting.tolerance;
    if let Some(target_error) = setting.auto {
        // The density stays the scene's, so the reference shares the texels.
        c.auto = Some(AutoParams {
            target_error,
            keep: Keep {
                texels_per_unit: true,
                ..Keep::default()
            },
        });
    }
    c
}

/// Peak resident memory of this process (Linux), MiB.
fn peak_mib() -> f64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<f64>().ok())
        .map_or(0.0, |kb| kb / 1024.0)
}

/// Child mode: bake once, write the lightmap values as raw f32 to `values`, write the bake and
/// compare it with the point reference `points`, print one line.
fn child(args: &[String]) {
    let [scene, tpu, method, solver, rays, light, tol, values, points] = args else {
        panic!("child arguments: {args:?}")
    };
    let auto = method == "auto";
    let setting = Setting {
        technique: Technique::from_names(if auto { "montecarlo" } else { method }, solver).unwrap(),
        rays: rays.parse().unwrap(),
        light_samples: light.parse().unwrap(),
        tolerance: if auto { 1e-4 } else { tol.parse().unwrap() },
        auto: auto.then(|| tol.parse().unwrap()),
    };
    let config = config(tpu.parse().unwrap(), &setting);
    let start = Instant::now();
    match lightbake::compute(Path::new(scene), &config, &NoProgress) {
        Ok(baked) => {
            let seconds = start.elapsed().as_secs_f64();
            let peak = peak_mib(); // the bake's, before writing and reading it back
            let bytes: Vec<u8> = baked
                .lightmap
                .iter()
                .flat_map(|v| v.to_array())
                .flat_map(f32::to_le_bytes)
                .collect();
            std::fs::write(values, bytes).unwrap();
            let stages: Vec<String> = baked
                .stages
                .iter()
                .map(|s| format!("{}={:.3}", s.stage, s.seconds))
                .collect();
            let history: Vec<String> = baked
                .solution
                .history
                .iter()
                .map(|i| format!("{:e}", i.residual))
                .collect();
            let c = baked.config.clone();
            let (transport_rays, solution) = (baked.transport.rays, baked.solution.clone());
            let total_rays = (baked.plan.as_ref())
                .and_then(|p| p.total_rays)
                .unwrap_or(c.transport.gather_rays);
            let point_rmse = point_rmse(baked, Path::new(scene), Path::new(points));
            println!(
                "ok\t{seconds}\t{}\t{}\t{}\t{}\t{}\t{}\t{}\t{} {} {} {}\t{point_rmse}",
                stages.join(" "),
                transport_rays,
                solution.history.len(),
                solution.residual(),
                solution.converged,
                peak,
                history.join(","),
                c.technique.method(),
                c.technique.solver(),
                // Automatic runs: rays per texel in all, the reused pilot bakes included.
                total_rays,
                c.transport.light_samples
            );
        }
        Err(e) => println!("error\t{e}"),
    }
}

/// Writes `baked` next to the point reference `points`, reads it back as a renderer does and
/// returns its relative RMSE at the reference points.
fn point_rmse(baked: lightbake::Baked, input: &Path, points: &Path) -> f32 {
    let out = points.with_extension("bake");
    let _ = std::fs::remove_dir_all(&out);
    let config = baked.config.clone();
    let report = lightbake::write(baked, input, &out, &config, &NoProgress).expect("write");
    let render = RenderScene::load(&report.files[0]).expect("read the bake back");
    let text = std::fs::read_to_string(points).expect("point reference");
    let reference = PointReference::from_csv(&text, points).expect("point reference");
    points::compare(&render, &reference).rmse
}

fn run_child(scene: &Scene, setting: &Setting, values: &Path, points: &Path) -> Measured {
    let output = Command::new(std::env::current_exe().unwrap())
        .arg("--child")
        .args([
            scene.path.to_str().unwrap(),
            &scene.texels_per_unit.to_string(),
            if setting.auto.is_some() {
                "auto"
            } else {
                setting.technique.method()
            },
            setting.technique.solver(),
            &setting.rays.to_string(),
            &setting.light_samples.to_string(),
            &setting.auto.unwrap_or(setting.tolerance).to_string(),
            values.to_str().unwrap(),
            points.to_str().unwrap(),
        ])
        .output()
        .expect("run child");
    let text = String::from_utf8_lossy(&output.stdout);
    let line = text.lines().last().unwrap_or("error\tno output");
    let f: Vec<&str> = line.split('\t').collect();
    if f[0] != "ok" || f.len() < 9 {
        let stderr = String::from_utf8_lossy(&output.stderr);
        let message = f.get(1).map_or_else(
            || stderr.lines().last().unwrap_or("crashed").to_string(),
            |m| m.to_string(),
        );
        return Measured {
            error: Some(message),
            point_rmse: f32::NAN,
            ..Default::default()
        };
    }
    Measured {
        seconds: f[1].parse().unwrap(),
        stages: f[2].to_string(),
        rays: f[3].parse().unwrap(),
        iterations: f[4].parse().unwrap(),
        residual: f[5].parse().unwrap(),
        converged: f[6] == "true",
        peak_mib: f[7].parse().unwrap(),
        history: f[8].split(',').filter_map(|r| r.parse().ok()).collect(),
        chosen: f.get(9).and_then(|c| {
            let c: Vec<&str> = c.split(' ').collect();
            Some((
                Technique::from_names(c.first()?, c.get(1)?).ok()?,
                c.get(2)?.parse().ok()?,
                c.get(3)?.parse().ok()?,
            ))
        }),
        point_rmse: f.get(10).and_then(|p| p.parse().ok()).unwrap_or(f32::NAN),
        error: None,
    }
}

fn read_values(path: &Path) -> Vec<Vec3> {
    std::fs::read(path)
        .unwrap()
        .chunks_exact(12)
        .map(|c| {
            let f = |k: usize| f32::from_le_bytes(c[k..k + 4].try_into().unwrap());
            Vec3::new(f(0), f(4), f(8))
        })
        .collect()
}

/// (relative RMSE, p95, max) of `x` against `r` over the texels not listed in `skip` (texels
/// buried in geometry, which a bake fills from neighbours); see the module docs.
fn errors(x: &[Vec3], r: &[Vec3], skip: &[u32]) -> (f32, f32, f32) {
    let [p95, max] =
        metrics::percentiles(&metrics::floored_relative_errors(x, r, skip), [0.95, 1.0]);
    (metrics::rmse_over_mean(x, r, skip), p95, max)
}

/// The path-traced reference at the scene's texels: mean, relative RMS standard error,
/// seconds, samples per texel, and which texels to skip (buried in geometry).
struct Ref {
    mean: Vec<Vec3>,
    noise: f32,
    seconds: f64,
    samples: u32,
    invalid: Vec<u32>,
    /// Where each texel's sample is (for region errors in the stability table).
    position: Vec<Vec3>,
}

fn reference(scene: &Scene, quick: bool) -> Ref {
    let mut config = BakeConfig::medium();
    config.atlas.texels_per_unit = scene.texels_per_unit;
    let params = lightbake::reference::ReferenceParams {
        samples_per_pass: 32,
        max_samples: if quick { 1024 } else { 4096 },
        target_rel_error: Some(if quick { 0.01 } else { 0.004 }),
        time_limit: Some(Duration::from_secs(if quick {
            60.min(scene.reference_seconds)
        } else {
            scene.reference_seconds
        })),
        ..Default::default()
    };
    let start = Instant::now();
    let computed = lightbake::reference::compute(&scene.path, &config, &params, &NoProgress)
        .expect("reference");
    let reference = computed.reference;
    let invalid = computed.texels.invalid;
    Ref {
        noise: metrics::noise_over_mean(&reference.std_error, &reference.mean, &invalid),
        seconds: start.elapsed().as_secs_f64(),
        samples: reference.samples,
        mean: reference.mean,
        invalid,
        position: computed.texels.position,
    }
}

/// The scene's point reference (see the module docs), written to `<work>/points_<scene>.csv`
/// for the children; returns the file and its relative noise.
fn point_reference(scene: &Scene, work: &Path, quick: bool) -> (PathBuf, f32) {
    let mut config = BakeConfig::medium();
    config.atlas.texels_per_unit = scene.texels_per_unit;
    let params = lightbake::reference::ReferenceParams {
        samples_per_pass: 32,
        max_samples: 4096,
        target_rel_error: Some(if quick { 0.01 } else { 0.005 }),
        time_limit: Some(Duration::from_secs(scene.reference_seconds / 2)),
        ..Default::default()
    };
    let n = if quick { 1024 } else { 4096 };
    let (r, _) =
        points::compute(&scene.path, &config, &params, n, &NoProgress).expect("point reference");
    let path = work.join(format!("points_{}.csv", scene.name));
    std::fs::write(&path, r.to_csv()).expect("write the point reference");
    (path, metrics::noise_over_mean(&r.std_error, &r.mean, &[]))
}

/// The path tracer itself at increasing sample counts, for the "same error, how much faster"
/// comparison: (seconds, relative RMSE against the reference) per sample count.
fn path_tracer_curve(scene: &Scene, reference: &Ref, quick: bool) -> Vec<(u32, f64, f32)> {
    let mut config = BakeConfig::medium();
    config.atlas.texels_per_unit = scene.texels_per_unit;
    let counts: &[u32] = if quick {
        &scene.pt_counts[..scene.pt_counts.len().min(3)]
    } else {
        scene.pt_counts
    };
    counts
        .iter()
        .map(|&spp| {
            let params = lightbake::reference::ReferenceParams {
                max_samples: spp,
                samples_per_pass: spp.min(64),
                seed: 7, // independent of the reference's own samples
                ..Default::default()
            };
            let start = Instant::now();
            let pt = lightbake::reference::compute(&scene.path, &config, &params, &NoProgress)
                .expect("path tracer");
            let seconds = start.elapsed().as_secs_f64();
            (
                spp,
                seconds,
                errors(&pt.reference.mean, &reference.mean, &reference.invalid).0,
            )
        })
        .collect()
}

const COLORS: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
];

fn chart_error_vs_time(
    path: &Path,
    scene: &str,
    rows: &[&Row],
    noise: f32,
    pt: &[(u32, f64, f32)],
) -> Result<(), Box<dyn std::error::Error>> {
    let ok: Vec<&&Row> = rows
        .iter()
        .filter(|r| r.measured.error.is_none() && r.rmse.is_finite())
        .collect();
    let times = ok
        .iter()
        .map(|r| r.measured.seconds)
        .chain(pt.iter().map(|p| p.1));
    let errs = ok
        .iter()
        .map(|r| r.rmse as f64)
        .chain(pt.iter().map(|p| p.2 as f64))
        .chain([noise as f64]);
    let (t0, t1) = times.fold((f64::MAX, f64::MIN), |(a, b), t| (a.min(t), b.max(t)));
    let (e0, e1) = errs.fold((f64::MAX, f64::MIN), |(a, b), e| {
        (a.min(e.max(1e-5)), b.max(e))
    });
    let root = BitMapBackend::new(path, (900, 600)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!("{scene}: error against the path-traced reference vs bake time"),
            ("sans-serif", 22),
        )
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(
            (t0 * 0.7..t1 * 1.4).log_scale(),
            (e0 * 0.7..e1 * 1.4).log_scale(),
        )?;
    chart
        .configure_mesh()
        .x_desc("wall time (s)")
        .y_desc("relative RMSE")
        .y_label_formatter(&|v| format!("{:.1}%", v * 100.0))
        .draw()?;
    let mut labels: Vec<String> = ok.iter().map(|r| r.setting.label()).collect();
    labels.dedup();
    labels.sort();
    labels.dedup();
    for (k, label) in labels.iter().enumerate() {
        let color = COLORS[k % COLORS.len()];
        let mut pts: Vec<(f64, f64)> = ok
            .iter()
            .filter(|r| &r.setting.label() == label)
            .map(|r| (r.measured.seconds, r.rmse as f64))
            .collect();
        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
        chart
            .draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))?
            .label(label.as_str())
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 18, y)], color.stroke_width(2)));
        if label.starts_with("automatic") {
            chart.draw_series(
                pts.iter()
                    .map(|&p| TriangleMarker::new(p, 8, BLACK.filled())),
            )?;
        } else {
            chart.draw_series(pts.iter().map(|&p| Circle::new(p, 4, color.filled())))?;
        }
    }
    if !pt.is_empty() {
        let pts: Vec<(f64, f64)> = pt.iter().map(|p| (p.1, p.2 as f64)).collect();
        chart
            .draw_series(LineSeries::new(pts.clone(), BLACK.stroke_width(2)))?
            .label("path tracer (reference code)")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 18, y)], BLACK.stroke_width(2)));
        chart.draw_series(pts.iter().map(|&p| Cross::new(p, 5, BLACK)))?;
    }
    let dash: Vec<(f64, f64)> = vec![(t0 * 0.7, noise as f64), (t1 * 1.4, noise as f64)];
    chart
        .draw_series(DashedLineSeries::new(
            dash,
            6,
            4,
            RGBColor(120, 120, 120).stroke_width(1),
        ))?
        .label("reference noise")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 18, y)], RGBColor(120, 120, 120)));
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerLeft)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}

fn chart_residuals(path: &Path, rows: &[&Row]) -> Result<(), Box<dyn std::error::Error>> {
    let root = BitMapBackend::new(path, (900, 600)).into_drawing_area();
    root.fill(&WHITE)?;
    let max_it = rows
        .iter()
        .map(|r| r.measured.history.len())
        .max()
        .unwrap_or(1)
        .max(2);
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "Solver residual vs iteration (Cornell box and ρ = 0.9 furnace, 256 rays)",
            ("sans-serif", 22),
        )
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(1..max_it, (1e-7f64..1.0).log_scale())?;
    chart
        .configure_mesh()
        .x_desc("iteration")
        .y_desc("relative update")
        .draw()?;
    for (k, row) in rows.iter().enumerate() {
        let color = COLORS[k % COLORS.len()];
        let pts: Vec<(usize, f64)> = row
            .measured
            .history
            .iter()
            .enumerate()
            .map(|(i, r)| (i + 1, (*r as f64).max(1e-7)))
            .collect();
        chart
            .draw_series(LineSeries::new(pts, color.stroke_width(2)))?
            .label(format!("{} {}", row.scene, row.setting.technique.solver()))
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 18, y)], color.stroke_width(2)));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}

/// Markdown rows comparing each automatic run with the fixed runs of the same scene: is any
/// fixed run both faster and more accurate (then the choice is off the front), and how long the
/// fastest fixed run at or below its error took.
fn pareto_rows(rows: &[Row], noise: f32) -> String {
    let ok = |r: &&Row| r.measured.error.is_none() && r.rmse.is_finite();
    let fixed: Vec<&Row> = rows
        .iter()
        .filter(ok)
        .filter(|r| r.setting.auto.is_none())
        .collect();
    let mut out = String::new();
    for a in rows.iter().filter(ok).filter(|r| r.setting.auto.is_some()) {
        let target = a.setting.auto.unwrap();
        let (t, e) = (a.measured.seconds, a.rmse);
        let corrected = metrics::without_noise(e, noise);
        let dominated = fixed
            .iter()
            .filter(|f| f.measured.seconds < t && f.rmse < e)
            .min_by(|x, y| x.measured.seconds.total_cmp(&y.measured.seconds));
        let front = fixed
            .iter()
            .filter(|f| f.rmse <= e)
            .min_by(|x, y| x.measured.seconds.total_cmp(&y.measured.seconds));
        let front_cell = front.map_or("none".to_string(), |f| {
            format!(
                "{} K={}: {:.2}s ({:.2}%)",
                f.setting.label(),
                f.setting.rays,
                f.measured.seconds,
                f.rmse * 100.0
            )
        });
        let verdict = match dominated {
            None => "on the front".to_string(),
            Some(d) => format!(
                "{:.1}× the time of {} K={} ({:.2}%)",
                t / d.measured.seconds,
                d.setting.label(),
                d.setting.rays,
                d.rmse * 100.0
            ),
        };
        let _ = writeln!(
            out,
            "| {} | {:.0}% | {} K={} L={} | {:.2} | {:.2}% ({:.2}%) | {} | {} | {} |",
            a.scene,
            target * 100.0,
            format_args!(
                "{}/{}",
                a.setting.technique.method(),
                a.setting.technique.solver()
            ),
            a.setting.rays,
            a.setting.light_samples,
            t,
            e * 100.0,
            corrected * 100.0,
            if corrected <= target { "yes" } else { "no" },
            front_cell,
            verdict
        );
    }
    out
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.first().map(String::as_str) == Some("--child") {
        child(&args[1..]);
        return;
    }
    if args.first().map(String::as_str) == Some(directional::CHILD) {
        directional::child(&args[1..], peak_mib);
        return;
    }
    let directional_only = args.iter().any(|a| a == "--directional-only");
    let (mut directional_md, mut directional_csv) = directional::headers();
    let quick = args.iter().any(|a| a == "--quick");
    let only: Vec<&str> = args
        .windows(2)
        .filter(|w| w[0] == "--scene")
        .map(|w| w[1].as_str())
        .collect();
    let methods: Vec<&str> = args
        .windows(2)
        .filter(|w| w[0] == "--method")
        .map(|w| w[1].as_str())
        .collect();
    let gallery = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("examples/gallery");
    let work = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/chart");
    std::fs::create_dir_all(&work).unwrap();
    std::fs::create_dir_all(&gallery).unwrap();
    if args.iter().any(|a| a == "--relight") {
        let md = relight_table(&work, &gallery);
        println!("{md}");
        return;
    }
    font::register();
    if args.iter().any(|a| a == "--probes") {
        println!("{}", probes::measure_all(&gallery));
        return;
    }

    let mut rows: Vec<Row> = Vec::new();
    let mut md = String::new();
    let mut headline = String::new();
    let mut pareto = String::new();
    // References the stability table reuses: (scene name, path, density, reference).
    let mut kept: Vec<(&'static str, PathBuf, f32, Ref)> = Vec::new();
    for scene in scenes(&work, quick) {
        if !only.is_empty() && !only.contains(&scene.name) {
            continue;
        }
        eprintln!("== {}: directional overhead", scene.name);
        let (row, csv) =
            directional::overhead(scene.name, &scene.path, scene.texels_per_unit, &work);
        eprint!("   {row}");
        directional_md.push_str(&row);
        directional_csv.push_str(&csv);
        if directional_only {
            continue;
        }
        eprintln!("== {}: reference", scene.name);
        let reference = reference(&scene, quick);
        let noise = reference.noise;
        eprintln!(
            "   {} texels, {} spp, noise {:.2}%, {:.1}s",
            reference.mean.len(),
            reference.samples,
            noise * 100.0,
            reference.seconds
        );
        let (points, point_noise) = point_reference(&scene, &work, quick);
        eprintln!("   point reference noise {:.2}%", point_noise * 100.0);
        let pt = path_tracer_curve(&scene, &reference, quick);
        let mut scene_rows = Vec::new();
        for setting in settings(&scene, quick) {
            if !methods.is_empty() && !methods.contains(&setting.technique.method()) {
                continue;
            }
            let values = work.join("values.bin");
            let _ = std::fs::remove_file(&values);
            let measured = run_child(&scene, &setting, &values, &points);
            let mut setting = setting;
            if let (Some(_), Some((technique, rays, light))) = (setting.auto, measured.chosen) {
                (setting.technique, setting.rays) = (technique, rays);
                setting.light_samples = light;
            }
            let (rmse, p95, max) = if measured.error.is_none() {
                errors(&read_values(&values), &reference.mean, &reference.invalid)
            } else {
                (f32::NAN, f32::NAN, f32::NAN)
            };
            eprintln!(
                "   {:<26} K={:<5} {:>8.2}s  rmse {:>6.2}%  points {:>6.2}%  {}",
                setting.label(),
                setting.rays,
                measured.seconds,
                rmse * 100.0,
                measured.point_rmse * 100.0,
                measured.error.as_deref().unwrap_or("")
            );
            scene_rows.push(Row {
                scene: scene.name.to_string(),
                setting,
                measured,
                rmse,
                p95,
                max,
            });
        }
        pareto.push_str(&pareto_rows(&scene_rows, noise));
        let refs: Vec<&Row> = scene_rows.iter().collect();
        let chart = gallery.join(format!("error_vs_time_{}.png", scene.name));
        if let Err(e) = chart_error_vs_time(&chart, scene.name, &refs, noise, &pt) {
            eprintln!("chart {}: {e}", chart.display());
        }
        // Headline: time for the best bake to reach each error level vs the path tracer.
        let _ = writeln!(
            headline,
            "| {} | {} | {:.2}% |{}",
            scene.name,
            reference.mean.len(),
            noise * 100.0,
            {
                let mut cells = String::new();
                for target in [0.05f32, 0.02, 0.01] {
                    let true_error = |e: f32| metrics::without_noise(e, noise);
                    let bake = scene_rows
                        .iter()
                        .filter(|r| r.measured.error.is_none() && true_error(r.rmse) <= target)
                        .map(|r| r.measured.seconds)
                        .fold(f64::INFINITY, f64::min);
                    // The path tracer's error falls like 1/√spp: interpolate its time to `target`.
                    let pt_time = pt
                        .iter()
                        .map(|&(_, s, e)| s * (true_error(e) as f64 / target as f64).powi(2))
                        .fold(f64::INFINITY, f64::min);
                    let cell = if bake.is_finite() {
                        format!(
                            " {:.2}s vs {:.1}s ({:.0}×) |",
                            bake,
                            pt_time,
                            pt_time / bake
                        )
                    } else {
                        format!(" not reached vs {pt_time:.1}s |")
                    };
                    cells.push_str(&cell);
                }
                cells
            }
        );
        rows.extend(scene_rows);
        if scene.name == "cornell_box" || scene.name == "two_rooms" {
            kept.push((
                scene.name,
                scene.path.clone(),
                scene.texels_per_unit,
                reference,
            ));
        }
    }

    if directional_only {
        println!("{directional_md}");
        return;
    }
    eprintln!("== stability cases");
    let known = |name: &str| {
        kept.iter()
            .find(|k| k.0 == name)
            .map(|(_, path, tpu, r)| stability::Known {
                path,
                texels_per_unit: *tpu,
                mean: &r.mean,
                invalid: &r.invalid,
                noise: r.noise,
                position: &r.position,
            })
    };
    let stability_md = stability::table(
        &work,
        known("cornell_box").as_ref(),
        known("two_rooms").as_ref(),
    );
    eprintln!("== quality figures");
    let quality_md = stability::quality_table(&work, known("cornell_box").as_ref());

    // Residual chart: every solver on the Cornell box and the furnace at 256 rays.
    let residual_rows: Vec<&Row> = rows
        .iter()
        .filter(|r| {
            r.setting.technique.is_monte_carlo()
                && r.setting.auto.is_none()
                && r.setting.rays == 256
                && r.measured.error.is_none()
        })
        .filter(|r| r.scene == "cornell_box" || r.scene == "furnace")
        .collect();
    if let Err(e) = chart_residuals(&gallery.join("residual_vs_iteration.png"), &residual_rows) {
        eprintln!("residual chart: {e}");
    }

    // CSV and Markdown.
    let mut csv = String::from(
        "scene,method,solver,rays_per_texel,light_samples,seconds,stages,rays,mrays_per_s,peak_mib,iterations,residual,converged,rel_rmse,p95_rel,max_rel,point_rel_rmse,error\n",
    );
    let _ = writeln!(
        md,
        "| scene | method | solver | K | time (s) | rays (M) | Mrays/s | peak MiB | iterations | rel. RMSE | p95 | max | point RMSE |"
    );
    let _ = writeln!(
        md,
        "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
    );
    for r in &rows {
        let m = &r.measured;
        let mrays = m.rays as f64 * 1e-6;
        let rate = if m.seconds > 0.0 {
            mrays / m.seconds
        } else {
            0.0
        };
        let method = match r.setting.auto {
            Some(t) => format!("auto {:.0}% → {}", t * 100.0, r.setting.technique.method()),
            None => r.setting.technique.method().to_string(),
        };
        let _ = writeln!(
            csv,
            "{},{},{},{},{},{:.4},{},{},{:.3},{:.1},{},{:e},{},{:.5},{:.5},{:.5},{:.5},{}",
            r.scene,
            method,
            r.setting.technique.solver(),
            r.setting.rays,
            r.setting.light_samples,
            m.seconds,
            m.stages,
            m.rays,
            rate,
            m.peak_mib,
            m.iterations,
            m.residual,
            m.converged,
            r.rmse,
            r.p95,
            r.max,
            m.point_rmse,
            m.error.as_deref().unwrap_or("").replace(',', ";")
        );
        if let Some(e) = &m.error {
            let _ = writeln!(
                md,
                "| {} | {} | {} | {} | — | — | — | — | — | refused: {} | | | |",
                r.scene,
                method,
                r.setting.technique.solver(),
                r.setting.rays,
                e.chars().take(60).collect::<String>()
            );
        } else {
            let _ = writeln!(
                md,
                "| {} | {} | {} | {} | {:.2} | {:.1} | {:.1} | {:.0} | {}{} | {:.2}% | {:.1}% | {:.0}% | {:.2}% |",
                r.scene,
                method,
                r.setting.technique.solver(),
                r.setting.rays,
                m.seconds,
                mrays,
                rate,
                m.peak_mib,
                m.iterations,
                if m.converged { "" } else { " (cap)" },
                r.rmse * 100.0,
                r.p95 * 100.0,
                r.max * 100.0,
                m.point_rmse * 100.0
            );
        }
    }
    let mut report = String::new();
    let _ = writeln!(
        report,
        "Time to reach a relative RMSE (corrected for the reference's noise), fastest bake vs the built-in path tracer (same texels, same run):\n"
    );
    let _ = writeln!(
        report,
        "| scene | texels | reference noise | 5% | 2% | 1% |\n|---|---:|---:|---|---|---|"
    );
    report.push_str(&headline);
    let _ = writeln!(
        report,
        "\nThe automatic choice (`--quality draft/medium/high`: 8%, 4%, 2% targets; pilot included in its time) against the Pareto front of the fixed settings:\n"
    );
    let _ = writeln!(
        report,
        "| scene | target | chosen | time (s) | error (corrected) | target met | fastest fixed run at ≤ that error | verdict |\n|---|---:|---|---:|---:|---|---|---|"
    );
    report.push_str(&pareto);
    let _ = writeln!(
        report,
        "\nStability: where methods fail, what lightbake does, measured in the same run:\n"
    );
    report.push_str(&stability_md);
    let _ = writeln!(report, "\nLightmap quality, measured in the same run:\n");
    report.push_str(&quality_md);
    report.push_str(&relight_table(&work, &gallery));
    let _ = writeln!(
        report,
        "\nDirectional overhead (`--directional`, {} rays per texel; the automatic choice at 4%, plain and directional bakes back to back):\n",
        lightbake::lightmap::directional::DEFAULT_RAYS
    );
    report.push_str(&directional_md);
    let _ = writeln!(report, "\nEvery run:\n");
    report.push_str(&md);
    std::fs::write(gallery.join("bench_directional.csv"), &directional_csv).unwrap();
    std::fs::write(gallery.join("bench.csv"), csv).unwrap();
    std::fs::write(gallery.join("bench.md"), &report).unwrap();
    println!("{report}");
    println!("wrote {}/bench.csv, bench.md and charts", gallery.display());
}

/// The relight figures of the large hall: `bench_relight.csv` in `gallery`, and the Markdown
/// table returned.
fn relight_table(work: &Path, gallery: &Path) -> String {
    let hall = work.join("large_hall.gltf");
    lightbake::testing::large_hall()
        .write_gltf(&hall)
        .expect("write large_hall.gltf");
    eprintln!("== large_hall: relight against a fresh bake");
    let row = relight::measure("large_hall", &hall, work);
    eprintln!("   {}", row.csv());
    let csv = format!("{}\n{}\n", relight::RelightRow::CSV_HEADER, row.csv());
    std::fs::write(gallery.join("bench_relight.csv"), csv).unwrap();
    relight::RelightRow::markdown(&[row])
}
