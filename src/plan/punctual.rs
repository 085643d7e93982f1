//! The resolution error of direct light from punctual lights, sampled rather than modelled.
//!
//! Second differences of texel values ([`super::resolution_error`]) see how the light curves
//! *between* texel centres, but not a shadow or cone edge narrower than a texel, nor lookups
//! that read a gutter or a buried texel. For punctual lights (sun, point, spot: the hard edges)
//! the exact irradiance at any point costs one shadow ray per light, so the error a renderer
//! shows can be measured directly: texel values as transport computes them (the mean of
//! jittered footprint points, `transport::montecarlo`), read back by a bilinear lookup at
//! area-weighted random surface points and compared with the exact irradiance there — the
//! point yardstick's procedure on the direct punctual light alone, where no path tracing is
//! needed. Lookup neighbours that are gutters or buried (invalid) texels are left out of the
//! bilinear weights, as dilation and the invalid-texel fill replace them by their neighbours;
//! such lookups are counted ([`PunctualSample::border_share`]).
//!
//! **The texels' values are the pilot runs' own.** Monte Carlo transport keeps each texel's
//! punctual light (`Transport::punctual`, 2×2 jittered points a run), so the sample casts one
//! shadow ray per point and light and none per texel. A run's texel value is noisy (4 points
//! across a shadow edge), but the two runs' are independent: the product of their lookup
//! errors, `(a − e)·(b − e)`, has the squared bias of the lookup as its mean and none of the
//! footprint sampling's noise, as the gathered sample's products do for the rest of the light.
//! Where the runs did not keep it (another transport method), the texels are traced here at
//! [`GRID`]² points each and both factors are that one value.

use glam::{Vec2, Vec3};

use crate::Result;
use crate::lights::{punctual_irradiance, triangle_point};
use crate::sampling::{self, Rng};
use crate::scene::Scene;
use crate::shard::{self, Packed, Shards, bits, flag};
use crate::texels::{NO_TEXEL, Texels};
use crate::trace::Tracer;

/// Random surface points the error is measured at.
pub(crate) const POINTS: usize = 16_384;
/// Jittered footprint points per texel side when the texels' punctual light is traced here
/// (the runs did not keep theirs). Until 7 December it was traced for every texel whatever
/// the transport, 4×4 points standing for the mean of the three runs a bake averages: 16
/// shadow rays a texel and light, up to a third of planning (the courtyard at `high`). Its
/// cheaper forms were rejected because a single noisy value squared reads its noise as
/// lookup error (2×2 raised the lamp room at `draft` and `medium`), or because refining only
/// where four points disagreed measured less error than the bake showed (it missed slivers
/// of contact shadow: the courtyard at `medium` 0.46% → 0.18%). The runs' own values with
/// their errors multiplied have neither fault: no noise in the mean, no selection.
pub(crate) const GRID: u32 = 4;
/// Mixed into the seed: these streams differ from transport's and the point yardstick's.
const SALT: u64 = 0x05EE_D0FD_1EC7;

/// The error of one sampled point.
#[derive(Clone, Copy, Debug)]
pub(crate) struct PointError {
    /// Squared error (mean over channels) of the bilinear lookup against the exact irradiance:
    /// the product of the two runs' errors (unbiased, negative at times).
    pub(crate) square: f32,
    /// The lookup left out a gutter or buried neighbour.
    pub(crate) border: bool,
    /// The bilinear lookup of the total light (what the mean of a relative error divides by).
    pub(crate) total: f32,
    /// The texels that lookup blends and their weights (zero where one was left out), so the
    /// total can be read again from another bake of the same texels
    /// ([`PunctualSample::normalised_by`]).
    pub(crate) lookup: [(u32, f32); 4],
}

