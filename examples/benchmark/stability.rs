//! The failure cases of the radiosity core, measured in the benchmark run: for each, what fails,
//! what lightbake does about it, and the measured effect (a Markdown table in `bench.md`).

use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

use glam::Vec3;
use lightbake::config::{FormFactors, RowSolver, Technique};

use lightbake::{BakeConfig, Baked, NoProgress, metrics, testing};

/// A reference the main run computed, with where its texels are.
pub struct Known<'a> {
    pub path: &'a Path,
    pub texels_per_unit: f32,
    pub mean: &'a [Vec3],
    /// Texels buried in geometry (sorted), left out of every error.
    pub invalid: &'a [u32],
    pub noise: f32,
    pub position: &'a [Vec3],
}

struct Case {
    method: String,
    fails: String,
    cure: String,
    effect: String,
}

fn bake(path: &Path, config: &BakeConfig) -> Result<(Baked, f64), String> {
    let start = Instant::now();
    lightbake::compute(path, config, &NoProgress)
        .map(|b| (b, start.elapsed().as_secs_f64()))
        .map_err(|e| e.to_string())
}

fn finite(b: &Baked) -> bool {
    b.lightmap.iter().all(|v| v.is_finite())
}

/// The texels an error over the region `select` leaves out: the reference's invalid ones and
/// those outside the region.
fn outside(known: &Known, select: impl Fn(Vec3) -> bool) -> Vec<u32> {
    (0..known.position.len() as u32)
        .filter(|&i| known.invalid.binary_search(&i).is_ok() || !select(known.position[i as usize]))
        .collect()
}

/// Relative RMSE against a reference over the texels `select` keeps (and the reference keeps).
fn rmse(x: &[Vec3], known: &Known, select: impl Fn(Vec3) -> bool) -> f32 {
    metrics::rmse_over_mean(x, known.mean, &outside(known, select))
}

/// The furnace of `lightbake::testing` with albedo `rho`; above 1 written by editing the JSON
/// (the builder refuses it, as glTF does; the loader must cope anyway).
fn furnace_file(dir: &Path, rho: f32) -> std::path::PathBuf {
    let path = dir.join(format!("furnace_{rho}.gltf"));
    let (mut json, bin) = lightbake::testing::furnace(rho.min(1.0), 1.0).to_gltf_json();
    json["materials"][0]["pbrMetallicRoughness"]["baseColorFactor"] =
        serde_json::json!([rho, rho, rho, 1.0]);
    json["buffers"][0]["uri"] = serde_json::Value::String(format!(
        "data:application/octet-stream;base64,{}",
        base64::Engine::encode(&base64::engine::general_purpose::STANDARD, &bin)
    ));
    std::fs::write(&path, serde_json::to_vec(&json).unwrap()).expect("write furnace");
    path
}

fn point_singularity(dir: &Path) -> Case {
    let path = furnace_file(dir, 0.9);
    let mut c = BakeConfig::draft();
    c.atlas.texels_per_unit = 16.0;
    c.technique = Technique::stored(FormFactors::Point, RowSolver::Jacobi);
    c.solve.tolerance = 1e-5;
    let effect = match bake(&path, &c) {
        Ok((b, seconds)) => {
            let t = &b.texels;
            // The box is convex: every pair sees each other, the raw kernel needs no rays.
            let raw_max = testing::raw_point_kernel_max_row_sum(t);
            let cured_max = (0..b.transport.len())
                .map(|i| b.transport.row(i).map(|(_, f)| f).sum::<f32>() + b.transport.escape[i])
                .fold(0.0f32, f32::max);
            format!(
                "furnace ρ=0.9, {} texels: raw max row sum {raw_max:.3}; cured rows ≤ {cured_max:.4}; \
                 worst texel {:.2}% from 1/(1−ρ), finite: {} ({seconds:.1}s)",
                t.len(),
                metrics::max_relative_deviation(&b.lightmap, 10.0) * 100.0,
                finite(&b)
            )
        }
        Err(e) => format!("bake failed: {e}"),
    };
    Case {
        method: "point".into(),
        fails: "r → 0 between touching walls: `cosθᵢcosθⱼAⱼ/(πr²)` is unbounded, rows sum above 1 and the iteration would gain energy".into(),
        cure: "each entry capped by the point-to-disk bound, rows above 1 scaled to 1".into(),
        effect,
    }
}

