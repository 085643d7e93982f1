//! The per-texel error map (`--error-map`): the planner's estimate of the relative error a
//! renderer shows, texel by texel, so an artist sees where a bake is weak and why.
//!
//! Two parts, as in the plan's scene-wide prediction ([`super::Plan::predicted_error`]):
//!
//! - **Noise**: the standard deviation of the texel's Monte Carlo estimate before denoising.
//!   Where the bake stored Monte Carlo rows it is the texel's own variance
//!   ([`gathering_noise`]): each gathering ray returns the radiosity of the texel it hits (or
//!   the sky's), so the rows and the solution give the mean and mean square of what the rays
//!   returned, and the variance of their mean falls with the texel's rays (all runs
//!   together). Emitter light samples add the denoiser's model of their noise
//!   ([`expected_noise`]'s direct term). The matrix-free gatherer keeps no rows: its texels get
//!   the denoiser's model whole. Deterministic methods have none. When a pilot measured the
//!   scene's noise ([`super::Plan::predicted_noise`]) the map is scaled to it: the texels' own
//!   variances say *where* the noise is, the pilot pair *how much* (stratified rays fall faster
//!   than the independent-ray variance says).
//! - **Resolution**: what a bilinear lookup between texel centres misses where the light
//!   curves, from the second differences of the stored page values along both page axes and
//!   the planner's model of the lookup's error ([`super::resolution_error`]); a hard shadow
//!   edge is a second difference the size of the step. Without the denoiser the noise's share
//!   of the squared second differences is taken out. Texels without a second difference on
//!   either axis (strips one texel wide, lone texels) get 0.
//!
//! Both are relative to the texel's value plus 5% of the scene's mean (the floor of
//! [`metrics::floored_relative_errors`]: dark texels do not dominate). Invalid (buried)
//! texels, filled from their neighbours, get 0.

use glam::Vec3;

use super::{G_MEAN, G_MEAN_SQUARE, resolution_squares};
use crate::lightmap::denoise::expected_noise;
use crate::metrics;
use crate::texels::Texels;
use crate::transport::Transport;

/// Share of the scene's mean light added to each texel's value before dividing by it.
const FLOOR: f32 = 0.05;

/// How many samples made each texel's estimate.
#[derive(Clone, Debug)]
pub(crate) struct Samples<'a> {
    /// Gathering rays per texel, all combined runs together.
    pub(crate) rays: &'a [f32],
    /// Emitter light samples per gathering ray (0 without emitters).
    pub(crate) light_per_ray: f32,
}

/// Per texel and channel, the standard deviation of the irradiance `H` (W/m²) that stored
/// Monte Carlo rows `transport` and the solved irradiance `h` give, with `sky` radiance:
/// `(E[X²] − E[X]²) / K` for the value `X` a gathering ray returns (`ρ_j·H_j` of the texel it
/// hits, `π·sky` when it escapes; `F_ij` is the share of the rays that hit `j`), plus the
/// emitter light samples' noise of the direct light, the denoiser's `(direct/L)²`.
pub(crate) fn gathering_noise(
    transport: &Transport,
    texels: &Texels,
    h: &[Vec3],
    sky: Vec3,
    samples: &Samples,
) -> Vec<Vec3> {
    (0..transport.len())
        .map(|i| {
            let (mean, square) = ray_moments(transport, i, texels, h, sky);
            let k = samples.rays[i].max(1.0);
            let mut variance = (square - mean * mean).max(Vec3::ZERO) / k;
            let lights = samples.light_per_ray * k;
            if lights > 0.0 {
                let sampled = (transport.direct[i]
                    - sky * std::f32::consts::PI * transport.escape[i])
                    .max(Vec3::ZERO);
                variance += (sampled / lights) * (sampled / lights);
            }
            variance.sqrt()
        })
        .collect()
}

