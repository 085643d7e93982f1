//! Stage 9 — `Render`: a camera view of a baked scene, with an optional ray-traced specular
//! layer (the classic two-pass method: radiosity for diffuse interreflection, ray tracing for
//! the view-dependent part).
//!
//! Diffuse shading at a visible point `x` (TEXCOORD_0 → `uv0`, TEXCOORD_1 → `uv1`):
//!
//! ```text
//!   L_d(x) = baseColor(uv0) · lightmap(uv1) + Le(uv0)         lightmap = H/π (bilinear)
//! ```
//!
//! When the bake has directional pages (`bake --directional`), `lightmap(uv1)` is replaced by
//! the L1 reconstruction `max(0, L0 + L1·n)` (each page bilinear at `uv1`;
//! `lightmap::directional`) at the shading normal `n`: the material's `normalTexture` applied to
//! the interpolated normal ([`Scene::shading_normal`]). Without directional pages a normal map
//! changes nothing in the diffuse term (the lightmap holds one value per texel).
//!
//! With `specular` on, surfaces with `roughness ≤ GLOSSY_MAX_ROUGHNESS` become nodes of a
//! Whitted ray tree (the `shade` module documents the model: Schlick Fresnel, GGX glossy lobe,
//! refraction with absorption, energy-conserving composite). Leaves of the tree (depth limit,
//! rough surfaces) take `L_d` from the lightmap, so indirect diffuse light is never re-traced.
//!
//! | Parameter (`RenderOptions`) | Default | Meaning |
//! |---|---|---|
//! | `width`, `height` | 512 × 512 | image size in pixels |
//! | `spp` | 16 | jittered samples per pixel (stratified in a √spp grid); the mean when adaptive |
//! | `adaptive` | true | spend the samples where the image needs them (the `adaptive` module) |
//! | `specular` | false | build the ray tree at specular surfaces |
//! | `max_depth` | 6 | tree depth; hits at this depth are leaves (`L_d`) |
//! | `glossy_samples` | 8 | GGX rays at a glossy primary hit (1 deeper in the tree) |
//! | `background` | 0 | radiance of rays that leave the scene |
//! | `seed` | 0 | random streams are seeded by (seed, pixel) |
//!
//! Input: a glTF written by `lightbake bake`: every baked primitive has `TEXCOORD_1` and
//! `extras.lightmap = {"exr", "page"}` (a shared mesh's node carries it with its page rect,
//! `scale_offset`, which the loader applies to `TEXCOORD_1`); the EXR pages hold `H/π`. The scene loader resolves
//! everything the renderer reads — each instance's EXR page, each material's specular
//! parameters (`scene::Surface`), the cameras — so this module never looks at glTF JSON. Scenes without any lightmap are
//! refused. As glTF asks, back faces of single-sided materials are culled (rays pass through
//! them); the bake writes a double-sided surface as two single-sided primitives back to back. Limits: no alpha, no texture transforms, punctual lights are invisible (their light
//! is in the lightmap), and the baker treated glass and mirrors as Lambertian (ρ = baseColor),
//! so shadows behind glass are as dark as behind any opaque object of that colour.

mod adaptive;
mod shade;

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};
use rayon::prelude::*;

/// The loader resolves the document's cameras into [`Scene::cameras`]; the renderer's callers
/// choose among them with these.
pub use crate::scene::{Camera, GltfCamera, select};

use crate::lightmap::Page;
use crate::probes::Probes;
use crate::sampling::Rng;
use crate::scene::{self, Scene};
use crate::trace::Tracer;
use crate::{Error, Result, output};

/// What to render and how.
#[derive(Clone, Debug)]
pub struct RenderOptions {
    /// Pixels across.
    pub width: u32,
    /// Pixels down.
    pub height: u32,
    /// Jittered samples per pixel (the mean over the image when adaptive).
    pub spp: u32,
    /// Spend the samples where the image needs them.
    pub adaptive: bool,
    /// Add the ray-traced specular layer (mirrors, glossy metals, glass).
    pub specular: bool,
    /// Depth of the specular ray tree.
    pub max_depth: u32,
    /// GGX rays at a glossy primary hit.
    pub glossy_samples: u32,
    /// Radiance of rays that leave the scene.
    pub background: Vec3,
    /// Seed of the random streams (seeded by seed and pixel).
    pub seed: u64,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            width: 512,
            height: 512,
            spp: 16,
            adaptive: true,
            specular: false,
            max_depth: 6,
            glossy_samples: 8,
            background: Vec3::ZERO,
            seed: 0,
        }
    }
}

