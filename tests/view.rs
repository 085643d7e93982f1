//! `lightbake view` in a real browser: a draft bake of the Cornell box opened in headless
//! Chromium (Debian's `chromium`, driven by Node's playwright-core through
//! `tests/view_browser.js`). The lit view from the glTF camera must match `lightbake render`
//! of the same camera, and every view must draw something else (the point-error view with a
//! point reference of 300 points).
//!
//! Runs only when `LIGHTBAKE_BROWSER_TEST` names the `node_modules` directory holding
//! playwright-core (`.ci/run` sets it, so CI always runs it); without it the test says so
//! and passes, since it needs a browser and Node. With `LIGHTBAKE_GALLERY` set to a directory
//! it also copies each view's picture there (`examples/gallery/view_<view>.png`).

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdout, Command, Stdio};

use glam::Vec3;
use lightbake::metrics;

use crate::util::{fixture, scratch};

/// The views the page offers (the last with a point reference), in the panel's order.
const VIEWS: [&str; 6] = ["lit", "lightmap", "albedo", "density", "charts", "error"];
const SIZE: u32 = 128;
/// The browser draws the lit view at SUPER × SIZE and its SUPER × SUPER pixel means are the
/// image (16 regular samples per pixel, as `render`'s 16 jittered ones anti-alias it).
const SUPER: u32 = 4;
/// Side of the pixel blocks whose means are compared: the two sampling patterns still differ
/// along edges.
const BLOCK: u32 = 4;
/// Largest relative RMS difference of block means between the browser's lit view and
/// `render`, both as shown at exposure 0 (clamped at 1). Measured 0.68% (SwiftShader in
/// Chromium 156, three.js r187); each wrong setting measured far above it: nearest instead of
/// linear filtering 2.2%, EXR rows not flipped 48%, `lightMapIntensity` 1 instead of π 57%,
/// TEXCOORD_0 instead of TEXCOORD_1 69%.
const TOLERANCE: f32 = 0.015;
/// Fraction of pixels (by more than 8 of 255 in a channel) a view switch must change; the
/// chart borders change least (thin lines over the lightmap view).
const MIN_CHANGED: f32 = 0.01;

