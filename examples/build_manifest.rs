//! Bakes the committed fixtures through a manifest with `lightbake::build`, twice: the second
//! build finds every scene up to date. Prints the JSON report and both wall times.
//!
//! `cargo run --release --example build_manifest [OUT_DIR]`

use std::path::PathBuf;
use std::time::Instant;

use lightbake::build::Gate;
use lightbake::{Manifest, NoProgress};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let fixtures = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("fixtures");
    let out = std::env::args().nth(1).map_or_else(
        || std::env::temp_dir().join("lightbake_build_manifest"),
        PathBuf::from,
    );
    std::fs::create_dir_all(&out)?;
    let manifest = format!(
        r#"
[defaults]
quality = "draft"

[[scene]]
path = "{fixtures}/cornell_box.gltf"
output = "cornell_box"

[[scene]]
path = "{fixtures}/textured.gltf"
output = "textured"
texels-per-unit = 16
"#,
        fixtures = fixtures.display()
    );
    let manifest = Manifest::parse(&manifest, &out)?;
    for run in ["first", "second"] {
        let start = Instant::now();
        let report = lightbake::build(&manifest, &NoProgress);
        println!("{run} build: {:.3} s", start.elapsed().as_secs_f64());
        println!("{}", report.to_json());
        let gate = Gate {
            max_error: Some(0.2),
            deny_warnings: false,
        };
        if report.failed() || !report.gate(&gate).is_empty() {
            return Err(format!("not good enough: {:?}", report.gate(&gate)).into());
        }
    }
    Ok(())
}
