//! The points a bake gets most wrong against a point reference: where the point error sits.
//!
//! ```text
//! cargo run --release --example point_worst -- BAKED.gltf REF.csv [N]
//! ```
//!
//! Prints the share of the squared error of the worst `N` points (default 20) and each one's
//! position, normal, lookup, reference and whether the lookup touched a black texel.

use std::path::Path;

use lightbake::reference::points::{self, PointReference};
use lightbake::render::RenderScene;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [baked, reference, rest @ ..] = &args[..] else {
        panic!("usage: point_worst BAKED REF.csv [N]")
    };
    let n: usize = rest.first().map_or(20, |s| s.parse().expect("N"));
    let text = std::fs::read_to_string(reference).expect("reference");
    let r = PointReference::from_csv(&text, Path::new(reference)).expect("reference");
    let render = RenderScene::load(Path::new(baked)).expect("baked scene");
    let lookups = points::look_up(&render, &r.points);
    let mut rows: Vec<(f32, usize)> = Vec::new();
    let mut mean = 0.0f64;
    for (k, l) in lookups.iter().enumerate() {
        if let Some(l) = l {
            let d = l.value - r.mean[k];
            rows.push(((d * d).element_sum() / 3.0, k));
            mean += (r.mean[k].element_sum() / 3.0) as f64;
        }
    }
    mean /= rows.len().max(1) as f64;
    let total: f64 = rows.iter().map(|r| r.0 as f64).sum();
    rows.sort_by(|a, b| b.0.total_cmp(&a.0));
    let worst: f64 = rows.iter().take(n).map(|r| r.0 as f64).sum();
    println!(
        "{} points, RMSE {:.2}% of the mean {mean:.4}; the worst {n} hold {:.1}% of the squared error",
        rows.len(),
        100.0 * (total / rows.len() as f64).sqrt() / mean,
        100.0 * worst / total
    );
    for &(sq, k) in rows.iter().take(n) {
        let p = &r.points[k];
        let l = lookups[k].unwrap();
        println!(
            "p=({:.3},{:.3},{:.3}) n=({:.2},{:.2},{:.2}) lookup {:.4} ref {:.4} (err {:.1}% of mean) black {} uv ({:.1},{:.1})",
            p.position.x,
            p.position.y,
            p.position.z,
            p.normal.x,
            p.normal.y,
            p.normal.z,
            l.value.element_sum() / 3.0,
            r.mean[k].element_sum() / 3.0,
            100.0 * (sq as f64).sqrt() / mean,
            l.touches_black,
            l.uv.x,
            l.uv.y
        );
    }
}
