//! The reference: an independent Monte Carlo path tracer that estimates `H_i/π` at the same
//! texels as a bake, with a per-texel standard error. It is the yardstick every form-factor
//! method and solver is measured against, so it shares the scene, atlas, texels and tracer with
//! the bake but none of the radiosity code (no form factors, no solver).
//!
//! For texel `i` with footprint `A_i` it estimates the radiance a white Lambertian surface there
//! would reflect:
//!
//! ```text
//!   H_i/π = (1/A_i) ∫_{A_i} ∫_Ω L_in(x, ω) cosθ/π dω dx
//! ```
//!
//! Each sample is one path: `x₀` uniform over the footprint (as the bake's gathering jitters it),
//! then cosine-sampled directions (pdf `cosθ/π`, so a bounce multiplies the throughput `β` by
//! `ρ`). At every vertex punctual lights are added by a shadow ray, and small emissive triangles
//! by next-event estimation combined with the cosine-sampled ray that hits them by multiple
//! importance sampling (power heuristic, one sample of each; emitters that `Emitters` leaves out
//! as large are found by the cosine rays alone), so emission counts exactly once. Rays that
//! leave the scene see the sky; rays that hit the back of a single-sided surface are absorbed.
//! After `ROULETTE_DEPTH` bounces a path survives each bounce with probability `q = max_c ρ_c`
//! and carries `β/q` (Russian roulette: unbiased; ends paths in a ρ → 1 furnace). Survival by
//! albedo rather than by throughput `max(β)` keeps the weights of survivors bounded: with
//! `q = max(β)` the ρ = 0.5 furnace had 5% noise at 64 paths, since the whole tail after the
//! third bounce rode on a few paths with weights ~16.
//!
//! Albedo and emission at a hit are the hit *texel's* `ρ` and `Le` — the same discretised
//! materials the bake solves with — so the difference between a bake and the reference is the
//! error of transport and solve, not of texture resolution. Geometry is exact: secondary vertices
//! lie on the hit triangle with its geometric normal; the first vertex uses the texel's normal.
//!
//! | parameter           | default  | effect                                                        |
//! |---------------------|----------|---------------------------------------------------------------|
//! | `samples_per_pass`  | 16       | paths per texel between stopping checks                       |
//! | `max_samples`       | 1024     | paths per texel at most; standard error ∝ 1/√samples          |
//! | `target_rel_error`  | none     | stop when the relative RMS standard error ≤ this (`rms_rel_error`) |
//! | `time_limit`        | none     | stop after the pass that crosses it                           |
//! | `seed`              | 0        | output depends on it, never on the thread count               |
//! | `max_depth`         | 1024     | bounces per path at most (0.99^1024 ≈ 3e-5: no visible bias)   |
//! | `sky`               | 0        | uniform radiance of rays that leave the scene                 |
//! | `indirect_only`     | false    | leave out light reaching `x₀` without a bounce, like the bake |
//! | `no_punctual_direct` | false   | leave out only punctual lights' light reaching `x₀` without a bounce, like probes with `indirect_only` |
//!
//! Camera mode ([`trace_view`], `lightbake reference --view`; see `reference/camera.rs`): the
//! same estimator of `H/π` (`Paths::reflected`) started at the first hit of jittered primary
//! rays through the renderer's pinhole camera gives `baseColor·H/π + Le` per pixel with a
//! standard error — the image `lightbake render` approximates with the lightmap.
//!
//! Probe mode ([`trace_sh`], `reference/probes.rs`): at points of free space, the L2
//! spherical-harmonic irradiance about a normal that a light probe there would hold (the
//! projection's irradiance, estimated one direction at a time through the L2 kernel), so baked
//! probes can be measured without L2's truncation as well as against the true irradiance
//! ([`points::trace_about`]).
//!
//! When to use: to measure a bake's error, in tests and benchmarks. Limits: slow (every texel
//! needs hundreds of paths for 1–2 % noise); the standard error is itself estimated, and heavy-
//! tailed paths (a small emitter reached only by a lucky bounce) can understate it at low sample
//! counts, so the target is checked only after [`MIN_SAMPLES_FOR_TARGET`] paths.

use std::f32::consts::PI;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use glam::{Vec2, Vec3};
use rayon::prelude::*;

