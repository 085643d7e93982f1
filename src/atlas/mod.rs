//! Stage 2 — `Atlas`: lightmap UVs for every instance, packed into pages.
//!
//! Either xatlas charts and packs the instances in world-space units (`xatlas.rs`, the only file
//! that touches xatlas-rs), or the input's own `TEXCOORD_1` is reused (`existing.rs`), after
//! checking it is inside \[0,1\] and free of overlaps. With `--instancing share`, a mesh
//! placed by several nodes is unwrapped once and each node gets a rect of a page (`share.rs`).

mod existing;
mod pack;
pub(crate) mod share;
pub(crate) mod slots;
pub(crate) mod xatlas;

pub use existing::Overlaps;
pub use share::{NodeRect, ShareReport, SharedMesh};

use glam::Vec2;

use crate::Result;
use crate::config::{AtlasParams, Instancing, UvMode};
use crate::scene::{Scene, Source};

/// Size of one lightmap page in texels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PageSize {
    /// Texels across.
    pub width: u32,
    /// Texels down.
    pub height: u32,
}

/// Lightmap UV layout of the whole scene.
#[derive(Clone, Debug)]
pub struct Atlas {
    /// Size of each page; `InstanceUv::triangle_page` indexes them.
    pub pages: Vec<PageSize>,
    /// Parallel to [`Scene::instances`].
    pub instances: Vec<InstanceUv>,
    /// Texel density actually used (texels per world unit).
    pub texels_per_unit: f32,
    /// True when the input's `TEXCOORD_1` was reused.
    pub(crate) reused_input_uvs: bool,
    /// Meshes written once, with a page rect per node (`--instancing share`; empty otherwise).
    /// `instances` holds every node's page UVs all the same.
    pub shared: Vec<SharedMesh>,
}

/// The lightmap parameterisation of one instance. Unwrapping splits vertices along chart seams,
/// so an instance gets its own vertex list: atlas vertex `a` copies local source vertex `xref[a]`.
#[derive(Clone, Debug, Default)]
pub struct InstanceUv {
    /// Local source vertex (index into the primitive's attribute accessors) of each atlas vertex.
    pub xref: Vec<u32>,
    /// Lightmap UV of each atlas vertex, in \[0,1\] of its page (glTF convention, v down).
    pub uv: Vec<Vec2>,
    /// One per instance triangle, same order as `Scene::triangles[instance.triangles]`,
    /// as indices into `xref`/`uv`, same winding.
    pub triangles: Vec<[u32; 3]>,
    /// Page of each triangle.
    pub triangle_page: Vec<u32>,
}

impl Atlas {
    /// Lightmap UVs of scene triangle `t` (an index into `Scene::triangles`) and its page.
    pub fn triangle_uv(&self, scene: &Scene, t: u32) -> ([Vec2; 3], u32) {
        let i = scene.triangle_instance[t as usize];
        let inst = &self.instances[i as usize];
        let local = (t - scene.instances[i as usize].triangles.start) as usize;
        let tri = inst.triangles[local];
        (
            [
                inst.uv[tri[0] as usize],
                inst.uv[tri[1] as usize],
                inst.uv[tri[2] as usize],
            ],
            inst.triangle_page[local],
        )
    }

    /// Debug-build consistency check.
    #[cfg(any(debug_assertions, test))]
    pub(crate) fn validate(&self, scene: &Scene) {
        assert_eq!(self.instances.len(), scene.instances.len());
        for (inst, si) in self.instances.iter().zip(&scene.instances) {
            assert_eq!(inst.xref.len(), inst.uv.len());
            assert_eq!(inst.triangles.len(), si.triangles.len());
            assert_eq!(inst.triangle_page.len(), si.triangles.len());
            let nv = si.vertices.end - si.vertices.start;
            assert!(inst.xref.iter().all(|&x| x < nv));
            assert!(
                inst.uv
                    .iter()
                    .all(|uv| uv.is_finite() && uv.min_element() >= 0.0 && uv.max_element() <= 1.0)
            );
            assert!(
                inst.triangle_page
                    .iter()
                    .all(|&p| (p as usize) < self.pages.len())
            );
            assert!(
                inst.triangles
                    .iter()
                    .flatten()
                    .all(|&a| (a as usize) < inst.xref.len())
            );
        }
    }
}

#[cfg(test)]
impl Atlas {
    /// Every number of the layout as bits (pages, vertices, UVs, triangles, pages of triangles):
    /// equal for equal layouts, for the determinism tests.
    pub(crate) fn layout_bits(&self) -> Vec<u32> {
        let mut bits: Vec<u32> = self
            .pages
            .iter()
            .flat_map(|p| [p.width, p.height])
            .collect();
        for inst in &self.instances {
            bits.extend(&inst.xref);
            bits.extend(
                inst.uv
                    .iter()
                    .flat_map(|uv| [uv.x.to_bits(), uv.y.to_bits()]),
            );
            bits.extend(inst.triangles.iter().flatten());
            bits.extend(&inst.triangle_page);
        }
        bits
    }
}

