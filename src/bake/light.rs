//! The one place a transport meets its solver: light transport and its solution for a
//! [`Technique`]. Stored rows are built by [`transport::build`] and iterated by
//! [`solve::solve`]; the matrix-free gatherer and the hierarchy make their transport as they
//! solve ([`solve::gather`], [`solve::hierarchical`]).

use crate::config::{FormFactors, SolveParams, Technique, TransportParams};
use crate::plan::error_map;
use crate::shard::{Alone, Shards};
use crate::solve::{self, Solution};
use crate::transport::{self, Surfaces, Transport};
use crate::{Progress, Result};

/// The transport of one bake and its solution.
#[derive(Clone, Debug)]
pub(crate) struct Lit {
    pub(crate) transport: Transport,
    pub(crate) solution: Solution,
    /// Per texel, the variance of what one gathering ray returned
    /// (`plan::error_map::ray_variance`), when `TransportParams::ray_variance` asked; else
    /// empty.
    pub(crate) ray_variance: Vec<f32>,
}

/// The processes a bake runs on: what they share of the per-item work ([`Shards`]), and how
/// they make a transport and its solution — the pilot bakes' and the final bake's: on one
/// process ([`Alone`]) [`transport_and_solve`], on several a distributed solve
/// ([`super::distributed`]) with the same result.
pub(crate) trait Processes: Shards {
    /// [`transport_and_solve`]'s result.
    fn light(
        &self,
        surfaces: Surfaces,
        technique: Technique,
        params: &TransportParams,
        texel_rays: Option<&[u32]>,
        solve: &SolveParams,
        progress: &dyn Progress,
    ) -> Result<Lit>;
}

impl Processes for Alone {
    fn light(
        &self,
        surfaces: Surfaces,
        technique: Technique,
        params: &TransportParams,
        texel_rays: Option<&[u32]>,
        solve: &SolveParams,
        progress: &dyn Progress,
    ) -> Result<Lit> {
        transport_and_solve(surfaces, technique, params, texel_rays, solve, progress)
    }
}

/// Light transport and its solution with `technique`; `texel_rays` as in [`transport::build`].
pub(crate) fn transport_and_solve(
    surfaces: Surfaces,
    technique: Technique,
    params: &TransportParams,
    texel_rays: Option<&[u32]>,
    solve: &SolveParams,
    progress: &dyn Progress,
) -> Result<Lit> {
    let mut ray_variance = Vec::new();
    let (transport, solution) = match technique {
        Technique::Stored {
            form_factors,
            solver,
        } => {
            let t = transport::build(surfaces, form_factors, params, texel_rays, progress)?;
            let s = solve::solve(&t, surfaces.texels, solver, solve, progress)?;
            if params.ray_variance && form_factors == FormFactors::MonteCarlo {
                let (texels, sky) = (surfaces.texels, params.sky);
                ray_variance = error_map::ray_variance(&t, texels, &s.irradiance, sky);
            }
            (t, s)
        }
        Technique::Gather => solve::gather::solve(surfaces, params, solve, progress)?,
        Technique::Hierarchical => solve::hierarchical::solve(surfaces, params, solve, progress)?,
    };
    Ok(Lit {
        transport,
        solution,
        ray_variance,
    })
}
