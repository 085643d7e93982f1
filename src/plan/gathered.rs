//! The resolution error of all the light, sampled at random surface points against a gather
//! there: what the second differences ([`super::resolution_error`]) cannot see on scenes lit by
//! emitters and interreflection.
//!
//! [`super::PunctualSample`] compares bilinear lookups with the exact punctual light at random
//! points. Emitters are area lights and interreflection has no closed form, but at a point both
//! can be *estimated* the way transport estimates them at a texel — cosine-distributed gathering
//! rays that return the reflected radiosity `ρ_j·H_j` of the texel they hit (the pilot's solved
//! `H`), emitter light samples combined with the rays' emitter hits by the power heuristic, the
//! sky through the rays that escape — only at the point itself rather than over a texel's
//! footprint, about the surface's shading normal (as the point yardstick and renderers shade).
//! The lookup of the pilot's texel values minus that estimate is the error a renderer shows
//! there, apart from the light's second bounce at texel resolution (a second-order effect).
//!
//! **Punctual lights apart.** Their direct light is exact at a point (one shadow ray per
//! light), so its part is each run's punctual light at the texels (the [`PunctualSample`]'s)
//! read back against the exact light there, about the shading normal, the two runs' errors
//! multiplied as below. The gather covers the rest (each run's lookup less the punctual
//! sample's value for that run: its own, or, when a sample taken on the same atlas with an
//! earlier pair is read again, that pair's run — still independent of the other factor, so
//! the product stays unbiased, only noisier), and the two mean squares add (independent
//! errors, as noise and resolution error are).
//!
//! **Noise out.** Both sides of the rest are noisy: the pilot's texels (K = 16) and the
//! point's own gather. Each of the pilot's two independent runs gives its own difference `d_a`, `d_b` (its
//! texels against a gather through its own solution, with independent rays), so
//! `E[d_a·d_b] = (E d)²`: the mean of the products estimates the mean square lookup error
//! without either noise (it can be negative at a point; only the mean is read). Its standard
//! error is kept ([`GatheredSample::relative_error_bounds`]).
//!
//! **Points** are drawn area-weighted over the scene's triangles; those nobody sees (a face
//! looking into geometry, the point yardstick's probe test) or whose texel is buried are left
//! out.
//!
//! **Gathered where the error is.** The mean square is ruled by few points: on the furnished
//! interior the 20 largest products of 40,000 held half of it, every one of them on a texel
//! whose light steps sharply to a neighbour's (a contact, a shadow edge, a moved sample point),
//! so how many landed there moved the estimate by ±24% between seeds, and the plan's texels by
//! 2×. So each drawn point's lookup is read first (no ray) and its rays are cast with
//! probability `a = step/step₀` within [[`MIN_ACCEPT`], 1]: `step` the largest product of the
//! two runs' differences between a texel its lookup reads and a 4-neighbour (unbiased for the
//! squared step of the light there, so noise alone leaves it near zero), `step₀` the step only
//! [`STEEP_AREA`] of the valid texels' area exceeds. A gathered point weighs `1/a` (its
//! Horvitz–Thompson weight) and every mean over the points is the weighted mean. On the
//! interior's pilot pairs (offline, from two seeds' uniform samples) this casts rays at 35% of
//! the drawn points for 1.04× the variance: the same rays measure the mean square with 0.37×
//! the variance. The precision the sample stops at ([`PRECISION`]) was halved with it (its
//! standard error within 10% of the mean square, not 20%); the interior's sample spends its
//! whole budget either way.
//!
//! **Cost.** Per gathered point, 16 probe rays, 2 runs × ([`GATHER_RAYS`] + [`LIGHT_SAMPLES`])
//! and one shadow ray per punctual light. The sample casts the rays of one batch's gathered
//! points at least, more while the estimate is not precise and the sample has cast less than
//! its budget (the bake gives it half the pilot's rays). A batch is what the budget pays for,
//! within [`MIN_BATCH`]..=[`BATCH`] points ([`batch_size`]): a first batch of 4096 whatever the
//! budget cost as much as a sub-second bake (the Cornell box at `draft` asks 285 points' rays;
//! 0.16–0.20 s → 0.09–0.13 s with the same plan, the guide's "The sample's first batch"). 9%
//! of the furnished interior's draft bake and 4% of its medium one, where the budget pays for
//! full batches.
//!
//! **Gathered once.** A point's light does not depend on the atlas its lookup reads (apart
//! from the second bounce at the gathering run's texel resolution), so the sample on the final
//! atlas draws the density pilot's points again, gathers those it gathered (with the same
//! probabilities, so the same weights) and reads its own pair's lookups against the light
//! the density pilot gathered there ([`Runs::reuse`], [`PointLight`]): no ray, and
//! `E[d_a·d_b]` stays the squared bias, each run's lookup being independent of the other run's
//! gather. Only points past those, while the sample is not precise and its budget holds a
//! whole batch, are gathered afresh.

