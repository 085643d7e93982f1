//! Automatic choice of bake settings: model no more of a scene than its light needs.
//!
//! With [`AutoParams`](crate::config::AutoParams) in the config, [`crate::compute`] chooses what the user did not fix.
//! This module holds the decisions and their reasons, and solves nothing: the pipeline
//! (`bake::pilot`) runs the pilot bakes and hands their measurements to the functions here.
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
//!   `PILOT_RAYS` gathering rays and independent seeds; the RMS difference of the two
//!   lightmaps over √2 is the noise of one such bake. Assuming 1/√K, the rays that reach the
//!   target are `K = K₀ · (noise₀ / (0.75·E))²` (a quarter of the error budget left for what
//!   the pilot cannot see: texel placement, leaks, solver tolerance), rounded up to four steps
//!   per octave. When that asks for more than `SECOND_PILOT_ABOVE`, a second pair at 4·K₀
//!   measures how fast the noise really falls (exponent clamped to ½ … `MAX_EXPONENT`):
//!   stratified samples fall faster than 1/√K at first (the 116k-triangle hall: 66% at K=16,
//!   15% at K=64), and 1/√K from K=16 asked that hall for 4096 rays for a 4% target; the
//!   fit asks for 640, which gave 4.4% (bench.md).
//!   Light samples follow as K/4, like the presets.
//! - **Nothing measured is thrown away**: the last pilot pair is part of the result, and so
//!   is the first pair when a second ran on the same atlas. The final lightmap is the
//!   ray-weighted mean of the pilot bakes on the final atlas and one more bake at the rays
//!   they lack (or of the pilots alone when they suffice). Keeping the first pair beside the
//!   second (its 16-ray runs were thrown away before) took planning on the Cornell box at
//!   `high` from 28% to 10% of the bake, on two rooms at `high` from 27% to 11%, on the lamp
//!   room at `medium` from 39% to 15% (one `density_figures` run, the guide's performance
//!   page). Its noise is that of
//!   independent runs averaged, which falls only as the square root of their number even where
//!   one run's stratified noise falls as `K^−α` (the furnished interior at `high`: one run of
//!   128 rays read 1.74% at random points, the mean of three runs of 64, 1.95%), and the rays
//!   are chosen for that. A single final run on pairs measured on the density pilot's atlas
//!   was tried and is not the default (see the guide, `src/guide/baking.md`).
//! - **The denoiser counts** where rays are most of the cost: when a second pair (4×
//!   `PILOT_RAYS`) ran, each of its runs is denoised as the final lightmap is, and the rays aim
//!   at what the denoiser leaves (`denoise_gain`: 0.52 on the furnished interior's final atlas
//!   at `high`, credited within ×½…×1). That gain holds at the pair's rays; a last bake beyond
//!   them is credited less, as the fourth root of the rays (`DENOISE_GAIN_RISE`: the range
//!   kernel narrows with the noise). A pair at 16 rays is not asked: the denoiser's range
//!   kernel is twice as wide there, and the gain it showed cost small scenes' p95 error.
//! - **Fewer rays where the lightmap matters less**: from the pilot's irradiance, an emitter
//!   texel whose rendered radiance is mostly its own `Le` gets `K·w²` rays (`w` the lightmap's
//!   share of what is seen), black and unlit texels the minimum (`MIN_TEXEL_RAYS`); on the
//!   fixtures this saves 1.8–3.0% of the rays (emitters are small) and never touches lit texels.
//! - **More rays where they disagree**: when a last bake follows a pair at 4× `PILOT_RAYS`, its
//!   rays move between the other texels, the total kept: each run measured what its rays
//!   returned per texel (`error_map::ray_variance`, from its rows and solution), and a texel
//!   whose neighbours' rays spread by `σ` gets rays ∝ `σ/(H + 5% of the mean)` (`spread_rays`:
//!   the least mean square relative noise), within ×½…×4 (and never below the pilots' rays).
//!   On the lamp room at `high` (seeds 0–3) the first form, `σ/√(H + 5%)`, took the point
//!   error 1.375% → 1.33% and the view 0.66% → 0.59% against uniform rays, and this one the
//!   p95 against 65,536-path references 2.01% → 1.85% beside it at the same time. Variances
//!   from 16-ray pairs cost `draft` bakes their accuracy and are not used.
//! - **Tolerance** E/10: the solver stops once its remaining error is well below the Monte
//!   Carlo error, not later.
//! - **Texel density where the error is** ([`density`]): a pilot pair on a uniform atlas of its
//!   own (quickly charted, at most `density::PILOT_TEXELS` texels) and its lookup-error sample
//!   at random surface points (`GatheredSample`) give each region of the surfaces (a
//!   connected surface between creases: a wall, a cabinet door, a cup) a density factor, ∝ the
//!   fourth root of its measured mean square error, within ×¼…×4; regions nobody sees (buried,
//!   facing into geometry) or no light reaches get ×⅛. Seen regions keep at least the preset's
//!   density, and only that while the sample's central estimate is within what the target
//!   leaves beside the noise; above it, the regions with most error rise first until the
//!   prediction meets it (up to ×4 and the preset's budget). The sample gathers its points
//!   where the pilot's light steps, weighed by one over their chance (`gathered`). The atlas, texels and validity
//!   are then laid out (once, but for the check below), and the pilot's noise at `PILOT_RAYS` is the transport plan's
//!   first measurement (its pair is not cast again on the new atlas). The laid-out atlas's
//!   own sample checks the choice once: when it predicts the bake above its target, its lookup
//!   error the larger part, the pilot's model is scaled to what that atlas measured and the
//!   atlas laid out again (`density::DensityChoice::raise_after`). A small scene is
//!   measured on its final atlas, uniform at the preset's density; when no factor is asked,
//!   or the factors would move fewer than 5% of its texels (a few unseen regions at ×⅛: a new
//!   layout and pair would cost more), that atlas and the pilot's pair are the bake's own
//!   (`bake::pilot::Reused::pair`).
//! - **Resolution error** is predicted (`predict_resolution`): what a renderer shows
//!   between texel centres, where it blends four texels bilinearly, differs from the light at
//!   that point where the light changes within a texel.
//!   It is *measured* at random surface points (`GatheredSample`): the last pilot pair's texel
//!   values (denoised as the final lightmap will be, when the denoiser's gain is credited, so
//!   that its smoothing of edges counts) read back by bilinear lookup against the light there
//!   — punctual lights exactly (one shadow ray each, about the shading normal, against each
//!   run's own punctual light at the texels, `Transport::punctual`), emitters, sky and
//!   interreflection gathered at the point as transport gathers at a texel (32 rays and 8
//!   emitter light samples through each run's solution). Each run's difference is independent
//!   of the other's, so the mean of their products has neither's noise; points are drawn in batches (4096, or as many as the
//!   budget pays for down to 1024) until the mean square is known to ±40% (two standard
//!   errors), is clearly small, or the sample has cast half the pilot's rays (it always casts
//!   one batch; 2.0 s of 22 s on the furnished interior at draft, 2.9 s of 65 s at medium). The pilot's
//!   second differences (`resolution_error`) it replaced are a lower bound (emitter shadows and
//!   contacts narrower than a texel are not in them) and stay in `--explain` beside it; the
//!   punctual sample (`PunctualSample`, about the face normal) still steers the adaptive
//!   density. Predicted (noise before denoising and resolution error in quadrature) against
//!   measured point error (reference noise out), draft / medium: furnished interior 8.9% / 4.9%
//!   for 8.1% / 5.6% (the second differences predicted 6.5% / 3.5%), Cornell box 6.6% / 3.0% for
//!   6.2% / 2.8%, lamp_room 8.0% / 4.2% for 7.1% / 2.6%, two_rooms 6.3% / 3.4% for 4.3% / 1.4%;
//!   the table is in the guide (`src/guide/performance.md`). `--explain` says plainly when the
//!   prediction is above the target, which part dominates, and about how much more texels (a
//!   range: the error falls as `h²` where light curves smoothly, as `√h` at edges) or rays
//!   would take.
//! - **Error map** (`error_map`, `--error-map`): the same two parts texel by texel, written
//!   beside each page so an artist sees where a bake is weak and whether texels or rays would help.
//!
//! The pilot costs nothing extra when its bakes suffice and a few solves otherwise (Cornell
//! box, 7167 texels, medium: 4 pilot bakes, 0.3 s, and no further bake). It measures the scene
//! rather than guessing from it: closed rooms with bright emitters need far more rays than a
//! sunlit terrain at the same target.

pub mod density;
pub(crate) mod error_map;
pub(crate) mod gathered;
pub(crate) mod memory;
pub(crate) mod punctual;

use glam::Vec3;

pub(crate) use gathered::GatheredSample;
pub use memory::{COUNT_BYTES_PER_RAY, MemoryEstimate, MemoryInputs, memory_estimate};
pub(crate) use memory::{entries_per_texel, format_bytes, row_entry_bytes};
pub(crate) use punctual::PunctualSample;

use crate::config::{BakeConfig, FormFactors, Keep, RowSolver, RowStorage, Technique};
use crate::metrics;
use crate::scene::Scene;
use crate::texels::{NO_TEXEL, Texels};

/// Gathering rays per texel of the pilot bakes.
pub(crate) const PILOT_RAYS: u32 = 16;
/// When the first pilot asks for more rays than this, a second pilot at 4× [`PILOT_RAYS`]
/// measures how fast the noise falls.
pub(crate) const SECOND_PILOT_ABOVE: u32 = 256;
/// Fastest noise fall the fit believes: stratified light samples and Hammersley gathering fall
/// faster than 1/√K at low K (Cornell box 16 → 64 rays: K^−0.78), then flatten towards 1/√K.
pub(crate) const MAX_EXPONENT: f32 = 0.75;
/// Bounds of the chosen gathering rays.
pub(crate) const RAYS_RANGE: (u32, u32) = (16, 4096);
/// Stored rows beyond this many bytes switch to the matrix-free gather solver.
pub(crate) const ROW_MEMORY_LIMIT: f64 = 4.0 * (1u64 << 30) as f64;

