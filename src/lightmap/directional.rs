//! Directional lightmaps: per texel, L1 spherical harmonics of the incident radiance, so a
//! renderer can shade a normal-mapped (perturbed) normal from a bake.
//!
//! ## What is stored
//!
//! Four RGB values per texel, in the bake's `H/π` units and glTF world axes (lightmapped
//! surfaces do not move):
//!
//! ```text
//!   L0  = (1/4π) ∫ L(ω) dω                       the mean incident radiance over the sphere
//!   L1  = (1/2π) ∫ L(ω) ω dω   (x, y, z pages)   its first moment
//! ```
//!
//! This is Bakery's "SH" layout (L0 plus the three L1 vectors `L1x, L1y, L1z`, evaluated by
//! the shader as `L0 + n.x·L1x + n.y·L1y + n.z·L1z`), with the radiance-transfer scale of the
//! irradiance convolution folded in, stored unnormalised in half-float EXR (Bakery divides
//! L1 by L0 for 8-bit textures; a float page does not need to). It is the same data as Godot's
//! directional lightmaps, which store the raw projections `c_lm = ∫ L Y_lm dω` in the order
//! (L0, L1 m=−1 (y), m=0 (z), m=+1 (x)) and scale them in the shader by `0.282095` and
//! `0.32573 = 0.488603·2/3`: `L0 = 0.282095·c_00`, `L1x = 0.32573·c_11`, `L1y = 0.32573·c_1−1`,
//! `L1z = 0.32573·c_10`.
//!
//! ## Reconstruction (the linear L1 irradiance convolution)
//!
//! Irradiance about a unit normal `n` (Ramamoorthi & Hanrahan 2001: the clamped cosine has
//! band weights `Â_0 = π`, `Â_1 = 2π/3`, `Â_2 = π/4`, …), truncated after band 1:
//!
//! ```text
//!   E(n)/π ≈ max(0, L0 + L1x·n.x + L1y·n.y + L1z·n.z)        per colour channel
//! ```
//!
//! At the surface's own normal this is the lightmap's `H/π` (the bake checks it: `agreement`).
//! We chose the linear reconstruction over Geomerics' non-linear one because it is exact for the
//! band-0/1 part of any radiance, is what both Godot and Bakery (with its non-linear option off)
//! evaluate, is linear (filtering, mipmapping and layer sums commute with it) and its error is a
//! known quantity: the dropped bands, `E − E_L1 = Σ_{l even ≥ 2} Â_l Σ_m L_lm Y_lm(n)`, mostly
//! band 2. For known radiance:
//!
//! | incident radiance                          | tilt 0°     | tilt 30°     | tilt 60°      |
//! |--------------------------------------------|-------------|--------------|---------------|
//! | uniform over the surface's hemisphere      | exact       | exact        | exact         |
//! | one direction along the surface normal     | −25 %       | −21 %        | 0 %           |
//!
//! (uniform hemisphere: `E(θ) = πL(1+cos θ)/2`, which has no band-2 part; one direction `l`:
//! `E_L1/π = P(1/4 + n·l/2)/π` against `P·max(0, n·l)/π`.) Real lighting lies between: the
//! sharper (more punctual) the light, the larger the error — see the guide's "Accuracy and
//! speed" ([`crate::guide::performance`]) for the fixtures' figures.
//!
//! ## How it is computed
//!
//! The transport rows hold scalar form factors only, so directions are gathered again after the
//! solve: per texel, `rays` stratified directions uniform over its hemisphere (pdf `1/2π`: the
//! projection's integrand has no cosine, and cosine-distributed rays would give L0 and the
//! tangential L1 an infinite variance at the horizon) from jittered footprint points. A ray
//! that reaches texel `j` sees `ρ_j H_j/π + Le_j` (the solved irradiance, through
//! `Texels::ray_end`); one that escapes sees the sky. Small emitters are also light-sampled,
//! one sample per ray, combined with the hemisphere rays by the power heuristic; punctual
//! lights add their unoccluded radiant flux density along their direction (2 × 2 footprint
//! points, as transport does). With `indirect_only` light that reaches the texel without a
//! bounce (emission, sky, punctual) is left out, as in the lightmap. Streams are seeded by
//! (seed, texel), so the result does not depend on the thread count.
//!
//! Limits: the L1 pages are linear in world space — for static surfaces only, like the
//! lightmap; the hemisphere gather adds noise of its own (`rays` = 256 gives a few percent per
//! texel in indirect-lit regions; not denoised).