use std::f32::consts::PI;

use glam::Vec3;

use super::punctual::{PunctualSample, bilinear};
use crate::Result;
use crate::lights::{Emitters, punctual_irradiance};
use crate::sampling::{self, Rng, cosine_hemisphere, frame, hammersley, power_weight};
use crate::scene::Scene;
use crate::shard::{self, Packed, Shards, bits};
use crate::texels::validity::{self, MAX_BACK, PROBE_RAYS};
use crate::texels::{NO_TEXEL, RayEnd, Texels};
use crate::trace::Tracer;

/// Random surface points are drawn in batches of this many (fewer on a small scene: as many
/// as the budget's rays gather, but at least [`MIN_BATCH`]) ...
pub(crate) const BATCH: usize = 4096;
/// ... the least batch: what the first batch draws whatever the budget.
pub(crate) const MIN_BATCH: usize = 1024;
/// ... until the mean square's two standard errors are within this share of it ...
pub(crate) const PRECISION: f64 = 0.2;
/// ... or the error is clearly small next to the target (its upper bound below this share of
/// it), or the sample's rays exceed its budget (the bake passes half the pilot's; the first
/// batch is gathered whatever the budget), or this many points have been drawn (most of
/// them read, not gathered). Stopping once the upper bound is below the room the target leaves
/// beside the noise (0.66 of it) was tried: the same bakes on the six small fixtures, with less
/// planning (two rooms at `draft` 18% → 8% of the bake), but the furnished interior's first
/// batch at `medium` had not yet met the heavy tail (a few contact points hold half the mean
/// square), so nothing was raised and it read 4.90% against its 4% target (3.31% before).
pub(crate) const SMALL: f32 = 0.25;
pub(crate) const MAX_POINTS: usize = 262_144;
/// Gathering rays per point and run (the pilot's own [`super::PILOT_RAYS`] twice over: the
/// point's noise then weighs less than the pilot texels' in the products' variance). Half
/// (16 rays and 4 light samples, 41% fewer rays a point) was tried on 7 December on all 21
/// corpus bakes: the noisier products drew more points and moved plans both ways — the Cornell
/// box at `high` raised (1.07 → 1.73 s, 1.32% → 1.01%), the interior at `high` 854 → 967 MB
/// (p95 2.4% → 2.6%), planning's share up on the spot scene at `medium` and `high` (17% → 28%,
/// 14% → 23%) and two rooms at `medium` (9% → 15%), down on a few `draft` bakes; not taken.
pub(crate) const GATHER_RAYS: u32 = 32;
/// Emitter light samples per point and run (a quarter of the rays, as the bake).
pub(crate) const LIGHT_SAMPLES: u32 = 8;
/// A drawn point on the steepest light (the top `STEEP_AREA` of the surface area by the step
/// to a neighbour texel) is always gathered; elsewhere in proportion to its step, but never
/// below `MIN_ACCEPT` (a step the pilot's noise hid weighs at most 1/`MIN_ACCEPT`).
pub(crate) const STEEP_AREA: f64 = 0.05;
pub(crate) const MIN_ACCEPT: f32 = 0.25;
/// Mixed into the seed: these streams differ from transport's, the punctual sample's and the
/// point yardstick's.
const SALT: u64 = 0x6A7E_5EED_0F90_1275;

/// One sampled point's squared lookup errors (means over channels).
#[derive(Clone, Copy, Debug)]
pub(crate) struct GatheredPoint {
    /// The scene triangle the point lies on.
    pub(crate) triangle: u32,
    /// `d_a·d_b` of the light other than punctual direct light (emitters, sky,
    /// interreflection): the lookup of each run's values less the punctual sample's for it,
    /// against the gather through that run. An unbiased estimate of its squared lookup error.
    pub(crate) rest_square: f32,
    /// `p_a·p_b` of the punctual direct light: each run's punctual light at the texels (the
    /// punctual sample's) looked up, against the exact light about the shading normal. An
    /// unbiased estimate of its squared lookup error: the footprint sampling's noise is
    /// independent between the runs.
    pub(crate) punctual_square: f32,
    /// The bilinear lookup of the two runs' mean (what a relative error divides by).
    pub(crate) total: f32,
    /// Half the squared difference of the two runs' lookups: an unbiased estimate of one run's
    /// noise as a renderer reads it (four texels blended, each point weighed by area).
    pub(crate) noise_square: f32,
    /// One over the probability the point was gathered with (see the module docs).
    pub(crate) weight: f32,
}

