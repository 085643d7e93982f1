//! The lightmap denoiser: lower error against the path-traced reference at low ray counts, no
//! harm at high ray counts, and hard shadow edges kept.

use std::path::Path;
use std::sync::OnceLock;

use glam::Vec3;
use lightbake::lightmap::denoise::{DenoiseParams, denoise};
use lightbake::reference::{self, ReferenceParams};
use lightbake::testing::{Face, Geometry, GltfBuilder, Light, Material};
use lightbake::{BakeConfig, Baked, NoProgress, compute, metrics};

use crate::util::{fixture, quick, scratch};

fn cornell_config(gather_rays: u32, denoise: bool) -> BakeConfig {
    let mut c = quick();
    c.atlas.texels_per_unit = 16.0;
    c.transport.gather_rays = gather_rays;
    c.transport.light_samples = gather_rays.min(64);
    c.transport.denoise = denoise;
    c
}

/// The path-traced Cornell box at the texels of `cornell_config` (texels depend only on the
/// atlas settings) and its invalid texels, computed once.
fn cornell_reference() -> &'static (Vec<Vec3>, Vec<u32>) {
    static REFERENCE: OnceLock<(Vec<Vec3>, Vec<u32>)> = OnceLock::new();
    REFERENCE.get_or_init(|| {
        let config = cornell_config(16, true);
        let params = ReferenceParams {
            max_samples: 2048,
            ..ReferenceParams::like(&config)
        };
        let c = reference::compute(&fixture("cornell_box.gltf"), &config, &params, &NoProgress)
            .unwrap();
        (c.reference.mean, c.texels.invalid)
    })
}

/// Relative RMS error of a Cornell bake against the reference, every valid texel (above 1e-3)
/// counting alike ([`metrics::rms_texel_relative_error`], channel sums).
fn cornell_error(gather_rays: u32, denoise: bool) -> f32 {
    let (mean, invalid) = cornell_reference();
    let baked = compute(
        &fixture("cornell_box.gltf"),
        &cornell_config(gather_rays, denoise),
        &NoProgress,
    )
    .unwrap();
    assert_eq!(baked.lightmap.len(), mean.len());
    let compared = (0..mean.len())
        .filter(|&i| invalid.binary_search(&(i as u32)).is_err() && mean[i].element_sum() > 1e-3)
        .count();
    assert!(compared > 1000, "{compared} texels compared");
    metrics::rms_texel_relative_error(&baked.lightmap, mean, invalid, 1e-3)
}

#[test]
fn lowers_the_error_at_low_ray_counts() {
    let raw = cornell_error(16, false);
    let denoised = cornell_error(16, true);
    eprintln!("Cornell box, K = 16: relative RMSE {raw:.4} -> {denoised:.4} denoised");
    assert!(denoised < 0.8 * raw, "{raw} -> {denoised}");
}

#[test]
fn does_not_raise_the_error_at_high_ray_counts() {
    let raw = cornell_error(512, false);
    let denoised = cornell_error(512, true);
    eprintln!("Cornell box, K = 512: relative RMSE {raw:.4} -> {denoised:.4} denoised");
    // Where noise is this low the filter's bias shows: measured 0.0341 -> 0.0360 (×1.056) on
    // the atlas that charted the floor in xatlas blocks, 0.0336 -> 0.0358 (×1.065) with the
    // floor one chart (a lower raw error, the same denoised one). 8% leaves room for layouts.
    assert!(denoised < 1.08 * raw, "{raw} -> {denoised}");
}

