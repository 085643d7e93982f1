//! Slot faces get texels at the scale of the slot's gap, and narrow faces near emitters four
//! texels across (issue 27, item 3).
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
//!
//! **Narrow faces** near emitters get [`ROWS`] texels across. A face narrower than that many
//! texels within [`ROWS`] of its own widths of an emitter, and at most [`REACH_TEXELS`]
//! texels (a light panel's border, a ceiling
//! recess's 2 cm band between the ceiling and the light's plane, the recess walls' corners
//! beside the light) is where light can change by its whole range over a few centimetres: the
//! recess band's falls from 1.5 to 0.3 over its 2 cm below the emitter's plane. A renderer
//! reads the half texel at each of its edges as the nearest texel centre, so on light falling
//! linearly by `Δ` across a width `w` an edge reads `Δ·s/(2w)` too much with texels `s` wide:
//! where the light at that edge is a fifth of the range, as on the band, `1 + 2s/w` times its
//! light, at most 1.5× from `s = w/4`. An emitter's light changes over lengths of the order of
//! the distance to it, so a face a few of its widths away sees that change across its width;
//! farther away, or in even light (a board's edge, a reveal away from any light), one row
//! reads a narrow face's mean well. (Without the two-texel bound, faces up to four texels wide
//! looked up to sixteen texels away: at `draft` 72 triangles, 1.17 m², of the Cornell box
//! were raised.) Raising every narrow face cost the furnished interior 2.6× its texels at
//! `medium` (33 m² of narrow faces at `draft`); raising those that touch a slot face too (with
//! near contacts) cost it 1.27× the wall time at `medium` for the same point error (2.02% →
//! 2.01%).
//!
//! A face is a connected region (`plan::density::Regions`). It is near an emitter when a corner of
//! one of its triangles lies within `ROWS·w` (at most [`REACH_TEXELS`] texels, at least a sixteenth
//! of a texel, as cut ends snap) of an edge of an emitter triangle, or the other way round, `w` its
//! width over all its triangles. Its width for the raise is the area over the bounding box's
//! diagonal of its triangles someone may see (a strip `w` by `L` reads about `w`, a square of side
//! `a` about `0.7a`, a ring or frame up to three times its width: on the safe side); those
//! triangles alone are raised, by `ROWS·texel/w` on quarter octaves, at most
//! ×[`MAX_NARROW_FACTOR`]. A narrow face then costs about `ROWS²·L/w` texels: its aspect ratio, not
//! its width. Together they add at most [`NARROW_TEXEL_SHARE`] × the uniform atlas's texels (the
//! cap lowered as for slot faces, separately, so narrow faces leave the slots' raise as it was).
//! Emitters keep their density (their texels hold mostly their emission). A triangle nobody sees is
//! not raised: inside a solid (more than a quarter of the probe rays from its centroid meet a back
//! face within [`REACH`] texels, the validity pass's test; a recess wall's band is one face with
//! the part buried in the slab above it) or facing the void of a scene without sky (every probe ray
//! escapes: no light reaches it).
//!
//! On by default (`AtlasParams::narrow_faces`), as part of the junction split: on the corpus
//! scenes it finds no narrow face at any preset (the Cornell box's light, itself narrow, is an
//! emitter), so their bakes are unchanged (the furnished interior's bytes compared at
//! `medium`, and at `draft` with near contacts); it costs them the regions and the emitters'
//! neighbourhoods (0.06–0.08 s of the interior's bakes). With near contacts their cuts separate a
//! slot's mouth and the band below it from the wall they belong to, which is what lets
//! `fixtures/narrow_faces.gltf`'s recess band be measured as narrow.

use std::collections::HashMap;

use glam::Vec3;
use rayon::prelude::*;