/// What a drawn point's draw found that no atlas changes: whether anybody sees it and the
/// light gathered there through each run. A later sample of the same scene on another atlas
/// (the final one, after the density pilot's) reads its own pair's lookups against these
/// gathers rather than gathering again ([`Runs::reuse`]). Each holds `accept`, the probability
/// that sample gathered the point with (its stream's draw `u` fell below it exactly when the
/// light was gathered or the probe test run; 0 when it never read the point): a later sample
/// keeps that probability rather than its own, so it gathers the same points, reads their
/// light without a ray and weighs them alike (any probability fixed before the point's light is
/// known keeps the weighted mean unbiased).
#[derive(Clone, Copy, Debug)]
pub(crate) enum PointLight {
    /// The non-punctual light gathered through each run about the shading normal (`rest`), and
    /// the exact punctual light there (zero when the sample leaves punctual light out).
    Gathered {
        rest: [Vec3; 2],
        exact: Vec3,
        accept: f32,
    },
    /// Nobody sees the point (the probe test): no atlas changes that.
    LeftOut { accept: f32 },
    /// Nothing was gathered (its lookup found no texel on that atlas, it was not drawn for
    /// gathering, or it is degenerate): draw it again.
    Redraw { accept: f32 },
}

impl PointLight {
    /// Nothing known.
    pub(crate) const NONE: PointLight = PointLight::Redraw { accept: 0.0 };

    fn accept(&self) -> f32 {
        match *self {
            PointLight::Gathered { accept, .. }
            | PointLight::LeftOut { accept }
            | PointLight::Redraw { accept } => accept,
        }
    }
}

/// What became of one drawn point.
enum Drawn {
    /// Kept, with its light for a later sample, and whether its light was gathered here
    /// (rays cast) or read from an earlier sample's.
    Kept(GatheredPoint, PointLight, bool),
    /// On this triangle, where nobody sees it, with its weight (1 on a buried texel, which
    /// costs no ray; one over the probe test's probability otherwise), and with whether an
    /// atlas had a say (a buried texel) or the geometry alone (the probe test).
    Unseen(u32, f32, PointLight),
    /// Read but not gathered.
    Passed(PointLight),
    /// Degenerate or not finite.
    Skipped,
}

impl Packed for Drawn {
    const FLOATS: usize = 18;
    fn pack(&self, out: &mut Vec<f32>) {
        let light = |l: &PointLight, out: &mut Vec<f32>| match *l {
            PointLight::Gathered {
                rest,
                exact,
                accept,
            } => {
                out.extend([1.0, accept]);
                out.extend(rest[0].to_array());
                out.extend(rest[1].to_array());
                out.extend(exact.to_array());
            }
            PointLight::LeftOut { accept } => out.extend([2.0, accept].into_iter().chain([0.0; 9])),
            PointLight::Redraw { accept } => out.extend([0.0, accept].into_iter().chain([0.0; 9])),
        };
        match self {
            Drawn::Kept(p, l, fresh) => {
                out.extend([
                    if *fresh { 1.0 } else { 3.0 },
                    bits(p.triangle),
                    p.rest_square,
                    p.punctual_square,
                    p.total,
                    p.noise_square,
                    p.weight,
                ]);
                light(l, out);
            }
            Drawn::Unseen(t, weight, l) => {
                out.extend([2.0, bits(*t), 0.0, 0.0, 0.0, 0.0, *weight]);
                light(l, out);
            }
            Drawn::Passed(l) => {
                out.extend([4.0; 1].into_iter().chain([0.0; 6]));
                light(l, out);
            }
            Drawn::Skipped => out.extend([0.0; 18]),
        }
    }
    fn unpack(v: &[f32]) -> Self {
        let light = |w: &[f32]| match w[0] as u32 {
            1 => PointLight::Gathered {
                rest: [Vec3::from_slice(&w[2..5]), Vec3::from_slice(&w[5..8])],
                exact: Vec3::from_slice(&w[8..11]),
                accept: w[1],
            },
            2 => PointLight::LeftOut { accept: w[1] },
            _ => PointLight::Redraw { accept: w[1] },
        };
        match v[0] as u32 {
            1 | 3 => Drawn::Kept(
                GatheredPoint {
                    triangle: v[1].to_bits(),
                    rest_square: v[2],
                    punctual_square: v[3],
                    total: v[4],
                    noise_square: v[5],
                    weight: v[6],
                },
                light(&v[7..]),
                v[0] as u32 == 1,
            ),
            2 => Drawn::Unseen(v[1].to_bits(), v[6], light(&v[7..])),
            4 => Drawn::Passed(light(&v[7..])),
            _ => Drawn::Skipped,
        }
    }
}

