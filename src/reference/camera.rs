//! The reference's camera mode: a path-traced image of the view `lightbake render` draws, with a
//! per-pixel standard error — the yardstick for rendered lightmaps.
//!
//! Each sample of pixel `(x, y)` is one primary ray through a uniformly jittered point of the
//! pixel, through the same pinhole [`Camera`] as the renderer (`Camera::direction`, same NDC
//! convention), then at the first visible hit `x₀`:
//!
//! ```text
//!   L = baseColor(uv0) · Ĥ(x₀)/π + Le(uv0)
//! ```
//!
//! where `Ĥ/π` is one path of the texel reference's estimator (next-event estimation for
//! punctual lights and small emitters, MIS with the cosine-sampled bounce, Russian roulette after
//! [`super::ROULETTE_DEPTH`] bounces) started at `x₀` with the interpolated normal instead of at
//! a texel footprint. The pixel value is the mean of its samples — the box-filtered pixel
//! integral, as the renderer's jittered samples estimate it — and its standard error is that of
//! the mean of independent samples (pure uniform jitter, no stratification, so the formula holds
//! and stopping early leaves no part of the pixel out).
//!
//! What is the same as `render` without `--specular`: camera, pixel footprint, baseColor and
//! emission (textures sampled at the hit's `TEXCOORD_0`), single-sided faces seen from behind are
//! skipped (culled) up to 8 times. What differs, by design: `H` is path-traced at the hit point
//! instead of looked up bilinearly in a lightmap, so the difference of the two images is the
//! lightmap's error (texel discretisation, interpolation, dilation, and the bake's transport and
//! solve error). Beyond the first hit the paths use the texels' `ρ` and `Le`, like the texel
//! reference. Rays that leave the scene see the sky `params.sky` (give `render --background` the
//! same value). All surfaces are Lambertian, as for the bake: no specular or transmission layer.
//!
//! Random streams are seeded by (seed, pixel, sample): the image does not depend on the thread
//! count, and the stopping rules (`max_samples`, `target_rel_error` over pixels, `time_limit`)
//! are those of the texel mode.

use glam::{Vec2, Vec3};

use super::{ItemSample, Paths, Reference, ReferenceParams, SEED_SALT, trace_items};
use crate::sampling::Rng;
use crate::scene::{Camera, Scene};
use crate::texels::Texels;
use crate::trace::{Hit, Tracer};
use crate::{Error, Progress, Result};

/// Mixed into the seed so pixel streams differ from texel streams of the same index.
const VIEW_SALT: u64 = 0x5649_4557; // "VIEW"
/// Back faces of single-sided surfaces skipped along a primary ray (as the renderer culls them).
const MAX_BACK_FACE_SKIPS: u32 = 8;

/// A path-traced camera image.
#[derive(Clone, Debug)]
pub struct View {
    /// Pixels across.
    pub width: u32,
    /// Pixels down.
    pub height: u32,
    /// Radiance per pixel (linear RGB), row 0 at the top, with its standard error and the
    /// run's samples per pixel, rays (primary, closest hits and shadow rays), time and stop.
    pub pixels: Reference,
}

impl View {
    /// One line: size, samples, rays, speed, error, time.
    pub fn summary(&self) -> String {
        format!(
            "{}x{} pixels, {} paths per pixel, {}",
            self.width,
            self.height,
            self.pixels.samples,
            self.pixels.cost_and_error()
        )
    }
}

/// Path-traces the view of `camera` at `width × height` pixels until a stopping rule of
/// `params` holds (`max_samples` is paths per pixel).
#[allow(clippy::too_many_arguments)]
pub fn trace_view(
    scene: &Scene,
    texels: &Texels,
    tracer: &Tracer,
    camera: &Camera,
    width: u32,
    height: u32,
    params: &ReferenceParams,
    progress: &dyn Progress,
) -> Result<View> {
    if width == 0 || height == 0 {
        return Err(Error::Option(format!(
            "image size {width}×{height} must be positive"
        )));
    }
    let aspect = width as f32 / height as f32;
    let pixel_sample: &ItemSample = &|paths, i, sample, rays| {
        let (x, y) = ((i % width as usize) as f32, (i / width as usize) as f32);
        let mut rng = Rng::new(params.seed ^ SEED_SALT ^ VIEW_SALT, i as u64, sample as u64);
        let jitter = rng.next_vec2();
        let ndc = Vec2::new(
            2.0 * (x + jitter.x) / width as f32 - 1.0,
            1.0 - 2.0 * (y + jitter.y) / height as f32,
        );
        let dir = camera.direction(ndc, aspect);
        let l = radiance(paths, camera.eye, dir, &mut rng, rays);
        if l.is_finite() { l } else { Vec3::ZERO }
    };
    let n = width as usize * height as usize;
    let pixels = trace_items(
        (scene, texels, tracer),
        n,
        params,
        progress,
        "reference view",
        pixel_sample,
    )?;
    Ok(View {
        width,
        height,
        pixels,
    })
}

/// One estimate of the radiance arriving at `origin` from `-dir`.
fn radiance(paths: &Paths, origin: Vec3, dir: Vec3, rng: &mut Rng, rays: &mut u64) -> Vec3 {
    let Some(hit) = first_front_hit(paths.tracer, origin, dir, rays) else {
        return paths.params.sky;
    };
    let s = paths.scene;
    let sp = s.surface_point(hit.triangle, hit.bary);
    if sp.n_geo == Vec3::ZERO {
        return Vec3::ZERO;
    }
    let emission = s.emission(sp.material, sp.uv0);
    let base = s.base_color(sp.material, sp.uv0);
    if base.max_element() <= 0.0 {
        return emission;
    }
    let x = sp.p + sp.n_geo * paths.tracer.epsilon;
    base * paths.reflected(x, sp.n, None, rng, rays) + emission
}

/// Closest front-face hit along the ray, skipping back faces of single-sided surfaces.
fn first_front_hit(tracer: &Tracer, origin: Vec3, dir: Vec3, rays: &mut u64) -> Option<Hit> {
    let mut o = origin;
    for _ in 0..MAX_BACK_FACE_SKIPS {
        *rays += 1;
        let hit = tracer.closest(o, dir, f32::INFINITY)?;
        if hit.front {
            return Some(hit);
        }
        o += dir * (hit.t + tracer.epsilon);
    }
    None
}
