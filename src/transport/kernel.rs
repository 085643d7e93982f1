//! Form-factor kernels: pure functions of geometry, no visibility, no scene.
//!
//! | kernel                          | formula                                                           |
//! |---------------------------------|-------------------------------------------------------------------|
//! | [`point_to_point`]              | `cosθ_i cosθ_j A_j / (π r²)` — unbounded as r → 0                 |
//! | [`point_to_disk_bound`]         | `A_j / (π r² + A_j)` — a coaxial facing disk of area `A_j`, ≤ 1   |
//! | `point_to_polygon`            | Lambert: `(1/2π) Σ_e γ_e n·(R_e × R_e+1)/‖R_e × R_e+1‖`           |
//! | [`parallel_rectangles`]         | Howell C-11, directly opposed rectangles                          |
//! | [`perpendicular_rectangles`]    | Howell C-14, perpendicular rectangles sharing an edge             |
//! | [`point_to_coaxial_disk`]       | `R² / (R² + h²)`                                                  |
//! | `coaxial_disks`               | Howell C-41, coaxial parallel disks                               |
//!
//! The first three are what the `point` and `polygon` methods evaluate per texel pair; the closed
//! forms from Howell's catalogue (*A Catalog of Radiation Heat Transfer Configuration Factors*)
//! are the yardsticks the tests hold them to. The closed forms work in f64: they are references.

use std::f32::consts::PI;
use std::f64::consts::PI as PI64;

use glam::Vec3;

/// Differential form factor from the point `x_i` (unit normal `n_i`) to a small patch of area
/// `a_j` at `x_j` (unit normal `n_j`): `cosθ_i cosθ_j a_j / (π r²)`, 0 when either faces away.
///
/// Accurate only when `r` is large against the patch size: it grows like 1/r² and is not
/// bounded by 1, so rows of adjacent texels at a corner sum to more than 1.
#[inline]
#[must_use]
pub fn point_to_point(x_i: Vec3, n_i: Vec3, x_j: Vec3, n_j: Vec3, a_j: f32) -> f32 {
    let d = x_j - x_i;
    let r2 = d.length_squared();
    if r2 <= 0.0 {
        return 0.0;
    }
    let cos_i = n_i.dot(d);
    let cos_j = -n_j.dot(d);
    if cos_i <= 0.0 || cos_j <= 0.0 {
        return 0.0;
    }
    // cos_i and cos_j above are both scaled by r: divide by r⁴ in all.
    cos_i * cos_j * a_j / (PI * r2 * r2)
}

/// The form factor from a point to a facing coaxial disk of area `a_j` at distance `r`,
/// `R²/(R² + r²)` with `πR² = a_j`: the largest a patch of that area can subtend at that
/// distance when seen head-on. Bounded by 1, so it caps [`point_to_point`] near r = 0.
#[inline]
#[must_use]
pub fn point_to_disk_bound(r2: f32, a_j: f32) -> f32 {
    let d = PI * r2 + a_j;
    if d > 0.0 { a_j / d } else { 0.0 }
}

/// Form factor from the point `x` (unit normal `n`) to the planar polygon `vertices`, by
/// Lambert's contour integral
///
/// ```text
///   F = (1/2π) Σ_e γ_e · n·(R_e × R_e+1)/‖R_e × R_e+1‖,   R_e = v_e − x,
/// ```
///
/// `γ_e` the angle between `R_e` and `R_e+1`. The polygon is first clipped to the half-space in
/// front of `x` (`n·(v − x) > 0`): a polygon reaching below the horizon would otherwise count
/// its hidden part with the wrong sign. Either winding gives the same value (the sum is taken
/// in absolute value), so the kernel does not know or care which side of the source emits;
/// callers check that. No allocation: clipping streams the vertices (Sutherland–Hodgman).
#[inline]
#[must_use]
pub(crate) fn point_to_polygon(x: Vec3, n: Vec3, vertices: &[Vec3]) -> f32 {
    let Some(&last) = vertices.last() else {
        return 0.0;
    };
    let height = |v: Vec3| n.dot(v - x);
    let mut contour = Contour::default();
    let (mut a, mut h_a) = (last - x, height(last));
    for &v in vertices {
        let (b, h_b) = (v - x, height(v));
        if (h_a > 0.0) != (h_b > 0.0) {
            // The edge crosses the horizon: its crossing point is a vertex of the clipped polygon.
            let t = h_a / (h_a - h_b);
            let p = a + (b - a) * t;
            contour.push(p - n * n.dot(p), n);
        }
        if h_b > 0.0 {
            contour.push(b, n);
        }
        (a, h_a) = (b, h_b);
    }
    contour.close(n);
    (contour.sum.abs() / (2.0 * PI)).min(1.0)
}