/// The lookup error of the pilot's lightmap at random surface points against a gather there.
#[derive(Clone, Debug, Default)]
pub(crate) struct GatheredSample {
    /// One per visible sampled point (points on buried or unrasterised texels are left out).
    pub(crate) points: Vec<GatheredPoint>,
    /// The triangles of drawn points left out as nobody's to see, with their weights: facing
    /// into geometry (the probe test) or on a buried texel.
    pub(crate) unseen: Vec<(u32, f32)>,
    /// Rays cast at the kept points (probes, gathering, light samples and punctual shadow rays).
    pub(crate) rays: u64,
    /// Points drawn, the left-out ones included.
    pub(crate) drawn: usize,
    /// What each drawn point's draw found that no atlas changes, by its stream index: for a
    /// later sample on another atlas ([`Runs::reuse`]).
    pub(crate) lights: Vec<PointLight>,
    /// Kept points whose light was read from an earlier sample's rather than gathered.
    pub(crate) reused: usize,
}

/// What the two runs give the sample: per texel, the irradiance `H` each run solved (what the
/// lightmap stores; not for `--indirect-only` bakes).
#[derive(Clone, Copy)]
pub(crate) struct Runs<'a> {
    pub(crate) irradiance: [&'a [Vec3]; 2],
    /// Uniform sky radiance the bake uses.
    pub(crate) sky: Vec3,
    /// The relative error the bake aims at, the rays the sample may cast past its first batch
    /// (and what sizes its batches, [`batch_size`]), and the seed of its streams.
    pub(crate) target: f32,
    pub(crate) budget_rays: u64,
    pub(crate) seed: u64,
    /// An earlier sample's [`GatheredSample::lights`] on the same scene with the same seed
    /// (empty for none): its points are drawn again and read on this atlas against the light
    /// gathered there, without a ray. The products stay unbiased: each run's lookup here is
    /// independent of the other run's gather there. What the earlier atlas changes in the
    /// gather is the second bounce at its texels' resolution (second order, as the module
    /// docs say of the pilot's own).
    pub(crate) reuse: &'a [PointLight],
}

/// Points per batch for a sample of `budget_rays` at `per_point` rays a gathered point: as many
/// as the budget gathers, within [`MIN_BATCH`]..=[`BATCH`]. A small scene's budget is smaller
/// than one full batch (the Cornell box at `draft`: 27k rays, about 280 points), and a full batch
/// cast there anyway was most of the bake.
pub(crate) fn batch_size(budget_rays: u64, per_point: u64) -> usize {
    (budget_rays / per_point.max(1)).clamp(MIN_BATCH as u64, BATCH as u64) as usize
}

