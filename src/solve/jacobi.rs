//! Jacobi iteration: `H ← H_direct + F·(ρ ⊙ H_old)`, every row from the previous sweep.
//!
//! Parallel over rows with rayon (rows are independent), deterministic because each row's sum
//! runs in a fixed order. Converges like ρⁿ; pick it on many cores. Memory: two copies of H.
//! The pieces of a sweep are public to the crate: a distributed bake
//! ([`crate::bake::distributed`]) runs the same sweep over a share of the rows.

use glam::Vec3;
use rayon::prelude::*;

use crate::texels::prefetch;
use crate::transport::{Rows, Transport};

/// One sweep; returns (Σ|ΔH|, Σ|H|) over all texels and channels. `emitted` is `π·Le` per
/// texel when the rows carry emission, else empty.
pub(crate) fn sweep(
    t: &Transport,
    albedo: &[Vec3],
    emitted: &[Vec3],
    h: &mut [Vec3],
) -> (f64, f64) {
    let radiosity = radiosity(h, albedo, emitted);
    let changes: Vec<(f64, f64)> = h
        .par_iter_mut()
        .enumerate()
        .with_min_len(1024)
        .map(|(i, hi)| {
            let new = gathered(t, i, &radiosity);
            let change = row_change(*hi, new);
            *hi = new;
            change
        })
        .collect();
    sum_changes(changes)
}

/// Radiosity leaving each texel, `ρ·H (+ π·Le)`: what the rows gather.
pub(crate) fn radiosity(h: &[Vec3], albedo: &[Vec3], emitted: &[Vec3]) -> Vec<Vec3> {
    h.par_iter()
        .zip(albedo)
        .enumerate()
        .map(|(j, (h, rho))| *h * *rho + emitted.get(j).copied().unwrap_or(Vec3::ZERO))
        .collect()
}

/// The new `H` of row `i` of `t`: its direct light plus what the row gathers from `radiosity`.
/// Inlined into the sweep's loop, as it was before rows had two storages (a call per row).
#[inline(always)]
pub(crate) fn gathered(t: &Transport, i: usize, radiosity: &[Vec3]) -> Vec3 {
    let gathered = match &t.rows {
        // Each entry's radiosity is a random read from a large vector, and a row is too short
        // to ask for its own entries far enough ahead: ask for the next row's while this one
        // is summed (the same sum, in the same order).
        Rows::Weights(w) => {
            let (start, end) = (w.row_start[i] as usize, w.row_start[i + 1] as usize);
            let next = w.row_start.get(i + 2).map_or(end, |&e| e as usize);
            for &a in &w.col[end..next] {
                if let Some(v) = radiosity.get(a as usize) {
                    prefetch(v);
                }
            }
            let mut acc = Vec3::ZERO;
            for (&j, &f) in w.col[start..end].iter().zip(&w.f[start..end]) {
                acc += radiosity[j as usize] * f;
            }
            acc
        }
        Rows::Counts(_) => t
            .row(i)
            .fold(Vec3::ZERO, |acc, (j, f)| acc + radiosity[j as usize] * f),
    };
    t.direct[i] + gathered
}

/// One texel's (|ΔH|, |H|) summed over channels.
#[inline]
pub(crate) fn row_change(old: Vec3, new: Vec3) -> (f64, f64) {
    (
        (new - old).abs().element_sum() as f64,
        new.element_sum() as f64,
    )
}

/// (Σ|ΔH|, Σ|H|) of every texel's [`row_change`], summed in texel order (so the stopping rule
/// sees the same sums whatever splits the rows).
pub(crate) fn sum_changes(changes: impl IntoIterator<Item = (f64, f64)>) -> (f64, f64) {
    changes
        .into_iter()
        .fold((0.0, 0.0), |(c, s), (dc, ds)| (c + dc, s + ds))
}
