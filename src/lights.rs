//! Light sampling shared by transport, the reference and the renderer: irradiance from punctual
//! lights (KHR_lights_punctual) with shadow rays, and the emissive triangles as area lights for
//! explicit light sampling (the emitted radiance of each comes from its texel).

use glam::{Vec2, Vec3};

use crate::sampling::{sample_cdf, triangle_point as sample_triangle};
use crate::scene::{Light, LightKind, Scene};
use crate::texels::{NO_TEXEL, Texels};
use crate::trace::Tracer;

/// Irradiance (W/m²) at `p` (normal `n`, origin already offset) from one punctual light.
#[inline]
pub(crate) fn punctual_irradiance(light: &Light, p: Vec3, n: Vec3, tracer: &Tracer) -> Vec3 {
    match light.kind {
        LightKind::Directional => {
            let l = -light.direction;
            let cos = n.dot(l);
            if cos <= 0.0 || !tracer.escapes(p, l, f32::INFINITY) {
                return Vec3::ZERO;
            }
            light.intensity * cos
        }
        LightKind::Point | LightKind::Spot { .. } => {
            let to_light = light.position - p;
            let d2 = to_light.length_squared();
            if d2 <= 0.0 {
                return Vec3::ZERO;
            }
            let d = d2.sqrt();
            let l = to_light / d;
            let cos = n.dot(l);
            if cos <= 0.0 {
                return Vec3::ZERO;
            }
            // KHR_lights_punctual range falloff: smooth window to zero at `range`.
            let window = light
                .range
                .map_or(1.0, |r| (1.0 - (d / r).powi(4)).clamp(0.0, 1.0));
            let cone = match light.kind {
                LightKind::Spot {
                    inner_cone_angle,
                    outer_cone_angle,
                } => {
                    let scale = 1.0 / (inner_cone_angle.cos() - outer_cone_angle.cos()).max(1e-3);
                    let offset = -outer_cone_angle.cos() * scale;
                    let a = (light.direction.dot(-l) * scale + offset).clamp(0.0, 1.0);
                    a * a
                }
                _ => 1.0,
            };
            if window * cone <= 0.0 || tracer.occluded(p, light.position) {
                return Vec3::ZERO;
            }
            light.intensity * (cos * window * cone / d2)
        }
    }
}

/// Emitters whose material covers more than this fraction of the scene's surface are left to the
/// gathering rays: they subtend large solid angles, where cosine-distributed rays find them with
/// little noise, while area sampling of a large emitter is noisy (1/r² near corners). Measured
/// on the furnace (every face emits): sampling them too raised the worst texel error from 0.01%
/// to 3.3% at K = L = 256. Small emitters (the Cornell light, 0.8% of its scene) are sampled.
pub(crate) const LARGE_EMITTER_FRACTION: f32 = 0.25;

/// Small emissive triangles, sampled in proportion to their emitted power.
pub(crate) struct Emitters {
    /// Scene triangles that emit.
    pub(crate) triangles: Vec<u32>,
    /// Cumulative power over `triangles`.
    pub(crate) cdf: Vec<f32>,
    /// Per scene triangle: probability of picking it divided by its area (area density of a
    /// light sample landing at a point on it), 0 for non-emitters.
    pub(crate) pdf_area: Vec<f32>,
    /// One bit per texel: it emits (any emitter, large ones too). A gathering ray asks this of
    /// every texel it hits; loading the texel's emission instead missed the cache on most hits.
    emissive: Vec<u64>,
}

