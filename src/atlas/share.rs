//! Shared instancing (`--instancing share`): a mesh placed by several nodes is unwrapped once
//! and written once; each node gets its own rectangle of a page, `uv_page = uv * scale + offset`.
//!
//! Everything after the atlas stays per scene instance: every node's [`InstanceUv`] holds its
//! page UVs, computed from the one base layout in f32 exactly as a shader computes them
//! (`base * scale + offset`, a multiply then an add), so what the bake stores at a texel is what
//! an engine looks up there. What changes is the layout:
//!
//! - A *block* is every scene instance one node places for one mesh (each primitive, and the
//!   back face of a double-sided one: the written mesh holds them all, and a node has one rect).
//!   A mesh is *shared* when two or more nodes place it and their blocks match primitive for
//!   primitive (same triangles kept by the loader, same vertices, no junction split); otherwise
//!   it is duplicated as in [`Instancing::Duplicate`](crate::config::Instancing).
//! - The first node's block is unwrapped by xatlas (as its own small scene) at the group's
//!   lowest effective density, so each copy is that layout scaled by 1 or more and the charts
//!   stay at least `padding` texels apart in every copy. A node's effective density is its
//!   densest instance's texels per unit times its size relative to the first node (the square
//!   root of the block's world-area ratio; a non-uniformly scaled copy gets the mean).
//! - When the base layout does not fit one page with room for padding, its density is lowered
//!   (a quarter at a time) until it does, and when a copy's rect would not fit a page, that
//!   copy's scale is capped; both are counted in [`ShareReport`].
//! - Unshared meshes are unwrapped and packed by xatlas as in duplicate mode, onto the first
//!   pages; the rects are shelf-packed onto pages of their own after them (tallest first), each
//!   with `padding` empty texels above and left of it (the base layout holds the padding right
//!   of and below its charts), each page trimmed to what it uses.

use std::collections::BTreeMap;

use glam::Vec2;

use super::pack::shelf_pack;
use super::{Atlas, InstanceUv, PageSize, page_side, xatlas};
use crate::config::AtlasParams;
use crate::scene::{Scene, Source};
use crate::{Error, Result};

/// A mesh written once: its base layout and each node's rect.
#[derive(Clone, Debug)]
pub struct SharedMesh {
    /// glTF mesh index.
    pub(crate) mesh: u32,
    /// The scene instances of the first node, in scene order, and their base layout: UVs in
    /// \[0,1\] of the base layout, `triangle_page` all 0. This is the written `TEXCOORD_1`.
    pub(crate) base: Vec<(u32, InstanceUv)>,
    /// Base layout size in texels (the charts plus `padding` right of and below them).
    pub(crate) base_size: Vec2,
    /// Texels per world unit of the base layout (on the first node's geometry).
    pub texels_per_unit: f32,
    /// The density was lowered from the group's lowest effective density to fit a page.
    pub(crate) lowered: bool,
    /// Each node placing the mesh, in node order.
    pub nodes: Vec<NodeRect>,
}

/// One node's rectangle: `uv_page = uv_base * scale + offset`, on `page`.
#[derive(Clone, Debug, PartialEq)]
pub struct NodeRect {
    pub(crate) node: u32,
    pub(crate) page: u32,
    pub(crate) scale: Vec2,
    pub(crate) offset: Vec2,
    /// Its scene instances, parallel to [`SharedMesh::base`].
    pub(crate) instances: Vec<u32>,
    /// Its scale was capped so the rect fits a page (its density is lower than asked).
    pub(crate) capped: bool,
}

/// What shared instancing did, for the bake's summary.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ShareReport {
    /// Meshes written once, and the nodes placing them.
    pub(crate) meshes: usize,
    pub(crate) nodes: usize,
    /// Base layouts whose density was lowered to fit a page, and copies capped to fit one.
    pub(crate) lowered: usize,
    pub(crate) capped: usize,
}

impl ShareReport {
    pub(crate) fn of(atlas: &Atlas) -> Option<ShareReport> {
        (!atlas.shared.is_empty()).then(|| ShareReport {
            meshes: atlas.shared.len(),
            nodes: atlas.shared.iter().map(|s| s.nodes.len()).sum(),
            lowered: atlas.shared.iter().filter(|s| s.lowered).count(),
            capped: (atlas.shared.iter().flat_map(|s| &s.nodes))
                .filter(|n| n.capped)
                .count(),
        })
    }

