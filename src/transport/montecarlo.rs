//! Monte Carlo hemisphere gathering: form factors from cosine-distributed rays.
//!
//! For receiving texel `i`, `K` rays leave points jittered over the texel's footprint in
//! cosine-distributed directions (a Hammersley pattern, rotated per texel). A ray that hits the
//! front of texel `j` adds `1/K` to `F_ij` (the fraction of `i`'s view filled by `j`, which is the
//! form factor `F_ij` by reciprocity-free gathering); a ray that leaves the scene adds `1/K` to
//! the sky fraction; a ray that hits the back of a single-sided surface is absorbed.
//!
//! | parameter       | default (medium) | effect                                                   |
//! |-----------------|------------------|----------------------------------------------------------|
//! | `gather_rays` K | 256              | rows hold ≤ K entries; noise in indirect light ∝ 1/√K     |
//! | `light_samples` | 64               | shadow rays to emitters; noise of emitter direct light    |
//!
//! Direct light from emitters combines both strategies by multiple importance sampling (Veach 1995):
//! each sample `x` of strategy `s` adds `Le·cosθ_i · n_s p_s / Σ_k (n_k p_k)²` (the power heuristic), so
//! small bright emitters are found by light samples and large ones by gathering rays, both
//! without double counting. Punctual lights are evaluated at 2×2 stratified points of the texel
//! (anti-aliased shadow edges). When to use: always as the default; limits: rows are noisy for
//! small K, and visibility is sampled (thin occluders between texels may be missed by few rays).

use std::f32::consts::PI;

use glam::{Vec2, Vec3};

use super::rows::{self, ChunkRows};
use super::{Sources, Surfaces, Transport};
use crate::config::TransportParams;
use crate::lights::{Emitters, punctual_irradiance, triangle_point};
use crate::sampling::{Rng, cosine_hemisphere, frame, hammersley, power_weight};
use crate::texels::{NO_TEXEL, RayEnd};
use crate::trace::Hit;
use crate::{Progress, Result};

/// Texels per parallel work item (one progress tick each).
pub(crate) const CHUNK: usize = 128;
/// Jittered points per texel for punctual lights.
pub(crate) const PUNCTUAL_GRID: u32 = 2;

/// Monte Carlo rows for every texel; `texel_rays` as in [`super::build`].
pub(crate) fn build(
    surfaces: Surfaces,
    params: &TransportParams,
    texel_rays: Option<&[u32]>,
    progress: &dyn Progress,
) -> Result<Transport> {
    let emitters = Emitters::new(surfaces.scene, surfaces.texels);
    let sources = params.split_direct.then(|| Sources::new(surfaces.scene));
    let ctx = Context {
        surfaces,
        params,
        emitters: &emitters,
        texel_rays,
        sources: sources.as_ref(),
    };
    let mut transport = ctx.rows(progress, false)?;
    transport.sources = sources.unwrap_or_default();
    Ok(transport)
}

/// [`Context::texel_row`]'s working space, reused from row to row: no allocation per texel.
#[derive(Default)]
pub(crate) struct RowScratch {
    /// The row's texel hits, sorted into its entries.
    hits: Vec<u32>,
    /// The gathering rays that hit a front face: the hit, the ray's direction and its cosine
    /// to the texel's normal.
    pending: Vec<(Hit, Vec3, f32)>,
    /// The texel each of `pending` lands in ([`crate::texels::NO_TEXEL`]: absorbed).
    landed: Vec<u32>,
}

impl RowScratch {
    /// Space for rows of up to `rays` gathering rays.
    pub(crate) fn new(rays: u32) -> RowScratch {
        let k = rays as usize;
        RowScratch {
            hits: Vec::with_capacity(k),
            pending: Vec::with_capacity(k),
            landed: Vec::with_capacity(k),
        }
    }
}

/// What gathering reads: the surfaces, the options, the emitters to sample and the per-texel
/// rays.
pub(crate) struct Context<'a> {
    pub(crate) surfaces: Surfaces<'a>,
    pub(crate) params: &'a TransportParams,
    pub(crate) emitters: &'a Emitters,
    pub(crate) texel_rays: Option<&'a [u32]>,
    /// Split direct light by source into the rows' `terms` ([`Transport::direct_terms`]).
    pub(crate) sources: Option<&'a Sources>,
}

