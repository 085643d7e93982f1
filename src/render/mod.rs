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
//! With `specular` on, surfaces with `roughness ≤ GLOSSY_MAX_ROUGHNESS` become nodes of a
//! Whitted ray tree (the `shade` module documents the model: Schlick Fresnel, GGX glossy lobe,
//! refraction with absorption, energy-conserving composite). Leaves of the tree (depth limit,
//! rough surfaces) take `L_d` from the lightmap, so indirect diffuse light is never re-traced.
//!
//! | Parameter (`RenderOptions`) | Default | Meaning |
//! |---|---|---|
//! | `width`, `height` | 512 × 512 | image size in pixels |
//! | `spp` | 16 | jittered samples per pixel (stratified in a √spp grid) |
//! | `specular` | false | build the ray tree at specular surfaces |
//! | `max_depth` | 6 | tree depth; hits at this depth are leaves (`L_d`) |
//! | `glossy_samples` | 8 | GGX rays at a glossy primary hit (1 deeper in the tree) |
//! | `background` | 0 | radiance of rays that leave the scene |
//! | `seed` | 0 | random streams are seeded by (seed, pixel) |
//!
//! Input: a glTF written by `lightbake bake`: every baked primitive has `TEXCOORD_1` and
//! `extras.lightmap = {"exr", "page"}`; the EXR pages hold `H/π`. The scene loader resolves
//! everything the renderer reads — each instance's EXR page, each material's specular
//! parameters ([`scene::Surface`]), the cameras — so this module never looks at glTF JSON. Scenes without any lightmap are
//! refused. As glTF asks, back faces of single-sided materials are culled (rays pass through
//! them); the bake writes a double-sided surface as two single-sided primitives back to back. Limits: no alpha, no texture transforms, punctual lights are invisible (their light
//! is in the lightmap), and the baker treated glass and mirrors as Lambertian (ρ = baseColor),
//! so shadows behind glass are as dark as behind any opaque object of that colour.

mod shade;

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};
use rayon::prelude::*;

/// The loader resolves the document's cameras into [`Scene::cameras`]; the renderer's callers
/// choose among them with these.
pub use crate::scene::{Camera, GltfCamera, select};
pub use shade::{GLOSSY_MAX_ROUGHNESS, MIRROR_ROUGHNESS};

use crate::lightmap::Page;
use crate::sampling::Rng;
use crate::scene::{self, Scene};
use crate::trace::Tracer;
use crate::{Error, Result, output};

/// What to render and how.
#[derive(Clone, Debug)]
pub struct RenderOptions {
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    pub specular: bool,
    pub max_depth: u32,
    pub glossy_samples: u32,
    pub background: Vec3,
    pub seed: u64,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            width: 512,
            height: 512,
            spp: 16,
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
    pub path: PathBuf,
    pub scene: Scene,
    pub tracer: Tracer,
    /// Decoded EXR pages (one per distinct `extras.lightmap` file).
    pub pages: Vec<Page>,
    /// Page of each scene instance (`None`: the primitive has no lightmap and shades black
    /// apart from its emission).
    pub instance_page: Vec<Option<u32>>,
    /// Per scene triangle: its back face is culled (glTF's `"doubleSided": false`; a baked
    /// double-sided wall is two such primitives, back to back, which would z-fight otherwise).
    /// Transmissive surfaces are kept: a single-sided one bounds a volume, and its back face
    /// is where rays leave the glass.
    pub cull_back: Vec<bool>,
}

/// A rendered image: linear RGB radiance, row 0 at the top.
#[derive(Clone, Debug)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<Vec3>,
    /// Samples that came out NaN or infinite and were replaced by black (should be 0).
    pub nonfinite: u64,
    /// Rays traced (primary and secondary).
    pub rays: u64,
}

impl RenderScene {
    /// Loads a baked glTF/GLB and the EXR pages its primitives reference.
    pub fn load(path: &Path) -> Result<RenderScene> {
        let (scene, _) = scene::load(path)?;
        let mut pages = Vec::new();
        let mut page_of_file: HashMap<&Path, u32> = HashMap::new();
        let mut instance_page = Vec::with_capacity(scene.instances.len());
        for inst in &scene.instances {
            let page = match &inst.lightmap {
                Some(file) if inst.has_uv1 => Some(match page_of_file.get(file.as_path()) {
                    Some(&k) => k,
                    None => {
                        pages.push(output::read_exr(file)?);
                        let k = pages.len() as u32 - 1;
                        page_of_file.insert(file, k);
                        k
                    }
                }),
                _ => None,
            };
            instance_page.push(page);
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
            cull_back,
        })
    }

    /// Instances that have no lightmap (they render black apart from emission).
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
        let shader = shade::Shader::new(self, options);
        let aspect = w as f32 / h as f32;
        // Stratify the spp samples over a grid about √spp on a side; leftovers are pure jitter.
        let grid = (options.spp as f32).sqrt().floor().max(1.0) as u32;
        let rows: Vec<(Vec<Vec3>, u64, u64)> = (0..h)
            .into_par_iter()
            .map(|y| {
                let mut row = Vec::with_capacity(w as usize);
                let (mut nonfinite, mut rays) = (0u64, 0u64);
                for x in 0..w {
                    let pixel = y as u64 * w as u64 + x as u64;
                    let mut rng = Rng::new(options.seed, pixel, PIXEL_STREAM);
                    let mut sum = Vec3::ZERO;
                    for s in 0..options.spp {
                        let jitter = rng.next_vec2();
                        let cell = if s < grid * grid {
                            (Vec2::new((s % grid) as f32, (s / grid) as f32) + jitter) / grid as f32
                        } else {
                            jitter
                        };
                        let ndc = Vec2::new(
                            2.0 * (x as f32 + cell.x) / w as f32 - 1.0,
                            1.0 - 2.0 * (y as f32 + cell.y) / h as f32,
                        );
                        let dir = camera.direction(ndc, aspect);
                        let l = shader.radiance(camera.eye, dir, 0, &mut rng, &mut rays);
                        if l.is_finite() {
                            sum += l;
                        } else {
                            nonfinite += 1;
                        }
                    }
                    row.push(sum / options.spp as f32);
                }
                (row, nonfinite, rays)
            })
            .collect();
        let mut image = Image {
            width: w,
            height: h,
            rgb: Vec::with_capacity((w * h) as usize),
            nonfinite: 0,
            rays: 0,
        };
        for (row, nonfinite, rays) in rows {
            image.rgb.extend(row);
            image.nonfinite += nonfinite;
            image.rays += rays;
        }
        Ok(image)
    }
}

/// Purpose tag of the per-pixel random streams.
const PIXEL_STREAM: u64 = 0x7265_6e64; // "rend"

impl Image {
    /// 8-bit sRGB PNG, tone-mapped as [`output::png`] describes (scale by `2^exposure`, then a
    /// soft shoulder that keeps mid-tones true and highlights some detail).
    pub fn to_png(&self, exposure: f32) -> Result<Vec<u8>> {
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