    /// One phrase for the bake's summary line.
    pub fn brief(&self) -> String {
        let mut s = format!(
            "instancing: {} mesh(es) shared by {} nodes (one rect each)",
            self.meshes, self.nodes
        );
        if self.lowered > 0 {
            s += &format!(
                ", {} base layout(s) at a lower density to fit a page",
                self.lowered
            );
        }
        if self.capped > 0 {
            s += &format!(", {} copies scaled down to fit a page", self.capped);
        }
        s
    }
}

/// Each node placing a mesh and its block: the node's scene instances of the mesh, in scene
/// order.
type Blocks = Vec<(u32, Vec<u32>)>;

/// The meshes that [`unwrap`] shares: per mesh, each node's block, the first node first. Only
/// meshes whose blocks all match the first one instance for instance.
pub(crate) fn shared_groups(scene: &Scene) -> Vec<(u32, Blocks)> {
    let mut blocks: BTreeMap<u32, BTreeMap<u32, Vec<u32>>> = BTreeMap::new();
    for (i, inst) in scene.instances.iter().enumerate() {
        blocks
            .entry(inst.mesh)
            .or_default()
            .entry(inst.node)
            .or_default()
            .push(i as u32);
    }
    blocks
        .into_iter()
        .filter(|(_, nodes)| nodes.len() >= 2)
        .map(|(mesh, nodes)| (mesh, nodes.into_iter().collect::<Vec<_>>()))
        .filter(|(_, nodes)| {
            let first = &nodes[0].1;
            nodes
                .iter()
                .all(|(_, block)| blocks_match(scene, first, block))
        })
        .collect()
}

/// Instances of meshes [`unwrap`] shares: the junction split leaves them whole (a shared mesh
/// cannot carry one node's cuts).
pub(crate) fn shared_instances(scene: &Scene) -> Vec<bool> {
    let mut shared = vec![false; scene.instances.len()];
    for (_, nodes) in shared_groups(scene) {
        for (_, block) in nodes {
            block.iter().for_each(|&i| shared[i as usize] = true);
        }
    }
    shared
}

/// Whether `block` has the same primitives, kept triangles and vertices as `first`, unsplit, so
/// one set of UVs serves both.
fn blocks_match(scene: &Scene, first: &[u32], block: &[u32]) -> bool {
    first.len() == block.len()
        && first.iter().zip(block).all(|(&a, &b)| {
            let (a, b) = (&scene.instances[a as usize], &scene.instances[b as usize]);
            a.primitive == b.primitive
                && a.back_of.is_some() == b.back_of.is_some()
                && a.source_triangle == b.source_triangle
                && a.vertices.len() == b.vertices.len()
                && a.split.blends.is_empty()
                && b.split.blends.is_empty()
                && a.split.sides.is_empty()
                && b.split.sides.is_empty()
                && (0..a.triangles.len()).all(|t| corner_order(scene, a, b, t).is_some())
        })
}

/// For triangle `t` of two matching instances: where each of `b`'s corners is among `a`'s
/// (the winding is reversed under a mirroring node).
fn corner_order(
    scene: &Scene,
    a: &crate::scene::Instance,
    b: &crate::scene::Instance,
    t: usize,
) -> Option<[usize; 3]> {
    let local = |inst: &crate::scene::Instance| {
        scene.triangles[inst.triangles.start as usize + t].map(|v| v - inst.vertices.start)
    };
    let (la, lb) = (local(a), local(b));
    let mut order = [0; 3];
    for (c, v) in lb.iter().enumerate() {
        order[c] = la.iter().position(|w| w == v)?;
    }
    (order[0] != order[1] && order[1] != order[2] && order[0] != order[2]).then_some(order)
}

