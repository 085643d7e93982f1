//! Where a bake's point error comes from: the squared error of a bake read as a renderer reads
//! it (`lightbake compare --points`), broken down by the cause each point falls under.
//!
//! ```text
//! cargo run --release --example point_breakdown -- OUT/scene.gltf POINTS.csv [OUT2/scene.gltf]
//! ```
//!
//! `OUT2` is a second bake of the same scene with another `--seed`: half the squared difference
//! of the two lookups is the bake's own noise at each point. Each point goes to the first cause
//! that holds, in this order:
//!
//! | cause     | the point's lookup …                                                              |
//! |-----------|------------------------------------------------------------------------------------|
//! | black     | blends a black texel (an unfilled gutter or invalid texel showing through)         |
//! | gutter    | blends a texel no triangle covers (its value was dilated from its neighbours)      |
//! | border    | blends a texel its chart covers only in part (value sampled off the texel centre)  |
//! | contact   | lies within one texel of another surface (an in-plane probe ray hits it): corners, |
//! |           | junctions, objects standing on the surface                                         |
//! | curved    | lies where the shading normal leaves the face's normal by more than 1°             |
//! | steep     | blends texels whose values differ by more than 30% of the reference: penumbrae     |
//! | interior  | none of the above                                                                  |
//!
//! Per cause: points, their share of the total squared error, the relative RMSE they add
//! (`√(Σ(x−r)²/N)/mean(r)` over all N points: the parts add up in squares to the total), the
//! bias within the cause (`Σx/Σr − 1`), and the shares of that squared error the reference's
//! noise (`Σσ²`) and the bake's noise (from `OUT2`) explain. Coverage of each page texel is
//! measured from the output itself (each primitive's `TEXCOORD_1` rasterised at 4 × 4 samples
//! per texel), so nothing but the written files is read.

use std::path::Path;

use glam::{Vec2, Vec3};
use lightbake::reference::points::{self, Lookup, PointReference};
use lightbake::render::RenderScene;

/// Sub-samples per texel side when measuring coverage.
const SUB: u32 = 4;
/// Causes, in the order a point is assigned to them.
const CAUSES: [&str; 7] = [
    "black", "gutter", "border", "contact", "curved", "steep", "interior",
];

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (out, refs, second) = match &args[..] {
        [o, r] => (o, r, None),
        [o, r, s] => (o, r, Some(s)),
        _ => panic!("usage: point_breakdown OUT/scene.gltf POINTS.csv [OUT2/scene.gltf]"),
    };
    let r = PointReference::from_csv(
        &std::fs::read_to_string(refs).expect("points file"),
        Path::new(refs),
    )
    .expect("points");
    let baked = RenderScene::load(Path::new(out)).expect("bake");
    let lookups = points::look_up(&baked, &r.points);
    let other = second.map(|s| {
        let b = RenderScene::load(Path::new(s)).expect("second bake");
        points::look_up(&b, &r.points)
    });
    let coverage = coverage(&baked);

    let mean_ref: f64 = (r.mean.iter())
        .zip(&lookups)
        .filter(|(_, l)| l.is_some())
        .map(|(m, _)| m.element_sum() as f64 / 3.0)
        .sum::<f64>()
        / lookups.iter().flatten().count().max(1) as f64;
    let mut sums = [Sums::default(); CAUSES.len()];
    let mut flagged = [Sums::default(); CAUSES.len()];
    let mut total = Sums::default();
    for (k, l) in lookups.iter().enumerate() {
        let Some(l) = l else { continue };
        let bits = causes(&baked, &coverage, &r, k, l, mean_ref as f32);
        let first = bits.trailing_zeros() as usize;
        let d = l.value - r.mean[k];
        let se = r.std_error[k];
        let bake_noise = match &other {
            Some(o) => o[k].map_or(0.0, |b| (l.value - b.value).length_squared() as f64 / 2.0),
            None => 0.0,
        };
        let mut targets: Vec<&mut Sums> = vec![&mut sums[first], &mut total];
        for (c, f) in flagged.iter_mut().enumerate() {
            if bits & (1 << c) != 0 {
                targets.push(f);
            }
        }
        for s in targets {
            s.n += 1;
            s.sq += d.length_squared() as f64;
            s.x += l.value.element_sum() as f64;
            s.r += r.mean[k].element_sum() as f64;
            s.ref_noise += se.length_squared() as f64;
            s.bake_noise += bake_noise;
        }
    }
    let n = total.n.max(1) as f64;
    let rel = |sq: f64| (sq / (3.0 * n)).sqrt() / mean_ref * 100.0;
    println!(
        "{out}: {} points, relative RMSE {:.2}%",
        total.n,
        rel(total.sq)
    );
    println!(
        "| cause | points | share of sq. error | adds RMSE | bias | ref. noise | bake noise |"
    );
    println!("|---|---:|---:|---:|---:|---:|---:|");
    for (name, s) in CAUSES.iter().zip(&sums) {
        print_row(name, s, &total, &rel);
    }
    println!("| *each cause alone (a point counts under every cause that holds)* |||||||");
    for (name, s) in CAUSES.iter().zip(&flagged) {
        print_row(&format!("any {name}"), s, &total, &rel);
    }
    print_row("all", &total, &total, &rel);
}

/// Sums over the points of one cause (channels summed).
#[derive(Default, Clone, Copy)]
struct Sums {
    n: usize,
    sq: f64,
    x: f64,
    r: f64,
    ref_noise: f64,
    bake_noise: f64,
}

