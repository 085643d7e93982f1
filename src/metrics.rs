//! Error metrics: how far a lightmap (or an image) is from a reference, and how noisy an estimate
//! is. Every accuracy figure of the tests, the examples and the benchmark comes from here, so
//! figures stay comparable.
//!
//! Values are RGB per texel (or pixel); `skip` lists texels left out (usually
//! `Texels::invalid`: buried texels a bake fills from neighbours). Sums run over the kept texels
//! and their three channels, in `f64`.
//!
//! Two normalisations of a relative RMS difference, both needed:
//!
//! | function           | formula                         | used for                                          |
//! |--------------------|---------------------------------|---------------------------------------------------|
//! | [`rmse_over_mean`] | `√(mean((x−r)²)) / mean(r)`     | *the* relative RMSE: README, benchmark, `--target-error`, the planner's pilot noise (`relative_noise`) |
//! | [`rmse_over_rms`]  | `√(Σ‖x−r‖² / Σ‖r‖²)`            | the reference's stopping rule and the tests written against it (images, bake vs reference) |
//!
//! They differ by the factor `rms(r)/mean(r)` ≥ 1 (`rmse_over_rms` is the smaller): a bright
//! light's texels weigh more in `√Σr²`. Both weigh a texel's error by the scene's overall
//! brightness, so near-black texels cannot dominate. Where every texel should count alike (the
//! denoiser's test, with texels below a floor left out), [`rms_texel_relative_error`] is the RMS
//! of per-texel relative errors: the Cornell box at K = 512 is 3% worse after denoising by it,
//! 9.5% worse by `rmse_over_mean` (the bright texels lose more).
//!
//! A reference's own noise (its standard errors σ) is normalised the same way by
//! [`noise_over_mean`] and [`noise_over_rms`]; against a noisy reference the expected squared
//! error is the true squared error plus the reference's variance, so [`without_noise`] subtracts
//! it in quadrature. Noise and error must share a normalisation for that to hold.
//!
//! Noises are 0 on a black reference (nothing to be noisy about); errors are NaN there, or when
//! every texel is skipped (undefined: a chart leaves them out).

use glam::Vec3;

/// Which of `len` texels take part: false for those listed in `skip`.
fn kept(len: usize, skip: &[u32]) -> Vec<bool> {
    let mut kept = vec![true; len];
    for &i in skip {
        if let Some(k) = kept.get_mut(i as usize) {
            *k = false;
        }
    }
    kept
}

/// Sums over the kept texels: (Σ‖d(a, b)‖², Σ of `r`'s channels, Σ‖r‖², channels counted).
fn sums(a: &[Vec3], b: &[Vec3], r: &[Vec3], skip: &[u32], d: impl Fn(Vec3, Vec3) -> Vec3) -> Sums {
    assert!(
        a.len() == r.len() && b.len() == r.len(),
        "values must share texels"
    );
    let mut s = Sums::default();
    for (((a, b), r), k) in a.iter().zip(b).zip(r).zip(kept(r.len(), skip)) {
        if k {
            s.square += d(*a, *b).length_squared() as f64;
            s.sum += r.element_sum() as f64;
            s.norm += r.length_squared() as f64;
            s.count += 3;
        }
    }
    s
}

#[derive(Default)]
struct Sums {
    square: f64,
    sum: f64,
    norm: f64,
    count: usize,
}

impl Sums {
    /// `√(square / count) / mean`: NaN if nothing was summed or the mean is not positive.
    fn over_mean(&self) -> f64 {
        if self.count == 0 || self.sum <= 0.0 {
            return f64::NAN;
        }
        let n = self.count as f64;
        (self.square / n).sqrt() / (self.sum / n)
    }
}

/// The relative RMSE of `x` against the reference `r`: `√(mean((x−r)²)) / mean(r)` over the
/// kept texels and channels (see the module docs).
pub fn rmse_over_mean(x: &[Vec3], r: &[Vec3], skip: &[u32]) -> f32 {
    sums(x, r, r, skip, |x, r| x - r).over_mean() as f32
}

/// The relative RMS noise of a reference `r` with standard errors `std_error`, normalised as
/// [`rmse_over_mean`]: `√(mean(σ²)) / mean(r)`; 0 on a black reference.
pub fn noise_over_mean(std_error: &[Vec3], r: &[Vec3], skip: &[u32]) -> f32 {
    let s = sums(std_error, std_error, r, skip, |s, _| s);
    if s.count == 0 || s.sum <= 0.0 {
        0.0
    } else {
        s.over_mean() as f32
    }
}

