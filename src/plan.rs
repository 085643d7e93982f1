//! Automatic choice of bake settings: model no more of a scene than its light needs.
//!
//! With [`AutoParams`] in the config, [`crate::compute`] chooses what the user did not fix:
//!
//! - **Texel density** from the quality preset, kept within a texel budget for the scene's
//!   surface area (a 10 cm prop or a 1 km terrain at 16 texels/m would get 2 or 10⁹ texels).
//! - **Method** Monte Carlo, **solver** Jacobi (the matrix-free gather solver when the stored
//!   rows would not fit in memory; never a choice that depends on the thread count). The benchmark
//!   (`examples/chart.rs`) puts Monte Carlo + Jacobi on the measured error-vs-time Pareto
//!   front of every fixture scene: point and polygon form factors are all-pairs (O(N²)) and
//!   biased on the Cornell box and the two-room scene (3.6–9.9% where Monte Carlo reaches
//!   1.5–3.5%), hierarchical is 3–18% off and slower.
//! - **Rays per texel** from a measured noise level: a *pilot* bakes the texels twice with
//!   [`PILOT_RAYS`] gathering rays and independent seeds; the RMS difference of the two
//!   lightmaps over √2 is the noise of one such bake. Noise falls as 1/√K, so the gathering
//!   rays that reach the target are `K = K₀ · (noise₀ / (0.75·E))²` (a quarter of the error
//!   budget left for what the pilot cannot see: texel placement, leaks, solver tolerance),
//!   rounded up to four steps per octave. Light samples follow as K/4, like the presets.
//! - **Tolerance** E/10: the solver stops once its remaining error is well below the Monte
//!   Carlo error, not later.
//!
//! The pilot costs `2·(K₀ + K₀/4)` rays per texel, about a quarter of a medium bake; it measures
//! the scene rather than guessing from it (closed rooms with bright emitters need far more rays
//! than a sunlit terrain at the same target). The denoiser's gain is not counted (it lowers the
//! error at low K and leaves it at high K), so the choice errs towards more rays.

use std::time::Instant;

use glam::Vec3;

use crate::config::{BakeConfig, Method, SolveParams, Solver, TransportParams};
use crate::scene::Scene;
use crate::texels::Texels;
use crate::trace::Tracer;
use crate::{NoProgress, Progress, Result, solve};

/// Gathering rays per texel of the pilot bakes.
pub const PILOT_RAYS: u32 = 16;
/// Bounds of the chosen gathering rays.
pub const RAYS_RANGE: (u32, u32) = (16, 4096);
/// Stored rows beyond this many bytes switch to the matrix-free gather solver.
pub const ROW_MEMORY_LIMIT: f64 = 4.0 * (1u64 << 30) as f64;

/// Which settings the user fixed; the automatic choice leaves those alone.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Keep {
    pub texels_per_unit: bool,
    pub method: bool,
    pub solver: bool,
    pub rays: bool,
    pub light_samples: bool,
    pub tolerance: bool,
}

/// Ask for an automatic choice aiming at a relative RMSE of the lightmap.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AutoParams {
    /// Target relative RMSE against a converged reference (0.04 = 4%).
    pub target_error: f32,
    pub keep: Keep,
}

impl AutoParams {
    /// The error each quality preset aims at: draft 8%, medium 4%, high 2%.
    pub fn for_preset(preset: &str) -> Option<f32> {
        match preset {
            "draft" => Some(0.08),
            "medium" => Some(0.04),
            "high" => Some(0.02),
            _ => None,
        }
    }
}

/// What was chosen and why, in order (density first).
#[derive(Clone, Debug, Default)]
pub struct Plan {
    pub target_error: f32,
    /// The pilot's measured relative noise at [`PILOT_RAYS`], if a pilot ran.
    pub pilot_noise: Option<f32>,
    /// Expected noise of the chosen bake (before denoising).
    pub predicted_error: Option<f32>,
    pub pilot_seconds: f64,
    pub pilot_rays: u64,
    /// One line per decision: what, and the measurement or rule behind it.
    pub reasons: Vec<String>,
    /// The choice in a few words, for the one-line summary.
    pub brief: String,
}

