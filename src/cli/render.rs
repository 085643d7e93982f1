//! `lightbake render`: a camera view of a baked scene (lightmap × base colour + emission, and
//! with `--specular` a ray-traced reflection/refraction layer), written as PNG or EXR.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use glam::Vec3;
use lightbake::render::{Camera, RenderOptions, RenderScene, select};
use lightbake::scene::Scene;

use crate::parse_rgb;

#[derive(clap::Args)]
pub struct Args {
    /// A baked scene (.gltf or .glb written by `lightbake bake`).
    scene: PathBuf,
    /// Output image: .png (tone-mapped sRGB) or .exr (linear radiance).
    #[arg(short, long)]
    output: PathBuf,
    #[command(flatten)]
    view: ViewArgs,
    /// Jittered samples per pixel (anti-aliasing; glossy reflections): the mean over the image,
    /// spent where the image needs them (edges, emitters) unless --uniform.
    #[arg(long, default_value_t = 16)]
    spp: u32,
    /// Every pixel gets exactly --spp samples (no adaptive sampling).
    #[arg(long)]
    uniform: bool,
    /// Add the ray-traced specular layer (mirrors, glossy metals, glass).
    #[arg(long)]
    specular: bool,
    /// Shade from the lightmap alone even where the bake has directional pages (normal maps
    /// then change nothing in the diffuse light).
    #[arg(long)]
    no_directional: bool,
    /// Depth of the specular ray tree.
    #[arg(long, default_value_t = 6)]
    max_depth: u32,
    /// Exposure of the PNG in stops (ignored for EXR).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    exposure: f32,
    /// Radiance R,G,B of rays that leave the scene.
    #[arg(long, value_parser = parse_rgb, default_value = "0,0,0")]
    background: Vec3,
    /// Seed of the sample streams.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// No summary line.
    #[arg(short, long)]
    quiet: bool,
}

/// Camera and image size, shared by `render` and `reference --view`.
#[derive(clap::Args)]
pub struct ViewArgs {
    /// glTF camera by name or index [default: the first camera, else a view of the whole scene].
    #[arg(long, conflicts_with_all = ["eye", "target"])]
    pub camera: Option<String>,
    /// Eye position X,Y,Z (with --target) instead of a glTF camera.
    #[arg(long, value_parser = parse_vec3, requires = "target")]
    pub eye: Option<Vec3>,
    /// Point the eye looks at, X,Y,Z.
    #[arg(long, value_parser = parse_vec3, requires = "eye")]
    pub target: Option<Vec3>,
    /// Vertical field of view in degrees (with --eye, or to override the camera's).
    #[arg(long)]
    pub fov: Option<f32>,
    /// Image size WxH [default: 512 wide, height from the camera's aspect ratio].
    #[arg(long, value_parser = parse_size)]
    pub size: Option<(u32, u32)>,
}

impl ViewArgs {
    /// Any camera or size option given.
    pub fn any(&self) -> bool {
        self.camera.is_some()
            || self.eye.is_some()
            || self.target.is_some()
            || self.fov.is_some()
            || self.size.is_some()
    }

    /// The camera and image size these options choose among the scene's cameras; a view
    /// framing the whole scene when it has no camera and there is no eye.
    pub fn resolve(&self, scene: &Scene) -> Result<(Camera, u32, u32)> {
        let (cameras, bounds) = (&scene.cameras, scene.bounds());
        let fov = self.fov.map(f32::to_radians);
        let framing = |aspect: f32| Camera::framing(bounds.0, bounds.1, 45f32.to_radians(), aspect);
        let mut camera = match (self.eye, self.target, &self.camera) {
            (Some(eye), Some(target), _) => Camera::look_at(eye, target, fov.unwrap_or(0.8)),
            (_, _, Some(name)) => select(cameras, name)?.camera,
            _ => cameras.first().map_or_else(|| framing(1.0), |c| c.camera),
        };
        if let Some(fov) = fov {
            camera.yfov = fov;
        }
        let (width, height) = self.size.unwrap_or_else(|| {
            let aspect = camera.aspect_ratio.unwrap_or(1.0).clamp(0.1, 10.0);
            (512, ((512.0 / aspect).round() as u32).max(1))
        });
        // A framing camera depends on the aspect ratio: rebuild it for the final size.
        if self.camera.is_none() && self.eye.is_none() && cameras.is_empty() {
            camera = framing(width as f32 / height as f32);
            if let Some(fov) = fov {
                camera.yfov = fov;
            }
        }
        Ok((camera, width, height))
    }
}

/// Refuses output paths other than .png and .exr.
pub fn check_image_path(path: &Path) -> Result<()> {
    let ext = path.extension().and_then(|e| e.to_str());
    if !matches!(
        ext.map(str::to_ascii_lowercase).as_deref(),
        Some("png" | "exr")
    ) {
        bail!("{}: the output must end in .png or .exr", path.display());
    }
    Ok(())
}

fn parse_vec3(s: &str) -> Result<Vec3, String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|p| p.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("{s:?}: {e}"))?;
    match v[..] {
        [x, y, z] => Ok(Vec3::new(x, y, z)),
        _ => Err(format!("expected X,Y,Z, got {s:?}")),
    }
}

fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("expected WxH, got {s:?}"))?;
    let parse = |v: &str| v.trim().parse::<u32>().map_err(|e| format!("{s:?}: {e}"));
    let (w, h) = (parse(w)?, parse(h)?);
    if w == 0 || h == 0 || w > 16384 || h > 16384 {
        return Err(format!("image size {w}x{h} out of range (1..=16384)"));
    }
    Ok((w, h))
}

pub fn run(args: &Args) -> Result<()> {
    check_image_path(&args.output)?;
    let start = Instant::now();
    let mut scene = RenderScene::load(&args.scene)
        .with_context(|| format!("loading {} failed", args.scene.display()))?;
    if args.no_directional {
        scene.ignore_directional();
    }
    let load_seconds = start.elapsed().as_secs_f64();
    if scene.unlit_instances() > 0 {
        eprintln!(
            "warning: {} primitive instance(s) have no lightmap and render black",
            scene.unlit_instances()
        );
    }

    let (camera, width, height) = args.view.resolve(&scene.scene)?;
    let options = RenderOptions {
        width,
        height,
        spp: args.spp,
        specular: args.specular,
        max_depth: args.max_depth,
        background: args.background,
        seed: args.seed,
        adaptive: !args.uniform,
        ..RenderOptions::default()
    };
    let t = Instant::now();
    let image = scene.render(&camera, &options)?;
    let render_seconds = t.elapsed().as_secs_f64();
    image
        .save(&args.output, args.exposure)
        .with_context(|| format!("writing {} failed", args.output.display()))?;
    if image.nonfinite > 0 {
        eprintln!(
            "warning: {} sample(s) were NaN or infinite and were set to black",
            image.nonfinite
        );
    }
    if !args.quiet {
        println!(
            "{width}x{height}, {} spp{}, {} triangles: load {load_seconds:.2}s, render {render_seconds:.2}s ({:.2} M rays, {:.2} M rays/s)",
            args.spp,
            if args.specular { ", specular" } else { "" },
            scene.tracer.len(),
            image.rays as f64 * 1e-6,
            image.rays as f64 * 1e-6 / render_seconds.max(1e-9),
        );
        println!("wrote {}", args.output.display());
    }
    Ok(())
}