use crate::config::BakeConfig;
use crate::lights::{Emitters, punctual_irradiance, triangle_point};
use crate::sampling::{
    Rng, cosine_hemisphere, frame, power_weight, triangle_point as sample_triangle,
};
use crate::texels::{RayEnd, Texels};
use crate::trace::Tracer;
use crate::{Error, Progress, Result, atlas, scene};

mod camera;
pub mod points;
mod probes;

pub use crate::bake::{Prepared, prepare};
pub use camera::{View, trace_view};
pub use probes::trace_sh;

/// Texels per parallel work item (one progress tick each).
const CHUNK: usize = 64;
/// Bounces before Russian roulette may end a path.
pub(crate) const ROULETTE_DEPTH: u32 = 4;
/// Paths per texel before the standard error is trusted for the stopping test.
pub const MIN_SAMPLES_FOR_TARGET: u32 = 32;
/// Mixed into the seed so the reference's random streams never coincide with a bake's.
const SEED_SALT: u64 = 0x5245_4645_5245_4e43; // "REFERENC"

/// How long and how the reference traces.
#[derive(Clone, Debug)]
pub struct ReferenceParams {
    /// Paths per item between stopping checks.
    pub samples_per_pass: u32,
    /// Paths per item at most.
    pub max_samples: u32,
    /// Stop when the relative RMS standard error is at most this.
    pub target_rel_error: Option<f32>,
    /// Stop after the pass that crosses this.
    pub time_limit: Option<Duration>,
    /// Seed of the random streams.
    pub seed: u64,
    /// Bounces per path at most.
    pub max_depth: u32,
    /// Uniform radiance of rays that leave the scene.
    pub sky: Vec3,
    /// Leave out light reaching the first vertex without a bounce, like the bake.
    pub indirect_only: bool,
    /// Leave out only the punctual lights' light reaching the first vertex without a bounce
    /// (what probes baked with `indirect_only` hold: `crate::probes::ProbeParams`).
    pub no_punctual_direct: bool,
}

impl Default for ReferenceParams {
    fn default() -> Self {
        ReferenceParams {
            samples_per_pass: 16,
            max_samples: 1024,
            target_rel_error: None,
            time_limit: None,
            seed: 0,
            max_depth: 1024,
            sky: Vec3::ZERO,
            indirect_only: false,
            no_punctual_direct: false,
        }
    }
}

impl ReferenceParams {
    /// Defaults with the sky, seed and indirect-only choice of a bake configuration, so the
    /// reference estimates what that bake estimates.
    pub fn like(config: &BakeConfig) -> Self {
        ReferenceParams {
            seed: config.transport.seed,
            sky: config.transport.sky,
            indirect_only: config.transport.indirect_only,
            ..Self::default()
        }
    }

    pub(crate) fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(Error::Option(m));
        if self.samples_per_pass < 2 {
            return bad(format!(
                "reference samples per pass must be at least 2 (for a standard error), got {}",
                self.samples_per_pass
            ));
        }
        if self.max_samples < 2 {
            return bad(format!(
                "reference samples per texel must be at least 2, got {}",
                self.max_samples
            ));
        }
        if self.max_depth == 0 {
            return bad("reference path depth must be at least 1".into());
        }
        if let Some(t) = self.target_rel_error
            && !(t.is_finite() && t > 0.0)
        {
            return bad(format!("target error must be a positive number, got {t}"));
        }
        if !(self.sky.is_finite() && self.sky.min_element() >= 0.0) {
            return bad(format!(
                "sky radiance must be finite and non-negative, got {}",
                self.sky
            ));
        }
        Ok(())
    }
}

/// Why tracing stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stop {
    /// `max_samples` paths per item were traced.
    MaxSamples,
    /// The relative RMS standard error reached `target_rel_error`.
    TargetError,
    /// A pass ended past `time_limit`.
    TimeLimit,
}

impl Stop {
    /// The reason in words, for summaries.
    pub fn reason(self) -> &'static str {
        match self {
            Stop::MaxSamples => "sample cap",
            Stop::TargetError => "target error reached",
            Stop::TimeLimit => "time limit",
        }
    }
}

