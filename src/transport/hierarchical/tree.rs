//! The node hierarchy: a quadtree over each page's texel grid, built bottom-up from Morton
//! codes, so every node's texels are one contiguous range of [`Tree::order`].
//!
//! Leaves are the texels themselves (node id = texel id); internal nodes follow, each created
//! after its children, so a parent's id is always larger than its children's. A node whose
//! texels do not share one orientation (a block straddling a chart border, a page root) is a
//! *cluster*: its kernel is sampled at its texels' own normals, never at an average normal.

use glam::{DVec3, Vec3};

use crate::texels::Texels;

/// Nodes whose normals stay within this angle (radians) of their mean are treated as planar.
pub(crate) const PLANAR_SPREAD: f32 = 0.05;

/// Flat node arrays indexed by node id; ids `0..texels` are the texels.
#[derive(Default)]
pub struct Tree {
    /// Texels in Morton order, page by page.
    pub order: Vec<u32>,
    /// Cumulative area along `order` (length `order.len() + 1`), for area-weighted picks.
    pub(crate) prefix_area: Vec<f64>,
    /// Cumulative `A·position` and `A·normal` along `order` (as `prefix_area`), for the
    /// centroid and projected area of any run of a node's texels.
    pub(crate) prefix_moment: Vec<DVec3>,
    pub(crate) prefix_normal: Vec<DVec3>,
    /// Range of `order` covered by each node.
    pub range: Vec<[u32; 2]>,
    /// Parent node, `u32::MAX` for page roots.
    pub(crate) parent: Vec<u32>,
    /// Children of each node: `children[child_start[k]..child_start[k + 1]]` (empty for leaves).
    pub(crate) child_start: Vec<u32>,
    pub(crate) children: Vec<u32>,
    /// `A`: world area (m²).
    pub area: Vec<f32>,
    /// Area-weighted centroid.
    pub(crate) centroid: Vec<Vec3>,
    /// Radius of a sphere around the centroid holding the node's texel footprints.
    pub(crate) radius: Vec<f32>,
    /// Angle (radians) bounding the spread of the node's normals around their mean.
    pub(crate) spread: Vec<f32>,
    /// Mean unit normal (zero when the normals cancel).
    pub(crate) normal: Vec<Vec3>,
    /// Page roots: the top of the hierarchy.
    pub roots: Vec<u32>,
}

impl Tree {
    /// Nodes, texels included.
    pub fn len(&self) -> usize {
        self.area.len()
    }
    /// No nodes.
    #[cfg(feature = "testing")] // public only with `testing`, where clippy asks for it beside `len`
    pub fn is_empty(&self) -> bool {
        self.area.is_empty()
    }

    /// Node `k` has no children (a texel).
    pub fn is_leaf(&self, k: u32) -> bool {
        self.child_start[k as usize] == self.child_start[k as usize + 1]
    }

    pub(crate) fn children(&self, k: u32) -> &[u32] {
        &self.children
            [self.child_start[k as usize] as usize..self.child_start[k as usize + 1] as usize]
    }

    pub(crate) fn is_planar(&self, k: u32) -> bool {
        self.spread[k as usize] < PLANAR_SPREAD
    }

    /// An area-weighted random texel of node `k` for `u ∈ [0,1)`.
    #[inline]
    pub(crate) fn pick_texel(&self, k: u32, u: f32) -> u32 {
        let [lo, hi] = self.range[k as usize];
        let (a, b) = (self.prefix_area[lo as usize], self.prefix_area[hi as usize]);
        let target = a + (b - a) * u as f64;
        let slice = &self.prefix_area[lo as usize + 1..hi as usize];
        let at = lo as usize + slice.partition_point(|&c| c <= target);
        self.order[at.min(hi as usize - 1)]
    }

    /// Stratum `s` of `m` equal runs of node `k`'s texels (in Morton order, so the runs of a
    /// full node are its quadtree sub-blocks): area, centroid and `Σ A_j n_j` (whose length is
    /// below the area where the normals differ). `None` for an empty run.
    #[inline]
    pub(crate) fn stratum(&self, k: u32, s: u32, m: u32) -> Option<(f32, Vec3, Vec3)> {
        let [lo, hi] = self.range[k as usize];
        let len = (hi - lo) as u64;
        let a = lo as usize + (len * s as u64 / m as u64) as usize;
        let b = lo as usize + (len * (s as u64 + 1) / m as u64) as usize;
        if b <= a {
            return None;
        }
        let area = self.prefix_area[b] - self.prefix_area[a];
        if area <= 0.0 {
            return None;
        }
        let centroid = (self.prefix_moment[b] - self.prefix_moment[a]) / area;
        let normal = self.prefix_normal[b] - self.prefix_normal[a];
        Some((area as f32, centroid.as_vec3(), normal.as_vec3()))
    }

