//! Light probes against the path tracer: the figures of the guide's "Light probes" section.
//!
//! ```text
//! cargo run --release --example probe_figures -- SCENE [QUALITY] [BUDGET] [POINTS] [SAMPLES] [RAYS] [REFINE[:LEVELS[:NOISY]]...]
//! ```
//!
//! Bakes `SCENE` at `QUALITY` (draft, medium or high; default medium) with `BUDGET` probes
//! (default, or `auto`: the library's, following the bake's rays) of `RAYS` rays each (default the library's), once per `REFINE` share
//! of the budget kept for refinement, divided over at most `LEVELS` levels (default the
//! library's; default: 0, the uniform grid, then the library's default share), the second half
//! of a probe's rays cast where its first half's noise is above `NOISY` of the light's scale
//! (default the library's `probes::NOISY`; 0: all rays at every probe).
//! Then draws `POINTS` (default 1000) random free-space points of the scene with random normals
//! (`probes::measure::free_space_points`) and path-traces `H/π` there about the normal with
//! `SAMPLES` paths (default 512): every bake is measured at the same points against the same
//! reference. Prints the probe count, the probe stage's seconds against the bake's, and the
//! relative RMSE of the interpolated probes with the reference's noise taken out, at each
//! bake's own probes and at the shared points: over all of them, and apart over the points
//! farther and closer than the budget's spacing from an emitter (`probes::measure`). Below
//! that, where the squared error lies: the points in the slab between the bake's outermost
//! probes and the bounds, and the worst points.
//!
//! `PROBE_INDIRECT_ONLY=1` bakes the probes without punctual lights' direct light and traces the
//! reference without it (`ReferenceParams::no_punctual_direct`). `PROBE_SEED=S` draws another set of points (default 3: the guide's figures). With
//! `PROBE_HOLD=1` each free-space figure is also given for the lookup that held the face's
//! value in the slab by the walls instead of continuing the outer cells' light. With
//! `PROBE_DUMP=PREFIX` each bake's free-space points are written to `PREFIX_REFINE:LEVELS.csv`
//! (position, normal, emitter distance, grid coordinates, then the red channel of the probes'
//! value, the reference, its standard error and the held lookup's value, NaN without
//! `PROBE_HOLD`), to see which points hold the error; the points at the probes go to
//! `PREFIX_REFINE:LEVELS_at_probes.csv` alike.

use std::path::Path;

