//! Stage 5 — `Transport`: how light moves between texels.
//!
//! For each receiving texel `i` this holds a sparse row of form factors `F_ij` ([`Rows`]: f32
//! weights, or for Monte Carlo the exact ray counts they come from), the fraction of its hemisphere that escapes to the sky, and the
//! direct irradiance `H_direct,i` from punctual lights, emissive surfaces and the sky.
//!
//! The system solved downstream is, per colour channel,
//!
//! ```text
//!   H_i = H_direct,i + Σ_j F_ij · ρ_j H_j        (W/m²)
//! ```
//!
//! i.e. gathering carries only *reflected* radiosity `ρH`; emitted radiosity `π·Le` enters once,
//! through `H_direct`, where it is estimated with explicit light sampling (small bright emitters
//! are otherwise missed) combined with the gathering rays by multiple importance sampling.

//!
//! `build` makes stored rows with the chosen [`FormFactors`]; the matrix-free gather solver
//! and the hierarchical solver (in [`crate::solve`]) use the pieces here — the Monte Carlo
//! method's per-texel gathering, the [`hierarchical`] links — without storing texel rows.
//! Every method builds its rows with one driver (`rows.rs`): parallel chunks of receivers,
//! concatenated in order.

mod all_pairs;
pub mod hierarchical;
// Public on purpose: the form-factor kernels and Howell's closed forms are the yardsticks of
// anyone checking form factors (the analytic tests, the benchmark's stability study).
pub mod kernel;
pub(crate) mod montecarlo;
mod point;
mod polygon;
pub(crate) mod rows;
mod storage;

use glam::Vec3;

use crate::config::{FormFactors, TransportParams};
use crate::scene::Scene;
use crate::texels::Texels;
use crate::trace::Tracer;
use crate::{Progress, Result};
pub use storage::{CountRow, CountRows, Row, Rows, WeightRows};

/// What every transport method reads: the scene, its texels and the tracer over the scene.
#[derive(Clone, Copy)]
pub struct Surfaces<'a> {
    /// The scene.
    pub scene: &'a Scene,
    /// Its texels.
    pub texels: &'a Texels,
    /// The BVH over the scene.
    pub tracer: &'a Tracer,
}

/// Form factors and direct light of every texel.
#[derive(Clone, Debug, Default)]
pub struct Transport {
    /// Row `i` holds `F_ij`, the fraction of the energy arriving at `i` that leaves `j` (rows
    /// sum to ≤ 1), for the source texels `j` it sees.
    pub rows: Rows,
    /// Fraction of texel `i`'s hemisphere that sees the sky.
    pub escape: Vec<f32>,
    /// Direct irradiance `H_direct` (W/m²): punctual lights, emitters, sky.
    pub direct: Vec<Vec3>,
    /// Rays cast building this.
    pub rays: u64,
    /// True when emitters are not in `direct` but are gathered through the rows like any other
    /// radiosity (`B_j = π·Le_j + ρ_j H_j`); false when `direct` already holds them (Monte Carlo
    /// with explicit light sampling), so rows carry only reflected radiosity `ρ_j H_j`.
    pub rows_carry_emission: bool,
    /// `direct` split by light source, `sources.len()` values per texel (texel-major), when
    /// `TransportParams::split_direct` asks for it (relighting and per-light layers), else
    /// empty. The sky is not a source: its part of `direct` is `π · sky · escape`.
    pub direct_terms: Vec<Vec3>,
    /// The sources of `direct_terms`.
    pub sources: Sources,
    /// The part of `direct` from punctual lights, per texel, as Monte Carlo transport samples
    /// it (jittered footprint points), when `TransportParams::keep_punctual` asks (the
    /// planner's pilot runs); empty otherwise, without punctual lights or for other methods.
    /// The planner's punctual sample takes each pilot run's own (`plan::PunctualSample`), so
    /// no shadow ray is cast for it again.
    pub punctual: Vec<Vec3>,
}