impl GatheredSample {
    /// Samples surface points of `scene` with the pilot's two `runs` in batches of [`batch_size`]
    /// until the estimate is within [`PRECISION`], clearly below the relative error
    /// `runs.target` ([`SMALL`]), past `runs.budget_rays`, or [`MAX_POINTS`]; `punctual` (the
    /// punctual lights' texel values) splits off the rest. `None` without texels.
    pub(crate) fn measure(
        scene: &Scene,
        texels: &Texels,
        tracer: &Tracer,
        runs: &Runs,
        punctual: Option<&PunctualSample>,
        shards: &dyn Shards,
    ) -> Result<Option<GatheredSample>> {
        if texels.is_empty() || scene.triangles.is_empty() {
            return Ok(None);
        }
        let Some(cdf) = area_cdf(scene) else {
            return Ok(None);
        };
        let emitters = Emitters::new(scene, texels);
        let light_samples = if emitters.is_empty() {
            0
        } else {
            LIGHT_SAMPLES
        };
        let valid = texels.valid_mask();
        let (step, steep) = light_steps(texels, &valid, runs.irradiance);
        let drawer = PointDrawer {
            scene,
            texels,
            tracer,
            runs: *runs,
            punctual,
            emitters,
            light_samples,
            valid,
            cdf,
            step,
            steep,
        };
        let per_point =
            (PROBE_RAYS + 2 * (GATHER_RAYS + light_samples)) as u64 + scene.lights.len() as u64;
        let batch_points = batch_size(runs.budget_rays, per_point);
        // Batches until the estimate is precise enough: each point has its own stream, so the
        // result does not depend on the thread count.
        let mut sample = GatheredSample::default();
        let mut drawn = 0;
        // Points whose light an earlier sample gathered are read first, all of them (they
        // cost no ray); past them a batch is cast only while the budget holds it whole.
        let free = runs.reuse.len();
        while drawn < MAX_POINTS {
            let size = if drawn < free {
                free - drawn
            } else {
                batch_points
            };
            let batch = shard::map(shards, size, |k| drawer.draw(drawn + k))?;
            drawn += size;
            for d in batch {
                let light = match d {
                    Drawn::Kept(p, light, fresh) => {
                        sample.points.push(p);
                        sample.reused += usize::from(!fresh);
                        sample.rays += if fresh { per_point } else { 0 };
                        light
                    }
                    Drawn::Unseen(t, weight, light) => {
                        sample.unseen.push((t, weight));
                        light
                    }
                    Drawn::Passed(light) => light,
                    Drawn::Skipped => PointLight::NONE,
                };
                sample.lights.push(light);
            }
            let (_, lo, hi) = sample.relative_error_bounds();
            let stderr = sample.mean_square_total().1;
            let mean_square = sample.mean_square_clamped();
            // Without earlier light, the first batch is gathered whatever the budget; past it,
            // batches while the rays are within the budget. (Until 7 December the first batch
            // ran on to the rays of as many points all gathered: three batches on a small
            // scene, where a third of the drawn points gather.)
            let spent = if free > 0 {
                sample.rays + per_point * batch_points as u64 > runs.budget_rays
            } else {
                sample.rays >= runs.budget_rays
            };
            if hi < SMALL * runs.target
                || (mean_square > 0.0 && 2.0 * stderr <= PRECISION * mean_square)
                || spent
            {
                break;
            }
            // No light at the points, or none visible: more of them will not tell more.
            if !(lo.is_finite() || drawn < 4 * batch_points) {
                break;
            }
        }
        sample.drawn = drawn;
        Ok(Some(sample))
    }

    /// Relative RMS lookup error of the light other than punctual direct light (its mean
    /// square clamped at 0).
    pub(crate) fn rest_error(&self) -> f32 {
        self.relative(self.mean_square(|p| p.rest_square).0)
    }

    /// Relative RMS noise of one run as a renderer reads it at these points (its bilinear
    /// lookup, area-weighted): below the texels' own relative noise, which weighs every texel
    /// alike and reads each alone. NaN without points or light.
    pub(crate) fn lookup_noise(&self) -> f32 {
        self.relative(self.mean_square(|p| p.noise_square).0)
    }

    /// Relative RMS lookup error of the punctual direct light at these points.
    pub(crate) fn punctual_error(&self) -> f32 {
        self.relative(self.mean_square(|p| p.punctual_square).0)
    }

    /// [`GatheredSample::relative_error`] and the relative errors with the mean square ∓ two
    /// standard errors of the per-point sums (how far the sample's own noise could move it).
    pub(crate) fn relative_error_bounds(&self) -> (f32, f32, f32) {
        let central = self.mean_square_clamped();
        let stderr = self.mean_square_total().1;
        let at = |r: f64| self.relative(r);
        (
            at(central),
            at(central - 2.0 * stderr),
            at(central + 2.0 * stderr),
        )
    }

    /// The mean square lookup error of all the light, each part's clamped at 0 (a product's
    /// mean can fall below 0 where the light is smooth).
    fn mean_square_clamped(&self) -> f64 {
        let rest = self.mean_square(|p| p.rest_square).0;
        let punctual = self.mean_square(|p| p.punctual_square).0;
        rest.max(0.0) + punctual.max(0.0)
    }

    /// The mean square lookup error of all the light (the rest's and the punctual light's
    /// squares added per point) and its standard error, in absolute units (NaN below two
    /// points).
    pub(crate) fn mean_square_total(&self) -> (f64, f64) {
        self.mean_square(|p| p.rest_square + p.punctual_square)
    }

    /// The points' mean light (what relative errors divide by).
    pub(crate) fn mean_light(&self) -> f64 {
        self.weighted_mean(|p| p.total).0
    }

    /// The mean of a per-point square and its standard error (NaN below two points).
    fn mean_square(&self, square: impl Fn(&GatheredPoint) -> f32) -> (f64, f64) {
        self.weighted_mean(square)
    }