/// A sampled point's error, or none where the lookup finds no texel.
impl Packed for Option<PointError> {
    const FLOATS: usize = 12;
    fn pack(&self, out: &mut Vec<f32>) {
        match self {
            Some(p) => {
                out.extend([1.0, p.square, flag(p.border), p.total]);
                for (j, w) in p.lookup {
                    out.extend([bits(j), w]);
                }
            }
            None => out.extend([0.0; 12]),
        }
    }
    fn unpack(v: &[f32]) -> Self {
        (v[0] != 0.0).then(|| PointError {
            square: v[1],
            border: v[2] != 0.0,
            total: v[3],
            lookup: std::array::from_fn(|k| (v[4 + 2 * k].to_bits(), v[5 + 2 * k])),
        })
    }
}

/// Direct punctual light at the texels and its lookup error at random surface points.
#[derive(Clone, Debug, Default)]
pub(crate) struct PunctualSample {
    /// Irradiance (W/m²) from punctual lights per texel, as each of the pilot pair's two runs
    /// computed it ([`crate::transport::Transport::punctual`]), or traced here when the runs
    /// did not keep it (both then the same).
    pub(crate) texel: [Vec<Vec3>; 2],
    /// One per visible sampled point (points on buried or unrasterised texels are left out).
    pub(crate) points: Vec<PointError>,
}

impl PunctualSample {
    /// Samples the scene's punctual lights at [`POINTS`] surface points against the texels'
    /// punctual light: `runs`, each pilot run's own when transport kept it, or traced here at
    /// [`GRID`]² footprint points per texel; `total` is the lightmap (any scale) each point's
    /// lookup is normalised by. `None` without punctual lights.
    pub(crate) fn measure(
        scene: &Scene,
        texels: &Texels,
        tracer: &Tracer,
        (total, runs): (&[Vec3], Option<[Vec<Vec3>; 2]>),
        seed: u64,
        shards: &dyn Shards,
    ) -> Result<Option<PunctualSample>> {
        if scene.lights.is_empty() || texels.is_empty() {
            return Ok(None);
        }
        // At `origin`, already lifted off its surface.
        let exact = |origin: Vec3, n: Vec3| -> Vec3 {
            scene
                .lights
                .iter()
                .map(|l| punctual_irradiance(l, origin, n, tracer))
                .sum()
        };
        let texel: [Vec<Vec3>; 2] = match runs {
            Some([a, b]) if a.len() == texels.len() && b.len() == texels.len() => [a, b],
            _ => {
                let traced: Vec<Vec3> = shard::map(shards, texels.len(), |i| {
                    let mut rng = Rng::new(seed ^ SALT, i as u64, 0);
                    let n = texels.normal[i];
                    let mut sum = Vec3::ZERO;
                    for s in 0..GRID * GRID {
                        let cell = Vec2::new((s % GRID) as f32, (s / GRID) as f32);
                        let u = (cell + rng.next_vec2()) / GRID as f32;
                        let p = texels.footprint_point(i, u) + n * tracer.epsilon;
                        sum += exact(texels.punctual_point(tracer, i, p), n);
                    }
                    sum / (GRID * GRID) as f32
                })?;
                [traced.clone(), traced]
            }
        };
        let valid = texels.valid_mask();
        let mut cdf = Vec::with_capacity(scene.triangles.len());
        let mut area = 0.0f64;
        for t in 0..scene.triangles.len() {
            let [a, b, c] = scene.triangles[t].map(|v| scene.positions[v as usize].as_dvec3());
            area += 0.5 * (b - a).cross(c - a).length();
            cdf.push(area as f32);
        }
        let points = shard::map(shards, POINTS, |k| {
            let mut rng = Rng::new(seed ^ SALT, k as u64, 1);
            let t = sampling::sample_cdf(&cdf, rng.next_f32()) as u32;
            let b = sampling::triangle_point(rng.next_vec2());
            let (p, n) = triangle_point(scene, t, b);
            let [ua, ub, uc] = texels.triangle_uv[t as usize];
            let uv = ua * (1.0 - b.x - b.y) + ub * b.x + uc * b.y;
            let page = texels.triangle_page[t as usize] as usize;
            let lookup = bilinear(texels, &valid, page, uv)?;
            let read =
                |v: &[Vec3]| -> Vec3 { lookup.0.iter().map(|&(j, w)| v[j as usize] * w).sum() };
            let e = exact(p + n * tracer.epsilon, n);
            // The two runs' errors are independent: their product holds the lookup's squared
            // bias, not the footprint sampling's noise.
            let [da, db] = [&texel[0], &texel[1]].map(|v| read(v) - e);
            Some(PointError {
                square: (da * db).element_sum() / 3.0,
                border: lookup.1,
                total: read(total).element_sum() / 3.0,
                lookup: lookup.0,
            })
        })?;
        let points = points.into_iter().flatten().collect();
        Ok(Some(PunctualSample { texel, points }))
    }