use crate::plan::density::Regions;
use crate::sampling::{cosine_hemisphere, frame, hammersley};
use crate::scene::Scene;
use crate::texels::validity::{MAX_BACK, PROBE_RAYS, REACH};
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
/// Texels across a narrow face, at least (the module docs: an edge then reads at most 1.5× on
/// light that falls to a fifth of its range across the face).
pub(crate) const ROWS: f32 = 4.0;
/// A narrow face looks for an emitter within [`ROWS`] of its widths, but at most this many
/// texels (beyond that, light from the emitter changes over more than a narrow face's width).
pub(crate) const REACH_TEXELS: f32 = 2.0;
/// Narrow faces rise at most this far above the preset's density (a 2 cm band at `draft`'s
/// 12.5 cm texels asks ×25; a 4 mm sliver would ask ×125).
pub(crate) const MAX_NARROW_FACTOR: f32 = 32.0;
/// Narrow faces add at most this many texels, as a share of the uniform atlas's.
pub(crate) const NARROW_TEXEL_SHARE: f64 = 1.0;

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
    /// Narrow faces raised to [`ROWS`] texels across: triangles, world area (m²), the
    /// largest factor, texels added at the preset's density, and the cap their texel share
    /// forced below [`MAX_NARROW_FACTOR`], if it did.
    pub narrow_triangles: usize,
    pub narrow_area: f64,
    pub narrow_max_factor: f32,
    pub narrow_added_texels: f64,
    pub narrow_capped: Option<f32>,
    /// Which raises ran ([`Raise`]).
    pub slots_on: bool,
    pub narrow_on: bool,
}

impl SlotReport {
    /// One phrase for the junction report: the rule and what it did.
    pub fn brief(&self) -> String {
        let narrow = if !self.narrow_on {
            String::new()
        } else if self.narrow_triangles == 0 {
            format!("narrow faces: none (at least {ROWS} texels across near an emitter)")
        } else {
            format!(
                "narrow faces: {} triangles ({:.3} m²) near an emitter raised to \
                 {ROWS} texels across, up to ×{:.1} (cap ×{}{}), about +{:.0} texels",
                self.narrow_triangles,
                self.narrow_area,
                self.narrow_max_factor,
                MAX_NARROW_FACTOR,
                self.narrow_capped.map_or(String::new(), |c| format!(
                    ", lowered to ×{c:.1} to add at most ×{NARROW_TEXEL_SHARE} the uniform \
                     atlas's texels"
                )),
                self.narrow_added_texels
            )
        };
        let slots = if !self.slots_on {
            String::new()
        } else if self.triangles == 0 {
            "slot faces: none (a texel no wider than a near contact's gap)".to_string()
        } else {
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
        };
        [slots, narrow]
            .into_iter()
            .filter(|s| !s.is_empty())
            .collect::<Vec<_>>()
            .join("; ")
    }
}

/// Which raises [`density`] makes.
pub(crate) struct Raise {
    /// Slot faces, with near contacts reaching this far (world units); `None` for none.
    pub(crate) slots: Option<f32>,
    /// Narrow faces near emitters.
    pub(crate) narrow: bool,
    /// The scene has a sky (a face looking at the void is lit).
    pub(crate) sky: bool,
}