/// A baked scene ready to render: geometry, materials and cameras (all resolved by the loader),
/// BVH and lightmap pages.
pub struct RenderScene {
    /// The baked glTF it was loaded from.
    pub path: PathBuf,
    /// Geometry, materials, lights and cameras, as the loader resolved them.
    pub scene: Scene,
    /// The BVH over the scene.
    pub tracer: Tracer,
    /// Decoded EXR pages (one per distinct `extras.lightmap` file).
    pub pages: Vec<Page>,
    /// Page of each scene instance (`None`: the primitive has no lightmap; it is lit by the
    /// probes when the bake has them, else black apart from its emission).
    pub instance_page: Vec<Option<u32>>,
    /// Directional pages (L0, L1x, L1y, L1z, indices into `pages`) of each instance whose bake
    /// has them: diffuse light is then reconstructed for the shading normal (the material's
    /// `normalTexture` applied), see `lightmap::directional`.
    pub(crate) instance_directional: Vec<Option<[u32; 4]>>,
    /// Per scene triangle: its back face is culled (glTF's `"doubleSided": false`; a baked
    /// double-sided wall is two such primitives, back to back, which would z-fight otherwise).
    /// Transmissive surfaces are kept: a single-sided one bounds a volume, and its back face
    /// is where rays leave the glass.
    pub(crate) cull_back: Vec<bool>,
    /// The bake's light probes, when its root `extras.light_probes` names a probe file
    /// (`crate::probes`): the light at points off the baked surfaces.
    pub probes: Option<Probes>,
}

/// The probe file the glTF `json` at `path` names in its root extras, read.
fn load_probes(path: &Path, json: &serde_json::Value) -> Result<Option<Probes>> {
    let key = crate::probes::file::EXTRAS_KEY;
    let Some(uri) = json["extras"][key]["uri"].as_str() else {
        return Ok(None);
    };
    let uri = output::decode_uri(uri)
        .ok_or_else(|| Error::invalid(path, format!("extras.{key}.uri {uri:?} is not a file")))?;
    let file = path.parent().unwrap_or(Path::new(".")).join(uri);
    let bytes = std::fs::read(&file).map_err(|e| Error::io(&file, e))?;
    crate::probes::file::from_json(&bytes, &file).map(Some)
}

/// A rendered image: linear RGB radiance, row 0 at the top.
#[derive(Clone, Debug)]
pub struct Image {
    /// Pixels across.
    pub width: u32,
    /// Pixels down.
    pub height: u32,
    /// Radiance per pixel, row-major.
    pub rgb: Vec<Vec3>,
    /// Samples that came out NaN or infinite and were replaced by black (should be 0).
    pub nonfinite: u64,
    /// Rays traced (primary and secondary).
    pub rays: u64,
}

