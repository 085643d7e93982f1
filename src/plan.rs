//! Automatic choice of bake settings: model no more of a scene than its light needs.
//!
//! With [`AutoParams`] in the config, [`crate::compute`] chooses what the user did not fix:
//!
//! - **Texel density** from the quality preset, kept within a texel budget for the scene's
//!   surface area (a 10 cm prop or a 1 km terrain at 16 texels/m would get 2 or 10⁹ texels).
//! - **Method** Monte Carlo, **solver** Jacobi (the matrix-free gather solver when the stored
//!   rows would not fit in memory; never a choice that depends on the thread count). The benchmark
//!   (`examples/benchmark/`) puts Monte Carlo + Jacobi on the measured error-vs-time Pareto
//!   front of every fixture scene: point and polygon form factors are all-pairs (O(N²)) and
//!   3.0–9.7% off on the Cornell box and the two-room scene (where Monte Carlo reaches
//!   1.5–3.6%), hierarchical is 2.7–7.9% off at 4–5× the time.
//! - **Rays per texel** from a measured noise level: a *pilot* bakes the texels twice with
//!   [`PILOT_RAYS`] gathering rays and independent seeds; the RMS difference of the two
//!   lightmaps over √2 is the noise of one such bake. Assuming 1/√K, the rays that reach the
//!   target are `K = K₀ · (noise₀ / (0.75·E))²` (a quarter of the error budget left for what
//!   the pilot cannot see: texel placement, leaks, solver tolerance), rounded up to four steps
//!   per octave. When that asks for more than [`SECOND_PILOT_ABOVE`], a second pair at 4·K₀
//!   measures how fast the noise really falls (exponent clamped to ½ … [`MAX_EXPONENT`]):
//!   stratified samples fall faster than 1/√K at first (the 116k-triangle hall: 66% at K=16,
//!   15% at K=64), and 1/√K from K=16 asked that hall for 4096 rays for a 4% target; the
//!   fit asks for 640, which gave 4.4% (bench.md).
//!   Light samples follow as K/4, like the presets.
//! - **Nothing measured is thrown away**: the last pilot pair is part of the result. The
//!   final lightmap is the ray-weighted mean of the two pilot bakes and one more bake at the
//!   rays they lack (or of the pilots alone when they suffice) — the least-variance combination
//!   of independent estimates whose variance falls as 1/K.
//! - **Fewer rays where the lightmap matters less**: from the pilot's irradiance, an emitter
//!   texel whose rendered radiance is mostly its own `Le` gets `K·w²` rays (`w` the lightmap's
//!   share of what is seen), black and unlit texels the minimum ([`MIN_TEXEL_RAYS`]); on the
//!   fixtures this saves 1.8–3.0% of the rays (emitters are small) and never touches lit texels.
//! - **Tolerance** E/10: the solver stops once its remaining error is well below the Monte
//!   Carlo error, not later.
//!
//! The pilot costs nothing extra when its bakes suffice and a few solves otherwise (Cornell
//! box, 7167 texels, medium: 4 pilot bakes, 0.3 s, and no further bake). It measures the scene
//! rather than guessing from it: closed rooms with bright emitters need far more rays than a
//! sunlit terrain at the same target. The denoiser's gain is not counted (it lowers the error
//! at low K and leaves it at high K), so the choice errs towards more rays.

use std::time::Instant;

use glam::Vec3;

use crate::config::{BakeConfig, Method, SolveParams, Solver, TexelRays, TransportParams};
use crate::scene::Scene;
use crate::solve::Solution;
use crate::texels::Texels;
use crate::trace::Tracer;
use crate::transport::Transport;
use crate::{NoProgress, Progress, Result, solve};

/// Gathering rays per texel of the pilot bakes.
pub const PILOT_RAYS: u32 = 16;
/// When the first pilot asks for more rays than this, a second pilot at 4× [`PILOT_RAYS`]
/// measures how fast the noise falls.
pub const SECOND_PILOT_ABOVE: u32 = 256;
/// Fastest noise fall the fit believes: stratified light samples and Hammersley gathering fall
/// faster than 1/√K at low K (Cornell box 16 → 64 rays: K^−0.78), then flatten towards 1/√K.
pub const MAX_EXPONENT: f32 = 0.75;
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
    /// Gathering rays per texel in all, the reused pilot bakes included.
    pub total_rays: Option<u32>,
    pub pilot_seconds: f64,
    pub pilot_rays: u64,
    /// Rays of pilot bakes not reused in the result (the first pair, when a second ran).
    pub discarded_rays: u64,
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
            self.total_rays.unwrap_or(config.transport.gather_rays)
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

