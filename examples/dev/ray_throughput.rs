//! Ray throughput of the tracer (obvhs CWBVH + lightbake's triangle test) on this machine:
//! closest-hit and occlusion rays, incoherent like gathering rays (random surface points,
//! cosine-distributed directions; occlusion between two random surface points that face each
//! other, as form-factor visibility rays do), on one thread
//! and on all cores, with the CPU utilisation of the parallel run.
//!
//! ```sh
//! cargo run --release --example ray_throughput
//! cargo run --release --example ray_throughput -- --write-scenes DIR   # .glb files to profile
//! ```
//!
//! On a shared machine wall-clock rates depend on the load; the table therefore also gives
//! Mrays per CPU-second of the 2-thread run, which does not.

use std::time::Instant;

use glam::Vec3;
use lightbake::sampling::{Rng, cosine_hemisphere, frame, triangle_point};
use lightbake::scene::{self, Scene};
use lightbake::testing::cpu_seconds;
use lightbake::trace::Tracer;
use rayon::prelude::*;

const RAYS: usize = 4_000_000;
const CHUNK: usize = 4096;

/// A random point on a random triangle (uniform over triangles), lifted by `eps`, and its normal.
fn surface_point(scene: &Scene, rng: &mut Rng, eps: f32) -> (Vec3, Vec3) {
    let t = scene.triangles[(rng.next_u32() as usize) % scene.triangles.len()];
    let p = |i: usize| scene.positions[t[i] as usize];
    let b = triangle_point(rng.next_vec2());
    let n = (p(1) - p(0)).cross(p(2) - p(0)).normalize_or_zero();
    let x = p(0) + (p(1) - p(0)) * b.x + (p(2) - p(0)) * b.y;
    (x + n * eps, n)
}

/// Casts `RAYS` rays of one kind on the current rayon pool:
/// (Mrays/s, hit fraction, CPU use, Mrays per CPU-second).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Kind {
    Closest,
    /// Occlusion between points that face each other (what the methods cast).
    Facing,
    /// Occlusion between any two points, coplanar floor pairs included (grazing rays).
    AnyPair,
}

fn run(scene: &Scene, tracer: &Tracer, kind: Kind) -> (f64, f64, f64, f64) {
    let eps = tracer.epsilon;
    let (cpu0, start) = (cpu_seconds(), Instant::now());
    let hits: usize = (0..RAYS / CHUNK)
        .into_par_iter()
        .map(|c| {
            let mut rng = Rng::new(1, c as u64, kind as u64);
            let mut hits = 0;
            for _ in 0..CHUNK {
                let (o, n) = surface_point(scene, &mut rng, eps);
                if kind == Kind::AnyPair {
                    let (p, _) = surface_point(scene, &mut rng, eps);
                    hits += tracer.occluded(o, p) as usize;
                } else if kind == Kind::Facing {
                    // A pair that faces each other, as every method's visibility rays join
                    // (the form-factor kernel is zero otherwise, so none casts the ray):
                    // coplanar floor pairs would graze the floor the whole way.
                    // Redraw both ends (a degenerate triangle faces nothing); give up after
                    // a while in a scene with no facing surfaces.
                    let (mut a, mut b) = (o, surface_point(scene, &mut rng, eps).0);
                    for _ in 0..1000 {
                        let (p, m) = surface_point(scene, &mut rng, eps);
                        let (q, k) = surface_point(scene, &mut rng, eps);
                        let d = q - p;
                        if m.dot(d) > 0.0 && k.dot(d) < 0.0 {
                            (a, b) = (p, q);
                            break;
                        }
                    }
                    let (o, p) = (a, b);
                    hits += tracer.occluded(o, p) as usize;
                } else {
                    let (tx, ty) = frame(n);
                    let l = cosine_hemisphere(rng.next_vec2());
                    let d = tx * l.x + ty * l.y + n * l.z;
                    hits += tracer.closest(o, d, f32::INFINITY).is_some() as usize;
                }
            }
            hits
        })
        .sum();
    let wall = start.elapsed().as_secs_f64();
    let cpu_s = cpu_seconds() - cpu0;
    let cpu = cpu_s / (wall * rayon::current_num_threads() as f64);
    let n = (RAYS / CHUNK * CHUNK) as f64;
    (
        n / wall * 1e-6,
        hits as f64 / n,
        cpu,
        n / cpu_s.max(1e-3) * 1e-6,
    )
}

fn main() {
    let dir = tempfile::tempdir().expect("temp dir");
    let scenes = [
        ("cornell_box", lightbake::testing::cornell_box()),
        ("large_hall", lightbake::testing::large_hall()),
    ];
    let args: Vec<String> = std::env::args().collect();
    if let Some(k) = args.iter().position(|a| a == "--write-scenes") {
        let out = std::path::PathBuf::from(args.get(k + 1).expect("--write-scenes DIR"));
        std::fs::create_dir_all(&out).expect("create dir");
        for (name, gltf) in scenes {
            let path = out.join(format!("{name}.glb"));
            std::fs::write(&path, gltf.to_glb_bytes()).expect("write scene");
            println!("wrote {}", path.display());
        }
        return;
    }
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    println!("{RAYS} incoherent rays per run; {cores} cores; Mrays/s (hit or occluded fraction)\n");
    println!(
        "| scene | triangles | kind | 1 thread | {cores} threads | speed-up | CPU use ({cores} threads) | per CPU-second |"
    );
    println!("|---|---:|---|---:|---:|---:|---:|---:|");
    for (name, gltf) in scenes {
        let path = dir.path().join(format!("{name}.glb"));
        std::fs::write(&path, gltf.to_glb_bytes()).expect("write scene");
        let (scene, _) = scene::load(&path).expect("load");
        let tracer = Tracer::new(&scene);
        for kind in [Kind::Closest, Kind::Facing, Kind::AnyPair] {
            let one = rayon::ThreadPoolBuilder::new()
                .num_threads(1)
                .build()
                .unwrap()
                .install(|| run(&scene, &tracer, kind));
            let all = run(&scene, &tracer, kind);
            println!(
                "| {name} | {} | {} | {:.2} ({:.0}%) | {:.2} | {:.2}× | {:.0}% | {:.2} |",
                scene.triangles.len(),
                match kind {
                    Kind::Closest => "closest hit",
                    Kind::Facing => "occlusion, facing pairs",
                    Kind::AnyPair => "occlusion, any pair (grazing included)",
                },
                one.0,
                one.1 * 100.0,
                all.0,
                all.0 / one.0,
                all.2 * 100.0,
                all.3
            );
        }
    }
}
