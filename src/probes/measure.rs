//! How the probes are measured against the path tracer: where the points are drawn, which of
//! them lie in an emitter's near field, and the error reported over each part.
//!
//! **Points.** Uniform in the scene's bounds with uniform random unit normals, points buried in
//! geometry (the probes' own test) drawn again: the free space a moving object can be in,
//! whatever the probe layout (so layouts are compared at the same points), the slab between the
//! outermost probes and the walls included.
//!
//! **Near field.** A point closer to an emitter (an emissive texel, a point or spot light) than
//! the spacing a uniform grid of the budget would have, `∛(bounds volume / budget)`, is *near*.
//! There irradiance changes by a large factor within one spacing (≈ 1/r² beside a small lamp,
//! the edge of a panel's solid angle under it), which no probe volume resolves: Unity's light
//! probe groups, Unreal's volumetric lightmaps, Godot's and Bevy's volumes all interpolate L2 SH
//! between probes tens of centimetres apart. A moving object's centre is seldom there, yet a few
//! such points (irradiance up to 20× the mean) rule a relative RMSE over all points. So the
//! error is reported three ways: over all points, over the far ones, and over the near ones
//! (each relative RMSE over its own points' mean, the reference's noise taken out). The
//! distance is the budget's (not the layout's local spacing), so every layout of one budget
//! splits the same points alike.

use glam::Vec3;

use super::place;
use crate::metrics;
use crate::scene::{LightKind, Scene};
use crate::texels::Texels;
use crate::trace::Tracer;

/// Mixed into the seed: the measuring points' streams differ from the probes'.
const SALT: u64 = 0x4d45_4153_5552; // "MEASUR"

/// `n` random points of the scene's free space, each with a random unit normal (see the module
/// docs); point `k` comes from its own random stream `(seed, k)`. Fewer when free space is
/// almost nowhere in the bounds.
#[must_use]
pub fn free_space_points(scene: &Scene, tracer: &Tracer, n: usize, seed: u64) -> Vec<(Vec3, Vec3)> {
    let Some((lo, hi)) = place::bounds(scene) else {
        return Vec::new();
    };
    place::free_points(tracer, n, seed ^ SALT, |u| lo + (hi - lo) * u, |_| true)
}

/// The near-field distance for `budget` probes in `scene`: the spacing of a uniform grid of
/// `budget` probes over its bounds (see the module docs).
#[must_use]
pub fn near_field(scene: &Scene, budget: u32) -> f32 {
    let (lo, hi) = place::bounds(scene).unwrap_or((Vec3::ZERO, Vec3::ZERO));
    place::grid(lo, hi, budget).1.min_element()
}

/// Distance from `p` to the nearest emitter: an emissive texel's sample point, a point or a
/// spot light (infinite without any).
#[must_use]
pub fn emitter_distance(scene: &Scene, texels: &Texels, p: Vec3) -> f32 {
    let texel = (0..texels.position.len())
        .filter(|&i| texels.emission[i].max_element() > 0.0)
        .map(|i| texels.position[i].distance(p));
    let light = (scene.lights.iter())
        .filter(|l| !matches!(l.kind, LightKind::Directional))
        .map(|l| l.position.distance(p));
    texel.chain(light).fold(f32::INFINITY, f32::min)
}

/// Indices of the points of `at` closer than `distance` to an emitter ([`emitter_distance`]).
#[must_use]
pub fn near_emitters(scene: &Scene, texels: &Texels, at: &[Vec3], distance: f32) -> Vec<u32> {
    (0..at.len() as u32)
        .filter(|&k| emitter_distance(scene, texels, at[k as usize]) < distance)
        .collect()
}

/// The probes' error at a set of points, over all of them and over the far and near ones apart:
/// relative RMSE over the part's own mean, the reference's noise taken out.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SplitError {
    /// Over every point.
    pub all: f32,
    /// Over the points outside the near field.
    pub far: f32,
    /// Over the points in the near field (0 with none).
    pub near: f32,
    /// Points in the near field.
    pub near_points: usize,
    /// The reference's relative noise over every point.
    pub noise: f32,
}

/// [`SplitError`] of `ours` against the reference `mean` ± `std_error`, `near` the indices of
/// the near points.
#[must_use]
pub fn split_error(ours: &[Vec3], mean: &[Vec3], std_error: &[Vec3], near: &[u32]) -> SplitError {
    let error = |skip: &[u32]| {
        let rmse = metrics::rmse_over_mean(ours, mean, skip);
        let noise = metrics::noise_over_mean(std_error, mean, skip);
        metrics::without_noise(rmse, noise)
    };
    let far: Vec<u32> = (0..ours.len() as u32)
        .filter(|k| near.binary_search(k).is_err())
        .collect();
    SplitError {
        all: error(&[]),
        far: error(near),
        near: if near.is_empty() { 0.0 } else { error(&far) },
        near_points: near.len(),
        noise: metrics::noise_over_mean(std_error, mean, &[]),
    }
}