/// `√(Σ‖x−r‖² / Σ‖r‖²)` over the kept texels: the relative RMS difference in the normalisation of
/// the reference's stopping rule (see the module docs).
pub fn rmse_over_rms(x: &[Vec3], r: &[Vec3], skip: &[u32]) -> f32 {
    let s = sums(x, r, r, skip, |x, r| x - r);
    if s.norm > 0.0 {
        (s.square / s.norm).sqrt() as f32
    } else {
        f32::NAN
    }
}

/// `√(Σ‖σ‖² / Σ‖r‖²)` over the kept texels: a reference's noise normalised as
/// [`rmse_over_rms`]; 0 on a black reference.
pub fn noise_over_rms(std_error: &[Vec3], r: &[Vec3], skip: &[u32]) -> f32 {
    let s = sums(std_error, std_error, r, skip, |s, _| s);
    if s.norm > 0.0 {
        (s.square / s.norm).sqrt() as f32
    } else {
        0.0
    }
}

/// `√(mean_i ((Σx_i − Σr_i) / Σr_i)²)` over the kept texels whose reference channel sum `Σr_i`
/// exceeds `min_reference` (near-black texels would set it alone): every texel counts alike.
/// NaN if no texel is compared.
pub fn rms_texel_relative_error(x: &[Vec3], r: &[Vec3], skip: &[u32], min_reference: f32) -> f32 {
    let (mut sum, mut n) = (0.0f64, 0usize);
    for ((x, r), k) in x.iter().zip(r).zip(kept(r.len(), skip)) {
        let r = r.element_sum();
        if k && r > min_reference {
            sum += ((x.element_sum() - r) / r).powi(2) as f64;
            n += 1;
        }
    }
    (sum / n as f64).sqrt() as f32
}

/// An error measured against a noisy reference with the reference's noise taken out:
/// `√max(0, error² − noise²)` (both in one normalisation).
pub fn without_noise(error: f32, noise: f32) -> f32 {
    (error * error - noise * noise).max(0.0).sqrt()
}

/// `√(Σ w·mean_c(m) / Σ w) / (Σ w·mean_c(r) / Σ w)` over the kept texels: the relative RMS
/// of an error known only by its expected square `m` per texel and channel, each texel weighing
/// `w` (its area: a figure over area, like random points on surfaces), normalised as
/// [`rmse_over_mean`]. `m` may come from an unbiased estimator that is negative where the
/// error is small; a negative total reads as 0. NaN when nothing is kept or `r`'s mean is
/// not positive.
pub(crate) fn weighted_rms_over_mean(m: &[Vec3], r: &[Vec3], w: &[f32], skip: &[u32]) -> f32 {
    assert!(
        m.len() == r.len() && w.len() == r.len(),
        "values must share texels"
    );
    let (mut square, mut sum, mut weight) = (0.0f64, 0.0f64, 0.0f64);
    for (((m, r), w), k) in m.iter().zip(r).zip(w).zip(kept(r.len(), skip)) {
        if k {
            square += *w as f64 * m.element_sum() as f64;
            sum += *w as f64 * r.element_sum() as f64;
            weight += *w as f64;
        }
    }
    if weight <= 0.0 || sum <= 0.0 {
        return f32::NAN;
    }
    let channels = 3.0 * weight;
    ((square.max(0.0) / channels).sqrt() / (sum / channels)) as f32
}

/// `Σx / Σr − 1` over the kept texels and channels: how much brighter `x` is on the whole.
pub fn relative_bias(x: &[Vec3], r: &[Vec3], skip: &[u32]) -> f32 {
    let (mut a, mut b) = (0.0f64, 0.0f64);
    for ((x, r), k) in x.iter().zip(r).zip(kept(r.len(), skip)) {
        if k {
            a += x.element_sum() as f64;
            b += r.element_sum() as f64;
        }
    }
    (a / b - 1.0) as f32
}