    /// The hierarchy over `texels`: a quadtree per page over the texels in Morton order.
    pub fn build(texels: &Texels) -> Tree {
        let n = texels.len();
        let mut t = Tree::default();
        // Leaves: the texels, with their footprint radius.
        for i in 0..n {
            t.area.push(texels.area[i]);
            t.centroid.push(texels.position[i]);
            t.radius
                .push(0.5 * (texels.du[i].length() + texels.dv[i].length()));
            t.spread.push(0.0);
            t.normal.push(texels.normal[i]);
            t.parent.push(u32::MAX);
            t.range.push([0, 0]);
        }

        // Morton order per page.
        let mut keyed: Vec<(u32, u64, u32)> = (0..n as u32)
            .map(|i| {
                let [x, y] = texels.xy[i as usize];
                (texels.page[i as usize], morton(x, y), i)
            })
            .collect();
        keyed.sort_unstable();
        t.order = keyed.iter().map(|k| k.2).collect();
        for (at, &i) in t.order.iter().enumerate() {
            t.range[i as usize] = [at as u32, at as u32 + 1];
        }
        t.prefix_area = std::iter::once(0.0)
            .chain(t.order.iter().scan(0.0f64, |acc, &i| {
                *acc += texels.area[i as usize] as f64;
                Some(*acc)
            }))
            .collect();

        let mut moment = DVec3::ZERO;
        let mut normal = DVec3::ZERO;
        t.prefix_moment = vec![moment];
        t.prefix_normal = vec![normal];
        for &i in &t.order {
            let a = texels.area[i as usize] as f64;
            moment += texels.position[i as usize].as_dvec3() * a;
            normal += texels.normal[i as usize].as_dvec3() * a;
            t.prefix_moment.push(moment);
            t.prefix_normal.push(normal);
        }

        // Group level by level: items are (page, key, node); a parent groups key >> 2.
        let mut items: Vec<(u32, u64, u32)> = keyed;
        let mut grouped_children: Vec<Vec<u32>> = Vec::new();
        loop {
            let mut next = Vec::with_capacity(items.len() / 4 + 1);
            for run in items.chunk_by(|a, b| a.0 == b.0 && a.1 >> 2 == b.1 >> 2) {
                let (page, key) = (run[0].0, run[0].1 >> 2);
                if run.len() == 1 {
                    next.push((page, key, run[0].2)); // no single-child chains
                    continue;
                }
                let id = t.len() as u32;
                let kids: Vec<u32> = run.iter().map(|r| r.2).collect();
                t.push_parent(id, &kids);
                grouped_children.push(kids);
                next.push((page, key, id));
            }
            items = next;
            // Keys shrink every pass, so each page ends as one root.
            if items.windows(2).all(|w| w[0].0 != w[1].0) {
                break;
            }
        }
        t.roots = items.iter().map(|i| i.2).collect();

        // Children lists in CSR form: leaves have none, internal node n + k has group k.
        t.child_start = Vec::with_capacity(t.len() + 1);
        t.child_start.push(0);
        for _ in 0..n {
            t.child_start.push(0);
        }
        for kids in &grouped_children {
            t.children.extend_from_slice(kids);
            t.child_start.push(t.children.len() as u32);
        }
        t
    }

    /// Appends node `id` aggregating `kids` (area-weighted centroid, normal; bounding radius
    /// and normal spread that contain the children's).
    fn push_parent(&mut self, id: u32, kids: &[u32]) {
        let mut a = 0.0f32;
        let mut c = Vec3::ZERO;
        let mut nsum = Vec3::ZERO;
        for &k in kids {
            let (ak, k) = (self.area[k as usize], k as usize);
            a += ak;
            c += self.centroid[k] * ak;
            nsum += self.normal[k] * ak;
            self.parent[k] = id;
        }
        let c = if a > 0.0 {
            c / a
        } else {
            self.centroid[kids[0] as usize]
        };
        let n = nsum.normalize_or_zero();
        let mut radius = 0.0f32;
        let mut spread = 0.0f32;
        for &k in kids {
            let k = k as usize;
            radius = radius.max((self.centroid[k] - c).length() + self.radius[k]);
            let angle = if n == Vec3::ZERO {
                std::f32::consts::PI
            } else {
                n.dot(self.normal[k]).clamp(-1.0, 1.0).acos()
            };
            spread = spread.max(angle + self.spread[k]);
        }
        let lo = self.range[kids[0] as usize][0];
        let hi = kids
            .iter()
            .map(|&k| self.range[k as usize][1])
            .max()
            .unwrap_or(lo);
        self.area.push(a);
        self.centroid.push(c);
        self.radius.push(radius);
        self.spread.push(spread);
        self.normal.push(n);
        self.parent.push(u32::MAX);
        self.range.push([lo, hi]);
        debug_assert_eq!(self.len() - 1, id as usize);
    }
}

/// Interleaves the bits of x and y (Morton / Z order): 2×2 blocks share `code >> 2`.
fn morton(x: u32, y: u32) -> u64 {
    fn spread(v: u32) -> u64 {
        let mut v = v as u64;
        v = (v | (v << 16)) & 0x0000_FFFF_0000_FFFF;
        v = (v | (v << 8)) & 0x00FF_00FF_00FF_00FF;
        v = (v | (v << 4)) & 0x0F0F_0F0F_0F0F_0F0F;
        v = (v | (v << 2)) & 0x3333_3333_3333_3333;
        v = (v | (v << 1)) & 0x5555_5555_5555_5555;
        v
    }
    spread(x) | (spread(y) << 1)
}
