//! The point yardstick: what a renderer shows, at random points on visible surfaces.
//!
//! The texel reference ([`super::trace`]) estimates `H/π` at the bake's own texels, so it sees the
//! error of transport and solve but not resolution error: what a renderer shows *between* texel
//! centres, where it blends four texels bilinearly (shadow and spot-cone edges, contact shadows,
//! corners, small objects). This module measures that.
//!
//! **Points.** Candidates are drawn area-weighted over every triangle of the *input* scene
//! (double-sided surfaces count twice: the loader made a flipped back instance for them, so
//! each side is drawn on its own), candidate `k` from its own random stream `(seed, k)`. A
//! candidate is **hidden** and left out (and counted) when its face looks into geometry: more
//! than `MAX_BACK` of `PROBE_RAYS` cosine-distributed probe rays from it hit back faces
//! (`validity::back_hits`, the texel validity pass's test, with unlimited reach) — a floor
//! inside a table leg, the bottom of a box resting on the floor, the inside of a closed solid.
//! Single-sided faces are seen from the front only. Candidates are drawn until `n` are visible.
//! With a [`Strip`] (`draw_in`) only the candidates in it count: the junction strip along a
//! wall, measured with all of the reference's points instead of the few a draw over the whole
//! scene puts there.
//!
//! **Estimator.** At each kept point `x` with geometric normal `n`, one sample is one path of the
//! texel reference's estimator (`Paths::reflected`: next-event estimation for punctual lights
//! and small emitters, MIS with the cosine-sampled bounce, Russian roulette) started at
//! `x + ε·n` about the surface's shading normal there (interpolated vertex normals, as texels,
//! the camera reference and renderers shade a smooth surface; on a faceted sphere the face's
//! own normal differs by up to half a facet, and irradiance about it differed from what the
//! bake stores by 7% RMS on `sphere_on_floor`), so the mean estimates `H(x)/π` at the point
//! itself (not a footprint average), with the standard error of the mean of independent paths. Paths after the first vertex read the
//! texels' `ρ` and `Le` like the texel reference, so the texel density of `config` only matters
//! for textured materials. The stopping rules (`max_samples`, `target_rel_error` over points,
//! `time_limit`) are the texel reference's; streams are seeded by (seed, point, sample), so the
//! result does not depend on the thread count.
//!
//! **Perturbed normals** ([`trace_about`] with [`Normals::Perturbed`]): the same estimator about
//! a normal that is not the surface's (a normal map's, or a tilted one), with light from below
//! the surface counted as zero — the first bounce's rays and light samples below the geometric
//! normal are dropped instead of hitting the surface's own front from just above it. The
//! yardstick of directional lightmaps (`tests/directional.rs`).
//!
//! **As a renderer reads it.** [`look_up`] takes a baked output loaded as `lightbake render`
//! loads it ([`RenderScene`]: the output glTF through the scene loader, each primitive's
//! `TEXCOORD_1` and the EXR page its `extras.lightmap` names, or its node's with the node's
//! rect for a shared mesh) and, for each point, finds the
//! baked surface under it (a short ray along `−n` from just above it; a face seen from behind
//! — the flipped copy a bake writes for a double-sided primitive, lying in the same plane — is
//! resolved by a scan for the front-facing triangle under the point), interpolates its
//! `TEXCOORD_1` and samples the page bilinearly (`Page::bilinear`: glTF's image convention,
//! texel centres, clamp-to-edge). Nothing of the bake's internal data is used, so the figure is
//! what a game engine would show.
//!
//! **Figures** ([`compare`]): relative RMSE `√mean((x−r)²)/mean(r)` over points and channels
//! ([`metrics::rmse_over_mean`], the texel figure's normalisation), also with the reference's
//! own noise taken out in quadrature ([`metrics::without_noise`]); median and p95 of the per-point
//! relative errors (per channel, floored at 5% of the mean: [`metrics::floored_relative_errors`],
//! as the benchmark's texel p95); the fraction of lookups whose bilinear footprint touches a
//! black texel (zero in every channel, with a positive weight) where the reference is more than
//! two standard errors above zero — unfilled gutters or invalid texels showing through; and the
//! reference's noise ([`metrics::noise_over_mean`]).
//!
//! **File** ([`PointReference::to_csv`]): UTF-8 CSV, `#` comment lines first, then a header and
//! one row per point: `x,y,z,nx,ny,nz,r,g,b,se_r,se_g,se_b,snx,sny,snz` — world position, unit
//! geometric normal, `H/π` (linear RGB), its standard error per channel and the unit shading
//! normal. Files without the last three columns (written before they existed) read with the
//! shading normal equal to the geometric one.
//!
//! Limits: the lookup needs the bake to keep the input's geometry (it does); a point with no
//! baked surface within a few ray offsets is counted as unmatched and left out. Emissive
//! surfaces are points like any other (a renderer adds their emission on top).

