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
//!
//! ```text
//! cargo run --release --example probe_diagnose -- SCENE QUALITY BUDGET PROBES SAMPLES truncation
//! ```
//!
//! The probes' own error beside the emitters (the default refined bake): at up to `PROBES` valid,
//! gathered probes closest to an emitter (and as many far ones), the path tracer's `H/π` about 256
//! normals spread over the sphere (a Fibonacci set) is projected onto L2 SH by quadrature; that
//! projection is what a perfect L2 probe would hold. The probe's error against the path tracer
//! splits into the truncation (projection − path tracer) and the bake's own (probe −
//! projection), over all normals and over the normals facing the nearest emitter.

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
    if rest.get(4).map(String::as_str) == Some("truncation") {
        return truncation(scene, config, rest);
    }
    // The uniform grid: the lookup below rebuilds its cells' corners.
    let mut params = ProbeParams {
        refine: 0.0,
        ..ProbeParams::default()
    };
    if let Some(b) = rest.get(1) {
        params.budget = Some(b.parse().expect("BUDGET"));
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
        .map(|&(position, normal)| Point::free(position, normal))
        .collect();
    for (k, &(_, normal)) in at.iter().enumerate() {
        for &(q, _, _) in &corners[k] {
            pts.push(Point::free(probes.position[q], normal));
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

/// Normals of the quadrature.
const NORMALS: usize = 256;

/// The `truncation` mode (see the module docs).
fn truncation(scene: &str, mut config: BakeConfig, rest: &[String]) {
    use lightbake::probes::{measure, sh};
    let mut params = ProbeParams::default();
    if let Some(b) = rest.get(1) {
        params.budget = Some(b.parse().expect("BUDGET"));
    }
    let count: usize = rest.get(2).map_or(16, |s| s.parse().expect("PROBES"));
    let samples: u32 = rest.get(3).map_or(1024, |s| s.parse().expect("SAMPLES"));
    config.output.probes = Some(params);
    let baked = lightbake::compute(Path::new(scene), &config, &NoProgress).expect("bake");
    let probes = baked.probes.as_ref().expect("probes");
    let tracer = Tracer::new(&baked.scene);
    let near_field = measure::near_field(&baked.scene, probes.budget);
    // Valid probes by distance to the nearest emitter texel (with that texel).
    let emitters: Vec<Vec3> = (0..baked.texels.position.len())
        .filter(|&i| baked.texels.emission[i].max_element() > 0.0)
        .map(|i| baked.texels.position[i])
        .collect();
    let nearest = |p: Vec3| {
        (emitters.iter().copied())
            .min_by(|a, b| a.distance(p).total_cmp(&b.distance(p)))
            .unwrap_or(p)
    };
    // Gathered probes only: a node refinement holds at its coarser cell's interpolated value
    // carries that cell's interpolation error, not a gather's.
    let gathered = probes.gathered();
    let mut by_distance: Vec<(f32, usize)> = (0..probes.len())
        .filter(|&q| probes.valid[q] && gathered[q])
        .map(|q| (nearest(probes.position[q]).distance(probes.position[q]), q))
        .collect();
    by_distance.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let far_from = by_distance.partition_point(|d| d.0 < near_field);
    let chosen: Vec<(f32, usize)> = (by_distance.iter().take(count.min(far_from)))
        .chain(
            by_distance[far_from..]
                .iter()
                .step_by(((by_distance.len() - far_from) / count).max(1))
                .take(count),
        )
        .copied()
        .collect();
    // A Fibonacci set of normals, equal weights 4π/M.
    let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
    let normals: Vec<Vec3> = (0..NORMALS)
        .map(|k| {
            let z = 1.0 - (2.0 * k as f32 + 1.0) / NORMALS as f32;
            let r = (1.0 - z * z).sqrt();
            let phi = golden * k as f32;
            Vec3::new(r * phi.cos(), r * phi.sin(), z)
        })
        .collect();
    // Beside the emitter texels nearest to the four nearest probes: points 2, 5 and 10 cm off
    // the emitter along its normal (no probe there: the truncation alone).
    let texel_of = |p: Vec3| {
        (0..baked.texels.position.len())
            .filter(|&i| baked.texels.emission[i].max_element() > 0.0)
            .min_by(|&a, &b| {
                let da = baked.texels.position[a].distance(p);
                da.total_cmp(&baked.texels.position[b].distance(p))
            })
            .expect("an emitter")
    };
    let close: Vec<(f32, Vec3)> = (chosen.iter().take(4))
        .flat_map(|&(_, q)| {
            let t = texel_of(probes.position[q]);
            let (e, n) = (baked.texels.position[t], baked.texels.normal[t]);
            [0.02f32, 0.05, 0.1].map(|d| (d, e + n * d))
        })
        .collect();
    let sites: Vec<Vec3> = (chosen.iter().map(|&(_, q)| probes.position[q]))
        .chain(close.iter().map(|c| c.1))
        .collect();
    let pts: Vec<Point> = (sites.iter())
        .flat_map(|&position| {
            normals.iter().map(move |&n| Point {
                position,
                normal: n,
                shading_normal: n,
            })
        })
        .collect();
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
    println!(
        "{scene}: {} probes, near field {near_field:.3}; per probe, relative RMS over the normals (over their mean; all normals | facing the emitter): probe vs path tracer and L2 projection vs path tracer (truncation), both without the noise, probe vs projection (bake), noise",
        probes.len()
    );
    // Sums over the near and the far probes: (probe−ref)², (proj−ref)², (probe−proj)², σ², ref.
    let mut sums = [[0.0f64; 5]; 2];
    for (c, &site) in sites.iter().enumerate() {
        let (d, q) = match chosen.get(c) {
            Some(&(d, q)) => (d, Some(q)),
            None => (close[c - chosen.len()].0, None),
        };
        let e = &r.mean[c * NORMALS..(c + 1) * NORMALS];
        let se = &r.std_error[c * NORMALS..(c + 1) * NORMALS];
        // L2 projection of the irradiance: E_lm = 4π/M Σ E(n) Y_lm(n) (per channel).
        let mut proj = [Vec3::ZERO; 9];
        for (k, &n) in normals.iter().enumerate() {
            let y = sh::basis(n);
            for m in 0..9 {
                proj[m] += e[k] * y[m] * (4.0 * std::f32::consts::PI / NORMALS as f32);
            }
        }
        let projected = |n: Vec3| {
            let y = sh::basis(n);
            (0..9).fold(Vec3::ZERO, |s, m| s + proj[m] * y[m])
        };
        let toward = (nearest(site) - site).normalize_or_zero();
        let mut row = [[0.0f64; 5]; 2];
        for (k, &n) in normals.iter().enumerate() {
            let p = projected(n);
            let ours = q.map_or(p, |q| sh::irradiance_over_pi(&probes.sh[q], n));
            let terms = [
                (ours - e[k]).length_squared(),
                (p - e[k]).length_squared(),
                (ours - p).length_squared(),
                se[k].length_squared(),
                e[k].element_sum() / 3.0,
            ];
            for (part, keep) in [(0, true), (1, n.dot(toward) > 0.5)] {
                if keep {
                    for t in 0..5 {
                        row[part][t] += terms[t] as f64;
                    }
                }
            }
        }
        if q.is_some() {
            let near = usize::from(d >= near_field);
            for t in 0..5 {
                sums[near][t] += row[0][t];
            }
        }
        // Noise taken out of the terms against the path tracer.
        let rel = |row: &[f64; 5], n: f64| {
            let mean = row[4] / n;
            let f = |t: usize| (row[t] / (3.0 * n)).sqrt() / mean;
            let clean = |t: usize| 100.0 * (f(t) * f(t) - f(3) * f(3)).max(0.0).sqrt();
            format!(
                "{:5.1}% {:5.1}% {:5.1}% ±{:4.1}%",
                clean(0),
                clean(1),
                100.0 * f(2),
                100.0 * f(3)
            )
        };
        let facing = normals.iter().filter(|n| n.dot(toward) > 0.5).count() as f64;
        println!(
            "  {} at {site:.3}, emitter {d:.3} away: {} | {}",
            q.map_or("point     ".into(), |q| format!("probe {q:4}")),
            rel(&row[0], NORMALS as f64),
            rel(&row[1], facing)
        );
    }
    for (part, name) in [(0, "near"), (1, "far")] {
        let s = &sums[part];
        let count = chosen
            .iter()
            .filter(|c| usize::from(c.0 >= near_field) == part)
            .count() as f64
            * NORMALS as f64;
        if count == 0.0 {
            continue;
        }
        let mean = s[4] / count;
        let g = |t: usize| (s[t] / (3.0 * count)).sqrt() / mean;
        let clean = |t: usize| 100.0 * (g(t) * g(t) - g(3) * g(3)).max(0.0).sqrt();
        println!(
            "{name} probes (noise taken out): probe vs path tracer {:.1}% (noise {:.1}%), truncation {:.1}%, bake vs projection {:.1}%",
            clean(0),
            100.0 * g(3),
            clean(1),
            100.0 * g(2)
        );
    }
}
