//! Stage 6 — `Solution`: the radiosity system iterated to a residual tolerance.
use glam::Vec3;
use crate::config::SolveParams;
use crate::texels::Texels;
use crate::transport::Transport;
use crate::{Progress, Result};

/// One sweep of a solver.
#[derive(Clone, Copy, Debug)]
pub struct Iteration {
    /// Relative residual ‖H_new − H_old‖₁ / ‖H_new‖₁ after this sweep.
    pub residual: f32,
    /// Wall seconds since the solver started.
    pub seconds: f64,
}

/// The solved irradiance per texel and how the solver got there.
#[derive(Clone, Debug, Default)]
pub struct Solution {
    /// Incident irradiance `H_i` (W/m²) per texel; the lightmap stores `H/π`.
    pub irradiance: Vec<Vec3>,
    pub history: Vec<Iteration>,
    /// True when the residual fell below the tolerance before the iteration cap.
    pub converged: bool,
}

impl Solution {
    /// Final relative residual (0 when no iteration was needed).
    pub fn residual(&self) -> f32 {
        self.history.last().map_or(0.0, |i| i.residual)
    }
}

pub fn solve(transport: &Transport, texels: &Texels, params: &SolveParams, progress: &dyn Progress) -> Result<Solution> {
    let _ = (transport, texels, params, progress);
    todo!()
}