use std::path::Path;

use glam::{Vec2, Vec3};
use rayon::prelude::*;

use super::{ItemSample, Reference, ReferenceParams, SEED_SALT, trace_items};
use crate::config::BakeConfig;
use crate::lightmap::Page;
use crate::lights::triangle_area;
use crate::render::RenderScene;
use crate::sampling::{Rng, sample_cdf, triangle_point};
use crate::scene::{Scene, SurfacePoint};
use crate::texels::Texels;
use crate::texels::validity::{self, MAX_BACK, PROBE_RAYS};
use crate::trace::Tracer;
use crate::{Error, Progress, Result, metrics};

/// Mixed into the seed: point streams differ from texel and pixel streams of the same index.
const POINTS_SALT: u64 = 0x504f_494e_5453; // "POINTS"
/// Random-stream purposes of a candidate: where it lies, how its probes turn.
const PLACE: u64 = 0;
const PROBE: u64 = 1;
/// Candidates drawn at most, per point asked for, before giving up on finding visible ones.
const MAX_DRAWS_PER_POINT: usize = 20;
/// The baked surface under a point is searched this many ray offsets above and below it.
const LOCATE_OFFSETS: f32 = 4.0;

/// A point on a surface: world position, the unit geometric normal of its (front) face and the
/// surface's unit interpolated (shading) normal there, turned to the face's side.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Point {
    /// World position.
    pub position: Vec3,
    /// Unit geometric normal of the face.
    pub normal: Vec3,
    /// Unit interpolated vertex normal, on the face's side.
    pub shading_normal: Vec3,
}

impl Point {
    /// A point off the surfaces (free space, where a probe is read) about a unit normal: the
    /// face's and the shading normal are both `normal`.
    #[must_use]
    pub fn free(position: Vec3, normal: Vec3) -> Point {
        Point {
            position,
            normal,
            shading_normal: normal,
        }
    }
}

/// Visible points drawn on a scene's surfaces.
#[derive(Clone, Debug, Default)]
pub struct PointSet {
    /// The visible points.
    pub points: Vec<Point>,
    /// Candidates left out as hidden (inside geometry) before the last kept point.
    pub hidden: usize,
}

/// Draws `n` visible points area-weighted over `scene`'s triangles (see the module docs).
pub fn draw(scene: &Scene, tracer: &Tracer, n: usize, seed: u64) -> Result<PointSet> {
    draw_in(scene, tracer, n, seed, None)
}