use std::f32::consts::PI;

use glam::{Vec2, Vec3};
use rayon::prelude::*;

use super::LightmapPages;
use crate::lights::{Emitters, punctual_irradiance, triangle_point};
use crate::sampling::{Rng, frame, hammersley, power_weight, uniform_hemisphere};
use crate::scene::LightKind;
use crate::texels::{RayEnd, Texels};
use crate::transport::Surfaces;
use crate::{Error, Progress, Result, metrics};

/// The names of the four coefficient pages, in storage order.
pub(crate) const NAMES: [&str; 4] = crate::scene::DIRECTIONAL_PAGES;
/// How the pages are read, as the glTF extras state it.
pub(crate) const CONVENTION: &str =
    "E(n)/pi = max(0, L0 + L1x*n.x + L1y*n.y + L1z*n.z), n world-space unit normal";
/// Default hemisphere rays per texel.
pub const DEFAULT_RAYS: u32 = 256;
/// Texels per parallel work item (one progress tick each).
const CHUNK: usize = 64;
/// Jittered footprint points per side for punctual lights (as transport's).
const PUNCTUAL_GRID: u32 = 2;
/// Mixed into the seed: these streams differ from the transport's of the same texel.
const SALT: u64 = 0x4449_5245_4354; // "DIRECT"

/// L0 and L1 (x, y, z) of one texel, `H/π` units (see the module docs).
pub type Sh1 = [Vec3; 4];

/// `E(n)/π` from a texel's coefficients for unit normal `n`: the linear L1 reconstruction,
/// clamped at zero.
#[inline]
pub fn irradiance_over_pi(c: &Sh1, n: Vec3) -> Vec3 {
    (c[0] + c[1] * n.x + c[2] * n.y + c[3] * n.z).max(Vec3::ZERO)
}

/// Adds radiance `l` (W/(sr·m²) per unit solid-angle weight, i.e. the integrand's value over
/// its sampling density) arriving from unit direction `dir` to `c`.
#[inline]
pub(crate) fn project(c: &mut Sh1, dir: Vec3, l: Vec3) {
    c[0] += l * (1.0 / (4.0 * PI));
    let l1 = l * (1.0 / (2.0 * PI));
    c[1] += l1 * dir.x;
    c[2] += l1 * dir.y;
    c[3] += l1 * dir.z;
}

/// How the directional gather runs.
#[derive(Clone, Debug)]
pub struct DirectionalParams {
    /// Hemisphere rays per texel (and emitter samples, one per ray).
    pub rays: u32,
    /// Seed of the random streams.
    pub seed: u64,
    /// Uniform sky radiance of rays that leave the scene.
    pub sky: Vec3,
    /// Leave out light that reaches a texel without a bounce (as the bake's option).
    pub indirect_only: bool,
}

/// What the final gather found, per texel (indexed like the texels).
#[derive(Clone, Debug, Default)]
pub(crate) struct Gathered {
    pub(crate) sh: Vec<Sh1>,
    /// `E/π` about the texel's own normal from the same samples (the clamped-cosine integral,
    /// no truncation): the lightmap's quantity, to check the gather against it.
    pub(crate) at_normal: Vec<Vec3>,
    pub(crate) rays: u64,
}

/// The final gather over the solved irradiance `h` (`H`, W/m², per texel).
pub(crate) fn gather(
    surfaces: Surfaces,
    h: &[Vec3],
    params: &DirectionalParams,
    progress: &dyn Progress,
) -> Result<Gathered> {
    let gatherer = Gatherer::new(surfaces, h, params);
    let texels = surfaces.texels;
    let n = texels.len();
    progress.begin("directional", n as u64);
    let mut out = vec![([Vec3::ZERO; 4], Vec3::ZERO, 0u64); n];
    out.par_chunks_mut(CHUNK)
        .enumerate()
        .try_for_each(|(c, chunk)| {
            if progress.aborted() {
                return Err(Error::Aborted);
            }
            for (k, (sh, e, rays)) in chunk.iter_mut().enumerate() {
                let normal = texels.normal[c * CHUNK + k];
                *rays = gatherer.incident(c * CHUNK + k, |dir, l| {
                    project(sh, dir, l);
                    *e += l * (normal.dot(dir).max(0.0) / PI);
                });
            }
            progress.advance(chunk.len() as u64);
            Ok(())
        })?;
    progress.end();
    Ok(Gathered {
        sh: out.iter().map(|o| o.0).collect(),
        at_normal: out.iter().map(|o| o.1).collect(),
        rays: out.iter().map(|o| o.2).sum(),
    })
}

