//! Probe error against probe count (`--probes`): two rooms and the furnished interior baked once
//! at `medium`, their probes gathered again from the same solution at budgets from 256 to 8192
//! (`probes::for_bake`), each measured at the same free-space points against two path-traced
//! references: the true irradiance about each point's normal (`reference::points::trace_about`,
//! what a surface there receives) and the L2 projection a probe could hold at best
//! (`reference::trace_sh`): the gap between the two is L2's truncation, the rest the probes' own
//! error (interpolation between them, gather noise, the bake's error).
//!
//! Writes `probe_error_vs_count.csv` and `probe_error_vs_count.png` in the gallery; returns the
//! Markdown table.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::Vec3;
use lightbake::probes::{self, ProbeParams, measure};
use lightbake::reference::points::{self, Normals, Point};
use lightbake::reference::{Reference, ReferenceParams};
use lightbake::trace::Tracer;
use lightbake::{BakeConfig, NoProgress};
use plotters::prelude::*;

/// Free-space points per scene and paths per point of each reference.
const POINTS: usize = 1000;
const SAMPLES: u32 = 1024;
/// The budgets charted.
const BUDGETS: [u32; 6] = [256, 512, 1024, 2048, 4096, 8192];

/// One budget of one scene.
struct Row {
    scene: &'static str,
    budget: u32,
    /// Probes placed (at most the budget), and the bake's automatic budget's marker.
    probes: usize,
    automatic: bool,
    seconds: f64,
    /// The bake's own computing time (without its probes).
    bake_seconds: f64,
    /// (all, far) against the true irradiance, then against the L2 projection.
    truth: (f32, f32),
    l2: (f32, f32),
}

impl Row {
    const CSV_HEADER: &'static str = "scene,budget,probes,automatic,probe_seconds,bake_seconds,all_vs_truth,far_vs_truth,all_vs_l2,far_vs_l2";

    fn csv(&self) -> String {
        format!(
            "{},{},{},{},{:.3},{:.2},{:.4},{:.4},{:.4},{:.4}",
            self.scene,
            self.budget,
            self.probes,
            self.automatic,
            self.seconds,
            self.bake_seconds,
            self.truth.0,
            self.truth.1,
            self.l2.0,
            self.l2.1
        )
    }
}

/// Measures both scenes; writes the CSV and the chart in `gallery`; returns the table.
pub fn measure_all(gallery: &Path) -> String {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("fixtures");
    let mut rows = Vec::new();
    for (name, file) in [
        ("two_rooms", "two_rooms.gltf"),
        ("furnished_interior", "furnished_interior.glb"),
    ] {
        rows.extend(scene(name, &root.join(file)));
    }
    let mut csv = format!("{}\n", Row::CSV_HEADER);
    for r in &rows {
        writeln!(csv, "{}", r.csv()).unwrap();
    }
    std::fs::write(gallery.join("probe_error_vs_count.csv"), csv).unwrap();
    chart(&gallery.join("probe_error_vs_count.png"), &rows).expect("probe chart");
    let mut md = String::from(
        "| scene | probes (budget) | probe stage | of the bake | all / far vs irradiance | all / far vs L2 |\n|---|---|---|---|---|---|\n",
    );
    for r in &rows {
        let auto = if r.automatic { " (automatic)" } else { "" };
        writeln!(
            md,
            "| {} | {} ({}{auto}) | {:.2} s | {:.1}% | {:.1}% / {:.1}% | {:.1}% / {:.1}% |",
            r.scene,
            r.probes,
            r.budget,
            r.seconds,
            100.0 * r.seconds / r.bake_seconds,
            100.0 * r.truth.0,
            100.0 * r.truth.1,
            100.0 * r.l2.0,
            100.0 * r.l2.1
        )
        .unwrap();
    }
    md
}

/// Bakes `path` at `medium` with probes at the automatic budget, then gathers the other budgets
/// from the same solution and measures every one at the same points.
fn scene(name: &'static str, path: &Path) -> Vec<Row> {
    eprintln!("== {name}: bake (medium, probes at the automatic budget)");
    let mut config = BakeConfig::medium();
    config.output.probes = Some(ProbeParams::default());
    let baked = lightbake::compute(path, &config, &NoProgress).expect("bake");
    let bake_seconds: f64 = (baked.stages.iter())
        .filter(|t| t.stage != "probes")
        .map(|t| t.seconds)
        .sum();
    let automatic = baked.probes.as_ref().expect("probes").budget;
    let tracer = Tracer::new(&baked.scene);
    let at = measure::free_space_points(&baked.scene, &tracer, POINTS, 3);
    // One split for every budget: the automatic budget's spacing.
    let positions: Vec<Vec3> = at.iter().map(|a| a.0).collect();
    let near_field = measure::near_field(&baked.scene, automatic);
    let near = measure::near_emitters(&baked.scene, &baked.texels, &positions, near_field);
    let params = ReferenceParams {
        max_samples: SAMPLES,
        seed: 7,
        ..ReferenceParams::like(&baked.config)
    };
    let surfaces = (&baked.scene, &baked.texels, &tracer);
    let t = Instant::now();
    let pts: Vec<Point> = (at.iter())
        .map(|&(position, normal)| Point::free(position, normal))
        .collect();
    let truth = points::trace_about(surfaces, &pts, Normals::Shading, &params, &NoProgress)
        .expect("reference");
    let l2 = lightbake::reference::trace_sh(surfaces, &at, &params, &NoProgress).expect("L2");
    eprintln!(
        "   {} points ({} near), references {:.0} s, noise {:.1}% / {:.1}% (L2)",
        at.len(),
        near.len(),
        t.elapsed().as_secs_f64(),
        100.0 * lightbake::metrics::noise_over_mean(&truth.std_error, &truth.mean, &[]),
        100.0 * lightbake::metrics::noise_over_mean(&l2.std_error, &l2.mean, &[])
    );
    let mut budgets: Vec<u32> = BUDGETS.to_vec();
    if !budgets.contains(&automatic) {
        budgets.push(automatic);
        budgets.sort_unstable();
    }
    let mut rows = Vec::new();
    for budget in budgets {
        let params = ProbeParams {
            budget: Some(budget),
            ..ProbeParams::default()
        };
        let t = Instant::now();
        let probes = probes::for_bake(&baked, &params, path, &NoProgress).expect("probes");
        let seconds = t.elapsed().as_secs_f64();
        let ours: Vec<Vec3> = (at.iter())
            .map(|&(p, n)| probes.irradiance_over_pi(p, n, Some(&tracer)))
            .collect();
        let split = |r: &Reference| {
            let e = measure::split_error(&ours, &r.mean, &r.std_error, &near);
            (e.all, e.far)
        };
        let row = Row {
            scene: name,
            budget,
            probes: probes.len(),
            automatic: budget == automatic,
            seconds,
            bake_seconds,
            truth: split(&truth),
            l2: split(&l2),
        };
        eprintln!("   {}", row.csv());
        rows.push(row);
    }
    rows
}