/// [`draw`], or with a `strip` only points in it: area-weighted over the strip's part of the
/// surfaces (candidates are drawn on the triangles that reach into the strip and those outside
/// it are drawn again), so that a junction strip a texel wide gets all `n` points instead of
/// the few a draw over the whole scene puts there. Points within two ray offsets
/// ([`Tracer::epsilon`], 0.4 mm on a room) of the strip's plane are left out: paths from
/// there may start behind the wall (measured on `two_rooms_angled`: 52 of 2036 points of a
/// 3 cm strip lay that close, and some read room A's light through the wall).
pub(crate) fn draw_in(
    scene: &Scene,
    tracer: &Tracer,
    n: usize,
    seed: u64,
    strip: Option<&Strip>,
) -> Result<PointSet> {
    let mut area = 0.0f64;
    let cumulative: Vec<f64> = (scene.triangles.iter())
        .map(|t| {
            let reaches = strip.is_none_or(|s| s.reaches(t.map(|i| scene.positions[i as usize])));
            if reaches {
                area += triangle_area(scene, t) as f64;
            }
            area
        })
        .collect();
    if area <= 0.0 || !area.is_finite() {
        return Err(Error::Option(match strip {
            None => "the scene has no surface to draw points on".into(),
            Some(s) => format!("no surface of the scene reaches into the strip {s}"),
        }));
    }
    let cdf: Vec<f32> = cumulative.iter().map(|a| (a / area) as f32).collect();
    let limit = (MAX_BACK * PROBE_RAYS as f32) as u32;
    // Paths start a ray offset off their surface, so from a point closer than that to the
    // strip's plane (a wall) they may start behind the wall: the reference cannot tell which
    // side such a point is on, and neither can a pixel of any renderer.
    let near_plane = 2.0 * tracer.epsilon;
    let candidate = |k: usize| -> Candidate {
        let mut rng = Rng::new(seed ^ POINTS_SALT, k as u64, PLACE);
        let t = sample_cdf(&cdf, rng.next_f32()) as u32;
        let b = triangle_point(rng.next_vec2());
        let sp = scene.surface_point(t, b);
        if sp.n_geo == Vec3::ZERO {
            return Candidate::Hidden;
        }
        if strip.is_some_and(|s| !s.contains(sp.p, sp.n_geo) || s.distance(sp.p) <= near_plane) {
            return Candidate::Outside;
        }
        let shift = Rng::new(seed ^ POINTS_SALT, k as u64, PROBE).next_vec2();
        let back = validity::back_hits(tracer, sp.p, sp.n_geo, PROBE_RAYS, shift, f32::INFINITY);
        match back <= limit {
            true => Candidate::Visible(Point {
                position: sp.p,
                normal: sp.n_geo,
                shading_normal: sp.n,
            }),
            false => Candidate::Hidden,
        }
    };
    // Candidates outside a strip cost no ray; a triangle may reach only a sliver of it.
    let max_draws = n.max(1) * MAX_DRAWS_PER_POINT * if strip.is_some() { 1024 } else { 1 };
    let mut set = PointSet::default();
    let (mut drawn, mut outside) = (0, 0);
    while set.points.len() < n {
        if drawn >= max_draws {
            let place = strip.map_or(String::new(), |s| {
                format!(" ({outside} outside the strip {s})")
            });
            return Err(Error::Option(format!(
                "only {} of {drawn} points drawn on the scene's surfaces are visible{place}",
                set.points.len()
            )));
        }
        let batch: Vec<Candidate> = (drawn..drawn + n).into_par_iter().map(candidate).collect();
        drawn += n;
        for c in batch {
            if set.points.len() == n {
                break;
            }
            match c {
                Candidate::Visible(p) => set.points.push(p),
                Candidate::Hidden => set.hidden += 1,
                Candidate::Outside => outside += 1,
            }
        }
    }
    Ok(set)
}

/// What became of a drawn candidate point.
enum Candidate {
    Visible(Point),
    /// Its face looks into geometry (or is degenerate).
    Hidden,
    /// Not in the strip asked for.
    Outside,
}

/// A strip beside a plane: the points `0 < (p − origin)·n̂ ≤ width` on surfaces not parallel to
/// the plane (`|normal·n̂| < ½`). With the plane of a wall and `n̂` towards its dark side, these
/// are the floor, ceiling and side walls along the wall's foot, head and edges: the junction
/// strip, where a texel straddling the wall leaks. Written and parsed as
/// `x,y,z,nx,ny,nz,width`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Strip {
    pub(crate) origin: Vec3,
    /// Unit normal of the plane, towards the strip.
    pub(crate) normal: Vec3,
    pub(crate) width: f32,
}

