//! Stage 6 — `Solution`: the radiosity system iterated to a tolerance.
//!
//! Per colour channel the system is `H = H_direct + F·(ρ ⊙ H)` (see [`crate::transport`]).
//! Its spectral radius is at most max ρ < 1, so the Neumann series converges; each sweep is one
//! more bounce of light. Solvers live one per file.
//!
//! Stopping: the update `‖H_k − H_{k−1}‖` shrinks by about the ratio `r` of successive updates,
//! so the remaining error is about `‖ΔH_k‖ · r/(1−r)`. The solver stops when that estimate,
//! relative to `‖H‖`, is below the tolerance — which matters as ρ → 1, where a small update still
//! hides a large remaining error (ρ = 0.99 needs about 100× the last update).

mod gather;
mod gauss_seidel;
mod jacobi;
mod southwell;

use std::time::Instant;

use glam::Vec3;

use crate::config::{Method, SolveParams, Solver, TransportParams};
use crate::scene::Scene;
use crate::texels::Texels;
use crate::trace::Tracer;
use crate::transport::{self, Transport};
use crate::{Error, Progress, Result};

/// One sweep of a solver.
#[derive(Clone, Copy, Debug)]
pub struct Iteration {
    /// Relative update ‖H_k − H_{k−1}‖₁ / ‖H_k‖₁ of this sweep.
    pub residual: f32,
    /// Estimated relative error left in H after this sweep.
    pub error_estimate: f32,
    /// Wall seconds since the solver started.
    pub seconds: f64,
}

/// The solved irradiance per texel and how the solver got there.
#[derive(Clone, Debug, Default)]
pub struct Solution {
    /// Incident irradiance `H_i` (W/m²) per texel; the lightmap stores `H/π`.
    pub irradiance: Vec<Vec3>,
    pub history: Vec<Iteration>,
    /// True when the error estimate fell below the tolerance before the iteration cap.
    pub converged: bool,
}

impl Solution {
    /// Final relative update (0 when no iteration was needed).
    pub fn residual(&self) -> f32 {
        self.history.last().map_or(0.0, |i| i.residual)
    }
}

/// Light transport and solution together: the hierarchical method and the matrix-free
/// gathering solver do not store texel rows, the others build [`Transport`] and iterate it.
pub fn run(
    scene: &Scene,
    texels: &Texels,
    tracer: &Tracer,
    transport_params: &TransportParams,
    params: &SolveParams,
    progress: &dyn Progress,
) -> Result<(Transport, Solution)> {
    match (transport_params.method, params.solver) {
        (Method::Hierarchical, _) => transport::hierarchical::solve(
            scene,
            texels,
            tracer,
            transport_params,
            params,
            progress,
        ),
        (_, Solver::Gather) => {
            gather::solve(scene, texels, tracer, transport_params, params, progress)
        }
        _ => {
            let t = transport::build(scene, texels, tracer, transport_params, progress)?;
            let s = solve(&t, texels, params, progress)?;
            Ok((t, s))
        }
    }
}

/// Emitted radiosity `π·Le` per texel when the rows carry emission, else nothing.
fn row_emission(transport: &Transport, texels: &Texels) -> Vec<Vec3> {
    if transport.rows_carry_emission {
        texels
            .emission
            .iter()
            .map(|le| *le * std::f32::consts::PI)
            .collect()
    } else {
        Vec::new()
    }
}

/// Iterates the stored system with the solver `params` names.
pub fn solve(
    transport: &Transport,
    texels: &Texels,
    params: &SolveParams,
    progress: &dyn Progress,
) -> Result<Solution> {
    match params.solver {
        Solver::Southwell => return southwell::solve(transport, texels, params, progress),
        Solver::Gather => {
            return Err(Error::Option(
                "the gather solver re-casts rays: call solve::run".into(),
            ));
        }
        Solver::Jacobi | Solver::GaussSeidel => {}
    }
    let n = transport.len();
    let emitted = row_emission(transport, texels);
    let mut h = transport.direct.clone();
    let mut solution = Solution::default();
    let start = Instant::now();
    progress.begin("solve", params.max_iterations as u64);
    let mut previous_residual = f32::INFINITY;
    for _ in 0..params.max_iterations {
        if progress.aborted() {
            return Err(Error::Aborted);
        }
        let (change, total) = match params.solver {
            Solver::GaussSeidel => gauss_seidel::sweep(transport, &texels.albedo, &emitted, &mut h),
            _ => jacobi::sweep(transport, &texels.albedo, &emitted, &mut h),
        };
        let residual = if total > 0.0 {
            (change / total) as f32
        } else {
            0.0
        };
        let ratio = if previous_residual.is_finite() && previous_residual > 0.0 {
            (residual / previous_residual).min(0.999)
        } else {
            0.5
        };
        previous_residual = residual;
        let error_estimate = residual * ratio / (1.0 - ratio);
        solution.history.push(Iteration {
            residual,
            error_estimate,
            seconds: start.elapsed().as_secs_f64(),
        });
        progress.advance(1);
        if !residual.is_finite() {
            return Err(Error::Option(format!(
                "the solver diverged (residual {residual}) after {} sweeps",
                solution.history.len()
            )));
        }
        if error_estimate < params.tolerance && solution.history.len() >= 2 || residual == 0.0 {
            solution.converged = true;
            break;
        }
    }
    progress.end();
    debug_assert_eq!(h.len(), n);
    debug_assert!(h.iter().all(|v| v.is_finite()));
    solution.irradiance = h;
    Ok(solution)
}
