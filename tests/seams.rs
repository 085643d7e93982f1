//! Seam stitching (`lightmap::seams`): the two sides of a UV seam filter to the same value.
//!
//! Two fixtures: a smooth sphere on a floor (`testing::sphere_on_floor`), which xatlas cuts into
//! several charts, and the flat floor of `point_light.gltf` on pages too small to hold it whole,
//! so xatlas splits it into charts on several pages. At the default page size the committed
//! fixtures are flat faces meeting at creases and have no seams at all.

use lightbake::lightmap::seams::{self, SeamParams};
use lightbake::lightmap::{self, LightmapPages};
use lightbake::{BakeConfig, Baked, NoProgress, compute};

use crate::util::{fixture, quick, scratch};

fn config(seams: bool) -> BakeConfig {
    let mut c = quick();
    c.atlas.texels_per_unit = 16.0;
    c.output.seams = seams;
    c
}

fn bake_sphere(seams: bool) -> Baked {
    let dir = scratch();
    let path = dir.path().join("sphere_on_floor.gltf");
    lightbake::testing::sphere_on_floor()
        .write_gltf(&path)
        .unwrap();
    compute(&path, &config(seams), &NoProgress).unwrap()
}

#[test]
fn seams_close_on_a_chart_cut_sphere() {
    let baked = bake_sphere(true);
    let r = baked.seams.expect("stitching is on");
    assert!(r.before.edges > 20, "{r:?}");
    assert!(r.before.samples >= r.before.edges);
    // The sides disagree visibly before (noise, independent texel grids) ...
    assert!(r.before.mean_abs_diff > 0.02 * r.before.mean_value, "{r:?}");
    // ... and agree after: measured 0.12 → 0.004 (mean) relative to the mean value.
    assert!(
        r.after.mean_abs_diff <= 0.1 * r.before.mean_abs_diff,
        "mean {} -> {}",
        r.before.mean_abs_diff,
        r.after.mean_abs_diff
    );
    assert!(
        r.after.max_abs_diff <= 0.3 * r.before.max_abs_diff,
        "max {} -> {}",
        r.before.max_abs_diff,
        r.after.max_abs_diff
    );
    // Stitching moves values between the sides; it does not darken or brighten the seams.
    assert!(
        (r.after.mean_value / r.before.mean_value - 1.0).abs() < 0.05,
        "{r:?}"
    );
    for page in &baked.pages.pages {
        assert!(
            page.rgb
                .iter()
                .all(|v| v.is_finite() && v.min_element() >= 0.0)
        );
    }
}

#[test]
fn seams_close_on_a_flat_floor_split_across_pages() {
    // A 4 × 4 m floor at 8 texels/m is 32 × 32 texels: on 32-texel pages xatlas cuts it up.
    let mut c = quick();
    c.atlas.max_page_size = 32;
    let baked = compute(&fixture("point_light.gltf"), &c, &NoProgress).unwrap();
    assert!(baked.pages.pages.len() > 1);
    let r = baked.seams.unwrap();
    assert!(r.before.edges > 10, "{r:?}");
    // Direct light only, exact: the sides differ by how each grid reconstructs the falloff.
    // Measured at 16 texels/m: 1.3 % → 0.01 % of the mean (mean), 3.8 % → 0.1 % (max).
    assert!(r.before.mean_abs_diff > 1e-3 * r.before.mean_value, "{r:?}");
    assert!(
        r.after.mean_abs_diff <= 0.1 * r.before.mean_abs_diff,
        "{r:?}"
    );
    assert!(r.after.max_abs_diff <= 0.3 * r.before.max_abs_diff, "{r:?}");
}

#[test]
fn no_seams_at_the_default_page_size_changes_nothing() {
    // Unsplit, the Cornell box is one chart per wall: nothing to stitch. (Split, the floor's
    // cuts around the blocks run on to its border as ordinary seams.)
    let mut c = quick();
    c.atlas.split_junctions = false;
    let baked = compute(&fixture("cornell_box.gltf"), &c, &NoProgress).unwrap();
    let r = baked.seams.unwrap();
    assert_eq!((r.before.edges, r.texels), (0, 0));
    let plain = dilated(&baked);
    for (a, b) in baked.pages.pages.iter().zip(&plain.pages) {
        assert_eq!(a.rgb, b.rgb);
    }
}

/// The pages as the pipeline leaves them before stitching: laid out, then dilated.
fn dilated(baked: &Baked) -> LightmapPages {
    let mut pages = LightmapPages::from_texels(&baked.texels, &baked.lightmap);
    lightmap::dilate(&mut pages, config(true).atlas.padding.max(2) * 2);
    pages
}

