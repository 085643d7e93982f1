//! Narrow faces (issue 27, item 3): on `fixtures/narrow_faces.gltf` a texel a renderer reads
//! for a face narrower than two texels (a door's top, bottom and edge in their slots, a
//! shelf's front edge, a ceiling light's border and recess) holds the light on that face.

use glam::Vec3;
use lightbake::reference::ReferenceParams;
use lightbake::reference::points::{self, PointReference};
use lightbake::render::RenderScene;
use lightbake::testing::{narrow_face, narrow_face_points};
use lightbake::{BakeConfig, NoProgress};

use crate::util::{fixture, scratch};

/// Points on the narrow faces whose draft lookup reads more than 1.5× their path-traced
/// reference (plus three standard errors), counting only references above 5% of the scene
/// mean: the acceptance, none allowed. Baked with near contacts
/// (`AtlasParams::near_contacts`).
///
/// Fails today: 17 of 215 points over (72 of 214 without near contacts). Measured with
/// `examples/dev/narrow_points.rs` (512 points, 1024 paths; points
/// above 1.5× plus three standard errors, and the largest ratio per face, draft / medium /
/// high):
///
/// | | points over | door edge | door top | door bottom | light recess |
/// |---|---|---|---|---|---|
/// | junction split alone | 93 / 49 / 3 | 7.4 / 4.2 / 2.0 | 5.1 / 2.9 / 1.6 | 5.2 / 1.6 / 1.2 | 4.3 / 3.0 / 1.8 |
/// | with near contacts | 38 / 22 / 4 | 3.9 / 2.4 / 2.0 | 3.7 / 2.5 / 1.5 | 3.5 / 1.6 / 1.2 | 4.8 / 3.7 / 1.8 |
///
/// The first cause was what the slot faces' rays read: the door's edge sees the jamb's lining
/// 3 mm away, and the lining's texel spanned the slot (H/π 0.015 there) and the lining's 1 cm
/// proud of the wall in the room (0.107 baked, 0.089 its texel reference: the door edge read 7.4× its reference). Near contacts cut the
/// lining along the door's outline, and the slot's lining texels now hold 0.002–0.04 like their
/// texel references. What is left is resolution on the narrow faces themselves: in the slot
/// the light falls from 0.15 at the mouth to 0.05 at 4 mm and 0.009 at 14 mm, and a texel
/// 2–3 cm wide holds the mean over its footprint (the door edge's texel next to the mouth
/// holds 0.035, its reference at its sample point 0.02), so a renderer's lookup 1.5 cm in reads
/// 3–4× its reference. Likewise the recess wall's 2 cm below the light, now its own chart: from
/// the ceiling up to the emitter's plane its light falls from about 1.5 to 0.3, and its one texel
/// row holds about 1.3. Neither is a cut; both need texels at the scale of the gap.
///
/// Also left: with near contacts the density plan's pilot finds 17 more regions buried (every
/// pilot texel of theirs invalid; 95 regions, 86.3 m², against 78, 83.2 m²), small ones such
/// as the recess wall's band below the light, and gives them ×⅛. Some lookups on that band then
/// read 0, and a few of this test's points in the recess's slot read the band's light (at
/// (0.450, 2.659, 0.010) 1.01 for 0.21, where the slot's texels hold 0.18). At a fixed density
/// (`--texels-per-unit 32`, draft, no density plan) the band and slot read cleanly (the band
/// 1.86 to 1.17 from the ceiling up, the slot 0.28 to 0.18) and the points over fall from 64
/// to 30, the recess's only ones at the top of the band.
#[test]
#[ignore = "issue 27 item 3 is open: the light falls across a slot face faster than a texel resolves"]
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
    use lightbake::testing::{Face, Geometry, GltfBuilder, Light, Material};
    let mut gltf = GltfBuilder::new("sealed_light");
    let grey = gltf.add_material(Material::grey("grey", 0.5));
    let floor = Geometry::grid(
        Vec3::new(-1.0, 0.0, 1.0),
        Vec3::X * 2.0,
        Vec3::NEG_Z * 2.0,
        4,
        4,
    );
    let floor = gltf.add_mesh("floor", floor, grey);
    gltf.add_mesh_node("floor", floor);
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
