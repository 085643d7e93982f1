//! Layout figures shared by the atlas programs (`atlas_speed`, `dense_unwrap`): a digest of
//! the layout, its chart count and overlapping texel centres.

use lightbake::atlas::{Atlas, Overlaps};
use lightbake::scene::Scene;

/// FNV-1a over every page size, xref, UV bit pattern, triangle and page: equal digests mean
/// byte-identical layouts.
pub fn digest(atlas: &Atlas) -> u64 {
    let mut words: Vec<u32> = atlas
        .pages
        .iter()
        .flat_map(|p| [p.width, p.height])
        .collect();
    for inst in &atlas.instances {
        words.extend(&inst.xref);
        words.extend(
            inst.uv
                .iter()
                .flat_map(|uv| [uv.x.to_bits(), uv.y.to_bits()]),
        );
        words.extend(inst.triangles.iter().flatten());
        words.extend(&inst.triangle_page);
    }
    words.iter().fold(0xcbf29ce484222325, |h, &w| {
        (h ^ u64::from(w)).wrapping_mul(0x100000001b3)
    })
}

/// Charts: triangles joined through shared atlas vertex pairs (edges inside a chart), per
/// instance.
pub fn charts(atlas: &Atlas) -> usize {
    atlas.instances.iter().map(|inst| inst.chart_count()).sum()
}

/// Texel centres strictly inside more than one triangle of the same page.
pub fn overlapping(scene: &Scene, atlas: &Atlas) -> u64 {
    (0..atlas.pages.len() as u32)
        .map(|page| {
            let triangles = (0..scene.triangles.len() as u32)
                .map(|t| atlas.triangle_uv(scene, t))
                .filter(|&(_, p)| p == page)
                .map(|(uv, _)| uv);
            Overlaps::find(atlas.pages[page as usize], triangles).overlapping
        })
        .sum()
}