/// Per-texel gathering rays (indexed like `Texels`); light samples scale with them.
#[derive(Clone, PartialEq, Eq)]
pub struct TexelRays(pub Vec<u32>);

impl std::fmt::Debug for TexelRays {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let total: u64 = self.0.iter().map(|&k| k as u64).sum();
        write!(f, "TexelRays({} texels, {total} rays)", self.0.len())
    }
}

/// What was chosen and why, in order (density first).
#[derive(Clone, Debug, Default)]
pub struct Plan {
    /// The relative RMSE aimed at.
    pub target_error: f32,
    /// The pilot's measured relative noise at `PILOT_RAYS`, if a pilot ran.
    pub pilot_noise: Option<f32>,
    /// Expected noise of the chosen bake (before denoising; [`Plan::denoise_gain`] of it is
    /// left after).
    pub predicted_noise: Option<f32>,
    /// Expected resolution error of the chosen density (`resolution_error`), measured on
    /// the pilot's irradiance.
    pub predicted_resolution: Option<f32>,
    /// What the resolution error is made of (`predict_resolution`).
    pub resolution_parts: Option<ResolutionParts>,
    /// Gathering rays per texel in all, the reused pilot bakes included.
    pub total_rays: Option<u32>,
    /// Wall seconds of the pilot bakes.
    pub pilot_seconds: f64,
    /// Seconds of the gathered point sample (`GatheredSample`) behind the resolution error.
    pub resolution_seconds: f64,
    /// Gathering rays the pilot bakes cast.
    pub pilot_rays: u64,
    /// The texel budget of the preset's density ([`choose_density`]), when the plan chose it:
    /// the most texels the density regions ([`density`]) may ask for.
    pub texel_budget: Option<(f64, f64)>,
    /// Gathering rays per texel of the pilot pair the resolution sample read (`PILOT_RAYS`,
    /// or 4× when a second pilot ran).
    pub resolution_pilot_rays: u32,
    /// Rays of pilot bakes not reused in the result (the density pilot's when the final atlas
    /// is another).
    pub discarded_rays: u64,
    /// Wall seconds of planning whose work the result does not contain: the density pilot (its
    /// atlas, pair and sample), pilot pairs not reused, the lookup-error samples. Pilot pairs
    /// the final bake averages in are the bake's own work, not counted here.
    pub overhead_seconds: f64,
    /// Whether the noise at `PILOT_RAYS` behind the rays is the density pilot's.
    pub noise_from_density_pilot: bool,
    /// What the denoiser leaves of the noise: measured on a pilot pair (denoised over raw
    /// relative noise), then, once the rays are chosen, as credited at the bake's rays (less
    /// beyond the pair's rays, as their fourth root); the rays aim at the noise after
    /// denoising when it was measured.
    pub denoise_gain: Option<f32>,
    /// Weight of each run of a first pilot pair averaged in beside a second
    /// (`choose_rays`): the rays of a run as noisy under the fitted fall `K^−α` as the
    /// earlier run is under `1/K`, which the other runs' ray weights and the denoiser's noise
    /// model assume. `None` without such a pair.
    pub earlier_weight: Option<f32>,
    /// Gathering rays per texel of the last bake where fewer than its `gather_rays` suffice
    /// (emitters, black and unlit texels, measured by the pilot); `None`: `gather_rays`
    /// everywhere. Monte Carlo rows only (not the gather solver, not hierarchical).
    pub texel_rays: Option<TexelRays>,
    /// One line per decision: what, and the measurement or rule behind it.
    pub reasons: Vec<String>,
    /// The choice in a few words, for the one-line summary.
    pub brief: String,
}

/// The parts of the predicted resolution error.
#[derive(Clone, Copy, Debug, Default)]
pub struct ResolutionParts {
    /// Relative RMS lookup error of all the light at random surface points against a gather
    /// there (`GatheredSample`), with its spread from the sample's own noise (the relative
    /// errors at the mean square ∓ two standard errors); the prediction when measured.
    pub gathered: Option<(f32, f32, f32)>,
    /// Its parts: the light other than punctual direct light (emitters, sky,
    /// interreflection), and punctual direct light at the same points about the shading normal.
    pub rest: Option<f32>,
    /// The part from punctual direct light (see `rest`).
    pub point_punctual: Option<f32>,
    /// Relative RMS lookup error of the light other than punctual direct light, from the
    /// pilot's second differences (`resolution_error`'s model; a lower bound).
    pub curved: f32,
    /// Relative RMS lookup error of punctual direct light, sampled at random surface points
    /// (`PunctualSample`): hard shadow and cone edges, sub-texel features, gutters.
    pub sampled: f32,
    /// Share of those lookups that read a gutter or buried neighbour.
    pub border_share: f32,
}

impl Plan {
    /// The expected error at random points of the surfaces, as a renderer shows the bake: noise
    /// and resolution error are independent, so they add in quadrature. `None` without a pilot.
    pub fn predicted_error(&self) -> Option<f32> {
        match (self.denoised_noise(), self.predicted_resolution) {
            (Some(n), Some(r)) => Some(n.hypot(r)),
            (n, r) => n.or(r),
        }
    }

    /// The predicted noise as the final lightmap keeps it: after denoising, when the
    /// denoiser's gain is credited.
    pub(crate) fn denoised_noise(&self) -> Option<f32> {
        (self.predicted_noise).map(|n| n * self.denoise_gain.unwrap_or(1.0))
    }

    /// The choice in a few words (sets [`Plan::brief`]), once every decision is made.
    pub(crate) fn finish(&mut self, config: &BakeConfig) {
        let mut s = format!(
            "auto for {:.1}%: {} K={}",
            self.target_error * 100.0,
            config.technique,
            self.total_rays.unwrap_or(config.transport.gather_rays)
        );
        if let Some(p) = self.predicted_error() {
            let over = if p > self.target_error {
                ", above the target"
            } else {
                ""
            };
            s += &format!(" (predicted {:.1}%{over})", p * 100.0);
        }
        self.brief = s;
    }
}

/// Total surface area of the scene's triangles (m²).
pub fn surface_area(scene: &Scene) -> f64 {
    (0..scene.triangles.len())
        .map(|t| scene.triangle_area(t))
        .sum()
}