impl Strip {
    /// The strip of `width` beside the plane through `origin` with normal `normal` (any length).
    pub fn new(origin: Vec3, normal: Vec3, width: f32) -> Strip {
        Strip {
            origin,
            normal: normal.normalize_or_zero(),
            width,
        }
    }

    /// Signed distance of `position` from the plane, positive on the strip's side.
    pub(crate) fn distance(&self, position: Vec3) -> f32 {
        (position - self.origin).dot(self.normal)
    }

    /// Whether a point at `position` on a face with unit normal `normal` is in the strip.
    pub fn contains(&self, position: Vec3, normal: Vec3) -> bool {
        let d = self.distance(position);
        d > 0.0 && d <= self.width && normal.dot(self.normal).abs() < 0.5
    }

    /// Whether some of the triangle with these corners may be in the strip: it is not parallel
    /// to the plane and its distances from it overlap `(0, width]`.
    fn reaches(&self, corners: [Vec3; 3]) -> bool {
        let [a, b, c] = corners;
        let normal = (b - a).cross(c - a).normalize_or_zero();
        let d = corners.map(|p| self.distance(p));
        let (low, high) = (d[0].min(d[1]).min(d[2]), d[0].max(d[1]).max(d[2]));
        high > 0.0 && low <= self.width && normal.dot(self.normal).abs() < 0.5
    }
}

impl std::fmt::Display for Strip {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (o, n) = (self.origin, self.normal);
        write!(
            f,
            "{},{},{},{},{},{},{}",
            o.x, o.y, o.z, n.x, n.y, n.z, self.width
        )
    }
}

impl std::str::FromStr for Strip {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Strip, String> {
        let expected = "a strip is seven numbers: x,y,z,nx,ny,nz,width";
        let v: Vec<f32> = (s.split(','))
            .map(|x| x.trim().parse::<f32>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|e| format!("{expected} ({e})"))?;
        let [x, y, z, nx, ny, nz, width] = v[..] else {
            return Err(format!("{expected}, not {}", v.len()));
        };
        let normal = Vec3::new(nx, ny, nz);
        if !v.iter().all(|c| c.is_finite()) || normal == Vec3::ZERO || width <= 0.0 {
            return Err(format!(
                "{expected}, all finite, a non-zero normal and a positive width"
            ));
        }
        Ok(Strip::new(Vec3::new(x, y, z), normal, width))
    }
}

/// Path-traces `H/π` at every point until a stopping rule of `params` holds (items of the
/// returned [`Reference`] are the points).
pub fn trace(
    scene: &Scene,
    texels: &Texels,
    tracer: &Tracer,
    points: &[Point],
    params: &ReferenceParams,
    progress: &dyn Progress,
) -> Result<Reference> {
    trace_about(
        (scene, texels, tracer),
        points,
        Normals::Shading,
        params,
        progress,
    )
}

/// How [`trace_about`] reads each point's `shading_normal`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Normals {
    /// The surface's smooth normal ([`trace`]).
    Shading,
    /// A perturbed normal (a normal map's): light from below the surface (the point's
    /// geometric `normal`) counts as zero. The irradiance a renderer should reconstruct there
    /// from directional pages (`lightmap::directional`).
    Perturbed,
}

/// [`trace`], with the points' `shading_normal` read as `normals` says.
pub fn trace_about(
    (scene, texels, tracer): (&Scene, &Texels, &Tracer),
    points: &[Point],
    normals: Normals,
    params: &ReferenceParams,
    progress: &dyn Progress,
) -> Result<Reference> {
    let eps = tracer.epsilon;
    let sample: &ItemSample = &|paths, i, sample, rays| {
        let mut rng = Rng::new(
            params.seed ^ SEED_SALT ^ POINTS_SALT,
            i as u64,
            sample as u64,
        );
        let p = points[i];
        paths.reflected(
            p.position + p.normal * eps,
            p.shading_normal,
            (normals == Normals::Perturbed).then_some(p.normal),
            &mut rng,
            rays,
        )
    };
    trace_items(
        (scene, texels, tracer),
        points.len(),
        params,
        progress,
        "reference points",
        sample,
    )
}

