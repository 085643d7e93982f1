//! Bakes `assets/lightbake.toml` into `OUT_DIR/baked` with `lightbake::build`. Cargo re-runs this
//! script when anything under `assets/` changes; lightbake's cache then re-bakes only the
//! scenes whose inputs changed. A failed scene or a bake above the error gate fails the build.

use std::path::{Path, PathBuf};

use lightbake::build::Gate;
use lightbake::{Manifest, NoProgress};

/// The largest estimated error (relative) a shipped lightmap may have.
const MAX_ERROR: f32 = 0.15;

fn main() {
    println!("cargo:rerun-if-changed=assets");
    let assets = Path::new("assets");
    let out = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets OUT_DIR"));
    let mut manifest =
        Manifest::load(&assets.join("lightbake.toml")).unwrap_or_else(|e| panic!("{e}"));
    // Outputs go to OUT_DIR, never into the source tree.
    for scene in &mut manifest.scenes {
        let relative = scene.output.strip_prefix(assets).unwrap_or(&scene.output);
        scene.output = out.join(relative);
    }
    let report = lightbake::build(&manifest, &NoProgress);
    std::fs::write(out.join("report.json"), report.to_json()).expect("OUT_DIR is writable");
    for scene in &report.scenes {
        for warning in &scene.result.warnings {
            println!("cargo:warning={}: {warning}", scene.path.display());
        }
    }
    let gate = Gate {
        max_error: Some(MAX_ERROR),
        deny_warnings: true,
    };
    let mut problems = report.gate(&gate);
    for scene in report.scenes.iter().filter(|s| s.error.is_some()) {
        let error = scene.error.as_deref().unwrap_or_default();
        problems.push(format!("{}: {error}", scene.path.display()));
    }
    assert!(
        problems.is_empty(),
        "lightmaps not good enough: {problems:#?}"
    );
}
