//! Southwell iteration as progressive refinement (Cohen, Chen, Wallace & Greenberg 1988):
//! shoot the texel with the most unshot power.
//!
//! Each texel keeps unshot radiosity `ΔB_j` — light it has received (or emits) but not yet passed
//! on. Shooting `j` distributes it down column `j` of the stored system:
//!
//! ```text
//!   ΔH_i += F_ij · ΔB_j        for every receiver i that sees j
//!   ΔB_i += ρ_i F_ij · ΔB_j    (what i reflects of it, to be shot later)
//!   ΔB_j  = 0
//! ```
//!
//! starting from `H = H_direct` and `ΔB_j = ρ_j H_direct,j` (plus `π·Le_j` when the rows carry
//! emission). Each shot removes the largest term of the residual, so early shots carry most of
//! the light; the columns come from a transpose (CSC) of the rows built once.
//!
//! Picking: a lazy max-heap keyed by unshot power `A_j · ΔB_j` (channel sum). A receiver is
//! pushed again only when its power has grown past [`REQUEUE_GROWTH`] times the key it is queued
//! under, and an entry whose key is not the texel's latest is skipped when popped. So each pick
//! is within a factor 2 of the largest unshot power (a relaxed Southwell), while heap traffic
//! drops from one push per form factor touched to a few per texel shot (a push per touched entry
//! made the whole solve about 4× slower on the ρ = 0.99 furnace). The heap is rebuilt when it
//! holds more than a few entries per texel. Ties go to the lower texel id: deterministic, serial.
//!
//! Stopping: unshot power `U` (per channel, `Σ A_j ΔB_j`) is what the solution still lacks.
//! Shot once it arrives as `d·U` (`d`, the delivered fraction, measured over the last batch of
//! shots: 1 in a closed scene), a fraction `q` of the shot power comes back as new unshot power,
//! so the area-weighted irradiance still to come is `U·d/(1−q)`. Relative to the irradiance
//! already gathered, `Σ A_i H_i`, that is the error estimate, compared with the tolerance like
//! the other solvers' (theirs is unweighted; texels have nearly equal areas). The residual
//! reported is `U / Σ A_i H_i` (channel sums).
//!
//! | parameter        | default            | effect                                              |
//! |------------------|--------------------|-----------------------------------------------------|
//! | `tolerance`      | from the preset    | stop when the error estimate falls below it         |
//! | `max_iterations` | 10 000             | cap on batches of n shots (n = texels)             |
//!
//! One [`Iteration`](super::Iteration) is recorded per batch of `n` shots ("a sweep's worth").
//!
//! When to use it: the first shots give a usable picture soonest (with [`ambient`] for display),
//! and it needs fewer sweep-equivalents than Gauss–Seidel when light is concentrated (a small
//! emitter). Limits: serial; the transpose doubles row memory; scattered f64 updates and the
//! heap make a sweep-equivalent about 10× a Gauss–Seidel sweep (486-texel furnace, K = 128:
//! ρ = 0.9 in 56 batches, 0.1 s, against 52 sweeps, 0.005 s), so when light is spread evenly
//! Gauss–Seidel wins. Its error estimate is the more honest one: at ρ = 0.99 and tolerance 1e-5
//! it stopped 0.001% from the answer, Jacobi and Gauss–Seidel 0.02–0.04%.

use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::time::Instant;

use glam::{DVec3, Vec3};

use super::{Solution, Stopping};
use crate::config::SolveParams;
use crate::texels::Texels;
use crate::transport::Transport;
use crate::{Progress, Result};

/// Heap entries per texel before the heap is rebuilt from the current powers.
const HEAP_SLACK: usize = 4;
/// A queued texel is queued again once its unshot power exceeds its key by this factor.
const REQUEUE_GROWTH: f32 = 2.0;
/// Largest ratio of returned to shot power trusted in the error estimate (as in `solve`).
const MAX_RETURN: f64 = 0.999;

/// Column `j` of the rows: receivers `row[col_start[j]..col_start[j+1]]` with `F_ij` in `f`.
struct Columns {
    col_start: Vec<u32>,
    row: Vec<u32>,
    f: Vec<f32>,
}