/// [`super::prepare`] (texels as a bake's with the same `config`, for the materials the paths
/// read), then [`draw`] `n` points with `params.seed` and [`trace`] them: the point reference of
/// the *input* scene, and the tracing run's figures (rays, time, noise).
pub fn compute(
    input: &Path,
    config: &BakeConfig,
    params: &ReferenceParams,
    n: usize,
    progress: &dyn Progress,
) -> Result<(PointReference, Reference)> {
    compute_in(input, config, params, n, None, progress)
}

/// [`compute`] with the points drawn in `strip` only (`draw_in`).
pub fn compute_in(
    input: &Path,
    config: &BakeConfig,
    params: &ReferenceParams,
    n: usize,
    strip: Option<&Strip>,
    progress: &dyn Progress,
) -> Result<(PointReference, Reference)> {
    params.validate()?;
    let mut p = super::prepare(input, config, progress)?;
    // A bake's pilot pair kept from the density pilot is no use to a path tracer.
    p.density.pair = None;
    let set = draw_in(&p.scene, &p.tracer, n, params.seed, strip)?;
    let traced = trace(
        &p.scene,
        &p.texels,
        &p.tracer,
        &set.points,
        params,
        progress,
    )?;
    Ok((PointReference::new(set, &traced), traced))
}

/// What a point reference file holds: points and their path-traced `H/π`.
#[derive(Clone, Debug, Default)]
pub struct PointReference {
    /// The points.
    pub points: Vec<Point>,
    /// Path-traced `H/π` per point.
    pub mean: Vec<Vec3>,
    /// Standard error of `mean`, per channel.
    pub std_error: Vec<Vec3>,
    /// Candidates left out as hidden.
    pub hidden: usize,
    /// Paths per point.
    pub(crate) samples: u32,
}

impl PointReference {
    /// The points of `set` with their estimates in `traced`.
    pub fn new(set: PointSet, traced: &Reference) -> Self {
        PointReference {
            points: set.points,
            mean: traced.mean.clone(),
            std_error: traced.std_error.clone(),
            hidden: set.hidden,
            samples: traced.samples,
        }
    }

    /// The points in `strip` (the junction strip along a wall, see [`Strip`]).
    pub fn in_strip(&self, strip: &Strip) -> PointReference {
        let keep: Vec<usize> = (0..self.points.len())
            .filter(|&k| strip.contains(self.points[k].position, self.points[k].normal))
            .collect();
        PointReference {
            points: keep.iter().map(|&k| self.points[k]).collect(),
            mean: keep.iter().map(|&k| self.mean[k]).collect(),
            std_error: keep.iter().map(|&k| self.std_error[k]).collect(),
            hidden: self.hidden,
            samples: self.samples,
        }
    }

    /// The CSV file (see the module docs); `f32` values print in their shortest exact form.
    pub fn to_csv(&self) -> String {
        let mut s = format!(
            "# lightbake point reference: path-traced H/pi at points on visible surfaces\n\
             # points={} hidden={} samples={}\n\
             x,y,z,nx,ny,nz,r,g,b,se_r,se_g,se_b,snx,sny,snz\n",
            self.points.len(),
            self.hidden,
            self.samples
        );
        for ((p, m), se) in self.points.iter().zip(&self.mean).zip(&self.std_error) {
            let row = [p.position, p.normal, *m, *se, p.shading_normal]
                .map(|v| v.to_array().map(|c| c.to_string()).join(","));
            s.push_str(&row.join(","));
            s.push('\n');
        }
        s
    }

