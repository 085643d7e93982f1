//! Narrow faces (issue 27, item 3): on `fixtures/narrow_faces.gltf` a texel a renderer reads
//! for a face narrower than two texels (a door's top, bottom and edge in their slots, a
//! shelf's front edge, a ceiling light's border and recess) holds the light on that face.

use glam::Vec3;
use lightbake::reference::ReferenceParams;
use lightbake::reference::points::{self, PointReference};
use lightbake::render::RenderScene;
use lightbake::testing::{narrow_face, narrow_face_points};
use lightbake::{BakeConfig, NoProgress};

use crate::util::{fixture, grey_floor, scratch};

/// Points on the narrow faces whose draft lookup reads more than 1.5× their path-traced
/// reference (plus three standard errors), counting only references above 5% of the scene
/// mean: the acceptance, none allowed. Baked with near contacts
/// (`AtlasParams::near_contacts`), whose slot faces get texels at their gap's scale
/// (`AtlasParams::slot_faces`, `atlas::slots`).
///
/// 8 of 215 points were over before narrow faces near emitters (`AtlasParams::narrow_faces`)
/// got four texels across: 17 before slot faces, 72 without near contacts. Measured with
/// `examples/dev/narrow_points.rs` (512 points, 1024 paths; points above 1.5× plus three
/// standard errors, and the largest ratio per face), one run, `bake --quality Q
/// --near-contacts` with and without `--no-slot-faces`, draft / medium / high, before narrow
/// faces:
///
/// | | points over | door edge | door top | door bottom | light recess |
/// |---|---|---|---|---|---|
/// | near contacts alone | 35 / 18 / 1 | 3.5 / 2.3 / 1.8 | 4.0 / 2.6 / 1.5 | 5.3 / 1.7 / 1.3 | 3.5 / 3.9 / 1.9 |
/// | with slot faces | 12 / 10 / 2 | 1.7 / 1.5 / 1.4 | 1.4 / 1.2 / 1.2 | 1.9 / 1.4 / 1.3 | 4.2 / 5.1 / 2.0 |
///
/// The door's slots were resolved by slot faces (their texels at most the gap wide where the
/// cap, ×16 the preset's density, allows). What was left was the ceiling light's recess: its
/// band between the ceiling and the emitter's plane, which faces no surface (the emitter
/// lights it at grazing angles and its light falls from about 1.5 at the ceiling to 0.3 at the
/// emitter's plane over its 2 cm, one texel row at draft), and the recess walls' 2 cm beyond
/// the panel's corners. Both are narrower than four texels and lie within four of their
/// widths of the emitter: narrow faces give them four texels across (`atlas::slots`). With
/// them, at draft / medium / high, points over went 15 → 1, 9 → 1 and 2 → 1 (the guide's
/// baking page has the table with texels, time and memory). Tried before and not kept: keeping cut points off interior edges unless within
/// 1/1024 texel (a tilted cut at y = 2.66 left a 1 mm sliver charted with the band) removed
/// that point but not the count, and moved the corpus' plans both ways.
#[test]
fn narrow_faces_read_at_most_one_and_a_half_times_their_light() {
    let input = fixture("narrow_faces.gltf");
    let mut config = BakeConfig::draft();
    config.atlas.near_contacts = true;
    let p = lightbake::prepare(&input, &config, &NoProgress).expect("prepares");
    let trace = |set: points::PointSet, paths: u32| {
        let params = ReferenceParams {
            max_samples: paths,
            ..ReferenceParams::default()
        };
        let traced = points::trace(
            &p.scene,
            &p.texels,
            &p.tracer,
            &set.points,
            &params,
            &NoProgress,
        )
        .expect("traces");
        PointReference::new(set, &traced)
    };
    let narrow = trace(
        narrow_face_points(&p.scene, &p.tracer, 256, 1).expect("narrow points"),
        256,
    );
    let all = trace(
        points::draw(&p.scene, &p.tracer, 512, 2).expect("draws"),
        64,
    );
    let grey = |v: Vec3| v.element_sum() / 3.0;
    let scene_mean = all.mean.iter().map(|&m| grey(m)).sum::<f32>() / all.mean.len() as f32;

    let dir = scratch();
    lightbake::bake(&input, dir.path(), &config, &NoProgress).expect("bakes");
    let baked = RenderScene::load(&dir.path().join("narrow_faces.gltf")).expect("loads");
    let lookups = points::look_up(&baked, &narrow.points);
    let mut over = Vec::new();
    let mut counted = 0;
    for (k, l) in lookups.iter().enumerate() {
        let (x, r, se) = (
            grey(l.as_ref().expect("on a baked surface").value),
            grey(narrow.mean[k]),
            grey(narrow.std_error[k]),
        );
        if r > 0.05 * scene_mean {
            counted += 1;
            if x > 1.5 * r + 3.0 * se {
                let p = &narrow.points[k];
                over.push(format!(
                    "{} at {:.3}: {x:.4} for {r:.4}",
                    narrow_face(p.position, p.normal).unwrap_or("?"),
                    p.position
                ));
            }
        }
    }
    assert!(counted > 100, "{counted} points above 5% of the mean");
    assert!(
        over.is_empty(),
        "{} of {counted} narrow-face points read above 1.5x their reference:\n{}",
        over.len(),
        over.join("\n")
    );
}

