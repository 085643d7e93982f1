//! The bake's noise, against which an incremental bake's point error is judged: full bakes of
//! an edited scene with several seeds (texels planned, wall time, point error), the plans of
//! the unedited and the edited scene per seed (texel count, density-pilot lines), a full
//! re-trace on the previous bake's layout (`Retrace::All`: the old plan, every row traced), and
//! the incremental bake, all against the same point reference.
//!
//! ```text
//! cargo run --release --example incremental_noise -- OUT SEEDS REFERENCE.csv [EDITED.glb] [--fixed]
//! ```
//!
//! With `--fixed` (after a run without, which bakes `OUT/old`): only full bakes of the
//! unedited scene with the old bake's kept settings (its plan) and each seed; REFERENCE is
//! then the unedited scene's.
//!
//! `EDITED.glb` defaults to `OUT/../edited/furnished_interior.glb` as `incremental_figures`
//! writes it; the unedited scene is `fixtures/furnished_interior.glb`. Prints one CSV line per
//! bake.

use std::path::{Path, PathBuf};
use std::time::Instant;

use lightbake::incremental::{self, Retrace, Since};
use lightbake::reference::points::{self, PointReference};
use lightbake::render::RenderScene;
use lightbake::{NoProgress, bake, prepare};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let fixed_only = args.iter().any(|a| a == "--fixed");
    let args: Vec<&String> = args.iter().filter(|a| !a.starts_with("--")).collect();
    let out = PathBuf::from(args[0]);
    let seeds: u64 = args[1].parse().expect("SEEDS");
    let reference_csv = PathBuf::from(args[2]);
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/furnished_interior.glb");
    let edited = args.get(3).map_or_else(
        || out.join("../edited/furnished_interior.glb"),
        PathBuf::from,
    );
    let name = "furnished_interior.glb";
    let text = std::fs::read_to_string(&reference_csv).expect("reference");
    let reference = PointReference::from_csv(&text, &reference_csv).expect("reference");
    let error = |dir: &Path| {
        let render = RenderScene::load(&dir.join(name)).expect("load the bake");
        points::compare(&render, &reference).rmse_without_noise
    };
    let config = |seed: u64| {
        lightbake::build::options::Options {
            quality: Some("medium".into()),
            keep_transport: Some(true),
            seed: Some(seed),
            ..Default::default()
        }
        .config()
        .expect("options")
    };
    println!("bake,seed,texels,seconds,point_rmse");
    if fixed_only {
        // Full bakes of the *unedited* scene with the previous bake's settings (`OUT/old`, as
        // kept: its density factors, rays and technique; no pilot), every seed: the spread of
        // the bake at the plan the incremental bake keeps. Not the edited scene: its junction
        // cuts number the triangles otherwise, and the kept factors are per triangle.
        let kept = lightbake::kept::read(&out.join("old").join(name)).expect("OUT/old");
        for seed in 0..seeds {
            let mut fixed = kept.settings.config().expect("kept settings");
            fixed.transport.seed = seed;
            let dir = out.join(format!("fixed_{seed}"));
            let _ = std::fs::remove_dir_all(&dir);
            let t = Instant::now();
            let r = bake(&scene, &dir, &fixed, &NoProgress).expect("fixed bake");
            println!(
                "full_unedited_old_plan,{seed},{},{:.2},{}",
                r.texels,
                t.elapsed().as_secs_f64(),
                error(&dir)
            );
        }
        return;
    }

    // The plans alone (density pilot and layout), both scenes, every seed.
    for seed in 0..seeds {
        for (label, input) in [("plan_unedited", &scene), ("plan_edited", &edited)] {
            let t = Instant::now();
            let p = prepare(input, &config(seed), &NoProgress).expect("prepare");
            let secs = t.elapsed().as_secs_f64();
            println!("{label},{seed},{},{secs:.2},", p.texels.len());
        }
    }
    // The previous bake (seed 0) and the incremental bake from it.
    let old = out.join("old");
    let _ = std::fs::remove_dir_all(&old);
    let t = Instant::now();
    let r = bake(&scene, &old, &config(0), &NoProgress).expect("old bake");
    println!(
        "old_unedited,0,{},{:.2},",
        r.texels,
        t.elapsed().as_secs_f64()
    );
    let since = old.join(name);
    let inc = out.join("incremental");
    let _ = std::fs::remove_dir_all(&inc);
    let t = Instant::now();
    let r = incremental::bake_since(&edited, &since, &inc, &config(0), &NoProgress).expect("inc");
    println!(
        "incremental,0,{},{:.2},{}",
        r.texels,
        t.elapsed().as_secs_f64(),
        error(&inc)
    );
    // Every row traced again on the old layout: the old plan, a full trace.
    let all = out.join("retrace_all");
    let _ = std::fs::remove_dir_all(&all);
    let t = Instant::now();
    let Since::Incremental(baked, _) =
        incremental::compute_since(&edited, &since, &config(0), Retrace::All, &NoProgress)
            .expect("retrace all")
    else {
        panic!("the re-trace baked in full");
    };
    let out_config = baked.config.clone();
    let r = lightbake::write(*baked, &edited, &all, &out_config, &NoProgress).expect("write");
    println!(
        "retrace_all_old_plan,0,{},{:.2},{}",
        r.texels,
        t.elapsed().as_secs_f64(),
        error(&all)
    );
    // Full bakes of the edited scene, every seed.
    for seed in 0..seeds {
        let dir = out.join(format!("full_{seed}"));
        let _ = std::fs::remove_dir_all(&dir);
        let t = Instant::now();
        let r = bake(&edited, &dir, &config(seed), &NoProgress).expect("full bake");
        for reason in r.plan.iter().flat_map(|p| &p.reasons) {
            eprintln!("full_edited seed {seed}: {reason}");
        }
        println!(
            "full_edited,{seed},{},{:.2},{}",
            r.texels,
            t.elapsed().as_secs_f64(),
            error(&dir)
        );
    }
}