/// The density factor of every scene triangle from its slot's gap and its face's width (see
/// the module docs) at `tpu` texels per unit; empty when no triangle is raised.
pub(crate) fn density(
    scene: &Scene,
    tracer: &Tracer,
    tpu: f32,
    raise: &Raise,
) -> (Vec<f32>, SlotReport) {
    let texel = 1.0 / tpu;
    let gaps: Vec<f32> = (0..scene.triangles.len() as u32)
        .into_par_iter()
        .map(|t| {
            raise
                .slots
                .map_or(f32::INFINITY, |near| gap(scene, tracer, t, near))
        })
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
    let slots = Capped::of(scene, tpu, &raw, MAX_FACTOR, MAX_TEXEL_SHARE);
    // Light is steep near emitters (whose own texels hold mostly their emission, and are not
    // raised).
    let mut emitter = vec![false; scene.triangles.len()];
    for inst in &scene.instances {
        if scene.materials[inst.material as usize]
            .emission
            .max_element()
            > 0.0
        {
            for t in inst.triangles.clone() {
                emitter[t as usize] = true;
            }
        }
    }
    let narrow = if raise.narrow {
        narrow_factors(scene, tracer, texel, raise.sky, &emitter)
    } else {
        vec![1.0; scene.triangles.len()]
    };
    let narrow = Capped::of(scene, tpu, &narrow, MAX_NARROW_FACTOR, NARROW_TEXEL_SHARE);
    let mut report = SlotReport {
        min_gap: f32::INFINITY,
        added_texels: slots.added,
        capped: slots.capped,
        narrow_added_texels: narrow.added,
        narrow_capped: narrow.capped,
        slots_on: raise.slots.is_some(),
        narrow_on: raise.narrow,
        ..Default::default()
    };
    for (t, (&gap, (&f, &g))) in gaps
        .iter()
        .zip(slots.factors.iter().zip(&narrow.factors))
        .enumerate()
    {
        let area = scene.triangle_area(t);
        if f > 1.0 {
            report.triangles += 1;
            report.area += area;
            report.min_gap = report.min_gap.min(gap);
            report.max_factor = report.max_factor.max(f);
        }
        if g > 1.0 {
            report.narrow_triangles += 1;
            report.narrow_area += area;
            report.narrow_max_factor = report.narrow_max_factor.max(g);
        }
    }
    if report.triangles + report.narrow_triangles == 0 {
        let none = SlotReport {
            slots_on: report.slots_on,
            narrow_on: report.narrow_on,
            ..Default::default()
        };
        return (Vec::new(), none);
    }
    let factors = (slots.factors.iter().zip(&narrow.factors))
        .map(|(&a, &b)| a.max(b))
        .collect();
    (factors, report)
}

/// Factors capped so that together they add at most a share of the uniform atlas's texels.
struct Capped {
    factors: Vec<f32>,
    /// Texels added at the preset's density (before packing).
    added: f64,
    /// The cap the share forced below the largest factor allowed, if it did.
    capped: Option<f32>,
}

impl Capped {
    /// `raw` (per scene triangle) capped at `max`, then lowered a quarter octave at a time
    /// until the raised triangles add at most `share` × the uniform atlas's texels at `tpu`.
    fn of(scene: &Scene, tpu: f32, raw: &[f32], max: f32, share: f64) -> Capped {
        // Texels added at a cap: Σ A·tpu²·(f² − 1) over the raised triangles.
        let area = |t: usize| scene.triangle_area(t);
        let per_area = f64::from(tpu).powi(2);
        let added = |cap: f32| -> f64 {
            let raise = |f: f32| f64::from(f.min(cap)).powi(2) - 1.0;
            let raised = raw.iter().enumerate().filter(|&(_, &f)| f > 1.0);
            raised.map(|(t, &f)| area(t) * per_area * raise(f)).sum()
        };
        let uniform: f64 = (0..scene.triangles.len()).map(area).sum::<f64>() * per_area;
        let mut cap = max;
        while cap > 1.0 && added(cap) > share * uniform {
            cap = quantise(cap / 2f32.powf(1.0 / STEPS_PER_OCTAVE));
        }
        Capped {
            factors: raw.iter().map(|&f| f.min(cap)).collect(),
            added: added(cap),
            capped: (cap < max).then_some(cap),
        }
    }
}

