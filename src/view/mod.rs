//! The viewer page: a baked scene in the browser, drawn by three.js as a renderer would draw
//! it (`lightbake view`).
//!
//! [`Viewer`] answers the page's requests: the page and the vendored three.js (embedded in the
//! binary, so it works offline), the files of the baked scene (read from its directory at
//! each request, so a new bake shows on reload) and, with a point reference, the per-point
//! error of the bake read as a renderer reads it ([`points::look_up`]). [`serve`] answers
//! them over HTTP on 127.0.0.1.
//!
//! The page (`web/viewer.js`) loads the output as any three.js user would: `GLTFLoader`, the
//! EXR page each primitive's `extras.lightmap.exr` names (`EXRLoader`, half float, rows
//! flipped so row 0 is the top as glTF images are, linear filtering, clamp to edge), as
//! `lightMap` on `TEXCOORD_1` (`channel = 1`) with `lightMapIntensity = π` (three.js divides
//! a light map by π, a texel holds `H/π`), on a Lambert material without lights. A mesh
//! baked with `--instancing share` takes the page its node's `extras.lightmap` names, and the
//! node's `scale_offset` as the texture's `repeat` and `offset` (a clone per node). three.js
//! r187 is vendored under `web/three/` (MIT, `web/three/LICENSE`).
//!
//! With light probes (a bake with `--probes`), the page also shows the probes (small spheres
//! coloured by their mean light, invalid ones red; a toggle) and a movable sphere lit by them
//! (arrow keys, Page Up/Down, or drag it): its L2 SH is the probes' interpolated at its centre
//! by this server, through [`Probes::sh_at`] with the same visibility test as
//! `lightbake probes --at` and `render` (`/probes/at?x,y,z`), and its shader evaluates the
//! irradiance per normal, `E(n)/π` times its albedo. Meshes of the glTF without a lightmap
//! are lit the same way, each from the probes at its bounding box's centre (per object, as a
//! three.js `LightProbe` lights an object); without probes they stay black apart from their
//! emission, as in `render`. A limit: the visibility test runs from that centre against the
//! whole scene, the object included, so a closed object hides every probe from its own centre
//! and takes the nearest valid probe (the lookup's last resort) instead of a blend.

use std::path::{Component, Path, PathBuf};

use serde_json::json;

use crate::metrics;
use crate::probes::Probes;
use crate::reference::points::{self, PointReference};
use crate::render::RenderScene;
use crate::trace::Tracer;
use crate::{Error, Result};

/// One answer to a request.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Reply {
    /// HTTP status: 200, or 404 for anything not served.
    pub(crate) status: u16,
    pub(crate) content_type: &'static str,
    pub(crate) body: Vec<u8>,
}

/// The embedded files of the page: URL path, content type, bytes.
const PAGE_FILES: &[(&str, &str, &[u8])] = {
    const JS: &str = "text/javascript; charset=utf-8";
    macro_rules! web {
        ($url:literal, $type:expr) => {
            ($url, $type, include_bytes!(concat!("web", $url)))
        };
    }
    &[
        (
            "/",
            "text/html; charset=utf-8",
            include_bytes!("web/index.html"),
        ),
        web!("/viewer.js", JS),
        web!("/three/build/three.module.js", JS),
        web!("/three/build/three.core.js", JS),
        web!("/three/examples/jsm/loaders/GLTFLoader.js", JS),
        web!("/three/examples/jsm/loaders/EXRLoader.js", JS),
        web!("/three/examples/jsm/utils/BufferGeometryUtils.js", JS),
        web!("/three/examples/jsm/utils/SkeletonUtils.js", JS),
        web!("/three/examples/jsm/libs/fflate.module.js", JS),
        web!("/three/examples/jsm/controls/OrbitControls.js", JS),
        web!("/three/LICENSE", "text/plain; charset=utf-8"),
    ]
};

/// URL prefix of the baked scene's directory.
const SCENE_PREFIX: &str = "/scene/";

/// What the page shows: a baked scene and, optionally, its per-point error.
#[derive(Clone, Debug)]
pub struct Viewer {
    /// The baked scene's directory (canonical): the only files served from disk lie under it.
    dir: PathBuf,
    /// The `.gltf`/`.glb` file name within `dir`.
    file: String,
    /// `/points.json`, when a point reference was given.
    points: Option<Vec<u8>>,
    /// The bake's probes and a tracer of its scene, when the glTF names probes.
    probes: Option<std::sync::Arc<ProbeLight>>,
}

