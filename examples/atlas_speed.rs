//! Speed and quality of the atlas stage alone on the 116k-triangle test hall, at the texel
//! density the benchmark bakes it at.
//!
//!     cargo run --release --example atlas_speed [-- <runs> [<texels per unit>]]
//!
//! Prints one row per run: wall time, CPU time (user + sys of the whole process) over wall time,
//! and what the layout costs downstream — pages, page texels, patches (`texels::build`), charts
//! (edge-connected triangles sharing lightmap UVs), seam edges (`lightmap::seams::find`) and
//! texel centres claimed twice. It uses only the public API, so the same file builds against an
//! older checkout for an interleaved before/after comparison.

use std::collections::HashMap;
use std::time::Instant;

use glam::{DVec2, Vec2};
use lightbake::BakeConfig;
use lightbake::atlas::{Atlas, PageSize};
use lightbake::scene::Scene;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let runs: usize = args.next().map_or(Ok(3), |a| a.parse())?;
    let tpu: f32 = args.next().map_or(Ok(3.0), |a| a.parse())?;

    let dir = tempfile::tempdir()?;
    let path = dir.path().join("large_hall.glb");
    std::fs::write(&path, lightbake::testing::large_hall().to_glb_bytes())?;
    let (scene, source) = lightbake::scene::load(&path)?;
    let mut params = BakeConfig::draft().atlas;
    params.texels_per_unit = tpu;
    params.uv = lightbake::config::UvMode::Unwrap;

    println!(
        "large_hall: {} triangles, {} instances, {tpu} texels per unit",
        scene.triangles.len(),
        scene.instances.len()
    );
    println!(
        "{:>4} {:>8} {:>6} {:>6} {:>10} {:>8} {:>7} {:>6} {:>8} {:>17}",
        "run",
        "wall s",
        "cpu/w",
        "pages",
        "page tx",
        "patches",
        "charts",
        "seams",
        "overlap",
        "digest"
    );
    for run in 0..runs {
        let cpu = cpu_seconds();
        let start = Instant::now();
        let atlas = lightbake::atlas::build(&scene, &source, &params)?;
        let wall = start.elapsed().as_secs_f64();
        let cpu = cpu_seconds() - cpu;
        let page_texels: u64 = atlas
            .pages
            .iter()
            .map(|p| u64::from(p.width * p.height))
            .sum();
        let patches = lightbake::texels::build(&scene, &atlas)?.len();
        let seams = lightbake::lightmap::seams::find(&scene, &atlas, &Default::default());
        println!(
            "{run:>4} {wall:>8.3} {:>6.2} {:>6} {page_texels:>10} {patches:>8} {:>7} {:>6} {:>8} {:016x}",
            cpu / wall,
            atlas.pages.len(),
            charts(&atlas),
            seams.edges.len(),
            overlapping(&scene, &atlas),
            digest(&atlas),
        );
    }
    Ok(())
}

/// FNV-1a over every page size, xref, UV bit pattern, triangle and page: equal digests mean
/// byte-identical layouts.
fn digest(atlas: &Atlas) -> u64 {
    let mut words: Vec<u32> = atlas
        .pages
        .iter()
        .flat_map(|p| [p.width, p.height])
        .collect();
    for inst in &atlas.instances {
        words.extend(&inst.xref);
        words.extend(
            inst.uv
                .iter()
                .flat_map(|uv| [uv.x.to_bits(), uv.y.to_bits()]),
        );
        words.extend(inst.triangles.iter().flatten());
        words.extend(&inst.triangle_page);
    }
    words.iter().fold(0xcbf29ce484222325, |h, &w| {
        (h ^ u64::from(w)).wrapping_mul(0x100000001b3)
    })
}

/// User + system CPU time of this process so far (Linux; 0 elsewhere).
fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    // Fields after the parenthesised command name; utime and stime are the 12th and 13th.
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let fields: Vec<f64> = rest
        .split_whitespace()
        .map(|f| f.parse().unwrap_or(0.0))
        .collect();
    // Clock ticks; 100 per second on Linux.
    fields
        .get(11)
        .zip(fields.get(12))
        .map_or(0.0, |(u, s)| (u + s) / 100.0)
}

/// Charts: triangles joined through shared atlas vertex pairs (edges inside a chart), per
/// instance.
fn charts(atlas: &Atlas) -> usize {
    let mut total = 0;
    for inst in &atlas.instances {
        let n = inst.triangles.len();
        let mut parent: Vec<usize> = (0..n).collect();
        fn root(parent: &mut [usize], mut i: usize) -> usize {
            while parent[i] != i {
                parent[i] = parent[parent[i]];
                i = parent[i];
            }
            i
        }
        let mut first_with_edge: HashMap<(u32, u32), usize> = HashMap::new();
        for (t, tri) in inst.triangles.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                let other = *first_with_edge.entry((a.min(b), a.max(b))).or_insert(t);
                let (ra, rb) = (root(&mut parent, t), root(&mut parent, other));
                parent[ra] = rb;
            }
        }
        total += (0..n).filter(|&t| root(&mut parent, t) == t).count();
    }
    total
}

/// Texel centres strictly inside more than one triangle of the same page.
fn overlapping(scene: &Scene, atlas: &Atlas) -> u64 {
    let mut claimed: Vec<Vec<bool>> = atlas
        .pages
        .iter()
        .map(|p| vec![false; (p.width * p.height) as usize])
        .collect();
    let mut overlaps = 0;
    for t in 0..scene.triangles.len() as u32 {
        let (uv, page) = atlas.triangle_uv(scene, t);
        let size = atlas.pages[page as usize];
        for_each_centre_inside(uv, size, |x, y| {
            let c = &mut claimed[page as usize][(y * size.width + x) as usize];
            overlaps += u64::from(*c);
            *c = true;
        });
    }
    overlaps
}

/// As in `atlas::existing`: centres strictly inside, edge functions in a canonical order so two
/// triangles sharing an edge never both claim a centre on it.
fn for_each_centre_inside(uv: [Vec2; 3], size: PageSize, mut f: impl FnMut(u32, u32)) {
    let scale = DVec2::new(f64::from(size.width), f64::from(size.height));
    let p = uv.map(|v| v.as_dvec2() * scale);
    let lo = p[0].min(p[1]).min(p[2]);
    let hi = p[0].max(p[1]).max(p[2]);
    let first = |v: f64| (v - 0.5).ceil().max(0.0) as u32;
    let last = |v: f64, n: u32| ((v - 0.5).floor().min(f64::from(n) - 1.0)).max(-1.0) as i64;
    let (x_end, y_end) = (last(hi.x, size.width), last(hi.y, size.height));
    let edge = |a: DVec2, b: DVec2, c: DVec2| {
        if (a.x, a.y) <= (b.x, b.y) {
            (b - a).perp_dot(c - a)
        } else {
            -(a - b).perp_dot(c - b)
        }
    };
    for y in first(lo.y)..(y_end + 1).max(0) as u32 {
        for x in first(lo.x)..(x_end + 1).max(0) as u32 {
            let c = DVec2::new(f64::from(x) + 0.5, f64::from(y) + 0.5);
            let e = [
                edge(p[0], p[1], c),
                edge(p[1], p[2], c),
                edge(p[2], p[0], c),
            ];
            if e.iter().all(|&v| v > 0.0) || e.iter().all(|&v| v < 0.0) {
                f(x, y);
            }
        }
    }
}
