//! Plane frames, segment clipping and a box grid: what the junction split
//! ([`super::junctions`]) and the shadow cuts ([`super::shadow_cuts`]) share.

use glam::{DVec2, DVec3, Vec3};

/// A plane with orthonormal axes: 2D coordinates in it.
#[derive(Clone, Debug)]
pub(super) struct Plane {
    pub(super) origin: DVec3,
    pub(super) axes: [DVec3; 2],
    pub(super) normal: DVec3,
}

impl Plane {
    pub(super) fn to_2d(&self, p: DVec3) -> DVec2 {
        let d = p - self.origin;
        DVec2::new(d.dot(self.axes[0]), d.dot(self.axes[1]))
    }

    pub(super) fn to_3d(&self, p: DVec2) -> DVec3 {
        self.origin + self.axes[0] * p.x + self.axes[1] * p.y
    }
}

/// A patch's triangles in plane coordinates, each with its [`clip_box`]: a segment skips those
/// it cannot meet.
pub(super) struct Triangles2d {
    pub(super) corners: Vec<[DVec2; 3]>,
    boxes: Vec<Option<[DVec2; 2]>>,
    /// The boxed triangles by their boxes' smaller `x`, and the widest box along `x`: a
    /// segment scans only the stretch it can reach.
    by_x: Vec<u32>,
    span: f64,
    /// Triangles without a box, clipped against every segment.
    slivers: Vec<u32>,
}

/// Boxes are widened by this share of the snap distance. [`clip_interval`] widens each edge by
/// `1e-9 · snap`, which moves a corner of angle `θ` out by `1e-9 · snap / sin(θ/2)`: at most
/// `5e-4 · snap` for the corners [`clip_box`] gives a box (`sin θ ≥ 4e-6`).
const BOX_MARGIN: f64 = 1e-3;

/// The box outside which no segment has a piece in triangle `c` by [`clip_interval`] at
/// `1e-9 · snap`; `None` for a sliver, whose widened edges may reach anywhere along it.
pub(super) fn clip_box(c: [DVec2; 3], snap: f64) -> Option<[DVec2; 2]> {
    let sliver = (0..3).any(|k| {
        let (u, v) = (c[(k + 1) % 3] - c[k], c[(k + 2) % 3] - c[k]);
        let scale = u.length() * v.length();
        !(u.perp_dot(v).abs() >= 4e-6 * scale && scale > 0.0)
    });
    let margin = DVec2::splat(BOX_MARGIN * snap);
    (!sliver).then(|| {
        let (lo, hi) = (c[0].min(c[1]).min(c[2]), c[0].max(c[1]).max(c[2]));
        [lo - margin, hi + margin]
    })
}

/// Whether segment `a → b` may meet a triangle of [`clip_box`] `bounds`.
pub(super) fn may_clip(bounds: Option<[DVec2; 2]>, a: DVec2, b: DVec2) -> bool {
    bounds.is_none_or(|[lo, hi]| !(a.max(b).cmplt(lo).any() || a.min(b).cmpgt(hi).any()))
}

impl Triangles2d {
    /// `corners` clipped at `1e-9 · snap` (as [`Triangles2d::inside_intervals`] does).
    pub(super) fn new(corners: Vec<[DVec2; 3]>, snap: f64) -> Self {
        let boxes: Vec<Option<[DVec2; 2]>> = corners.iter().map(|&c| clip_box(c, snap)).collect();
        let (mut by_x, mut slivers) = (Vec::new(), Vec::new());
        let mut span = 0.0f64;
        for (t, b) in boxes.iter().enumerate() {
            match b {
                Some([lo, hi]) => {
                    by_x.push(t as u32);
                    span = span.max(hi.x - lo.x);
                }
                None => slivers.push(t as u32),
            }
        }
        let low = |t: u32| boxes[t as usize].map_or(0.0, |b| b[0].x);
        by_x.sort_by(|&i, &j| low(i).total_cmp(&low(j)));
        Triangles2d {
            corners,
            boxes,
            by_x,
            span,
            slivers,
        }
    }