/// The probes of the viewed bake and the scene's tracer, for `/probes/at`.
struct ProbeLight {
    probes: Probes,
    tracer: Tracer,
}

impl std::fmt::Debug for ProbeLight {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "ProbeLight({} probes)", self.probes.len())
    }
}

/// Whether the glTF or GLB at `path` names light probes in its root extras (a quick look at
/// its JSON, so a scene without probes is not loaded twice).
fn names_probes(path: &Path) -> bool {
    let Ok(bytes) = std::fs::read(path) else {
        return false;
    };
    // A GLB's JSON chunk: its length at bytes 12..16, the JSON from byte 20.
    let json = if bytes.starts_with(b"glTF") && bytes.len() >= 20 {
        let n = u32::from_le_bytes([bytes[12], bytes[13], bytes[14], bytes[15]]) as usize;
        bytes.get(20..20 + n).unwrap_or(&[])
    } else {
        &bytes[..]
    };
    serde_json::from_slice::<serde_json::Value>(json)
        .is_ok_and(|v| v["extras"][crate::probes::file::EXTRAS_KEY].is_object())
}

impl Viewer {
    /// A viewer of the baked scene `gltf` (written by `lightbake bake`); with `reference` (a
    /// point reference CSV) the bake is read at its points now, for the error view.
    pub fn new(gltf: &Path, reference: Option<&Path>) -> Result<Viewer> {
        let canonical = gltf.canonicalize().map_err(|e| Error::io(gltf, e))?;
        let file = canonical
            .file_name()
            .and_then(|n| n.to_str())
            .filter(|_| canonical.is_file())
            .ok_or_else(|| Error::invalid(gltf, "not a file with a UTF-8 name"))?
            .to_string();
        let dir = canonical.parent().unwrap_or(Path::new("/")).to_path_buf();
        let baked = match reference.is_some() || names_probes(&canonical) {
            true => Some(RenderScene::load(gltf)?),
            false => None,
        };
        let points = match (reference, &baked) {
            (Some(csv), Some(baked)) => {
                let text = std::fs::read_to_string(csv).map_err(|e| Error::io(csv, e))?;
                let reference = PointReference::from_csv(&text, csv)?;
                Some(point_errors(baked, &reference))
            }
            _ => None,
        };
        let probes = baked.and_then(|b| {
            let probes = b.probes?;
            Some(std::sync::Arc::new(ProbeLight {
                probes,
                tracer: b.tracer,
            }))
        });
        Ok(Viewer {
            dir,
            file,
            points,
            probes,
        })
    }

    /// The answer to a GET of `url` (path and query).
    pub(crate) fn respond(&self, url: &str) -> Reply {
        let path = url.split(['?', '#']).next().unwrap_or("");
        let found = |content_type, body| Reply {
            status: 200,
            content_type,
            body,
        };
        if let Some((_, content_type, bytes)) = PAGE_FILES.iter().find(|(p, ..)| *p == path) {
            return found(content_type, bytes.to_vec());
        }
        match path {
            "/info.json" => {
                let info = json!({
                    "scene": format!("{SCENE_PREFIX}{}", encode(&self.file)),
                    "points": self.points.is_some(),
                    "probes": self.probes.is_some(),
                });
                found("application/json", info.to_string().into_bytes())
            }
            "/points.json" if self.points.is_some() => {
                found("application/json", self.points.clone().unwrap_or_default())
            }
            "/probes/at" => match (&self.probes, probe_query(url)) {
                (Some(light), Some(p)) => found("application/json", light.sh_json(p).into_bytes()),
                _ => not_found(),
            },
            _ => path
                .strip_prefix(SCENE_PREFIX)
                .and_then(|rest| self.scene_file(rest))
                .map_or_else(not_found, |(t, body)| found(t, body)),
        }
    }