/// Per row of `rows` (all texels', or one process's part), the variance of the irradiance one
/// gathering ray returns there, the mean over the channels: [`gathering_noise`]'s
/// `E[X²] − E[X]²` for `K = 1`, without light samples. Where a texel's rays disagree most, more of them lower the
/// lightmap's noise most (`plan::spread_rays`).
pub(crate) fn ray_variance(rows: &Transport, texels: &Texels, h: &[Vec3], sky: Vec3) -> Vec<f32> {
    use rayon::prelude::*;
    (0..rows.len())
        .into_par_iter()
        .map(|r| {
            let (mean, square) = ray_moments(rows, r, texels, h, sky);
            (square - mean * mean).max(Vec3::ZERO).element_sum() / 3.0
        })
        .collect()
}

/// Mean and mean square of what a gathering ray of row `r` of `rows` returns: the radiosity
/// `ρ_j·H_j` (plus `π·Le_j` where rows carry emission) of the texel it hits with probability
/// `F_ij`, `π·sky` when it escapes.
fn ray_moments(rows: &Transport, r: usize, texels: &Texels, h: &[Vec3], sky: Vec3) -> (Vec3, Vec3) {
    let sky = sky * std::f32::consts::PI;
    let escape = rows.escape[r];
    let (mut mean, mut square) = (sky * escape, sky * sky * escape);
    for (j, f) in rows.row(r) {
        let j = j as usize;
        let emitted = match rows.rows_carry_emission {
            true => texels.emission[j] * std::f32::consts::PI,
            false => Vec3::ZERO,
        };
        let b = texels.albedo[j] * h[j] + emitted;
        mean += b * f;
        square += b * b * f;
    }
    (mean, square)
}

/// The denoiser's noise model per texel ([`expected_noise`]), for a bake that kept no rows:
/// `H` the solved irradiance, `direct` its direct part, `k` and `l` the rays and light samples.
pub(crate) fn modelled_noise(h: &[Vec3], direct: &[Vec3], k: u32, l: u32) -> Vec<Vec3> {
    h.iter()
        .zip(direct)
        .map(|(&h, &d)| Vec3::splat(expected_noise(h - d, d, k as f32, l as f32)))
        .collect()
}

/// Per texel, the relative error (resolution, noise, and the two in quadrature) of the stored
/// values `stored` (what the pages hold, `H/π`), whose noise before denoising is `sigma`
/// (standard deviations in the units of `stored`); `denoised` says the denoiser ran,
/// `noise_level` is the plan's predicted relative noise when a pilot measured it.
pub(crate) fn error_map(
    texels: &Texels,
    stored: &[Vec3],
    sigma: &[Vec3],
    denoised: bool,
    noise_level: Option<f32>,
) -> Vec<Vec3> {
    let n = texels.len();
    let valid = texels.valid_mask();
    let level = |v: Vec3| v.max(Vec3::ZERO).element_sum() / 3.0;
    let kept = (0..n).filter(|&i| valid[i]);
    let (sum, count) = kept.fold((0.0f64, 0usize), |(s, c), i| {
        (s + level(stored[i]) as f64, c + 1)
    });
    let floor = FLOOR * (sum / count.max(1) as f64) as f32;
    let scale = match noise_level {
        Some(level) => {
            let measured = metrics::noise_over_mean(sigma, stored, &texels.invalid);
            if measured > 0.0 {
                level / measured
            } else {
                1.0
            }
        }
        None => 1.0,
    };
    let (square, no_difference) = resolution_squares(texels, [stored, stored]);
    // A second difference of values with independent noise σ carries 6σ² along each axis and
    // 4σ² between the axes (the shared centre): its share of the model's square.
    let noise_in_square = 12.0 * G_MEAN_SQUARE + 8.0 * G_MEAN * G_MEAN;
    (0..n)
        .map(|i| {
            let value = level(stored[i]) + floor;
            if !valid[i] || value <= 0.0 {
                return Vec3::ZERO;
            }
            let noise = sigma[i] * scale;
            let mut curve = square[i];
            if !denoised {
                curve -= noise * noise * noise_in_square;
            }
            let resolution = match no_difference.binary_search(&(i as u32)) {
                Ok(_) => 0.0,
                Err(_) => (curve.element_sum() / 3.0).max(0.0).sqrt() / value,
            };
            let noise = level(noise * noise).sqrt() / value;
            let map = Vec3::new(resolution, noise, resolution.hypot(noise));
            if map.is_finite() { map } else { Vec3::ZERO }
        })
        .collect()
}