    /// The box of every corner (empty: `INFINITY..NEG_INFINITY`).
    pub(super) fn bounds(&self) -> [DVec2; 2] {
        let (mut lo, mut hi) = (DVec2::INFINITY, DVec2::NEG_INFINITY);
        for c in self.corners.iter().flatten() {
            (lo, hi) = (lo.min(*c), hi.max(*c));
        }
        [lo, hi]
    }

    /// Parameter intervals of segment `a → b` inside the triangles, merged across gaps up to
    /// `snap` (the snap they were boxed for).
    pub(super) fn inside_intervals(&self, a: DVec2, b: DVec2, snap: f64) -> Vec<[f64; 2]> {
        let length = a.distance(b);
        let low = |t: u32| self.boxes[t as usize].map_or(0.0, |b| b[0].x);
        let start = self
            .by_x
            .partition_point(|&t| low(t) < a.x.min(b.x) - self.span);
        let boxed = (self.by_x[start..].iter())
            .take_while(|&&t| low(t) <= a.x.max(b.x))
            .filter(|&&t| may_clip(self.boxes[t as usize], a, b));
        let inside = (boxed.chain(&self.slivers))
            .filter_map(|&t| clip_interval(a, b, self.corners[t as usize], 1e-9 * snap))
            .collect();
        merge_intervals(inside, snap / length)
    }
}

/// Parameter intervals sorted and merged across gaps up to `gap`; the same whatever order
/// they come in (equal starts merge alike).
fn merge_intervals(mut inside: Vec<[f64; 2]>, gap: f64) -> Vec<[f64; 2]> {
    inside.sort_by(|x, y| x[0].total_cmp(&y[0]));
    let mut merged: Vec<[f64; 2]> = Vec::new();
    for iv in inside {
        match merged.last_mut() {
            Some(m) if iv[0] <= m[1] + gap => m[1] = m[1].max(iv[1]),
            _ => merged.push(iv),
        }
    }
    merged
}

/// The parameter interval of segment `a → b` inside the counter-clockwise triangle `c`
/// (boundary included within `eps`).
// Out of line: inlined into `inside_intervals`' closure (as it was once the junction split ran
// instances in parallel), the furnished interior's split took 15–20% more CPU time.
#[inline(never)]
pub(super) fn clip_interval(a: DVec2, b: DVec2, c: [DVec2; 3], eps: f64) -> Option<[f64; 2]> {
    let d = b - a;
    let (mut s0, mut s1) = (0.0f64, 1.0f64);
    for k in 0..3 {
        let e = c[(k + 1) % 3] - c[k];
        let n = DVec2::new(-e.y, e.x).normalize_or_zero(); // inward for counter-clockwise
        let num = n.dot(a - c[k]) + eps;
        let den = n.dot(d);
        if den.abs() < 1e-300 {
            if num < 0.0 {
                return None;
            }
        } else {
            let s = -num / den;
            if den > 0.0 {
                s0 = s0.max(s);
            } else {
                s1 = s1.min(s);
            }
        }
    }
    (s1 > s0).then_some([s0, s1])
}

/// Items binned by their bounding boxes in a uniform grid (the broad phase).
pub(super) struct BoxGrid {
    lo: DVec3,
    cell: DVec3,
    dims: [usize; 3],
    cells: Vec<Vec<u32>>,
}

impl BoxGrid {
    /// An empty grid of `dims` cells (whole numbers ≥ 1) over `lo .. lo + extent`.
    pub(super) fn new(lo: DVec3, extent: DVec3, dims: DVec3) -> BoxGrid {
        let dims = [dims.x as usize, dims.y as usize, dims.z as usize];
        let cell = extent / DVec3::new(dims[0] as f64, dims[1] as f64, dims[2] as f64);
        BoxGrid {
            lo,
            cell,
            dims,
            cells: vec![Vec::new(); dims[0] * dims[1] * dims[2]],
        }
    }

    /// Adds item `id` with the box `a..b`.
    pub(super) fn insert(&mut self, id: u32, a: DVec3, b: DVec3) {
        for c in self.cells_of(a, b) {
            self.cells[c].push(id);
        }
    }

