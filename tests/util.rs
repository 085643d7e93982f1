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

/// A closed 4 × 2 × 2 m grey room (x ∈ [−2, 2], y ∈ [0, 2], z ∈ [−1, 1]) lit by a ceiling
/// panel from `corner` along `across` and 0.8 m along z; returns the builder and the grey
/// material, for tests to add to.
pub fn panel_room(
    name: &str,
    corner: glam::Vec3,
    across: glam::Vec3,
) -> (lightbake::testing::GltfBuilder, usize) {
    use glam::Vec3;
    use lightbake::testing::{Face, Geometry, GltfBuilder, Material};
    let mut gltf = GltfBuilder::new(name);
    let grey = gltf.add_material(Material::grey("grey", 0.7));
    let panel = gltf.add_material(Material::grey("panel", 0.8).emitting([1.0; 3], 10.0));
    let shell = Geometry::box_faces(
        Vec3::new(-2.0, 0.0, -1.0),
        Vec3::new(2.0, 2.0, 1.0),
        &Face::ALL,
        4,
    )
    .flipped();
    let mesh = gltf.add_mesh("shell", shell, grey);
    gltf.add_mesh_node("shell", mesh);
    let light = Geometry::grid(corner, across, Vec3::Z * 0.8, 1, 1);
    let mesh = gltf.add_mesh("panel", light, panel);
    gltf.add_mesh_node("panel", mesh);
    (gltf, grey)
}

/// A grey 2 × 2 m floor at y = 0 centred on the origin (4 × 4 quads); returns its material.
pub fn grey_floor(gltf: &mut lightbake::testing::GltfBuilder) -> usize {
    use glam::Vec3;
    use lightbake::testing::{Geometry, Material};
    let grey = gltf.add_material(Material::grey("grey", 0.5));
    let floor = Geometry::grid(
        Vec3::new(-1.0, 0.0, 1.0),
        Vec3::X * 2.0,
        Vec3::NEG_Z * 2.0,
        4,
        4,
    );
    let floor = gltf.add_mesh("floor", floor, grey);
    gltf.add_mesh_node("floor", floor);
    grey
}