/// Each scene triangle's factor for [`ROWS`] texels of size `texel` across the seen part of
/// its region, when the region is near an `emitter` triangle (see the module docs): 1 for
/// emitters, for triangles nobody sees and for regions at least that wide.
fn narrow_factors(
    scene: &Scene,
    tracer: &Tracer,
    texel: f32,
    sky: bool,
    emitter: &[bool],
) -> Vec<f32> {
    let regions = Regions::of(scene);
    let n = regions.len();
    let corners = |t: usize| scene.triangles[t].map(|v| scene.positions[v as usize]);
    // Each region's width over all its triangles (buried ones too: the seen part's width is
    // measured below).
    let (mut lo, mut hi) = (vec![Vec3::MAX; n], vec![Vec3::MIN; n]);
    for t in 0..scene.triangles.len() {
        let r = regions.of_triangle[t] as usize;
        for p in corners(t) {
            lo[r] = lo[r].min(p);
            hi[r] = hi[r].max(p);
        }
    }
    let width = |area: f64, lo: Vec3, hi: Vec3| {
        (area / f64::from((hi - lo).length()).max(f64::MIN_POSITIVE)) as f32
    };
    // Candidates: narrower than ROWS texels, looking for emitters within ROWS widths and at
    // most REACH_TEXELS texels (at least a sixteenth of a texel, as cut ends snap).
    let touch = (texel / 16.0).max(4.0 * tracer.epsilon);
    let reach: Vec<f32> = (0..n)
        .map(|r| {
            let w = width(regions.area[r], lo[r], hi[r]);
            if w < ROWS * texel {
                (ROWS * w).min(REACH_TEXELS * texel).max(touch)
            } else {
                0.0
            }
        })
        .collect();
    // Candidate triangles on a grid of texel-sized cells; each emitter triangle then visits
    // the cells within the largest reach of it (emitters are few, candidates many).
    let cell = |p: Vec3| (p / texel).floor().as_ivec3();
    let bounds = |c: [Vec3; 3], d: f32| {
        let (lo, hi) = (c[0].min(c[1]).min(c[2]), c[0].max(c[1]).max(c[2]));
        (cell(lo - Vec3::splat(d)), cell(hi + Vec3::splat(d)))
    };
    let mut grid: HashMap<glam::IVec3, Vec<u32>> = HashMap::new();
    let mut farthest = 0.0f32;
    for t in 0..scene.triangles.len() {
        let d = reach[regions.of_triangle[t] as usize];
        if d <= 0.0 || emitter[t] {
            continue;
        }
        farthest = farthest.max(d);
        let (a, b) = bounds(corners(t), 0.0);
        for x in a.x..=b.x {
            for y in a.y..=b.y {
                for z in a.z..=b.z {
                    grid.entry(glam::IVec3::new(x, y, z))
                        .or_default()
                        .push(t as u32);
                }
            }
        }
    }
    // A triangle is within `d` of another when a corner of either lies within `d` of an edge
    // of the other (for two overlapping parallel edges, a corner of one always lies beside the
    // other).
    let near_edges = |p: Vec3, tri: [Vec3; 3], d: f32| {
        (0..3).any(|k| segment_distance(p, tri[k], tri[(k + 1) % 3]) <= d)
    };
    let within = |c: [Vec3; 3], e: [Vec3; 3], d: f32| {
        c.iter().any(|&p| near_edges(p, e, d)) || e.iter().any(|&p| near_edges(p, c, d))
    };
    let mut touching = vec![false; scene.triangles.len()];
    for s in (0..scene.triangles.len()).filter(|&t| emitter[t] && !grid.is_empty()) {
        let e = corners(s);
        let (a, b) = bounds(e, farthest);
        let mut visit = |ts: &[u32]| {
            for &t in ts {
                let t = t as usize;
                if !touching[t] {
                    let d = reach[regions.of_triangle[t] as usize];
                    touching[t] = within(corners(t), e, d);
                }
            }
        };
        // A large emitter (a sky panel) visits the grid's cells rather than its own.
        let volume = (b - a + glam::IVec3::ONE).as_dvec3();
        if volume.x * volume.y * volume.z > grid.len() as f64 {
            let inside = |c: &glam::IVec3| c.cmpge(a).all() && c.cmple(b).all();
            for ts in grid.iter().filter(|(c, _)| inside(c)).map(|(_, ts)| ts) {
                visit(ts);
            }
        } else {
            for x in a.x..=b.x {
                for y in a.y..=b.y {
                    for z in a.z..=b.z {
                        if let Some(ts) = grid.get(&glam::IVec3::new(x, y, z)) {
                            visit(ts);
                        }
                    }
                }
            }
        }
    }
    let mut near_emitter = vec![false; n];
    for (t, &touching) in touching.iter().enumerate() {
        near_emitter[regions.of_triangle[t] as usize] |= touching;
    }
    // Probe rays only for the regions near an emitter, and never for emitters (not raised).
    let seen: Vec<bool> = (0..scene.triangles.len() as u32)
        .into_par_iter()
        .map(|t| {
            !emitter[t as usize]
                && near_emitter[regions.of_triangle[t as usize] as usize]
                && may_be_seen(scene, tracer, t, texel, sky)
        })
        .collect();
    // The seen part's width.
    let (mut lo, mut hi, mut area) = (vec![Vec3::MAX; n], vec![Vec3::MIN; n], vec![0.0; n]);
    for t in (0..scene.triangles.len()).filter(|&t| seen[t]) {
        let r = regions.of_triangle[t] as usize;
        for p in corners(t) {
            lo[r] = lo[r].min(p);
            hi[r] = hi[r].max(p);
        }
        area[r] += scene.triangle_area(t);
    }
    let factor: Vec<f32> = (0..n)
        .map(|r| {
            let width = width(area[r], lo[r], hi[r]);
            if area[r] > 0.0 && width > 0.0 && width < ROWS * texel {
                quantise(ROWS * texel / width)
            } else {
                1.0
            }
        })
        .collect();
    (regions.of_triangle.iter().zip(&seen))
        .map(|(&r, &seen)| if seen { factor[r as usize] } else { 1.0 })
        .collect()
}