    fn cells_of(&self, a: DVec3, b: DVec3) -> impl Iterator<Item = usize> + use<> {
        let index = |p: DVec3| {
            let q = ((p - self.lo) / self.cell).floor();
            [q.x, q.y, q.z]
                .iter()
                .zip(self.dims)
                .map(|(&q, d)| (q.max(0.0) as usize).min(d - 1))
                .collect::<Vec<_>>()
        };
        let (i, j) = (index(a), index(b));
        let dims = self.dims;
        (i[2]..=j[2]).flat_map(move |z| {
            let (i, j) = (i.clone(), j.clone());
            (i[1]..=j[1])
                .flat_map(move |y| (i[0]..=j[0]).map(move |x| (z * dims[1] + y) * dims[0] + x))
        })
    }

    /// Items whose boxes may overlap the box `a..b`, ascending.
    pub(super) fn query(&self, a: DVec3, b: DVec3) -> Vec<u32> {
        let mut found: Vec<u32> = self
            .cells_of(a, b)
            .flat_map(|c| self.cells[c].iter().copied())
            .collect();
        found.sort_unstable();
        found.dedup();
        found
    }
}

/// Welded id per vertex: vertices at the same position share one (+0.0 folds −0.0 into 0.0).
pub(super) fn weld(positions: &[Vec3]) -> Vec<u32> {
    let key = |v: usize| (positions[v] + Vec3::ZERO).to_array().map(f32::to_bits);
    let mut order: Vec<u32> = (0..positions.len() as u32).collect();
    order.sort_unstable_by_key(|&v| (key(v as usize), v));
    let mut weld = vec![0u32; positions.len()];
    for (id, same) in order
        .chunk_by(|&a, &b| key(a as usize) == key(b as usize))
        .enumerate()
    {
        for &v in same {
            weld[v as usize] = id as u32;
        }
    }
    weld
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::Rng;

    /// The box and sort by `x` only skip triangles a segment cannot meet: the same intervals
    /// as clipping every triangle, slivers (a zero-length edge, a needle) and segments along
    /// edges among them.
    #[test]
    fn boxed_triangles_give_the_intervals_of_clipping_them_all() {
        let mut rng = Rng::new(7, 0, 0);
        let mut point = || DVec2::new(rng.next_f32() as f64 * 4.0, rng.next_f32() as f64 * 4.0);
        let mut corners: Vec<[DVec2; 3]> = (0..300)
            .map(|_| {
                let a = point();
                let (b, c) = (a + (point() - 2.0) * 0.2, a + (point() - 2.0) * 0.2);
                // Counter-clockwise, as patches give them.
                if (b - a).perp_dot(c - a) >= 0.0 {
                    [a, b, c]
                } else {
                    [a, c, b]
                }
            })
            .collect();
        let a = point();
        corners.push([a, a, a + DVec2::X]); // a zero-length edge
        corners.push([a, a + DVec2::X, a + DVec2::new(0.5, 1e-9)]); // a needle
        let snap = 1e-3;
        let boxed = Triangles2d::new(corners.clone(), snap);
        // Every triangle clipped, in list order.
        let brute = |a: DVec2, b: DVec2| {
            let inside = (corners.iter())
                .filter_map(|&c| clip_interval(a, b, c, 1e-9 * snap))
                .collect();
            merge_intervals(inside, snap / a.distance(b))
        };
        let mut met = 0;
        for k in 0..2000 {
            let (a, b) = match k % 3 {
                // Along a triangle's edge, a little beyond its ends.
                0 => {
                    let c = corners[k % corners.len()];
                    (c[0].lerp(c[1], -0.1), c[0].lerp(c[1], 1.1))
                }
                _ => {
                    let a = point();
                    (a, a + (point() - 2.0) * 0.5)
                }
            };
            let expected = brute(a, b);
            met += usize::from(!expected.is_empty());
            assert_eq!(
                boxed.inside_intervals(a, b, snap),
                expected,
                "segment {a} → {b}"
            );
        }
        assert!(met > 500, "only {met} segments met a triangle");
    }
}