    /// The same sample with each point's total read from `total` (another bake of the same
    /// texels): the exact light and the texels' punctual light do not depend on the bake, so a
    /// later pilot pair on the same atlas needs no shadow ray to be measured against.
    pub(crate) fn normalised_by(mut self, total: &[Vec3]) -> PunctualSample {
        for p in &mut self.points {
            let read: Vec3 = p.lookup.iter().map(|&(j, w)| total[j as usize] * w).sum();
            p.total = read.element_sum() / 3.0;
        }
        self
    }

    /// Relative RMS error of the lookups (over the points' mean total light).
    pub(crate) fn relative_error(&self) -> f32 {
        let n = self.points.len().max(1) as f64;
        let square: f64 = self.points.iter().map(|p| p.square as f64).sum::<f64>() / n;
        let mean: f64 = self.points.iter().map(|p| p.total as f64).sum::<f64>() / n;
        if mean > 0.0 {
            (square.max(0.0).sqrt() / mean) as f32
        } else {
            f32::NAN
        }
    }

    /// Share of the lookups that left out a gutter or buried neighbour.
    pub(crate) fn border_share(&self) -> f32 {
        let border = self.points.iter().filter(|p| p.border).count();
        border as f32 / self.points.len().max(1) as f32
    }
}

/// The texels (and weights) a renderer's bilinear lookup at page position `uv` (texel units)
/// blends, without gutters and buried texels, and whether any was left out. `None` when the
/// texel under `uv` is itself missing or buried (a point nobody sees through the lightmap).
pub(super) fn bilinear(
    texels: &Texels,
    valid: &[bool],
    page: usize,
    uv: Vec2,
) -> Option<([(u32, f32); 4], bool)> {
    let size = texels.pages[page];
    let at = |x: i64, y: i64| -> Option<u32> {
        if x < 0 || y < 0 || x >= size.width as i64 || y >= size.height as i64 {
            return None;
        }
        let j = texels.index[page][(y * size.width as i64 + x) as usize];
        (j != NO_TEXEL && valid[j as usize]).then_some(j)
    };
    at(uv.x.floor() as i64, uv.y.floor() as i64)?;
    let c = uv - Vec2::splat(0.5);
    let (x0, y0) = (c.x.floor(), c.y.floor());
    let f = c - Vec2::new(x0, y0);
    let mut out = [(0u32, 0.0f32); 4];
    let (mut sum, mut border) = (0.0, false);
    for (k, (dx, dy)) in [(0, 0), (1, 0), (0, 1), (1, 1)].into_iter().enumerate() {
        let w = if dx == 1 { f.x } else { 1.0 - f.x } * if dy == 1 { f.y } else { 1.0 - f.y };
        match at(x0 as i64 + dx, y0 as i64 + dy) {
            Some(j) => {
                out[k] = (j, w);
                sum += w;
            }
            None => border |= w > 0.0,
        }
    }
    if sum <= 0.0 {
        return None;
    }
    for o in &mut out {
        o.1 /= sum;
    }
    Some((out, border))
}
