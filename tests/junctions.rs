//! Junction splitting: no lightmap texel straddles the two-room wall, and what a renderer shows
//! along the wall on the dark side agrees with the path tracer (it does not without the split).

use std::collections::BTreeMap;

use glam::Vec3;
use lightbake::reference::ReferenceParams;
use lightbake::reference::points::{self, PointReference, Strip};
use lightbake::render::RenderScene;
use lightbake::{BakeConfig, NoProgress};

use crate::util::{fixture, scratch};

fn draft(split_junctions: bool) -> BakeConfig {
    let mut config = BakeConfig::draft();
    config.atlas.split_junctions = split_junctions;
    config
}

/// Texels (page, x, y) of one instance touched by triangles on both sides of the wall at x = 0
/// (each triangle's texels taken conservatively: its UV bounding box).
fn texels_on_both_sides(split_junctions: bool) -> usize {
    let prepared = lightbake::prepare(
        &fixture("two_rooms.gltf"),
        &draft(split_junctions),
        &NoProgress,
    )
    .expect("prepares");
    let (scene, atlas) = (&prepared.scene, &prepared.atlas);
    let mut shared = 0;
    for inst in &scene.instances {
        let mut sides: BTreeMap<(u32, i64, i64), [bool; 2]> = BTreeMap::new();
        for t in inst.triangles.clone() {
            let corners = scene.triangles[t as usize].map(|v| scene.positions[v as usize]);
            let x = (corners[0] + corners[1] + corners[2]).x / 3.0;
            if x.abs() < 1e-4 {
                continue; // the wall itself
            }
            let (uv, page) = atlas.triangle_uv(scene, t);
            let size = atlas.pages[page as usize];
            let scale = glam::Vec2::new(size.width as f32, size.height as f32);
            let lo = (uv[0].min(uv[1]).min(uv[2]) * scale).floor();
            let hi = (uv[0].max(uv[1]).max(uv[2]) * scale).ceil();
            for tx in lo.x as i64..hi.x as i64 {
                for ty in lo.y as i64..hi.y as i64 {
                    sides.entry((page, tx, ty)).or_default()[usize::from(x > 0.0)] = true;
                }
            }
        }
        shared += sides.values().filter(|s| s[0] && s[1]).count();
    }
    shared
}

#[test]
fn no_texel_straddles_the_two_rooms_wall() {
    assert_eq!(texels_on_both_sides(true), 0);
    // The measure can fail: without the split, floor and ceiling texels run under the wall.
    assert!(texels_on_both_sides(false) > 10);
}

/// Relative RMSE of a draft bake read as a renderer reads it at the points of `reference`.
fn strip_error(reference: &PointReference, split_junctions: bool) -> f32 {
    let dir = scratch();
    lightbake::bake(
        &fixture("two_rooms.gltf"),
        dir.path(),
        &draft(split_junctions),
        &NoProgress,
    )
    .expect("bakes");
    let baked = RenderScene::load(&dir.path().join("two_rooms.gltf")).expect("loads");
    points::compare(&baked, reference).rmse
}

/// The junction strip: points within a draft texel (12.5 cm) of the wall on room B's side
/// (floor, ceiling and side walls along the wall, and the floor across the doorway).
/// Measured at 8192 points × 2048 paths (src/guide/performance.md, "Lightmap quality"): 16.8% with the split,
/// 96% without (room A's light read through texels under the wall), reference noise 2.9%.
/// Here 1024 points × 128 paths: the split must stay below 30%, and without it the error is
/// above 60%.
#[test]
fn the_dark_side_of_the_two_rooms_wall_shows_no_leak() {
    let params = ReferenceParams {
        max_samples: 128,
        ..ReferenceParams::default()
    };
    let wall = Strip::new(Vec3::ZERO, Vec3::X, 0.125);
    let (strip, _) = points::compute_in(
        &fixture("two_rooms.gltf"),
        &draft(true),
        &params,
        1024,
        Some(&wall),
        &NoProgress,
    )
    .expect("traces");
    // Every point is in the strip, none on the wall's own plane (where paths may start
    // behind the wall), and they reach the floor, the ceiling and both side walls.
    assert_eq!(strip.points.len(), 1024);
    assert!(
        strip
            .points
            .iter()
            .all(|p| wall.contains(p.position, p.normal))
    );
    assert!(strip.points.iter().all(|p| p.position.x > 8e-4));
    for normal in [Vec3::Y, Vec3::NEG_Y, Vec3::Z, Vec3::NEG_Z] {
        let on = strip.points.iter().filter(|p| p.normal.dot(normal) > 0.99);
        assert!(on.count() > 50, "few points on the faces facing {normal}");
    }
    let (on, off) = (strip_error(&strip, true), strip_error(&strip, false));
    assert!(on < 0.3, "strip error with the split {on}");
    assert!(off > 0.6, "strip error without the split {off}");
}