    /// Reads [`PointReference::to_csv`]'s format back; `what` names the file in errors.
    pub fn from_csv(text: &str, what: &Path) -> Result<Self> {
        let bad = |line: usize, m: &str| Error::invalid(what, format!("line {line}: {m}"));
        let mut r = PointReference::default();
        let mut header = false;
        for (k, line) in text.lines().enumerate() {
            let line = line.trim();
            if let Some(comment) = line.strip_prefix('#') {
                for (key, value) in comment.split_whitespace().filter_map(|w| w.split_once('=')) {
                    match key {
                        "hidden" => r.hidden = value.parse().unwrap_or(0),
                        "samples" => r.samples = value.parse().unwrap_or(0),
                        _ => {}
                    }
                }
                continue;
            }
            if line.is_empty() {
                continue;
            }
            if !header {
                if !line.starts_with("x,y,z,") {
                    return Err(bad(
                        k + 1,
                        "expected the header x,y,z,nx,ny,nz,r,g,b,se_r,se_g,se_b",
                    ));
                }
                header = true;
                continue;
            }
            let v: Vec<f32> = line
                .split(',')
                .map(|c| c.trim().parse::<f32>())
                .collect::<std::result::Result<_, _>>()
                .map_err(|e| bad(k + 1, &e.to_string()))?;
            let (shading, v) = match v[..] {
                [.., snx, sny, snz] if v.len() == 15 => (Some(Vec3::new(snx, sny, snz)), &v[..12]),
                _ => (None, &v[..]),
            };
            let [x, y, z, nx, ny, nz, r_, g, b, sr, sg, sb] = v[..] else {
                return Err(bad(
                    k + 1,
                    &format!("expected 12 or 15 numbers, got {}", v.len()),
                ));
            };
            let normal = Vec3::new(nx, ny, nz);
            r.points.push(Point {
                position: Vec3::new(x, y, z),
                normal,
                shading_normal: shading.unwrap_or(normal),
            });
            r.mean.push(Vec3::new(r_, g, b));
            r.std_error.push(Vec3::new(sr, sg, sb));
        }
        if r.points.is_empty() {
            return Err(Error::invalid(what, "no points"));
        }
        Ok(r)
    }
}

/// A point's value as a renderer shows it.
#[derive(Clone, Copy, Debug)]
pub struct Lookup {
    /// Bilinear `H/π` from the page at the point's `TEXCOORD_1`.
    pub value: Vec3,
    /// A texel of the bilinear footprint with a positive weight is black in every channel.
    pub touches_black: bool,
    /// Where it was read: the index into [`RenderScene::pages`] and the `TEXCOORD_1` there.
    pub page: u32,
    /// The `TEXCOORD_1` it was read at, on `page`.
    pub uv: Vec2,
    /// The baked surface's interpolated vertex normal at the point.
    pub shading_normal: Vec3,
}

/// Reads the baked lightmap at every point as a renderer does (see the module docs); `None`
/// where no baked surface with a lightmap lies under the point.
pub fn look_up(baked: &RenderScene, points: &[Point]) -> Vec<Option<Lookup>> {
    points
        .par_iter()
        .map(|p| {
            let sp = locate(&baked.scene, &baked.tracer, p)?;
            let k = baked.instance_page[sp.instance as usize]?;
            Some(lookup_page(&baked.pages[k as usize], k, &sp))
        })
        .collect()
}

fn lookup_page(page: &Page, k: u32, sp: &SurfacePoint) -> Lookup {
    let touches_black = page
        .footprint(sp.uv1)
        .iter()
        .any(|&(k, w)| w > 0.0 && page.rgb[k].max_element() <= 0.0);
    Lookup {
        value: page.bilinear(sp.uv1),
        touches_black,
        page: k,
        uv: sp.uv1,
        shading_normal: sp.n,
    }
}

