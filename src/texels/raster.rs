//! Conservative rasterisation of lightmap charts into texels, by exact polygon clipping.
//!
//! Each triangle's lightmap UVs (in texel units of its page) are clipped against every texel
//! square they overlap (Sutherland–Hodgman, in f64). The clipped polygon's area is the exact
//! fraction of the texel the triangle covers, and its centroid, mapped to world space through
//! the triangle's barycentrics, is where that piece of surface sits. A texel's patch is the
//! world-area-weighted average of its pieces ("fragments"):
//!
//! | field      | from each fragment (weighted by its world area)                            |
//! |------------|-----------------------------------------------------------------------------|
//! | `area`     | covered fraction × triangle world area / triangle UV area (summed)          |
//! | `position` | clipped polygon's centroid in world space                                   |
//! | `normal`   | vertex normals interpolated there (dominant face's normal if they cancel)    |
//! | `albedo`   | `base_color × base_color_texture`, texture averaged over the polygon        |
//! | `emission` | `emission × emissive_texture`, same sampling                                |
//!
//! A texel is a patch when its total coverage exceeds [`MIN_COVERAGE`], and also when it is the
//! best-covered texel of some triangle, so that every triangle owns at least one texel (a
//! triangle smaller than a texel still reflects light). Triangles with degenerate lightmap UVs
//! get the texel under their UV centroid.
//!
//! Work is split into bands of [`BAND_ROWS`] rows per page, processed in parallel; each band
//! sees its triangles in scene order and owns its rows, so sums never depend on the thread
//! count, and texel ids follow (page, y, x).

use std::collections::BTreeMap;

use glam::{DMat2, DVec2, DVec3, Vec2, Vec3};
use rayon::prelude::*;

use super::{NO_TEXEL, Texels};
use crate::Result;
use crate::atlas::{Atlas, PageSize};
use crate::scene::MAX_ALBEDO;
use crate::scene::{Material, Scene};

/// Rows per parallel work item: small enough to balance two cores on one page, large enough
/// that triangles rarely straddle bands.
const BAND_ROWS: u32 = 16;
/// A texel covered less than this fraction is a patch only when some triangle needs it.
const MIN_COVERAGE: f64 = 1e-4;
/// Lightmap UV area (texel²) below which a triangle has no usable parameterisation.
const MIN_UV_AREA: f64 = 1e-12;
/// A triangle clipped by four half-planes has at most seven vertices.
const MAX_POLYGON: usize = 8;
/// Texture sample points per fragment: the centroid plus one per polygon vertex.
const MAX_SAMPLES: usize = MAX_POLYGON + 1;

/// Rasterises every scene triangle into its lightmap page: one patch per covered texel.
pub fn build(scene: &Scene, atlas: &Atlas) -> Result<Texels> {
    let setups: Vec<TriangleSetup> = (0..scene.triangles.len() as u32)
        .into_par_iter()
        .map(|t| TriangleSetup::new(scene, atlas, t))
        .collect();
    let bands = bin_into_bands(&atlas.pages, &setups);
    let results: Vec<BandResult> = bands
        .par_iter()
        .map(|band| rasterise_band(scene, &setups, band))
        .collect();

    // Flatten the bands (already in (page, y, x) order) and pick each triangle's best texel.
    let mut records = Vec::with_capacity(results.iter().map(|r| r.texels.len()).sum());
    let mut best: Vec<Option<(usize, f64)>> = vec![None; setups.len()];
    for result in results {
        let offset = records.len();
        for (t, local, area) in result.best {
            let slot = &mut best[t as usize];
            if slot.is_none_or(|(_, a)| area > a) {
                *slot = Some((offset + local, area));
            }
        }
        records.extend(result.texels);
    }
    let mut keep: Vec<bool> = records
        .iter()
        .map(|r| r.coverage.fraction > MIN_COVERAGE)
        .collect();
    for &(record, _) in best.iter().flatten() {
        keep[record] = true;
    }

    // Triangles that cover nothing (degenerate UVs) take the texel under their UV centroid,
    // creating it from the triangle alone when nothing else covers it.
    let mut triangle_keys = Vec::with_capacity(setups.len());
    let mut fallback_texels: BTreeMap<TexelKey, Coverage> = BTreeMap::new();
    for (t, s) in setups.iter().enumerate() {
        if let Some((record, _)) = best[t] {
            triangle_keys.push(records[record].key);
            continue;
        }
        let key = s.centroid_texel(&atlas.pages);
        triangle_keys.push(key);
        match records.binary_search_by_key(&key, |r| r.key) {
            Ok(record) => keep[record] = true,
            Err(_) => fallback_texels
                .entry(key)
                .or_default()
                .add(&whole_triangle_fragment(scene, s, t as u32)),
        }
    }
    let mut kept: Vec<Record> = records
        .into_iter()
        .zip(keep)
        .filter_map(|(r, k)| k.then_some(r))
        .chain(
            fallback_texels
                .into_iter()
                .map(|(key, coverage)| Record { key, coverage }),
        )
        .collect();
    kept.sort_by_key(|r| r.key);

    let patches: Vec<Patch> = kept
        .par_iter()
        .map(|r| Patch::new(scene, &setups, r))
        .collect();
    let texels = assemble(atlas, &setups, &kept, &patches, &triangle_keys);
    #[cfg(debug_assertions)]
    texels.validate();
    Ok(texels)
}