impl Context<'_> {
    /// Every texel's row; with `direct_only` the rows are dropped as they are made (only direct
    /// light, sky fraction and rays remain: memory O(K) per chunk).
    pub(crate) fn rows(&self, progress: &dyn Progress, direct_only: bool) -> Result<Transport> {
        let n = self.surfaces.texels.len();
        rows::build(n, CHUNK, "transport", progress, |range, out| {
            let mut scratch = RowScratch::new(self.params.gather_rays);
            for i in range {
                let start = out.col.len();
                self.texel_row(i, &mut scratch, out);
                if direct_only {
                    out.forget_row(start);
                }
            }
        })
    }

    /// A point of texel `i`'s footprint ([`Texels::footprint_point`]) for `u ∈ [0,1)²`,
    /// lifted off the surface by the ray epsilon.
    #[inline]
    pub(crate) fn footprint_point(&self, i: usize, u: Vec2) -> Vec3 {
        let Surfaces { texels, tracer, .. } = self.surfaces;
        texels.footprint_point(i, u) + texels.normal[i] * tracer.epsilon
    }

    /// Gathers row `i` into `out`. `bake::incremental` draws the same rays again without
    /// tracing them (`row_rays`): a change to what is drawn here, or in what order, must be
    /// made there too.
    pub(crate) fn texel_row(&self, i: usize, scratch: &mut RowScratch, out: &mut ChunkRows) {
        let Surfaces {
            scene,
            texels,
            tracer,
        } = self.surfaces;
        let n = texels.normal[i];
        let (tx, ty) = frame(n);
        let p = self.params;
        let k = self.texel_rays.map_or(p.gather_rays, |r| r[i]).max(1);
        let l = if self.emitters.is_empty() || p.light_samples == 0 {
            0
        } else if k == p.gather_rays {
            p.light_samples
        } else {
            // A reduced texel keeps the light-sample-to-ray ratio.
            ((p.light_samples as u64 * k as u64 / p.gather_rays.max(1) as u64) as u32).max(4)
        };
        let (kf, lf) = (k as f32, l as f32);
        let mut rng = Rng::new(self.params.seed, i as u64, 0);
        let shift = rng.next_vec2();
        let mut escaped = 0u32;
        let mut emitted = Vec3::ZERO;
        // This texel's direct light by source, when split: each contribution is added to its
        // source's term as it is added to the total.
        let terms = out.terms.len();
        if let Some(sources) = self.sources {
            out.terms.resize(terms + sources.len(), Vec3::ZERO);
        }
        let add_term = |out: &mut ChunkRows, source: usize, e: Vec3| {
            if self.sources.is_some() {
                out.terms[terms + source] += e;
            }
        };
        let emitter_source = |j: u32| self.sources.map_or(0, |s| s.of_texel(scene, texels, j));

        // Gathering rays: form factors, sky, and the gathering half of emitter MIS. All K rays
        // are traced first and their texels looked up after, so the lookups' cache misses
        // overlap instead of stalling one ray at a time (same rays, same sums, same order).
        let RowScratch {
            hits,
            pending,
            landed,
        } = scratch;
        hits.clear();
        pending.clear();
        for s in 0..k {
            let local = cosine_hemisphere(hammersley(s, k, shift));
            let dir = tx * local.x + ty * local.y + n * local.z;
            let origin = self.footprint_point(i, rng.next_vec2());
            match texels.ray_hit(tracer, origin, dir) {
                Ok(hit) => pending.push((hit, dir, local.z)),
                Err(RayEnd::Escaped) => escaped += 1,
                Err(_) => {}
            }
        }
        for (hit, _, _) in pending.iter() {
            texels.prefetch_texel(hit);
        }
        landed.clear();
        landed.extend(
            pending
                .iter()
                .map(|(hit, _, _)| texels.texel_at(hit.triangle, hit.bary)),
        );
        for (&(hit, dir, cos), &j) in pending.iter().zip(landed.iter()) {
            if j == NO_TEXEL {
                continue;
            }
            hits.push(j);
            if self.emitters.emits(j) {
                let le = texels.emission[j as usize];
                let p_gather = cos / PI;
                let (_, n_l) = triangle_point(scene, hit.triangle, hit.bary);
                let p_light = self.emitters.pdf_toward(hit.triangle, n_l, dir, hit.t);
                let e = le * (cos * power_weight(kf * p_gather, lf * p_light));
                emitted += e;
                add_term(out, emitter_source(j), e);
            }
        }

        // Light samples: the explicit half of emitter MIS, stratified over the emitters' area
        // (a Hammersley set, rotated per texel). Independent samples left 8–12% per-texel noise
        // near the Cornell light at L = 64, measured against the reference path tracer.
        let light_shift = rng.next_vec2();
        for s in 0..l {
            let u = hammersley(s, l, light_shift);
            let origin = self.footprint_point(i, rng.next_vec2());
            let Some(x) = self
                .emitters
                .sample_from((scene, texels, tracer), origin, Some(n), u)
            else {
                continue;
            };
            let p_gather = x.cos_i / PI;
            let e = x.le * (x.cos_i * power_weight(lf * x.pdf_solid_angle(), kf * p_gather));
            emitted += e;
            add_term(out, emitter_source(x.texel), e);
        }

        // Punctual lights at stratified footprint points.
        let (punctual, shadow_rays) = self.punctual_light(i, n, &mut rng, out, terms);

        let escape = escaped as f32 / kf;
        let sky = self.params.sky * (PI * escape);
        let direct = emitted + punctual + sky;
        debug_assert!(direct.is_finite(), "texel {i}: direct {direct}");
        // As `end_row` treats the total: a non-finite term counts as no light.
        for term in &mut out.terms[terms..] {
            if !term.is_finite() {
                *term = Vec3::ZERO;
            }
        }

        // Row: the hit counts per source texel, `F_ij = hits / K`, stored as counts (exact,
        // see `Rows`) or as f32 weights with repeated hits merged.
        hits.sort_unstable();
        let before = out.col.len();
        if self.params.count_rows {
            out.counts.push_row(hits, k);
        } else {
            for run in hits.chunk_by(|a, b| a == b) {
                out.col.push(run[0]);
                out.f.push(run.len() as f32 / kf);
            }
        }
        out.end_row(before, escape, direct);
        out.rays += k as u64 + l as u64 + shadow_rays;
    }

    /// Texel `i`'s direct light from the punctual lights (normal `n`), the mean over
    /// [`PUNCTUAL_GRID`]² stratified footprint points, each light's share added to its source
    /// term (from `terms` in `out.terms`) when they are split; kept in `out.punctual` when the
    /// parameters ask. Returns the light and the shadow rays cast.
    fn punctual_light(
        &self,
        i: usize,
        n: Vec3,
        rng: &mut Rng,
        out: &mut ChunkRows,
        terms: usize,
    ) -> (Vec3, u64) {
        let Surfaces {
            scene,
            texels,
            tracer,
        } = self.surfaces;
        let mut punctual = Vec3::ZERO;
        if scene.lights.is_empty() {
            return (punctual, 0);
        }
        let g = PUNCTUAL_GRID;
        for s in 0..g * g {
            let u = (Vec2::new((s % g) as f32, (s / g) as f32) + rng.next_vec2()) / g as f32;
            let p = texels.punctual_point(tracer, i, self.footprint_point(i, u));
            for (l, light) in scene.lights.iter().enumerate() {
                let e = punctual_irradiance(light, p, n, tracer);
                punctual += e;
                if self.sources.is_some() {
                    out.terms[terms + l] += e;
                }
            }
        }
        punctual /= (g * g) as f32;
        if self.sources.is_some() {
            for term in &mut out.terms[terms..terms + scene.lights.len()] {
                *term /= (g * g) as f32;
            }
        }
        if self.params.keep_punctual {
            out.punctual.push(if punctual.is_finite() {
                punctual
            } else {
                Vec3::ZERO
            });
        }
        (punctual, (g * g) as u64 * scene.lights.len() as u64)
    }
}