impl Columns {
    /// Transposes the rows (counting sort: receivers stay in increasing order per column).
    fn new(t: &Transport) -> Columns {
        let n = t.len();
        let mut col_start = vec![0u32; n + 1];
        for i in 0..n {
            for (j, _) in t.row(i) {
                col_start[j as usize + 1] += 1;
            }
        }
        for j in 0..n {
            col_start[j + 1] += col_start[j];
        }
        let mut next: Vec<u32> = col_start[..n].to_vec();
        let entries = col_start[n] as usize;
        let mut row = vec![0u32; entries];
        let mut f = vec![0.0f32; entries];
        for i in 0..n {
            for (j, f_ij) in t.row(i) {
                let k = next[j as usize] as usize;
                row[k] = i as u32;
                f[k] = f_ij;
                next[j as usize] += 1;
            }
        }
        Columns { col_start, row, f }
    }

    #[inline]
    fn column(&self, j: usize) -> impl Iterator<Item = (usize, f32)> + '_ {
        let r = self.col_start[j] as usize..self.col_start[j + 1] as usize;
        self.row[r.clone()]
            .iter()
            .map(|&i| i as usize)
            .zip(self.f[r].iter().copied())
    }
}

/// Power shot, delivered to receivers and reflected back into unshot, per channel, since the
/// last [`Progressive::take_tally`].
#[derive(Clone, Copy, Debug, Default)]
struct Tally {
    shot: DVec3,
    delivered: DVec3,
    reflected: DVec3,
}

/// The state of a progressive-refinement solve: irradiance so far and unshot radiosity.
pub(crate) struct Progressive<'a> {
    albedo: &'a [Vec3],
    area: &'a [f32],
    escape: &'a [f32],
    columns: Columns,
    /// Irradiance gathered so far (f64: late shots add increments far below an f32 ulp of H).
    h: Vec<DVec3>,
    /// Unshot radiosity `ΔB` per texel.
    unshot: Vec<DVec3>,
    /// (unshot power bits, texel): non-negative f32 bits order like the values.
    heap: BinaryHeap<(u32, Reverse<u32>)>,
    /// The key each texel's live heap entry has (0: not queued).
    queued: Vec<u32>,
    tally: Tally,
}

