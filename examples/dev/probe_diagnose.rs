//! Where the probes' error between probes comes from: a per-point decomposition.
//!
//! ```text
//! cargo run --release --example probe_diagnose -- SCENE [QUALITY] [BUDGET] [POINTS] [SAMPLES]
//! ```
//!
//! Bakes `SCENE` with probes on a uniform grid (no refinement) as `probe_figures` does and draws the same free-space points. At
//! each point it path-traces `H/π` about the point's normal at the point and at the eight
//! corners of its grid cell (the corners' probe positions, the same normal), and splits the
//! lookup's error `ours − ref(p)` exactly into
//!
//! - *bake*: `Σ w_c (probe_c − ref_c) / Σ w_c`, the probes' own error at the corners the lookup
//!   used (gather noise, SH truncation), and
//! - *interpolation*: `Σ w_c ref_c / Σ w_c − ref(p)`, the error of interpolating the true field
//!   with the lookup's weights;
//!
//! and reports the interpolation of the true field with plain trilinear weights over all eight
//! corners (nothing dropped) beside it. Each term's relative RMSE is normalised by the mean
//! reference, as `probe_figures` does, with its noise (the traced values' standard errors
//! combined with the weights) taken out.

use std::path::Path;

use glam::Vec3;
use lightbake::probes::ProbeParams;
use lightbake::reference::ReferenceParams;
use lightbake::reference::points::{self, Normals, Point};
use lightbake::trace::Tracer;
use lightbake::{BakeConfig, NoProgress};

/// A point's distance to the nearest emitter texel and its (total, bake, interpolation) error.
type Split = (f32, Vec3, Vec3, Vec3);