#[test]
fn off_leaves_pages_alone_and_on_changes_only_texels_along_seams() {
    let off = bake_sphere(false);
    assert!(off.seams.is_none());
    let plain = dilated(&off);
    for (a, b) in off.pages.pages.iter().zip(&plain.pages) {
        assert_eq!(a.rgb, b.rgb);
    }

    let on = bake_sphere(true);
    assert_eq!(on.lightmap, off.lightmap, "stitching runs after the solve");
    let report = on.seams.unwrap();
    let found = seams::find(&on.scene, &on.atlas, &SeamParams::default());
    let mut changed = 0;
    for (k, (a, b)) in on.pages.pages.iter().zip(&plain.pages).enumerate() {
        for (i, (x, y)) in a.rgb.iter().zip(&b.rgb).enumerate() {
            if x == y {
                continue;
            }
            changed += 1;
            // A changed texel is one of the 4 a bilinear lookup on a seam reads: its centre
            // is within one texel (in x and in y) of a seam sample on its page.
            let centre =
                glam::Vec2::new((i as u32 % a.width) as f32, (i as u32 / a.width) as f32) + 0.5;
            let near = found.samples.iter().any(|s| {
                (0..2).any(|side| {
                    s.page[side] == k as u32 && (s.uv[side] - centre).abs().max_element() < 1.0
                })
            });
            assert!(near, "page {k} texel {i} changed away from every seam");
        }
    }
    assert!(
        changed > 0 && changed <= report.texels,
        "{changed} of {}",
        report.texels
    );
    let total: usize = on.pages.pages.iter().map(|p| p.rgb.len()).sum();
    assert!(changed * 5 < total, "{changed} of {total} texels changed");
}

#[test]
fn stitching_is_deterministic() {
    let baked = bake_sphere(false);
    let params = SeamParams::default();
    let mut a = baked.pages.clone();
    let mut b = baked.pages.clone();
    let ra = seams::stitch_bake(&baked.scene, &baked.atlas, &mut a, &params);
    // Once more, on a single thread (stitching is serial; nothing may depend on the pool).
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let rb = pool.install(|| seams::stitch_bake(&baked.scene, &baked.atlas, &mut b, &params));
    assert_eq!(
        (ra.before, ra.after, ra.texels),
        (rb.before, rb.after, rb.texels)
    );
    for (x, y) in a.pages.iter().zip(&b.pages) {
        assert_eq!(x.rgb, y.rgb);
    }
}

#[test]
fn creases_are_not_seams() {
    // The Cornell box: boxes and walls, every shared edge a 90° crease.
    let (scene, source) = lightbake::scene::load(&fixture("cornell_box.gltf")).unwrap();
    let atlas = lightbake::atlas::build(&scene, &source, &BakeConfig::medium().atlas).unwrap();
    let params = SeamParams::default();
    assert_eq!(seams::find(&scene, &atlas, &params).edges.len(), 0);
    // The same edges are found once normals are ignored: the test sees them.
    let blind = SeamParams {
        min_normal_dot: -2.0,
        min_face_dot: -2.0,
        ..params
    };
    assert!(!seams::find(&scene, &atlas, &blind).edges.is_empty());
}

#[test]
fn cli_reports_seams_and_no_seams_turns_them_off() {
    let run = |extra: &[&str]| {
        let dir = scratch();
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_lightbake"))
            .args(["bake", fixture("point_light.gltf").to_str().unwrap(), "-o"])
            .arg(dir.path())
            .args([
                "--texels-per-unit",
                "8",
                "--rays",
                "16",
                "--max-page-size",
                "32",
            ])
            .args(extra)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let on = run(&[]);
    assert!(
        on.contains("seams: ") && on.contains(" edges, max diff "),
        "{on}"
    );
    let off = run(&["--no-seams"]);
    assert!(!off.contains("seams: "), "{off}");
}

/// Mean `|A − B|` between the two sides of the T-junction lines of `testing::t_junction_floor`
/// (z = 1 and z = 2, x ∈ (0, 3)) as a renderer reads the written bake, and the mean value there.
fn t_junction_mismatch(seams: bool) -> (f32, f32, lightbake::lightmap::seams::SeamReport) {
    use lightbake::reference::points::{self, Point};
    let dir = scratch();
    let input = dir.path().join("t_junction_floor.gltf");
    lightbake::testing::t_junction_floor()
        .write_gltf(&input)
        .unwrap();
    let out = dir.path().join("out");
    let report = lightbake::bake(&input, &out, &config(seams), &NoProgress).unwrap();
    let baked = lightbake::render::RenderScene::load(&report.files[0]).unwrap();
    let side = |z: f32| {
        (0..300)
            .map(|k| Point {
                position: glam::Vec3::new((k as f32 + 0.5) / 100.0, 0.0, z),
                normal: glam::Vec3::Y,
                shading_normal: glam::Vec3::Y,
            })
            .collect::<Vec<_>>()
    };
    let value = |points: Vec<Point>| -> Vec<glam::Vec3> {
        points::look_up(&baked, &points)
            .into_iter()
            .map(|l| l.expect("the floor is under every point").value)
            .collect()
    };
    let (mut diff, mut sum, mut n) = (0.0, 0.0, 0.0);
    for z in [1.0, 2.0] {
        let below = value(side(z - 1e-4));
        let above = value(side(z + 1e-4));
        for (a, b) in below.iter().zip(&above) {
            diff += (*a - *b).abs().element_sum() / 3.0;
            sum += (*a + *b).element_sum() / 6.0;
            n += 1.0;
        }
    }
    (diff / n, sum / n, report.seams.unwrap_or_default())
}

#[test]
fn seams_close_at_t_junctions() {
    // Edges meet mid-edge (a long tile against three short ones) and partly (tiles offset by
    // half a tile, in another instance): seams no shared end points would find.
    let (open, mean, _) = t_junction_mismatch(false);
    let (stitched, _, report) = t_junction_mismatch(true);
    assert!(open > 0.01 * mean, "open {open} of mean {mean}");
    assert!(report.before.edges >= 5, "{report:?}");
    // Measured: see the module docs of `lightmap::seams`.
    assert!(stitched <= 0.1 * open, "{open} -> {stitched} (mean {mean})");
}
