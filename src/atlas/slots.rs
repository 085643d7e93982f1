//! Slot faces get texels at the scale of the slot's gap (issue 27, item 3).
//!
//! A face with another surface facing it (normals opposed within 30°) from a gap `g` narrower
//! than a texel is a slot face: a door's edge 3 mm from its lining and the lining under it, a
//! ceiling light's side 2 cm from its recess wall. Light enters at the slot's mouth and falls
//! by about e over a length of the order of `g` (measured on `fixtures/narrow_faces.gltf`'s
//! 3 mm door slot: 0.15 at the mouth, 0.05 at 4 mm, 0.009 at 14 mm, an e-fold every 1.2–1.9
//! gaps). A texel of size `s` holds the mean over its footprint, and a renderer's bilinear
//! lookup between texel centres `s` apart on a falloff `e^(−x/L)` over-reads by up to
//! `cosh(s/2L)` midway, the footprint's mean another `sinh(s/2L)/(s/2L)`: about 1.13 × 1.04 at
//! `s = L`, 1.54 × 1.18 ≈ 1.8 at `s = 2L`, past the 1.5× the issue allows. So a slot face's
//! texels are at most the gap wide: its density factor is `texel / g` (rounded up to a
//! quarter octave), which is 1 at a gap of one texel, where near contacts begin.
//!
//! Bounds: at most ×[`MAX_FACTOR`] the preset's density (a 1 mm gap at draft would ask for
//! ×125), and the slot faces together add at most [`MAX_TEXEL_SHARE`] × the uniform atlas's
//! texels (the cap is lowered a quarter octave at a time until they do), so a scene full of
//! narrow gaps costs at most twice its texels.
//!
//! Found by rays: from the centroid of each triangle and the points halfway to its corners,
//! along its normal, up to a texel; the centroid's ray must find a facing front face, and the
//! gap is the nearest such hit. Gaps of at most two ray epsilons are contacts (a box standing
//! on a floor), not slots. Run on the split scene with near contacts only
//! (`AtlasParams::near_contacts`): their cuts make the slot's faces triangles of their own, so
//! the raise stays inside the slot; without them a triangle reaching into a slot would raise
//! a whole wall.

use glam::Vec3;
use rayon::prelude::*;

use crate::scene::Scene;
use crate::trace::Tracer;

/// Normals opposed at least this much (cosine of 30°) face each other, as near contacts do.
const FACING_DOT: f32 = 0.866;
/// Slot faces rise at most this far above the preset's density.
pub(crate) const MAX_FACTOR: f32 = 16.0;
/// Slot faces add at most this many texels, as a share of the uniform atlas's.
pub(crate) const MAX_TEXEL_SHARE: f64 = 1.0;
/// Factors on quarter-octave steps, like the density plan's (few distinct densities: few
/// xatlas meshes).
const STEPS_PER_OCTAVE: f32 = 4.0;

/// What [`density`] raised.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SlotReport {
    /// Slot-face triangles raised, and their world area (m²).
    pub triangles: usize,
    pub area: f64,
    /// The narrowest gap found (world units) and the largest factor given.
    pub min_gap: f32,
    pub max_factor: f32,
    /// Texels the raise adds at the preset's density (before packing).
    pub added_texels: f64,
    /// The cap the texel share forced below [`MAX_FACTOR`], if it did.
    pub capped: Option<f32>,
}

impl SlotReport {
    /// One phrase for the junction report: the rule and what it did.
    pub fn brief(&self) -> String {
        if self.triangles == 0 {
            return "slot faces: none (a texel no wider than a near contact's gap)".into();
        }
        format!(
            "slot faces: {} triangles ({:.3} m², gaps from {:.1} mm) raised to a texel no wider \
             than their gap, up to ×{:.1} (cap ×{}{}), about +{:.0} texels",
            self.triangles,
            self.area,
            self.min_gap * 1e3,
            self.max_factor,
            MAX_FACTOR,
            self.capped.map_or(String::new(), |c| format!(
                ", lowered to ×{c:.1} to add at most ×{MAX_TEXEL_SHARE} the uniform atlas's texels"
            )),
            self.added_texels
        )
    }
}