/// A light sealed inside a thin closed solid lights nothing around it. The floor runs on under
/// 24 posts 2.5 cm across (closed boxes, too narrow for the junction split to cut the floor
/// around them), each with a point light inside 1 cm up. A 12.5 cm floor texel around a post
/// reaches under it, and a punctual sample drawn there sees the light through no wall: before
/// `Texels::punctual_point` the brightest floor texel read 253 (`H/π`) where no visible point
/// sees any light. The interior fixture's lamp, its bulb inside the pole, made its shade's
/// underside read `ρ·H` ≈ 80 in one texel (0.4–0.6 beside it) that way.
#[test]
fn lights_sealed_inside_thin_posts_light_nothing_around_them() {
    use lightbake::testing::{Face, Geometry, GltfBuilder, Light};
    let mut gltf = GltfBuilder::new("sealed_light");
    let grey = grey_floor(&mut gltf);
    // Posts a fifth of a texel across (too narrow for the junction split to cut the floor
    // around), at offsets that walk across the texel grid, each with a light inside.
    for k in 0..24 {
        let (a, b) = ((k % 6) as f32, (k / 6) as f32);
        let o = Vec3::new(
            -0.85 + 0.3 * a + 0.021 * b,
            0.0,
            -0.85 + 0.4 * b + 0.017 * a,
        );
        let (min, max) = (o, o + Vec3::new(0.025, 0.5, 0.025));
        let post = gltf.add_mesh("post", Geometry::box_faces(min, max, &Face::ALL, 1), grey);
        gltf.add_mesh_node("post", post);
        let light = o + Vec3::new(0.0125, 0.01, 0.0125);
        gltf.add_light_node(Light::point("sealed", [1.0; 3], 1.0), light, Vec3::NEG_Y);
    }
    let dir = scratch();
    let input = dir.path().join("sealed_light.gltf");
    gltf.write_gltf(&input).expect("writes");
    let mut config = BakeConfig::draft();
    config.atlas.texels_per_unit = 8.0;
    let baked = lightbake::compute(&input, &config, &NoProgress).expect("bakes");
    let t = &baked.texels;
    let brightest = (0..t.len())
        .max_by(|&a, &b| {
            let (la, lb) = (baked.lightmap[a], baked.lightmap[b]);
            la.max_element().total_cmp(&lb.max_element())
        })
        .expect("texels");
    let value = baked.lightmap[brightest].max_element();
    assert!(
        value < 1e-3,
        "texel at {} (normal {}) reads {value}",
        t.position[brightest],
        t.normal[brightest]
    );
}

/// Slot faces get texels at the scale of their gap (`atlas::slots`), within the cap on the
/// texels they add. A board 6 mm over a floor at draft (12.5 cm texels): the floor under the
/// board and the board's underside face each other across the gap and ask for ×16, which
/// would add about 19× this small scene's uniform texels, so the cap lowers the raise until
/// they add at most that many (×3.4). Without slot faces the floor under the board keeps the
/// preset's texels.
#[test]
fn a_board_over_a_floor_gets_texels_at_its_gap_within_the_cap() {
    use lightbake::testing::{Face, Geometry, GltfBuilder};
    let mut gltf = GltfBuilder::new("board_over_floor");
    let grey = grey_floor(&mut gltf);
    let (min, max) = (Vec3::new(-0.2, 0.006, -0.2), Vec3::new(0.2, 0.026, 0.2));
    let board = gltf.add_mesh("board", Geometry::box_faces(min, max, &Face::ALL, 1), grey);
    gltf.add_mesh_node("board", board);
    let dir = scratch();
    let input = dir.path().join("board_over_floor.gltf");
    gltf.write_gltf(&input).expect("writes");

    let under_board = |slot_faces: bool| {
        let mut config = BakeConfig::draft();
        config.atlas.near_contacts = true;
        config.atlas.slot_faces = slot_faces;
        let p = lightbake::prepare(&input, &config, &NoProgress).expect("prepares");
        let t = &p.texels;
        let under = (0..t.len())
            .filter(|&i| {
                let q = t.position[i];
                t.normal[i].y > 0.9 && q.y < 0.003 && q.x.abs() < 0.2 && q.z.abs() < 0.2
            })
            .count();
        (under, t.len())
    };
    let (off, off_total) = under_board(false);
    let (on, on_total) = under_board(true);
    // 0.16 m² at 8 /m is 10 whole texels (25 with the partial ones round the outline's cut);
    // at ×3.4, about 115 whole ones.
    assert!(
        off <= 40,
        "{off} floor texels under the board without slot faces"
    );
    assert!(
        on >= 3 * off,
        "{on} floor texels under the board with slot faces, {off} without"
    );
    // The cap: slot faces add at most the uniform atlas's texels (plus packing's borders).
    assert!(
        on_total <= 3 * off_total,
        "{on_total} texels with slot faces, {off_total} without"
    );
}

