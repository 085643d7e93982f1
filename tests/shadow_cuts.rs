//! Shadow cuts: along the sun shadow of the courtyard's low wall, what a renderer shows of a
//! draft bake agrees with the path tracer far better with the cuts than without.

use glam::Vec3;
use lightbake::reference::ReferenceParams;
use lightbake::reference::points::{self, PointReference, PointSet};
use lightbake::render::RenderScene;
use lightbake::{BakeConfig, NoProgress};

use crate::util::{fixture, scratch};

fn draft(shadow_cuts: bool) -> BakeConfig {
    let mut config = BakeConfig::draft();
    config.atlas.shadow_cuts = shadow_cuts;
    config
}

/// Relative RMSE of a bake of fixture `name` with `config`, read as a renderer reads it, at
/// `reference`'s points, and the reference's noise.
fn point_error(name: &str, config: &BakeConfig, reference: &PointReference) -> (f32, f32) {
    let dir = scratch();
    lightbake::bake(&fixture(name), dir.path(), config, &NoProgress).expect("bakes");
    let stem = name.rsplit_once('.').map_or(name, |(stem, _)| stem);
    let gltf = dir.path().join(format!("{stem}.gltf"));
    let baked = RenderScene::load(&gltf).expect("loads");
    let c = points::compare(&baked, reference);
    (c.rmse, c.noise)
}

/// [`point_error`] of the courtyard at draft, with or without shadow cuts.
fn error(reference: &PointReference, shadow_cuts: bool) -> (f32, f32) {
    point_error("courtyard.gltf", &draft(shadow_cuts), reference)
}

/// The ground within one draft texel (12.5 cm) of the shadow edge the low wall's top casts
/// (wall 1.2 m high, its far face at z = 1.5; the edge's middle 2.4 m), drawn from 65536
/// visible points, 256 paths each. Measured: 1.4% with the cuts, 43.6% without (138 points,
/// reference noise 1.2%): without them the bilinear lookup blurs the step over a texel on each
/// side.
#[test]
fn the_courtyard_s_sun_shadow_edge_is_sharp_in_a_draft_bake() {
    let p = lightbake::prepare(&fixture("courtyard.gltf"), &draft(false), &NoProgress)
        .expect("prepares");
    let sun = p.scene.lights[0].direction;
    let shift = sun * (1.2 / -sun.y);
    let edge = Vec3::new(0.0, 0.0, 1.5) + shift;
    let all = points::draw(&p.scene, &p.tracer, 65536, 7).expect("draws");
    let strip = PointSet {
        points: all
            .points
            .into_iter()
            .filter(|q| {
                q.normal.y > 0.9
                    && (q.position.z - edge.z).abs() < 0.125
                    && (q.position.x - edge.x).abs() < 1.2
            })
            .collect(),
        hidden: 0,
    };
    assert!(strip.points.len() > 60, "{} points", strip.points.len());
    let params = ReferenceParams {
        max_samples: 256,
        ..ReferenceParams::default()
    };
    let traced = points::trace(
        &p.scene,
        &p.texels,
        &p.tracer,
        &strip.points,
        &params,
        &NoProgress,
    )
    .expect("traces");
    let reference = PointReference::new(strip, &traced);
    let ((on, noise), (off, _)) = (error(&reference, true), error(&reference, false));
    eprintln!(
        "strip of {} points: {on} with the cuts, {off} without, reference noise {noise}",
        reference.points.len()
    );
    assert!(on < 0.05, "strip error with the cuts {on}");
    assert!(off > 0.25, "strip error without the cuts {off}");
}

/// [`point_error`] of `sphere_on_floor.gltf` at draft with shadow cuts, stitched or not.
fn sphere_error(reference: &PointReference, seams: bool) -> (f32, f32) {
    let mut config = draft(true);
    config.output.seams = seams;
    point_error("sphere_on_floor.gltf", &config, reference)
}

/// Seam stitching leaves the sphere's hard shadow alone: on the floor around the shadow of the
/// sphere (point light at (0.8, 2, 0.6), sphere r = 0.5 at (0, 0.5, 0); the outline crosses
/// z = 0 at x = 0.395 and −1.07) a stitched draft bake is no worse than an unstitched one.
/// Before the extensions of the outline's free ends were kept out of stitching they hugged the
/// outline and the stitch pulled lit and shadowed texels together: measured 15.7% stitched
/// against 3.2% unstitched there (5324 points, reference noise 1.0%; whole scene 9.28%
/// against 2.81%); now 3.1% stitched.
#[test]
fn stitching_does_not_blur_the_sphere_s_hard_shadow() {
    let p = lightbake::prepare(&fixture("sphere_on_floor.gltf"), &draft(true), &NoProgress)
        .expect("prepares");
    let all = points::draw(&p.scene, &p.tracer, 16384, 11).expect("draws");
    let around = PointSet {
        points: all
            .points
            .into_iter()
            .filter(|q| {
                q.normal.y > 0.9
                    && (-1.4..0.8).contains(&q.position.x)
                    && (-0.8..0.9).contains(&q.position.z)
            })
            .collect(),
        hidden: 0,
    };
    assert!(around.points.len() > 300, "{} points", around.points.len());
    let params = ReferenceParams {
        max_samples: 256,
        ..ReferenceParams::default()
    };
    let traced = points::trace(
        &p.scene,
        &p.texels,
        &p.tracer,
        &around.points,
        &params,
        &NoProgress,
    )
    .expect("traces");
    let reference = PointReference::new(around, &traced);
    let ((stitched, noise), (open, _)) = (
        sphere_error(&reference, true),
        sphere_error(&reference, false),
    );
    eprintln!(
        "{} floor points around the shadow: {stitched} stitched, {open} unstitched, reference noise {noise}",
        reference.points.len()
    );
    assert!(
        stitched <= 1.2 * open + 0.005,
        "stitched {stitched} against unstitched {open}"
    );
}
