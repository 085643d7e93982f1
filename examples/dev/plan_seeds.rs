//! The automatic plan of one scene across seeds: how stable it is.
//!
//! ```text
//! cargo run --release --example plan_seeds -- SCENE QUALITY SEEDS [FIRST]
//! ```
//!
//! For each seed from `FIRST` (default 0), prepares the bake as `lightbake bake --quality
//! QUALITY --seed S` would (the density pilot, the atlas, the validity pass; no transport) and
//! prints the texels laid out and the seconds taken on stdout, and the plan's reasons on the
//! texel density (the sample's points, its predicted lookup error and range) on stderr.

use std::path::PathBuf;
use std::time::Instant;

use lightbake::{NoProgress, prepare};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let scene = PathBuf::from(&args[0]);
    let quality = args[1].clone();
    let seeds: u64 = args[2].parse().expect("SEEDS");
    let first: u64 = args.get(3).map_or(0, |s| s.parse().expect("FIRST"));
    println!("seed,texels,seconds");
    for seed in first..first + seeds {
        let config = lightbake::build::options::Options {
            quality: Some(quality.clone()),
            seed: Some(seed),
            ..Default::default()
        }
        .config()
        .expect("options");
        let t = Instant::now();
        let p = prepare(&scene, &config, &NoProgress).expect("prepare");
        println!("{seed},{},{:.2}", p.texels.len(), t.elapsed().as_secs_f64());
        for r in p.plan().iter().flat_map(|p| &p.reasons) {
            if r.contains("predicted") || r.contains("texel density") {
                eprintln!("  seed {seed}: {r}");
            }
        }
    }
}