impl Plan {
    fn brief(&self, config: &BakeConfig) -> String {
        let mut s = format!(
            "auto for {:.1}%: {}/{} K={}",
            self.target_error * 100.0,
            method_name(config.transport.method),
            solver_name(config.solve.solver),
            config.transport.gather_rays
        );
        if let Some(p) = self.predicted_error {
            s += &format!(" (predicted {:.1}%)", p * 100.0);
        }
        s
    }
}

pub fn method_name(m: Method) -> &'static str {
    match m {
        Method::MonteCarlo => "montecarlo",
        Method::Point => "point",
        Method::Polygon => "polygon",
        Method::Hierarchical => "hierarchical",
    }
}

pub fn solver_name(s: Solver) -> &'static str {
    match s {
        Solver::Jacobi => "jacobi",
        Solver::GaussSeidel => "gauss-seidel",
        Solver::Southwell => "southwell",
        Solver::Gather => "gather",
    }
}

/// Total surface area of the scene's triangles (m²).
pub fn surface_area(scene: &Scene) -> f64 {
    scene
        .triangles
        .iter()
        .map(|t| {
            let p = |i: usize| scene.positions[t[i] as usize].as_dvec3();
            0.5 * (p(1) - p(0)).cross(p(2) - p(0)).length()
        })
        .sum()
}

/// Texel budget for a preset density: `tpu = 16` (medium) allows 4 096 … 262 144 texels,
/// scaled with the density's square for the other presets.
fn texel_budget(preset_tpu: f32) -> (f64, f64) {
    let s = (preset_tpu as f64 / 16.0).powi(2);
    (4096.0 * s, 262_144.0 * s)
}

/// Step 1, before the atlas: the texel density.
pub fn choose_density(scene: &Scene, config: &mut BakeConfig, plan: &mut Plan, keep: &Keep) {
    let area = surface_area(scene);
    let tpu = config.atlas.texels_per_unit;
    let texels = area * (tpu as f64).powi(2);
    if keep.texels_per_unit {
        plan.reasons.push(format!(
            "texel density {tpu} /m (fixed by the user): about {texels:.0} texels over {area:.3} m²"
        ));
        return;
    }
    let (lo, hi) = texel_budget(tpu);
    let chosen = if texels < lo {
        (lo / area).sqrt() as f32
    } else if texels > hi {
        (hi / area).sqrt() as f32
    } else {
        tpu
    };
    // Round to 3 significant digits so the choice reads well and is stable.
    let chosen = if chosen.is_finite() && chosen > 0.0 {
        let scale = 10f32.powf(chosen.log10().floor() - 2.0);
        ((chosen / scale).round() * scale).clamp(1e-3, 100_000.0)
    } else {
        tpu
    };
    config.atlas.texels_per_unit = chosen;
    let why = if chosen == tpu {
        format!("the preset's density gives {texels:.0} texels, within the budget {lo:.0}…{hi:.0}")
    } else {
        format!(
            "the preset's {tpu} /m would give {texels:.0} texels over {area:.3} m², outside the budget {lo:.0}…{hi:.0}"
        )
    };
    plan.reasons.push(format!(
        "texel density {chosen} /m: {why} (about {:.0} texels)",
        area * (chosen as f64).powi(2)
    ));
}