/// A reference estimate per item: per texel (indexed like [`Texels`]) from [`trace`], per pixel
/// from [`trace_view`] ([`View::pixels`]).
#[derive(Clone, Debug)]
pub struct Reference {
    /// Estimated `H/π` per texel, radiance per pixel.
    pub mean: Vec<Vec3>,
    /// Standard error of `mean`, per channel.
    pub std_error: Vec<Vec3>,
    /// Paths per item (the same for every item).
    pub samples: u32,
    /// Rays cast (closest hits and shadow rays; primary rays too for pixels).
    pub rays: u64,
    /// Wall seconds.
    pub seconds: f64,
    /// Relative RMS standard error over items, `√(Σσ²/Σμ²)` (see `rms_rel_error`).
    pub rms_rel_error: f32,
    /// Why tracing stopped.
    pub stop: Stop,
}

impl Reference {
    /// One line for texels: samples, rays, speed, error, time.
    pub fn summary(&self) -> String {
        format!(
            "{} texels, {} samples per texel, {}",
            self.mean.len(),
            self.samples,
            self.cost_and_error()
        )
    }

    /// The end of a summary line, the same for texels and pixels: rays, speed, error, time.
    fn cost_and_error(&self) -> String {
        format!(
            "{:.2} M rays ({:.2} M rays/s), relative RMS standard error {:.2}% ({}), {:.2}s",
            self.rays as f64 * 1e-6,
            self.rays as f64 * 1e-6 / self.seconds.max(1e-9),
            self.rms_rel_error * 100.0,
            self.stop.reason(),
            self.seconds
        )
    }
}

/// A texel's footprint point for `u ∈ [0,1)²`, on the surface (not lifted off it). Partly
/// covered texels are sampled around the centroid of their covered part with the footprint
/// scaled by the covered fraction — the same rule as the bake's gathering, which keeps paths
/// from starting beyond the edge of a surface.
#[inline]
pub fn footprint_point(texels: &Texels, i: usize, u: Vec2) -> Vec3 {
    texels.footprint_point(i, u)
}

/// Running sums of one texel's path estimates (f64, so millions of samples lose nothing).
#[derive(Clone, Copy, Default)]
struct Sums {
    sum: [f64; 3],
    sq: [f64; 3],
}

impl Sums {
    #[inline]
    fn add(&mut self, v: Vec3) {
        for (c, x) in v.to_array().into_iter().enumerate() {
            let x = x as f64;
            self.sum[c] += x;
            self.sq[c] += x * x;
        }
    }

    /// Mean and standard error of the mean after `n ≥ 2` samples.
    fn mean_and_error(&self, n: u32) -> (Vec3, Vec3) {
        let n = n as f64;
        let mut mean = [0.0f32; 3];
        let mut se = [0.0f32; 3];
        for c in 0..3 {
            let m = self.sum[c] / n;
            let var = ((self.sq[c] - self.sum[c] * m) / (n - 1.0)).max(0.0);
            mean[c] = m as f32;
            se[c] = (var / n).sqrt() as f32;
        }
        (Vec3::from(mean), Vec3::from(se))
    }
}

/// Relative RMS standard error `√(Σ_i ‖σ_i‖² / Σ_i ‖μ_i‖²)` over texels (μ the estimate, σ its
/// standard error, both RGB): the noise the reference adds to a relative RMS difference
/// between a bake and the reference. A mean of per-texel ratios `σ_i/μ_i` was tried first and
/// is useless as a stopping rule: texels buried under the Cornell box's blocks or above its
/// light (μ ≈ 1e-4 of the room's) had ratios near 1 and set the RMS alone. 0 for a black scene.
pub(crate) fn rms_rel_error(mean: &[Vec3], std_error: &[Vec3]) -> f32 {
    crate::metrics::noise_over_rms(std_error, mean, &[])
}

/// Traces reference paths at every texel until a stopping rule of `params` holds.
pub fn trace(
    scene: &scene::Scene,
    texels: &Texels,
    tracer: &Tracer,
    params: &ReferenceParams,
    progress: &dyn Progress,
) -> Result<Reference> {
    let sample = |paths: &Paths, i, sample, rays: &mut u64| paths.sample(i, sample, rays);
    trace_items(
        (scene, texels, tracer),
        texels.len(),
        params,
        progress,
        "reference",
        &sample,
    )
}