/// `Σ|x − r| / Σ|r|` over all texels and channels (for results that should agree to rounding,
/// where one dark texel's ratio would say nothing).
pub fn relative_l1(x: &[Vec3], r: &[Vec3]) -> f32 {
    let diff: f32 = x
        .iter()
        .zip(r)
        .map(|(x, r)| (*x - *r).abs().element_sum())
        .sum();
    diff / r.iter().map(|r| r.abs().element_sum()).sum::<f32>()
}

/// The largest `|x − expected| / expected` over every texel and channel: the check for scenes
/// with one known value everywhere (the furnace).
pub fn max_relative_deviation(x: &[Vec3], expected: f32) -> f32 {
    x.iter()
        .flat_map(|v| v.to_array())
        .map(|c| (c - expected).abs() / expected)
        .fold(0.0, f32::max)
}

/// Per kept texel and channel, `|x−r| / (r + 0.05·mean(r))`: relative errors whose floor keeps
/// dark texels from dominating (the benchmark's p95 and max come from these).
pub fn floored_relative_errors(x: &[Vec3], r: &[Vec3], skip: &[u32]) -> Vec<f32> {
    let s = sums(x, r, r, skip, |x, r| x - r);
    let floor = 0.05 * (s.sum / s.count as f64) as f32;
    x.iter()
        .zip(r)
        .zip(kept(r.len(), skip))
        .filter(|(_, k)| *k)
        .flat_map(|((a, b), _)| (0..3).map(move |c| (a[c] - b[c]).abs() / (b[c] + floor)))
        .collect()
}

/// The `ps` percentiles (0..=1) of `values`, each the sorted value at `⌊n·p⌋` (the last one
/// for p = 1); NaN for no values.
pub fn percentiles<const N: usize>(values: &[f32], ps: [f32; N]) -> [f32; N] {
    let mut sorted = values.to_vec();
    sorted.sort_by(f32::total_cmp);
    ps.map(|p| match sorted.len() {
        0 => f32::NAN,
        n => sorted[((n as f32 * p) as usize).min(n - 1)],
    })
}

/// The median of `values` (the upper one of an even count), NaN for none.
pub fn median(values: &[f32]) -> f32 {
    percentiles(values, [0.5])[0]
}

