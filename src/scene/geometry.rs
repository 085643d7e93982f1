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

/// Parameter intervals of segment `a → b` inside the triangles `corners` (plane coordinates),
/// merged across gaps up to `snap`.
pub(super) fn inside_intervals(
    a: DVec2,
    b: DVec2,
    corners: &[[DVec2; 3]],
    snap: f64,
) -> Vec<[f64; 2]> {
    let length = a.distance(b);
    let mut inside: Vec<[f64; 2]> = corners
        .iter()
        .filter_map(|&c| clip_interval(a, b, c, 1e-9 * snap))
        .collect();
    inside.sort_by(|x, y| x[0].total_cmp(&y[0]));
    let mut merged: Vec<[f64; 2]> = Vec::new();
    for iv in inside {
        match merged.last_mut() {
            Some(m) if iv[0] <= m[1] + snap / length => m[1] = m[1].max(iv[1]),
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