/// Relative RMS of `d` with noise variance `v` taken out, over the mean `m`.
fn rel(d: &[Vec3], v: &[Vec3], m: f64) -> (f64, f64) {
    let n = 3.0 * d.len() as f64;
    let sq: f64 = d.iter().map(|x| x.length_squared() as f64).sum::<f64>() / n;
    let var: f64 = v.iter().map(|x| x.element_sum() as f64).sum::<f64>() / n;
    (sq.sqrt() / m, (sq - var).max(0.0).sqrt() / m)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [scene, rest @ ..] = &args[..] else {
        panic!("usage: probe_diagnose SCENE [QUALITY] [BUDGET] [POINTS] [SAMPLES]")
    };
    let quality = rest.first().map_or("medium", String::as_str);
    let mut config = match quality {
        "draft" => BakeConfig::draft(),
        "high" => BakeConfig::high(),
        _ => BakeConfig::medium(),
    };
    // The uniform grid: the lookup below rebuilds its cells' corners.
    let mut params = ProbeParams {
        refine: 0.0,
        ..ProbeParams::default()
    };
    if let Some(b) = rest.get(1) {
        params.budget = b.parse().expect("BUDGET");
    }
    let n: usize = rest.get(2).map_or(300, |s| s.parse().expect("POINTS"));
    let samples: u32 = rest.get(3).map_or(512, |s| s.parse().expect("SAMPLES"));
    config.output.probes = Some(params);
    let baked = lightbake::compute(Path::new(scene), &config, &NoProgress).expect("bake");
    let probes = baked.probes.as_ref().expect("probes");
    let grid = probes.grid.expect("a grid");
    let tracer = Tracer::new(&baked.scene);
    let emitters: Vec<Vec3> = (0..baked.texels.position.len())
        .filter(|&i| baked.texels.emission[i].max_element() > 0.0)
        .map(|i| baked.texels.position[i])
        .collect();
    println!(
        "{scene}: grid {:?} step {:.3}, {} emitter texels",
        grid.count,
        grid.step.x,
        emitters.len()
    );
    let at = probes.points_between(&tracer, n, 3, false);
    // The eight corners of each point's cell, their trilinear weights and whether the lookup
    // keeps them (valid and visible).
    let mut corners: Vec<[(usize, f32, bool); 8]> = Vec::new();
    let mut local = Vec::new();
    for &(p, nrm) in &at {
        let g = grid.local(p);
        local.push(g);
        let mut c8 = [(0usize, 0.0f32, false); 8];
        let mut base = [0u32; 3];
        let mut frac = [0f32; 3];
        for a in 0..3 {
            let last = grid.count[a] - 1;
            let x = g[a].clamp(0.0, last as f32);
            let i = (x.floor() as u32).min(grid.count[a] - 2);
            base[a] = i;
            frac[a] = x - i as f32;
        }
        for (corner, slot) in c8.iter_mut().enumerate() {
            let mut w = 1.0;
            let mut ijk = base;
            for a in 0..3 {
                if (corner >> a) & 1 == 1 {
                    ijk[a] += 1;
                    w *= frac[a];
                } else {
                    w *= 1.0 - frac[a];
                }
            }
            let q = (ijk[0] + grid.count[0] * (ijk[1] + grid.count[1] * ijk[2])) as usize;
            let keep =
                probes.valid[q] && !tracer.occluded(p + nrm * tracer.epsilon, probes.position[q]);
            *slot = (q, w, keep);
        }
        corners.push(c8);
    }
    // Reference at the points, then at every point's corners about the point's normal.
    let mut pts: Vec<Point> = at
        .iter()
        .map(|&(position, normal)| Point {
            position,
            normal,
            shading_normal: normal,
        })
        .collect();
    for (k, &(_, normal)) in at.iter().enumerate() {
        for &(q, _, _) in &corners[k] {
            pts.push(Point {
                position: probes.position[q],
                normal,
                shading_normal: normal,
            });
        }
    }
    let reference = ReferenceParams {
        max_samples: samples,
        seed: 7,
        ..ReferenceParams::like(&baked.config)
    };
    let r = points::trace_about(
        (&baked.scene, &baked.texels, &tracer),
        &pts,
        Normals::Shading,
        &reference,
        &NoProgress,
    )
    .expect("reference");
    let m = at.len();
    let mean: f64 = r.mean[..m]
        .iter()
        .map(|v| v.element_sum() as f64)
        .sum::<f64>()
        / (3.0 * m as f64);
    let (mut total, mut total_v) = (Vec::new(), Vec::new());
    let (mut bake, mut bake_v) = (Vec::new(), Vec::new());
    let (mut interp, mut interp_v) = (Vec::new(), Vec::new());
    let (mut full, mut full_v) = (Vec::new(), Vec::new());
    let mut rows = Vec::new();
    for k in 0..m {
        let (p, nrm) = at[k];
        let ours = probes.irradiance_over_pi(p, nrm, Some(&tracer));
        let rp = r.mean[k];
        let sp = r.std_error[k] * r.std_error[k];
        let (mut wsum, mut b, mut it, mut itv) = (0.0f32, Vec3::ZERO, Vec3::ZERO, Vec3::ZERO);
        let (mut f, mut fv) = (Vec3::ZERO, Vec3::ZERO);
        let mut dropped = 0;
        for (c, &(q, w, keep)) in corners[k].iter().enumerate() {
            let j = m + 8 * k + c;
            let rc = r.mean[j];
            let vc = r.std_error[j] * r.std_error[j];
            f += w * rc;
            fv += w * w * vc;
            if keep {
                let pc = lightbake::probes::sh::irradiance_over_pi(&probes.sh[q], nrm);
                wsum += w;
                b += w * (pc - rc);
                it += w * rc;
                itv += w * w * vc;
            } else if w > 0.0 {
                dropped += 1;
            }
        }
        if wsum <= 1e-6 {
            continue;
        }
        b /= wsum;
        it /= wsum;
        itv /= wsum * wsum;
        total.push(ours - rp);
        total_v.push(sp);
        bake.push(b);
        bake_v.push(itv);
        interp.push(it - rp);
        interp_v.push(itv + sp);
        full.push(f - rp);
        full_v.push(fv + sp);
        let d = emitters
            .iter()
            .map(|e| e.distance(p))
            .fold(f32::INFINITY, f32::min);
        rows.push((
            (ours - rp).length_squared(),
            k,
            ours.x,
            rp.x,
            r.std_error[k].x,
            b.x,
            (it - rp).x,
            (f - rp).x,
            dropped,
            d,
        ));
    }
    println!(
        "{} points (cells with a kept corner), mean reference {mean:.4}; relative RMSE (raw, noise out):",
        total.len()
    );
    for (name, d, v) in [
        ("lookup's total", &total, &total_v),
        ("bake at the kept corners", &bake, &bake_v),
        ("interpolating the true field (kept)", &interp, &interp_v),
        ("interpolating the true field (all 8)", &full, &full_v),
    ] {
        let (raw, clean) = rel(d, v, mean);
        println!("  {name:38} {:6.2}% {:6.2}%", 100.0 * raw, 100.0 * clean);
    }
    rows.sort_by(|a, b| b.0.total_cmp(&a.0));
    let all: f32 = rows.iter().map(|r| r.0).sum();
    let mut acc = 0.0;
    for (i, r) in rows.iter().enumerate() {
        acc += r.0;
        if acc >= 0.5 * all {
            println!("  half the squared error in the worst {} points", i + 1);
            break;
        }
    }
    println!(
        "  worst points (red channel): p, cell coords, n, ours, ref ± se, bake, interp(kept), interp(all), dropped, distance to nearest emitter texel"
    );
    for r in rows.iter().take(20) {
        let k = r.1;
        println!(
            "  {:6.3} g {:5.2} n {:5.2}: {:.3} {:.3}±{:.3} bake {:+.3} interp {:+.3} all8 {:+.3} drop {} d {:.3}",
            at[k].0, local[k], at[k].1, r.2, r.3, r.4, r.5, r.6, r.7, r.8, r.9
        );
    }
    // Error against distance to the emitters.
    let mut by_d: Vec<Split> = Vec::new();
    let mut idx = 0;
    for k in 0..m {
        let p = at[k].0;
        if corners[k].iter().all(|c| !c.2) {
            continue;
        }
        let d = emitters
            .iter()
            .map(|e| e.distance(p))
            .fold(f32::INFINITY, f32::min);
        by_d.push((d, total[idx], bake[idx], interp[idx]));
        idx += 1;
    }
    for (lo, hi) in [(0.0, 0.25), (0.25, 0.5), (0.5, 1.0), (1.0, 100.0)] {
        let sel: Vec<_> = by_d.iter().filter(|x| x.0 >= lo && x.0 < hi).collect();
        let sq = |f: &dyn Fn(&Split) -> Vec3| {
            sel.iter()
                .map(|x| f(x).length_squared() as f64)
                .sum::<f64>()
                / (3.0 * total.len() as f64)
        };
        println!(
            "  emitter distance {lo:.2}..{hi:.2}: {} points, share of total squared error {:.0}%, bake {:.0}%, interp {:.0}%",
            sel.len(),
            100.0 * sq(&|x| x.1) / (rel(&total, &[], 1.0).0.powi(2)),
            100.0 * sq(&|x| x.2) / (rel(&total, &[], 1.0).0.powi(2)),
            100.0 * sq(&|x| x.3) / (rel(&total, &[], 1.0).0.powi(2)),
        );
    }
}