/// The density factor of every scene triangle from its slot's gap (see the module docs) at
/// `tpu` texels per unit, with near contacts reaching `near` (world units); empty when no
/// triangle is raised.
pub(crate) fn density(
    scene: &Scene,
    tracer: &Tracer,
    tpu: f32,
    near: f32,
) -> (Vec<f32>, SlotReport) {
    let texel = 1.0 / tpu;
    let gaps: Vec<f32> = (0..scene.triangles.len() as u32)
        .into_par_iter()
        .map(|t| gap(scene, tracer, t, near))
        .collect();
    let raw: Vec<f32> = gaps
        .iter()
        .map(|&g| {
            if g.is_finite() {
                quantise(texel / g)
            } else {
                1.0
            }
        })
        .collect();
    // Texels added at a cap: Σ A·tpu²·(f² − 1) over the raised triangles.
    let area = |t: usize| scene.triangle_area(t);
    let per_area = f64::from(tpu).powi(2);
    let added = |cap: f32| -> f64 {
        let raise = |f: f32| f64::from(f.min(cap)).powi(2) - 1.0;
        let raised = raw.iter().enumerate().filter(|&(_, &f)| f > 1.0);
        raised.map(|(t, &f)| area(t) * per_area * raise(f)).sum()
    };
    let uniform: f64 = (0..scene.triangles.len()).map(area).sum::<f64>() * per_area;
    let mut cap = MAX_FACTOR;
    while cap > 1.0 && added(cap) > MAX_TEXEL_SHARE * uniform {
        cap = quantise(cap / 2f32.powf(1.0 / STEPS_PER_OCTAVE));
    }
    let factors: Vec<f32> = raw.iter().map(|&f| f.min(cap)).collect();
    let mut report = SlotReport {
        min_gap: f32::INFINITY,
        added_texels: added(cap),
        capped: (cap < MAX_FACTOR).then_some(cap),
        ..Default::default()
    };
    for (t, &f) in factors.iter().enumerate() {
        if f > 1.0 {
            report.triangles += 1;
            report.area += area(t);
            report.min_gap = report.min_gap.min(gaps[t]);
            report.max_factor = report.max_factor.max(f);
        }
    }
    if report.triangles == 0 {
        return (Vec::new(), SlotReport::default());
    }
    (factors, report)
}

/// `f` rounded up to a quarter octave; 1 for at most 1.
fn quantise(f: f32) -> f32 {
    if f <= 1.0 {
        return 1.0;
    }
    let steps = (f.log2() * STEPS_PER_OCTAVE - 1e-4).ceil();
    2f32.powf(steps / STEPS_PER_OCTAVE)
}

/// The gap in front of scene triangle `t`: the nearest facing front face within `near` along
/// its normal from its centroid and the points halfway to its corners, when the centroid's ray
/// finds one; infinite otherwise.
fn gap(scene: &Scene, tracer: &Tracer, t: u32, near: f32) -> f32 {
    let [a, b, c] = scene.triangles[t as usize].map(|v| scene.positions[v as usize]);
    let n = (b - a).cross(c - a).normalize_or_zero();
    if n == Vec3::ZERO {
        return f32::INFINITY;
    }
    let eps = tracer.epsilon;
    let centroid = (a + b + c) / 3.0;
    let facing_at = |p: Vec3| -> Option<f32> {
        let hit = tracer.closest(p + n * eps, n, near)?;
        let [u0, u1, u2] =
            scene.triangles[hit.triangle as usize].map(|v| scene.positions[v as usize]);
        let m = (u1 - u0).cross(u2 - u0).normalize_or_zero();
        let g = hit.t + eps;
        (hit.front && m.dot(n) <= -FACING_DOT && g > 2.0 * eps).then_some(g)
    };
    let Some(mut g) = facing_at(centroid) else {
        return f32::INFINITY;
    };
    for corner in [a, b, c] {
        if let Some(h) = facing_at(0.5 * (centroid + corner)) {
            g = g.min(h);
        }
    }
    g
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn factors_round_up_to_quarter_octaves() {
        assert_eq!(quantise(0.5), 1.0);
        assert_eq!(quantise(1.0), 1.0);
        assert!((quantise(2.0) - 2.0).abs() < 1e-5);
        let f = quantise(4.17);
        assert!(f >= 4.17 && f < 4.17 * 2f32.powf(0.25), "{f}");
    }
}