    /// The weighted mean of a per-point value over the points (each weighing one over the
    /// probability it was gathered with) and its standard error, `Σw²(x − m)²/(Σw)²` with the
    /// `n/(n − 1)` correction (NaN below two points).
    fn weighted_mean(&self, value: impl Fn(&GatheredPoint) -> f32) -> (f64, f64) {
        let n = self.points.len() as f64;
        if n < 2.0 {
            return (f64::NAN, f64::NAN);
        }
        let (mut w, mut wx) = (0.0f64, 0.0f64);
        for p in &self.points {
            w += f64::from(p.weight);
            wx += f64::from(p.weight) * f64::from(value(p));
        }
        let mean = wx / w;
        let spread: f64 = self
            .points
            .iter()
            .map(|p| (f64::from(p.weight) * (f64::from(value(p)) - mean)).powi(2))
            .sum();
        (mean, (spread * n / (n - 1.0)).sqrt() / w)
    }

    /// A mean square over the points' mean light, as a relative RMS error (clamped at 0).
    fn relative(&self, mean_square: f64) -> f32 {
        let mean = self.mean_light();
        if !(mean > 0.0 && mean_square.is_finite()) {
            return f32::NAN;
        }
        (mean_square.max(0.0).sqrt() / mean) as f32
    }
}

/// Cumulative area over the scene's triangles, to draw points area-weighted; `None` when the
/// scene has no (finite) area.
fn area_cdf(scene: &Scene) -> Option<Vec<f32>> {
    let mut cdf = Vec::with_capacity(scene.triangles.len());
    let mut area = 0.0f64;
    for t in &scene.triangles {
        let [a, b, c] = t.map(|v| scene.positions[v as usize].as_dvec3());
        area += 0.5 * (b - a).cross(c - a).length();
        cdf.push(area as f32);
    }
    (area > 0.0 && area.is_finite()).then_some(cdf)
}

/// Per texel, the step of the light to its neighbours: the largest product of the two runs'
/// differences to a valid 4-neighbour on its page (mean over channels; unbiased for the squared
/// step, so noise alone leaves it near zero), and the step only [`STEEP_AREA`] of the valid
/// texels' area exceeds (0 when the light is flat everywhere).
fn light_steps(texels: &Texels, valid: &[bool], h: [&[Vec3]; 2]) -> (Vec<f32>, f32) {
    let mut step = vec![0.0f32; texels.len()];
    for (i, (&page, &[x, y])) in texels.page.iter().zip(&texels.xy).enumerate() {
        if !valid[i] {
            continue;
        }
        let size = texels.pages[page as usize];
        for (nx, ny) in [(x + 1, y), (x, y + 1)] {
            if nx >= size.width || ny >= size.height {
                continue;
            }
            let j = texels.index[page as usize][(ny * size.width + nx) as usize];
            if j == NO_TEXEL || !valid[j as usize] {
                continue;
            }
            let product =
                ((h[0][i] - h[0][j as usize]) * (h[1][i] - h[1][j as usize])).element_sum() / 3.0;
            if product.is_finite() {
                step[i] = step[i].max(product);
                step[j as usize] = step[j as usize].max(product);
            }
        }
    }
    let mut order: Vec<u32> = (0..texels.len() as u32)
        .filter(|&i| valid[i as usize])
        .collect();
    order.sort_unstable_by(|&a, &b| {
        step[a as usize]
            .total_cmp(&step[b as usize])
            .then(a.cmp(&b))
    });
    let total: f64 = order
        .iter()
        .map(|&i| f64::from(texels.area[i as usize]))
        .sum();
    let mut below = 0.0f64;
    let mut steep = 0.0f32;
    for &i in &order {
        below += f64::from(texels.area[i as usize]);
        if below >= (1.0 - STEEP_AREA) * total {
            steep = step[i as usize];
            break;
        }
    }
    (step, steep)
}

/// What drawing a point and estimating its light need, shared by all the sample's points.
struct PointDrawer<'a> {
    scene: &'a Scene,
    texels: &'a Texels,
    tracer: &'a Tracer,
    runs: Runs<'a>,
    punctual: Option<&'a PunctualSample>,
    emitters: Emitters,
    /// Emitter light samples per point and run ([`LIGHT_SAMPLES`], none without emitters).
    light_samples: u32,
    /// Texels a lookup may read.
    valid: Vec<bool>,
    /// [`area_cdf`] of the scene.
    cdf: Vec<f32>,
    /// [`light_steps`]: per texel, and the steep step every point at or above is gathered.
    step: Vec<f32>,
    steep: f32,
}