/// Whether anyone may see scene triangle `t` in light: from its centroid, at most
/// [`MAX_BACK`] of [`PROBE_RAYS`] probe rays meet a back face within [`REACH`] texels (it is
/// not inside a solid), and without a sky some ray meets a surface (it does not face the void
/// outside a closed model, where no light reaches it).
fn may_be_seen(scene: &Scene, tracer: &Tracer, t: u32, texel: f32, sky: bool) -> bool {
    let Some(&[a, b, c]) = scene.triangles.get(t as usize) else {
        return false;
    };
    let [a, b, c] = [a, b, c].map(|v| scene.positions[v as usize]);
    let n = (b - a).cross(c - a).normalize_or_zero();
    if n == Vec3::ZERO {
        return false;
    }
    let reach = (REACH * texel).max(8.0 * tracer.epsilon);
    let origin = (a + b + c) / 3.0 + n * tracer.epsilon;
    let (tx, ty) = frame(n);
    let (mut back, mut escaped) = (0, 0);
    for k in 0..PROBE_RAYS {
        let local = cosine_hemisphere(hammersley(k, PROBE_RAYS, glam::Vec2::ZERO));
        let dir = tx * local.x + ty * local.y + n * local.z;
        match tracer.closest(origin, dir, f32::INFINITY) {
            Some(hit) if !hit.front && hit.t <= reach => back += 1,
            Some(_) => {}
            None => escaped += 1,
        }
    }
    back as f32 <= MAX_BACK * PROBE_RAYS as f32 && (sky || escaped < PROBE_RAYS)
}

/// The distance from `p` to the segment from `a` to `b`.
fn segment_distance(p: Vec3, a: Vec3, b: Vec3) -> f32 {
    let ab = b - a;
    let s = if ab.length_squared() > 0.0 {
        ((p - a).dot(ab) / ab.length_squared()).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (a + ab * s).distance(p)
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
