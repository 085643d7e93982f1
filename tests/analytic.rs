//! Scenes with closed-form answers: the furnace and a point light over a black floor.

use std::f32::consts::PI;

use lightbake::{NoProgress, compute, metrics};

use crate::util::{fixture, quick};

/// Closed box, every face ρ and Le = 1: H/π = Le/(1−ρ) at every texel.
fn furnace(name: &str, rho: f32, tolerance: f32) {
    let mut config = quick();
    config.transport.gather_rays = 128;
    config.solve.tolerance = 1e-5;
    let baked = compute(&fixture(name), &config, &NoProgress).unwrap();
    let expected = 1.0 / (1.0 - rho);
    let worst = metrics::max_relative_deviation(&baked.lightmap, expected);
    assert!(baked.solution.converged);
    assert!(
        worst < tolerance,
        "{name}: worst relative error {worst} (expected {expected})"
    );
}

#[test]
fn furnace_rho_05_within_1_percent() {
    furnace("furnace.gltf", 0.5, 0.01);
}

#[test]
fn furnace_rho_09_within_1_percent() {
    furnace("furnace_09.gltf", 0.9, 0.01);
}

/// Point light of intensity I at height d over a black floor: H/π = I cos³θ / (π d²).
#[test]
fn point_light_cos_cubed() {
    let (intensity, height) = (10.0f32, 2.0f32);
    let baked = compute(&fixture("point_light.gltf"), &quick(), &NoProgress).unwrap();
    let t = &baked.texels;
    let mut checked = 0;
    for target in [0.0f32, 0.5, 1.0, 1.5] {
        // The texel whose centre is nearest to (target, 0, 0).
        let i = (0..t.len())
            .min_by(|&a, &b| {
                let da = (t.position[a] - glam::Vec3::new(target, 0.0, 0.0)).length();
                let db = (t.position[b] - glam::Vec3::new(target, 0.0, 0.0)).length();
                da.total_cmp(&db)
            })
            .unwrap();
        let p = t.position[i];
        let r = (p - glam::Vec3::new(0.0, height, 0.0)).length();
        let cos = height / r;
        let expected = intensity * cos / (PI * r * r);
        let got = baked.lightmap[i];
        for c in got.to_array() {
            assert!(
                (c - expected).abs() / expected < 0.01,
                "at {p}: got {c}, expected {expected}"
            );
        }
        checked += 1;
    }
    assert_eq!(checked, 4);
}