/// The running contour sum of [`point_to_polygon`] over the streamed clipped vertices.
#[derive(Default)]
struct Contour {
    first: Option<Vec3>,
    previous: Option<Vec3>,
    sum: f32,
}

impl Contour {
    #[inline]
    fn push(&mut self, r: Vec3, n: Vec3) {
        match self.previous {
            Some(p) => self.sum += edge_term(p, r, n),
            None => self.first = Some(r),
        }
        self.previous = Some(r);
    }

    #[inline]
    fn close(&mut self, n: Vec3) {
        if let (Some(first), Some(last)) = (self.first, self.previous) {
            self.sum += edge_term(last, first, n);
        }
    }
}

/// One edge of the contour integral: `γ · n·(a × b)/‖a × b‖`, with γ the angle from `a` to `b`.
#[inline]
fn edge_term(a: Vec3, b: Vec3, n: Vec3) -> f32 {
    let c = a.cross(b);
    let sin = c.length();
    if sin <= 0.0 {
        return 0.0; // degenerate edge, or one through x: it subtends nothing
    }
    let gamma = sin.atan2(a.dot(b));
    gamma * n.dot(c) / sin
}

/// Howell C-11: from one `a × b` rectangle to a directly opposed, parallel, identical one at
/// distance `c`.
#[must_use]
pub fn parallel_rectangles(a: f64, b: f64, c: f64) -> f64 {
    let (x, y) = (a / c, b / c);
    let (x2, y2) = (x * x, y * y);
    let log = 0.5 * ((1.0 + x2) * (1.0 + y2) / (1.0 + x2 + y2)).ln();
    let sx = (1.0 + x2).sqrt();
    let sy = (1.0 + y2).sqrt();
    2.0 / (PI64 * x * y)
        * (log + x * sy * (x / sy).atan() + y * sx * (y / sx).atan() - x * x.atan() - y * y.atan())
}

/// Howell C-14: from a rectangle of width `w` to a perpendicular rectangle of height `h`, both
/// sharing an edge of length `l`.
#[must_use]
pub fn perpendicular_rectangles(w: f64, h: f64, l: f64) -> f64 {
    let (hh, ww) = (h / l, w / l);
    let (h2, w2) = (hh * hh, ww * ww);
    let s = (h2 + w2).sqrt();
    let log = ((1.0 + w2) * (1.0 + h2) / (1.0 + w2 + h2)).ln()
        + w2 * (w2 * (1.0 + w2 + h2) / ((1.0 + w2) * (w2 + h2))).ln()
        + h2 * (h2 * (1.0 + h2 + w2) / ((1.0 + h2) * (h2 + w2))).ln();
    (ww * (1.0 / ww).atan() + hh * (1.0 / hh).atan() - s * (1.0 / s).atan() + 0.25 * log)
        / (PI64 * ww)
}

/// From a differential area to a parallel coaxial disk of radius `r` at height `h`.
#[must_use]
pub fn point_to_coaxial_disk(r: f64, h: f64) -> f64 {
    r * r / (r * r + h * h)
}

