//! L2 spherical harmonics of incident radiance: the basis, the projection of samples and the
//! irradiance convolution.
//!
//! Coefficients are the raw projections of the incident radiance `L` (W/(sr·m²)) on the real
//! SH basis, in three.js's order and with its constants (`SphericalHarmonics3`):
//!
//! ```text
//!   c_i = ∫ L(ω) Y_i(ω) dω,   i = 0..9
//!   Y_0 = 0.282095
//!   Y_1 = 0.488603·y   Y_2 = 0.488603·z   Y_3 = 0.488603·x
//!   Y_4 = 1.092548·xy  Y_5 = 1.092548·yz  Y_6 = 0.315392·(3z² − 1)
//!   Y_7 = 1.092548·xz  Y_8 = 0.546274·(x² − y²)
//! ```
//!
//! Irradiance about a unit normal `n` is the convolution with the clamped cosine
//! (Ramamoorthi & Hanrahan 2001), whose band weights are `Â_0 = π`, `Â_1 = 2π/3`, `Â_2 = π/4`:
//!
//! ```text
//!   E(n)/π = Σ_i (Â_l(i)/π)·c_i·Y_i(n) = Σ_i w_l(i)·c_i·Y_i(n),   w = (1, 2/3, 1/4)
//! ```
//!
//! which is three.js's `getIrradianceAt(n)` divided by π. Bands above 2 are dropped (odd bands
//! above 1 have zero weight; band 4's is `1/24`): the truncation error is largest for light
//! from a single direction — +6% of its flux density along it, +9% at 90° — and vanishes for
//! radiance without bands above 2 (uniform, a uniform hemisphere). The value is clamped at
//! zero, where the ringing of a point light's projection goes negative facing away from it.

use glam::Vec3;

/// Nine RGB coefficients (see the module docs).
pub type Sh2 = [Vec3; 9];

/// The nine basis functions at unit direction `d`.
#[inline]
#[must_use]
pub fn basis(d: Vec3) -> [f32; 9] {
    let (x, y, z) = (d.x, d.y, d.z);
    [
        0.282_095,
        0.488_603 * y,
        0.488_603 * z,
        0.488_603 * x,
        1.092_548 * x * y,
        1.092_548 * y * z,
        0.315_392 * (3.0 * z * z - 1.0),
        1.092_548 * x * z,
        0.546_274 * (x * x - y * y),
    ]
}

/// Band weight `Â_l/π` of the clamped-cosine convolution for each coefficient.
pub const COSINE_OVER_PI: [f32; 9] = [
    1.0,
    2.0 / 3.0,
    2.0 / 3.0,
    2.0 / 3.0,
    0.25,
    0.25,
    0.25,
    0.25,
    0.25,
];

/// Adds a sample to `c`: `w` is radiance over sampling density (divided by the sample count)
/// arriving from unit direction `d`, so that `Σ w·Y(d)` estimates `∫ L Y dω`.
#[inline]
pub fn project(c: &mut Sh2, d: Vec3, w: Vec3) {
    for (ci, y) in c.iter_mut().zip(basis(d)) {
        *ci += w * y;
    }
}

/// `E(n)/π` for unit normal `n` from radiance coefficients `c`, clamped at zero.
#[inline]
#[must_use]
pub fn irradiance_over_pi(c: &Sh2, n: Vec3) -> Vec3 {
    let y = basis(n);
    let mut e = Vec3::ZERO;
    for i in 0..9 {
        e += c[i] * (COSINE_OVER_PI[i] * y[i]);
    }
    e.max(Vec3::ZERO)
}

/// `E(n)/π` from the L2 projection of light arriving from one unit direction `d` with flux
/// density 1, as a function of `t = n·d` (unclamped): the addition theorem sums each band's
/// `Y_lm(n)·Y_lm(d)` to `(2l + 1)/(4π)·P_l(t)`, so
/// `k(t) = (1 + 2t + (5/8)(3t² − 1))/(4π)`. `∫ L(d)·k(n·d) dω` is the L2 irradiance over π
/// of any radiance `L` — what [`irradiance_over_pi`] reads from its projection — which is how
/// the reference path tracer estimates it one direction at a time
/// (`crate::reference::trace_sh`). Negative for `t` near −½ (the ringing).
#[inline]
#[must_use]
pub fn kernel(t: f32) -> f32 {
    (1.0 + 2.0 * t + 0.625 * (3.0 * t * t - 1.0)) / (4.0 * std::f32::consts::PI)
}

/// `c·s`, coefficient by coefficient.
#[inline]
#[must_use]
pub fn scaled(c: &Sh2, s: f32) -> Sh2 {
    c.map(|v| v * s)
}

/// `a + b`, coefficient by coefficient.
#[inline]
#[must_use]
pub fn add(a: &Sh2, b: &Sh2) -> Sh2 {
    std::array::from_fn(|i| a[i] + b[i])
}

#[cfg(test)]
mod tests {
    use std::f32::consts::PI;

    use glam::Vec2;

    use super::*;
    use crate::sampling::hammersley;

    /// Uniform direction on the sphere from a point of the unit square.
    fn sphere(u: Vec2) -> Vec3 {
        let z = 1.0 - 2.0 * u.x;
        let r = (1.0 - z * z).max(0.0).sqrt();
        let phi = 2.0 * PI * u.y;
        Vec3::new(r * phi.cos(), r * phi.sin(), z)
    }