use glam::Vec3;
use lightbake::probes::measure::{self, SplitError};
use lightbake::probes::{DEFAULT_REFINE, ProbeParams, Probes};
use lightbake::reference::points::{self, Normals, Point};
use lightbake::reference::{Reference, ReferenceParams};
use lightbake::trace::Tracer;
use lightbake::{BakeConfig, Baked, NoProgress};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [scene, rest @ ..] = &args[..] else {
        panic!(
            "usage: probe_figures SCENE [QUALITY] [BUDGET] [POINTS] [SAMPLES] [RAYS] [REFINE[:LEVELS[:NOISY]]...]"
        )
    };
    let quality = rest.first().map_or("medium", String::as_str);
    let mut config = match quality {
        "draft" => BakeConfig::draft(),
        "high" => BakeConfig::high(),
        _ => BakeConfig::medium(),
    };
    let mut params = ProbeParams::default();
    // Probes without punctual direct light, against a reference without it.
    let indirect_only = std::env::var("PROBE_INDIRECT_ONLY").is_ok();
    params.indirect_only = indirect_only;
    if let Some(b) = rest.get(1) {
        params.budget = (b != "auto").then(|| b.parse().expect("BUDGET"));
    }
    let n: usize = rest.get(2).map_or(1000, |s| s.parse().expect("POINTS"));
    let samples: u32 = rest.get(3).map_or(512, |s| s.parse().expect("SAMPLES"));
    if let Some(r) = rest.get(4) {
        params.rays = r.parse().expect("RAYS");
    }
    let shares: Vec<(f32, u32, f32)> = match rest.get(5..) {
        Some(r) if !r.is_empty() => (r.iter())
            .map(|s| {
                let mut parts = s.split(':');
                let share = parts.next().unwrap_or(s).parse().expect("REFINE");
                let levels = parts
                    .next()
                    .map_or(params.levels, |l| l.parse().expect("LEVELS"));
                let noisy = parts
                    .next()
                    .map_or(params.noisy, |x| x.parse().expect("NOISY"));
                (share, levels, noisy)
            })
            .collect(),
        _ => vec![
            (0.0, params.levels, params.noisy),
            (DEFAULT_REFINE, params.levels, params.noisy),
        ],
    };
    let mut bakes = Vec::new();
    for &(refine, levels, noisy) in &shares {
        config.output.probes = Some(ProbeParams {
            refine,
            levels,
            noisy,
            ..params.clone()
        });
        let baked = lightbake::compute(Path::new(scene), &config, &NoProgress).expect("bake");
        let total: f64 = baked.stages.iter().map(|s| s.seconds).sum();
        let probe_seconds: f64 = (baked.stages.iter())
            .filter(|s| s.stage == "probes")
            .map(|s| s.seconds)
            .sum();
        let probes = baked.probes.clone().expect("probes");
        let grid = probes.grid.expect("the automatic grid");
        println!(
            "{scene} ({quality}), refine {refine}:{levels}, noisy {noisy}: {} probes ({} valid, {} moved, divided cells per level {:?}), grid {:?} step {:.3}, {:.2} M rays; probes {probe_seconds:.2}s of {total:.2}s computing ({:.1}%)",
            probes.len(),
            probes.valid_count(),
            probes.moved,
            probes
                .refinement
                .cells
                .iter()
                .map(Vec::len)
                .collect::<Vec<_>>(),
            grid.count,
            grid.step.x,
            probes.rays as f64 * 1e-6,
            100.0 * probe_seconds / total
        );
        bakes.push((format!("{refine}:{levels}:{noisy}"), baked, probes));
    }
    let baked = &bakes[0].1;
    let tracer = Tracer::new(&baked.scene);
    let near_field = measure::near_field(&baked.scene, bakes[0].2.budget);
    let reference = ReferenceParams {
        max_samples: samples,
        seed: 7,
        no_punctual_direct: indirect_only,
        ..ReferenceParams::like(&baked.config)
    };
    let surfaces = (&baked.scene, &baked.texels, &tracer);
    let trace = |at: &[(Vec3, Vec3)]| {
        let pts: Vec<Point> = (at.iter())
            .map(|&(position, normal)| Point::free(position, normal))
            .collect();
        points::trace_about(surfaces, &pts, Normals::Shading, &reference, &NoProgress)
            .expect("reference")
    };
    // The L2 projection a probe holds, path-traced at the same points with as many samples.
    let trace_l2 = |at: &[(Vec3, Vec3)]| {
        lightbake::reference::trace_sh(surfaces, at, &reference, &NoProgress).expect("reference")
    };
    // The same free-space points for every bake.
    let seed = std::env::var("PROBE_SEED").map_or(3, |s| s.parse().expect("PROBE_SEED"));
    let shared = measure::free_space_points(&baked.scene, &tracer, n, seed);
    let shared_ref = trace(&shared);
    let shared_l2 = trace_l2(&shared);
    println!(
        "{} free-space points; near field: closer than {near_field:.3} to an emitter",
        shared.len()
    );
    for (refine, _, probes) in &bakes {
        // At the bake's own gathered probes (no interpolation: SH truncation, gather noise and
        // the bake's own error).
        let at_probes = at_probes(probes, n);
        let own = trace(&at_probes);
        let own_l2 = trace_l2(&at_probes);
        for (what, at, r, l2) in [
            ("at the probes", &at_probes, &own, &own_l2),
            ("free space", &shared, &shared_ref, &shared_l2),
        ] {
            report(
                refine,
                what,
                probes,
                (baked, &tracer, near_field),
                at,
                (r, l2),
            );
        }
    }
}

/// Up to `n` of the gathered probes (`Probes::gathered`), each with a normal of its own.
fn at_probes(probes: &Probes, n: usize) -> Vec<(Vec3, Vec3)> {
    let gathered = probes.gathered();
    let count = gathered.iter().filter(|&&g| g).count();
    (0..probes.len())
        .filter(|&i| gathered[i])
        .step_by((count / n).max(1))
        .map(|i| {
            let u = (i as f32 * 0.618_034).fract();
            let v = (i as f32 * 0.414_214).fract();
            let z = 1.0 - 2.0 * u;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let phi = std::f32::consts::TAU * v;
            (
                probes.position[i],
                Vec3::new(r * phi.cos(), r * phi.sin(), z),
            )
        })
        .collect()
}

