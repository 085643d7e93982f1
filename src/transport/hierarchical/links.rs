//! Link refinement: which node pairs exchange light, and their form factors.
//!
//! A candidate link (receiver `p` ← source `q`) is accepted when its transfer estimate
//! `F_pq · B_q · A_p` (W, the BF oracle) is at most `ε`, or when neither node can be split;
//! otherwise the larger node is split and its children are linked instead. Pairs whose bounding
//! spheres overlap (near field, and a node with itself) are always split while possible.
//!
//! `F_pq` averages, over `SAMPLES` area-stratified receiver points `x`, the form factor from
//! `x` to `q`: Lambert's exact contour integral over the source texel's parallelogram when `q`
//! is a texel, else the point-to-disk kernel `A_q cosθ_x cosθ_y / (π r² + A_q/S)` towards an
//! area-stratified point `y` of `q`, with the normals of the texels the points lie on (so
//! clusters of non-coplanar texels need no average normal). Each sample is weighted by one
//! shadow ray from `x` to a point of `q`. The oracle uses the unoccluded estimate, and for
//! clusters the cosine-free bound `A_q / (π d_min² + A_q)`; shadow rays are cast only for
//! accepted links.

use std::f32::consts::PI;

use glam::{Vec2, Vec3};
use rayon::prelude::*;

use super::tree::Tree;
use crate::sampling::Rng;
use crate::scene::Scene;
use crate::texels::Texels;
use crate::trace::Tracer;
use crate::transport::all_pairs;

/// Kernel samples per link (no rays: cheap), on a 4×4 grid of a texel or area strata of a node.
pub(crate) const KERNEL_SAMPLES: u32 = 16;
/// Shadow rays per accepted link.
pub(crate) const SAMPLES: u32 = 4;
/// Pairs closer than this many times the sum of their radii are near field: split while
/// possible (the kernel then varies little over either node, so few samples suffice).
pub(crate) const NEAR: f32 = 2.0;
/// Height above a node's plane (in units of the pair's summed radii) below which the other
/// node counts as in the plane: it receives at most a cosine of about this much.
const COPLANAR: f32 = 1e-3;
/// Pairs per parallel work item.
const CHUNK: usize = 256;
/// Random-stream purpose of link sampling.
const PURPOSE: u64 = 0x4852_4c4b;

/// Links in compressed rows by receiver node: row `p` is `source[start[p]..start[p+1]]`.
#[derive(Default)]
pub struct Links {
    /// Where each receiver node's row starts in `source` and `f` (one more than the nodes).
    pub start: Vec<u32>,
    /// Source node of each link.
    pub source: Vec<u32>,
    /// Form factor of each link (visibility included).
    pub f: Vec<f32>,
    /// Visible fraction of each link's unoccluded form factor (what its shadow rays saw).
    pub(crate) visible: Vec<f32>,
    /// Shadow rays cast.
    pub rays: u64,
}

impl Links {
    /// Links held.
    pub fn len(&self) -> usize {
        self.source.len()
    }
    /// No links.
    #[cfg(feature = "testing")] // public only with `testing`, where clippy asks for it beside `len`
    pub fn is_empty(&self) -> bool {
        self.source.is_empty()
    }
}

/// What refinement reads.
pub struct Refiner<'a> {
    /// The texels the tree is built on.
    pub texels: &'a Texels,
    /// The BVH the shadow rays are cast against.
    pub tracer: &'a Tracer,
    /// The hierarchy over the texels.
    pub tree: &'a Tree,
    /// Every texel's footprint polygon.
    pub footprints: &'a [Footprint],
    /// Radiosity of each node used by the oracle (W/m², largest channel).
    pub b: &'a [f32],
    /// Oracle threshold ε (W).
    pub epsilon: f32,
    /// Seed of the random streams.
    pub seed: u64,
}

/// Output of one chunk of candidate pairs.
#[derive(Default)]
struct Chunk {
    links: Vec<(u32, u32, f32, f32)>,
    next: Vec<(u32, u32)>,
    rays: u64,
}

