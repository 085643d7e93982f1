//! Shading: the lightmap lookup, and the Whitted ray tree of the specular layer.
//!
//! At a hit seen from direction `v` with shading normal `n` (cos θ = n·v):
//!
//! ```text
//!   L_d   = baseColor · lightmap(uv1)                       diffuse, from the bake (H/π)
//!   L     = L_d + Le                                        leaves, rough surfaces, no --specular
//!
//!   L     = m · F_m · L_r                                   metal part
//!         + (1−m) · [ F_d · L_r + (1−F_d) · (τ · c · L_t + (1−τ) · L_d) ]   dielectric part
//!         + Le
//!   F_m   = Schlick(F0 = baseColor, cos θ)
//!   F_d   = s · Schlick(F0 = min(((η−1)/(η+1))² · s_c, 1), cos θ)   (cos θ_t when leaving glass;
//!           1 under total internal reflection)
//!   L_r   = radiance along the mirror direction (roughness ≤ MIRROR_ROUGHNESS), or the mean
//!           over GGX-sampled directions weighted by min(1, G₂·(v·h)/((n·v)(n·h)))
//!   L_t   = radiance along the refracted direction; on the way out of a volume the result is
//!           attenuated by exp(−σ·t) (Beer–Lambert over the path inside)
//! ```
//!
//! with `m` metallic, `τ` transmission, `η` ior, `s`/`s_c` KHR_materials_specular's factor and
//! colour, `c` = baseColor tinting light that enters a transmissive surface, `σ` from
//! KHR_materials_volume (`−ln(attenuationColor)/attenuationDistance`). Every term is a convex
//! combination of children (Fresnel ≤ 1, glossy weights clamped to 1, baseColor ≤ 1), so a
//! pixel never exceeds the brightest `L_d + Le` in the scene plus `Le` of the specular surface
//! itself: energy is conserved whatever the depth.
//!
//! | Constant | Value | Meaning |
//! |---|---|---|
//! | [`MIRROR_ROUGHNESS`] | 0.02 | at or below: one perfect mirror ray |
//! | [`GLOSSY_MAX_ROUGHNESS`] | 0.5 | above: no specular layer (lightmap only) |
//!
//! Limits: Schlick's Fresnel is applied once per node with the macro-normal angle (not per
//! microfacet); a single-sided transmissive surface is taken to bound a volume (hitting it from
//! behind means leaving the glass); diffuse light through glass comes from the bake, which
//! treated glass as an opaque Lambertian surface.

use glam::Vec3;

use super::{RenderOptions, RenderScene};
use crate::lightmap::directional;
use crate::sampling::{Rng, frame, hammersley};
use crate::scene::{Surface, SurfacePoint};
use crate::trace::Hit;

/// Roughness at or below which reflection is one perfect mirror ray.
pub(crate) const MIRROR_ROUGHNESS: f32 = 0.02;
/// Roughness above which a surface has no specular layer: it is shaded from the lightmap alone.
pub(crate) const GLOSSY_MAX_ROUGHNESS: f32 = 0.5;

/// Has a specular layer worth tracing.
fn is_specular(surface: &Surface) -> bool {
    surface.roughness <= GLOSSY_MAX_ROUGHNESS
}

pub(super) struct Shader<'a> {
    scene: &'a RenderScene,
    options: &'a RenderOptions,
    epsilon: f32,
}

impl<'a> Shader<'a> {
    pub(super) fn new(scene: &'a RenderScene, options: &'a RenderOptions) -> Self {
        Shader {
            scene,
            options,
            epsilon: scene.tracer.epsilon,
        }
    }