/// Lays the patches out as [`Texels`] and resolves every triangle's texel.
fn assemble(
    atlas: &Atlas,
    setups: &[TriangleSetup],
    kept: &[Record],
    patches: &[Patch],
    triangle_keys: &[TexelKey],
) -> Texels {
    let n = kept.len();
    let mut texels = Texels {
        pages: atlas.pages.clone(),
        position: Vec::with_capacity(n),
        normal: Vec::with_capacity(n),
        area: Vec::with_capacity(n),
        albedo: Vec::with_capacity(n),
        emission: Vec::with_capacity(n),
        page: Vec::with_capacity(n),
        xy: Vec::with_capacity(n),
        triangle: Vec::with_capacity(n),
        du: Vec::with_capacity(n),
        dv: Vec::with_capacity(n),
        jitter: vec![1.0; n],
        index: atlas
            .pages
            .iter()
            .map(|p| vec![NO_TEXEL; (p.width * p.height) as usize])
            .collect(),
        triangle_texel: Vec::new(),
        triangle_uv: setups.iter().map(|s| s.uv.map(|q| q.as_vec2())).collect(),
        triangle_page: setups.iter().map(|s| s.page).collect(),
        invalid: Vec::new(),
        cuts: Default::default(),
    };
    let cell = |(page, y, x): TexelKey| {
        (
            page as usize,
            (y * atlas.pages[page as usize].width + x) as usize,
        )
    };
    for (id, (record, patch)) in kept.iter().zip(patches).enumerate() {
        let (page, y, x) = record.key;
        let (p, k) = cell(record.key);
        texels.index[p][k] = id as u32;
        texels.position.push(patch.position);
        texels.normal.push(patch.normal);
        texels.area.push(patch.area);
        texels.albedo.push(patch.albedo);
        texels.emission.push(patch.emission);
        texels.page.push(page);
        texels.xy.push([x, y]);
        texels.triangle.push(patch.triangle);
        texels.du.push(patch.du);
        texels.dv.push(patch.dv);
    }
    texels.triangle_texel = triangle_keys
        .iter()
        .map(|&key| {
            let (p, k) = cell(key);
            texels.index[p][k]
        })
        .collect();
    texels
}

/// (page, y, x): sorts texels in id order.
type TexelKey = (u32, u32, u32);

/// Everything rasterisation needs about one scene triangle, in texel units of its page.
struct TriangleSetup {
    page: u32,
    /// Lightmap UVs in texel units.
    uv: [DVec2; 3],
    /// Texel coordinates (relative to `uv[0]`) → barycentrics of vertices 1 and 2;
    /// `None` when the lightmap UVs (or the triangle itself) are degenerate.
    to_barycentric: Option<DMat2>,
    /// World area per texel² of UV area.
    world_per_texel: f64,
    world_area: f64,
    /// Unit normal of the front face (zero for a degenerate triangle).
    geometric_normal: DVec3,
    /// World step of one texel in x and in y on the triangle's plane.
    du: Vec3,
    dv: Vec3,
    material: u32,
}

impl TriangleSetup {
    fn new(scene: &Scene, atlas: &Atlas, t: u32) -> TriangleSetup {
        let (uv, page) = atlas.triangle_uv(scene, t);
        let size = atlas.pages[page as usize];
        let texel_scale = DVec2::new(size.width as f64, size.height as f64);
        let uv = uv.map(|q| q.as_dvec2() * texel_scale);
        let p = scene.triangles[t as usize].map(|v| scene.positions[v as usize].as_dvec3());
        let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
        let cross = e1.cross(e2);
        let world_area = 0.5 * cross.length();
        let geometric_normal = cross.normalize_or_zero();
        let uv_edges = DMat2::from_cols(uv[1] - uv[0], uv[2] - uv[0]);
        let uv_area = 0.5 * uv_edges.determinant().abs();
        let usable = uv_area > MIN_UV_AREA && world_area > 0.0;
        let to_barycentric = usable.then(|| uv_edges.inverse());
        let (du, dv) = match to_barycentric {
            // The UV→world Jacobian: world(q) = p0 + [e1 e2]·M⁻¹·(q − q0).
            Some(m) => (
                e1 * m.x_axis.x + e2 * m.x_axis.y,
                e1 * m.y_axis.x + e2 * m.y_axis.y,
            ),
            // No parameterisation: an orthonormal frame on the plane, one texel ≈ the triangle.
            None => {
                let tangent = e1.normalize_or_zero();
                let side = world_area.sqrt();
                (tangent * side, geometric_normal.cross(tangent) * side)
            }
        };
        let instance = scene.triangle_instance[t as usize] as usize;
        TriangleSetup {
            page,
            uv,
            to_barycentric,
            world_per_texel: if usable { world_area / uv_area } else { 0.0 },
            world_area,
            geometric_normal,
            du: du.as_vec3(),
            dv: dv.as_vec3(),
            material: scene.instances[instance].material,
        }
    }