/// The scene of `instances` alone (vertex and triangle ranges renumbered; no textures, lights
/// or cameras), for unwrapping part of a scene.
fn sub_scene(scene: &Scene, instances: &[u32]) -> Scene {
    let mut sub = Scene {
        materials: scene.materials.clone(),
        ..Scene::default()
    };
    let new_index: BTreeMap<u32, u32> = (instances.iter().enumerate())
        .map(|(k, &i)| (i, k as u32))
        .collect();
    for (k, &i) in instances.iter().enumerate() {
        let mut inst = scene.instances[i as usize].clone();
        let vertices = inst.vertices.start as usize..inst.vertices.end as usize;
        let first_vertex = sub.positions.len() as u32;
        let first_triangle = sub.triangles.len() as u32;
        sub.positions
            .extend_from_slice(&scene.positions[vertices.clone()]);
        sub.normals
            .extend_from_slice(&scene.normals[vertices.clone()]);
        sub.uv0.extend_from_slice(&scene.uv0[vertices.clone()]);
        sub.uv1.extend_from_slice(&scene.uv1[vertices]);
        let triangles = inst.triangles.start as usize..inst.triangles.end as usize;
        sub.triangles.extend(
            scene.triangles[triangles]
                .iter()
                .map(|t| t.map(|v| v - inst.vertices.start + first_vertex)),
        );
        inst.vertices = first_vertex..sub.positions.len() as u32;
        inst.triangles = first_triangle..sub.triangles.len() as u32;
        sub.triangle_instance.resize(sub.triangles.len(), k as u32);
        inst.back_of = inst.back_of.and_then(|b| new_index.get(&b).copied());
        inst.back = inst.back.and_then(|b| new_index.get(&b).copied());
        sub.instances.push(inst);
    }
    sub
}

/// World-space area of scene instance `i`.
fn instance_area(scene: &Scene, i: u32) -> f64 {
    let inst = &scene.instances[i as usize];
    scene.triangles[inst.triangles.start as usize..inst.triangles.end as usize]
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|v| scene.positions[v as usize].as_dvec3());
            0.5 * (b - a).cross(c - a).length()
        })
        .sum()
}

/// How many times the base layout's density may be lowered (by a quarter each) before giving up.
const MAX_LOWERINGS: u32 = 48;

/// Unwraps `scene` with shared meshes (see the module docs); without any, as duplicate mode does.
pub(crate) fn unwrap(scene: &Scene, source: &Source, params: &AtlasParams) -> Result<Atlas> {
    let groups = shared_groups(scene);
    if groups.is_empty() {
        return xatlas::unwrap(scene, source, params);
    }
    let (mut instances, mut pages) = unwrap_unshared(scene, source, params, &groups)?;
    let mut shared = (groups.iter())
        .map(|(mesh, nodes)| shared_mesh(scene, source, params, *mesh, nodes))
        .collect::<Result<Vec<_>>>()?;
    place_rects(&mut shared, &mut pages, params);
    for s in &shared {
        write_node_uvs(scene, s, &mut instances);
    }
    Ok(Atlas {
        pages,
        instances,
        texels_per_unit: params.texels_per_unit,
        reused_input_uvs: false,
        shared,
    })
}

/// Texels per unit asked for scene instance `i`.
fn instance_density(params: &AtlasParams, i: u32) -> f32 {
    params.texels_per_unit
        * params
            .instance_density
            .get(i as usize)
            .copied()
            .unwrap_or(1.0)
}

/// The instances outside every group, unwrapped by xatlas as in duplicate mode: every scene
/// instance's UVs (those of the groups' still empty) and the pages they use, the first pages.
fn unwrap_unshared(
    scene: &Scene,
    source: &Source,
    params: &AtlasParams,
    groups: &[(u32, Blocks)],
) -> Result<(Vec<InstanceUv>, Vec<PageSize>)> {
    let mut in_group = vec![false; scene.instances.len()];
    for (_, nodes) in groups {
        for (_, block) in nodes {
            block.iter().for_each(|&i| in_group[i as usize] = true);
        }
    }
    let unshared: Vec<u32> = (0..scene.instances.len() as u32)
        .filter(|&i| !in_group[i as usize])
        .collect();
    let mut instances = vec![InstanceUv::default(); scene.instances.len()];
    let has_triangles = |i: &u32| !scene.instances[*i as usize].triangles.is_empty();
    if !unshared.iter().any(has_triangles) {
        return Ok((instances, Vec::new()));
    }
    let sub = sub_scene(scene, &unshared);
    // The sub-scene holds the unshared instances' triangles in instance order.
    let triangle_density = if params.triangle_density.is_empty() {
        Vec::new()
    } else {
        unshared
            .iter()
            .flat_map(|&i| {
                let r = &scene.instances[i as usize].triangles;
                params.triangle_density[r.start as usize..r.end as usize].iter()
            })
            .copied()
            .collect()
    };
    let sub_params = AtlasParams {
        instance_density: unshared
            .iter()
            .map(|&i| instance_density(params, i) / params.texels_per_unit)
            .collect(),
        triangle_density,
        ..params.clone()
    };
    let atlas = xatlas::unwrap(&sub, source, &sub_params)?;
    for (uv, &i) in atlas.instances.into_iter().zip(&unshared) {
        instances[i as usize] = uv;
    }
    Ok((instances, atlas.pages))
}