/// Narrow faces near emitters get four texels across (`atlas::slots`, on by default): two
/// fittings over a floor, each a 40 × 40 × 4 cm box whose underside is a 36 cm panel framed
/// by a 2 cm border. The left panel emits; the right one is plain. At draft (12.5 cm texels)
/// the left border, touching the emitter, is raised towards 4 texels across its 2 cm (×25 on
/// quarter octaves, as far as the narrow faces' texel share allows); the right border, in
/// even light, keeps the preset's density, and so does the left one with the rule off.
#[test]
fn narrow_faces_beside_an_emitter_get_four_texels_across() {
    use lightbake::testing::{Face, Geometry, GltfBuilder, Material};
    let mut gltf = GltfBuilder::new("framed_panels");
    let grey = grey_floor(&mut gltf);
    let light = gltf.add_material(Material::grey("light", 0.8).emitting([1.0; 3], 5.0));
    let (l, e, y0, y1) = (0.2f32, 0.18f32, 1.0f32, 1.04f32);
    for (name, x, panel) in [("lit", -0.5f32, light), ("plain", 0.5, grey)] {
        let v = |dx: f32, y: f32, z: f32| Vec3::new(x + dx, y, z);
        let mut body = Geometry::box_faces(
            v(-l, y0, -l),
            v(l, y1, l),
            &[Face::PosX, Face::NegX, Face::PosY, Face::PosZ, Face::NegZ],
            1,
        );
        for (min, max) in [
            (v(-l, y0, -l), v(-e, y0, l)),
            (v(e, y0, -l), v(l, y0, l)),
            (v(-e, y0, -l), v(e, y0, -e)),
            (v(-e, y0, e), v(e, y0, l)),
        ] {
            body.append(&Geometry::box_face(min, max, Face::NegY, 1, 1));
        }
        let mesh = gltf.add_mesh(name, body, grey);
        let face = Geometry::box_face(v(-e, y0, -e), v(e, y0, e), Face::NegY, 1, 1);
        gltf.add_primitive(mesh, face, panel);
        gltf.add_mesh_node(name, mesh);
    }
    let dir = scratch();
    let input = dir.path().join("framed_panels.gltf");
    gltf.write_gltf(&input).expect("writes");

    // Texels on each fitting's border (facing down at its underside, outside the panel).
    let borders = |narrow_faces: bool| {
        let mut config = BakeConfig::draft();
        config.atlas.narrow_faces = narrow_faces;
        let p = lightbake::prepare(&input, &config, &NoProgress).expect("prepares");
        let t = &p.texels;
        let on_border = |x: f32| {
            (0..t.len())
                .filter(|&i| {
                    let q = t.position[i] - Vec3::new(x, y0, 0.0);
                    let (a, b) = (q.x.abs(), q.z.abs());
                    t.normal[i].y < -0.9 && q.y.abs() < 1e-3 && a.max(b) > e && a.max(b) < l
                })
                .count()
        };
        (on_border(-0.5), on_border(0.5))
    };
    let (lit, plain) = borders(true);
    let (lit_off, plain_off) = borders(false);
    // 0.0304 m² of border: about 2 texels at 8 /m (36 with each strip's partial texels), and
    // 264 when raised (measured; ×26.9 would give about 1400, but on this small scene the
    // narrow faces' texel share caps the raise, shared with the fitting's 4 cm sides beside
    // the panel).
    assert!(
        lit >= 5 * plain.max(1),
        "{lit} texels on the emitter's border, {plain} on the plain panel's"
    );
    assert_eq!(
        plain, plain_off,
        "the plain panel's border moved with the rule"
    );
    assert!(
        lit_off <= 2 * plain_off.max(1),
        "{lit_off} texels on the emitter's border without the rule, {plain_off} on the plain one"
    );
}