    /// Radiance arriving at `origin` along `-dir`; `depth` is this ray's level in the tree.
    pub(super) fn radiance(
        &self,
        origin: Vec3,
        dir: Vec3,
        depth: u32,
        rng: &mut Rng,
        rays: &mut u64,
    ) -> Vec3 {
        let Some(hit) = self.intersect(origin, dir, rays) else {
            return self.options.background;
        };
        let scene = &self.scene.scene;
        let sp = scene.surface_point(hit.triangle, hit.bary);
        let surface = &scene.materials[sp.material as usize].surface;
        let base = scene.base_color(sp.material, sp.uv0);
        let emission = if hit.front {
            scene.emission(sp.material, sp.uv0)
        } else {
            Vec3::ZERO
        };
        let l_d = base * self.diffuse_light(hit.triangle, &sp);
        let tree = self.options.specular && depth < self.options.max_depth;
        if !tree || !is_specular(surface) {
            return l_d + emission;
        }

        let v = -dir;
        let entering = hit.front;
        let (n, n_geo) = if entering {
            (sp.n, sp.n_geo)
        } else {
            (-sp.n, -sp.n_geo)
        };
        // A shading normal facing away from the viewer would reflect into the surface.
        let n = if n.dot(v) > 1e-4 { n } else { n_geo };
        let cos_i = n.dot(v).clamp(1e-4, 1.0);
        let above = sp.p + n_geo * self.epsilon;
        let below = sp.p - n_geo * self.epsilon;

        let l_r = self.reflection(above, n_geo, n, v, surface.roughness, depth, rng, rays);
        let mut l = emission;
        if surface.metallic > 0.0 {
            l += surface.metallic * schlick(base, cos_i) * l_r;
        }
        let dielectric = 1.0 - surface.metallic;
        if dielectric > 0.0 {
            let eta = if entering {
                1.0 / surface.ior
            } else {
                surface.ior
            };
            let sin2_t = eta * eta * (1.0 - cos_i * cos_i);
            let tir = sin2_t >= 1.0;
            let f0 = (((surface.ior - 1.0) / (surface.ior + 1.0)).powi(2) * surface.specular_color)
                .min(Vec3::ONE);
            // Leaving a denser medium, Schlick needs the angle on the thinner side.
            let cos_f = if eta > 1.0 {
                (1.0 - sin2_t).max(0.0).sqrt()
            } else {
                cos_i
            };
            let f_d = if tir {
                Vec3::ONE
            } else {
                surface.specular * schlick(f0, cos_f)
            };
            let mut body = Vec3::ZERO;
            if surface.transmission > 0.0 && !tir {
                let cos_t = (1.0 - sin2_t).sqrt();
                let t_dir = (-v * eta + n * (eta * cos_i - cos_t)).normalize();
                let tint = if entering { base } else { Vec3::ONE };
                let l_t = self.radiance(below, t_dir, depth + 1, rng, rays);
                body += surface.transmission * tint * l_t;
            }
            if entering {
                body += (1.0 - surface.transmission) * l_d;
            }
            l += dielectric * (f_d * l_r + (Vec3::ONE - f_d) * body);
        }
        if !entering {
            // The ray travelled hit.t inside the volume.
            l *= (-surface.attenuation * hit.t).exp();
        }
        l
    }

    /// Mirror ray, or the GGX-weighted mean over sampled reflection directions.
    #[allow(clippy::too_many_arguments)]
    fn reflection(
        &self,
        origin: Vec3,
        n_geo: Vec3,
        n: Vec3,
        v: Vec3,
        roughness: f32,
        depth: u32,
        rng: &mut Rng,
        rays: &mut u64,
    ) -> Vec3 {
        if roughness <= MIRROR_ROUGHNESS {
            let mut r = 2.0 * n.dot(v) * n - v;
            if r.dot(n_geo) <= 0.0 {
                r = 2.0 * n_geo.dot(v) * n_geo - v;
            }
            return self.radiance(origin, r.normalize(), depth + 1, rng, rays);
        }
        let alpha = roughness * roughness;
        let k = if depth == 0 {
            self.options.glossy_samples.max(1)
        } else {
            1
        };
        let (t, b) = frame(n);
        let n_v = n.dot(v).max(1e-4);
        let shift = rng.next_vec2();
        let mut sum = Vec3::ZERO;
        for i in 0..k {
            let u = hammersley(i, k, shift);
            // GGX normal distribution sampling: tan²θ_h = α² u / (1 − u).
            let tan2 = alpha * alpha * u.x / (1.0 - u.x).max(1e-6);
            let cos_h = 1.0 / (1.0 + tan2).sqrt();
            let sin_h = (1.0 - cos_h * cos_h).max(0.0).sqrt();
            let phi = std::f32::consts::TAU * u.y;
            let h = t * (sin_h * phi.cos()) + b * (sin_h * phi.sin()) + n * cos_h;
            let v_h = v.dot(h);
            if v_h <= 0.0 {
                continue;
            }
            let l = (2.0 * v_h * h - v).normalize();
            let n_l = n.dot(l);
            if n_l <= 0.0 || l.dot(n_geo) <= 0.0 {
                continue;
            }
            let g2 = smith_g1(n_v, alpha) * smith_g1(n_l, alpha);
            let w = (g2 * v_h / (n_v * cos_h)).min(1.0);
            sum += w * self.radiance(origin, l, depth + 1, rng, rays);
        }
        sum / k as f32
    }