/// One group's base layout and each node's rect, sized in texels (placed on a page later).
fn shared_mesh(
    scene: &Scene,
    source: &Source,
    params: &AtlasParams,
    mesh: u32,
    nodes: &[(u32, Vec<u32>)],
) -> Result<SharedMesh> {
    let first = &nodes[0].1;
    let effective = effective_densities(scene, params, nodes);
    let lowest = effective.iter().copied().fold(f32::INFINITY, f32::min);
    let (base, base_size, tpu, lowered) =
        fitting_base_layout(scene, source, params, mesh, first, lowest)?;
    // Every copy at least as dense as the base layout (so padding holds), at most a page
    // (a texel less, so rounding the rect up to whole texels still fits).
    let (padding, max_side) = (params.padding as f32, params.max_page_size as f32);
    let fit = (max_side - padding - 1.0) / base_size.max_element();
    let node_rects = nodes
        .iter()
        .zip(&effective)
        .map(|((node, block), &e)| {
            let wanted = (e / tpu).max(1.0);
            NodeRect {
                node: *node,
                page: 0,
                scale: Vec2::splat(wanted.min(fit)),
                offset: Vec2::ZERO,
                instances: block.clone(),
                capped: wanted > fit,
            }
        })
        .collect();
    Ok(SharedMesh {
        mesh,
        base: first.iter().copied().zip(base).collect(),
        base_size,
        texels_per_unit: tpu,
        lowered,
        nodes: node_rects,
    })
}

/// Each node's effective density: its densest instance's texels per unit times its size
/// relative to the first node (the square root of the blocks' world-area ratio).
fn effective_densities(scene: &Scene, params: &AtlasParams, nodes: &[(u32, Vec<u32>)]) -> Vec<f32> {
    let first_area: f64 = nodes[0].1.iter().map(|&i| instance_area(scene, i)).sum();
    nodes
        .iter()
        .map(|(_, block)| {
            let area: f64 = block.iter().map(|&i| instance_area(scene, i)).sum();
            let size = if first_area > 0.0 {
                (area / first_area).sqrt() as f32
            } else {
                1.0
            };
            let densest = (block.iter())
                .map(|&i| instance_density(params, i))
                .fold(0.0, f32::max);
            size * densest
        })
        .collect()
}

/// The base layout of `first` (the first node's block of `mesh`) at `tpu` texels per unit,
/// lowered a quarter at a time until it fits a page with room for padding: its UVs, its size
/// in texels, the density it got and whether that was lowered.
fn fitting_base_layout(
    scene: &Scene,
    source: &Source,
    params: &AtlasParams,
    mesh: u32,
    first: &[u32],
    mut tpu: f32,
) -> Result<(Vec<InstanceUv>, Vec2, f32, bool)> {
    let (padding, max_side) = (params.padding as f32, params.max_page_size as f32);
    let sub = sub_scene(scene, first);
    let mut lowerings = 0;
    loop {
        let sub_params = AtlasParams {
            texels_per_unit: tpu,
            instance_density: Vec::new(),
            triangle_density: Vec::new(),
            ..params.clone()
        };
        let layout = if sub.triangles.is_empty() {
            None
        } else {
            let atlas = xatlas::unwrap(&sub, source, &sub_params)?;
            base_layout(atlas, padding)
        };
        match layout {
            Some((base, size)) if size.max_element() + padding + 1.0 <= max_side => {
                return Ok((base, size, tpu, lowerings > 0));
            }
            None if sub.triangles.is_empty() => {
                let empty = vec![InstanceUv::default(); first.len()];
                return Ok((empty, Vec2::ONE, tpu, lowerings > 0));
            }
            _ if lowerings < MAX_LOWERINGS => {
                tpu *= 0.75;
                lowerings += 1;
            }
            _ => {
                return Err(Error::Option(format!(
                    "mesh {mesh}: its lightmap layout does not fit a {} texel page even at {tpu} texels per unit: raise --max-page-size",
                    params.max_page_size
                )));
            }
        }
    }
}