/// The atlas' needle bound (`atlas::xatlas`, private there): a triangle with an edge shorter
/// than this many texels is hidden from xatlas.
const NEEDLE_EDGE_TEXELS: f64 = 1e-3;

/// The split of every fixture it cuts, at the draft and medium densities a bake chooses (shadow
/// cuts on, as a bake splits): no triangle of a cut instance has an edge below the atlas'
/// needle bound (the inputs have none), and each cut instance keeps its area and the length of
/// its open edges (no T-junction).
#[test]
fn the_split_of_every_fixture_makes_no_needle_and_keeps_its_invariants() {
    use lightbake::config::AutoParams;
    use lightbake::plan::{self, Plan};
    use lightbake::scene::Scene;

    let area = |s: &Scene, t: u32| {
        let [a, b, c] = s.triangles[t as usize].map(|v| s.positions[v as usize].as_dvec3());
        0.5 * (b - a).cross(c - a).length()
    };
    let mut cut_fixtures = 0;
    for name in [
        "two_rooms.gltf",
        "two_rooms_angled.gltf",
        "cornell_box.gltf",
        "courtyard.gltf",
        "lamp_room.gltf",
        "furnished_interior.glb",
    ] {
        for (quality, preset) in &BakeConfig::PRESETS[..2] {
            let (scene, source) = lightbake::scene::load(&fixture(name)).expect("loads");
            let mut config = preset.clone();
            let mut plan = Plan {
                target_error: AutoParams::for_preset(quality).expect("preset"),
                ..Default::default()
            };
            plan::choose_density(&scene, &mut config, &mut plan, &Default::default());
            let tpu = f64::from(config.atlas.texels_per_unit);
            let input = scene.clone();
            let (split, report) = lightbake::split_junctions(scene, &source, &config);
            let report = report.expect("the split runs");
            let what = format!("{name} at {quality} ({tpu} /m): {}", report.brief());
            let mut cut = 0;
            for (i, inst) in split.instances.iter().enumerate() {
                if inst.split.blends.is_empty() {
                    continue;
                }
                cut += 1;
                let before: f64 = input.instances[i]
                    .triangles
                    .clone()
                    .map(|t| area(&input, t))
                    .sum();
                let after: f64 = inst.triangles.clone().map(|t| area(&split, t)).sum();
                assert!(
                    (after - before).abs() <= 1e-5 * before,
                    "{what}: instance {i} area {before} → {after}"
                );
                for t in inst.triangles.clone() {
                    let p = split.triangles[t as usize].map(|v| split.positions[v as usize]);
                    let shortest = (0..3)
                        .map(|k| f64::from(p[k].distance(p[(k + 1) % 3])))
                        .fold(f64::INFINITY, f64::min);
                    assert!(
                        shortest * tpu >= NEEDLE_EDGE_TEXELS,
                        "{what}: instance {i} triangle {t} has an edge of {:.1e} texel: {p:?}",
                        shortest * tpu
                    );
                }
                let (open_before, open_after) =
                    (open_edge_length(&input, i), open_edge_length(&split, i));
                assert!(
                    open_after <= open_before + 1e-3 / tpu + 1e-6 * open_before,
                    "{what}: instance {i}: open edges {open_before} m → {open_after} m (a T-junction)"
                );
            }
            assert_eq!(cut > 0, report.receivers > 0, "{what}");
            cut_fixtures += usize::from(cut > 0);
        }
    }
    assert!(
        cut_fixtures >= 10,
        "{cut_fixtures} of 12 splits cut anything"
    );
}

/// Total length of instance `i`'s open edges (one triangle on them; corners welded at 10 µm, as
/// the two sides of a cut edge blend its point from either end). A vertex the split left inside
/// the edge of a neighbour (a T-junction) opens that edge and both pieces beside it, so the
/// split must not add to this length (it may take from it: a cut point landing on an input's
/// T-junction closes it). A distance check alone cannot tell: `furnished_interior`'s
/// closed solids touch along collinear edges and have finely tessellated faces beside one-quad
/// faces, so vertices lie inside other faces' edges already in the input.
fn open_edge_length(scene: &lightbake::scene::Scene, i: usize) -> f64 {
    let inst = &scene.instances[i];
    let key = |v: u32| {
        let p = scene.positions[v as usize].as_dvec3() * 1e5;
        [p.x.round() as i64, p.y.round() as i64, p.z.round() as i64]
    };
    let mut edges: BTreeMap<([i64; 3], [i64; 3]), (usize, f64)> = BTreeMap::new();
    for t in inst.triangles.clone() {
        let tri = scene.triangles[t as usize];
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            let (ka, kb) = (key(a), key(b));
            let length = scene.positions[a as usize].distance(scene.positions[b as usize]);
            edges
                .entry((ka.min(kb), ka.max(kb)))
                .or_insert((0, f64::from(length)))
                .0 += 1;
        }
    }
    edges.values().filter(|e| e.0 == 1).map(|e| e.1).sum()
}