/// `rms(a − b) / √2 / mean((a + b)/2)` over all channels of the texels not listed in `skip`:
/// the relative RMS noise of one of two independent estimates (normalised as
/// [`rmse_over_mean`]); 0 for black maps.
pub(crate) fn relative_noise(a: &[Vec3], b: &[Vec3], skip: &[u32]) -> f32 {
    let (mut sq, mut sum, mut count) = (0.0f64, 0.0f64, 0usize);
    for ((x, y), k) in a.iter().zip(b).zip(kept(a.len(), skip)) {
        if !k {
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

    fn close(a: f32, b: f32) -> bool {
        (a - b).abs() < 1e-6 * b.abs().max(1.0)
    }

    /// Reference 1 and 3 (mean 2, rms √5), bake off by +1 on the first texel: mean((x−r)²) = ½.
    fn pair() -> (Vec<Vec3>, Vec<Vec3>) {
        let r = vec![Vec3::splat(1.0), Vec3::splat(3.0)];
        let x = vec![Vec3::splat(2.0), Vec3::splat(3.0)];
        (x, r)
    }

    #[test]
    fn the_two_normalisations_of_a_known_difference() {
        let (x, r) = pair();
        assert!(close(rmse_over_mean(&x, &r, &[]), 0.5f32.sqrt() / 2.0));
        // Σ‖x−r‖² = 3, Σ‖r‖² = 3 + 27.
        assert!(close(rmse_over_rms(&x, &r, &[]), 0.1f32.sqrt()));
        assert_eq!(rmse_over_mean(&r, &r, &[]), 0.0);
        // Skipping the only differing texel leaves no error.
        assert_eq!(rmse_over_mean(&x, &r, &[0]), 0.0);
        assert_eq!(rmse_over_rms(&x, &r, &[0]), 0.0);
        // Out-of-range skips are ignored.
        assert!(close(rmse_over_mean(&x, &r, &[7]), 0.5f32.sqrt() / 2.0));
    }

    #[test]
    fn undefined_errors_are_nan_and_black_noise_is_zero() {
        let black = [Vec3::ZERO];
        assert!(rmse_over_mean(&[Vec3::ONE], &black, &[]).is_nan());
        assert!(rmse_over_rms(&[Vec3::ONE], &black, &[]).is_nan());
        assert!(rmse_over_mean(&[Vec3::ONE], &[Vec3::ONE], &[0]).is_nan());
        assert_eq!(noise_over_mean(&[Vec3::ONE], &black, &[]), 0.0);
        assert_eq!(noise_over_rms(&[Vec3::ONE], &black, &[]), 0.0);
    }

    #[test]
    fn noise_shares_the_normalisation_of_its_error() {
        let (_, r) = pair();
        let se = vec![Vec3::splat(0.1), Vec3::splat(0.3)];
        // mean(σ²) = 0.05, mean(r) = 2; Σ‖σ‖² = 0.3, Σ‖r‖² = 30.
        assert!(close(noise_over_mean(&se, &r, &[]), 0.05f32.sqrt() / 2.0));
        assert!(close(noise_over_rms(&se, &r, &[]), 0.1));
        assert!(close(noise_over_mean(&se, &r, &[1]), 0.1));
    }

    #[test]
    fn texel_relative_error_counts_every_texel_alike() {
        // Texel 0 is 100% off (channel sums 6 vs 3), texel 1 exact: √(½·1²).
        let (x, r) = pair();
        assert!(close(
            rms_texel_relative_error(&x, &r, &[], 0.0),
            0.5f32.sqrt()
        ));
        // Below the floor or skipped, texel 0 is not compared.
        assert_eq!(rms_texel_relative_error(&x, &r, &[], 3.0), 0.0);
        assert_eq!(rms_texel_relative_error(&x, &r, &[0], 0.0), 0.0);
        assert!(rms_texel_relative_error(&x, &r, &[0, 1], 0.0).is_nan());
    }

    #[test]
    fn weighted_rms_of_expected_squares() {
        let (_, r) = pair();
        // Expected squares 1 and 0, weights 3 and 1: √(3/4) over the weighted mean (3+3)/4.
        let m = vec![Vec3::ONE, Vec3::ZERO];
        let w = [3.0, 1.0];
        assert!(close(
            weighted_rms_over_mean(&m, &r, &w, &[]),
            0.75f32.sqrt() / 1.5
        ));
        assert!(close(weighted_rms_over_mean(&m, &r, &w, &[0]), 0.0));
        // A negative total (an unbiased estimate of a small error) reads as 0.
        let negative = vec![-Vec3::ONE, Vec3::ZERO];
        assert_eq!(weighted_rms_over_mean(&negative, &r, &w, &[]), 0.0);
        assert!(weighted_rms_over_mean(&m, &r, &w, &[0, 1]).is_nan());
    }

    #[test]
    fn noise_comes_off_in_quadrature() {
        assert!(close(without_noise(0.05, 0.03), 0.04));
        assert_eq!(without_noise(0.02, 0.03), 0.0);
        assert_eq!(without_noise(0.02, 0.0), 0.02);
    }

    #[test]
    fn bias_l1_and_deviation_of_known_values() {
        let (x, r) = pair();
        // Σx = 15, Σr = 12.
        assert!(close(relative_bias(&x, &r, &[]), 0.25));
        assert_eq!(relative_bias(&x, &r, &[0]), 0.0);
        assert!(close(relative_l1(&x, &r), 0.25));
        let lightmap = [Vec3::new(2.0, 2.1, 1.8)];
        assert!(close(max_relative_deviation(&lightmap, 2.0), 0.1));
    }

    #[test]
    fn floored_errors_and_percentiles() {
        let (x, r) = pair();
        // floor 0.05·2 = 0.1: |2−1|/1.1 on texel 0's channels, 0 on texel 1's.
        let mut e = floored_relative_errors(&x, &r, &[]);
        e.sort_by(f32::total_cmp);
        assert_eq!(e.len(), 6);
        assert_eq!(e[..3], [0.0; 3]);
        assert!(e[3..].iter().all(|&v| close(v, 1.0 / 1.1)));
        assert_eq!(floored_relative_errors(&x, &r, &[0]), vec![0.0; 3]);

        let v: Vec<f32> = (0..100).rev().map(|i| i as f32).collect();
        assert_eq!(
            percentiles(&v, [0.0, 0.05, 0.95, 1.0]),
            [0.0, 5.0, 95.0, 99.0]
        );
        assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&[4.0, 1.0, 3.0, 2.0]), 3.0);
        assert!(median(&[]).is_nan());
    }

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
}
