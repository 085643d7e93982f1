//! The one place a transport meets its solver: light transport and its solution for a
//! [`Technique`]. Stored rows are built by [`transport::build`] and iterated by
//! [`solve::solve`]; the matrix-free gatherer and the hierarchy make their transport as they
//! solve ([`solve::gather`], [`solve::hierarchical`]).

use crate::config::{BakeConfig, SolveParams, Technique, TransportParams};
use crate::solve::{self, Solution};
use crate::transport::{self, Surfaces, Transport};
use crate::{Progress, Result};

/// The transport of one bake and its solution.
#[derive(Clone, Debug)]
pub(crate) struct Lit {
    pub(crate) transport: Transport,
    pub(crate) solution: Solution,
}

/// What makes the final bake's transport and solution from the planned settings and the
/// per-texel rays: [`by_technique`] on this machine, or a distributed solve
/// ([`super::distributed`]).
pub(crate) type LightFn<'a> =
    &'a dyn Fn(Surfaces, &BakeConfig, Option<&[u32]>, &dyn Progress) -> Result<Lit>;

/// [`transport_and_solve`] with `config`'s technique and parameters.
pub(crate) fn by_technique(
    surfaces: Surfaces,
    config: &BakeConfig,
    texel_rays: Option<&[u32]>,
    progress: &dyn Progress,
) -> Result<Lit> {
    transport_and_solve(
        surfaces,
        config.technique,
        &config.transport,
        texel_rays,
        &config.solve,
        progress,
    )
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
    let (transport, solution) = match technique {
        Technique::Stored {
            form_factors,
            solver,
        } => {
            let t = transport::build(surfaces, form_factors, params, texel_rays, progress)?;
            let s = solve::solve(&t, surfaces.texels, solver, solve, progress)?;
            (t, s)
        }
        Technique::Gather => solve::gather::solve(surfaces, params, solve, progress)?,
        Technique::Hierarchical => solve::hierarchical::solve(surfaces, params, solve, progress)?,
    };
    Ok(Lit {
        transport,
        solution,
    })
}