/// Step 2, once texels and the tracer exist: method, solver, rays and tolerance.
pub fn choose_transport(
    scene: &Scene,
    texels: &Texels,
    tracer: &Tracer,
    config: &mut BakeConfig,
    plan: &mut Plan,
    keep: &Keep,
    progress: &dyn Progress,
) -> Result<()> {
    let n = texels.len();
    let e = plan.target_error;
    if !keep.method {
        config.transport.method = Method::MonteCarlo;
        plan.reasons.push(
            "method montecarlo: on the benchmark's error-vs-time Pareto front on every fixture; \
             point/polygon are all-pairs and biased 3.6–9.9% on the Cornell box and two rooms, \
             hierarchical 3–18% off and slower"
                .into(),
        );
    }
    let emitters = texels.emission.iter().any(|l| l.max_element() > 0.0);
    let sampled = emitters || config.transport.sky.max_element() > 0.0 || !scene.lights.is_empty();
    if config.transport.method == Method::MonteCarlo && !keep.rays && n > 0 && sampled {
        progress.begin("pilot", 2);
        let start = Instant::now();
        let (noise, rays) = pilot_noise(scene, texels, tracer, &config.transport)?;
        progress.advance(2);
        progress.end();
        plan.pilot_seconds = start.elapsed().as_secs_f64();
        plan.pilot_rays = rays;
        plan.pilot_noise = Some(noise);
        let k0 = PILOT_RAYS as f32;
        let wanted = k0 * (noise / (0.75 * e)).powi(2);
        let k = round_up_quarter_octave(wanted).clamp(RAYS_RANGE.0, RAYS_RANGE.1);
        let predicted = noise * (k0 / k as f32).sqrt();
        config.transport.gather_rays = k;
        plan.predicted_error = Some(predicted);
        plan.reasons.push(format!(
            "gathering rays K={k}: the pilot (2 bakes at K={PILOT_RAYS}, {:.2}s) measured {:.2}% noise; \
             1/√K scaling needs K≥{wanted:.0} for 75% of the {:.1}% target; expected {:.2}%{}",
            plan.pilot_seconds,
            noise * 100.0,
            e * 100.0,
            predicted * 100.0,
            if wanted > RAYS_RANGE.1 as f32 {
                " (capped: the target needs more rays than the cap; expect more error)"
            } else {
                ""
            }
        ));
    } else if !keep.rays && config.transport.method == Method::MonteCarlo {
        plan.reasons.push(format!(
            "gathering rays K={}: nothing to measure (no light reaches the texels)",
            config.transport.gather_rays
        ));
    }
    if !keep.light_samples && config.transport.method == Method::MonteCarlo {
        if emitters {
            config.transport.light_samples = (config.transport.gather_rays / 4).max(4);
            plan.reasons.push(format!(
                "light samples L={}: a quarter of K, as measured best on the Cornell box",
                config.transport.light_samples
            ));
        } else {
            config.transport.light_samples = 0;
            plan.reasons
                .push("light samples L=0: the scene has no emissive surfaces".into());
        }
    }
    if !keep.solver {
        let rows = n as f64 * config.transport.gather_rays as f64 * 8.0;
        config.solve.solver = if config.transport.method == Method::MonteCarlo
            && rows > ROW_MEMORY_LIMIT
        {
            plan.reasons.push(format!(
                "solver gather: stored rows would take {:.1} GiB (> {:.0} GiB); re-casting rays each bounce needs O(texels) memory",
                rows / (1u64 << 30) as f64,
                ROW_MEMORY_LIMIT / (1u64 << 30) as f64
            ));
            Solver::Gather
        } else {
            // Not Gauss–Seidel on one thread: the output must not depend on the thread count.
            plan.reasons.push(format!(
                "solver jacobi: stored rows take {:.0} MiB; parallel sweeps, the same result on any number of threads",
                rows / (1u64 << 20) as f64
            ));
            Solver::Jacobi
        };
    }
    if !keep.tolerance {
        config.solve.tolerance = (e / 10.0).clamp(1e-6, 0.5);
        plan.reasons.push(format!(
            "tolerance {:.1e}: a tenth of the target, so iterating stops once it is below the Monte Carlo error",
            config.solve.tolerance
        ));
    }
    plan.brief = plan.brief(config);
    Ok(())
}

/// The smallest of 4·2ⁿ, 5·2ⁿ, 6·2ⁿ, 7·2ⁿ at or above `x` (four steps per octave: powers of
/// two alone overshoot the rays, and the time, by up to 2×).
fn round_up_quarter_octave(x: f32) -> u32 {
    let x = x.clamp(1.0, 1e9);
    let mut step = 1u32;
    while (step * 8) as f32 <= x {
        step *= 2;
    }
    (x / step as f32).ceil() as u32 * step
}