/// Shelf-packs every node's rect (texel scale, still) onto pages after `pages` (xatlas' ones),
/// then turns each rect's scale and offset into page units.
fn place_rects(shared: &mut [SharedMesh], pages: &mut Vec<PageSize>, params: &AtlasParams) {
    let first_rect_page = pages.len() as u32;
    let mut items: Vec<(usize, usize, [u32; 2])> = Vec::new();
    for (g, s) in shared.iter().enumerate() {
        for (n, rect) in s.nodes.iter().enumerate() {
            let size = (s.base_size * rect.scale).ceil().as_uvec2() + params.padding;
            items.push((g, n, [size.x, size.y]));
        }
    }
    items.sort_by_key(|&(g, n, [w, h])| (std::cmp::Reverse(h), std::cmp::Reverse(w), g, n));
    let side = params.max_page_size;
    let placed = shelf_pack(&items.iter().map(|i| i.2).collect::<Vec<_>>(), [side, side]);
    let rect_pages = placed.iter().map(|p| p.0 + 1).max().unwrap_or(0);
    let mut extent = vec![[0u32; 2]; rect_pages as usize];
    for (&(_, _, [w, h]), &(page, [x, y])) in items.iter().zip(&placed) {
        let e = &mut extent[page as usize];
        *e = [e[0].max(x + w), e[1].max(y + h)];
    }
    pages.extend(extent.iter().map(|&[w, h]| PageSize {
        width: page_side(w as f32, params.max_page_size),
        height: page_side(h as f32, params.max_page_size),
    }));
    let padding = params.padding as f32;
    for (&(g, n, _), &(page, [x, y])) in items.iter().zip(&placed) {
        let page = first_rect_page + page;
        let size = pages[page as usize];
        let page_texels = Vec2::new(size.width as f32, size.height as f32);
        let s = &mut shared[g];
        let rect = &mut s.nodes[n];
        rect.page = page;
        rect.offset = (Vec2::new(x as f32, y as f32) + padding) / page_texels;
        rect.scale = s.base_size * rect.scale / page_texels;
    }
}

/// Every node's page UVs of shared mesh `s` from its base layout, as a shader computes them.
fn write_node_uvs(scene: &Scene, s: &SharedMesh, instances: &mut [InstanceUv]) {
    for rect in &s.nodes {
        for ((first, base), &i) in s.base.iter().zip(&rect.instances) {
            let (a, b) = (
                &scene.instances[*first as usize],
                &scene.instances[i as usize],
            );
            let triangles = (0..base.triangles.len())
                .map(|t| {
                    let order = corner_order(scene, a, b, t).expect("checked by blocks_match");
                    order.map(|c| base.triangles[t][c])
                })
                .collect();
            instances[i as usize] = InstanceUv {
                xref: base.xref.clone(),
                uv: base.uv.iter().map(|&uv| page_uv(uv, rect)).collect(),
                triangles,
                triangle_page: vec![rect.page; base.triangles.len()],
            };
        }
    }
}

/// A base-layout UV on `rect`'s page: `uv * scale + offset`, a multiply then an add in f32 (no
/// fused multiply-add), as a shader writes it.
pub(crate) fn page_uv(uv: Vec2, rect: &NodeRect) -> Vec2 {
    let scaled = uv * rect.scale;
    scaled + rect.offset
}

/// The base layout of a one-page xatlas atlas: UVs in \[0,1\] of the charts' extent plus
/// `padding` (texels) right of and below them, and that size in texels. `None` when xatlas
/// needed more than one page.
fn base_layout(atlas: Atlas, padding: f32) -> Option<(Vec<InstanceUv>, Vec2)> {
    let [page] = atlas.pages[..] else {
        return None;
    };
    let page_texels = Vec2::new(page.width as f32, page.height as f32);
    let extent = (atlas.instances.iter())
        .flat_map(|i| &i.uv)
        .fold(Vec2::ZERO, |e, &uv| e.max(uv * page_texels));
    let size = extent.ceil() + padding;
    let instances = (atlas.instances.into_iter())
        .map(|mut inst| {
            for uv in &mut inst.uv {
                *uv = (*uv * page_texels / size).clamp(Vec2::ZERO, Vec2::ONE);
            }
            inst
        })
        .collect();
    Some((instances, size))
}