impl Emitters {
    pub(crate) fn new(scene: &Scene, texels: &Texels) -> Emitters {
        // Surface area per material, to leave large emitters to the gathering rays.
        let mut material_area = vec![0.0f64; scene.materials.len()];
        let mut total_area = 0.0f64;
        for (t, tri) in scene.triangles.iter().enumerate() {
            let a = triangle_area(scene, tri) as f64;
            material_area
                [scene.instances[scene.triangle_instance[t] as usize].material as usize] += a;
            total_area += a;
        }
        let large = |m: usize| material_area[m] > LARGE_EMITTER_FRACTION as f64 * total_area;
        let mut triangles = Vec::new();
        let mut power = Vec::new();
        for (t, tri) in scene.triangles.iter().enumerate() {
            let inst = &scene.instances[scene.triangle_instance[t] as usize];
            let m = &scene.materials[inst.material as usize];
            if m.emission.max_element() <= 0.0 || large(inst.material as usize) {
                continue;
            }
            let area = triangle_area(scene, tri);
            // Emissive textures vary over the triangle: weigh by the texel it mostly covers.
            let le = texels
                .emission
                .get(texels.triangle_texel[t] as usize)
                .copied()
                .unwrap_or(m.emission);
            let weight = area * (le.x + le.y + le.z).max(1e-6 * m.emission.max_element());
            if area > 0.0 && weight.is_finite() && weight > 0.0 {
                triangles.push(t as u32);
                power.push(weight);
            }
        }
        let total: f64 = power.iter().map(|&p| p as f64).sum();
        let mut cdf = Vec::with_capacity(power.len());
        let mut pdf_area = vec![0.0; scene.triangles.len()];
        let mut acc = 0.0f64;
        for (&t, &p) in triangles.iter().zip(&power) {
            acc += p as f64;
            cdf.push((acc / total) as f32);
            pdf_area[t as usize] =
                (p as f64 / total) as f32 / triangle_area(scene, &scene.triangles[t as usize]);
        }
        let mut emissive = vec![0u64; texels.len().div_ceil(64)];
        for (j, le) in texels.emission.iter().enumerate() {
            if le.max_element() > 0.0 {
                emissive[j / 64] |= 1 << (j % 64);
            }
        }
        Emitters {
            triangles,
            cdf,
            pdf_area,
            emissive,
        }
    }

    /// Texel `j` emits.
    #[inline]
    pub(crate) fn emits(&self, j: u32) -> bool {
        self.emissive
            .get(j as usize / 64)
            .is_some_and(|w| w & (1 << (j % 64)) != 0)
    }

    pub(crate) fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    /// Picks an emissive triangle for `u ∈ [0,1)` and returns `u` rescaled to [0,1) within the
    /// picked triangle's share of the distribution, so one stratified 2D sample stratifies both
    /// the pick and the point on the triangle.
    #[inline]
    pub(crate) fn pick_stratified(&self, u: f32) -> (u32, f32) {
        let k = sample_cdf(&self.cdf, u);
        let lo = if k == 0 { 0.0 } else { self.cdf[k - 1] };
        let hi = self.cdf[k];
        let rescaled = if hi > lo {
            ((u - lo) / (hi - lo)).clamp(0.0, 0.999_999_94)
        } else {
            0.5
        };
        (self.triangles[k], rescaled)
    }

    /// Picks an emissive triangle for `u ∈ [0,1)`.
    #[inline]
    pub(crate) fn pick(&self, u: f32) -> u32 {
        self.triangles[sample_cdf(&self.cdf, u)]
    }

    /// The light sample `u ∈ [0,1)²` (stratified: [`Emitters::pick_stratified`]) seen from `x`
    /// with normal `n`: `None` when [`Emitters::sample_at`] finds none or the shadow ray is
    /// blocked.
    #[inline]
    pub(crate) fn sample_from(
        &self,
        (scene, texels, tracer): (&Scene, &Texels, &Tracer),
        x: Vec3,
        n: Option<Vec3>,
        u: Vec2,
    ) -> Option<LightSample> {
        let (tri, u0) = self.pick_stratified(u.x);
        let bary = sample_triangle(Vec2::new(u0, u.y));
        let sample = self.sample_at((scene, texels), x, n, tri, bary)?;
        (!tracer.occluded(x, sample.point)).then_some(sample)
    }