/// One estimate for item `i` (a texel or a pixel), sample `k`, counting its rays.
pub(crate) type ItemSample<'s> = dyn Fn(&Paths, usize, u32, &mut u64) -> Vec3 + Sync + 's;

/// The texel and camera modes' common part: checks `params`, sets up the paths through the
/// scene (emitters for next-event estimation), runs [`run_passes`] over `n` items and times it.
pub(crate) fn trace_items(
    (scene, texels, tracer): (&scene::Scene, &Texels, &Tracer),
    n: usize,
    params: &ReferenceParams,
    progress: &dyn Progress,
    stage: &str,
    sample: &ItemSample,
) -> Result<Reference> {
    params.validate()?;
    let start = Instant::now();
    let emitters = Emitters::new(scene, texels);
    let paths = Paths {
        scene,
        texels,
        tracer,
        emitters: &emitters,
        params,
    };
    let mut estimate = run_passes(n, params, progress, stage, &|i, k, rays| {
        sample(&paths, i, k, rays)
    })?;
    estimate.seconds = start.elapsed().as_secs_f64();
    Ok(estimate)
}

/// Adds `sample(item, k, &mut rays)` for `k = 0, 1, …` to the running sums of every one of `n`
/// items (texels or pixels), a pass of `params.samples_per_pass` at a time, until a stopping
/// rule of `params` holds. Items are split into fixed chunks and every sample draws its own
/// random stream, so the sums do not depend on the thread count. `seconds` is its own time.
fn run_passes(
    n: usize,
    params: &ReferenceParams,
    progress: &dyn Progress,
    stage: &str,
    sample: &(dyn Fn(usize, u32, &mut u64) -> Vec3 + Sync),
) -> Result<Reference> {
    let start = Instant::now();
    let mut sums = vec![Sums::default(); n];
    let (mut samples, mut rays) = (0u32, 0u64);
    let mut stop = Stop::MaxSamples;
    let aborted = AtomicBool::new(false);
    progress.begin(stage, n as u64 * params.max_samples as u64);
    while samples < params.max_samples {
        let first = samples;
        let pass = params.samples_per_pass.min(params.max_samples - samples);
        rays += sums
            .par_chunks_mut(CHUNK)
            .enumerate()
            .map(|(c, chunk)| {
                if aborted.load(Ordering::Relaxed) || progress.aborted() {
                    aborted.store(true, Ordering::Relaxed);
                    return 0;
                }
                let mut rays = 0u64;
                for (k, s) in chunk.iter_mut().enumerate() {
                    for k_sample in first..first + pass {
                        s.add(sample(c * CHUNK + k, k_sample, &mut rays));
                    }
                }
                progress.advance(chunk.len() as u64 * pass as u64);
                rays
            })
            .sum::<u64>();
        if aborted.load(Ordering::Relaxed) {
            progress.end();
            return Err(Error::Aborted);
        }
        samples += pass;
        if samples >= params.max_samples {
            break;
        }
        if let Some(target) = params.target_rel_error
            && samples >= MIN_SAMPLES_FOR_TARGET
        {
            let (mean, se): (Vec<Vec3>, Vec<Vec3>) =
                sums.iter().map(|s| s.mean_and_error(samples)).unzip();
            if rms_rel_error(&mean, &se) <= target {
                stop = Stop::TargetError;
                break;
            }
        }
        if params.time_limit.is_some_and(|t| start.elapsed() >= t) {
            stop = Stop::TimeLimit;
            break;
        }
    }
    progress.end();
    let (mean, std_error): (Vec<Vec3>, Vec<Vec3>) =
        sums.iter().map(|s| s.mean_and_error(samples)).unzip();
    let rms = rms_rel_error(&mean, &std_error);
    if stop == Stop::MaxSamples && params.target_rel_error.is_some_and(|t| rms <= t) {
        stop = Stop::TargetError;
    }
    Ok(Reference {
        mean,
        std_error,
        samples,
        rays,
        seconds: start.elapsed().as_secs_f64(),
        rms_rel_error: rms,
        stop,
    })
}