#[cfg(test)]
mod tests {
    use glam::{Quat, Vec3};

    use super::super::xatlas::tests::{Part, cube, params, quad, scene_of, source};
    use super::*;
    use crate::atlas::for_each_touched_texel;

    /// `part` as mesh 1 placed by `node`: scaled, rotated, moved; winding reversed when the
    /// transform mirrors (as the loader does).
    fn placed(part: &Part, node: u32, scale: Vec3, turn: f32, offset: Vec3) -> Part {
        let mut p = part.clone();
        let rotation = Quat::from_rotation_y(turn);
        p.positions
            .iter_mut()
            .for_each(|x| *x = rotation * (*x * scale) + offset);
        if scale.x * scale.y * scale.z < 0.0 {
            p.triangles.iter_mut().for_each(|t| t.swap(1, 2));
        }
        p.mesh = 1;
        p.node = node;
        p
    }

    /// A floor (mesh 0, unshared) and a double-sided box (mesh 1) placed by three nodes: as
    /// is, twice the size, and mirrored at 1.5 times the size.
    fn boxes() -> Scene {
        let floor = quad(Vec3::new(-4.0, -4.0, -1.0), 8.0, 8.0);
        let unit = cube(1.0, 2);
        let parts = [
            floor,
            placed(&unit, 1, Vec3::ONE, 0.0, Vec3::new(-2.0, 0.0, 0.0)),
            placed(&unit, 2, Vec3::splat(2.0), 0.3, Vec3::new(0.0, 0.0, 0.0)),
            placed(
                &unit,
                3,
                Vec3::new(-1.5, 1.5, 1.5),
                0.0,
                Vec3::new(3.0, 0.0, 0.0),
            ),
        ];
        scene_of(&parts, &[1, 2, 3])
    }

    fn shared_params(tpu: f32, max_page_size: u32, padding: u32) -> AtlasParams {
        AtlasParams {
            padding,
            instancing: crate::config::Instancing::Share,
            ..params(tpu, max_page_size)
        }
    }

    /// Every texel a triangle touches (sampled every quarter texel) belongs to one chart of
    /// one instance, and no texel of another chart lies within `padding` texels of it.
    fn assert_padded(atlas: &Atlas, padding: u32) {
        let mut owner: Vec<Vec<(u32, usize)>> = atlas
            .pages
            .iter()
            .map(|p| vec![(u32::MAX, 0); (p.width * p.height) as usize])
            .collect();
        for (i, inst) in atlas.instances.iter().enumerate() {
            let chart = inst.charts();
            for (t, tri) in inst.triangles.iter().enumerate() {
                let page = inst.triangle_page[t] as usize;
                let uv = tri.map(|k| inst.uv[k as usize]);
                for_each_touched_texel(uv, atlas.pages[page], |k| {
                    owner[page][k] = (i as u32, chart[t]);
                });
            }
        }
        for (owner, size) in owner.iter().zip(&atlas.pages) {
            let (w, h) = (i64::from(size.width), i64::from(size.height));
            let reach = i64::from(padding);
            for y in 0..h {
                for x in 0..w {
                    let me = owner[(y * w + x) as usize];
                    if me.0 == u32::MAX {
                        continue;
                    }
                    for ny in (y - reach).max(0)..=(y + reach).min(h - 1) {
                        for nx in (x - reach).max(0)..=(x + reach).min(w - 1) {
                            let other = owner[(ny * w + nx) as usize];
                            assert!(
                                other.0 == u32::MAX || other == me,
                                "padding {padding}: {me:?} at ({x}, {y}) and {other:?} at ({nx}, {ny})"
                            );
                        }
                    }
                }
            }
        }
    }

    /// Every node's page UVs are the base layout's `uv * scale + offset` in f32, bit for bit.
    fn assert_page_uvs_exact(atlas: &Atlas) {
        for shared in &atlas.shared {
            for rect in &shared.nodes {
                for ((_, base), &i) in shared.base.iter().zip(&rect.instances) {
                    let inst = &atlas.instances[i as usize];
                    assert_eq!(inst.uv.len(), base.uv.len());
                    assert_eq!(inst.xref, base.xref);
                    for (uv, b) in inst.uv.iter().zip(&base.uv) {
                        let x = b.x * rect.scale.x;
                        let y = b.y * rect.scale.y;
                        let expected = [x + rect.offset.x, y + rect.offset.y];
                        assert_eq!(uv.to_array().map(f32::to_bits), expected.map(f32::to_bits));
                    }
                    assert!(inst.triangle_page.iter().all(|&p| p == rect.page));
                }
            }
        }
    }

