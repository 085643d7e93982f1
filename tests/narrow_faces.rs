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
/// mean: the acceptance, none allowed.
///
/// Fails today, at every preset: measured with `examples/dev/narrow_points.rs` (512 points,
/// 1024 paths), the door's latch edge reads up to 8.5× (draft) and 4× (medium, high), its top
/// 5.6× / 2.3× / 2.4×, the light's recess 4.7× / 3.2× / 2.7×. The cause is not where the
/// narrow faces' own samples lie (their texel reference, paths from the same footprints,
/// agrees with the point reference within the footprint's gradient) but what their rays read:
/// the door's edge sees the jamb's lining 3 mm away, and the lining's texel spans the slot
/// (H/π 0.015 there) and the lining's 1 cm proud of the wall in the room: it holds 0.107, its
/// own texel reference 0.089, and the slot reads that average.
#[test]
#[ignore = "issue 27 item 3 is open: slot faces read the average of the facing texel"]
fn narrow_faces_read_at_most_one_and_a_half_times_their_light() {
    let input = fixture("narrow_faces.gltf");
    let config = BakeConfig::draft();
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