/// Held by each browser test: two Chromiums drawing with SwiftShader at once on a loaded
/// machine made the page load time out (30 s) in a full test run.
static ONE_BROWSER: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// The `lightbake view` server (and its stdout, kept open), ended when dropped.
struct Server(Child, BufReader<ChildStdout>);

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn lightbake(args: &[&str]) {
    let out = Command::new(env!("CARGO_BIN_EXE_lightbake"))
        .args(args)
        .output()
        .expect("run lightbake");
    assert!(
        out.status.success(),
        "lightbake {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Starts `lightbake view` with a point reference on a free port; returns it and the URL it
/// printed.
fn view(scene: &Path, points: &Path) -> (Server, String) {
    view_with(scene, &["--points", points.to_str().unwrap()])
}

/// Starts `lightbake view` of `scene` with the `extra` options on a free port.
fn view_with(scene: &Path, extra: &[&str]) -> (Server, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_lightbake"))
        .args(["view", scene.to_str().unwrap(), "--port", "0"])
        .args(extra)
        .stdout(Stdio::piped())
        .spawn()
        .expect("start lightbake view");
    let stdout = BufReader::new(child.stdout.take().unwrap());
    let mut server = Server(child, stdout);
    let mut url = String::new();
    server.1.read_line(&mut url).unwrap();
    assert!(url.starts_with("http://127.0.0.1:"), "printed {url:?}");
    (server, url.trim().to_string())
}

/// Means of `block` × `block` pixel blocks of a `size`² image.
fn blocks(rgb: &[Vec3], size: u32, block: u32) -> Vec<Vec3> {
    let n = size / block;
    (0..n * n)
        .map(|b| {
            let (bx, by) = (b % n * block, b / n * block);
            let sum: Vec3 = (0..block * block)
                .map(|k| rgb[((by + k / block) * size + bx + k % block) as usize])
                .sum();
            sum / (block * block) as f32
        })
        .collect()
}

/// Bakes fixture `name` at draft (with the `extra` bake options) into `dir/out` and renders the
/// bake's first camera at `SIZE`² with `lightbake render`: the fixture, the baked glTF and the
/// rendered EXR.
fn bake_and_render(dir: &Path, name: &str, extra: &[&str]) -> (PathBuf, PathBuf, PathBuf) {
    let (scene, out) = (fixture(name), dir.join("out"));
    let baked = out.join(name);
    let mut bake = vec![
        "bake",
        scene.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--quality",
        "draft",
        "--quiet",
    ];
    bake.extend(extra);
    lightbake(&bake);
    let rendered = dir.join("render.exr");
    let size = format!("{SIZE}x{SIZE}");
    lightbake(&[
        "render",
        baked.to_str().unwrap(),
        "--camera",
        "0",
        "--size",
        &size,
        "-o",
        rendered.to_str().unwrap(),
        "--quiet",
    ]);
    (scene, baked, rendered)
}

/// What a browser test needs: playwright-core's `node_modules` (CI sets
/// `LIGHTBAKE_BROWSER_TEST`; `None`, and the test skips, without it), the one browser at a
/// time, a scratch directory and its `shots` folder.
struct Browser {
    node_path: std::ffi::OsString,
    _one: std::sync::MutexGuard<'static, ()>,
    dir: tempfile::TempDir,
    shots: std::path::PathBuf,
}

impl Browser {
    fn take() -> Option<Browser> {
        let Some(node_path) = std::env::var_os("LIGHTBAKE_BROWSER_TEST") else {
            eprintln!("skipped: set LIGHTBAKE_BROWSER_TEST to playwright-core's node_modules");
            return None;
        };
        let one = ONE_BROWSER.lock().unwrap_or_else(|e| e.into_inner());
        let dir = scratch();
        let shots = dir.path().join("shots");
        std::fs::create_dir(&shots).unwrap();
        Some(Browser {
            node_path,
            _one: one,
            dir,
            shots,
        })
    }
}

#[test]
fn viewer_page_in_chromium_matches_render_and_every_view_differs() {
    let Some(one) = Browser::take() else { return };
    let (dir, shots, node_path) = (&one.dir, &one.shots, &one.node_path);
    let (scene, baked, rendered) = bake_and_render(dir.path(), "cornell_box.gltf", &[]);

    let points = dir.path().join("points.csv");
    lightbake(&[
        "reference",
        scene.to_str().unwrap(),
        "--points",
        "300",
        "--spp",
        "256",
        "-o",
        points.to_str().unwrap(),
    ]);

    let (_server, url) = view(&baked, &points);
    browser(&url, shots, node_path, &VIEWS);
    let difference = lit_vs_render(shots, &rendered);
    assert!(difference < TOLERANCE, "{difference}");

    // Each view draws another image than the one before it; the chart borders and the point
    // errors are also checked against the lightmap view they are drawn over (the smallest
    // changes).
    let image = |view: &str| {
        image::open(shots.join(format!("{view}.png")))
            .unwrap()
            .to_rgb8()
    };
    let over_lightmap = [["lightmap", "charts"], ["lightmap", "error"]];
    for pair in VIEWS
        .windows(2)
        .chain(over_lightmap.iter().map(|p| p.as_slice()))
    {
        let (a, b) = (image(pair[0]), image(pair[1]));
        assert_eq!(a.dimensions(), (SIZE, SIZE));
        let changed = a
            .pixels()
            .zip(b.pixels())
            .filter(|(p, q)| p.0.iter().zip(q.0).any(|(x, y)| x.abs_diff(y) > 8))
            .count() as f32
            / (SIZE * SIZE) as f32;
        eprintln!(
            "{} -> {}: {:.1}% of pixels changed",
            pair[0],
            pair[1],
            changed * 100.0
        );
        assert!(changed > MIN_CHANGED, "{pair:?}: {changed}");
    }
    if let Some(gallery) = std::env::var_os("LIGHTBAKE_GALLERY") {
        for view in VIEWS {
            let name = format!("view_{view}.png");
            std::fs::copy(
                shots.join(format!("{view}.png")),
                Path::new(&gallery).join(name),
            )
            .unwrap();
        }
    }
}

/// Runs `tests/view_browser.js` on the page at `url`: the lit view's pixels and a picture of
/// each of `views` into `shots`.
fn browser(url: &str, shots: &Path, node_path: &std::ffi::OsStr, views: &[&str]) {
    browser_with(url, shots, node_path, views, None);
}

/// [`browser`], and with `probe_spots` (`LIGHTBAKE_PROBE_SPOTS`, see the script) the probe
/// sphere's pictures too.
fn browser_with(
    url: &str,
    shots: &Path,
    node_path: &std::ffi::OsStr,
    views: &[&str],
    probe_spots: Option<&str>,
) {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/view_browser.js");
    let side = SIZE.to_string();
    let run = || {
        let mut node = Command::new("node");
        if let Some(spots) = probe_spots {
            node.env("LIGHTBAKE_PROBE_SPOTS", spots);
        }
        node.arg(&script)
            .args([
                url,
                shots.to_str().unwrap(),
                &side,
                &side,
                &(SIZE * SUPER).to_string(),
            ])
            .args(views)
            .env("NODE_PATH", node_path)
            .output()
            .expect("run node")
    };
    let mut node = run();
    // A Playwright timeout is the machine, not the page (a CI run on a loaded 2-core machine
    // once missed the page's load event by 120 s; software WebGL, a cold browser start): run
    // once more. Page errors and wrong pixels fail at once.
    if !node.status.success() && String::from_utf8_lossy(&node.stderr).contains("TimeoutError") {
        eprintln!(
            "the browser timed out; once more:\n{}",
            String::from_utf8_lossy(&node.stderr)
        );
        node = run();
    }
    assert!(
        node.status.success(),
        "{}",
        String::from_utf8_lossy(&node.stderr)
    );
}

/// Relative RMS difference of 4×4-pixel block means between the browser's lit view (in
/// `shots`) and `render`'s image, both as the page shows them at exposure 0.
fn lit_vs_render(shots: &Path, rendered: &Path) -> f32 {
    let lit: serde_json::Value =
        serde_json::from_slice(&std::fs::read(shots.join("lit.json")).unwrap()).unwrap();
    let fine: Vec<Vec3> = lit["rgb"]
        .as_array()
        .unwrap()
        .chunks(3)
        .map(|c| Vec3::from_array(std::array::from_fn(|k| c[k].as_f64().unwrap() as f32)))
        .collect();
    let browser = blocks(&fine, SIZE * SUPER, SUPER);
    let render = lightbake::output::read_exr(rendered).unwrap();
    assert_eq!(
        (render.width, render.height, browser.len()),
        (SIZE, SIZE, (SIZE * SIZE) as usize)
    );
    // What the page shows at exposure 0: radiance above 1 is white (the emitter, 17).
    let shown = |v: &[Vec3]| v.iter().map(|x| x.min(Vec3::ONE)).collect::<Vec<_>>();
    let (browser, render) = (shown(&browser), shown(&render.rgb));
    let difference = metrics::rmse_over_rms(
        &blocks(&browser, SIZE, BLOCK),
        &blocks(&render, SIZE, BLOCK),
        &[],
    );
    eprintln!(
        "browser vs render: {:.2}% over {BLOCK}x{BLOCK} blocks, {:.2}% per pixel, bias {:+.2}%",
        difference * 100.0,
        metrics::rmse_over_rms(&browser, &render, &[]) * 100.0,
        metrics::relative_bias(&browser, &render, &[]) * 100.0
    );
    difference
}

/// `--instancing share`: the instanced fixture's box is one mesh placed by two nodes, each with
/// its page rect in its node's extras; the page must apply the rect per node as `render` does.
#[test]
fn shared_meshes_in_chromium_match_render() {
    let Some(one) = Browser::take() else { return };
    let (dir, shots, node_path) = (&one.dir, &one.shots, &one.node_path);
    let (scene, baked, rendered) =
        bake_and_render(dir.path(), "instanced.gltf", &["--instancing", "share"]);
    let scene_s = scene.to_str().unwrap();
    let points = dir.path().join("points.csv");
    lightbake(&[
        "reference",
        scene_s,
        "--points",
        "50",
        "--spp",
        "16",
        "-o",
        points.to_str().unwrap(),
    ]);
    let (_server, url) = view(&baked, &points);
    browser(&url, shots, node_path, &["lit", "density"]);
    let difference = lit_vs_render(shots, &rendered);
    assert!(difference < TOLERANCE, "{difference}");
}

/// Two rooms sealed from each other by a wall, a ceiling panel lighting room A (x < 0) and
/// room B dark, a camera in room A: the scene of the probe sphere test.
fn sealed_rooms() -> lightbake::testing::GltfBuilder {
    use lightbake::testing::{Camera, Face, Geometry};
    let (mut gltf, grey) =
        crate::util::panel_room("sealed_rooms", Vec3::new(-1.5, 1.99, -0.4), Vec3::X);
    let wall = Geometry::box_faces(
        Vec3::new(-0.05, 0.0, -1.0),
        Vec3::new(0.05, 2.0, 1.0),
        &[Face::PosX, Face::NegX],
        4,
    );
    let mesh = gltf.add_mesh("wall", wall, grey);
    gltf.add_mesh_node("wall", mesh);
    gltf.add_camera_node(
        Camera::perspective("room A", 1.0, Some(1.0)),
        Vec3::new(-1.9, 1.6, 0.9),
        Vec3::new(-0.6, 0.7, -0.6),
    );
    gltf
}

/// `lightbake view` of a `--probes` bake: the page shows the probes (the toggle changes the
/// picture) and a sphere lit by them, whose centre pixel (facing the camera) is
/// `E(n)/π` of the SH the page got for the sphere's centre at the normal towards the eye, not
/// black in the lit room, and black once moved into the sealed dark room.
#[test]
fn probe_sphere_in_chromium_is_lit_by_the_probes_where_it_is() {
    let Some(one) = Browser::take() else { return };
    let (dir, shots, node_path) = (&one.dir, &one.shots, &one.node_path);
    let input = dir.path().join("sealed_rooms.gltf");
    std::fs::write(&input, sealed_rooms().to_gltf_bytes()).unwrap();
    let out = dir.path().join("out");
    lightbake(&[
        "bake",
        input.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--quality",
        "draft",
        "--probes",
        "--quiet",
    ]);
    let (_server, url) = view_with(&out.join("sealed_rooms.gltf"), &[]);
    // Room A under the panel, then room B, each seen from 0.8 m in front.
    let spots = [
        (Vec3::new(-1.0, 1.0, 0.0), Vec3::new(-1.0, 1.0, 0.8)),
        (Vec3::new(1.0, 1.0, 0.0), Vec3::new(1.0, 1.0, 0.8)),
    ];
    let json = serde_json::json!(
        spots
            .iter()
            .map(|(s, e)| serde_json::json!({"sphere": s.to_array(), "eye": e.to_array()}))
            .collect::<Vec<_>>()
    );
    browser_with(&url, shots, node_path, &["lit"], Some(&json.to_string()));

    let result: serde_json::Value =
        serde_json::from_slice(&std::fs::read(shots.join("probes.json")).unwrap()).unwrap();
    let floats = |v: &serde_json::Value| -> Vec<f32> {
        (v.as_array().unwrap().iter())
            .map(|x| x.as_f64().unwrap() as f32)
            .collect()
    };
    let mut centres = Vec::new();
    for (k, (sphere, eye)) in spots.iter().enumerate() {
        let spot = &result["spots"][k];
        let sh = floats(&spot["sh"]);
        let c: lightbake::probes::Sh2 =
            std::array::from_fn(|m| Vec3::new(sh[3 * m], sh[3 * m + 1], sh[3 * m + 2]));
        let centre = Vec3::from_slice(&floats(&spot["centre"]));
        let expected = lightbake::probes::sh::irradiance_over_pi(&c, (*eye - *sphere).normalize());
        eprintln!("sphere at {sphere}: centre pixel {centre}, E/π of its SH {expected}");
        assert!(
            (centre - expected).abs().max_element() <= 0.02 * expected.max_element() + 1e-4,
            "sphere at {sphere}: the shader gives {centre}, the SH {expected}"
        );
        centres.push(centre);
    }
    assert!(centres[0].min_element() > 0.05, "lit room: {}", centres[0]);
    assert!(
        centres[1].max_element() < 1e-3 * centres[0].max_element(),
        "the sealed room is dark: {} vs {}",
        centres[1],
        centres[0]
    );

    // The probe toggle draws the probes over the lit view.
    let image = |name: &str| image::open(shots.join(name)).unwrap().to_rgb8();
    let (off, on) = (image("probes_off.png"), image("probes_on.png"));
    let changed = (off.pixels().zip(on.pixels()))
        .filter(|(p, q)| p.0.iter().zip(q.0).any(|(x, y)| x.abs_diff(y) > 8))
        .count();
    eprintln!("probes shown: {changed} pixels changed");
    assert!(changed >= 20, "the probes changed {changed} pixels");
}