impl<'a> Progressive<'a> {
    pub(crate) fn new(transport: &'a Transport, texels: &'a Texels) -> Progressive<'a> {
        let emitted = super::row_emission(transport, texels);
        let h: Vec<DVec3> = transport.direct.iter().map(|d| d.as_dvec3()).collect();
        let unshot = (0..transport.len())
            .map(|j| {
                let e = emitted.get(j).copied().unwrap_or(Vec3::ZERO);
                (texels.albedo[j] * transport.direct[j] + e).as_dvec3()
            })
            .collect();
        let mut p = Progressive {
            albedo: &texels.albedo,
            area: &texels.area,
            escape: &transport.escape,
            columns: Columns::new(transport),
            h,
            unshot,
            heap: BinaryHeap::new(),
            queued: Vec::new(),
            tally: Tally::default(),
        };
        p.rebuild_heap();
        p
    }

    #[inline]
    fn power_key(&self, j: usize) -> u32 {
        ((self.unshot[j] * self.area[j] as f64).element_sum() as f32).to_bits()
    }

    fn rebuild_heap(&mut self) {
        self.queued = (0..self.unshot.len()).map(|j| self.power_key(j)).collect();
        let entries: Vec<(u32, Reverse<u32>)> = (self.queued.iter().enumerate())
            .filter(|&(_, &key)| f32::from_bits(key) > 0.0)
            .map(|(j, &key)| (key, Reverse(j as u32)))
            .collect();
        self.heap = BinaryHeap::from(entries);
    }

    /// The texel with the most unshot power, removed from the heap; `None` when all is shot.
    fn pick(&mut self) -> Option<usize> {
        while let Some((key, Reverse(j))) = self.heap.pop() {
            let j = j as usize;
            if key == self.queued[j] {
                self.queued[j] = 0;
                return Some(j);
            }
        }
        None
    }

    /// Shoots texel `j`'s unshot radiosity to every texel that sees it.
    fn shoot_from(&mut self, j: usize) {
        let b = std::mem::take(&mut self.unshot[j]);
        // Σ A_i F_ij and Σ A_i ρ_i F_ij, for the tally (times b once, after the loop).
        let (mut af, mut af_rho) = (0.0f64, DVec3::ZERO);
        for (i, f_ij) in self.columns.column(j) {
            let rho = self.albedo[i].as_dvec3();
            let dh = b * f_ij as f64;
            self.h[i] += dh;
            self.unshot[i] += dh * rho;
            let a_f = self.area[i] as f64 * f_ij as f64;
            af += a_f;
            af_rho += rho * a_f;
            let key = self.power_key(i);
            let power = f32::from_bits(key);
            if power > 0.0 && power > REQUEUE_GROWTH * f32::from_bits(self.queued[i]) {
                self.queued[i] = key;
                self.heap.push((key, Reverse(i as u32)));
            }
        }
        self.tally.shot += b * self.area[j] as f64;
        self.tally.delivered += b * af;
        self.tally.reflected += b * af_rho;
        if self.heap.len() > HEAP_SLACK * self.unshot.len() + 1024 {
            self.rebuild_heap();
        }
    }

    /// Up to `shots` shots, most unshot power first; returns how many were made (fewer only
    /// when nothing is left to shoot).
    pub(crate) fn shoot(&mut self, shots: usize) -> usize {
        for done in 0..shots {
            let Some(j) = self.pick() else {
                return done;
            };
            self.shoot_from(j);
        }
        shots
    }

    /// Irradiance gathered so far.
    pub(crate) fn irradiance(&self) -> Vec<Vec3> {
        self.h.iter().map(|h| h.as_vec3()).collect()
    }

    /// The intermediate estimate for display: irradiance so far plus the [`ambient`] term.
    pub(crate) fn display(&self) -> Vec<Vec3> {
        let ambient = ambient(self.area, self.albedo, self.escape, &self.unshot);
        self.h.iter().map(|h| h.as_vec3() + ambient).collect()
    }

    /// (residual, error estimate) now, from the unshot power and the tally of shots since the
    /// last call (see the module doc).
    fn take_tally(&mut self) -> (f32, f32) {
        let tally = std::mem::take(&mut self.tally);
        let (mut unshot, mut gathered) = (DVec3::ZERO, DVec3::ZERO);
        for j in 0..self.h.len() {
            let a = self.area[j] as f64;
            unshot += self.unshot[j] * a;
            gathered += self.h[j] * a;
        }
        let residual = ratio(unshot.element_sum(), gathered.element_sum());
        let mut error = 0.0f64;
        for c in 0..3 {
            let (delivered, returned) = if tally.shot[c] > 0.0 {
                (
                    tally.delivered[c] / tally.shot[c],
                    (tally.reflected[c] / tally.shot[c]).min(MAX_RETURN),
                )
            } else {
                (1.0, MAX_RETURN) // nothing shot in this channel: assume the worst
            };
            let remaining = unshot[c] * delivered / (1.0 - returned);
            error = error.max(ratio(remaining, gathered[c]));
        }
        (residual as f32, error as f32)
    }
}

/// `a / b`, 0 when there is nothing (`a` = 0) and infinite when only `a` is.
fn ratio(a: f64, b: f64) -> f64 {
    if a <= 0.0 {
        0.0
    } else if b > 0.0 {
        a / b
    } else {
        f64::INFINITY
    }
}

/// Ambient irradiance for displaying an unfinished solve (Cohen et al. 1988, §4.1), per channel:
///
/// ```text
///   H_ambient = (1−ē) · ΔB̄ / (1 − ρ̄ (1−ē))
/// ```
///
/// with `ΔB̄ = Σ A_j ΔB_j / Σ A_j` the mean unshot radiosity, `ρ̄` the area-weighted mean
/// reflectance and `ē` the area-weighted fraction of hemispheres that see the sky. Cohen's term
/// assumes a closed scene (`ē = 0`); the `(1−ē)` factors let open scenes lose light to the sky at
/// every bounce. Adding it to every texel's `H` gives the right total without knowing where the
/// unshot light will land — the picture is neither black nor dim early on.
pub(crate) fn ambient(area: &[f32], albedo: &[Vec3], escape: &[f32], unshot: &[DVec3]) -> Vec3 {
    let (mut total_area, mut rho, mut sky, mut b) = (0.0f64, DVec3::ZERO, 0.0f64, DVec3::ZERO);
    for j in 0..area.len() {
        let a = area[j] as f64;
        total_area += a;
        rho += albedo[j].as_dvec3() * a;
        sky += escape.get(j).copied().unwrap_or(0.0) as f64 * a;
        b += unshot[j] * a;
    }
    if total_area <= 0.0 {
        return Vec3::ZERO;
    }
    let (rho, stays, b) = (
        rho / total_area,
        (1.0 - sky / total_area).clamp(0.0, 1.0),
        b / total_area,
    );
    let h = b * stays / (DVec3::ONE - rho * stays).max(DVec3::splat(1.0 - MAX_RETURN));
    h.as_vec3()
}