/// The front-facing baked surface under `p` (instance, interpolated `TEXCOORD_1` and normal).
fn locate(scene: &Scene, tracer: &Tracer, p: &Point) -> Option<SurfacePoint> {
    let reach = LOCATE_OFFSETS * tracer.epsilon;
    let facing = |t: u32, b: Vec2| {
        let sp = scene.surface_point(t, b);
        (sp.n_geo.dot(p.normal) > 0.9).then_some(sp)
    };
    let hit = tracer.closest(p.position + p.normal * reach, -p.normal, 2.0 * reach);
    if let Some(hit) = hit
        && hit.front
        && let Some(found) = facing(hit.triangle, hit.bary)
    {
        return Some(found);
    }
    // Seen from behind or missed: a coplanar flipped copy won the tie, or the point lies on an
    // edge. Scan for the nearest front-facing triangle whose plane and interior hold the point.
    let mut best: Option<(f32, u32, Vec2)> = None;
    for (t, tri) in scene.triangles.iter().enumerate() {
        let [a, b, c] = tri.map(|v| scene.positions[v as usize]);
        let n = (b - a).cross(c - a);
        let n_len = n.length();
        if n_len <= 0.0 || n.dot(p.normal) <= 0.9 * n_len {
            continue;
        }
        let distance = (p.position - a).dot(n / n_len).abs();
        if distance > reach || best.is_some_and(|(d, ..)| d <= distance) {
            continue;
        }
        if let Some(bary) = barycentrics(a, b, c, p.position, reach / n_len.sqrt()) {
            best = Some((distance, t as u32, bary));
        }
    }
    best.and_then(|(_, t, b)| facing(t, b))
}