fn high_albedo(dir: &Path) -> Vec<Case> {
    let mut out = Vec::new();
    let path = furnace_file(dir, 0.99);
    let mut cells = Vec::new();
    for solver in [
        Technique::DEFAULT,
        Technique::stored(FormFactors::MonteCarlo, RowSolver::GaussSeidel),
        Technique::stored(FormFactors::MonteCarlo, RowSolver::Southwell),
        Technique::Gather,
    ] {
        let mut c = BakeConfig::draft();
        c.atlas.texels_per_unit = 8.0;
        c.transport.gather_rays = 64;
        c.transport.light_samples = 16;
        c.technique = solver;
        c.solve.tolerance = 1e-4;
        cells.push(match bake(&path, &c) {
            Ok((b, s)) => format!(
                "{}: {} sweeps{}, worst texel {:.2}%, {s:.1}s",
                solver.solver(),
                b.solution.history.len(),
                if b.solution.converged { "" } else { " (cap)" },
                metrics::max_relative_deviation(&b.lightmap, 100.0) * 100.0
            ),
            Err(e) => format!("{}: {e}", solver.solver()),
        });
    }
    out.push(Case {
        method: "every solver".into(),
        fails: "ρ → 1: the spectral radius → 1, updates shrink by only 1% per sweep and a small update hides a large remaining error".into(),
        cure: "stop on the update extrapolated over the remaining geometric series (≈100× the last update at ρ=0.99), not on the update itself".into(),
        effect: format!("furnace ρ=0.99 (exact 100): {}", cells.join("; ")),
    });
    let path = furnace_file(dir, 1.5);
    let mut c = BakeConfig::draft();
    c.atlas.texels_per_unit = 8.0;
    let effect = match bake(&path, &c) {
        Ok((b, s)) => format!(
            "furnace with baseColor 1.5: warning \"{}\"; {} sweeps, converged {}, max {:.1} (ρ clamped to 0.99: exact 100), {s:.1}s",
            b.scene
                .stats
                .warnings
                .first()
                .map_or("none", String::as_str)
                .chars()
                .take(70)
                .collect::<String>(),
            b.solution.history.len(),
            b.solution.converged,
            b.lightmap
                .iter()
                .map(|v| v.max_element())
                .fold(0.0f32, f32::max)
        ),
        Err(e) => format!("refused: {e}"),
    };
    out.push(Case {
        method: "every method".into(),
        fails: "ρ ≥ 1 or < 0 in the input: the series diverges".into(),
        cure: "albedo clamped to [0, 0.99] with a warning naming the material".into(),
        effect,
    });
    out
}

fn few_rays(cornell: &Known) -> Case {
    let mut cells = Vec::new();
    for k in [1u32, 2, 4] {
        let mut c = BakeConfig::medium();
        c.atlas.texels_per_unit = cornell.texels_per_unit;
        c.transport.gather_rays = k;
        c.transport.light_samples = k;
        cells.push(match bake(cornell.path, &c) {
            Ok((b, _)) => format!(
                "K={k}: {:.0}% error, {} sweeps{}, finite {}",
                rmse(&b.lightmap, cornell, |_| true) * 100.0,
                b.solution.history.len(),
                if b.solution.converged { "" } else { " (cap)" },
                finite(&b)
            ),
            Err(e) => format!("K={k}: {e}"),
        });
    }
    Case {
        method: "montecarlo".into(),
        fails: "few rays (K = 1..4): rows of one or two entries, very noisy".into(),
        cure: "rows are hit fractions (sum ≤ 1 by construction), so the iteration stays bounded; the denoiser smooths within charts".into(),
        effect: format!(
            "Cornell box vs reference: {}",
            cells.join("; ")
        ),
    }
}

fn leak(two_rooms: &Known) -> Case {
    // Room B's floor away from the doorway (x > 0.5, |z| > 0.6): lit only through the door.
    // Enough rays (K = 1024) that what is left is bias, not noise.
    let far_b = |p: Vec3| p.x > 0.5 && p.z.abs() > 0.6 && p.y.abs() < 0.01;
    let mut cells = Vec::new();
    for validity in [true, false] {
        let mut c = BakeConfig::medium();
        c.atlas.texels_per_unit = two_rooms.texels_per_unit;
        c.transport.gather_rays = 1024;
        c.transport.light_samples = 128;
        c.transport.validity = validity;
        cells.push(match bake(two_rooms.path, &c) {
            Ok((b, _)) => format!(
                "validity {}: rel. RMSE {:.1}%, mean {:+.1}% ({} moved, {} invalid, {} divided); whole scene {:.2}%",
                if validity { "on" } else { "off" },
                rmse(&b.lightmap, two_rooms, far_b) * 100.0,
                metrics::relative_bias(&b.lightmap, two_rooms.mean, &outside(two_rooms, far_b)) * 100.0,
                b.validity.moved,
                b.validity.invalid,
                b.validity.divided,
                rmse(&b.lightmap, two_rooms, |_| true) * 100.0,
            ),
            Err(e) => e.to_string(),
        });
    }
    Case {
        method: "montecarlo, gather".into(),
        fails: "zero-thickness wall standing on a floor (and meeting side walls and ceiling) that runs on under it: texels under the wall gather from both rooms, and rays from room B that hit them read room A's light".into(),
        cure: "texel validity: probe rays find buried samples (moved, else invalid and filled) and texels a wall divides: their samples and jitter stay on one side, and hits on the other side read the neighbour there (cell map in `texel_at`)".into(),
        effect: format!(
            "two_rooms, room B floor away from the door vs reference (noise {:.1}%), K=1024: {}",
            two_rooms.noise * 100.0,
            cells.join("; ")
        ),
    }
}