impl Refiner<'_> {
    /// Refines from every pair of page roots down, breadth first (each round in parallel,
    /// collected in order, so the links do not depend on the thread count).
    pub fn refine(&self, aborted: &dyn Fn() -> bool) -> Option<Links> {
        let roots = &self.tree.roots;
        let mut frontier: Vec<(u32, u32)> = roots
            .iter()
            .flat_map(|&p| roots.iter().map(move |&q| (p, q)))
            .collect();
        let mut accepted: Vec<(u32, u32, f32, f32)> = Vec::new();
        let mut rays = 0;
        while !frontier.is_empty() {
            if aborted() {
                return None;
            }
            let chunks: Vec<Chunk> = frontier
                .par_chunks(CHUNK)
                .map(|pairs| {
                    let mut out = Chunk::default();
                    for &(p, q) in pairs {
                        self.visit(p, q, &mut out);
                    }
                    out
                })
                .collect();
            frontier = Vec::with_capacity(chunks.iter().map(|c| c.next.len()).sum());
            for c in chunks {
                accepted.extend(c.links);
                frontier.extend(c.next);
                rays += c.rays;
            }
        }
        accepted.par_sort_unstable_by_key(|&(p, q, _, _)| (p, q));
        let mut links = Links {
            start: vec![0; self.tree.len() + 1],
            source: accepted.iter().map(|l| l.1).collect(),
            f: accepted.iter().map(|l| l.2).collect(),
            visible: accepted.iter().map(|l| l.3).collect(),
            rays,
        };
        for &(p, _, _, _) in &accepted {
            links.start[p as usize + 1] += 1;
        }
        for k in 0..self.tree.len() {
            links.start[k + 1] += links.start[k];
        }
        Some(links)
    }

    /// Accepts the link p ← q, splits it, or drops it (no light can pass).
    fn visit(&self, p: u32, q: u32, out: &mut Chunk) {
        let t = self.tree;
        let (pi, qi) = (p as usize, q as usize);
        if p == q && t.is_leaf(p) {
            return; // a texel does not see itself
        }
        let d = t.centroid[qi] - t.centroid[pi];
        let dist = d.length();
        let reach = t.radius[pi] + t.radius[qi];
        if t.is_planar(p) && t.is_planar(q) && p != q {
            // Every point of q on or behind p's plane, or p on or behind q's front: no
            // exchange. Points of a planar node lie within `r·sin(spread)` of its plane, and
            // the other node's points within `r·(sin∠(n_p, n_q) + sin(spread))` of a plane
            // through its centroid parallel to it; so coplanar blocks of one face (no light
            // between them) are culled here instead of being split down to texel pairs in the
            // near field, each pair estimated only to find zero.
            let (np, nq) = (t.normal[pi], t.normal[qi]);
            let tilt = np.cross(nq).length();
            let (sp, sq) = (t.spread[pi].sin(), t.spread[qi].sin());
            let (rp, rq) = (t.radius[pi], t.radius[qi]);
            let tolerance = COPLANAR * reach;
            if np.dot(d) + rp * sp + rq * (tilt + sq) <= tolerance
                || nq.dot(-d) + rq * sq + rp * (tilt + sp) <= tolerance
            {
                return;
            }
        }
        let (split_p, split_q) = (!t.is_leaf(p), !t.is_leaf(q));
        let near = p == q || dist < NEAR * reach;
        let mut rng = Rng::new(self.seed, ((p as u64) << 32) | q as u64, PURPOSE);
        let mut x = [Vec3::ZERO; KERNEL_SAMPLES as usize];
        let mut y = [Vec3::ZERO; KERNEL_SAMPLES as usize];
        let mut f = [0.0f32; KERNEL_SAMPLES as usize];
        if !(near && (split_p || split_q)) {
            self.estimate(p, q, &mut rng, &mut x, &mut y, &mut f);
            let f_est = f.iter().sum::<f32>() / KERNEL_SAMPLES as f32;
            let f_oracle = if t.is_planar(p) && t.is_planar(q) {
                f_est
            } else {
                let d_min = (dist - reach).max(0.0);
                let a_q = t.area[qi];
                f_est.max(a_q / (PI * d_min * d_min + a_q))
            };
            let error = f_oracle * self.b[qi] * t.area[pi];
            if error <= self.epsilon || !(split_p || split_q) {
                if f_est <= 0.0 {
                    return;
                }
                // Visibility from SAMPLES shadow rays, spread over the strata (5 is coprime
                // to 16, so the order visits every row and column of a 4×4 grid early).
                let (mut seen, mut total, mut cast) = (0.0f32, 0.0f32, 0);
                for k in 0..KERNEL_SAMPLES as usize {
                    let s = k * 5 % KERNEL_SAMPLES as usize;
                    if f[s] <= 0.0 {
                        continue;
                    }
                    total += f[s];
                    if !self.tracer.occluded(x[s], y[s]) {
                        seen += f[s];
                    }
                    cast += 1;
                    if cast == SAMPLES {
                        break;
                    }
                }
                out.rays += cast as u64;
                if seen > 0.0 {
                    let visible = seen / total;
                    out.links.push((p, q, (f_est * visible).min(1.0), visible));
                }
                return;
            }
        }
        self.split(p, q, out);
    }

    /// Split: a node linked with itself pairs up its children; else the larger node.
    fn split(&self, p: u32, q: u32, out: &mut Chunk) {
        let t = self.tree;
        let (pi, qi) = (p as usize, q as usize);
        let (split_p, split_q) = (!t.is_leaf(p), !t.is_leaf(q));
        if p == q {
            for &a in t.children(p) {
                for &b in t.children(p) {
                    out.next.push((a, b));
                }
            }
        } else if split_p && (!split_q || t.area[pi] >= t.area[qi]) {
            out.next.extend(t.children(p).iter().map(|&a| (a, q)));
        } else {
            out.next.extend(t.children(q).iter().map(|&b| (p, b)));
        }
    }

    /// Per-texel correction of the pushed irradiance: `s_i = R*_i / R_i`, where
    /// `R_i = Σ_{a ∋ i} Σ_{links a←q} F_aq` is the row sum texel `i` receives through the
    /// hierarchy (its ancestors' links included) and `R*_i` the same sum with each link's form
    /// factor evaluated at `i`'s own centre (times the link's visible fraction).
    ///
    /// A link's `F_aq` is the mean over the receiver node; pushed down unchanged it is wrong for
    /// the texels near the node's edges (a floor texel next to a wall sees more of the wall
    /// than the block it belongs to). Those errors are systematic, not noise: in the furnace
    /// they left row sums off by up to ±14% per texel. Scaling by `s_i` makes every texel's row
    /// sum its own, so a uniform radiosity (the furnace) is exact per texel; the direction of
    /// the light within the row stays the node's. No rays: kernels only, one pass over the
    /// links each texel inherits.
    pub fn row_scale(&self, links: &Links) -> Vec<f32> {
        let (t, texels) = (self.tree, self.texels);
        (0..texels.len())
            .into_par_iter()
            .with_min_len(64)
            .map(|i| {
                let x = footprint_point(texels, self.tracer, i, Vec2::splat(0.5));
                let n = texels.normal[i];
                let (mut r, mut r_star) = (0.0f64, 0.0f64);
                let mut a = i as u32;
                while a != u32::MAX {
                    let e = links.start[a as usize] as usize..links.start[a as usize + 1] as usize;
                    for ((&q, &f), &v) in links.source[e.clone()]
                        .iter()
                        .zip(&links.f[e.clone()])
                        .zip(&links.visible[e])
                    {
                        r += f as f64;
                        r_star += if a as usize == i {
                            f as f64
                        } else {
                            (self.point_form_factor(x, n, i as u32, q) * v).min(1.0) as f64
                        };
                    }
                    a = t.parent[a as usize];
                }
                if r > 0.0 && r_star > 0.0 {
                    (r_star / r).clamp(0.25, 4.0) as f32
                } else {
                    1.0
                }
            })
            .collect()
    }

    /// Unoccluded form factor from the point `x` (normal `n`, on texel `i`) to node `q`:
    /// Lambert's contour integral for a texel, else the disk-bounded point kernel summed over
    /// `KERNEL_SAMPLES` runs of `q`'s texels (its quadtree sub-blocks), each at its centroid
    /// with its projected area `−d̂·Σ A_j n_j` (exact in the far field, any normals).
    fn point_form_factor(&self, x: Vec3, n: Vec3, i: u32, q: u32) -> f32 {
        let (t, texels) = (self.tree, self.texels);
        if t.is_leaf(q) {
            if q == i {
                return 0.0;
            }
            return texel_form_factor(texels, &self.footprints[q as usize], x, n, q as usize);
        }
        let mut sum = 0.0f32;
        for s in 0..KERNEL_SAMPLES {
            let Some((a, c, normal)) = t.stratum(q, s, KERNEL_SAMPLES) else {
                continue;
            };
            let d = c - x;
            let r2 = d.length_squared();
            let r = r2.sqrt();
            if r <= 0.0 {
                continue;
            }
            let cos_x = n.dot(d) / r;
            let projected = -normal.dot(d) / r;
            if cos_x > 0.0 && projected > 0.0 {
                sum += cos_x * projected / (PI * r2 + a);
            }
        }
        sum
    }

    /// Unoccluded per-sample form factors `f[s]` from receiver points `x[s]` of p, with source
    /// points `y[s]` of q for the shadow rays.
    fn estimate(
        &self,
        p: u32,
        q: u32,
        rng: &mut Rng,
        x: &mut [Vec3],
        y: &mut [Vec3],
        f: &mut [f32],
    ) {
        let (t, texels) = (self.tree, self.texels);
        let m = KERNEL_SAMPLES as f32;
        let a_q = t.area[q as usize];
        for s in 0..KERNEL_SAMPLES as usize {
            let stratum = (s as f32 + rng.next_f32()) / m;
            let cell = Vec2::new((s % 4) as f32, (s / 4) as f32);
            let (i, u) = if t.is_leaf(p) {
                (p, (cell + rng.next_vec2()) * 0.25) // 4×4 strata of the receiver texel
            } else {
                (t.pick_texel(p, stratum), rng.next_vec2())
            };
            let n_x = texels.normal[i as usize];
            x[s] = footprint_point(texels, self.tracer, i as usize, u);
            if t.is_leaf(q) {
                // Cell midpoints, not the jittered ray origins: the kernel to an adjacent
                // texel is singular at the shared edge, and jitter left ±10% noise.
                let x_mid = if t.is_leaf(p) {
                    footprint_point(texels, self.tracer, i as usize, (cell + 0.5) * 0.25)
                } else {
                    x[s]
                };
                f[s] =
                    texel_form_factor(texels, &self.footprints[q as usize], x_mid, n_x, q as usize);
                y[s] = footprint_point(texels, self.tracer, q as usize, rng.next_vec2());
            } else {
                let j = t.pick_texel(q, (s as f32 + rng.next_f32()) / m) as usize;
                y[s] = footprint_point(texels, self.tracer, j, rng.next_vec2());
                let d = y[s] - x[s];
                let r2 = d.length_squared();
                let r = r2.sqrt();
                let cos_x = n_x.dot(d) / r;
                let cos_y = -texels.normal[j].dot(d) / r;
                f[s] = if r > 0.0 && cos_x > 0.0 && cos_y > 0.0 {
                    a_q * cos_x * cos_y / (PI * r2 + a_q / m)
                } else {
                    0.0
                };
            }
        }
    }
}