/// Solves the stored system by progressive refinement (see the module doc). When the cap stops
/// it first, the [`ambient`] term is added: the best estimate of the unfinished solution.
pub(crate) fn solve(
    transport: &Transport,
    texels: &Texels,
    params: &SolveParams,
    progress: &dyn Progress,
) -> Result<Solution> {
    let n = transport.len();
    let start = Instant::now();
    let mut state = Progressive::new(transport, texels);
    let mut solution = Solution::default();
    let history = &mut solution.history;
    let mut stopping = Stopping::begin(("southwell", "batches"), params, history, start, progress);
    while stopping.next()? {
        let shots = state.shoot(n);
        let (residual, error_estimate) = state.take_tally();
        if stopping.record(residual, error_estimate)? || shots < n {
            solution.converged = true;
            break;
        }
    }
    stopping.end();
    solution.irradiance = if solution.converged {
        state.irradiance()
    } else {
        state.display()
    };
    debug_assert!(solution.irradiance.iter().all(|h| h.is_finite()));
    Ok(solution)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{BakeConfig, FormFactors, RowSolver, Technique};
    use crate::solve::tests::fixture;
    use crate::transport::{Rows, WeightRows};
    use crate::{NoProgress, compute};

    fn config() -> BakeConfig {
        let mut c = BakeConfig::draft();
        c.transport.gather_rays = 64;
        c.transport.light_samples = 16;
        c.solve.tolerance = 1e-5;
        c
    }

    #[test]
    fn transpose_lists_every_entry_once_by_column() {
        let t = Transport {
            rows: Rows::Weights(WeightRows {
                row_start: vec![0, 2, 3, 5],
                col: vec![1, 2, 0, 0, 1],
                f: vec![0.1, 0.2, 0.3, 0.4, 0.5],
            }),
            escape: vec![0.0; 3],
            direct: vec![Vec3::ZERO; 3],
            ..Default::default()
        };
        let c = Columns::new(&t);
        let columns: Vec<Vec<(usize, f32)>> = (0..3).map(|j| c.column(j).collect()).collect();
        assert_eq!(columns[0], vec![(1, 0.3), (2, 0.4)]);
        assert_eq!(columns[1], vec![(0, 0.1), (2, 0.5)]);
        assert_eq!(columns[2], vec![(0, 0.2)]);
    }

    #[test]
    fn agrees_with_gauss_seidel_and_is_deterministic() {
        let mut c = config();
        c.technique = Technique::stored(FormFactors::MonteCarlo, RowSolver::GaussSeidel);
        let baked = compute(&fixture("cornell_box.gltf"), &c, &NoProgress).unwrap();
        let southwell = |t| {
            super::super::solve(
                t,
                &baked.texels,
                RowSolver::Southwell,
                &c.solve,
                &NoProgress,
            )
        };
        let a = southwell(&baked.transport).unwrap();
        let b = southwell(&baked.transport).unwrap();
        assert!(a.converged);
        assert_eq!(a.irradiance, b.irradiance);
        let err = crate::metrics::relative_l1(&a.irradiance, &baked.solution.irradiance);
        assert!(err < 1e-4, "southwell vs gauss-seidel: {err}");
    }

    /// Cohen's ambient term brings an unfinished solve closer to the converged one.
    #[test]
    fn ambient_term_improves_the_intermediate_picture() {
        for name in ["furnace_09.gltf", "cornell_box.gltf"] {
            let baked = compute(&fixture(name), &config(), &NoProgress).unwrap();
            let converged = &baked.solution.irradiance;
            let mut state = Progressive::new(&baked.transport, &baked.texels);
            let n = baked.texels.len();
            for shots in [n / 4, n, 4 * n] {
                state.shoot(shots);
                let plain = crate::metrics::relative_l1(&state.irradiance(), converged);
                let shown = crate::metrics::relative_l1(&state.display(), converged);
                assert!(
                    shown < plain,
                    "{name}: after {shots} more shots ambient gives {shown}, without {plain}"
                );
            }
        }
    }
}
