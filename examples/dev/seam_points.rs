//! Where seam stitching changes a bake's point error: the same bake with and without
//! `--no-seams`, read as a renderer reads it, against a point reference.
//!
//! ```text
//! cargo run --release --example seam_points -- STITCHED.gltf UNSTITCHED.gltf REF.csv [N]
//! ```
//!
//! Prints both relative RMSEs, how much of the difference in squared error the `N` points that
//! lost most (default 30) carry, and each of them: position, normal, page and texel position of
//! the lookup, both lookups and the reference. With `SEAM_POINTS_CSV=FILE` set it also writes
//! every point's change in squared error, position, normal and values there.

use std::path::Path;

use lightbake::reference::points::{self, PointReference};
use lightbake::render::RenderScene;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [stitched, unstitched, reference, rest @ ..] = &args[..] else {
        panic!("usage: seam_points STITCHED UNSTITCHED REF.csv [N]")
    };
    let n: usize = rest.first().map_or(30, |s| s.parse().expect("N"));
    let text = std::fs::read_to_string(reference).expect("reference");
    let r = PointReference::from_csv(&text, Path::new(reference)).expect("reference");
    let a = RenderScene::load(Path::new(stitched)).expect("stitched bake");
    let b = RenderScene::load(Path::new(unstitched)).expect("unstitched bake");
    let (la, lb) = (
        points::look_up(&a, &r.points),
        points::look_up(&b, &r.points),
    );
    let grey = |v: glam::Vec3| v.element_sum() / 3.0;
    let mean: f64 = r.mean.iter().map(|m| grey(*m) as f64).sum::<f64>() / r.mean.len() as f64;
    let (mut sa, mut sb) = (0.0f64, 0.0f64);
    // (extra squared error of the stitched lookup, point)
    let mut rows: Vec<(f64, usize)> = Vec::new();
    for k in 0..r.points.len() {
        let (Some(x), Some(y)) = (&la[k], &lb[k]) else {
            continue;
        };
        let ea = ((x.value - r.mean[k]) * (x.value - r.mean[k])).element_sum() as f64 / 3.0;
        let eb = ((y.value - r.mean[k]) * (y.value - r.mean[k])).element_sum() as f64 / 3.0;
        sa += ea;
        sb += eb;
        rows.push((ea - eb, k));
    }
    let count = rows.len() as f64;
    println!(
        "{} points: stitched {:.3}%, unstitched {:.3}% (relative RMSE, reference noise in); changed {}",
        rows.len(),
        100.0 * (sa / count).sqrt() / mean,
        100.0 * (sb / count).sqrt() / mean,
        rows.iter().filter(|r| r.0 != 0.0).count()
    );
    let gained: f64 = rows.iter().filter(|r| r.0 > 0.0).map(|r| r.0).sum();
    let lost: f64 = rows.iter().filter(|r| r.0 < 0.0).map(|r| r.0).sum();
    rows.sort_by(|x, y| y.0.total_cmp(&x.0));
    let worst: f64 = rows.iter().take(n).map(|r| r.0).sum();
    println!(
        "squared error: +{gained:.5} where stitching hurt, {lost:.5} where it helped (net {:.5}); the worst {n} carry +{worst:.5}",
        gained + lost
    );
    if let Ok(path) = std::env::var("SEAM_POINTS_CSV") {
        let mut out = String::from("d,x,y,z,nx,ny,nz,stitched,unstitched,ref\n");
        for &(d, k) in &rows {
            let p = &r.points[k];
            out += &format!(
                "{d},{},{},{},{},{},{},{},{},{}\n",
                p.position.x,
                p.position.y,
                p.position.z,
                p.normal.x,
                p.normal.y,
                p.normal.z,
                grey(la[k].as_ref().unwrap().value),
                grey(lb[k].as_ref().unwrap().value),
                grey(r.mean[k])
            );
        }
        std::fs::write(path, out).expect("csv");
    }
    for &(d, k) in rows.iter().take(n) {
        let p = &r.points[k];
        let (x, y) = (la[k].as_ref().unwrap(), lb[k].as_ref().unwrap());
        let page = &a.pages[x.page as usize];
        let texel = x.uv * glam::Vec2::new(page.width as f32, page.height as f32);
        println!(
            "{:+.5} p=({:.3},{:.3},{:.3}) n=({:.2},{:.2},{:.2}) page {} texel ({:.2},{:.2}) stitched {:.4} unstitched {:.4} ref {:.4}",
            d,
            p.position.x,
            p.position.y,
            p.position.z,
            p.normal.x,
            p.normal.y,
            p.normal.z,
            x.page,
            texel.x,
            texel.y,
            grey(x.value),
            grey(y.value),
            grey(r.mean[k]),
        );
    }
}