impl PointDrawer<'_> {
    /// Point `k` of the sample, from its own stream: its squared lookup errors, or why it is
    /// left out.
    fn draw(&self, k: usize) -> Drawn {
        let (scene, texels, tracer, runs) = (self.scene, self.texels, self.tracer, &self.runs);
        let seed = runs.seed;
        let mut rng = Rng::new(seed ^ SALT, k as u64, 0);
        let t = sampling::sample_cdf(&self.cdf, rng.next_f32()) as u32;
        let b = sampling::triangle_point(rng.next_vec2());
        let sp = scene.surface_point(t, b);
        if sp.n_geo == Vec3::ZERO {
            return Drawn::Skipped;
        }
        let earlier = runs.reuse.get(k).copied().unwrap_or(PointLight::NONE);
        let shift = rng.next_vec2();
        let u = rng.next_f32();
        // The lookup first: it costs no ray, and says how steep the light is there.
        let [ua, ub, uc] = texels.triangle_uv[t as usize];
        let uv = ua * (1.0 - b.x - b.y) + ub * b.x + uc * b.y;
        let page = texels.triangle_page[t as usize] as usize;
        let Some((lookup, _)) = bilinear(texels, &self.valid, page, uv) else {
            // A buried texel here, whoever draws it (no ray): the earlier light, if any, stays
            // for another atlas.
            return Drawn::Unseen(t, 1.0, earlier);
        };
        let step = lookup
            .iter()
            .filter(|&&(_, w)| w > 0.0)
            .map(|&(j, _)| self.step[j as usize])
            .fold(0.0f32, f32::max);
        let own = if self.steep > 0.0 {
            (step / self.steep).clamp(MIN_ACCEPT, 1.0)
        } else {
            1.0
        };
        // An earlier sample's choice stands (its light is at hand, no ray); its own otherwise.
        let accept = match earlier.accept() {
            0.0 => own,
            earlier => earlier,
        };
        if u >= accept {
            return Drawn::Passed(PointLight::Redraw { accept });
        }
        let weight = 1.0 / accept;
        // Points nobody sees (faces looking into geometry: a floor under a cabinet, the
        // bottom of a box on the floor) are left out, as the point yardstick leaves them.
        match earlier {
            PointLight::LeftOut { .. } => {
                return Drawn::Unseen(t, weight, PointLight::LeftOut { accept });
            }
            PointLight::Gathered { .. } => {}
            PointLight::Redraw { .. } => {
                let back =
                    validity::back_hits(tracer, sp.p, sp.n_geo, PROBE_RAYS, shift, f32::INFINITY);
                if back > (MAX_BACK * PROBE_RAYS as f32) as u32 {
                    return Drawn::Unseen(t, weight, PointLight::LeftOut { accept });
                }
            }
        }
        let read = |v: &[Vec3]| -> Vec3 { lookup.iter().map(|&(j, w)| v[j as usize] * w).sum() };
        let origin = sp.p + sp.n_geo * tracer.epsilon;
        // Each run's own punctual light at the texels (the same for both when traced apart).
        let punctual_texels =
            [0, 1].map(|r| self.punctual.map_or(Vec3::ZERO, |p| read(&p.texel[r])));
        let (rest, exact, fresh) = match earlier {
            PointLight::Gathered { rest, exact, .. } => (rest, exact, false),
            _ => {
                // Punctual light: the exact light about the shading normal (no noise); the
                // rest gathered through each run.
                let exact = match self.punctual {
                    Some(_) => scene
                        .lights
                        .iter()
                        .map(|l| punctual_irradiance(l, origin, sp.n, tracer))
                        .sum(),
                    None => Vec3::ZERO,
                };
                let rest = [0usize, 1].map(|r| {
                    let mut rng = Rng::new(seed ^ SALT, k as u64, 1 + r as u64);
                    self.gather(origin, (sp.n, sp.n_geo), runs.irradiance[r], &mut rng)
                });
                (rest, exact, true)
            }
        };
        let light = PointLight::Gathered {
            rest,
            exact,
            accept,
        };
        let [da, db] = [0usize, 1].map(|r| read(runs.irradiance[r]) - punctual_texels[r] - rest[r]);
        let [pa, pb] = punctual_texels.map(|p| p - exact);
        let [ha, hb] = runs.irradiance.map(read);
        let total = (ha + hb) * 0.5;
        let spread = ha - hb;
        let point = GatheredPoint {
            triangle: t,
            rest_square: (da * db).element_sum() / 3.0,
            punctual_square: (pa * pb).element_sum() / 3.0,
            total: total.element_sum() / 3.0,
            noise_square: (spread * spread).element_sum() / 6.0,
            weight,
        };
        if point.rest_square.is_finite()
            && point.punctual_square.is_finite()
            && point.total.is_finite()
            && point.noise_square.is_finite()
        {
            Drawn::Kept(point, light, fresh)
        } else {
            Drawn::Skipped
        }
    }

    /// The non-punctual light at a point, as transport estimates it at a texel, through a
    /// run's solved irradiance `h`, about the shading normal `n`. Light from below the face
    /// (`n_geo`) counts as zero, as the reference path tracer counts it: a ray the shading
    /// normal tilts under the face would pass into what lies below it.
    fn gather(&self, origin: Vec3, (n, n_geo): (Vec3, Vec3), h: &[Vec3], rng: &mut Rng) -> Vec3 {
        let (scene, texels, tracer, emitters) =
            (self.scene, self.texels, self.tracer, &self.emitters);
        let light_samples = self.light_samples;
        let (kf, lf) = (GATHER_RAYS as f32, light_samples as f32);
        let (tx, ty) = frame(n);
        let shift = rng.next_vec2();
        let (mut emitted, mut reflected, mut escaped) = (Vec3::ZERO, Vec3::ZERO, 0u32);
        for s in 0..GATHER_RAYS {
            let local = cosine_hemisphere(hammersley(s, GATHER_RAYS, shift));
            let dir = tx * local.x + ty * local.y + n * local.z;
            if n_geo.dot(dir) <= 0.0 {
                continue;
            }
            match texels.ray_end(tracer, origin, dir) {
                RayEnd::Escaped => escaped += 1,
                RayEnd::Absorbed => {}
                RayEnd::Texel(hit, j) => {
                    let j = j as usize;
                    reflected += texels.albedo[j] * h[j];
                    let le = texels.emission[j];
                    if le.max_element() > 0.0 {
                        let (_, n_l) = crate::lights::triangle_point(scene, hit.triangle, hit.bary);
                        let p_light = emitters.pdf_toward(hit.triangle, n_l, dir, hit.t);
                        emitted += le * (local.z * power_weight(kf * local.z / PI, lf * p_light));
                    }
                }
            }
        }
        let light_shift = rng.next_vec2();
        for s in 0..light_samples {
            let u = hammersley(s, light_samples, light_shift);
            let Some(x) = emitters.sample_from((scene, texels, tracer), origin, Some(n), u) else {
                continue;
            };
            if n_geo.dot(x.point - origin) <= 0.0 {
                continue;
            }
            let p_gather = x.cos_i / PI;
            emitted += x.le * (x.cos_i * power_weight(lf * x.pdf_solid_angle(), kf * p_gather));
        }
        emitted + reflected / kf + self.runs.sky * (PI * escaped as f32 / kf)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::atlas::PageSize;

    /// One row of texels on one page, of equal area.
    fn row(n: u32) -> Texels {
        Texels {
            pages: vec![PageSize {
                width: n,
                height: 1,
            }],
            index: vec![(0..n).collect()],
            xy: (0..n).map(|x| [x, 0]).collect(),
            page: vec![0; n as usize],
            area: vec![1.0; n as usize],
            position: vec![Vec3::ZERO; n as usize],
            ..Texels::default()
        }
    }

    #[test]
    fn the_light_steps_where_both_runs_step_and_not_where_they_disagree() {
        let texels = row(6);
        let valid = vec![true; 6];
        // A step of 4 between texels 1 and 2 in both runs; between 3 and 4 the runs step
        // oppositely (noise), and texel 5 is buried.
        let a: Vec<Vec3> = [1.0, 1.0, 5.0, 5.0, 6.0, 9.0].map(Vec3::splat).to_vec();
        let b: Vec<Vec3> = [1.0, 1.0, 5.0, 5.0, 4.0, 9.0].map(Vec3::splat).to_vec();
        let mut valid_but_5 = valid.clone();
        valid_but_5[5] = false;
        let (step, steep) = light_steps(&texels, &valid_but_5, [&a, &b]);
        assert_eq!(step, vec![0.0, 16.0, 16.0, 0.0, 0.0, 0.0]);
        // The top 5% of five valid texels' area is the steepest texel's.
        assert_eq!(steep, 16.0);
        // Flat light: no step anywhere, so every point is gathered.
        let flat = vec![Vec3::ONE; 6];
        assert_eq!(light_steps(&texels, &valid, [&flat, &flat]).1, 0.0);
    }
}