/// The light sources direct light is split into ([`Transport::direct_terms`]): every punctual
/// light of the scene in scene order, then every emissive material in material order. Direct
/// light is linear in each source's intensity or emission, so scaling a source scales its term.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Sources {
    /// Sources `0..lights` are the scene's punctual lights.
    pub(crate) lights: usize,
    /// Source `lights + k` is the emission of material `emissive[k]`.
    pub(crate) emissive: Vec<u32>,
    /// Per material: its source, or `u32::MAX` when it does not emit.
    pub(crate) material_source: Vec<u32>,
}

impl Sources {
    pub(crate) fn new(scene: &Scene) -> Sources {
        let mut emissive = Vec::new();
        let material_source = (scene.materials.iter().enumerate())
            .map(
                |(m, material)| match material.emission.max_element() > 0.0 {
                    true => {
                        emissive.push(m as u32);
                        (scene.lights.len() + emissive.len() - 1) as u32
                    }
                    false => u32::MAX,
                },
            )
            .collect();
        Sources {
            lights: scene.lights.len(),
            emissive,
            material_source,
        }
    }

    pub(crate) fn len(&self) -> usize {
        self.lights + self.emissive.len()
    }
    /// The source of emitting texel `j`: its main triangle's material.
    #[inline]
    pub(crate) fn of_texel(&self, scene: &Scene, texels: &Texels, j: u32) -> usize {
        let t = texels.triangle[j as usize] as usize;
        let m = scene.instances[scene.triangle_instance[t] as usize].material;
        self.material_source[m as usize] as usize
    }
}

impl Transport {
    /// The entries of row `i` as (source texel, F_ij).
    #[inline(always)]
    pub fn row(&self, i: usize) -> Row<'_> {
        self.rows.row(i)
    }

    /// Rows given as (source texel, `F_ij`) per receiver, with each receiver's escape
    /// fraction; no direct light, no rays. How rows come back from outside the builders (a
    /// kept transport, `bake::kept`), so readers never touch the row storage.
    pub(crate) fn from_rows<R>(rows: impl Iterator<Item = R>, escape: Vec<f32>) -> Transport
    where
        R: Iterator<Item = (u32, f32)>,
    {
        let mut w = WeightRows::default();
        for row in rows {
            for (j, f) in row {
                w.col.push(j);
                w.f.push(f);
            }
            w.row_start.push(w.col.len() as u32);
        }
        Transport {
            rows: Rows::Weights(w),
            escape,
            ..Default::default()
        }
    }

    /// Texels (receivers).
    pub fn len(&self) -> usize {
        self.direct.len()
    }
    /// No texels.
    pub fn is_empty(&self) -> bool {
        self.direct.is_empty()
    }

    /// Debug-build check: finite, non-negative, rows bounded.
    #[cfg(debug_assertions)]
    pub(crate) fn validate(&self) {
        assert_eq!(self.rows.len(), self.direct.len());
        if let Rows::Weights(w) = &self.rows {
            assert_eq!(w.col.len(), w.f.len());
        }
        assert!(
            self.direct
                .iter()
                .all(|d| d.is_finite() && d.min_element() >= 0.0)
        );
        for i in 0..self.len() {
            let sum: f32 = self.row(i).map(|(_, f)| f).sum::<f32>() + self.escape[i];
            assert!(sum <= 1.0 + 1e-3, "row {i} sums to {sum}");
        }
    }
}

/// Stored rows of form factors and direct light for every texel. `texel_rays` (indexed like
/// the texels) gives a texel fewer gathering rays than `params.gather_rays` (Monte Carlo rows
/// only; see [`crate::plan`]); `None` casts `gather_rays` everywhere.
pub(crate) fn build(
    surfaces: Surfaces,
    form_factors: FormFactors,
    params: &TransportParams,
    texel_rays: Option<&[u32]>,
    progress: &dyn Progress,
) -> Result<Transport> {
    let transport = match form_factors {
        FormFactors::MonteCarlo => montecarlo::build(surfaces, params, texel_rays, progress)?,
        FormFactors::Point => point::build(surfaces, params, progress)?,
        FormFactors::Polygon => polygon::build(surfaces, params, progress)?,
    };
    #[cfg(debug_assertions)]
    transport.validate();
    Ok(transport)
}
