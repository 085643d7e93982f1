//! Shared helpers: fixture paths, quick configs, scratch directories.

use std::path::PathBuf;

use lightbake::BakeConfig;

pub fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("fixtures")
        .join(name)
}

/// A small, fast configuration for tests (accuracy tests raise what they need).
pub fn quick() -> BakeConfig {
    let mut c = BakeConfig::draft();
    c.atlas.texels_per_unit = 8.0;
    c.transport.gather_rays = 64;
    c.transport.light_samples = 16;
    c
}

pub fn scratch() -> tempfile::TempDir {
    tempfile::tempdir().expect("temp dir")
}

/// All files below `dir`, sorted, relative.
pub fn list_files(dir: &std::path::Path) -> Vec<String> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push(p.strip_prefix(dir).unwrap().to_string_lossy().into_owned());
            }
        }
    }
    out.sort();
    out
}

/// The path-traced reference at a bake's own texels, `samples` paths per texel.
pub fn texel_reference(baked: &lightbake::Baked, samples: u32) -> lightbake::reference::Reference {
    let params = lightbake::reference::ReferenceParams {
        max_samples: samples,
        ..Default::default()
    };
    let tracer = lightbake::trace::Tracer::new(&baked.scene);
    lightbake::reference::trace(
        &baked.scene,
        &baked.texels,
        &tracer,
        &params,
        &lightbake::NoProgress,
    )
    .unwrap()
}
