//! The reference's probe mode: the L2 spherical-harmonic irradiance a light probe at a point of
//! free space would hold, path-traced, with a standard error — the yardstick for baked probes
//! that leaves out what no L2 probe can hold.
//!
//! A probe stores the projection of the incident radiance on bands 0–2 (`crate::probes::sh`);
//! an engine reads irradiance about a normal `n` from it. For light from a small source that
//! differs from the true irradiance by up to a tenth of its flux density (the truncation of the
//! clamped cosine), so a probe can be exact and still read several percent from
//! [`super::points::trace_about`]'s irradiance. This mode estimates the probe's own quantity:
//!
//! ```text
//!   E₂(n)/π = ∫ L_in(x, ω)·k(n·ω) dω,   k(t) = (1 + 2t + (5/8)(3t² − 1))/(4π)
//! ```
//!
//! (`crate::probes::sh::kernel`: the L2 projection's irradiance of one direction), clamped at
//! zero as the probes' lookup clamps it. Against both references, the difference between the
//! two figures is L2's truncation and the rest is the probes' own (gather noise, the bake's
//! error, interpolation between probes).
//!
//! Each sample at `(x, n)` is one direction `ω` — cosine-distributed about `n` or uniform over
//! the sphere, even odds (the kernel is large in front of `n`, small and partly negative behind;
//! on `two_rooms`' free-space points the mixture's noise is 0.7× the sphere's alone) — and one
//! light sample of the small emitters, combined by the power heuristic (as the probes' gather
//! and the texel mode do); where `ω` hits a texel `j` from the front, `L_in = Le_j`
//! (MIS-weighted) plus `ρ_j` times one path of the texel mode's estimator of `H/π` started
//! there (next-event estimation at every vertex, Russian roulette); rays that escape see the
//! sky, the back of a single-sided surface absorbs. Punctual lights add `F·k(n·l)` (their flux density `F` along their direction `l`)
//! unless `no_punctual_direct`. Light reaching `x` directly from emitters and the sky always
//! counts, as in the probes. Like the probes' gather and the texel mode, hits read the texels'
//! `ρ` and `Le`, so the difference is the probes' error, not texture resolution. Random streams
//! are seeded by (seed, point, sample): the result does not depend on the thread count.

use std::f32::consts::PI;

use glam::{Vec2, Vec3};

use super::{ItemSample, Reference, ReferenceParams, SEED_SALT, trace_items};
use crate::lights::{punctual_irradiance, triangle_point};
use crate::probes::sh::kernel;
use crate::sampling::{Rng, cosine_hemisphere, frame, power_weight, uniform_sphere};
use crate::scene::{LightKind, Scene};
use crate::texels::{RayEnd, Texels};
use crate::trace::Tracer;
use crate::{Progress, Result};

/// Mixed into the seed so point streams differ from texel and pixel streams of the same index.
const PROBE_SALT: u64 = 0x0050_524f_4245; // "PROBE"

/// Path-traces the L2 irradiance over π at each point of `at` (position in free space, unit
/// normal) until a stopping rule of `params` holds (`max_samples` is samples per point).
pub fn trace_sh(
    (scene, texels, tracer): (&Scene, &Texels, &Tracer),
    at: &[(Vec3, Vec3)],
    params: &ReferenceParams,
    progress: &dyn Progress,
) -> Result<Reference> {
    // The paths start one bounce from `x`: `no_punctual_direct` is this mode's own choice at
    // `x`; the texel mode's `indirect_only` stays, as the bake's `H` at the hit leaves direct
    // light out alike.
    let paths_params = ReferenceParams {
        no_punctual_direct: false,
        ..params.clone()
    };
    let punctual = !params.no_punctual_direct;
    let sample: &ItemSample = &|paths, i, sample, rays| {
        let (x, n) = at[i];
        let mut rng = Rng::new(
            params.seed ^ SEED_SALT ^ PROBE_SALT,
            i as u64,
            sample as u64,
        );
        let mut e = Vec3::ZERO;
        let (dir, p_dir) = direction(n, rng.next_f32(), rng.next_vec2());
        *rays += 1;
        match texels.ray_end(tracer, x, dir) {
            RayEnd::Escaped => e += paths.params.sky * kernel(n.dot(dir)) / p_dir,
            RayEnd::Texel(hit, j) => {
                let j = j as usize;
                let (p, n_hit) = triangle_point(scene, hit.triangle, hit.bary);
                let mut l = Vec3::ZERO;
                let le = texels.emission[j];
                if le.max_element() > 0.0 {
                    let p_light = paths.emitters.pdf_toward(hit.triangle, n_hit, dir, hit.t);
                    l += le * (p_dir * power_weight(p_dir, p_light));
                }
                let rho = texels.albedo[j];
                if rho.max_element() > 0.0 && n_hit != Vec3::ZERO {
                    let from = p + n_hit * tracer.epsilon;
                    l += rho * paths.reflected(from, n_hit, None, &mut rng, rays);
                }
                e += l * kernel(n.dot(dir)) / p_dir;
            }
            RayEnd::Absorbed => {}
        }
        if !paths.emitters.is_empty() {
            *rays += 1;
            let u = rng.next_vec2();
            if let Some(s) = (paths.emitters).sample_from((scene, texels, tracer), x, None, u) {
                let toward = (s.point - x) / s.r2.sqrt();
                let w = power_weight(s.pdf_solid_angle(), direction_pdf(n, toward));
                e += s.le * (w * kernel(n.dot(toward)));
            }
        }
        for light in scene.lights.iter().filter(|_| punctual) {
            let l = match light.kind {
                LightKind::Directional => -light.direction,
                _ => (light.position - x).normalize_or_zero(),
            };
            *rays += 1;
            // About its own direction the light's irradiance is its flux density.
            e += punctual_irradiance(light, x, l, tracer) * kernel(n.dot(l));
        }
        if e.is_finite() { e } else { Vec3::ZERO }
    };
    let mut r = trace_items(
        (scene, texels, tracer),
        at.len(),
        &paths_params,
        progress,
        "reference probes",
        sample,
    )?;
    // The probes' lookup clamps at zero; the estimate of a mean that is negative reads zero.
    for m in &mut r.mean {
        *m = m.max(Vec3::ZERO);
    }
    Ok(r)
}

/// A direction for the estimate about normal `n`: with probability ½ cosine-distributed about
/// `n` (where the kernel is large), else uniform over the sphere (its back lobe and ringing);
/// the direction and its density under the mixture ([`direction_pdf`]).
fn direction(n: Vec3, pick: f32, u: Vec2) -> (Vec3, f32) {
    let dir = if pick < 0.5 {
        let (tx, ty) = frame(n);
        let local = cosine_hemisphere(u);
        (tx * local.x + ty * local.y + n * local.z).normalize()
    } else {
        uniform_sphere(u)
    };
    (dir, direction_pdf(n, dir))
}

/// Density of [`direction`]'s mixture at `dir`: half the cosine's `max(0, n·ω)/π`, half the
/// sphere's `1/4π`.
fn direction_pdf(n: Vec3, dir: Vec3) -> f32 {
    0.5 * n.dot(dir).max(0.0) / PI + 0.5 / (4.0 * PI)
}
