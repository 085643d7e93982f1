//! Directional lightmaps (`lightmap::directional`): irradiance reconstructed from the L1 pages
//! at normals tilted 30° and 60° from the surface, against the path tracer at those normals.
//!
//! Run with `--nocapture` to see the figures the README quotes.

use std::f32::consts::PI;

use glam::Vec3;
use lightbake::lightmap::directional::{self, DirectionalParams, Gatherer, Sh1};
use lightbake::reference::ReferenceParams;
use lightbake::reference::points::{self, Point};
use lightbake::sampling::frame;
use lightbake::trace::Tracer;
use lightbake::transport::Surfaces;
use lightbake::{BakeConfig, Baked, NoProgress, compute, metrics};

use crate::util::fixture;

/// Texels checked per fixture (every n-th valid one).
const TEXELS: usize = 120;

/// Errors relative to the reference's mean at one tilt (see [`tilted_errors`]).
#[derive(Debug)]
pub struct TiltErrors {
    /// L1 reconstruction against the path tracer (the reference's noise taken out).
    pub l1: f32,
    /// The expected L1 truncation error: the reconstruction against the clamped-cosine
    /// integral of the gather's own samples about the tilted normal.
    pub truncation: f32,
    /// That integral against the path tracer: the gather's and the solution's own error.
    pub gather: f32,
    /// The plain lightmap (the surface normal's `H/π`) against the path tracer: what a
    /// renderer without directional pages shows.
    pub flat: f32,
}

/// The coefficients of texel `i` as the pages hold them.
fn coefficients(baked: &Baked, i: usize) -> Sh1 {
    let (pages, _) = baked
        .directional
        .as_ref()
        .expect("baked with directional pages");
    let t = &baked.texels;
    let [x, y] = t.xy[i];
    std::array::from_fn(|c| {
        let page = &pages[c].pages[t.page[i] as usize];
        page.rgb[(y * page.width + x) as usize]
    })
}

/// Bakes `name` at draft with directional pages and measures, at `TEXELS` texels with the
/// normal tilted by each of `tilts` (degrees) about an axis turning from texel to texel.
pub fn tilted_errors(name: &str, tilts: &[f32]) -> Vec<TiltErrors> {
    let mut config = BakeConfig::draft();
    config.output.directional = Some(directional::DEFAULT_RAYS);
    let baked = compute(&fixture(name), &config, &NoProgress).unwrap();
    let t = &baked.texels;
    let valid = t.valid_mask();
    let ids: Vec<usize> = (0..t.len()).filter(|&i| valid[i]).collect();
    let ids: Vec<usize> = ids
        .iter()
        .step_by((ids.len() / TEXELS).max(1))
        .copied()
        .collect();
    let tracer = Tracer::new(&baked.scene);
    let surfaces = Surfaces {
        scene: &baked.scene,
        texels: t,
        tracer: &tracer,
    };
    let params = DirectionalParams {
        rays: directional::DEFAULT_RAYS,
        seed: config.transport.seed,
        sky: config.transport.sky,
        indirect_only: false,
    };
    let gatherer = Gatherer::new(surfaces, &baked.solution.irradiance, &params);
    let reference = ReferenceParams {
        max_samples: 1024,
        ..ReferenceParams::like(&baked.config)
    };
    tilts
        .iter()
        .map(|&deg| {
            let normals: Vec<Vec3> = ids
                .iter()
                .map(|&i| {
                    let n = t.normal[i];
                    let (a, b) = frame(n);
                    let phi = i as f32 * 2.399_963; // the golden angle: axes spread evenly
                    let axis = a * phi.cos() + b * phi.sin();
                    let theta = deg.to_radians();
                    n * theta.cos() + axis * theta.sin()
                })
                .collect();
            let pts: Vec<Point> = ids
                .iter()
                .zip(&normals)
                .map(|(&i, &m)| Point {
                    position: t.position[i],
                    normal: t.normal[i],
                    shading_normal: m,
                })
                .collect();
            let traced =
                points::trace_perturbed(&baked.scene, t, &tracer, &pts, &reference, &NoProgress).unwrap();
            let l1: Vec<Vec3> = ids
                .iter()
                .zip(&normals)
                .map(|(&i, &m)| directional::irradiance_over_pi(&coefficients(&baked, i), m))
                .collect();
            let gathered: Vec<Vec3> = ids
                .iter()
                .zip(&normals)
                .map(|(&i, &m)| {
                    let mut e = Vec3::ZERO;
                    gatherer.incident(i, |dir, l| e += l * (m.dot(dir).max(0.0) / PI));
                    e
                })
                .collect();
            let flat: Vec<Vec3> = ids.iter().map(|&i| baked.lightmap[i]).collect();
            let noise = metrics::noise_over_mean(&traced.std_error, &traced.mean, &[]);
            let vs_reference = |x: &[Vec3]| {
                metrics::without_noise(metrics::rmse_over_mean(x, &traced.mean, &[]), noise)
            };
            let errors = TiltErrors {
                l1: vs_reference(&l1),
                truncation: metrics::rmse_over_mean(&l1, &gathered, &[]),
                gather: vs_reference(&gathered),
                flat: vs_reference(&flat),
            };
            println!(
                "{name} tilt {deg}°: L1 vs reference {:.1}%, expected truncation {:.1}%, gather vs reference {:.1}%, plain lightmap vs reference {:.1}% (reference noise {:.1}%, {} texels)",
                errors.l1 * 100.0,
                errors.truncation * 100.0,
                errors.gather * 100.0,
                errors.flat * 100.0,
                noise * 100.0,
                ids.len()
            );
            errors
        })
        .collect()
}

/// The acceptance test of issue 16 item 3, on the Cornell box (a small emitter: strongly
/// directional light near it) and the spot-and-directional scene (punctual lights and their
/// bounce): at 30° and 60° the gather itself is within the draft bake's error budget (8%) of
/// the path tracer, the reconstruction is within the expected truncation error plus that
/// budget, and it is closer to the path tracer than the plain lightmap.
#[test]
fn tilted_normals_match_the_path_tracer_within_the_truncation_error() {
    for name in ["cornell_box.gltf", "spot_and_directional.gltf"] {
        for (tilt, e) in [30.0, 60.0].iter().zip(tilted_errors(name, &[30.0, 60.0])) {
            assert!(e.gather <= 0.08, "{name} {tilt}°: {e:?}");
            assert!(e.l1 <= e.truncation + 0.08, "{name} {tilt}°: {e:?}");
            assert!(e.l1 < e.flat, "{name} {tilt}°: {e:?}");
        }
    }
}