    /// Coefficients of radiance `l(ω)` over the sphere, by a dense Hammersley rule (summed in
    /// f64: 2¹⁸ f32 additions of small terms would drift by a percent).
    fn project_sphere(l: impl Fn(Vec3) -> f32) -> Sh2 {
        let n = 1 << 18;
        let mut sum = [0.0f64; 9];
        for k in 0..n {
            let d = sphere(hammersley(k, n, Vec2::ZERO));
            let w = f64::from(l(d)) * 4.0 * std::f64::consts::PI / f64::from(n);
            for (s, y) in sum.iter_mut().zip(basis(d)) {
                *s += w * f64::from(y);
            }
        }
        sum.map(|s| Vec3::splat(s as f32))
    }

    #[test]
    fn the_basis_is_orthonormal() {
        for i in 0..9 {
            for j in 0..9 {
                let c = project_sphere(|d| basis(d)[i]);
                let expected = if i == j { 1.0 } else { 0.0 };
                assert!(
                    (c[j].x - expected).abs() < 2e-3,
                    "<Y{i}, Y{j}> = {}",
                    c[j].x
                );
            }
        }
    }

    #[test]
    fn uniform_radiance_gives_its_value_for_every_normal() {
        // E = π·L for every normal: E/π = L.
        let c = project_sphere(|_| 2.0);
        for n in [Vec3::X, Vec3::NEG_Y, Vec3::new(0.6, 0.0, 0.8)] {
            assert!((irradiance_over_pi(&c, n).x - 2.0).abs() < 1e-3);
        }
    }

    #[test]
    fn a_hemisphere_of_light_is_close_to_the_closed_form() {
        // Unit radiance from the +Z hemisphere: E(θ)/π = (1 + cos θ)/2 exactly (bands 0 and
        // 1 only, band 2 of this radiance is zero).
        let c = project_sphere(|d| if d.z > 0.0 { 1.0 } else { 0.0 });
        for deg in [0.0f32, 45.0, 90.0, 135.0, 180.0] {
            let t = deg.to_radians();
            let n = Vec3::new(t.sin(), 0.0, t.cos());
            let e = irradiance_over_pi(&c, n).x;
            assert!((e - (1.0 + t.cos()) / 2.0).abs() < 3e-3, "{deg}°: {e}");
        }
    }

    #[test]
    fn one_direction_is_within_the_l2_truncation_of_the_cosine() {
        // Flux density 1 along +Z: exact E = cos θ for θ < 90°. L2 truncation is within 6%
        // of the flux density at every angle (largest where the cosine has its kink).
        let mut c = [Vec3::ZERO; 9];
        project(&mut c, Vec3::Z, Vec3::ONE);
        for deg in [0.0f32, 30.0, 60.0, 90.0, 120.0, 180.0] {
            let t = deg.to_radians();
            let n = Vec3::new(t.sin(), 0.0, t.cos());
            let e = irradiance_over_pi(&c, n).x * PI;
            assert!((e - t.cos().max(0.0)).abs() < 0.1, "{deg}°: {e}");
        }
        // Along the direction itself: 1/4·(1 + 2 + 5/4)·... = 0.25 + 0.5 + 0.3125 = 1.0625.
        let e0 = irradiance_over_pi(&c, Vec3::Z).x * PI;
        assert!((e0 - (0.25 + 0.5 + 0.3125)).abs() < 1e-3, "{e0}");
    }

    #[test]
    fn the_kernel_is_the_irradiance_of_one_projected_direction() {
        let d = Vec3::new(0.36, 0.48, 0.8);
        let mut c = [Vec3::ZERO; 9];
        project(&mut c, d, Vec3::ONE);
        // Normals where the projection's irradiance is positive (the kernel is unclamped).
        for n in [d, Vec3::X, Vec3::Y, Vec3::Z, -d] {
            let e = irradiance_over_pi(&c, n).x;
            assert!((e - kernel(n.dot(d))).abs() < 1e-5, "{n}: {e}");
        }
        // Uniform radiance: ∫ k dω = 1 (only band 0 survives).
        let n = 1 << 12;
        let sum: f32 = (0..n)
            .map(|k| kernel(1.0 - 2.0 * (k as f32 + 0.5) / n as f32) * 4.0 * PI / n as f32)
            .sum();
        assert!((sum - 1.0).abs() < 1e-4, "{sum}");
    }

    #[test]
    fn three_js_irradiance_is_ours_times_pi() {
        // three.js getIrradianceAt constants: 0.886227 = π·0.282095, 2·0.511664 = 2π/3·0.488603,
        // 2·0.429043 = π/4·1.092548, 0.743125 = π/4·0.315392·3, 0.247708 = π/4·0.315392.
        let c: Sh2 = std::array::from_fn(|i| Vec3::splat(0.1 * (i as f32 + 1.0)));
        let n = Vec3::new(0.36, 0.48, 0.8);
        let (x, y, z) = (n.x, n.y, n.z);
        let three = 0.886227 * c[0].x
            + 2.0 * 0.511664 * (c[1].x * y + c[2].x * z + c[3].x * x)
            + 2.0 * 0.429043 * (c[4].x * x * y + c[5].x * y * z + c[7].x * x * z)
            + c[6].x * (0.743125 * z * z - 0.247708)
            + 0.429043 * c[8].x * (x * x - y * y);
        assert!((irradiance_over_pi(&c, n).x * PI - three).abs() < 1e-4);
    }
}