    /// A file of the scene's directory by its URL-encoded relative path; `None` for paths
    /// that leave the directory (`..`, absolute, links out of it) or cannot be read.
    fn scene_file(&self, encoded: &str) -> Option<(&'static str, Vec<u8>)> {
        let relative = percent_encoding::percent_decode_str(encoded)
            .decode_utf8()
            .ok()?;
        let relative = Path::new(relative.as_ref());
        if !relative
            .components()
            .all(|c| matches!(c, Component::Normal(_)))
        {
            return None;
        }
        let path = self.dir.join(relative).canonicalize().ok()?;
        if !path.starts_with(&self.dir) {
            return None;
        }
        let content_type = match path.extension().and_then(|e| e.to_str()) {
            Some("gltf") => "model/gltf+json",
            Some("glb") => "model/gltf-binary",
            Some("png") => "image/png",
            Some("jpg" | "jpeg") => "image/jpeg",
            Some("exr") => "image/x-exr",
            Some("json") => "application/json",
            Some("ktx2") => "image/ktx2",
            _ => "application/octet-stream",
        };
        Some((content_type, std::fs::read(path).ok()?))
    }
}

/// The point of a `/probes/at?x,y,z` query (finite coordinates only).
fn probe_query(url: &str) -> Option<glam::Vec3> {
    let (_, query) = url.split_once('?')?;
    let v: Vec<f32> = query
        .split(',')
        .map(|c| c.trim().parse::<f32>().ok().filter(|x| x.is_finite()))
        .collect::<Option<_>>()?;
    match v[..] {
        [x, y, z] => Some(glam::Vec3::new(x, y, z)),
        _ => None,
    }
}

impl ProbeLight {
    /// `{"sh": [27 floats]}`: the probes' coefficients interpolated at `p` (coefficient `m` of
    /// channel `c` at `3m + c`, the probe file's order), probes `p` cannot see left out.
    fn sh_json(&self, p: glam::Vec3) -> String {
        let c = self.probes.sh_at(p, |q| !self.tracer.occluded(p, q));
        let flat: Vec<f32> = c.iter().flat_map(|v| v.to_array()).collect();
        json!({ "sh": flat }).to_string()
    }
}

fn not_found() -> Reply {
    Reply {
        status: 404,
        content_type: "text/plain; charset=utf-8",
        body: b"not found".to_vec(),
    }
}

/// A file name as one URL path segment.
fn encode(name: &str) -> String {
    percent_encoding::utf8_percent_encode(name, percent_encoding::NON_ALPHANUMERIC).to_string()
}

/// The page's `/points.json`: per point its position, normal, reference and baked `H/π` (null
/// where no lightmapped surface lies under it) and relative error — the largest over channels
/// of [`metrics::floored_relative_errors`], as `lightbake compare` reports them.
fn point_errors(baked: &RenderScene, reference: &PointReference) -> Vec<u8> {
    let lookups = points::look_up(baked, &reference.points);
    let (x, r): (Vec<_>, Vec<_>) = lookups
        .iter()
        .zip(&reference.mean)
        .filter_map(|(l, m)| l.map(|l| (l.value, *m)))
        .unzip();
    let mut errors = metrics::floored_relative_errors(&x, &r, &[])
        .chunks(3)
        .map(|c| c.iter().copied().fold(0.0, f32::max))
        .collect::<Vec<_>>()
        .into_iter();
    let list: Vec<_> = lookups
        .iter()
        .zip(&reference.points)
        .zip(&reference.mean)
        .map(|((l, p), m)| {
            json!({
                "position": p.position.to_array(),
                "normal": p.normal.to_array(),
                "reference": m.to_array(),
                "baked": l.map(|l| l.value.to_array()),
                "error": l.and_then(|_| errors.next()),
            })
        })
        .collect();
    json!({ "points": list }).to_string().into_bytes()
}

/// Answers the viewer's requests on `server` until it is unblocked (or fails).
pub fn serve(viewer: &Viewer, server: &tiny_http::Server) {
    for request in server.incoming_requests() {
        let reply = if *request.method() == tiny_http::Method::Get {
            viewer.respond(request.url())
        } else {
            not_found()
        };
        let header = tiny_http::Header::from_bytes("Content-Type", reply.content_type)
            .expect("content types are valid header values");
        let response = tiny_http::Response::from_data(reply.body)
            .with_status_code(reply.status)
            .with_header(header);
        // A browser that went away mid-reply is not the server's failure.
        let _ = request.respond(response);
    }
}