    /// The texel under the UV centroid (clamped into the page).
    fn centroid_texel(&self, pages: &[PageSize]) -> TexelKey {
        let c = (self.uv[0] + self.uv[1] + self.uv[2]) / 3.0;
        let size = pages[self.page as usize];
        let x = (c.x.max(0.0) as u32).min(size.width - 1);
        let y = (c.y.max(0.0) as u32).min(size.height - 1);
        (self.page, y, x)
    }

    /// Texel rows the triangle overlaps, clamped to the page.
    fn rows(&self, height: u32) -> std::ops::Range<u32> {
        let min = self.uv.iter().map(|q| q.y).fold(f64::INFINITY, f64::min);
        let max = self
            .uv
            .iter()
            .map(|q| q.y)
            .fold(f64::NEG_INFINITY, f64::max);
        span(min, max, height)
    }
}

/// Texel indices overlapped by [min, max], clamped to [0, n).
fn span(min: f64, max: f64, n: u32) -> std::ops::Range<u32> {
    let lo = (min.floor().max(0.0) as u32).min(n);
    let hi = (max.ceil().max(0.0) as u32).min(n);
    lo..hi
}

/// One parallel work item: rows `rows` of page `page` and the triangles overlapping them.
struct Band {
    page: u32,
    width: u32,
    rows: std::ops::Range<u32>,
    triangles: Vec<u32>,
}

fn bin_into_bands(pages: &[PageSize], setups: &[TriangleSetup]) -> Vec<Band> {
    let mut first_band = Vec::with_capacity(pages.len());
    let mut bands = Vec::new();
    for (page, size) in pages.iter().enumerate() {
        first_band.push(bands.len());
        for y0 in (0..size.height).step_by(BAND_ROWS as usize) {
            bands.push(Band {
                page: page as u32,
                width: size.width,
                rows: y0..(y0 + BAND_ROWS).min(size.height),
                triangles: Vec::new(),
            });
        }
    }
    for (t, s) in setups.iter().enumerate() {
        if s.to_barycentric.is_none() {
            continue;
        }
        let rows = s.rows(pages[s.page as usize].height);
        if rows.is_empty() {
            continue;
        }
        let first = first_band[s.page as usize];
        for b in rows.start / BAND_ROWS..=(rows.end - 1) / BAND_ROWS {
            bands[first + b as usize].triangles.push(t as u32);
        }
    }
    bands
}

/// Sums of one texel's fragments (weights are world areas).
#[derive(Clone, Copy, Debug, Default)]
struct Coverage {
    /// Covered fraction of the texel's UV square.
    fraction: f64,
    /// World area covered.
    area: f64,
    position: DVec3,
    normal: DVec3,
    albedo: DVec3,
    emission: DVec3,
    /// The triangle with the largest world area in the texel, and that area.
    dominant: u32,
    dominant_area: f64,
}

/// One triangle's piece of one texel.
struct Fragment {
    triangle: u32,
    fraction: f64,
    area: f64,
    position: DVec3,
    normal: DVec3,
    albedo: DVec3,
    emission: DVec3,
}

impl Coverage {
    fn add(&mut self, f: &Fragment) {
        self.fraction += f.fraction;
        self.area += f.area;
        self.position += f.position * f.area;
        self.normal += f.normal * f.area;
        self.albedo += f.albedo * f.area;
        self.emission += f.emission * f.area;
        if f.area > self.dominant_area {
            self.dominant = f.triangle;
            self.dominant_area = f.area;
        }
    }
}

/// A texel with some coverage.
struct Record {
    key: TexelKey,
    coverage: Coverage,
}

struct BandResult {
    /// Covered texels in (y, x) order.
    texels: Vec<Record>,
    /// Per triangle of the band: its best-covered texel in the band (index into `texels`)
    /// and the world area it covers there.
    best: Vec<(u32, usize, f64)>,
}