/// A chart line: label, value of a row, colour, dashed.
type Line = (&'static str, fn(&Row) -> f32, RGBColor, bool);

/// Error against probe count, one panel per scene: far and all points, against the true
/// irradiance (solid) and the L2 projection (dashed); the automatic budget marked.
fn chart(path: &Path, rows: &[Row]) -> Result<(), Box<dyn std::error::Error>> {
    let root = BitMapBackend::new(path, (1200, 520)).into_drawing_area();
    root.fill(&WHITE)?;
    let panels = root.split_evenly((1, 2));
    for (panel, scene) in panels.iter().zip(["two_rooms", "furnished_interior"]) {
        let mine: Vec<&Row> = rows.iter().filter(|r| r.scene == scene).collect();
        if mine.is_empty() {
            continue;
        }
        let errors = mine
            .iter()
            .flat_map(|r| [r.truth.0, r.truth.1, r.l2.0, r.l2.1]);
        let (e0, e1) = errors.fold((f32::MAX, 0.0f32), |(a, b), e| (a.min(e), b.max(e)));
        // x is log₂ of the probe count, labelled with the count.
        let x = |r: &Row| (r.probes as f64).log2();
        let (n0, n1) =
            (mine.iter()).fold((f64::MAX, 0.0f64), |(a, b), r| (a.min(x(r)), b.max(x(r))));
        let mut chart = ChartBuilder::on(panel)
            .caption(
                format!("{scene} (medium): probes vs path tracer"),
                ("sans-serif", 20),
            )
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(60)
            .build_cartesian_2d(
                n0 - 0.3..n1 + 0.3,
                (f64::from(e0.max(1e-3)) * 0.8..f64::from(e1) * 1.25).log_scale(),
            )?;
        chart
            .configure_mesh()
            .x_desc("probes")
            .y_desc("relative RMSE at 1000 free-space points")
            .light_line_style(WHITE)
            .x_labels(8)
            .y_labels(12)
            .x_label_formatter(&|v| format!("{:.0}", v.exp2()))
            .y_label_formatter(&|v| format!("{:.0}%", v * 100.0))
            .draw()?;
        let lines: [Line; 4] = [
            (
                "all points vs irradiance",
                |r| r.truth.0,
                RGBColor(200, 60, 40),
                false,
            ),
            ("all points vs L2", |r| r.l2.0, RGBColor(200, 60, 40), true),
            (
                "far from emitters vs irradiance",
                |r| r.truth.1,
                RGBColor(40, 90, 190),
                false,
            ),
            (
                "far from emitters vs L2",
                |r| r.l2.1,
                RGBColor(40, 90, 190),
                true,
            ),
        ];
        for (label, value, color, dashed) in lines {
            let pts: Vec<(f64, f64)> = (mine.iter()).map(|r| (x(r), f64::from(value(r)))).collect();
            let style = color.stroke_width(2);
            if dashed {
                // The legend's sample dashed too: two short strokes.
                chart
                    .draw_series(DashedLineSeries::new(pts.clone(), 8, 5, style))?
                    .label(label)
                    .legend(move |(x, y)| {
                        EmptyElement::at((x, y))
                            + PathElement::new([(0, 0), (7, 0)], style)
                            + PathElement::new([(11, 0), (18, 0)], style)
                    });
            } else {
                chart
                    .draw_series(LineSeries::new(pts.clone(), style))?
                    .label(label)
                    .legend(move |(x, y)| PathElement::new([(x, y), (x + 18, y)], style));
            }
            chart.draw_series(pts.iter().map(|&p| Circle::new(p, 3, color.filled())))?;
            let auto = (mine.iter())
                .filter(|r| r.automatic)
                .map(|r| (x(r), f64::from(value(r))));
            chart.draw_series(auto.map(|p| TriangleMarker::new(p, 8, BLACK.filled())))?;
        }
        let five = vec![(n0 - 0.3, 0.05), (n1 + 0.3, 0.05)];
        chart
            .draw_series(DashedLineSeries::new(five, 4, 4, BLACK.stroke_width(1)))?
            .label("5% (issue 29's aim); ▲ the automatic budget")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 18, y)], BLACK));
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::LowerLeft)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()?;
    }
    root.present()?;
    Ok(())
}