/// Barycentrics `(u, v)` of `p` projected onto triangle `abc` when inside it (each coordinate
/// at least `-slack`).
fn barycentrics(a: Vec3, b: Vec3, c: Vec3, p: Vec3, slack: f32) -> Option<Vec2> {
    let (e1, e2, d) = (b - a, c - a, p - a);
    let (d11, d12, d22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
    let (d1, d2) = (d.dot(e1), d.dot(e2));
    let det = d11 * d22 - d12 * d12;
    if det <= 0.0 {
        return None;
    }
    let u = (d22 * d1 - d12 * d2) / det;
    let v = (d11 * d2 - d12 * d1) / det;
    (u >= -slack && v >= -slack && 1.0 - u - v >= -slack).then_some(Vec2::new(u, v))
}

/// A bake read as a renderer shows it, against a point reference (see the module docs).
#[derive(Clone, Copy, Debug)]
pub struct PointComparison {
    /// Points compared.
    pub points: usize,
    /// Points with no baked, lightmapped surface under them (left out).
    pub unmatched: usize,
    /// `√mean((x−r)²) / mean(r)` over points and channels.
    pub rmse: f32,
    /// `rmse` with the reference's noise taken out in quadrature.
    pub rmse_without_noise: f32,
    /// The reference's relative RMS noise `√mean(σ²) / mean(r)`.
    pub noise: f32,
    /// Median and 95th percentile of per-point, per-channel relative errors (floored at 5%
    /// of the mean).
    pub median: f32,
    /// The 95th percentile of the same relative errors (see `median`).
    pub p95: f32,
    /// Fraction of lookups whose footprint touches a black texel where the reference is not black.
    pub black_touch: f32,
    /// `Σx/Σr − 1`: how much brighter the bake is on the whole.
    pub(crate) bias: f32,
}

impl PointComparison {
    /// The figures in one block of lines.
    pub fn summary(&self) -> String {
        format!(
            "points compared        {} ({} without a baked surface)\n\
             relative RMSE          {:.2}% ({:.2}% without the reference's noise)\n\
             median / p95 error     {:.2}% / {:.2}%\n\
             lookups touching black {:.2}%\n\
             bias                   {:+.2}%\n\
             reference noise        {:.2}%",
            self.points,
            self.unmatched,
            self.rmse * 100.0,
            self.rmse_without_noise * 100.0,
            self.median * 100.0,
            self.p95 * 100.0,
            self.black_touch * 100.0,
            self.bias * 100.0,
            self.noise * 100.0
        )
    }
}

/// Compares `baked` (read as a renderer reads it) with the point reference `r`.
pub fn compare(baked: &RenderScene, r: &PointReference) -> PointComparison {
    let lookups = look_up(baked, &r.points);
    let (mut x, mut m, mut se) = (Vec::new(), Vec::new(), Vec::new());
    let mut black = 0usize;
    for ((l, mean), s) in lookups.iter().zip(&r.mean).zip(&r.std_error) {
        if let Some(l) = l {
            x.push(l.value);
            m.push(*mean);
            se.push(*s);
            let lit = (*mean - 2.0 * *s).max_element() > 0.0;
            black += (l.touches_black && lit) as usize;
        }
    }
    let rmse = metrics::rmse_over_mean(&x, &m, &[]);
    let noise = metrics::noise_over_mean(&se, &m, &[]);
    let [median, p95] =
        metrics::percentiles(&metrics::floored_relative_errors(&x, &m, &[]), [0.5, 0.95]);
    PointComparison {
        points: x.len(),
        unmatched: lookups.len() - x.len(),
        rmse,
        rmse_without_noise: metrics::without_noise(rmse, noise),
        noise,
        median,
        p95,
        black_touch: black as f32 / x.len().max(1) as f32,
        bias: metrics::relative_bias(&x, &m, &[]),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_strip_reads_back_as_written_and_refuses_what_is_not_one() {
        let strip: Strip = "0.5, 0, -1, 2, 0, 0, 0.03".parse().unwrap();
        assert_eq!(strip, Strip::new(Vec3::new(0.5, 0.0, -1.0), Vec3::X, 0.03));
        assert_eq!(strip.to_string().parse::<Strip>().unwrap(), strip);
        // In the strip: beside the plane on its side, within the width, not parallel to it.
        assert!(strip.contains(Vec3::new(0.51, 0.0, 0.0), Vec3::Y));
        assert!(!strip.contains(Vec3::new(0.49, 0.0, 0.0), Vec3::Y));
        assert!(!strip.contains(Vec3::new(0.54, 0.0, 0.0), Vec3::Y));
        assert!(!strip.contains(Vec3::new(0.51, 0.0, 0.0), Vec3::NEG_X));
        for bad in [
            "1,2,3",
            "0,0,0,0,0,0,1",
            "0,0,0,1,0,0,0",
            "0,0,0,1,0,0,x",
            "0,0,0,1,0,0,inf",
        ] {
            assert!(bad.parse::<Strip>().is_err(), "{bad} parsed");
        }
    }

    #[test]
    fn csv_round_trips() {
        let r = PointReference {
            points: vec![Point {
                position: Vec3::new(0.1, -2.5, 3.0e-7),
                normal: Vec3::Y,
                shading_normal: Vec3::new(0.6, 0.8, 0.0),
            }],
            mean: vec![Vec3::new(0.3, 0.25, 1.0 / 3.0)],
            std_error: vec![Vec3::splat(0.001)],
            hidden: 4,
            samples: 256,
        };
        let back = PointReference::from_csv(&r.to_csv(), "p.csv".as_ref()).unwrap();
        assert_eq!(back.points, r.points);
        assert_eq!((back.mean, back.std_error), (r.mean, r.std_error));
        assert_eq!((back.hidden, back.samples), (4, 256));
        assert!(PointReference::from_csv("x,y,z\n1,2\n", "p.csv".as_ref()).is_err());
        // A file from before the shading normal: it reads as the geometric normal.
        let old = "x,y,z,nx,ny,nz,r,g,b,se_r,se_g,se_b\n0,0,0,0,1,0,0.5,0.5,0.5,0,0,0\n";
        let old = PointReference::from_csv(old, "p.csv".as_ref()).unwrap();
        assert_eq!(old.points[0].shading_normal, Vec3::Y);
    }

    #[test]
    fn barycentrics_of_inside_and_outside_points() {
        let (a, b, c) = (Vec3::ZERO, Vec3::X, Vec3::Z);
        let bary = barycentrics(a, b, c, Vec3::new(0.25, 0.1, 0.5), 0.0).unwrap();
        assert!((bary - Vec2::new(0.25, 0.5)).length() < 1e-6);
        assert!(barycentrics(a, b, c, Vec3::new(0.8, 0.0, 0.8), 0.0).is_none());
    }
}