/// Grey floor under a slab x ∈ [−½, ½] (across the whole floor), sun straight down: the floor
/// has a shadow band with straight edges at x = ±½ (1/π lit, only weak indirect light inside).
fn slab_shadow() -> GltfBuilder {
    let mut gltf = GltfBuilder::new("slab_shadow");
    let grey = gltf.add_material(Material::grey("grey", 0.5));
    let floor = Geometry::grid(
        Vec3::new(-2.0, 0.0, 2.0),
        Vec3::X * 4.0,
        -Vec3::Z * 4.0,
        4,
        4,
    );
    let mesh = gltf.add_mesh("floor", floor, grey);
    gltf.add_mesh_node("floor", mesh);
    let slab = Geometry::box_faces(
        Vec3::new(-0.5, 0.5, -2.5),
        Vec3::new(0.5, 0.6, 2.5),
        &[
            Face::PosX,
            Face::NegX,
            Face::PosY,
            Face::NegY,
            Face::PosZ,
            Face::NegZ,
        ],
        2,
    );
    let mesh = gltf.add_mesh("slab", slab, grey);
    gltf.add_mesh_node("slab", mesh);
    gltf.add_light_node(
        Light::directional("sun", [1.0; 3], 1.0),
        Vec3::new(0.0, 3.0, 0.0),
        Vec3::NEG_Y,
    );
    gltf
}

/// Worst change, as a fraction of the lit level, of floor texels of the slab scene farther than
/// `band` texels from the geometric shadow edge, and how many there are.
fn change_outside_edge_band(baked: &Baked, raw: &[Vec3], band: f32) -> (f32, usize) {
    let t = &baked.texels;
    let texel = 1.0 / 16.0;
    let lit = 3.0 / std::f32::consts::PI;
    let (mut worst, mut checked) = (0.0f32, 0);
    for (i, (p, n)) in t.position.iter().zip(&t.normal).enumerate() {
        let edge_distance = (p.x.abs() - 0.5).abs() / texel;
        if n.y < 0.99 || p.y > 0.01 || edge_distance < band || p.z.abs() > 1.8 {
            continue;
        }
        worst = worst.max((baked.lightmap[i] - raw[i]).element_sum().abs() / lit);
        checked += 1;
    }
    (worst, checked)
}

/// Beyond `EDGE_BAND` texels from the geometric shadow edge, denoising moves no floor texel by
/// more than 3 % of the lit level: the edge is not blurred wider than that band. A weak sky makes
/// the noise model count direct light as sampled (the harder case); a filter with an unbounded
/// range kernel fails the same check.
#[test]
fn keeps_hard_shadow_edges() {
    const EDGE_BAND: f32 = 1.5;
    let dir = scratch();
    let path = dir.path().join("slab_shadow.gltf");
    slab_shadow().write_gltf(&path).unwrap();
    let bake = |denoise: bool| {
        let mut c = cornell_config(32, denoise);
        c.transport.light_samples = 16;
        c.transport.sky = Vec3::splat(0.05);
        // The edge within one chart, as the filter must keep it (shadow cuts would end the
        // chart there, and no filter would reach across).
        c.atlas.shadow_cuts = false;
        compute(Path::new(&path), &c, &NoProgress).unwrap()
    };
    let (raw, mut denoised) = (bake(false), bake(true));
    let (worst, checked) = change_outside_edge_band(&denoised, &raw.lightmap, EDGE_BAND);
    eprintln!(
        "slab shadow: {checked} floor texels beyond {EDGE_BAND} texels of the edge, worst change {worst:.4} of the lit level"
    );
    assert!(checked > 1000);
    assert!(worst < 0.03, "worst change {worst} of the lit level");

    // Control: ignoring the values (huge noise) blurs the edge across the band.
    denoised.lightmap = raw.lightmap.clone();
    let noise = vec![1e3; raw.lightmap.len()];
    denoise(
        &raw.texels,
        &mut denoised.lightmap,
        &noise,
        &DenoiseParams::default(),
        &lightbake::NoProgress,
    )
    .unwrap();
    let (blurred, _) = change_outside_edge_band(&denoised, &raw.lightmap, EDGE_BAND);
    assert!(
        blurred > 0.06,
        "a value-blind filter changed at most {blurred}"
    );
}