impl RenderScene {
    /// Loads a baked glTF/GLB and the EXR pages its primitives reference.
    pub fn load(path: &Path) -> Result<RenderScene> {
        let (scene, source) = scene::load(path)?;
        let probes = load_probes(path, &source.json)?;
        let mut pages = Vec::new();
        let mut page_of_file: HashMap<PathBuf, u32> = HashMap::new();
        let mut instance_page = Vec::with_capacity(scene.instances.len());
        let mut instance_directional = Vec::with_capacity(scene.instances.len());
        let mut read = |file: &'_ Path| -> Result<u32> {
            Ok(match page_of_file.get(file) {
                Some(&k) => k,
                None => {
                    pages.push(output::read_exr(file)?);
                    let k = pages.len() as u32 - 1;
                    page_of_file.insert(file.to_owned(), k);
                    k
                }
            })
        };
        for inst in &scene.instances {
            let page = match &inst.lightmap {
                Some(file) if inst.has_uv1 => Some(read(file)?),
                _ => None,
            };
            instance_page.push(page);
            let directional = match &inst.directional {
                Some(files) if page.is_some() => {
                    let [a, b, c, d] = files;
                    Some([read(a)?, read(b)?, read(c)?, read(d)?])
                }
                _ => None,
            };
            instance_directional.push(directional);
        }
        if instance_page.iter().all(Option::is_none) {
            return Err(Error::invalid(
                path,
                "no lightmaps: no primitive has TEXCOORD_1 and extras.lightmap; \
                 bake the scene first with `lightbake bake`",
            ));
        }
        let tracer = Tracer::new(&scene);
        let cull_back = scene
            .triangle_instance
            .iter()
            .map(|&i| {
                let material = &scene.materials[scene.instances[i as usize].material as usize];
                !material.double_sided && material.surface.transmission == 0.0
            })
            .collect();
        Ok(RenderScene {
            path: path.to_owned(),
            scene,
            tracer,
            pages,
            instance_page,
            instance_directional,
            cull_back,
            probes,
        })
    }

    /// Shade from the lightmap pages alone, as if the bake had no directional pages (to
    /// compare).
    pub fn ignore_directional(&mut self) {
        self.instance_directional.iter_mut().for_each(|d| *d = None);
    }

    /// The directional pages (L0, L1x, L1y, L1z) of scene instance `instance`, if it has them.
    pub(crate) fn directional(&self, instance: u32) -> Option<[&Page; 4]> {
        self.instance_directional[instance as usize].map(|ks| ks.map(|k| &self.pages[k as usize]))
    }

    /// The lightmap page of scene instance `instance`, if it has one.
    pub(crate) fn page(&self, instance: u32) -> Option<&Page> {
        self.instance_page[instance as usize].map(|k| &self.pages[k as usize])
    }

    /// Instances that have no lightmap (lit by the probes when the bake has them, else black
    /// apart from emission).
    pub fn unlit_instances(&self) -> usize {
        self.instance_page.iter().filter(|p| p.is_none()).count()
    }

    /// The camera named or numbered `selector`; without one the document's first camera, or a
    /// view framing the scene when it has none.
    pub fn camera(&self, selector: Option<&str>, aspect: f32) -> Result<Camera> {
        match selector {
            Some(s) => Ok(select(&self.scene.cameras, s)?.camera),
            None => Ok(self.scene.cameras.first().map_or_else(
                || {
                    let (lo, hi) = self.scene.bounds();
                    Camera::framing(lo, hi, 45f32.to_radians(), aspect)
                },
                |c| c.camera,
            )),
        }
    }

    /// Radiance arriving at `origin` from direction `-dir` (`dir` unit): the value a pixel
    /// sample sees. `rng` drives glossy sampling only.
    pub fn radiance(
        &self,
        origin: Vec3,
        dir: Vec3,
        options: &RenderOptions,
        rng: &mut Rng,
    ) -> Vec3 {
        let mut rays = 0;
        shade::Shader::new(self, options).radiance(origin, dir, 0, rng, &mut rays)
    }

    /// Renders the view of `camera`: rows in parallel, each pixel's samples from its own
    /// random stream, so the image does not depend on the thread count.
    pub fn render(&self, camera: &Camera, options: &RenderOptions) -> Result<Image> {
        let (w, h) = (options.width, options.height);
        if w == 0 || h == 0 || options.spp == 0 {
            return Err(Error::Option(format!(
                "image size {w}×{h} and samples per pixel {} must be positive",
                options.spp
            )));
        }
        let view = View {
            shader: shade::Shader::new(self, options),
            camera,
            width: w,
            height: h,
        };
        let first = adaptive::first_pass_spp(options);
        let mut pixels = view.pass(|x, y| {
            let mut samples = Samples::default();
            let mut rng = Rng::new(options.seed, view.pixel(x, y), PIXEL_STREAM);
            view.sample(x, y, first, &mut rng, &mut samples);
            samples
        });
        if first < options.spp {
            let extra = adaptive::extra_samples(&pixels, w, h, options.spp - first, options.spp);
            let refined = view.pass(|x, y| {
                let pixel = view.pixel(x, y);
                let mut samples = Samples::default();
                if extra[pixel as usize] > 0 {
                    let mut rng = Rng::new(options.seed, pixel, REFINE_STREAM);
                    view.sample(x, y, extra[pixel as usize], &mut rng, &mut samples);
                }
                samples
            });
            for (p, r) in pixels.iter_mut().zip(&refined) {
                p.merge(r);
            }
        }
        Ok(Image {
            width: w,
            height: h,
            rgb: pixels.iter().map(|p| p.sum / p.n as f32).collect(),
            nonfinite: pixels.iter().map(|p| p.nonfinite).sum(),
            rays: pixels.iter().map(|p| p.rays).sum(),
        })
    }
}

/// What a render pass needs to trace a pixel's samples.
struct View<'a> {
    shader: shade::Shader<'a>,
    camera: &'a Camera,
    width: u32,
    height: u32,
}