/// Relative RMS noise of a Monte Carlo bake at [`PILOT_RAYS`] rays, from two independent seeds,
/// and the rays both cast.
fn pilot_noise(
    scene: &Scene,
    texels: &Texels,
    tracer: &Tracer,
    transport: &TransportParams,
) -> Result<(f32, u64)> {
    let solve_params = SolveParams {
        solver: Solver::Jacobi,
        tolerance: 1e-3,
        max_iterations: 1000,
    };
    let mut runs = Vec::with_capacity(2);
    let mut rays = 0;
    for stream in 0..2u64 {
        let params = TransportParams {
            method: Method::MonteCarlo,
            gather_rays: PILOT_RAYS,
            light_samples: (PILOT_RAYS / 4).max(4),
            seed: transport.seed ^ (0x9E37_79B9_7F4A_7C15u64.wrapping_mul(stream + 1)),
            ..transport.clone()
        };
        let (t, s) = solve::run(scene, texels, tracer, &params, &solve_params, &NoProgress)?;
        rays += t.rays;
        let values: Vec<Vec3> = s
            .irradiance
            .iter()
            .zip(&t.direct)
            .map(|(h, d)| {
                if transport.indirect_only {
                    (*h - *d).max(Vec3::ZERO)
                } else {
                    *h
                }
            })
            .collect();
        runs.push(values);
    }
    Ok((relative_noise(&runs[0], &runs[1], &texels.invalid), rays))
}

/// `rms(a − b) / √2 / mean((a + b)/2)` over all channels of the texels not listed in `skip`:
/// the relative RMS noise of one of two independent estimates.
pub fn relative_noise(a: &[Vec3], b: &[Vec3], skip: &[u32]) -> f32 {
    let mut skipped = vec![false; a.len()];
    for &i in skip {
        if let Some(s) = skipped.get_mut(i as usize) {
            *s = true;
        }
    }
    let (mut sq, mut sum, mut count) = (0.0f64, 0.0f64, 0usize);
    for ((x, y), s) in a.iter().zip(b).zip(&skipped) {
        if *s {
            continue;
        }
        sq += (*x - *y).length_squared() as f64;
        sum += (*x + *y).element_sum() as f64 * 0.5;
        count += 3;
    }
    if count == 0 || sum <= 0.0 {
        return 0.0;
    }
    let mean = sum / count as f64;
    let rms = (sq / count as f64 / 2.0).sqrt();
    let r = (rms / mean) as f32;
    if r.is_finite() { r } else { 0.0 }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relative_noise_of_known_offsets() {
        // a − b = ±0.2 on a mean of 1: rms(a−b)/√2 = 0.1414.
        let a = vec![Vec3::splat(1.1), Vec3::splat(0.9)];
        let b = vec![Vec3::splat(0.9), Vec3::splat(1.1)];
        assert!((relative_noise(&a, &b, &[]) - 0.2 / 2f32.sqrt()).abs() < 1e-5);
        assert_eq!(relative_noise(&a, &a, &[]), 0.0);
        // Skipped texels do not count.
        let c = vec![Vec3::splat(1.1), Vec3::splat(5.0)];
        let d = vec![Vec3::splat(1.1), Vec3::splat(1.0)];
        assert_eq!(relative_noise(&c, &d, &[1]), 0.0);
        // Black maps have no relative noise (and no NaN).
        assert_eq!(relative_noise(&[Vec3::ZERO], &[Vec3::ZERO], &[]), 0.0);
    }

    #[test]
    fn rounding_has_four_steps_per_octave() {
        let r: Vec<u32> = [1.0, 7.5, 8.0, 8.5, 75.0, 100.0, 128.0, 129.0]
            .into_iter()
            .map(round_up_quarter_octave)
            .collect();
        assert_eq!(r, [1, 8, 8, 10, 80, 112, 128, 160]);
    }

    #[test]
    fn budget_scales_with_density() {
        assert_eq!(texel_budget(16.0), (4096.0, 262_144.0));
        assert_eq!(texel_budget(32.0), (16_384.0, 1_048_576.0));
    }
}