/// The final gather of incident radiance at texels.
pub struct Gatherer<'a> {
    surfaces: Surfaces<'a>,
    h: &'a [Vec3],
    emitters: Emitters,
    params: &'a DirectionalParams,
}

impl<'a> Gatherer<'a> {
    /// A gatherer of `surfaces` lit by the solved irradiance `h` (per texel).
    pub fn new(surfaces: Surfaces<'a>, h: &'a [Vec3], params: &'a DirectionalParams) -> Self {
        Gatherer {
            surfaces,
            h,
            emitters: Emitters::new(surfaces.scene, surfaces.texels),
            params,
        }
    }

    /// Calls `add(dir, w)` for every sample of texel `i`'s incident radiance: `Σ w·f(dir)`
    /// estimates `∫ L(ω) f(ω) dω` for any `f` (the SH basis in the bake; a clamped cosine about
    /// another normal in the tests). Returns the rays cast.
    pub fn incident(&self, i: usize, mut add: impl FnMut(Vec3, Vec3)) -> u64 {
        let Surfaces {
            scene,
            texels,
            tracer,
        } = self.surfaces;
        let p = self.params;
        let direct = !p.indirect_only;
        let n = texels.normal[i];
        let (tx, ty) = frame(n);
        let k = p.rays.max(1);
        let kf = k as f32;
        let mut rng = Rng::new(p.seed ^ SALT, i as u64, 0);
        let shift = rng.next_vec2();
        let light_shift = rng.next_vec2();
        let lift = |u: Vec2| texels.footprint_point(i, u) + n * tracer.epsilon;
        let p_hemi = 1.0 / (2.0 * PI);
        let sample_emitters = direct && !self.emitters.is_empty();
        let mut rays = 0u64;
        for s in 0..k {
            let local = uniform_hemisphere(hammersley(s, k, shift));
            let dir = tx * local.x + ty * local.y + n * local.z;
            let origin = lift(rng.next_vec2());
            rays += 1;
            match texels.ray_end(tracer, origin, dir) {
                RayEnd::Escaped if direct => add(dir, p.sky / (p_hemi * kf)),
                RayEnd::Texel(hit, j) => {
                    let j = j as usize;
                    let mut l = texels.albedo[j] * self.h[j] / PI / p_hemi;
                    let le = texels.emission[j];
                    if direct && le.max_element() > 0.0 {
                        let (_, n_l) = triangle_point(scene, hit.triangle, hit.bary);
                        let p_light = self.emitters.pdf_toward(hit.triangle, n_l, dir, hit.t);
                        l += le * power_weight(p_hemi, p_light);
                    }
                    add(dir, l / kf);
                }
                _ => {}
            }
            if sample_emitters {
                let u = hammersley(s, k, light_shift);
                if let Some(y) =
                    self.emitters
                        .sample_from((scene, texels, tracer), origin, Some(n), u)
                {
                    rays += 1;
                    let dir = (y.point - origin).normalize();
                    add(dir, y.le * power_weight(y.pdf_solid_angle(), p_hemi) / kf);
                }
            }
        }
        if direct && !scene.lights.is_empty() {
            let g = PUNCTUAL_GRID;
            let weight = 1.0 / (g * g) as f32;
            for s in 0..g * g {
                let u = (Vec2::new((s % g) as f32, (s / g) as f32) + rng.next_vec2()) / g as f32;
                let x = texels.punctual_point(tracer, i, lift(u));
                for light in &scene.lights {
                    let l = match light.kind {
                        LightKind::Directional => -light.direction,
                        _ => (light.position - x).normalize_or_zero(),
                    };
                    if n.dot(l) > 0.0 {
                        rays += 1;
                        // About its own direction the light's irradiance is its flux density.
                        add(l, punctual_irradiance(light, x, l, tracer) * weight);
                    }
                }
            }
        }
        rays
    }
}

/// The four coefficient pages ([`NAMES`]) laid out like the lightmap (signed values kept).
pub(crate) fn pages(texels: &Texels, sh: &[Sh1]) -> [LightmapPages; 4] {
    std::array::from_fn(|c| {
        let values: Vec<Vec3> = sh.iter().map(|s| s[c]).collect();
        LightmapPages::from_texels_signed(texels, &values)
    })
}