impl View<'_> {
    fn pixel(&self, x: u32, y: u32) -> u64 {
        y as u64 * self.width as u64 + x as u64
    }

    /// `per_pixel(x, y)` for every pixel, rows in parallel, in row-major order.
    fn pass(&self, per_pixel: impl Fn(u32, u32) -> Samples + Sync) -> Vec<Samples> {
        let rows: Vec<Vec<Samples>> = (0..self.height)
            .into_par_iter()
            .map(|y| (0..self.width).map(|x| per_pixel(x, y)).collect())
            .collect();
        rows.concat()
    }

    /// Adds `n` jittered samples of pixel (x, y) to `out`, stratified over a grid about √n on
    /// a side (leftovers are pure jitter).
    fn sample(&self, x: u32, y: u32, n: u32, rng: &mut Rng, out: &mut Samples) {
        let (w, h) = (self.width as f32, self.height as f32);
        let grid = (n as f32).sqrt().floor().max(1.0) as u32;
        let mut sum = Vec3::ZERO;
        for s in 0..n {
            let jitter = rng.next_vec2();
            let cell = if s < grid * grid {
                (Vec2::new((s % grid) as f32, (s / grid) as f32) + jitter) / grid as f32
            } else {
                jitter
            };
            let ndc = Vec2::new(
                2.0 * (x as f32 + cell.x) / w - 1.0,
                1.0 - 2.0 * (y as f32 + cell.y) / h,
            );
            let dir = self.camera.direction(ndc, w / h);
            let l = self
                .shader
                .radiance(self.camera.eye, dir, 0, rng, &mut out.rays);
            if l.is_finite() {
                sum += l;
                let luminance = adaptive::luminance(l);
                out.lo = out.lo.min(luminance);
                out.hi = out.hi.max(luminance);
            } else {
                out.nonfinite += 1;
            }
        }
        out.sum += sum;
        out.n += n;
    }
}

/// The samples of one pixel so far.
#[derive(Clone, Copy, Debug)]
struct Samples {
    sum: Vec3,
    n: u32,
    /// Range of the samples' luminance.
    lo: f32,
    hi: f32,
    nonfinite: u64,
    rays: u64,
}

impl Default for Samples {
    fn default() -> Self {
        Samples {
            sum: Vec3::ZERO,
            n: 0,
            lo: f32::INFINITY,
            hi: f32::NEG_INFINITY,
            nonfinite: 0,
            rays: 0,
        }
    }
}

impl Samples {
    fn merge(&mut self, other: &Samples) {
        self.sum += other.sum;
        self.n += other.n;
        self.lo = self.lo.min(other.lo);
        self.hi = self.hi.max(other.hi);
        self.nonfinite += other.nonfinite;
        self.rays += other.rays;
    }
}

/// Purpose tag of the per-pixel random streams.
const PIXEL_STREAM: u64 = 0x7265_6e64; // "rend"
/// Purpose tag of the adaptive pass's per-pixel streams.
const REFINE_STREAM: u64 = 0x7265_666e; // "refn"

impl Image {
    /// `self` and `other` (of the same height) side by side, `self` on the left.
    pub fn beside(&self, other: &Image) -> Image {
        let mut rgb = Vec::with_capacity(self.rgb.len() + other.rgb.len());
        for y in 0..self.height as usize {
            for i in [self, other] {
                let w = i.width as usize;
                rgb.extend_from_slice(&i.rgb[y * w..(y + 1) * w]);
            }
        }
        Image {
            width: self.width + other.width,
            height: self.height,
            rgb,
            nonfinite: self.nonfinite + other.nonfinite,
            rays: self.rays + other.rays,
        }
    }

    /// 8-bit sRGB PNG, tone-mapped as [`output::png`] describes (scale by `2^exposure`, then a
    /// soft shoulder that keeps mid-tones true and highlights some detail).
    pub(crate) fn to_png(&self, exposure: f32) -> Result<Vec<u8>> {
        output::write_png_image(&self.rgb, self.width, self.height, exposure)
    }

    /// Writes `path` as a linear 32-bit float OpenEXR (`.exr`) or a tone-mapped PNG (any other
    /// extension must be `.png`).
    pub fn save(&self, path: &Path, exposure: f32) -> Result<()> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("png") => {
                let png = self.to_png(exposure)?;
                std::fs::write(path, png).map_err(|e| Error::io(path, e))
            }
            Some("exr") => output::write_exr_image(path, &self.rgb, self.width, self.height),
            _ => Err(Error::Option(format!(
                "{}: the image must end in .png or .exr",
                path.display()
            ))),
        }
    }
}