/// Prints the probes' error at `at` against the reference `r`.
fn report(
    refine: &str,
    what: &str,
    probes: &Probes,
    (baked, tracer, near_field): (&Baked, &Tracer, f32),
    at: &[(Vec3, Vec3)],
    (r, l2): (&Reference, &Reference),
) {
    let ours: Vec<Vec3> = (at.iter())
        .map(|&(p, n)| probes.irradiance_over_pi(p, n, Some(tracer)))
        .collect();
    let positions: Vec<Vec3> = at.iter().map(|a| a.0).collect();
    let near = measure::near_emitters(&baked.scene, &baked.texels, &positions, near_field);
    let SplitError {
        all,
        far,
        near: near_error,
        near_points,
        noise,
    } = measure::split_error(&ours, &r.mean, &r.std_error, &near);
    println!(
        "  refine {refine}, {what}: {} points: all {:.2}%, far {:.2}%, near {:.2}% ({near_points} points); reference noise {:.2}%",
        at.len(),
        100.0 * all,
        100.0 * far,
        100.0 * near_error,
        100.0 * noise,
    );
    let e = measure::split_error(&ours, &l2.mean, &l2.std_error, &near);
    println!(
        "    against the path tracer's L2 projection: all {:.2}%, far {:.2}%, near {:.2}%; its noise {:.2}%",
        100.0 * e.all,
        100.0 * e.far,
        100.0 * e.near,
        100.0 * e.noise,
    );
    let mut held_values = None;
    if std::env::var("PROBE_HOLD").is_ok() {
        // The lookup as it was before the slab's continuation: the point moved onto the box of
        // the grid's positions, its visibility still tested from where it is.
        let grid = probes.grid.expect("a grid");
        let last = Vec3::from(grid.count.map(|c| c.saturating_sub(1) as f32));
        let held: Vec<Vec3> = (at.iter())
            .map(|&(p, n)| {
                let x = grid.local(p).clamp(Vec3::ZERO, last);
                let on_box = grid.origin + grid.rotation * (grid.step * x);
                let from = p + n * tracer.epsilon;
                let c = probes.sh_at(on_box, |q| !tracer.occluded(from, q));
                lightbake::probes::sh::irradiance_over_pi(&c, n)
            })
            .collect();
        let e = measure::split_error(&held, &r.mean, &r.std_error, &near);
        println!(
            "    the face's value held in the slab: all {:.2}%, far {:.2}%, near {:.2}%",
            100.0 * e.all,
            100.0 * e.far,
            100.0 * e.near
        );
        held_values = Some(held);
    }
    if let Ok(prefix) = std::env::var("PROBE_DUMP") {
        use std::fmt::Write as _;
        let mut out = String::from("k,x,y,z,nx,ny,nz,emitter,gx,gy,gz,ours,reference,std,held\n");
        let grid = probes.grid.expect("a grid");
        for k in 0..at.len() {
            let (p, n) = at[k];
            let g = grid.local(p);
            let _ = writeln!(
                out,
                "{k},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
                p.x,
                p.y,
                p.z,
                n.x,
                n.y,
                n.z,
                measure::emitter_distance(&baked.scene, &baked.texels, p),
                g.x,
                g.y,
                g.z,
                ours[k].x,
                r.mean[k].x,
                r.std_error[k].x,
                held_values.as_ref().map_or(f32::NAN, |h| h[k].x)
            );
        }
        let part = if what == "free space" {
            ""
        } else {
            "_at_probes"
        };
        std::fs::write(format!("{prefix}_{refine}{part}.csv"), out).expect("dump");
    }
    // Where the squared error lies.
    let sq: Vec<f32> = (0..at.len())
        .map(|k| (ours[k] - r.mean[k]).length_squared())
        .collect();
    let all_sq: f32 = sq.iter().sum();
    let grid = probes.grid.expect("a grid");
    let last = Vec3::from(grid.count.map(|c| c.saturating_sub(1) as f32));
    let slab: Vec<usize> = (0..at.len())
        .filter(|&k| {
            let g = grid.local(at[k].0);
            g.cmplt(Vec3::ZERO).any() || g.cmpgt(last).any()
        })
        .collect();
    // The far points inside the grid's box and in the slab, apart.
    for (name, inside) in [("inside the grid's box", true), ("in the slab", false)] {
        let skip: Vec<u32> = (0..at.len() as u32)
            .filter(|k| {
                near.binary_search(k).is_ok()
                    || slab.binary_search(&(*k as usize)).is_ok() == inside
            })
            .collect();
        let e = measure::split_error(&ours, &r.mean, &r.std_error, &skip);
        println!(
            "    far, {name}: {:.2}% ({} points)",
            100.0 * e.far,
            at.len() - skip.len()
        );
    }
    let near_sq: f32 = near.iter().map(|&k| sq[k as usize]).sum();
    let slab_sq: f32 = slab.iter().map(|&k| sq[k]).sum();
    println!(
        "    squared error: near {:.0}%, in the slab outside the grid {:.0}% ({} points)",
        100.0 * near_sq / all_sq,
        100.0 * slab_sq / all_sq,
        slab.len()
    );
    let mut worst: Vec<(f32, usize)> = sq.iter().copied().zip(0..).collect();
    worst.sort_by(|a, b| b.0.total_cmp(&a.0));
    for &(_, k) in worst.iter().take(3) {
        println!(
            "    p {:.3} n {:.2} (emitter {:.2} away): probes {:.4}, reference {:.4} ± {:.4}",
            at[k].0,
            at[k].1,
            measure::emitter_distance(&baked.scene, &baked.texels, at[k].0),
            ours[k].x,
            r.mean[k].x,
            r.std_error[k].x
        );
    }
}