/// Howell C-41: from a disk of radius `r1` to a parallel coaxial disk of radius `r2` at
/// distance `h`.
#[cfg(test)]
#[must_use]
pub(crate) fn coaxial_disks(r1: f64, r2: f64, h: f64) -> f64 {
    let (a, b) = (r1 / h, r2 / h);
    let x = 1.0 + (1.0 + b * b) / (a * a);
    0.5 * (x - (x * x - 4.0 * (b / a).powi(2)).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A regular `sides`-gon of radius `r` centred at `c` in the plane z = c.z, with the area of
    /// the disk of radius `r` (so it stands in for the disk to second order).
    fn disk(c: Vec3, r: f32, sides: u32) -> Vec<Vec3> {
        let step = 2.0 * PI / sides as f32;
        let area_ratio = sides as f32 * step.sin() / (2.0 * PI);
        let rr = r / area_ratio.sqrt();
        (0..sides)
            .map(|k| c + rr * Vec3::new((k as f32 * step).cos(), (k as f32 * step).sin(), 0.0))
            .collect()
    }

    #[test]
    fn closed_forms_match_the_catalogue_values() {
        let close = |got: f64, want: f64| (got - want).abs() < 5e-5;
        assert!(close(parallel_rectangles(1.0, 1.0, 1.0), 0.19982));
        assert!(close(parallel_rectangles(1.0, 1.0, 2.0), 0.06859));
        assert!(close(parallel_rectangles(1.0, 1.0, 0.5), 0.41525));
        assert!(close(parallel_rectangles(1.0, 1.5, 0.5), 0.47558));
        assert!(close(perpendicular_rectangles(1.0, 1.0, 1.0), 0.20004));
        assert!(close(coaxial_disks(0.1, 0.2, 0.5), 0.13393));
        assert!(close(point_to_coaxial_disk(1.0, 1.0), 0.5));
    }

    #[test]
    fn contour_integral_of_a_coaxial_disk() {
        for (r, h) in [(1.0f32, 1.0f32), (0.3, 2.0), (2.0, 0.25)] {
            let polygon = disk(Vec3::new(0.0, 0.0, h), r, 256);
            let want = point_to_coaxial_disk(r as f64, h as f64) as f32;
            let up = point_to_polygon(Vec3::ZERO, Vec3::Z, &polygon);
            assert!(
                (up - want).abs() / want < 1e-3,
                "r {r} h {h}: {up} vs {want}"
            );
            // Reversed winding: same value.
            let reversed: Vec<Vec3> = polygon.iter().rev().copied().collect();
            let down = point_to_polygon(Vec3::ZERO, Vec3::Z, &reversed);
            assert!((down - up).abs() < 1e-6);
        }
    }

    /// The differential factor at the centre of a unit square's opposite, by integrating the
    /// point-to-point kernel finely, against the contour integral of the whole square.
    #[test]
    fn contour_integral_of_a_square_matches_the_integrated_kernel() {
        let h = 0.5f32;
        let square = [
            Vec3::new(-0.5, -0.5, h),
            Vec3::new(0.5, -0.5, h),
            Vec3::new(0.5, 0.5, h),
            Vec3::new(-0.5, 0.5, h),
        ];
        let exact = point_to_polygon(Vec3::ZERO, Vec3::Z, &square);
        let m = 400;
        let cell = 1.0 / m as f32;
        let mut sum = 0.0f64;
        for a in 0..m {
            for b in 0..m {
                let p = Vec3::new(
                    -0.5 + (a as f32 + 0.5) * cell,
                    -0.5 + (b as f32 + 0.5) * cell,
                    h,
                );
                sum += point_to_point(Vec3::ZERO, Vec3::Z, p, -Vec3::Z, cell * cell) as f64;
            }
        }
        assert!((exact as f64 - sum).abs() / sum < 1e-4, "{exact} vs {sum}");
        // Closed form for a point at the centre below a 2a × 2b rectangle (Howell B-3 with
        // four quarter rectangles): 4 · (1/2π)[X/√(1+X²) atan(Y/√(1+X²)) + Y/√(1+Y²) atan(X/√(1+Y²))].
        let x = 0.5f64 / h as f64;
        let s = (1.0 + x * x).sqrt();
        let quarter = (x / s * (x / s).atan() * 2.0) / (2.0 * PI64);
        assert!(
            (exact as f64 - 4.0 * quarter).abs() < 1e-5,
            "{exact} vs {}",
            4.0 * quarter
        );
    }

    #[test]
    fn a_polygon_below_the_horizon_is_clipped() {
        // A vertical unit square standing on the receiver's plane, beside it: half of it below.
        let wall = |z0: f32| {
            [
                Vec3::new(1.0, -0.5, z0),
                Vec3::new(1.0, 0.5, z0),
                Vec3::new(1.0, 0.5, z0 + 1.0),
                Vec3::new(1.0, -0.5, z0 + 1.0),
            ]
        };
        let above = point_to_polygon(Vec3::ZERO, Vec3::Z, &wall(0.0));
        let straddling = point_to_polygon(Vec3::ZERO, Vec3::Z, &wall(-0.5));
        let upper_half = [
            Vec3::new(1.0, -0.5, 0.0),
            Vec3::new(1.0, 0.5, 0.0),
            Vec3::new(1.0, 0.5, 0.5),
            Vec3::new(1.0, -0.5, 0.5),
        ];
        let want = point_to_polygon(Vec3::ZERO, Vec3::Z, &upper_half);
        assert!(above > 0.0 && straddling > 0.0);
        assert!((straddling - want).abs() < 1e-6, "{straddling} vs {want}");
        let below = point_to_polygon(Vec3::ZERO, Vec3::Z, &wall(-2.0));
        assert_eq!(below, 0.0);
    }

    #[test]
    fn point_kernel_is_unbounded_and_the_disk_bound_is_not() {
        let a_j = 1.0;
        let near = point_to_point(Vec3::ZERO, Vec3::Z, Vec3::new(0.0, 0.0, 0.1), -Vec3::Z, a_j);
        assert!(near > 10.0);
        assert!(point_to_disk_bound(0.01, a_j) < 1.0);
        // Far away both agree.
        let far = point_to_point(
            Vec3::ZERO,
            Vec3::Z,
            Vec3::new(0.0, 0.0, 30.0),
            -Vec3::Z,
            a_j,
        );
        let bound = point_to_disk_bound(900.0, a_j);
        assert!((far - bound).abs() / far < 1e-3);
    }
}