impl InstanceUv {
    /// Each triangle's chart, named by one of its triangles: triangles join across edges whose
    /// two atlas vertices they share.
    pub fn charts(&self) -> Vec<usize> {
        let mut parent: Vec<usize> = (0..self.triangles.len()).collect();
        fn root(parent: &mut [usize], mut i: usize) -> usize {
            while parent[i] != i {
                parent[i] = parent[parent[i]];
                i = parent[i];
            }
            i
        }
        let mut first = std::collections::BTreeMap::new();
        for (t, tri) in self.triangles.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                let other = *first.entry((a.min(b), a.max(b))).or_insert(t);
                let (ra, rb) = (root(&mut parent, t), root(&mut parent, other));
                parent[ra] = rb;
            }
        }
        (0..parent.len()).map(|t| root(&mut parent, t)).collect()
    }

    /// How many charts the instance's triangles form ([`InstanceUv::charts`]).
    pub fn chart_count(&self) -> usize {
        let chart = self.charts();
        (0..chart.len()).filter(|&t| chart[t] == t).count()
    }
}

/// Calls `visit` with the index of every texel of a `size` page that the triangle with page
/// UVs `uv` touches, sampled every quarter texel (for the layout tests).
#[cfg(test)]
pub(crate) fn for_each_touched_texel(uv: [Vec2; 3], size: PageSize, mut visit: impl FnMut(usize)) {
    let texels = Vec2::new(size.width as f32, size.height as f32);
    let [a, b, c] = uv.map(|p| p * texels);
    let steps = ((b - a).length().max((c - a).length()) * 4.0).ceil() as u32 + 1;
    for i in 0..=steps {
        for j in 0..=steps - i {
            let p = a + (b - a) * (i as f32 / steps as f32) + (c - a) * (j as f32 / steps as f32);
            let x = (p.x as u32).min(size.width - 1);
            let y = (p.y as u32).min(size.height - 1);
            visit((y * size.width + x) as usize);
        }
    }
}

/// Smallest page side that holds `texels` texels: a multiple of 4, within [16, `max`].
pub(crate) fn page_side(texels: f32, max: u32) -> u32 {
    let side = if texels.is_finite() {
        texels.max(0.0).min(max as f32).ceil() as u32
    } else {
        max
    };
    side.next_multiple_of(4).clamp(16.min(max), max)
}

/// Per scene instance: [`build`] will share its mesh's UVs with other nodes (`--instancing
/// share` and unwrapping), so the junction split must leave it whole.
pub(crate) fn shared_instances(scene: &Scene, source: &Source, params: &AtlasParams) -> Vec<bool> {
    if params.instancing == Instancing::Share && !reuses_input_uvs(scene, source, params) {
        share::shared_instances(scene)
    } else {
        vec![false; scene.instances.len()]
    }
}

/// [`build`] will reuse the input's `TEXCOORD_1` (so the charts cannot change).
pub(crate) fn reuses_input_uvs(scene: &Scene, source: &Source, params: &AtlasParams) -> bool {
    match params.uv {
        UvMode::Unwrap => false,
        UvMode::Existing => true,
        UvMode::Auto => existing::reuse(scene, source, params).is_ok(),
    }
}

/// An atlas for measuring, not for output (the density pilot's): every instance of one density
/// is charted by smooth patches ([`xatlas`]'s dense path) whatever its triangles' size, which
/// costs a fraction of xatlas' chart growing on curved meshes and gives more, smaller charts.
/// Shared instancing and reused `TEXCOORD_1` are laid out as [`build_with`] does.
pub(crate) fn build_quick(
    scene: &Scene,
    source: &Source,
    params: &AtlasParams,
    progress: &dyn crate::Progress,
) -> Result<Atlas> {
    if params.instancing == Instancing::Duplicate && !reuses_input_uvs(scene, source, params) {
        return xatlas::unwrap_charted(scene, source, params, xatlas::Charting::Quick, progress);
    }
    build_with(scene, source, params, progress)
}

/// Builds the atlas: reuses the input's `TEXCOORD_1` or unwraps, as `params.uv` says.
pub fn build(scene: &Scene, source: &Source, params: &AtlasParams) -> Result<Atlas> {
    build_with(scene, source, params, &crate::NoProgress)
}

/// [`build`], telling `progress` how the unwrapping goes (stage "atlas").
pub(crate) fn build_with(
    scene: &Scene,
    source: &Source,
    params: &AtlasParams,
    progress: &dyn crate::Progress,
) -> Result<Atlas> {
    let unwrap = || match params.instancing {
        Instancing::Duplicate => xatlas::unwrap_with(scene, source, params, progress),
        Instancing::Share => share::unwrap(scene, source, params),
    };
    let atlas = match params.uv {
        UvMode::Unwrap => unwrap()?,
        UvMode::Existing => existing::reuse(scene, source, params)?,
        UvMode::Auto => match existing::reuse(scene, source, params) {
            Ok(atlas) => atlas,
            Err(_) => unwrap()?,
        },
    };
    #[cfg(debug_assertions)]
    atlas.validate(scene);
    Ok(atlas)
}
