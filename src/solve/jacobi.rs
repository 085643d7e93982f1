//! Jacobi iteration: `H ← H_direct + F·(ρ ⊙ H_old)`, every row from the previous sweep.
//!
//! Parallel over rows with rayon (rows are independent), deterministic because each row's sum
//! runs in a fixed order. Converges like ρⁿ; pick it on many cores. Memory: two copies of H.

use glam::Vec3;
use rayon::prelude::*;

use crate::transport::Transport;

/// One sweep; returns (Σ|ΔH|, Σ|H|) over all texels and channels. `emitted` is `π·Le` per
/// texel when the rows carry emission, else empty.
pub fn sweep(t: &Transport, albedo: &[Vec3], emitted: &[Vec3], h: &mut [Vec3]) -> (f64, f64) {
    let radiosity: Vec<Vec3> = h
        .par_iter()
        .zip(albedo)
        .enumerate()
        .map(|(j, (h, rho))| *h * *rho + emitted.get(j).copied().unwrap_or(Vec3::ZERO))
        .collect();
    h.par_iter_mut()
        .enumerate()
        .with_min_len(1024)
        .map(|(i, hi)| {
            let gathered = t
                .row(i)
                .fold(Vec3::ZERO, |acc, (j, f)| acc + radiosity[j as usize] * f);
            let new = t.direct[i] + gathered;
            let change = (new - *hi).abs().element_sum() as f64;
            *hi = new;
            (change, new.element_sum() as f64)
        })
        .collect::<Vec<_>>()
        .iter()
        .fold((0.0, 0.0), |(c, s), (dc, ds)| (c + dc, s + ds))
}
