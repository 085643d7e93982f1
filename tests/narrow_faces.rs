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
/// Fails today: 8 of 215 points over, all on the light's recess (17 before slot faces, 72
/// without near contacts). Measured with `examples/dev/narrow_points.rs` (512 points, 1024
/// paths; points above 1.5× plus three standard errors, and the largest ratio per face), one
/// run, `bake --quality Q --near-contacts` with and without `--no-slot-faces`, draft / medium /
/// high:
///
/// | | points over | door edge | door top | door bottom | light recess |
/// |---|---|---|---|---|---|
/// | near contacts alone | 35 / 18 / 1 | 3.5 / 2.3 / 1.8 | 4.0 / 2.6 / 1.5 | 5.3 / 1.7 / 1.3 | 3.5 / 3.9 / 1.9 |
/// | with slot faces | 12 / 10 / 2 | 1.7 / 1.5 / 1.4 | 1.4 / 1.2 / 1.2 | 1.9 / 1.4 / 1.3 | 4.2 / 5.1 / 2.0 |
///
/// (This test's settings, draft without the automatic plan: 41 → 15 of those points over,
/// 15,257 → 25,422 texels.) The door's slots are resolved: their faces' texels are now at most
/// the gap wide where the cap (×16 the preset's density) allows, and the light falling from
/// the slot's mouth is read where it is. What is left is the ceiling light's recess. Four of
/// the 8 are on the recess wall's band between the ceiling and the emitter's plane, which
/// faces no surface (no slot face): the emitter lights it at grazing angles and its light
/// falls from about 1.5 at the ceiling to 0.3 at the emitter's plane over its 2 cm, one texel
/// row at draft (a texel at 1.9 cm, the slot's gap, would still be one row). Two are on the
/// recess walls' 2 cm beyond the panel's corners, in the slot but facing no surface along
/// their normal (the rule's rays look straight ahead), so they keep the preset's texels; one is
/// on the panel's side, where next to the emitter the light falls faster than an e-fold per
/// gap; and one at (0.450, 2.659, 0.010) reads the band's light (1.16 for 0.21) where the
/// slot's texels beside it hold 0.16, as before slot faces. Why: the slot's top, a cut along
/// y = 2.66, ends 2.5 mm from the wall quad's diagonal, and a cut point within the touch
/// distance (a sixteenth of a texel) of a mesh edge moves onto it. The cut tilts (2.659 at one
/// end, 2.66 at the other), and the 1 mm sliver above it stays with the face above the slot,
/// charted with the band. Keeping cut points off interior edges unless within 1/1024 texel
/// (rounding only) removed that point but not the count (8 of 216, other band and corner
/// points), and moved the corpus' plans both ways in one run against the build before: the
/// interior at `draft` 5.97% → 6.22%, at `medium` 3.31% → 3.06% for 14% more memory, the
/// courtyard at `medium` 1.26% → 1.55% (p95 19.2% → 20.8%), the Cornell box at `draft` 7.02% →
/// 5.65%. Not kept. The density plan's ×⅛ for regions
/// its pilot finds buried no longer reaches slot faces (the plan's factors are raised to
/// theirs); the band, no slot face, can still get it.
#[test]
#[ignore = "issue 27 item 3 is open: the light recess's band below the emitter and its corners read above 1.5x"]
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