/// Binds the viewer's HTTP server on 127.0.0.1 (`port` 0: any free port).
pub fn bind(port: u16) -> Result<tiny_http::Server> {
    tiny_http::Server::http(("127.0.0.1", port)).map_err(|e| {
        Error::io(
            format!("cannot listen on 127.0.0.1:{port}"),
            std::io::Error::other(e),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn viewer() -> (tempfile::TempDir, Viewer) {
        let dir = tempfile::tempdir().unwrap();
        let scene = dir.path().join("out");
        std::fs::create_dir(&scene).unwrap();
        std::fs::write(scene.join("a b.gltf"), "{}").unwrap();
        std::fs::write(scene.join("a b_lightmap0.exr"), "exr").unwrap();
        std::fs::write(dir.path().join("secret"), "no").unwrap();
        let v = Viewer::new(&scene.join("a b.gltf"), None).unwrap();
        (dir, v)
    }

    #[test]
    fn serves_the_page_the_scene_files_and_nothing_outside_them() {
        let (_dir, v) = viewer();
        assert_eq!(v.respond("/").status, 200);
        assert!(v.respond("/viewer.js?x=1").body.starts_with(b"//"));
        let info: serde_json::Value =
            serde_json::from_slice(&v.respond("/info.json").body).unwrap();
        assert_eq!(info["scene"], "/scene/a%20b%2Egltf");
        assert_eq!(info["points"], false);
        let exr = v.respond("/scene/a%20b_lightmap0.exr");
        assert_eq!((exr.status, exr.content_type), (200, "image/x-exr"));
        assert_eq!(exr.body, b"exr");
        for outside in [
            "/scene/../secret",
            "/scene/%2E%2E/secret",
            "/scene/%2Fetc%2Fpasswd",
            "/scene/",
            "/secret",
            "/points.json",
        ] {
            assert_eq!(v.respond(outside).status, 404, "{outside}");
        }
    }

    #[test]
    fn probe_queries_parse_three_finite_numbers_and_need_probes() {
        assert_eq!(
            probe_query("/probes/at?1,-2.5,3e-1"),
            Some(glam::Vec3::new(1.0, -2.5, 0.3))
        );
        for bad in [
            "/probes/at",
            "/probes/at?1,2",
            "/probes/at?1,2,3,4",
            "/probes/at?1,x,3",
            "/probes/at?1,NaN,3",
            "/probes/at?inf,0,0",
        ] {
            assert_eq!(probe_query(bad), None, "{bad}");
        }
        // A bake without probes answers no probe queries, and says so in its info.
        let (_dir, v) = viewer();
        assert_eq!(v.respond("/probes/at?0,0,0").status, 404);
        let info: serde_json::Value =
            serde_json::from_slice(&v.respond("/info.json").body).unwrap();
        assert_eq!(info["probes"], false);
    }

    #[test]
    fn every_embedded_module_import_is_served() {
        let (_dir, v) = viewer();
        for (path, ..) in PAGE_FILES.iter().filter(|(p, ..)| p.ends_with(".js")) {
            let text = String::from_utf8(v.respond(path).body).unwrap();
            let base = &path[..path.rfind('/').unwrap()];
            for line in text
                .lines()
                .filter(|l| l.trim_start().starts_with("import"))
            {
                let Some(target) = line.split(['\'', '"']).nth(1) else {
                    continue; // a multi-line import: its `from` line is checked below
                };
                check_import(&v, base, target);
            }
            for line in text.lines().filter(|l| l.starts_with("} from ")) {
                check_import(&v, base, line.split(['\'', '"']).nth(1).unwrap());
            }
        }
    }

    /// `target`, imported by a file under `base`, is served (bare `three` and `three/addons/`
    /// go through the page's import map).
    fn check_import(v: &Viewer, base: &str, target: &str) {
        let url = if target == "three" {
            "/three/build/three.module.js".to_string()
        } else if let Some(rest) = target.strip_prefix("three/addons/") {
            format!("/three/examples/jsm/{rest}")
        } else {
            let mut parts: Vec<&str> = base.split('/').collect();
            for part in target.split('/') {
                match part {
                    "." => {}
                    ".." => {
                        parts.pop();
                    }
                    p => parts.push(p),
                }
            }
            parts.join("/")
        };
        assert_eq!(v.respond(&url).status, 200, "{base} imports {target}");
    }
}