/// The stages a reference needs, and the reference itself.
#[derive(Clone, Debug)]
pub struct Computed {
    /// The loaded scene (after the junction split).
    pub scene: scene::Scene,
    /// The input document as read.
    pub source: scene::Source,
    /// The lightmap UV layout, as the bake's.
    pub atlas: atlas::Atlas,
    /// The texels, as the bake's.
    pub texels: Texels,
    /// The estimate per texel.
    pub reference: Reference,
}

/// [`prepare`] (the bake's own: the texels are a bake's texels with the same `config`), then
/// [`trace`]. The estimates are raw: a bake replaces its `texels.invalid`
/// (buried) texels by their neighbours' values, so compare on the others or apply
/// [`crate::texels::validity::fill_invalid`] too.
pub fn compute(
    input: &Path,
    config: &BakeConfig,
    params: &ReferenceParams,
    progress: &dyn Progress,
) -> Result<Computed> {
    params.validate()?;
    let mut p = prepare(input, config, progress)?;
    // A bake's pilot pair kept from the density pilot is no use to a path tracer.
    p.density.pair = None;
    let reference = trace(&p.scene, &p.texels, &p.tracer, params, progress)?;
    Ok(Computed {
        scene: p.scene,
        source: p.source,
        atlas: p.atlas,
        texels: p.texels,
        reference,
    })
}

pub(crate) struct Paths<'a> {
    pub(crate) scene: &'a scene::Scene,
    pub(crate) texels: &'a Texels,
    pub(crate) tracer: &'a Tracer,
    pub(crate) emitters: &'a Emitters,
    pub(crate) params: &'a ReferenceParams,
}