/// Issue-6 figures measured in the same run: the denoiser's gain against the reference at low
/// and high ray counts (Cornell box), and the seam discontinuity before and after stitching.
pub fn quality_table(dir: &Path, cornell: Option<&Known>) -> String {
    let mut md = String::from("| what | setting | without | with |\n|---|---|---:|---:|\n");
    if let Some(c) = cornell {
        for k in [16u32, 64, 512] {
            let error = |denoise: bool| {
                let mut config = BakeConfig::medium();
                config.atlas.texels_per_unit = c.texels_per_unit;
                config.transport.gather_rays = k;
                config.transport.light_samples = (k / 4).max(4);
                config.transport.denoise = denoise;
                bake(c.path, &config).map_or(f32::NAN, |(b, _)| rmse(&b.lightmap, c, |_| true))
            };
            let _ = writeln!(
                md,
                "| denoiser: relative RMSE vs reference (noise {:.2}%), Cornell box | K={k}, L={} | {:.2}% | {:.2}% |",
                c.noise * 100.0,
                (k / 4).max(4),
                error(false) * 100.0,
                error(true) * 100.0
            );
        }
    }
    let sphere = dir.join("sphere_on_floor.gltf");
    lightbake::testing::sphere_on_floor()
        .write_gltf(&sphere)
        .expect("write sphere");
    let large = dir.join("large_hall.glb");
    for (name, path, tpu) in [
        ("sphere_on_floor", &sphere, 16.0),
        ("large_hall", &large, 3.0),
    ] {
        let mut config = BakeConfig::medium();
        config.atlas.texels_per_unit = tpu;
        config.transport.gather_rays = 64;
        config.transport.light_samples = 16;
        match bake(path, &config) {
            Ok((b, _)) => {
                if let Some(r) = b.seams.filter(|r| r.before.edges == 0) {
                    let _ = writeln!(
                        md,
                        "| seams, {name} | {} edges: every chart ends at a crease or open edge | – | – |",
                        r.before.edges
                    );
                } else if let Some(r) = b.seams {
                    let rel = |x: f32| x / r.before.mean_value.max(1e-12) * 100.0;
                    let _ = writeln!(
                        md,
                        "| seams: mean / max difference of the two sides' bilinear lookups, relative to the mean along seams, {name} | {} edges, {} texels solved in {:.0} ms | {:.2}% / {:.1}% | {:.3}% / {:.2}% |",
                        r.before.edges,
                        r.texels,
                        r.seconds * 1e3,
                        rel(r.before.mean_abs_diff),
                        rel(r.before.max_abs_diff),
                        rel(r.after.mean_abs_diff),
                        rel(r.after.max_abs_diff)
                    );
                }
            }
            Err(e) => {
                let _ = writeln!(md, "| seams, {name} | failed: {e} | | |");
            }
        }
    }
    md
}

/// Runs every case whose inputs exist (`cornell`, `two_rooms`: references from the main run)
/// and returns the Markdown table.
pub fn table(dir: &Path, cornell: Option<&Known>, two_rooms: Option<&Known>) -> String {
    let mut cases = vec![point_singularity(dir)];
    cases.extend(high_albedo(dir));
    if let Some(c) = cornell {
        cases.push(few_rays(c));
    }
    if let Some(t) = two_rooms {
        cases.push(leak(t));
    }
    let mut md = String::from(
        "| method | what fails | what lightbake does | measured effect |\n|---|---|---|---|\n",
    );
    for c in cases {
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} |",
            c.method, c.fails, c.cure, c.effect
        );
    }
    md
}