/// How the gather agrees with the lightmap `H/π` at each texel's own normal, over the valid
/// texels ([`metrics::rmse_over_mean`], [`metrics::relative_bias`]).
pub(crate) fn agreement(texels: &Texels, gathered: &Gathered, lightmap: &[Vec3]) -> Agreement {
    let recon: Vec<Vec3> = (gathered.sh.iter().zip(&texels.normal))
        .map(|(c, &n)| irradiance_over_pi(c, n))
        .collect();
    let skip = &texels.invalid;
    Agreement {
        gathered_rmse: metrics::rmse_over_mean(&gathered.at_normal, lightmap, skip),
        gathered_bias: metrics::relative_bias(&gathered.at_normal, lightmap, skip),
        l1_rmse: metrics::rmse_over_mean(&recon, lightmap, skip),
        l1_bias: metrics::relative_bias(&recon, lightmap, skip),
    }
}

/// `agreement`'s figures, relative to the lightmap's mean.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Agreement {
    /// The gathered irradiance (no truncation) against the lightmap: the gather's noise and
    /// the lightmap's own error.
    pub(crate) gathered_rmse: f32,
    pub(crate) gathered_bias: f32,
    /// The L1 reconstruction against the lightmap: the above plus the truncation at the
    /// surface normal.
    pub(crate) l1_rmse: f32,
    pub(crate) l1_bias: f32,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `n` tilted by `angle` from +Z towards +X.
    fn tilted(angle: f32) -> Vec3 {
        Vec3::new(angle.sin(), 0.0, angle.cos())
    }

    /// Coefficients of radiance `l(ω)` over the +Z hemisphere, by a fine midpoint rule.
    fn project_hemisphere(l: impl Fn(Vec3) -> f32) -> Sh1 {
        let mut c = [Vec3::ZERO; 4];
        let n = 512;
        for a in 0..n {
            for b in 0..n {
                let u = Vec2::new((a as f32 + 0.5) / n as f32, (b as f32 + 0.5) / n as f32);
                let d = uniform_hemisphere(u);
                let w = 2.0 * PI / (n * n) as f32;
                project(&mut c, d, Vec3::splat(l(d) * w));
            }
        }
        c
    }

    #[test]
    fn uniform_hemisphere_radiance_is_reconstructed_exactly() {
        // E(θ)/π = (1 + cos θ)/2 for unit radiance over the hemisphere: no band-2 part.
        let c = project_hemisphere(|_| 1.0);
        for deg in [0.0f32, 30.0, 60.0, 90.0] {
            let t = deg.to_radians();
            let e = irradiance_over_pi(&c, tilted(t)).x;
            assert!((e - (1.0 + t.cos()) / 2.0).abs() < 2e-3, "{deg}°: {e}");
        }
    }

    #[test]
    fn one_direction_has_the_closed_form_truncation_error() {
        // Flux density P = 1 along +Z: E_L1/π = (1/4 + cos/2)/π, exact E/π = max(0, cos)/π.
        let mut c = [Vec3::ZERO; 4];
        project(&mut c, Vec3::Z, Vec3::ONE);
        for (deg, error) in [(0.0f32, -0.25f32), (30.0, -0.2113), (60.0, 0.0)] {
            let cos = deg.to_radians().cos();
            let e = irradiance_over_pi(&c, tilted(deg.to_radians())).x * PI;
            assert!(
                ((e - cos) / cos - error).abs() < 1e-3,
                "{deg}°: {e} vs {cos}"
            );
        }
    }

    #[test]
    fn the_layout_is_godots_scaled() {
        // Godot: L0 = 0.282095·∫L·Y00, L1x = 0.32573·∫L·Y11 with Y00 = 0.282095,
        // Y11 = 0.488603·x; a direction d with flux density 1.
        let d = Vec3::new(0.36, 0.48, 0.8);
        let mut c = [Vec3::ZERO; 4];
        project(&mut c, d, Vec3::ONE);
        assert!((c[0].x - 0.282095 * 0.282095).abs() < 1e-5);
        assert!((c[1].x - 0.32573 * 0.488603 * d.x).abs() < 1e-5);
        assert!((c[2].x - 0.32573 * 0.488603 * d.y).abs() < 1e-5);
        assert!((c[3].x - 0.32573 * 0.488603 * d.z).abs() < 1e-5);
    }
}