/// Clips every triangle of the band against every texel square it overlaps.
fn rasterise_band(scene: &Scene, setups: &[TriangleSetup], band: &Band) -> BandResult {
    if band.triangles.is_empty() {
        return BandResult {
            texels: Vec::new(),
            best: Vec::new(),
        };
    }
    // Accumulate on a dense grid spanning the columns the band's triangles reach.
    let min_x = band
        .triangles
        .iter()
        .flat_map(|&t| setups[t as usize].uv)
        .map(|q| q.x);
    let max_x = min_x.clone();
    let columns = span(
        min_x.fold(f64::INFINITY, f64::min),
        max_x.fold(f64::NEG_INFINITY, f64::max),
        band.width,
    );
    let grid_width = columns.len();
    let mut grid = vec![Coverage::default(); grid_width * band.rows.len()];
    let mut best_cells = Vec::with_capacity(band.triangles.len());
    let mut uv0 = [Vec2::ZERO; MAX_SAMPLES];

    for &t in &band.triangles {
        let s = &setups[t as usize];
        let Some(to_barycentric) = s.to_barycentric else {
            continue;
        };
        let material = &scene.materials[s.material as usize];
        let textured = material.base_color_texture.is_some() || material.emissive_texture.is_some();
        let triangle = Polygon::triangle(s.uv);
        let rows = s.rows(band.rows.end);
        let mut best: Option<(usize, f64)> = None;
        for y in rows.start.max(band.rows.start)..rows.end {
            let row = triangle.clip(1, y as f64, y as f64 + 1.0);
            if row.len < 3 {
                continue;
            }
            let (lo, hi) = row.extent(0);
            for x in span(lo, hi, band.width) {
                let cell = row.clip(0, x as f64, x as f64 + 1.0);
                let Some((fraction, centroid)) = cell.area_centroid() else {
                    continue;
                };
                let weights = |q: DVec2| {
                    let b = to_barycentric * (q - s.uv[0]);
                    DVec3::new(1.0 - b.x - b.y, b.x, b.y)
                };
                let samples = if textured {
                    footprint_uv0(scene, t, weights, centroid, &cell, &mut uv0)
                } else {
                    0
                };
                let fragment = Fragment {
                    fraction,
                    area: fraction * s.world_per_texel,
                    ..shade(scene, material, t, weights(centroid), &uv0[..samples])
                };
                let k = (y - band.rows.start) as usize * grid_width + (x - columns.start) as usize;
                grid[k].add(&fragment);
                if best.is_none_or(|(_, a)| fragment.area > a) {
                    best = Some((k, fragment.area));
                }
            }
        }
        if let Some((k, area)) = best {
            best_cells.push((t, k, area));
        }
    }

    // Compact the grid in (y, x) order and renumber the best cells.
    let mut record_of_cell = vec![usize::MAX; grid.len()];
    let mut texels = Vec::new();
    for (k, coverage) in grid.into_iter().enumerate() {
        if coverage.area > 0.0 {
            record_of_cell[k] = texels.len();
            let y = band.rows.start + (k / grid_width) as u32;
            let x = columns.start + (k % grid_width) as u32;
            texels.push(Record {
                key: (band.page, y, x),
                coverage,
            });
        }
    }
    let best = best_cells
        .into_iter()
        .filter(|&(_, k, _)| record_of_cell[k] != usize::MAX)
        .map(|(t, k, area)| (t, record_of_cell[k], area))
        .collect();
    BandResult { texels, best }
}

/// Position, normal, albedo and emission at barycentric weights `w`, with textures averaged
/// over the `TEXCOORD_0` samples `uv0`; coverage fields are left for the caller.
fn shade(scene: &Scene, material: &Material, t: u32, w: DVec3, uv0: &[Vec2]) -> Fragment {
    let [i0, i1, i2] = scene.triangles[t as usize].map(|v| v as usize);
    let blend =
        |a: &[Vec3]| a[i0].as_dvec3() * w.x + a[i1].as_dvec3() * w.y + a[i2].as_dvec3() * w.z;
    Fragment {
        triangle: t,
        fraction: 0.0,
        area: 0.0,
        position: blend(&scene.positions),
        normal: blend(&scene.normals),
        albedo: material.base_color.as_dvec3()
            * average_texture(scene, material.base_color_texture, uv0),
        emission: material.emission.as_dvec3()
            * average_texture(scene, material.emissive_texture, uv0),
    }
}

/// `TEXCOORD_0` at points spread over a clipped polygon: its centroid and the midpoints towards
/// each vertex (all inside, since the polygon is convex). Returns how many were written.
fn footprint_uv0(
    scene: &Scene,
    t: u32,
    weights: impl Fn(DVec2) -> DVec3,
    centroid: DVec2,
    cell: &Polygon,
    uv0: &mut [Vec2; MAX_SAMPLES],
) -> usize {
    let [i0, i1, i2] = scene.triangles[t as usize].map(|v| v as usize);
    let points =
        std::iter::once(centroid).chain(cell.vertices().iter().map(|&v| (v + centroid) * 0.5));
    let mut n = 0;
    for q in points {
        let w = weights(q).as_vec3();
        uv0[n] = scene.uv0[i0] * w.x + scene.uv0[i1] * w.y + scene.uv0[i2] * w.z;
        n += 1;
    }
    n
}

/// Mean of `texture` at `uv0` (white without a texture).
fn average_texture(scene: &Scene, texture: Option<u32>, uv0: &[Vec2]) -> DVec3 {
    match texture.and_then(|i| scene.textures.get(i as usize)) {
        Some(texture) if !uv0.is_empty() => {
            let sum: DVec3 = uv0.iter().map(|&uv| texture.sample(uv).as_dvec3()).sum();
            sum / uv0.len() as f64
        }
        _ => DVec3::ONE,
    }
}