/// A point of texel `i`'s footprint for `u ∈ [0,1)²` ([`Texels::footprint_point`]: partly
/// covered texels shrunk around their covered centroid, moved samples within their jitter
/// cell), lifted off the surface by the ray epsilon. The same points the Monte Carlo method
/// and the reference start from: a copy that ignored the jitter put receivers of texels moved
/// away from a block back under it (Cornell box 3.05% → 3.61% once divided texels moved).
#[inline]
pub fn footprint_point(t: &Texels, tracer: &Tracer, i: usize, u: Vec2) -> Vec3 {
    t.footprint_point(i, u) + t.normal[i] * tracer.epsilon
}

/// A texel's footprint polygon (world space): the texel square, cut for a partly covered
/// border texel by a line perpendicular to the offset of its covered centroid, placed so the
/// polygon has the covered area (exact for the common strip along a chart edge).
#[derive(Clone, Copy, Default)]
pub struct Footprint {
    v: [Vec3; 5],
    len: u8,
}

/// The footprint of every texel.
pub fn footprints(scene: &Scene, t: &Texels) -> Vec<Footprint> {
    (0..t.len())
        .into_par_iter()
        .with_min_len(1024)
        .map(|i| footprint(scene, t, i))
        .collect()
}

/// Texel `i`'s covered rectangle ([`all_pairs::Footprint::of`]: exact for a border strip or a
/// corner of an axis-aligned chart), scaled to the covered area. (Cutting the square by one
/// line across its centroid's offset instead turned a chart corner's quarter texel into a
/// wedge: the texels at a box's corners saw gaps there and summed to 0.95 in the furnace.)
fn footprint(scene: &Scene, t: &Texels, i: usize) -> Footprint {
    let r = all_pairs::Footprint::of(scene, t, i).with_area(t.area[i]);
    let (a, b) = (r.du * 0.5, r.dv * 0.5);
    let c = r.centre;
    Footprint {
        v: [c - a - b, c + a - b, c + a + b, c - a + b, Vec3::ZERO],
        len: 4,
    }
}