/// Texel budget for a preset density: `tpu = 16` (medium) allows 4 096 … 262 144 texels,
/// scaled with the density's square for the other presets. Texels over the surfaces' area:
/// the laid-out atlas adds its charts' borders (9–10% at 32 /m on the furnished interior, 64% at
/// 8 /m: 56,324 texels laid out for 34,358 over the area), which the density pilot cannot
/// predict well from a coarse atlas of its own (`plan::density`, the cap).
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
    plan.texel_budget = Some((lo, hi));
    let chosen = if texels < lo {
        (lo / area).sqrt() as f32
    } else if texels > hi {
        (hi / area).sqrt() as f32
    } else {
        tpu
    };
    // Round to 3 significant digits so the choice reads well and is stable.
    let chosen = if chosen.is_finite() && chosen > 0.0 {
        round_significant(chosen, 3).clamp(1e-3, 100_000.0)
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

/// `x` rounded to `digits` significant digits: a chosen number that reads well and is stable.
fn round_significant(x: f32, digits: i32) -> f32 {
    let x = f64::from(x);
    let k = x.log10().floor() as i32 - (digits - 1);
    // Dividing by an exact power of ten keeps 13.4 from printing as 13.400001.
    let rounded = if k < 0 {
        let m = 10f64.powi(-k);
        (x * m).round() / m
    } else {
        let m = 10f64.powi(k);
        (x / m).round() * m
    };
    rounded as f32
}

/// Step 2, once texels exist: the method. Monte Carlo unless the user fixed it; the solver is
/// kept (a hierarchical technique's Jacobi sweeps become Monte Carlo rows with Jacobi).
pub(crate) fn choose_method(config: &mut BakeConfig, plan: &mut Plan, keep: &Keep) {
    if keep.method {
        return;
    }
    config.technique = match config.technique {
        Technique::Stored { solver, .. } => Technique::stored(FormFactors::MonteCarlo, solver),
        Technique::Gather => Technique::Gather,
        Technique::Hierarchical => Technique::DEFAULT,
    };
    plan.reasons.push(
        "method montecarlo: on the benchmark's error-vs-time Pareto front on every fixture; \
         point/polygon are all-pairs (O(N²)) and 3.0–9.7% off on the Cornell box and two rooms \
         where Monte Carlo reaches 1.5–3.6%; hierarchical is 2.7–7.9% off at 4–5× the time"
            .into(),
    );
}

/// Share of the target `e` the rays bring the noise to ([`choose_rays`]); the resolution error
/// gets what is left in quadrature, `√(1 − 0.75²) ≈ 0.66·e`.
///
/// An even split (`1/√2`: least texels × rays when the resolution's mean square falls as one
/// over the texels and the noise's as one over the rays) was tried on 7 December, every corpus
/// bake at seed 0 against this build, one run: the furnished interior at `high` laid out 802k
/// texels instead of 929k but needed a run past its 64-ray pair, 48.0 → 54.8 s (861 → 770 MB,
/// 1.76% → 1.78%, p95 1.22% → 1.13%); at `medium` 11.9 → 10.2 s, 3.36% → 3.44% (p95 2.65% →
/// 2.25%); the lamp room at `draft` 4.87% → 6.02% on 13% fewer texels, at `high` 7.4 → 8.1 s
/// for 1.19% → 1.15%; the courtyard at `high` 5.9 → 6.3 s (0.86% → 0.82%); the interior at
/// `draft` 6.01% → 6.24%; elsewhere point error moved by at most 0.11 points (11 bakes the
/// same figures). No better error per second where the cost is; not taken.
pub(crate) const NOISE_SHARE: f32 = 0.75;

/// Gathering rays that bring `noise`, measured at `k` rays and falling as `K^−alpha`, to
/// [`NOISE_SHARE`] of the target `e`.
fn rays_for_target(k: f32, noise: f32, alpha: f32, e: f32) -> f32 {
    k * (noise / (NOISE_SHARE * e)).powf(1.0 / alpha)
}

/// Whether the noise `first` measured at [`PILOT_RAYS`] asks for a second pilot at 4× the rays.
pub(crate) fn needs_second_pilot(first: f32, e: f32) -> bool {
    rays_for_target(PILOT_RAYS as f32, first, 0.5, e) > SECOND_PILOT_ABOVE as f32 && first > 0.0
}

/// How fast the denoiser's share of the noise rises with the rays beyond the pilot pair it was
/// measured on: `g(T) = g_pair · (T / T_pair)^¼`, `T` the bake's rays in all (first pairs at
/// their weight) and `T_pair` the last pair's two runs together, never above 1. The range
/// kernel is tied to the expected noise (`lightmap::denoise`), so as rays lower the noise it
/// admits fewer neighbours across the light's own gradients: on a gradient the admitted band
/// is as wide as the noise, `K^−½`, and the noise left goes as one over the square root of
/// the neighbours, `K^¼`. Measured 7 December (seed pairs at fixed rays, 32 texels/m,
/// denoised against raw relative noise): lamp room 0.48 / 0.49 / 0.60 / 0.94 at K = 64 / 128
/// / 256 / 1024 (the rule from the pair at 64: 0.48 / 0.57 / 0.80), two rooms 0.30 / 0.32 /
/// 0.35 / 0.60 (0.30 / 0.36 / 0.50), furnished interior 0.65 / 0.69 / 0.74 at 64 / 128 / 256
/// (0.65 / 0.78), Cornell box 0.52 / 0.65 / 0.81 / 0.94 (it rises from 64 on: its pair-only
/// bakes are still credited more than they get). Three of four moving 2–7% from 64 to 128 is
/// why the rule starts at the pair's two runs together, not at one run's rays. Crediting the
/// pair's gain at any `K` aimed the lamp room at `high` at 1.44% after denoising where, by the
/// gain measured at 256 rays, its rays left about 1.7%, and its p95 against a 16×-path
/// reference went 1.7% → 2.4% against the build before the cost work
/// (`bake::pilot::DENOISE_GAIN_RANGE`).
pub(crate) const DENOISE_GAIN_RISE: f32 = 0.25;

/// The denoiser's gain credited at `ratio` times the rays of the pair that measured `measured`
/// ([`DENOISE_GAIN_RISE`]); 1 (no credit) when nothing was measured.
pub(crate) fn denoise_gain_at(measured: Option<f32>, ratio: f32) -> f32 {
    measured.map_or(1.0, |g| {
        (g * ratio.max(1.0).powf(DENOISE_GAIN_RISE)).min(1.0)
    })
}

/// Step 3, from the pilot's relative noise at [`PILOT_RAYS`] (`first`) and at 4× (`second`,
/// when [`needs_second_pilot`]): the gathering rays of the bake that completes the last pilot
/// pair. Returns true when that pair alone reaches the target (no further bake). Expects
/// `plan.pilot_seconds` to be set. `earlier` is the rays per run of a first pair on the same
/// texels averaged in beside the last (0 without one); its weight in the mean is set in
/// `plan.earlier_weight`.
///
/// The final lightmap is the ray-weighted mean of the pairs and that bake: independent runs,
/// whose noise falls only as the square root of their number even where each run's own
/// (stratified) noise falls as `K^−alpha`. The rays aim at the noise after denoising when
/// `plan.denoise_gain` was measured.
pub(crate) fn choose_rays(
    config: &mut BakeConfig,
    plan: &mut Plan,
    first: f32,
    second: Option<f32>,
    earlier: u32,
) -> bool {
    let e = plan.target_error;
    let NoiseFit {
        noise,
        k_pilot,
        alpha,
        wanted,
    } = fit_noise(plan, first, second);
    plan.pilot_noise = Some(noise);
    let k = round_up_quarter_octave(wanted).clamp(RAYS_RANGE.0, RAYS_RANGE.1);
    // The last pilot's two runs are reused: only the rays they lack are cast again.
    let last_pilot = if second.is_some() {
        4 * PILOT_RAYS
    } else {
        PILOT_RAYS
    };
    // One run's noise at `k` rays.
    let run_noise = |k: f32| noise * (k_pilot / k).powf(alpha);
    // The reused pair and one more run of `extra` rays: independent runs in a ray-weighted
    // mean, whose variances add as the squares of the weights (not a single run of all the
    // rays: stratification holds within a run, not across runs).
    let (kp, ke) = (last_pilot as f32, earlier as f32);
    // A first pair's runs fall faster than 1/K below the last pair's rays: each weighs as the
    // rays of a 1/K run as noisy (its inverse variance beside the last pair's), fewer than
    // it cast when α > ½ (16 rays count as 8 at α = 0.75).
    let we = if earlier > 0 {
        ke * (ke / kp).powf(2.0 * alpha - 1.0)
    } else {
        0.0
    };
    plan.earlier_weight = (earlier > 0).then_some(we);
    let combined = |extra: f32| {
        let sum = 2.0 * (kp + we) + extra;
        let pair = 2.0 * (kp / sum * run_noise(kp)).powi(2);
        let first = if we > 0.0 {
            2.0 * (we / sum * run_noise(ke)).powi(2)
        } else {
            0.0
        };
        let more = if extra > 0.0 {
            (extra / sum * run_noise(extra)).powi(2)
        } else {
            0.0
        };
        (pair + first + more).sqrt()
    };
    // What the denoiser leaves at the bake's rays: the gain measured on the last pair holds at
    // the pair's rays together and rises beyond them (see `DENOISE_GAIN_RISE`).
    let pair_rays = 2.0 * (kp + we);
    let gain_at = |extra: f32| denoise_gain_at(plan.denoise_gain, (pair_rays + extra) / pair_rays);
    let aim = NOISE_SHARE * e;
    let reused = 2 * (last_pilot + earlier);
    let enough = combined(0.0) * gain_at(0.0) <= aim;
    config.transport.gather_rays = if enough {
        last_pilot
    } else {
        // The fewest rays, on quarter-octave steps, that bring the mean to the aim.
        let cap = RAYS_RANGE.1.saturating_sub(reused).max(RAYS_RANGE.0);
        let mut extra = RAYS_RANGE.0;
        while extra < cap && combined(extra as f32) * gain_at(extra as f32) > aim {
            extra = round_up_quarter_octave(extra as f32 + 1.0);
        }
        extra.min(cap)
    };
    let extra = if enough {
        0
    } else {
        config.transport.gather_rays
    };
    let total = reused + extra;
    let predicted = combined(extra as f32);
    let measured_gain = plan.denoise_gain;
    let credited = gain_at(extra as f32);
    plan.denoise_gain = measured_gain.map(|_| credited);
    plan.predicted_noise = Some(predicted);
    plan.total_rays = Some(total);
    let measured = if second.is_some() {
        format!(
            "{:.2}% noise at K={PILOT_RAYS} and {:.2}% at K={}, falling as K^−{alpha:.2}",
            first * 100.0,
            noise * 100.0,
            4 * PILOT_RAYS
        )
    } else {
        format!(
            "{:.2}% noise at K={PILOT_RAYS}, assumed to fall as K^−½",
            first * 100.0
        )
    };
    let bakes = if earlier > 0 {
        "the four pilot bakes"
    } else {
        "the last two pilot bakes"
    };
    let reuse_why = if enough {
        format!("{bakes} ({reused} rays together) are the bake, nothing more is cast")
    } else {
        format!(
            "{bakes} ({reused} rays) are averaged with one more at K={}",
            config.transport.gather_rays
        )
    };
    let denoised = match measured_gain {
        Some(g) => format!(
            " before denoising, {:.2}% after (the denoiser left ×{g:.2} of the last pilot \
             pair's noise; credited ×{credited:.2} at {:.1}× the pair's rays, as its range \
             kernel narrows with the noise)",
            predicted * credited * 100.0,
            (pair_rays + extra as f32) / pair_rays,
        ),
        None => String::new(),
    };
    plan.reasons.push(format!(
        "gathering rays K={} in all: the pilot ({}, {:.2}s) measured {measured}; \
         K≥{wanted:.0} reaches 75% of the {:.1}% target; expected {:.2}%{denoised}; {reuse_why}{}",
        plan.total_rays.unwrap_or(k),
        match (second.is_some(), plan.noise_from_density_pilot) {
            (true, true) => "2 bakes here and the density pilot's 2",
            (true, false) => "4 bakes",
            (false, _) => "2 bakes",
        },
        plan.pilot_seconds,
        e * 100.0,
        predicted * 100.0,
        if wanted > RAYS_RANGE.1 as f32 {
            " (capped: the target needs more rays than the cap; expect more error)"
        } else {
            ""
        }
    ));
    enough
}

/// How a run's noise falls with its rays, fitted to the pilot pairs ([`choose_rays`]).
struct NoiseFit {
    /// One run's relative noise at `k_pilot` rays: the last pair's.
    noise: f32,
    /// The last pair's rays per run.
    k_pilot: f32,
    /// The noise falls as `K^−alpha` (½ unless a second pair measured it).
    alpha: f32,
    /// The rays per run at which the noise, less what the denoiser takes, meets
    /// `NOISE_SHARE` of the target.
    wanted: f32,
}

/// The fit from the pair at [`PILOT_RAYS`] (relative noise `first`) and, on a hard scene, a
/// second pair at 4× (`second`): the exponent from the two, else ½.
fn fit_noise(plan: &Plan, first: f32, second: Option<f32>) -> NoiseFit {
    let e = plan.target_error;
    let gain = plan.denoise_gain.unwrap_or(1.0);
    let k0 = PILOT_RAYS as f32;
    let (mut noise, mut k_pilot, mut alpha) = (first, k0, 0.5f32);
    let mut wanted = rays_for_target(k0, first * gain, alpha, e);
    if let Some(n1) = second {
        // A hard scene: measured again at 4× the rays, fit how fast the noise falls.
        if n1 > 0.0 {
            alpha = ((first / n1).ln() / 4f32.ln()).clamp(0.5, MAX_EXPONENT);
            (noise, k_pilot) = (n1, 4.0 * k0);
            wanted = rays_for_target(k_pilot, n1 * gain, alpha, e);
            // Beyond the pair's rays the denoiser is credited less: a few steps settle it (the
            // credit rises as K^¼, the noise falls at least as K^−½).
            for _ in 0..8 {
                let credited = denoise_gain_at(plan.denoise_gain, wanted / (2.0 * k_pilot));
                wanted = rays_for_target(k_pilot, n1 * credited, alpha, e);
            }
        } else {
            wanted = 4.0 * k0;
        }
    }
    NoiseFit {
        noise,
        k_pilot,
        alpha,
        wanted,
    }
}

/// Step 3 when no pilot can measure anything (no light reaches the texels).
pub(crate) fn keep_rays_unmeasured(config: &BakeConfig, plan: &mut Plan) {
    plan.reasons.push(format!(
        "gathering rays K={}: nothing to measure (no light reaches the texels)",
        config.transport.gather_rays
    ));
}

/// Step 4: light samples, a quarter of the rays (none without emissive surfaces).
pub(crate) fn choose_light_samples(
    config: &mut BakeConfig,
    plan: &mut Plan,
    keep: &Keep,
    emitters: bool,
) {
    if keep.light_samples || !config.technique.is_monte_carlo() {
        return;
    }
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

/// Step 5: the solver, from the memory the stored rows of `texels` would take — Jacobi over
/// f32 rows, over Monte Carlo rows stored as ray counts when only those stay within
/// [`ROW_MEMORY_LIMIT`] (slower sweeps), or the matrix-free gatherer beyond it.
pub(crate) fn choose_solver(texels: usize, config: &mut BakeConfig, plan: &mut Plan, keep: &Keep) {
    if keep.solver {
        return;
    }
    let stored = match config.technique {
        Technique::Stored { .. } => config.technique,
        _ => Technique::DEFAULT,
    };
    let n = texels as f64;
    let bytes = |counts| {
        n * entries_per_texel(stored, n, config.transport.gather_rays as f64)
            * row_entry_bytes(stored, counts)
    };
    let storage = config.transport.row_storage;
    let counts = stored.is_monte_carlo()
        && match storage {
            RowStorage::Auto => bytes(false) > ROW_MEMORY_LIMIT,
            RowStorage::F32 => false,
            RowStorage::Counts => true,
        };
    config.transport.count_rows = counts;
    let rows = bytes(counts);
    let what = match (counts, storage) {
        (true, RowStorage::Counts) => {
            "stored Monte Carlo rows as exact ray counts (about 1 byte per ray; forced by --rows counts)"
        }
        (true, _) => {
            "stored Monte Carlo rows as exact ray counts (about 1 byte per ray; f32 rows would exceed the limit)"
        }
        (false, RowStorage::F32) => "stored f32 rows (forced by --rows f32)",
        (false, _) => "stored f32 rows",
    };
    config.technique = if config.technique.is_monte_carlo() && rows > ROW_MEMORY_LIMIT {
        config.transport.count_rows = false;
        plan.reasons.push(format!(
            "transport matrix-free, solver gather: {what} would take {:.1} GiB (> {:.0} GiB); re-casting rays each bounce needs O(texels) memory",
            rows / (1u64 << 30) as f64,
            ROW_MEMORY_LIMIT / (1u64 << 30) as f64
        ));
        Technique::Gather
    } else {
        // Not Gauss–Seidel on one thread: the output must not depend on the thread count.
        plan.reasons.push(format!(
            "transport {what}: {:.0} MiB (≤ {:.0} GiB); solver jacobi: parallel sweeps, the same result on any number of threads",
            rows / (1u64 << 20) as f64,
            ROW_MEMORY_LIMIT / (1u64 << 30) as f64
        ));
        match config.technique {
            Technique::Stored { form_factors, .. } => {
                Technique::stored(form_factors, RowSolver::Jacobi)
            }
            Technique::Gather => Technique::DEFAULT,
            Technique::Hierarchical => Technique::Hierarchical,
        }
    };
}

/// Step 6: the tolerance, a tenth of the target.
pub(crate) fn choose_tolerance(config: &mut BakeConfig, plan: &mut Plan, keep: &Keep) {
    if keep.tolerance {
        return;
    }
    config.solve.tolerance = (plan.target_error / 10.0).clamp(1e-6, 0.5);
    plan.reasons.push(format!(
        "tolerance {:.1e}: a tenth of the target, so iterating stops once it is below the Monte Carlo error",
        config.solve.tolerance
    ));
}

/// Step 7, when one more bake follows the pilot: fewer rays per texel where the lightmap
/// matters less (see `texel_rays`), from the irradiance of each pilot run, and, from the
/// variance of what each texel's pilot rays returned (`variance`, with `pilot_rays` the rays the
/// final mean already holds per texel), more where the rays disagree most ([`spread_rays`]).
pub(crate) fn choose_texel_rays(
    texels: &Texels,
    pilot: &[&[Vec3]],
    variance: Option<(&[f32], f32)>,
    k: u32,
    plan: &mut Plan,
) {
    let n = texels.len();
    let h = pilot_mean(pilot);
    let (mut rays, reduced) = texel_rays(texels, &h, k);
    let full = k as u64 * n as u64;
    let cast: u64 = rays.iter().map(|&k| k as u64).sum();
    let mut changed = false;
    if reduced.0 + reduced.1 > 0 {
        plan.reasons.push(format!(
            "fewer rays where the lightmap matters less: {} emitter texels (rendered radiance mostly Le) and {} black or unlit texels; the last bake casts {:.1}% fewer gathering rays",
            reduced.0,
            reduced.1,
            100.0 * (full - cast) as f64 / full.max(1) as f64
        ));
        changed = true;
    }
    if let Some((variance, pilot_rays)) = variance
        && let Some(spread) = spread_rays(texels, &h, variance, pilot_rays, k, &mut rays)
    {
        plan.reasons.push(spread.reason());
        changed = true;
    }
    if changed {
        plan.texel_rays = Some(TexelRays(rays));
    }
}

/// Step 3b, after the rays: the resolution error of the density and the prediction that
/// combines it with the noise. Measured at random surface points against a gather there
/// (`gathered`, [`GatheredSample`]) when there is one; otherwise the sampled punctual part
/// ([`PunctualSample`]) and the rest from the pilot's second differences ([`resolution_error`],
/// a lower bound) in quadrature. `pilot` is the last pilot pair's lightmap values.
pub(crate) fn predict_resolution(
    texels: &Texels,
    pilot: [&[Vec3]; 2],
    punctual: Option<&PunctualSample>,
    gathered: Option<&GatheredSample>,
    plan: &mut Plan,
) {
    let n = texels.len();
    let mean: Vec<Vec3> = (0..n).map(|i| (pilot[0][i] + pilot[1][i]) * 0.5).collect();
    let without = without_punctual(pilot, punctual);
    let (square, skip) = resolution_squares(texels, [&without[0], &without[1]]);
    let curved = metrics::weighted_rms_over_mean(&square, &mean, &texels.area, &skip);
    let sampled = punctual.map_or(0.0, |p| p.relative_error());
    let gathered_bounds = gathered
        .map(|g| g.relative_error_bounds())
        .filter(|b| b.0.is_finite());
    let rest = gathered.map(|g| g.rest_error()).filter(|r| r.is_finite());
    let point_punctual = gathered
        .map(|g| g.punctual_error())
        .filter(|r| r.is_finite());
    let r = match gathered_bounds {
        Some((r, _, _)) => r,
        None => curved.hypot(sampled),
    };
    if !r.is_finite() {
        return;
    }
    let parts = ResolutionParts {
        gathered: gathered_bounds,
        rest,
        point_punctual,
        curved,
        sampled,
        border_share: punctual.map_or(0.0, |p| p.border_share()),
    };
    plan.resolution_parts = Some(parts);
    let pct = |x: f32| format!("{:.2}%", x * 100.0);
    let measured = match (gathered_bounds, gathered) {
        (Some((_, lo, hi)), Some(g)) => format!(
            "measured at {} random surface points{}: the pilot's texel values{} read back by \
             bilinear lookup against the light gathered at each point ({} rays and light \
             samples per point and run; the two runs' independent differences multiplied, so \
             neither's noise counts; {}…{} within two standard errors; {:.2}s, {:.1}% of the \
             pilot's rays): emitters, sky and interreflection {} (the pilot's second \
             differences alone saw {}), punctual direct light {} (the exact light at the same \
             points; {} at {} points about the face normals, {:.1}% of those lookups reading a \
             gutter or buried neighbour)",
            g.points.len(),
            if g.reused > 0 {
                format!(
                    " ({} of them the density pilot's, read against the light it gathered \
                     there: no ray cast again)",
                    g.reused
                )
            } else {
                String::new()
            },
            if plan.denoise_gain.is_some() {
                " (denoised, as the final lightmap will be)"
            } else {
                ""
            },
            gathered::GATHER_RAYS + gathered::LIGHT_SAMPLES,
            pct(lo),
            pct(hi),
            plan.resolution_seconds,
            100.0 * g.rays as f64 / plan.pilot_rays.max(1) as f64,
            rest.map_or("—".into(), pct),
            pct(curved),
            point_punctual.map_or("—".into(), pct),
            pct(sampled),
            punctual::POINTS,
            parts.border_share * 100.0,
        ),
        _ => format!(
            "punctual direct light {} (sampled: texel values read back by bilinear lookup at {} \
             random surface points against the exact light there; {:.1}% of those lookups read \
             a gutter or buried neighbour), the rest {} (the pilot's second differences between \
             texel centres; a lower bound: emitter shadow edges narrower than a texel are not in \
             it)",
            pct(sampled),
            punctual::POINTS,
            parts.border_share * 100.0,
            pct(curved),
        ),
    };
    push_prediction(plan, r, &measured);
}

/// Sets the resolution error `r` and says what the prediction is, noise and `r` in
/// quadrature, against the target; `measured` says where `r` comes from.
fn push_prediction(plan: &mut Plan, r: f32, measured: &str) {
    plan.predicted_resolution = Some(r);
    let e = plan.target_error;
    let noise = plan.denoised_noise().unwrap_or(0.0);
    let combined = noise.hypot(r);
    let pct = |x: f32| format!("{:.2}%", x * 100.0);
    let verdict = if combined <= e {
        format!(
            "within the {:.1}% target as far as this estimate sees",
            e * 100.0
        )
    } else {
        format!(
            "ABOVE the {:.1}% target: {}",
            e * 100.0,
            over_target(e, noise, r)
        )
    };
    let after = if plan.denoise_gain.is_some() {
        " (after denoising)"
    } else {
        ""
    };
    plan.reasons.push(format!(
        "prediction {} at random points of the surfaces, as a renderer shows the bake: noise{after} \
         {} and resolution error {} in quadrature — {verdict}. Resolution error {measured}",
        pct(combined),
        pct(noise),
        pct(r),
    ));
}

/// Why a prediction of noise `noise` and resolution error `r` in quadrature is above the
/// target `e`, which part dominates, and about how much more of texels or rays would reach it.
/// Texels: the lookup error falls as `h²` (texel size `h`) where the light curves smoothly and
/// only as `√h` at edges narrower than a texel, so the density a given fall needs lies between
/// those two powers of it. Rays: the noise falls as `1/√K` (the slowest the fit allows).
fn over_target(e: f32, noise: f32, r: f32) -> String {
    let pct = |x: f32| format!("{:.2}%", x * 100.0);
    // Each part's share of the budget once the other is as it is.
    let room = |other: f32| (e * e - other * other).max(0.0).sqrt();
    let density = |need: f32| {
        let fall = r / need;
        format!(
            "×{:.1}…×{:.1} the texel density (×{:.1}…×{:.0} the texels: the first where the \
             light curves smoothly, the second at shadow edges narrower than a texel)",
            fall.sqrt(),
            fall * fall,
            fall,
            fall.powi(4)
        )
    };
    let rays = |need: f32| format!("×{:.1} the rays", (noise / need).powi(2));
    if r >= noise {
        let need_r = room(noise);
        if need_r <= 0.0 {
            return format!(
                "resolution error {} is the larger part, and the noise {} alone exceeds the \
                 target; more rays first ({}), then more texels",
                pct(r),
                pct(noise),
                rays(0.75 * e)
            );
        }
        format!(
            "resolution error {} is the larger part, and more rays cannot lower it; bringing \
             it to {} (beside the noise {}) takes about {}",
            pct(r),
            pct(need_r),
            pct(noise),
            density(need_r)
        )
    } else {
        let need_n = room(r);
        if need_n <= 0.0 {
            return format!(
                "noise {} is the larger part, and the resolution error {} alone exceeds the \
                 target; more texels ({}) and rays",
                pct(noise),
                pct(r),
                density(0.75 * e)
            );
        }
        format!(
            "noise {} is the larger part (the rays are at their cap or the fall was slower \
             than measured); bringing it to {} (beside the resolution error {}) takes about {}",
            pct(noise),
            pct(need_n),
            pct(r),
            rays(need_n)
        )
    }
}

/// The pilot's values without the direct light of punctual lights (measured apart by
/// [`PunctualSample`]), so the second differences see the rest alone.
fn without_punctual(pilot: [&[Vec3]; 2], punctual: Option<&PunctualSample>) -> [Vec<Vec3>; 2] {
    [0, 1].map(|r| match punctual {
        Some(p) => pilot[r]
            .iter()
            .zip(&p.texel[r])
            .map(|(h, d)| *h - *d)
            .collect(),
        None => pilot[r].to_vec(),
    })
}

/// Neighbouring texels in a page whose normals are this close (cos 26°) lie on one smooth
/// surface: their second difference measures the light, not a crease.
const SAME_SURFACE_COS: f32 = 0.9;
/// Mean and mean square of the bilinear lookup's error per unit second difference along one
/// axis, over a texel (`g(t) = 1/24 + t(1−t)/2`, t uniform on [0, 1]; see [`resolution_error`]).
const G_MEAN: f32 = 1.0 / 8.0;
const G_MEAN_SQUARE: f32 = 49.0 / 2880.0;

/// Relative RMS error, over the surfaces' area, of what a renderer reads from the lightmap
/// (bilinear lookup between texel centres) against the light at each point, estimated from
/// two independent bakes of the same texels (`pilot`, the values the lightmap stores).
///
/// **Model.** Along one page axis, with texel size `h` and a light `f` of second derivative
/// `f''`: a texel's value is the mean of `f` over its footprint (its sample points jitter over
/// it), `f(cᵢ) + f''h²/24`; a renderer at `x = cᵢ + t·h`, t ∈ [0, 1], reads the linear
/// interpolation of the two values, and `f` lies `f''h²·t(1−t)/2` below the chord through
/// `f(cᵢ)` and `f(cᵢ₊₁)`. The lookup's error is therefore `D·g(t)` with
/// `g(t) = 1/24 + t(1−t)/2` and `D = f''h²`, which is exactly the second difference
/// `vᵢ₋₁ − 2vᵢ + vᵢ₊₁` of the texel values (for a quadratic; the footprint mean shifts every
/// value alike). Over uniform t: mean `g` = 1/24 + 1/12 = 1/8 (the midpoint alone, point-sampled,
/// would give the textbook h²f''/8 with 1/24 on top for the footprint) and mean `g²` =
/// 1/576 + 1/144 + 1/120 = 49/2880 (RMS 0.130·|D|). In two dimensions a mixed term `xy` is
/// reproduced exactly by bilinear interpolation and by footprint means, so with `Dx`, `Dy` the
/// second differences along x and y and (t, s) uniform over the cell, the mean square error is
/// `49/2880·(Dx² + Dy²) + 2·(1/8)²·Dx·Dy`. No constant is fitted to a scene.
///
/// **Noise.** A second difference of noisy values carries six times a texel's noise variance,
/// which at pilot ray counts would swamp the light's curvature. The two bakes are independent,
/// so the product of their second differences, `D_a·D_b`, estimates `D²` without it (and
/// `(Dx_a·Dy_b + Dx_b·Dy_a)/2` the mixed product): unbiased, though it can be negative where
/// the light is smooth; the area sum is clamped at 0.
///
/// **Where.** A second difference needs both neighbours along an axis: in the same page, valid
/// (not in `Texels::invalid`), on the same smooth surface (`SAME_SURFACE_COS`). A texel with
/// one axis counts it twice (the light assumed as curved across as along); one with neither
/// (a texel-wide strip, a lone texel) is left out, as are the lookups near chart borders that
/// read dilated gutters: the figure covers the chart interiors. Aggregated with
/// [`metrics::weighted_rms_over_mean`] over texel areas against the mean of the two bakes.
/// NaN when no texel has a second difference or the light is black.
#[cfg(test)]
pub(crate) fn resolution_error(texels: &Texels, pilot: [&[Vec3]; 2]) -> f32 {
    let (square, skip) = resolution_squares(texels, pilot);
    let n = texels.len();
    let mean: Vec<Vec3> = (0..n).map(|i| (pilot[0][i] + pilot[1][i]) * 0.5).collect();
    metrics::weighted_rms_over_mean(&square, &mean, &texels.area, &skip)
}

/// Per texel, the expected square of the bilinear lookup's error over its cell (per channel,
/// may be negative where the light is smooth: see [`resolution_error`]), and the texels that
/// have no second difference (ascending).
fn resolution_squares(texels: &Texels, pilot: [&[Vec3]; 2]) -> (Vec<Vec3>, Vec<u32>) {
    let n = texels.len();
    let valid = texels.valid_mask();
    let neighbour = |i: usize, dx: i64, dy: i64| -> Option<usize> {
        let page = texels.page[i] as usize;
        let size = texels.pages[page];
        let [x, y] = texels.xy[i];
        let (x, y) = (x as i64 + dx, y as i64 + dy);
        if x < 0 || y < 0 || x >= size.width as i64 || y >= size.height as i64 {
            return None;
        }
        let j = texels.index[page][(y * size.width as i64 + x) as usize];
        (j != NO_TEXEL
            && valid[j as usize]
            && texels.normal[i].dot(texels.normal[j as usize]) >= SAME_SURFACE_COS)
            .then_some(j as usize)
    };
    let second_difference = |i: usize, dx: i64, dy: i64| -> Option<[Vec3; 2]> {
        let (a, b) = (neighbour(i, -dx, -dy)?, neighbour(i, dx, dy)?);
        Some(pilot.map(|h| h[a] - 2.0 * h[i] + h[b]))
    };
    let mut square = vec![Vec3::ZERO; n];
    let mut skip = Vec::new();
    for i in 0..n {
        let along = if valid[i] {
            (second_difference(i, 1, 0), second_difference(i, 0, 1))
        } else {
            (None, None)
        };
        square[i] = match along {
            (Some([xa, xb]), Some([ya, yb])) => {
                G_MEAN_SQUARE * (xa * xb + ya * yb) + G_MEAN * G_MEAN * (xa * yb + xb * ya)
            }
            (Some([a, b]), None) | (None, Some([a, b])) => 2.0 * G_MEAN_SQUARE * a * b,
            (None, None) => {
                skip.push(i as u32);
                Vec3::ZERO
            }
        };
    }
    (square, skip)
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
pub(crate) const MIN_TEXEL_RAYS: u32 = 16;

/// Per texel, the pilot runs' mean irradiance over the channels.
fn pilot_mean(pilot: &[&[Vec3]]) -> Vec<f32> {
    let n = pilot.first().map_or(0, |h| h.len());
    let runs = pilot.len().max(1) as f32;
    (0..n)
        .map(|i| pilot.iter().map(|h| h[i].element_sum() / 3.0).sum::<f32>() / runs)
        .collect()
}

/// Gathering rays per texel for the final bake, from the pilot's mean irradiance `h`: a texel's
/// lightmap noise reaches the rendered image as `ρH/π` next to its emission `Le`, so its relative
/// error there is the lightmap's times `w = (ρH/π)/(ρH/π + Le)`, and `K·w²` rays keep it level
/// with a plain texel's. Black texels (ρ = 0) and texels the pilot found unlit (below 10⁻³ of
/// the mean) get the minimum. Returns the rays and (emitter, black or unlit) texel counts reduced.
fn texel_rays(texels: &Texels, h: &[f32], k: u32) -> (Vec<u32>, (usize, usize)) {
    let n = texels.len();
    let mean = |v: Vec3| v.element_sum() / 3.0;
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

/// Share of the scene's mean light added to a texel's value where its noise is weighed
/// ([`spread_rays`]), as the point figures floor their relative errors.
const SPREAD_FLOOR: f32 = 0.05;
/// Bounds of a texel's rays ([`spread_rays`], the pilots' and the last bake's together) over
/// the uniform count: a variance from 64 rays a run, even its neighbours', can miss a small
/// bright source.
const SPREAD_RANGE: (f32, f32) = (0.5, 4.0);

/// Half the side of the window [`neighbour_variance`] averages over, in texels.
const SPREAD_RADIUS: i64 = 2;

/// Per texel, the mean per-ray variance of its valid neighbours on the page within
/// [`SPREAD_RADIUS`] on the same surface (normals within 25°, within two texel diagonals of
/// where the page puts them), itself left out; its own where it has none. Its own pilot rays
/// would decide its rays and weigh in its value: a texel whose few rays missed a bright spot
/// reads low in both, and fewer rays would keep more of that low value (measured: the lamp
/// room at `high` 1.30% → 1.43% with its own variance).
fn neighbour_variance(texels: &Texels, variance: &[f32], valid: &[bool]) -> Vec<f32> {
    use rayon::prelude::*;
    (0..texels.len())
        .into_par_iter()
        .map(|i| {
            let reach = 2.0 * (texels.du[i].length() + texels.dv[i].length());
            let surface = (0.9, reach * reach);
            let (mut sum, mut count) = (0.0f64, 0u32);
            texels.for_surface_neighbours(i, SPREAD_RADIUS, valid, surface, |dx, dy, j| {
                if (dx, dy) != (0, 0) {
                    sum += f64::from(variance[j].max(0.0));
                    count += 1;
                }
            });
            match count {
                0 => variance[i].max(0.0),
                c => (sum / f64::from(c)) as f32,
            }
        })
        .collect()
}

/// What [`spread_rays`] did.
#[derive(Clone, Copy, Debug)]
struct Spread {
    texels: usize,
    raised: usize,
    range: (f32, f32),
    rms: f32,
    p95: f32,
}

impl Spread {
    fn reason(&self) -> String {
        format!(
            "rays where they disagree: {} texels' rays ∝ σ/(H + 5% of the mean) (σ the spread of \
             what one of the pilot's rays returned at the texel's neighbours; the least mean \
             square noise relative to the light, floored as the point figures floor it), \
             ×{:.2}…×{:.2} of \
             the uniform count, {} raised, the same rays in all; by the pilot's variances the \
             RMS noise ×{:.2} and the texels' 95th-percentile relative noise ×{:.2} of uniform \
             rays",
            self.texels, self.range.0, self.range.1, self.raised, self.rms, self.p95
        )
    }
}

/// The last bake's rays per texel, moved between texels where the rays the final mean holds
/// (`pilot_rays` already, plus `rays[i]`) lower the error a renderer shows most: a texel whose
/// gathering rays return values of spread `σ` (per-ray variance `variance`, the pilot's) has
/// noise `σ/√K`. The point figures weigh it two ways, the squared noise over the scene's mean
/// (RMS: `K ∝ σ` is best) and relative to the light there, floored at 5% of the mean (p95);
/// `K ∝ σ/(H + floor)` minimises the mean square of the relative noise, what the p95 reads
/// (`K ∝ σ²/(H + floor)²` would even it out, at a cost to the RMS). Measured on the lamp
/// room at `high`, seeds 0–3, against 65,536-path references (7 December): p95 2.01% with
/// `K ∝ σ/√(H + floor)` (the form first taken, the squared noise weighed by one over the
/// light), 1.85% with this one, 1.84% with `σ/(H + floor)^1.5`; the point error 1.29%, 1.28%,
/// 1.37% on average; the same time.
/// Within [`SPREAD_RANGE`] of the uniform count and never below the pilots' rays plus
/// [`MIN_TEXEL_RAYS`]; the total stays. Only texels the other rules left at `k` (not
/// emitters, black or unlit) and valid ones move. `None` when nothing would.
fn spread_rays(
    texels: &Texels,
    h: &[f32],
    variance: &[f32],
    pilot_rays: f32,
    k: u32,
    rays: &mut [u32],
) -> Option<Spread> {
    let n = texels.len();
    if variance.len() != n || h.len() != n {
        return None;
    }
    let valid = texels.valid_mask();
    let h: Vec<f32> = h.iter().map(|&h| h.max(0.0)).collect();
    let kept: Vec<usize> = (0..n).filter(|&i| valid[i]).collect();
    let mean_h = kept.iter().map(|&i| f64::from(h[i])).sum::<f64>() / kept.len().max(1) as f64;
    let floor = SPREAD_FLOOR * mean_h as f32;
    let moved: Vec<usize> = kept.into_iter().filter(|&i| rays[i] == k).collect();
    if moved.len() < 2 || floor <= 0.0 {
        return None;
    }
    let spread = neighbour_variance(texels, variance, &valid);
    let mut share: Vec<f32> = moved
        .iter()
        .map(|&i| spread[i].sqrt() / (h[i] + floor))
        .collect();
    let mean =
        |share: &[f32]| share.iter().map(|&s| f64::from(s)).sum::<f64>() / share.len() as f64;
    let total = pilot_rays + k as f32;
    let least = MIN_TEXEL_RAYS.min(k);
    // A texel keeps the pilots' rays and gets at least `least` more.
    let lowest = SPREAD_RANGE.0.max((pilot_rays + least as f32) / total);
    // Normalise to mean 1 within the range: a few rounds settle the clamped texels.
    for _ in 0..6 {
        let m = mean(&share);
        if m <= 0.0 || !m.is_finite() {
            return None;
        }
        for s in &mut share {
            *s = (*s / m as f32).clamp(lowest, SPREAD_RANGE.1);
        }
    }
    let (mut raised, mut range) = (0, (f32::INFINITY, 0.0f32));
    // The noise by the pilot's variances, before and after, for the reason.
    let (mut before, mut after) = (0.0f64, 0.0f64);
    let (mut rel_before, mut rel_after) = (Vec::new(), Vec::new());
    for (&i, &s) in moved.iter().zip(&share) {
        let ki = ((total * s - pilot_rays).round().max(0.0) as u32).clamp(least, RAYS_RANGE.1);
        raised += usize::from(ki > k);
        rays[i] = ki;
        let t = pilot_rays + ki as f32;
        range = (range.0.min(t / total), range.1.max(t / total));
        let v = spread[i];
        before += f64::from(v / total);
        after += f64::from(v / t);
        let light = h[i] + floor;
        rel_before.push((v / total).sqrt() / light);
        rel_after.push((v / t).sqrt() / light);
    }
    let [p95_before] = metrics::percentiles(&rel_before, [0.95]);
    let [p95_after] = metrics::percentiles(&rel_after, [0.95]);
    Some(Spread {
        texels: moved.len(),
        raised,
        range,
        rms: (after / before.max(f64::MIN_POSITIVE)).sqrt() as f32,
        p95: p95_after / p95_before.max(f32::MIN_POSITIVE),
    })
}

/// A large bake (its f32 rows' estimated peak above [`LARGE_BAKE_BYTES`]) stores its Monte
/// Carlo rows as ray counts when f32 rows would take it above this many bytes per texel.
pub(crate) const MAX_BYTES_PER_TEXEL: f64 = 2048.0;
/// See [`MAX_BYTES_PER_TEXEL`]: below this, a bake's peak is mostly what every bake holds.
pub(crate) const LARGE_BAKE_BYTES: f64 = 512.0 * 1024.0 * 1024.0;

/// Step 5b, once the rays are chosen: how stored Monte Carlo rows are held (forced by
/// `config.transport.row_storage`, `--rows`, or chosen here) — f32 weights
/// (fastest sweeps) when their estimated peak `f32_rows` fits `limit`, else exact ray counts
/// (`count_rows`: the same output, slower sweeps) when theirs does; left as is when
/// neither fits ([`fit_memory`] may then switch to the gather solver). A large bake of
/// `texels` texels whose f32 rows would pass `MAX_BYTES_PER_TEXEL` takes counts too: the
/// same bytes out, 4–6× less row memory, and whole bakes measured within ±4% of f32's time
/// (the sweeps are a small part next to casting the rays). Sets `config.transport.count_rows`;
/// returns the reason, with both estimates.
pub fn choose_row_storage(
    f32_rows: &MemoryEstimate,
    count_rows: &MemoryEstimate,
    limit: f64,
    texels: f64,
    config: &mut BakeConfig,
) -> Option<String> {
    let Technique::Stored {
        form_factors: FormFactors::MonteCarlo,
        ..
    } = config.technique
    else {
        return None;
    };
    let (f32_peak, counts_peak) = (
        format_bytes(f32_rows.total()),
        format_bytes(count_rows.total()),
    );
    let limit_text = format_bytes(limit);
    match config.transport.row_storage {
        RowStorage::F32 => {
            config.transport.count_rows = false;
            return Some(format!(
                "rows f32, forced by --rows f32: estimated peak {f32_peak} (as ray counts {counts_peak}); limit {limit_text}"
            ));
        }
        RowStorage::Counts => {
            config.transport.count_rows = true;
            return Some(format!(
                "rows as exact ray counts, forced by --rows counts: estimated peak {counts_peak} (with f32 rows {f32_peak}); limit {limit_text}"
            ));
        }
        RowStorage::Auto => {}
    }
    if config.transport.count_rows {
        return Some(format!(
            "rows as ray counts (chosen before; estimated peak {counts_peak}, with f32 rows {f32_peak}; limit {limit_text})"
        ));
    }
    let per_texel = f32_rows.total() / texels.max(1.0);
    if f32_rows.total() > LARGE_BAKE_BYTES
        && per_texel > MAX_BYTES_PER_TEXEL
        && count_rows.total() < f32_rows.total()
        && count_rows.total() <= limit
    {
        config.transport.count_rows = true;
        return Some(format!(
            "rows as exact ray counts: with f32 rows the estimated peak {f32_peak} is {:.1} KiB \
             per texel, above {:.0} KiB for a bake this large; with counts {counts_peak} (the same \
             output; slower sweeps)",
            per_texel / 1024.0,
            MAX_BYTES_PER_TEXEL / 1024.0
        ));
    }
    if f32_rows.total() <= limit {
        return Some(format!(
            "rows f32: estimated peak {f32_peak} within the memory limit {limit_text} (as ray counts {counts_peak}: smaller, slower sweeps)"
        ));
    }
    if count_rows.total() > limit {
        return None;
    }
    config.transport.count_rows = true;
    Some(format!(
        "rows as exact ray counts: the estimated peak with f32 rows {f32_peak} exceeds the memory limit {limit_text}, with counts {counts_peak} fits (the same output; slower sweeps)"
    ))
}

/// Step 5c, once the rays are chosen: when the bake's estimated peak (`stored`) exceeds
/// `limit` and the matrix-free gather solver's (`gather`) does not, switch to it (unless the
/// user fixed the solver or the method is not Monte Carlo). Returns the switch's message, for a
/// warning; the caller refuses what still does not fit.
pub fn fit_memory(
    stored: &MemoryEstimate,
    gather: &MemoryEstimate,
    limit: f64,
    config: &mut BakeConfig,
    plan: &mut Plan,
    keep: &Keep,
) -> Option<String> {
    let switchable =
        !keep.solver && config.technique.is_monte_carlo() && config.technique != Technique::Gather;
    if stored.total() <= limit || !switchable || gather.total() > limit {
        plan.reasons.push(format!(
            "memory: estimated peak {} within the limit {}",
            stored.describe(),
            format_bytes(limit)
        ));
        return None;
    }
    config.technique = Technique::Gather;
    // The gatherer casts the same rays at every texel.
    plan.texel_rays = None;
    let message = format!(
        "solver gather: the estimated peak {} with stored rows exceeds the memory limit {}; \
         the matrix-free gather solver needs about {} (it casts its rays again every bounce: \
         slower; the same rays at every texel)",
        stored.describe(),
        format_bytes(limit),
        format_bytes(gather.total())
    );
    plan.reasons.push(message.clone());
    plan.finish(config);
    Some(message)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rounding_has_four_steps_per_octave() {
        let r: Vec<u32> = [1.0, 7.5, 8.0, 8.5, 75.0, 100.0, 128.0, 129.0]
            .into_iter()
            .map(round_up_quarter_octave)
            .collect();
        assert_eq!(r, [1, 8, 8, 10, 80, 112, 128, 160]);
    }

    #[test]
    fn the_predicted_noise_is_that_of_the_rays_cast() {
        let mut plan = Plan {
            target_error: 0.04,
            ..Plan::default()
        };
        // 4% at K=16, aiming at 3%: the pilot pair (2 × 16) is the bake; its noise is that of
        // two independent runs, 4%/√2.
        let mut config = BakeConfig::default();
        assert!(choose_rays(&mut config, &mut plan, 0.04, None, 0));
        assert_eq!(plan.total_rays, Some(32));
        let pair = 0.04 / 2f32.sqrt();
        assert!((plan.predicted_noise.unwrap() - pair).abs() < 1e-6);
        // 5.9% at K=16: the pair (4.17%) and one more run; with 1/√K every ray counts alike,
        // so the mean of 32 + K rays has 5.9%·√(16/(32 + K)) ≤ 3% once K ≥ 29.9: 32 on
        // quarter-octave steps (28 leaves 3.05%).
        assert!(!choose_rays(&mut config, &mut plan, 0.059, None, 0));
        assert_eq!(plan.total_rays, Some(64));
        let at_64 = 0.059 * (16.0f32 / 64.0).sqrt();
        assert!((plan.predicted_noise.unwrap() - at_64).abs() < 1e-6);
        // The denoiser's measured gain lowers what the rays must reach: ×0.5 leaves the
        // pair's 4.17% at 2.09% after denoising, within 3%: the pair is the bake.
        plan.denoise_gain = Some(0.5);
        assert!(choose_rays(&mut config, &mut plan, 0.059, None, 0));
        assert_eq!(plan.total_rays, Some(32));
        // A second pilot at 64 rays falling as K^−0.75 (16 → 64: 8% → 2.83%): the pair's mean
        // is two independent runs, 2.83%/√2 = 2.0%, not one run of 128 rays (1.68%).
        plan.denoise_gain = None;
        plan.target_error = 0.02;
        assert!(!choose_rays(
            &mut config,
            &mut plan,
            0.08,
            Some(0.08 / 4f32.powf(0.75)),
            0
        ));
        // One more run brings the mean to the aim (75% of 2%), and its noise is that of the
        // runs averaged: above what one run of all the rays would have.
        let n64 = 0.08 / 4f32.powf(0.75);
        let predicted = plan.predicted_noise.unwrap();
        let total = plan.total_rays.unwrap() as f32;
        assert_eq!(total, 128.0 + config.transport.gather_rays as f32);
        assert!(predicted <= 0.75 * 0.02, "{predicted}");
        assert!(predicted > n64 * (64.0 / total).powf(0.75), "{predicted}");
        // The first pair (16 rays a run) averaged in beside the second: its 32 rays are in
        // the total, the mean's noise is lower for the same further run, and the run that
        // completes it needs no more rays than without it.
        let without = (config.transport.gather_rays, predicted);
        assert!(!choose_rays(&mut config, &mut plan, 0.08, Some(n64), 16));
        assert!(config.transport.gather_rays <= without.0);
        assert_eq!(plan.total_rays.unwrap(), 160 + config.transport.gather_rays);
        // Each 16-ray run (8% noise, falling as K^−0.75) weighs as 8 rays of a 1/K run: its
        // inverse variance beside the 64-ray runs'. At the same further rays the first pair
        // lowers the mean's noise.
        let we = plan.earlier_weight.expect("a weight for the first pair");
        assert!((we - 8.0).abs() < 1e-4, "{we}");
        let k = config.transport.gather_rays as f32;
        let at = |we: f32, k: f32| {
            let sum = 128.0 + 2.0 * we + k;
            let run = |r: f32| 0.08 * (16.0 / r).powf(0.75);
            let first = 2.0 * (we / sum * 0.08).powi(2);
            (2.0 * (64.0 / sum * n64).powi(2) + first + (k / sum * run(k)).powi(2)).sqrt()
        };
        assert!((plan.predicted_noise.unwrap() - at(8.0, k)).abs() < 1e-5);
        assert!(at(8.0, k) < at(0.0, k));
    }

    #[test]
    fn the_denoiser_is_credited_less_as_rays_go_beyond_the_pair_that_measured_it() {
        // The gain holds at the pair's rays and rises as the fourth root of the rays beyond.
        assert_eq!(denoise_gain_at(None, 4.0), 1.0);
        assert_eq!(denoise_gain_at(Some(0.5), 1.0), 0.5);
        assert_eq!(denoise_gain_at(Some(0.5), 0.5), 0.5);
        assert!((denoise_gain_at(Some(0.5), 16.0) - 1.0).abs() < 1e-6);
        assert_eq!(denoise_gain_at(Some(0.8), 16.0), 1.0);
        let at_4 = denoise_gain_at(Some(0.5), 4.0);
        assert!((at_4 - 0.5 * 2f32.sqrt()).abs() < 1e-6, "{at_4}");

        // A hard scene (8% at K=16, 2.83% at K=64, falling as K^−0.75) aiming at 2%: the pair
        // alone (2.0% before denoising) is the bake when the denoiser halves its noise...
        let n64 = 0.08 / 4f32.powf(0.75);
        let mut plan = Plan {
            target_error: 0.02,
            denoise_gain: Some(0.5),
            ..Plan::default()
        };
        let mut config = BakeConfig::default();
        assert!(choose_rays(&mut config, &mut plan, 0.08, Some(n64), 0));
        assert_eq!(plan.denoise_gain, Some(0.5));
        // ...but where one more run is needed, the gain credited is the one at the bake's rays,
        // and the rays bring the noise so credited to the aim: more than crediting the
        // pair's gain at any rays would ask for.
        plan.target_error = 0.01;
        plan.denoise_gain = Some(0.5);
        assert!(!choose_rays(&mut config, &mut plan, 0.08, Some(n64), 0));
        let total = plan.total_rays.unwrap() as f32;
        let credited = plan.denoise_gain.unwrap();
        assert!((credited - denoise_gain_at(Some(0.5), total / 128.0)).abs() < 1e-6);
        assert!(credited > 0.5);
        let after = plan.denoised_noise().unwrap();
        assert!(after <= 0.75 * 0.01, "{after}");
        let before = plan.predicted_noise.unwrap();
        assert!(before * 0.5 < 0.75 * 0.01 * 0.9, "{before}");
    }

    /// A `w × h` page fully covered by texels facing +z, of unit area, lit by `f(x, y)` at the
    /// texel centres; returns the texels and their values.
    fn page(w: u32, h: u32, f: impl Fn(f32, f32) -> f32) -> (Texels, Vec<Vec3>) {
        let mut t = Texels {
            pages: vec![crate::atlas::PageSize {
                width: w,
                height: h,
            }],
            index: vec![(0..w * h).collect()],
            ..Texels::default()
        };
        let mut values = Vec::new();
        for y in 0..h {
            for x in 0..w {
                t.position.push(Vec3::new(x as f32, y as f32, 0.0));
                t.xy.push([x, y]);
                t.page.push(0);
                t.normal.push(Vec3::Z);
                t.area.push(1.0);
                values.push(Vec3::splat(f(x as f32, y as f32)));
            }
        }
        (t, values)
    }

    /// Rays go where a texel's rays disagree (`spread_rays`), read from its neighbours: four
    /// times the per-ray variance at the same light is twice the rays, twice the light at the
    /// same variance ×1/√2 of them (but for the floor); the total stays, and texels the other rules set (here one at
    /// the least) or that are buried keep theirs.
    #[test]
    fn rays_follow_the_spread_of_what_they_return_at_the_same_total() {
        // Columns 0–3 variance 1, columns 4–7 variance 4; rows 0–1 lit 1, rows 2–3 lit 1.5.
        let (w, k, pilot_rays) = (8u32, 100, 20.0);
        let (mut t, h) = page(w, 4, |_, y| if y < 2.0 { 1.0 } else { 1.5 });
        t.du = vec![Vec3::X; t.len()];
        t.dv = vec![Vec3::Y; t.len()];
        let id = |x: u32, y: u32| (y * w + x) as usize;
        t.invalid = vec![id(4, 1) as u32];
        let variance: Vec<f32> = (0..t.len())
            .map(|i| if i as u32 % w < 4 { 1.0 } else { 4.0 })
            .collect();
        let mut rays = vec![k; t.len()];
        rays[id(0, 0)] = MIN_TEXEL_RAYS;
        let spread =
            spread_rays(&t, &pilot_mean(&[&h]), &variance, pilot_rays, k, &mut rays).unwrap();
        assert_eq!(rays[id(0, 0)], MIN_TEXEL_RAYS, "set by another rule");
        assert_eq!(rays[id(4, 1)], k, "buried");
        assert_eq!(spread.texels, 30);
        let total = |x, y| pilot_rays + rays[id(x, y)] as f32;
        let near = |a: f32, b: f32| (a / b - 1.0).abs() < 0.02;
        assert!(near(total(7, 0), 2.0 * total(1, 0)), "{rays:?}");
        // Rays as one over the light (floored): the relative noise's mean square is least.
        let floor = SPREAD_FLOOR * (15.0 + 16.0 * 1.5) / 31.0;
        let lit = (1.0 + floor) / (1.5 + floor);
        assert!(near(total(1, 3), lit * total(1, 0)), "{rays:?}");
        let moved = (0..t.len()).filter(|&i| i != id(0, 0) && i != id(4, 1));
        let cast: u32 = moved.map(|i| rays[i]).sum();
        assert!((cast as f32 / (30 * k) as f32 - 1.0).abs() < 0.01, "{cast}");
        assert!(spread.rms < 1.0 && spread.p95 < 1.0, "{spread:?}");
        // No spread measured anywhere: nothing to move.
        let mut rays = vec![k; t.len()];
        let none = vec![0.0; t.len()];
        assert!(spread_rays(&t, &pilot_mean(&[&h]), &none, pilot_rays, k, &mut rays).is_none());
    }

    #[test]
    fn a_linear_ramp_has_no_resolution_error() {
        let (t, v) = page(7, 5, |x, y| 1.0 + 0.25 * x - 0.125 * y);
        assert!(resolution_error(&t, [&v, &v]) < 1e-6);
        // Noise in one run only has no counterpart in the other: it does not count.
        let noisy: Vec<Vec3> = v
            .iter()
            .enumerate()
            .map(|(i, v)| *v + Vec3::splat(if i % 2 == 0 { 0.2 } else { -0.2 }))
            .collect();
        assert!(resolution_error(&t, [&noisy, &v]) < 1e-6);
    }

    /// The factors of the model, checked by integrating the lookup's error numerically: texel
    /// values are footprint means of `f = x²` (x in texels, so D = 2), the lookup interpolates
    /// them linearly between centres, and the mean and mean square of its error over a cell
    /// are `D/8` and `49/2880·D²`.
    #[test]
    fn bilinear_error_factors_match_a_numerical_integral() {
        let f = |x: f64| x * x;
        let texel = |c: f64| c * c + 1.0 / 12.0; // ∫ x² over [c − ½, c + ½]
        let steps = 100_000;
        let (mut mean, mut square) = (0.0f64, 0.0f64);
        for k in 0..steps {
            let t = (k as f64 + 0.5) / steps as f64;
            let e = texel(0.0) * (1.0 - t) + texel(1.0) * t - f(t);
            mean += e / steps as f64;
            square += e * e / steps as f64;
        }
        assert!((mean - 2.0 * G_MEAN as f64).abs() < 1e-6, "{mean}");
        assert!(
            (square - 4.0 * G_MEAN_SQUARE as f64).abs() < 1e-6,
            "{square}"
        );
    }

    #[test]
    fn a_quadratic_has_the_analytic_resolution_error() {
        // One row: the inner texels have the x axis only (counted twice), D = 2k everywhere.
        let k = 0.01;
        let (t, v) = page(9, 1, |x, _| 1.0 + k * x * x);
        let inner: f32 = (1..8).map(|x| 1.0 + k * (x * x) as f32).sum::<f32>() / 7.0;
        let expected = (2.0 * G_MEAN_SQUARE).sqrt() * 2.0 * k / inner;
        let r = resolution_error(&t, [&v, &v]);
        assert!((r - expected).abs() < 1e-3 * expected, "{r} vs {expected}");

        // Both axes curved alike: the centre of a 3×3 page has D along x and y (mean square
        // (2·49/2880 + 2/64)·D²), the middles of its sides D along one axis (2·49/2880·D²),
        // corners none.
        let (mut t, v) = page(3, 3, |x, y| 1.0 + k * (x * x + y * y));
        let d2 = (2.0 * k) * (2.0 * k);
        let centre = 2.0 * G_MEAN_SQUARE + 2.0 * G_MEAN * G_MEAN;
        let ms = (centre + 4.0 * 2.0 * G_MEAN_SQUARE) * d2 / 5.0;
        let mean = [1, 3, 4, 5, 7].map(|i| v[i].x).iter().sum::<f32>() / 5.0;
        let r = resolution_error(&t, [&v, &v]);
        assert!((r - ms.sqrt() / mean).abs() < 1e-3 * r, "{r}");
        // Rows whose normals differ are different surfaces: no second difference across them
        // (the middle of each row keeps its own along x).
        for i in [0, 1, 2, 6, 7, 8] {
            t.normal[i] = Vec3::X;
        }
        let one_axis = (2.0 * G_MEAN_SQUARE).sqrt() * 2.0 * k;
        let mean = [1, 4, 7].map(|i| v[i].x).iter().sum::<f32>() / 3.0;
        let r = resolution_error(&t, [&v, &v]);
        assert!((r - one_axis / mean).abs() < 1e-3 * r, "{r}");
        // Invalid texels are no neighbours either: only the centre is left.
        t.normal = vec![Vec3::Z; 9];
        t.invalid = vec![0, 1, 2, 6, 7, 8];
        let r = resolution_error(&t, [&v, &v]);
        assert!((r - one_axis / v[4].x).abs() < 1e-3 * r, "{r}");
    }

    #[test]
    fn budget_scales_with_density() {
        assert_eq!(texel_budget(16.0), (4096.0, 262_144.0));
        assert_eq!(texel_budget(32.0), (16_384.0, 1_048_576.0));
    }
}