    /// Closest hit that is visible: back faces of opaque single-sided materials are culled.
    fn intersect(&self, origin: Vec3, dir: Vec3, rays: &mut u64) -> Option<Hit> {
        *rays += 1;
        let scene = self.scene;
        scene
            .tracer
            .closest_culling(origin, dir, f32::INFINITY, &scene.cull_back)
    }

    /// `H/π` at `sp` (a point of triangle `t`): the L1 reconstruction at the shading normal
    /// from the directional pages when the bake has them, else the bilinear lookup of the
    /// lightmap at `uv1` (see [`crate::lightmap::Page::bilinear`]). A mesh without a lightmap
    /// (one the bake did not light, such as a prop added to the baked scene) reads the bake's
    /// light probes at the shading normal when there are any, as an engine lights what moves.
    fn diffuse_light(&self, t: u32, sp: &SurfacePoint) -> Vec3 {
        if let Some(pages) = self.scene.directional(sp.instance) {
            let c = pages.map(|p| p.bilinear(sp.uv1));
            let n = self.scene.scene.shading_normal(t, sp);
            return directional::irradiance_over_pi(&c, n);
        }
        match (self.scene.page(sp.instance), &self.scene.probes) {
            (Some(page), _) => page.bilinear(sp.uv1),
            (None, Some(probes)) => {
                let n = self.scene.scene.shading_normal(t, sp);
                let tracer = &self.scene.tracer;
                let from = sp.p + n * tracer.epsilon;
                let c = probes.sh_at(sp.p, |q| self.sees_past_itself(sp.instance, from, q));
                crate::probes::sh::irradiance_over_pi(&c, n)
            }
            (None, None) => Vec3::ZERO,
        }
    }

    /// Whether nothing but `instance` itself lies between `from` and the probe at `q`: a ball
    /// lit by probes must not hide the probes behind it from its own front (every point would
    /// read another set of probes, and the ball would show their seams), as an engine
    /// interpolates for the object, not through it.
    fn sees_past_itself(&self, instance: u32, mut from: Vec3, q: Vec3) -> bool {
        let (tracer, scene) = (&self.scene.tracer, &self.scene.scene);
        // A closed mesh is crossed at most a few times on the way to a probe.
        for _ in 0..8 {
            let d = q - from;
            let len = d.length();
            if len <= tracer.epsilon {
                return true;
            }
            let dir = d / len;
            match tracer.closest(from, dir, len - tracer.epsilon) {
                None => return true,
                Some(hit) if scene.triangle_instance[hit.triangle as usize] == instance => {
                    from += dir * (hit.t + tracer.epsilon);
                }
                Some(_) => return false,
            }
        }
        false
    }
}

/// Schlick's Fresnel approximation `F0 + (1 − F0)(1 − cos θ)⁵`.
#[inline]
fn schlick(f0: Vec3, cos: f32) -> Vec3 {
    f0 + (Vec3::ONE - f0) * (1.0 - cos).clamp(0.0, 1.0).powi(5)
}

/// Smith's masking term for GGX, `2 cos / (cos + √(α² + (1 − α²) cos²))`.
#[inline]
fn smith_g1(cos: f32, alpha: f32) -> f32 {
    let a2 = alpha * alpha;
    2.0 * cos / (cos + (a2 + (1.0 - a2) * cos * cos).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn schlick_goes_from_f0_to_one() {
        let f0 = Vec3::splat(0.04);
        assert!((schlick(f0, 1.0) - f0).length() < 1e-7);
        assert!((schlick(f0, 0.0) - Vec3::ONE).length() < 1e-7);
    }
}