/// One table row: `rel` turns a sum of squares into the relative RMSE it adds.
fn print_row(name: &str, s: &Sums, total: &Sums, rel: &dyn Fn(f64) -> f64) {
    let pct = |a: f64, b: f64| if b > 0.0 { a / b * 100.0 } else { 0.0 };
    println!(
        "| {name} | {} | {:.1}% | {:.2}% | {:+.2}% | {:.0}% | {:.0}% |",
        s.n,
        pct(s.sq, total.sq),
        rel(s.sq),
        pct(s.x - s.r, s.r),
        pct(s.ref_noise, s.sq),
        pct(s.bake_noise, s.sq),
    );
}

/// Which causes of [`CAUSES`] hold for point `k` (bit `c` for cause `c`; interior when none).
fn causes(
    baked: &RenderScene,
    coverage: &[Vec<f32>],
    r: &PointReference,
    k: usize,
    l: &Lookup,
    mean_ref: f32,
) -> u32 {
    let page = &baked.pages[l.page as usize];
    let taps: Vec<(usize, f32)> = (page.footprint(l.uv).into_iter())
        .filter(|&(_, w)| w > 0.0)
        .collect();
    let cover = &coverage[l.page as usize];
    let p = r.points[k];
    let lit = (r.mean[k] - 2.0 * r.std_error[k]).max_element() > 0.0;
    let values = taps.iter().map(|&(t, _)| page.rgb[t].element_sum() / 3.0);
    let (lo, hi) = values.fold((f32::MAX, f32::MIN), |(a, b), v| (a.min(v), b.max(v)));
    let scale = (r.mean[k].element_sum() / 3.0).max(0.05 * mean_ref);
    let flags = [
        l.touches_black && lit,
        taps.iter().any(|&(t, _)| cover[t] == 0.0),
        taps.iter().any(|&(t, _)| cover[t] < 1.0),
        near_other_surface(
            baked,
            p.position,
            p.normal,
            texel_size(baked, l, page.width),
        ),
        l.shading_normal.dot(p.normal) < 1f32.to_radians().cos(),
        hi - lo > 0.3 * scale,
    ];
    let bits = (flags.iter().enumerate()).fold(0, |b, (c, &f)| b | (f as u32) << c);
    if bits == 0 {
        1 << (CAUSES.len() - 1)
    } else {
        bits
    }
}

/// World size of one texel side at the lookup (from the page's texel count over the
/// surface's `TEXCOORD_1` spread: the nearest triangle's world area per texel area).
fn texel_size(baked: &RenderScene, l: &Lookup, width: u32) -> f32 {
    let page = &baked.pages[l.page as usize];
    let texels = (width * page.height) as f32;
    let scene = &baked.scene;
    let mut best = (f32::MAX, 0.0);
    for (t, tri) in scene.triangles.iter().enumerate() {
        if baked.instance_page[scene.triangle_instance[t] as usize] != Some(l.page) {
            continue;
        }
        let [a, b, c] = tri.map(|v| scene.uv1[v as usize]);
        let uv_area = (b - a).perp_dot(c - a).abs() / 2.0;
        if uv_area <= 0.0 {
            continue;
        }
        let centre = (a + b + c) / 3.0;
        let d = centre.distance(l.uv);
        if d < best.0 {
            let [p, q, s] = tri.map(|v| scene.positions[v as usize]);
            let area = (q - p).cross(s - p).length() / 2.0;
            best = (d, (area / (uv_area * texels)).sqrt());
        }
    }
    best.1
}

/// Another surface within `reach` of `p` along its own plane (8 probe rays just above it).
fn near_other_surface(baked: &RenderScene, p: Vec3, n: Vec3, reach: f32) -> bool {
    let eps = baked.tracer.epsilon;
    let (t, b) = n.any_orthonormal_pair();
    (0..8).any(|k| {
        let a = k as f32 * std::f32::consts::TAU / 8.0;
        let dir = t * a.cos() + b * a.sin();
        baked
            .tracer
            .closest(p + n * 2.0 * eps, dir, reach)
            .is_some()
    })
}

/// Per page, the fraction of each texel the baked triangles cover (sub-sampled).
fn coverage(baked: &RenderScene) -> Vec<Vec<f32>> {
    let mut hits: Vec<Vec<u32>> = (baked.pages.iter())
        .map(|p| vec![0; (p.width * p.height) as usize])
        .collect();
    let scene = &baked.scene;
    for (t, tri) in scene.triangles.iter().enumerate() {
        let Some(k) = baked.instance_page[scene.triangle_instance[t] as usize] else {
            continue;
        };
        let page = &baked.pages[k as usize];
        let scale = Vec2::new((page.width * SUB) as f32, (page.height * SUB) as f32);
        let [a, b, c] = tri.map(|v| scene.uv1[v as usize] * scale);
        let lo = a.min(b).min(c).floor().max(Vec2::ZERO);
        let hi = a.max(b).max(c).ceil().min(scale);
        let area = (b - a).perp_dot(c - a);
        if area == 0.0 {
            continue;
        }
        for y in lo.y as u32..hi.y as u32 {
            for x in lo.x as u32..hi.x as u32 {
                let s = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                let w =
                    [(a, b), (b, c), (c, a)].map(|(p, q)| (q - p).perp_dot(s - p) * area.signum());
                if w.iter().all(|&w| w >= 0.0) {
                    hits[k as usize][((y / SUB) * page.width + x / SUB) as usize] += 1;
                }
            }
        }
    }
    (hits.into_iter())
        .map(|h| {
            h.into_iter()
                .map(|c| (c as f32 / (SUB * SUB) as f32).min(1.0))
                .collect()
        })
        .collect()
}