/// Step 2, once texels and the tracer exist: method, solver, rays and tolerance. Returns the
/// pilot bakes for [`final_bake`] to reuse.
pub fn choose_transport(
    scene: &Scene,
    texels: &Texels,
    tracer: &Tracer,
    config: &mut BakeConfig,
    plan: &mut Plan,
    keep: &Keep,
    progress: &dyn Progress,
) -> Result<Option<PilotRuns>> {
    let n = texels.len();
    let e = plan.target_error;
    let mut pilot = None;
    if !keep.method {
        config.transport.method = Method::MonteCarlo;
        plan.reasons.push(
            "method montecarlo: on the benchmark's error-vs-time Pareto front on every fixture; \
             point/polygon are all-pairs (O(N²)) and 3.0–9.7% off on the Cornell box and two rooms \
             where Monte Carlo reaches 1.5–3.6%; hierarchical is 2.7–7.9% off at 4–5× the time"
                .into(),
        );
    }
    let emitters = texels.emission.iter().any(|l| l.max_element() > 0.0);
    let sampled = emitters || config.transport.sky.max_element() > 0.0 || !scene.lights.is_empty();
    if config.transport.method == Method::MonteCarlo && !keep.rays && n > 0 && sampled {
        progress.begin("pilot", 2);
        let start = Instant::now();
        let tolerance = (e / 10.0).min(1e-3);
        let bake = |k| PilotRuns::bake(scene, texels, tracer, &config.transport, k, tolerance);
        let mut runs = bake(PILOT_RAYS)?;
        let n0 = runs.noise(texels, config.transport.indirect_only);
        let (k0, mut noise, mut rays, mut alpha) = (PILOT_RAYS as f32, n0, runs.rays(), 0.5f32);
        let mut k_pilot = k0;
        let mut wanted = k0 * (n0 / (0.75 * e)).powf(1.0 / alpha);
        progress.advance(1);
        // A hard scene: measure again at 4× the rays and fit how fast the noise falls.
        let second = wanted > SECOND_PILOT_ABOVE as f32 && n0 > 0.0;
        if second {
            plan.discarded_rays = runs.rays();
            runs = bake(4 * PILOT_RAYS)?;
            let n1 = runs.noise(texels, config.transport.indirect_only);
            rays += runs.rays();
            if n1 > 0.0 {
                alpha = ((n0 / n1).ln() / 4f32.ln()).clamp(0.5, MAX_EXPONENT);
                (noise, k_pilot) = (n1, 4.0 * k0);
                wanted = k_pilot * (n1 / (0.75 * e)).powf(1.0 / alpha);
            } else {
                wanted = 4.0 * k0;
            }
        }
        progress.advance(1);
        progress.end();
        plan.pilot_seconds = start.elapsed().as_secs_f64();
        plan.pilot_rays = rays;
        plan.pilot_noise = Some(noise);
        let k = round_up_quarter_octave(wanted).clamp(RAYS_RANGE.0, RAYS_RANGE.1);
        let predicted = noise * (k_pilot / k as f32).powf(alpha);
        // The last pilot's two runs are reused: only the rays they lack are cast again.
        let reused = 2 * runs.gather_rays;
        runs.enough = k <= reused;
        config.transport.gather_rays = if runs.enough {
            runs.gather_rays
        } else {
            round_up_quarter_octave((k - reused) as f32).max(RAYS_RANGE.0)
        };
        pilot = Some(runs);
        plan.predicted_error = Some(predicted);
        plan.total_rays = Some(if runs_enough(&pilot) {
            reused
        } else {
            reused + config.transport.gather_rays
        });
        let measured = if second {
            format!(
                "{:.2}% noise at K={PILOT_RAYS} and {:.2}% at K={}, falling as K^−{alpha:.2}",
                n0 * 100.0,
                noise * 100.0,
                4 * PILOT_RAYS
            )
        } else {
            format!(
                "{:.2}% noise at K={PILOT_RAYS}, assumed to fall as K^−½",
                n0 * 100.0
            )
        };
        let reuse = if k <= reused {
            format!(
                "the last two pilot bakes ({reused} rays together) are the bake, nothing more is cast"
            )
        } else {
            format!(
                "the last two pilot bakes ({reused} rays) are averaged with one more at K={}",
                config.transport.gather_rays
            )
        };
        plan.reasons.push(format!(
            "gathering rays K={} in all: the pilot ({} bakes, {:.2}s) measured {measured}; \
             K≥{wanted:.0} reaches 75% of the {:.1}% target; expected {:.2}%; {reuse}{}",
            plan.total_rays.unwrap_or(k),
            if second { 4 } else { 2 },
            plan.pilot_seconds,
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
    if let Some(runs) = &pilot
        && !runs.enough
        && config.transport.method == Method::MonteCarlo
        && config.solve.solver != Solver::Gather
        && !keep.rays
    {
        let (rays, reduced) = texel_rays(texels, runs, config.transport.gather_rays);
        let full = config.transport.gather_rays as u64 * n as u64;
        let cast: u64 = rays.iter().map(|&k| k as u64).sum();
        if reduced.0 + reduced.1 > 0 {
            plan.reasons.push(format!(
                "fewer rays where the lightmap matters less: {} emitter texels (rendered radiance mostly Le) and {} black or unlit texels; the last bake casts {:.1}% fewer gathering rays",
                reduced.0,
                reduced.1,
                100.0 * (full - cast) as f64 / full.max(1) as f64
            ));
            config.transport.texel_rays = Some(TexelRays(rays.into()));
        }
    }
    plan.brief = plan.brief(config);
    Ok(pilot)
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

/// Fewest gathering rays a texel gets.
pub const MIN_TEXEL_RAYS: u32 = 16;

/// Gathering rays per texel for the final bake, from the pilot's mean irradiance: a texel's
/// lightmap noise reaches the rendered image as `ρH/π` next to its emission `Le`, so its relative
/// error there is the lightmap's times `w = (ρH/π)/(ρH/π + Le)`, and `K·w²` rays keep it level
/// with a plain texel's. Black texels (ρ = 0) and texels the pilot found unlit (below 10⁻³ of
/// the mean) get the minimum. Returns the rays and (emitter, black or unlit) texel counts reduced.
fn texel_rays(texels: &Texels, pilot: &PilotRuns, k: u32) -> (Vec<u32>, (usize, usize)) {
    let n = texels.len();
    let mean = |v: Vec3| v.element_sum() / 3.0;
    let h: Vec<f32> = (0..n)
        .map(|i| {
            pilot
                .runs
                .iter()
                .map(|(_, s)| mean(s.irradiance[i]))
                .sum::<f32>()
                / pilot.runs.len() as f32
        })
        .collect();
    let h_mean = h.iter().sum::<f32>() / n.max(1) as f32;
    let floor = MIN_TEXEL_RAYS.min(k);
    let mut reduced = (0, 0);
    let rays = (0..n)
        .map(|i| {
            let reflected = mean(texels.albedo[i]) * h[i] / std::f32::consts::PI;
            let emitted = mean(texels.emission[i]);
            if mean(texels.albedo[i]) <= 0.0 || h[i] <= 1e-3 * h_mean {
                reduced.1 += 1;
                return floor;
            }
            if emitted <= 0.0 {
                return k;
            }
            let w = reflected / (reflected + emitted);
            let ki = ((k as f32 * w * w).ceil() as u32).clamp(floor, k);
            if ki < k {
                reduced.0 += 1;
            }
            ki
        })
        .collect();
    (rays, reduced)
}

fn runs_enough(pilot: &Option<PilotRuns>) -> bool {
    pilot.as_ref().is_some_and(|p| p.enough)
}

/// Two Monte Carlo bakes of the same texels with independent seeds: their difference measures
/// the noise, and their mean is kept for the final bake ([`final_bake`]).
pub struct PilotRuns {
    /// Gathering rays (and light samples) of each run.
    pub gather_rays: u32,
    pub light_samples: u32,
    pub runs: Vec<(Transport, Solution)>,
    /// True when the runs alone reach the target: no further bake is needed.
    pub enough: bool,
}

impl PilotRuns {
    fn bake(
        scene: &Scene,
        texels: &Texels,
        tracer: &Tracer,
        transport: &TransportParams,
        k: u32,
        tolerance: f32,
    ) -> Result<PilotRuns> {
        let solve_params = SolveParams {
            solver: Solver::Jacobi,
            tolerance,
            max_iterations: 10_000,
        };
        let light_samples = (k / 4).max(4);
        let runs = (0..2u64)
            .map(|stream| {
                let params = TransportParams {
                    method: Method::MonteCarlo,
                    gather_rays: k,
                    light_samples,
                    seed: transport.seed ^ 0x9E37_79B9_7F4A_7C15u64.wrapping_mul(stream + 1),
                    ..transport.clone()
                };
                solve::run(scene, texels, tracer, &params, &solve_params, &NoProgress)
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(PilotRuns {
            gather_rays: k,
            light_samples,
            runs,
            enough: false,
        })
    }

    fn rays(&self) -> u64 {
        self.runs.iter().map(|(t, _)| t.rays).sum()
    }

    /// Relative RMS noise of one run (of what the lightmap stores).
    fn noise(&self, texels: &Texels, indirect_only: bool) -> f32 {
        let values = |(t, s): &(Transport, Solution)| -> Vec<Vec3> {
            s.irradiance
                .iter()
                .zip(&t.direct)
                .map(|(h, d)| {
                    if indirect_only {
                        (*h - *d).max(Vec3::ZERO)
                    } else {
                        *h
                    }
                })
                .collect()
        };
        relative_noise(
            &values(&self.runs[0]),
            &values(&self.runs[1]),
            &texels.invalid,
        )
    }
}

/// The final bake of `config`, reusing the pilot: the result is the mean of the pilot runs and
/// (unless they are enough) one more bake at `config`'s rays, weighted by gathering rays — each
/// run's variance falls as 1/K, so this is the least-variance combination. Returns the transport
/// (the last run's rows, the combined direct light), the combined solution and the effective
/// gathering rays and light samples per texel.
pub fn final_bake(
    scene: &Scene,
    texels: &Texels,
    tracer: &Tracer,
    config: &BakeConfig,
    pilot: Option<PilotRuns>,
    progress: &dyn Progress,
) -> Result<(Transport, Solution, u32, u32)> {
    let (k, l) = (config.transport.gather_rays, config.transport.light_samples);
    let bake = || {
        solve::run(
            scene,
            texels,
            tracer,
            &config.transport,
            &config.solve,
            progress,
        )
    };
    let Some(pilot) = pilot else {
        let (t, s) = bake()?;
        return Ok((t, s, k, l));
    };
    let mut runs: Vec<(f32, Transport, Solution)> = pilot
        .runs
        .into_iter()
        .map(|(t, s)| (pilot.gather_rays as f32, t, s))
        .collect();
    let (mut k_total, mut l_total) = (2 * pilot.gather_rays, 2 * pilot.light_samples);
    if !pilot.enough {
        let (t, s) = bake()?;
        runs.push((k as f32, t, s));
        k_total += k;
        l_total += l;
    }
    // Per texel, each run weighs by the rays it cast there (fewer where `texel_rays` cut them).
    let n = texels.len();
    let last = runs.len() - 1;
    let weight = |run: usize, w: f32, i: usize| match &config.transport.texel_rays {
        Some(r) if run == last && !pilot.enough => r.0[i] as f32,
        _ => w,
    };
    let (mut h, mut direct) = (vec![Vec3::ZERO; n], vec![Vec3::ZERO; n]);
    let (mut rays, mut converged) = (0, true);
    for i in 0..n {
        let total: f32 = runs
            .iter()
            .enumerate()
            .map(|(r, run)| weight(r, run.0, i))
            .sum();
        for (r, (w, t, s)) in runs.iter().enumerate() {
            let w = weight(r, *w, i) / total;
            h[i] += s.irradiance[i] * w;
            direct[i] += t.direct[i] * w;
        }
    }
    for (_, t, s) in &runs {
        rays += t.rays;
        converged &= s.converged;
    }
    let (mut transport, mut solution) = runs.pop().map(|(_, t, s)| (t, s)).unwrap();
    transport.direct = direct;
    transport.rays = rays;
    solution.irradiance = h;
    solution.converged = converged;
    Ok((transport, solution, k_total, l_total))
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