/// The part of `poly` where `n·(y − o) ≥ 0` (Sutherland–Hodgman; a quad gains at most one
/// vertex).
#[inline]
fn clip(poly: &Footprint, n: Vec3, o: Vec3) -> Footprint {
    let mut out = Footprint::default();
    let len = poly.len as usize;
    for k in 0..len {
        let (p0, p1) = (poly.v[k], poly.v[(k + 1) % len]);
        let (h0, h1) = (n.dot(p0 - o), n.dot(p1 - o));
        if h0 >= 0.0 && (out.len as usize) < 5 {
            out.v[out.len as usize] = p0;
            out.len += 1;
        }
        if (h0 >= 0.0) != (h1 >= 0.0) && (out.len as usize) < 5 {
            out.v[out.len as usize] = p0 + (p1 - p0) * (h0 / (h0 - h1));
            out.len += 1;
        }
    }
    out
}

#[cfg(test)]
fn polygon_area(poly: &Footprint) -> f32 {
    let len = poly.len as usize;
    let mut sum = Vec3::ZERO;
    for k in 1..len.saturating_sub(1) {
        sum += (poly.v[k] - poly.v[0]).cross(poly.v[k + 1] - poly.v[0]);
    }
    0.5 * sum.length()
}

/// Form factor from the point `x` (unit normal `n`) to texel `j`'s footprint polygon:
/// Lambert's contour integral `F = (1/2π) Σ_k γ_k n·(v_k × v_{k+1})/|v_k × v_{k+1}|` over
/// the part of the polygon above `x`'s tangent plane.
pub fn texel_form_factor(t: &Texels, footprint: &Footprint, x: Vec3, n: Vec3, j: usize) -> f32 {
    if t.normal[j].dot(x - t.position[j]) <= 0.0 {
        return 0.0; // x is behind the source's front
    }
    let poly = clip(footprint, n, x);
    let len = poly.len as usize;
    if len < 3 {
        return 0.0;
    }
    let mut sum = 0.0f32;
    for k in 0..len {
        let v0 = (poly.v[k] - x).normalize_or_zero();
        let v1 = (poly.v[(k + 1) % len] - x).normalize_or_zero();
        let cross = v0.cross(v1);
        let sin = cross.length();
        if sin > 1e-12 {
            sum += sin.atan2(v0.dot(v1)) * n.dot(cross) / sin;
        }
    }
    (sum.abs() / (2.0 * PI)).min(1.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::BakeConfig;

    /// In a closed box the exact form factors from any point to all texels sum to 1: checks
    /// the footprints of partly covered border texels and the contour integral together.
    #[test]
    fn texel_form_factors_sum_to_one_in_a_closed_box() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/fixtures/furnace.gltf");
        let (scene, source) = crate::scene::load(std::path::Path::new(path)).unwrap();
        let atlas = crate::atlas::build(&scene, &source, &BakeConfig::draft().atlas).unwrap();
        let t = crate::texels::build(&scene, &atlas).unwrap();
        let feet = footprints(&scene, &t);
        for (i, foot) in feet.iter().enumerate() {
            let area = polygon_area(foot);
            assert!(
                (area - t.area[i]).abs() < 1e-3 * t.area[i] + 1e-7,
                "texel {i}: {area}"
            );
        }
        let mut worst = 0.0f32;
        for i in 0..t.len() {
            let x = t.position[i] + t.normal[i] * 1e-4;
            let sum: f32 = (0..t.len())
                .filter(|&j| j != i)
                .map(|j| texel_form_factor(&t, &feet[j], x, t.normal[i], j))
                .sum();
            worst = worst.max((sum - 1.0).abs());
        }
        assert!(worst < 0.05, "worst row sum error {worst}");
    }
}
