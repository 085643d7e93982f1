//! Dense meshes (issue 28): a generated height field far finer than the lightmap's texels is
//! charted by smooth patches (`atlas::xatlas`, dense meshes), bakes with every triangle in a
//! chart and no texel centre claimed twice, and writes the same bytes on one and two threads.

use lightbake::NoProgress;
use lightbake::atlas::Overlaps;

use crate::util::{list_files, quick, scratch};

#[test]
fn a_dense_height_field_bakes_with_every_triangle_charted() {
    let dir = scratch();
    let input = dir.path().join("height_field.glb");
    // 80 000 triangles of 1/80 000 m², 0.013 texel² each at 32 texels per metre.
    lightbake::testing::height_field(80_000)
        .write_glb(&input)
        .unwrap();
    let mut config = quick();
    config.atlas.texels_per_unit = 32.0;

    let prepared = lightbake::prepare(&input, &config, &NoProgress).unwrap();
    let (scene, atlas) = (&prepared.scene, &prepared.atlas);
    assert!(scene.triangles.len() >= 80_000);
    for page in 0..atlas.pages.len() as u32 {
        let on_page: Vec<_> = (0..scene.triangles.len() as u32)
            .map(|t| atlas.triangle_uv(scene, t))
            .filter(|&(_, p)| p == page)
            .map(|(uv, _)| uv)
            .collect();
        let overlaps = Overlaps::find(atlas.pages[page as usize], on_page.into_iter());
        assert_eq!(overlaps.overlapping, 0, "page {page}: {overlaps:?}");
    }
    let flat = (0..scene.triangles.len() as u32)
        .filter(|&t| {
            let ([a, b, c], _) = atlas.triangle_uv(scene, t);
            (b - a).perp_dot(c - a) == 0.0
        })
        .count();
    assert_eq!(flat, 0, "triangles without lightmap area");
    // About 1.02 m² at 32² texels per m², less chart borders.
    assert!(
        prepared.texels.len() > 900,
        "{} texels",
        prepared.texels.len()
    );

    let bake = |threads: usize| {
        let out = scratch();
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| lightbake::bake(&input, out.path(), &config, &NoProgress))
            .unwrap();
        let files = list_files(out.path());
        let bytes: Vec<Vec<u8>> = files
            .iter()
            .map(|f| std::fs::read(out.path().join(f)).unwrap())
            .collect();
        gltf::import(out.path().join("height_field.glb")).unwrap();
        (files, bytes)
    };
    let (one, two) = (bake(1), bake(2));
    assert_eq!(one.0, two.0);
    assert!(one.1 == two.1, "the bake differs between 1 and 2 threads");
}