/// The whole triangle as one fragment, for triangles whose lightmap UVs cover nothing.
fn whole_triangle_fragment(scene: &Scene, s: &TriangleSetup, t: u32) -> Fragment {
    let material = &scene.materials[s.material as usize];
    let [i0, i1, i2] = scene.triangles[t as usize].map(|v| v as usize);
    let uv0 = [(scene.uv0[i0] + scene.uv0[i1] + scene.uv0[i2]) / 3.0];
    let f = shade(scene, material, t, DVec3::splat(1.0 / 3.0), &uv0);
    Fragment {
        area: s.world_area.max(f64::MIN_POSITIVE),
        normal: if s.geometric_normal != DVec3::ZERO {
            s.geometric_normal
        } else {
            f.normal
        },
        ..f
    }
}

/// The finished patch of one texel.
struct Patch {
    position: Vec3,
    normal: Vec3,
    area: f32,
    albedo: Vec3,
    emission: Vec3,
    triangle: u32,
    du: Vec3,
    dv: Vec3,
}

impl Patch {
    fn new(scene: &Scene, setups: &[TriangleSetup], record: &Record) -> Patch {
        let c = &record.coverage;
        let dominant = &setups[c.dominant as usize];
        let mean = |sum: DVec3| sum / c.area;
        let corners =
            scene.triangles[c.dominant as usize].map(|v| scene.positions[v as usize].as_dvec3());
        let position = mean(c.position);
        let position = if position.is_finite() {
            position
        } else {
            (corners[0] + corners[1] + corners[2]) / 3.0
        };
        // A texel spanning several facets of a curved surface has its centroid on a chord,
        // inside a convex solid (a 24-segment sphere at 4 cm texels: ~2 mm deep), where every
        // shadow ray hits the solid's back: dark spots all over a lit sphere. The dominant
        // facet's plane bounds a convex solid, so the centroid goes onto it.
        let g = dominant.geometric_normal;
        let position = position - g * (position - corners[0]).dot(g);
        // Interpolated normals, unless they cancel out or turn against the dominant face
        // (opposite faces mapped onto one texel by bad input UVs).
        let normal = match c.normal.try_normalize() {
            Some(n)
                if c.normal.length() > 1e-6 * c.area && (g == DVec3::ZERO || n.dot(g) > 0.0) =>
            {
                n
            }
            _ if g != DVec3::ZERO => g,
            n => n.unwrap_or(DVec3::Z),
        };
        Patch {
            position: position.as_vec3(),
            normal: normal.as_vec3(),
            area: (c.area as f32).max(f32::MIN_POSITIVE),
            albedo: finite_or_zero(mean(c.albedo))
                .clamp(DVec3::ZERO, DVec3::splat(MAX_ALBEDO as f64))
                .as_vec3(),
            emission: finite_or_zero(mean(c.emission)).max(DVec3::ZERO).as_vec3(),
            triangle: c.dominant,
            du: dominant.du,
            dv: dominant.dv,
        }
    }
}

fn finite_or_zero(v: DVec3) -> DVec3 {
    if v.is_finite() { v } else { DVec3::ZERO }
}

/// A small convex polygon in texel units (no allocation).
#[derive(Clone, Copy)]
struct Polygon {
    len: usize,
    v: [DVec2; MAX_POLYGON],
}

impl Polygon {
    fn triangle(v: [DVec2; 3]) -> Polygon {
        let mut p = Polygon {
            len: 3,
            v: [DVec2::ZERO; MAX_POLYGON],
        };
        p.v[..3].copy_from_slice(&v);
        p
    }

    fn vertices(&self) -> &[DVec2] {
        &self.v[..self.len]
    }

