//! Gauss–Seidel iteration: rows updated in place, in texel order, each using the newest values.
//!
//! About twice Jacobi's convergence per sweep on radiosity systems, but serial (a sweep depends
//! on its own results). Pick it on one or two cores or when memory for a second H is tight.

use glam::Vec3;

use crate::transport::Transport;

/// One sweep; returns (Σ|ΔH|, Σ|H|) over all texels and channels. `emitted` is `π·Le` per
/// texel when the rows carry emission, else empty.
pub(crate) fn sweep(
    t: &Transport,
    albedo: &[Vec3],
    emitted: &[Vec3],
    h: &mut [Vec3],
) -> (f64, f64) {
    let (mut change, mut total) = (0.0f64, 0.0f64);
    for i in 0..h.len() {
        let gathered = t.row(i).fold(Vec3::ZERO, |acc, (j, f)| {
            let j = j as usize;
            acc + (h[j] * albedo[j] + emitted.get(j).copied().unwrap_or(Vec3::ZERO)) * f
        });
        let new = t.direct[i] + gathered;
        change += (new - h[i]).abs().element_sum() as f64;
        total += new.element_sum() as f64;
        h[i] = new;
    }
    (change, total)
}