    #[test]
    fn a_mesh_placed_three_times_is_laid_out_once_with_a_padded_rect_per_node() {
        let scene = boxes();
        for padding in [1, 2, 4] {
            let atlas = build_ok(&scene, &shared_params(16.0, 512, padding));
            assert_eq!(atlas.shared.len(), 1);
            let shared = &atlas.shared[0];
            assert_eq!(shared.mesh, 1);
            // Front and back instance per node.
            assert_eq!(shared.base.len(), 2);
            let nodes: Vec<u32> = shared.nodes.iter().map(|n| n.node).collect();
            assert_eq!(nodes, [1, 2, 3]);
            assert!(!shared.lowered && shared.nodes.iter().all(|n| !n.capped));
            assert_page_uvs_exact(&atlas);
            assert_padded(&atlas, padding);
            // Copies scale with their node: the lowest density is the base (scale 1 in
            // texels), the others 2 and 1.5 times it.
            let texel_scale = |n: &NodeRect| {
                let page = atlas.pages[n.page as usize];
                n.scale * Vec2::new(page.width as f32, page.height as f32) / shared.base_size
            };
            let s: Vec<Vec2> = shared.nodes.iter().map(texel_scale).collect();
            for (s, expected) in s.iter().zip([1.0, 2.0, 1.5]) {
                assert!(
                    (*s - Vec2::splat(expected)).abs().max_element() < 1e-4,
                    "{s}"
                );
            }
            // The floor is unshared and unwrapped by xatlas on the first page.
            assert_eq!(atlas.instances[0].triangle_page, [0, 0]);
            assert!(shared.nodes.iter().all(|n| n.page >= 1));
        }
    }

    #[test]
    fn a_base_layout_too_large_for_a_page_is_lowered_and_big_copies_capped() {
        let scene = boxes();
        // The box at 64 texels per unit: six 64² faces, front and back, do not fit 128².
        let params = shared_params(64.0, 128, 2);
        let atlas = build_ok(&scene, &params);
        let shared = &atlas.shared[0];
        assert!(shared.lowered);
        assert!(shared.texels_per_unit < 64.0);
        assert!(shared.nodes.iter().any(|n| n.capped));
        assert!(
            atlas
                .pages
                .iter()
                .all(|p| p.width <= 128 && p.height <= 128)
        );
        assert_page_uvs_exact(&atlas);
        assert_padded(&atlas, 2);
        let report = ShareReport::of(&atlas).unwrap();
        assert_eq!((report.meshes, report.nodes, report.lowered), (1, 3, 1));
        assert!(report.brief().contains("lower density"));
    }

    #[test]
    fn blocks_that_differ_are_not_shared() {
        let unit = cube(1.0, 2);
        let mut smaller = placed(&unit, 2, Vec3::ONE, 0.0, Vec3::X * 2.0);
        smaller.triangles.pop();
        let scene = scene_of(
            &[placed(&unit, 1, Vec3::ONE, 0.0, Vec3::ZERO), smaller],
            &[],
        );
        assert!(shared_groups(&scene).is_empty());
        let atlas = build_ok(&scene, &shared_params(16.0, 512, 2));
        assert!(atlas.shared.is_empty());
        assert!(shared_instances(&scene).iter().all(|&s| !s));
        // A block the junction split cut is not shared either.
        let mut scene = boxes();
        let cut = scene.instances[2].triangles.len();
        scene.instances[2].split.sides = vec![0; cut];
        assert!(shared_groups(&scene).is_empty());
    }

    #[test]
    fn shared_layout_is_deterministic() {
        let scene = boxes();
        let first = build_ok(&scene, &shared_params(16.0, 256, 2)).layout_bits();
        for _ in 0..3 {
            assert!(build_ok(&scene, &shared_params(16.0, 256, 2)).layout_bits() == first);
        }
    }

    fn build_ok(scene: &Scene, params: &AtlasParams) -> Atlas {
        let atlas = super::super::build(scene, &source(), params).unwrap();
        atlas.validate(scene);
        atlas
    }
}