    /// Minimum and maximum of coordinate `axis`.
    fn extent(&self, axis: usize) -> (f64, f64) {
        self.vertices()
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                (lo.min(v[axis]), hi.max(v[axis]))
            })
    }

    /// The part with `lo ≤ coordinate[axis] ≤ hi`.
    fn clip(&self, axis: usize, lo: f64, hi: f64) -> Polygon {
        self.clip_half(axis, lo, 1.0).clip_half(axis, hi, -1.0)
    }

    /// Sutherland–Hodgman against one half-plane: keeps `side·(coordinate[axis] − bound) ≥ 0`.
    fn clip_half(&self, axis: usize, bound: f64, side: f64) -> Polygon {
        let mut out = Polygon {
            len: 0,
            v: [DVec2::ZERO; MAX_POLYGON],
        };
        let n = self.len;
        for i in 0..n {
            let (a, b) = (self.v[i], self.v[(i + 1) % n]);
            let (da, db) = (side * (a[axis] - bound), side * (b[axis] - bound));
            if da >= 0.0 {
                out.push(a);
            }
            if (da >= 0.0) != (db >= 0.0) {
                let mut cut = a + (b - a) * (da / (da - db));
                cut[axis] = bound; // exact on the texel edge, so neighbours tile perfectly
                out.push(cut);
            }
        }
        out
    }

    fn push(&mut self, p: DVec2) {
        debug_assert!(self.len < MAX_POLYGON);
        if self.len < MAX_POLYGON {
            self.v[self.len] = p;
            self.len += 1;
        }
    }

    /// Unsigned area and centroid, or `None` when the polygon has no area.
    fn area_centroid(&self) -> Option<(f64, DVec2)> {
        if self.len < 3 {
            return None;
        }
        // Fan from the first vertex, relative to it (small numbers, little cancellation).
        let o = self.v[0];
        let (mut twice_area, mut moment) = (0.0, DVec2::ZERO);
        for i in 1..self.len - 1 {
            let (p, q) = (self.v[i] - o, self.v[i + 1] - o);
            let cross = p.perp_dot(q);
            twice_area += cross;
            moment += (p + q) * cross;
        }
        (twice_area != 0.0).then(|| (0.5 * twice_area.abs(), o + moment / (3.0 * twice_area)))
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec2;

    use super::*;
    use crate::atlas::InstanceUv;
    use crate::scene::{Instance, Texture, Wrap};

    /// A one-instance scene whose atlas vertices are the scene vertices, on one `w × h` page.
    fn scene(
        positions: &[Vec3],
        lightmap_uv: &[Vec2],
        uv0: &[Vec2],
        triangles: &[[u32; 3]],
        material: Material,
        textures: Vec<Texture>,
        (width, height): (u32, u32),
    ) -> (Scene, Atlas) {
        let n = positions.len() as u32;
        let t = triangles.len() as u32;
        // Vertex normals from the faces (flat shading).
        let mut normals = vec![Vec3::ZERO; positions.len()];
        for tri in triangles {
            let p = tri.map(|v| positions[v as usize]);
            let face = (p[1] - p[0]).cross(p[2] - p[0]).normalize();
            for &v in tri {
                normals[v as usize] = face;
            }
        }
        let scene = Scene {
            positions: positions.to_vec(),
            normals,
            uv0: if uv0.is_empty() {
                vec![Vec2::ZERO; positions.len()]
            } else {
                uv0.to_vec()
            },
            uv1: vec![Vec2::ZERO; positions.len()],
            triangles: triangles.to_vec(),
            triangle_instance: vec![0; triangles.len()],
            instances: vec![Instance {
                node: 0,
                mesh: 0,
                primitive: 0,
                material: 0,
                vertices: 0..n,
                triangles: 0..t,
                source_triangle: (0..t).collect(),
                back_of: None,
                back: None,
                has_uv1: false,
                lightmap: None,
                directional: None,
                split: Default::default(),
            }],
            materials: vec![material],
            textures,
            ..Scene::default()
        };
        let atlas = Atlas {
            pages: vec![PageSize { width, height }],
            instances: vec![InstanceUv {
                xref: (0..n).collect(),
                uv: lightmap_uv.to_vec(),
                triangles: triangles.to_vec(),
                triangle_page: vec![0; triangles.len()],
            }],
            texels_per_unit: width as f32,
            reused_input_uvs: false,
            shared: Vec::new(),
        };
        (scene, atlas)
    }

    /// [`scene`] without textures, in the default material.
    fn untextured(
        positions: &[Vec3],
        lightmap_uv: &[Vec2],
        triangles: &[[u32; 3]],
        size: (u32, u32),
    ) -> (Scene, Atlas) {
        scene(
            positions,
            lightmap_uv,
            &[],
            triangles,
            Material::default(),
            vec![],
            size,
        )
    }

    /// The unit square in z = 0 facing +z, mapped onto the whole page (v down, so y flips).
    fn unit_quad(material: Material, textures: Vec<Texture>, size: (u32, u32)) -> (Scene, Atlas) {
        let positions = [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::X,
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::Y,
        ];
        let uv: Vec<Vec2> = positions
            .iter()
            .map(|p| Vec2::new(p.x, 1.0 - p.y))
            .collect();
        scene(
            &positions,
            &uv,
            &uv,
            &[[0, 1, 2], [0, 2, 3]],
            material,
            textures,
            size,
        )
    }

    #[test]
    fn unit_quad_on_4x4_page_gives_16_equal_texels_at_centres() {
        let (scene, atlas) = unit_quad(Material::default(), vec![], (4, 4));
        let texels = build(&scene, &atlas).unwrap();
        assert_eq!(texels.len(), 16);
        for i in 0..16 {
            let [x, y] = texels.xy[i];
            assert_eq!(
                [x, y],
                [i as u32 % 4, i as u32 / 4],
                "ids in (page, y, x) order"
            );
            assert!(
                (texels.area[i] - 1.0 / 16.0).abs() < 1e-6,
                "area {}",
                texels.area[i]
            );
            let centre = Vec3::new((x as f32 + 0.5) / 4.0, 1.0 - (y as f32 + 0.5) / 4.0, 0.0);
            assert!(
                texels.position[i].distance(centre) < 1e-5,
                "{} vs {centre}",
                texels.position[i]
            );
            assert_eq!(texels.normal[i], Vec3::Z);
            assert!(texels.du[i].distance(Vec3::new(0.25, 0.0, 0.0)) < 1e-6);
            assert!(texels.dv[i].distance(Vec3::new(0.0, -0.25, 0.0)) < 1e-6);
            assert_eq!(
                texels.albedo[i],
                Vec3::splat(MAX_ALBEDO),
                "white is clamped"
            );
            assert_eq!(texels.emission[i], Vec3::ZERO);
            assert_eq!(texels.index[0][(y * 4 + x) as usize], i as u32);
        }
        assert_eq!(texels.triangle_uv[0][2], Vec2::new(4.0, 0.0));
        // A hit in the middle of the second triangle lands in its texel.
        let hit = texels.texel_at(1, Vec2::splat(1.0 / 3.0));
        let p = texels.position[hit as usize];
        assert!(p.distance(Vec3::new(1.0 / 3.0, 2.0 / 3.0, 0.0)) < 0.2);
        assert!(texels.triangle_texel.iter().all(|&t| t != NO_TEXEL));
    }

    #[test]
    fn half_covered_texel_gets_half_the_area_at_the_covered_centroid() {
        // Texel units: the triangle (0,0) (1,0) (0,1) covers half of texel (0,0) of a 2 × 2 page.
        let positions = [
            Vec3::ZERO,
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(0.0, 0.0, -2.0),
        ];
        let uv = [Vec2::ZERO, Vec2::new(0.5, 0.0), Vec2::new(0.0, 0.5)];
        let (scene, atlas) = untextured(&positions, &uv, &[[0, 1, 2]], (2, 2));
        let texels = build(&scene, &atlas).unwrap();
        assert_eq!(texels.len(), 1);
        // A full texel is 4 m² here; half of it is the whole triangle.
        assert!((texels.area[0] - 2.0).abs() < 1e-6);
        assert!(texels.position[0].distance(Vec3::new(2.0, 0.0, -2.0) / 3.0) < 1e-6);
        assert!(texels.normal[0].distance(Vec3::Y) < 1e-6);
    }

    #[test]
    fn clipped_areas_sum_to_the_triangle_area_across_many_texels() {
        let positions = [
            Vec3::new(0.3, 0.1, 2.0),
            Vec3::new(4.1, -0.7, 1.0),
            Vec3::new(1.2, 3.3, 0.5),
        ];
        let uv = [
            Vec2::new(0.03, 0.11),
            Vec2::new(0.91, 0.27),
            Vec2::new(0.36, 0.97),
        ];
        let (scene, atlas) = untextured(&positions, &uv, &[[0, 1, 2]], (37, 29));
        let texels = build(&scene, &atlas).unwrap();
        let area: f64 = texels.area.iter().map(|&a| a as f64).sum();
        let expected = 0.5
            * (positions[1] - positions[0])
                .cross(positions[2] - positions[0])
                .length() as f64;
        assert!(
            (area - expected).abs() < 1e-5 * expected,
            "{area} vs {expected}"
        );
        let centroid: Vec3 = texels
            .position
            .iter()
            .zip(&texels.area)
            .map(|(p, a)| *p * *a)
            .sum::<Vec3>()
            / area as f32;
        let expected_centroid = (positions[0] + positions[1] + positions[2]) / 3.0;
        assert!(
            centroid.distance(expected_centroid) < 1e-4,
            "{centroid} vs {expected_centroid}"
        );
        // Partly covered texels are patches too: more than the texels whose centre is inside.
        assert!(
            texels.len() as f64 > expected / texels.area.iter().cloned().fold(0.0, f32::max) as f64
        );
    }

    #[test]
    fn albedo_is_clamped_and_emission_copied() {
        let material = Material {
            base_color: Vec3::new(1.5, 0.5, 0.25),
            emission: Vec3::new(1.0, 2.0, 30.0),
            ..Material::default()
        };
        let (scene, atlas) = unit_quad(material, vec![], (2, 2));
        let texels = build(&scene, &atlas).unwrap();
        for i in 0..texels.len() {
            assert!(texels.albedo[i].distance(Vec3::new(MAX_ALBEDO, 0.5, 0.25)) < 1e-6);
            assert!(texels.emission[i].distance(Vec3::new(1.0, 2.0, 30.0)) < 1e-5);
        }
    }

    #[test]
    fn textures_are_averaged_over_the_texel_footprint() {
        // 2 × 2 texture on the quad, 2 × 2 lightmap page: each texel sees one texture texel,
        // blended towards its neighbours by bilinear filtering away from the texel centre.
        let (red, green, blue) = (
            Vec3::new(0.8, 0.0, 0.0),
            Vec3::new(0.0, 0.8, 0.0),
            Vec3::new(0.0, 0.0, 0.8),
        );
        let texture = Texture {
            width: 2,
            height: 2,
            texels: vec![red, green, blue, Vec3::ZERO],
            wrap_s: Wrap::ClampToEdge,
            wrap_t: Wrap::ClampToEdge,
        };
        let material = Material {
            base_color_texture: Some(0),
            ..Material::default()
        };
        let (scene, atlas) = unit_quad(material, vec![texture], (2, 2));
        let texels = build(&scene, &atlas).unwrap();
        let top_left = texels.albedo[texels.index[0][0] as usize];
        // The exact footprint mean of the bilinear texture over the top-left quarter:
        // weights 0.875² (own), 0.875·0.125 (each side neighbour), 0.125² (diagonal).
        let exact = red * 0.875 * 0.875 + (green + blue) * 0.875 * 0.125;
        assert!(top_left.distance(exact) < 0.06, "{top_left} vs {exact}");
        assert!(
            top_left.x < 0.75 && top_left.y > 0.02 && top_left.z > 0.02,
            "point sampling: {top_left}"
        );
    }

    #[test]
    fn a_triangle_smaller_than_a_texel_still_gets_one() {
        let positions = [
            Vec3::ZERO,
            Vec3::new(0.001, 0.0, 0.0),
            Vec3::new(0.0, 0.001, 0.0),
        ];
        let uv = [
            Vec2::new(0.6, 0.6),
            Vec2::new(0.6001, 0.6),
            Vec2::new(0.6, 0.6001),
        ];
        let (scene, atlas) = untextured(&positions, &uv, &[[0, 1, 2]], (4, 4));
        let texels = build(&scene, &atlas).unwrap();
        assert_eq!(texels.len(), 1);
        assert_eq!(texels.xy[0], [2, 2]);
        assert_eq!(texels.triangle_texel[0], 0);
        assert!((texels.area[0] - 5e-7).abs() < 1e-9);
    }

    #[test]
    fn degenerate_lightmap_uvs_fall_back_to_the_centroid_texel() {
        let positions = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let uv = [Vec2::splat(0.3); 3];
        let (scene, atlas) = untextured(&positions, &uv, &[[0, 1, 2]], (4, 4));
        let texels = build(&scene, &atlas).unwrap();
        assert_eq!(texels.len(), 1);
        assert_eq!(texels.xy[0], [1, 1]);
        assert!((texels.area[0] - 0.5).abs() < 1e-6);
        assert_eq!(texels.normal[0], Vec3::Z);
        assert!(texels.du[0].is_finite() && texels.du[0].length() > 0.0);
    }

    #[test]
    fn opposite_faces_in_one_texel_keep_the_dominant_normal() {
        // Bad input UVs: a large front triangle and a smaller back-facing one share a texel.
        let positions = [
            Vec3::ZERO,
            Vec3::X,
            Vec3::Y, // facing +z
            Vec3::ZERO,
            Vec3::new(0.0, 0.5, 0.0),
            Vec3::new(0.5, 0.0, 0.0), // facing −z
        ];
        let uv = [
            Vec2::ZERO,
            Vec2::X,
            Vec2::Y,
            Vec2::ZERO,
            Vec2::new(0.0, 0.5),
            Vec2::new(0.5, 0.0),
        ];
        let tris = [[0, 1, 2], [3, 4, 5]];
        let (scene, atlas) = untextured(&positions, &uv, &tris, (1, 1));
        let texels = build(&scene, &atlas).unwrap();
        assert_eq!(texels.len(), 1);
        assert_eq!(texels.normal[0], Vec3::Z);
        assert_eq!(texels.triangle[0], 0);
        assert!((texels.area[0] - 0.625).abs() < 1e-6);
    }

    /// A bumpy grid of irregular triangles spanning several bands of a 64 × 64 page.
    fn bumpy_grid() -> (Scene, Atlas) {
        let n = 13;
        let mut positions = Vec::new();
        let mut uv = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                let (s, t) = (i as f32 / n as f32, j as f32 / n as f32);
                let wobble = ((i * 7 + j * 13) % 5) as f32 * 0.004;
                positions.push(Vec3::new(s * 3.0, (s * 9.0).sin() * 0.3 + t * 0.2, t * 2.0));
                uv.push(Vec2::new(
                    0.02 + 0.95 * s + wobble,
                    0.03 + 0.94 * t - wobble,
                ));
            }
        }
        let mut triangles = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let a = j * (n + 1) + i;
                triangles.push([a, a + n + 1, a + 1]);
                triangles.push([a + 1, a + n + 1, a + n + 2]);
            }
        }
        let material = Material {
            base_color: Vec3::new(0.7, 0.6, 0.5),
            ..Material::default()
        };
        scene(&positions, &uv, &[], &triangles, material, vec![], (64, 64))
    }

    #[test]
    fn results_do_not_depend_on_the_thread_count() {
        let (scene, atlas) = bumpy_grid();
        let run = |threads| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| build(&scene, &atlas).unwrap())
        };
        let (a, b) = (run(1), run(3));
        assert!(a.len() > 1000);
        assert_eq!(a.position, b.position);
        assert_eq!(a.normal, b.normal);
        assert_eq!(a.area, b.area);
        assert_eq!(a.albedo, b.albedo);
        assert_eq!(a.xy, b.xy);
        assert_eq!(a.triangle, b.triangle);
        assert_eq!(a.du, b.du);
        assert_eq!(a.index, b.index);
        assert_eq!(a.triangle_texel, b.triangle_texel);
        // Every triangle's texel is one it covers most: hitting its centre lands nearby.
        for t in 0..scene.triangles.len() as u32 {
            let id = a.texel_at(t, Vec2::splat(1.0 / 3.0));
            assert_ne!(id, NO_TEXEL);
        }
    }
}