    /// The point at barycentrics `bary` of emissive triangle `tri` as a light sample seen from
    /// `x` with normal `n` (`None`: a point in free space, which faces every way), visibility
    /// not tested (the caller traces the shadow ray to [`LightSample::point`]): `None` when
    /// either side faces away or the point has no texel.
    #[inline]
    pub(crate) fn sample_at(
        &self,
        (scene, texels): (&Scene, &Texels),
        x: Vec3,
        n: Option<Vec3>,
        tri: u32,
        bary: Vec2,
    ) -> Option<LightSample> {
        let (point, n_l) = triangle_point(scene, tri, bary);
        let to = point - x;
        let r2 = to.length_squared();
        if r2 <= 0.0 {
            return None;
        }
        let dir = to / r2.sqrt();
        // A point in free space (a light probe) has no surface: every direction counts.
        let (cos_i, cos_l) = (n.map_or(1.0, |n| n.dot(dir)), -n_l.dot(dir));
        if cos_i <= 0.0 || cos_l <= 0.0 {
            return None;
        }
        let j = texels.texel_at(tri, bary);
        if j == NO_TEXEL {
            return None;
        }
        Some(LightSample {
            point,
            texel: j,
            le: texels.emission[j as usize],
            cos_i,
            cos_l,
            r2,
            pdf_area: self.pdf_area[tri as usize],
        })
    }

    /// Solid-angle density with which light sampling picks the point of emissive triangle `tri`
    /// (geometric normal `n_l`) that a ray along unit `dir` hits at `distance`: the light half
    /// of the MIS weight of a gathered hit. 0 when the ray sees the triangle's back.
    #[inline]
    pub(crate) fn pdf_toward(&self, tri: u32, n_l: Vec3, dir: Vec3, distance: f32) -> f32 {
        let cos_l = -n_l.dot(dir);
        if cos_l > 0.0 {
            self.pdf_area[tri as usize] * distance * distance / cos_l
        } else {
            0.0
        }
    }
}

/// A light sample ([`Emitters::sample_at`], unoccluded if from [`Emitters::sample_from`]).
#[derive(Clone, Copy, Debug)]
pub(crate) struct LightSample {
    /// The point on the emitter.
    pub(crate) point: Vec3,
    /// The texel sampled.
    pub(crate) texel: u32,
    /// Emitted radiance of the texel sampled.
    pub(crate) le: Vec3,
    /// Cosines at the receiver and at the emitter.
    pub(crate) cos_i: f32,
    pub(crate) cos_l: f32,
    /// Squared distance.
    pub(crate) r2: f32,
    /// Area density of the sample on its triangle.
    pub(crate) pdf_area: f32,
}

impl LightSample {
    /// Solid-angle density of the sample, seen from the receiver.
    #[inline]
    pub(crate) fn pdf_solid_angle(&self) -> f32 {
        self.pdf_area * self.r2 / self.cos_l
    }
}

pub(crate) fn triangle_area(scene: &Scene, tri: &[u32; 3]) -> f32 {
    let p = |i: usize| scene.positions[tri[i] as usize];
    0.5 * (p(1) - p(0)).cross(p(2) - p(0)).length()
}

/// World position and geometric unit normal at barycentrics `b` of scene triangle `t`.
#[inline]
pub(crate) fn triangle_point(scene: &Scene, t: u32, b: Vec2) -> (Vec3, Vec3) {
    let [i0, i1, i2] = scene.triangles[t as usize];
    let (p0, p1, p2) = (
        scene.positions[i0 as usize],
        scene.positions[i1 as usize],
        scene.positions[i2 as usize],
    );
    let p = p0 * (1.0 - b.x - b.y) + p1 * b.x + p2 * b.y;
    (p, (p1 - p0).cross(p2 - p0).normalize_or_zero())
}
