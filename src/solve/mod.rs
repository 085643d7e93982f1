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

//!
//! The stored-row solvers ([`solve`]: Jacobi, Gauss–Seidel, Southwell) take a built
//! [`Transport`]; `gather` (matrix-free Monte Carlo) and [`hierarchical`] make the light
//! transport they iterate as they go. All of them stop by one shared rule (`Stopping`, below).

pub(crate) mod gather;
mod gauss_seidel;
pub mod hierarchical;
pub(crate) mod jacobi;
mod southwell;

use std::time::Instant;

use glam::Vec3;

use crate::config::{RowSolver, SolveParams};
use crate::texels::Texels;
use crate::transport::Transport;
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
    /// Each sweep, in order.
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

/// The stopping rule every solver shares: each iteration's residual and error estimate are
/// recorded as an [`Iteration`], a non-finite estimate is an error (the solver diverged), and
/// the loop ends at the tolerance, the iteration cap, or an abort.
pub(crate) struct Stopping<'a> {
    params: &'a SolveParams,
    history: &'a mut Vec<Iteration>,
    progress: &'a dyn Progress,
    /// Named in the divergence error, with the unit of one iteration.
    solver: &'static str,
    unit: &'static str,
    start: Instant,
    previous_residual: f32,
    /// Iterations of this loop (a hierarchical solve runs one loop per refinement).
    count: u32,
}

impl<'a> Stopping<'a> {
    /// Begins the `solve` progress stage; iterations are recorded in `history`, their times
    /// counted from `start`.
    pub(crate) fn begin(
        (solver, unit): (&'static str, &'static str),
        params: &'a SolveParams,
        history: &'a mut Vec<Iteration>,
        start: Instant,
        progress: &'a dyn Progress,
    ) -> Self {
        progress.begin("solve", params.max_iterations as u64);
        Stopping {
            params,
            history,
            progress,
            solver,
            unit,
            start,
            previous_residual: f32::INFINITY,
            count: 0,
        }
    }

    /// Before each iteration: false at the iteration cap, an error when aborted.
    pub(crate) fn next(&self) -> Result<bool> {
        if self.count == self.params.max_iterations {
            return Ok(false);
        }
        if self.progress.aborted() {
            return Err(Error::Aborted);
        }
        Ok(true)
    }

    /// An iteration that changed `H` by `change = Σ|ΔH|` with `total = Σ|H|`: the residual is
    /// their ratio, and the error left is the update extrapolated over the geometric series of
    /// the updates' ratio (see the module doc). True when converged.
    pub(crate) fn sweep(&mut self, change: f64, total: f64) -> Result<bool> {
        let residual = if total > 0.0 {
            (change / total) as f32
        } else {
            0.0
        };
        let ratio = if self.previous_residual.is_finite() && self.previous_residual > 0.0 {
            (residual / self.previous_residual).min(0.999)
        } else {
            0.5
        };
        self.previous_residual = residual;
        let error_estimate = residual * ratio / (1.0 - ratio);
        let below = self.record(residual, error_estimate)?;
        Ok(below && self.count >= 2 || residual == 0.0)
    }

    /// An iteration with the solver's own error estimate; true when it is below the tolerance.
    pub(crate) fn record(&mut self, residual: f32, error_estimate: f32) -> Result<bool> {
        self.count += 1;
        self.history.push(Iteration {
            residual,
            error_estimate,
            seconds: self.start.elapsed().as_secs_f64(),
        });
        self.progress.advance(1);
        if !error_estimate.is_finite() {
            return Err(Error::Internal(format!(
                "the {} solver diverged (residual {residual}, error estimate {error_estimate}) \
                 after {} {}",
                self.solver, self.count, self.unit
            )));
        }
        Ok(error_estimate < self.params.tolerance)
    }

    pub(crate) fn end(self) {
        self.progress.end();
    }
}

/// Emitted radiosity `π·Le` per texel when the rows carry emission, else nothing.
pub(crate) fn row_emission(transport: &Transport, texels: &Texels) -> Vec<Vec3> {
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

/// One sweep of Jacobi or Gauss–Seidel: (rows, albedo, emitted, H) → (Σ|ΔH|, Σ|H|).
type Sweep = fn(&Transport, &[Vec3], &[Vec3], &mut [Vec3]) -> (f64, f64);

/// Iterates the stored system with `solver`.
pub fn solve(
    transport: &Transport,
    texels: &Texels,
    solver: RowSolver,
    params: &SolveParams,
    progress: &dyn Progress,
) -> Result<Solution> {
    let (sweep, name): (Sweep, _) = match solver {
        RowSolver::Southwell => return southwell::solve(transport, texels, params, progress),
        RowSolver::Jacobi => (jacobi::sweep, "jacobi"),
        RowSolver::GaussSeidel => (gauss_seidel::sweep, "gauss-seidel"),
    };
    let n = transport.len();
    let emitted = row_emission(transport, texels);
    let mut h = transport.direct.clone();
    let mut solution = Solution::default();
    let start = Instant::now();
    let mut stopping = Stopping::begin(
        (name, "sweeps"),
        params,
        &mut solution.history,
        start,
        progress,
    );
    while stopping.next()? {
        let (change, total) = sweep(transport, &texels.albedo, &emitted, &mut h);
        if stopping.sweep(change, total)? {
            solution.converged = true;
            break;
        }
    }
    stopping.end();
    debug_assert_eq!(h.len(), n);
    debug_assert!(h.iter().all(|v| v.is_finite()));
    solution.irradiance = h;
    Ok(solution)
}

#[cfg(test)]
pub(crate) mod tests {
    /// A scene of `fixtures/`.
    pub(crate) fn fixture(name: &str) -> std::path::PathBuf {
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("fixtures")
            .join(name)
    }
}