impl Paths<'_> {
    /// One path estimate of texel `i`'s `H/π`; its random stream depends only on
    /// (seed, texel, sample), never on the thread that runs it. A footprint point cut off from
    /// the sample point starts its path at the sample point, as the bake reads lights there
    /// ([`Texels::punctual_point`]).
    fn sample(&self, i: usize, sample: u32, rays: &mut u64) -> Vec3 {
        let t = self.texels;
        let mut rng = Rng::new(self.params.seed ^ SEED_SALT, i as u64, sample as u64);
        let n = t.normal[i];
        let x = footprint_point(t, i, rng.next_vec2()) + n * self.tracer.epsilon;
        let x = t.punctual_point(self.tracer, i, x);
        *rays += 1;
        self.reflected(x, n, None, &mut rng, rays)
    }

    /// One path estimate of `H(x)/π` at the surface point `x` (already lifted off the surface
    /// by the ray offset) with unit normal `n`: the radiance a white Lambertian surface there
    /// reflects. Shared by the texel and the camera modes. Non-finite estimates count as 0.
    /// With a `horizon` (the surface's geometric normal, when `n` is a perturbed normal) light
    /// arriving at `x` from below it counts as zero: the surface itself blocks it (a ray into
    /// the surface would otherwise hit its own front from just above it).
    pub(crate) fn reflected(
        &self,
        x: Vec3,
        n: Vec3,
        horizon: Option<Vec3>,
        rng: &mut Rng,
        rays: &mut u64,
    ) -> Vec3 {
        let (t, eps) = (self.texels, self.tracer.epsilon);
        let (mut x, mut n) = (x, n);
        // The receiver is a white Lambertian surface: H/π is the radiance it reflects.
        let mut rho = Vec3::ONE;
        let mut beta = Vec3::ONE;
        let mut l = Vec3::ZERO;
        for depth in 0..self.params.max_depth {
            // Light that reaches x₀ without a bounce is direct light.
            let counts = depth > 0 || !self.params.indirect_only;
            let horizon = horizon.filter(|_| depth == 0);
            if counts {
                let punctual = depth > 0 || !self.params.no_punctual_direct;
                l += beta * rho * self.next_event(x, n, horizon, punctual, rng, rays) / PI;
            }
            let (tx, ty) = frame(n);
            let local = cosine_hemisphere(rng.next_vec2());
            let dir = tx * local.x + ty * local.y + n * local.z;
            if horizon.is_some_and(|h| h.dot(dir) <= 0.0) {
                break;
            }
            beta *= rho;
            *rays += 1;
            let (hit, j) = match t.ray_end(self.tracer, x, dir) {
                RayEnd::Texel(hit, j) => (hit, j),
                RayEnd::Escaped => {
                    if counts {
                        l += beta * self.params.sky;
                    }
                    break;
                }
                RayEnd::Absorbed => break,
            };
            let (p, n_hit) = triangle_point(self.scene, hit.triangle, hit.bary);
            let le = t.emission[j as usize];
            if counts && le.max_element() > 0.0 {
                // MIS weight of the cosine-sampled hit against light sampling of this point.
                let p_bsdf = local.z / PI;
                let p_light = self.emitters.pdf_toward(hit.triangle, n_hit, dir, hit.t);
                let w = if p_light > 0.0 {
                    p_bsdf * power_weight(p_bsdf, p_light)
                } else {
                    1.0
                };
                l += beta * le * w;
            }
            rho = t.albedo[j as usize];
            if rho.max_element() <= 0.0 || n_hit == Vec3::ZERO {
                break;
            }
            n = n_hit;
            x = p + n * eps;
            if depth + 1 >= ROULETTE_DEPTH {
                let q = rho.max_element().min(1.0);
                if rng.next_f32() >= q {
                    break;
                }
                beta /= q;
            }
        }
        if l.is_finite() { l } else { Vec3::ZERO }
    }

    /// Irradiance estimate at `x` (offset, normal `n`) from punctual lights (unless not
    /// `punctual`) and one MIS-weighted sample of the small emitters; none from below `horizon`.
    #[inline]
    fn next_event(
        &self,
        x: Vec3,
        n: Vec3,
        horizon: Option<Vec3>,
        punctual: bool,
        rng: &mut Rng,
        rays: &mut u64,
    ) -> Vec3 {
        let above = |dir: Vec3| horizon.is_none_or(|h| h.dot(dir) > 0.0);
        let mut e = Vec3::ZERO;
        for light in self.scene.lights.iter().filter(|_| punctual) {
            let toward = match light.kind {
                scene::LightKind::Directional => -light.direction,
                _ => light.position - x,
            };
            if above(toward) {
                e += punctual_irradiance(light, x, n, self.tracer);
            }
        }
        *rays += if punctual {
            self.scene.lights.len() as u64
        } else {
            0
        };
        if self.emitters.is_empty() {
            return e;
        }
        let tri = self.emitters.pick(rng.next_f32());
        let bary = sample_triangle(rng.next_vec2());
        let Some(y) = self
            .emitters
            .sample_at((self.scene, self.texels), x, Some(n), tri, bary)
        else {
            return e;
        };
        *rays += 1;
        if !above(y.point - x) || self.tracer.occluded(x, y.point) {
            return e;
        }
        let p_bsdf = y.cos_i / PI;
        e + y.le * (y.cos_i * power_weight(y.pdf_solid_angle(), p_bsdf))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sums_give_mean_and_standard_error() {
        let mut s = Sums::default();
        for v in [1.0f32, 2.0, 3.0, 4.0] {
            s.add(Vec3::splat(v));
        }
        let (m, se) = s.mean_and_error(4);
        assert!((m.x - 2.5).abs() < 1e-6);
        // Sample variance 5/3, standard error sqrt(5/12).
        assert!((se.y - (5.0f32 / 12.0).sqrt()).abs() < 1e-6, "{se}");
    }

    #[test]
    fn relative_error_is_noise_over_signal() {
        // A near-black texel with a large ratio σ/μ barely moves it.
        let mean = [Vec3::splat(2.0), Vec3::splat(1e-4)];
        let se = [Vec3::splat(0.1), Vec3::splat(1e-4)];
        assert!((rms_rel_error(&mean, &se) - 0.05).abs() < 1e-5);
        assert_eq!(rms_rel_error(&[Vec3::ZERO], &[Vec3::ZERO]), 0.0);
    }

    #[test]
    fn params_are_checked() {
        assert!(ReferenceParams::default().validate().is_ok());
        let p = ReferenceParams {
            samples_per_pass: 1,
            ..Default::default()
        };
        assert!(p.validate().is_err());
        let p = ReferenceParams {
            target_rel_error: Some(0.0),
            ..Default::default()
        };
        assert!(p.validate().is_err());
    }
}
