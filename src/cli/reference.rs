//! `lightbake reference`: path-traced reference lightmaps at a bake's texels, or with `--view`
//! a path-traced reference image of the view `lightbake render` draws.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context, Result, bail};
use glam::Vec3;
use lightbake::config::{AutoParams, Keep};
use lightbake::lightmap::{self, LightmapPages};
use lightbake::output::{self, Staging};
use lightbake::reference::points::{Normals, Point, Strip};
use lightbake::reference::{self, ReferenceParams};
use lightbake::render::Image;
use lightbake::{BakeConfig, Progress, texels};

use super::progress::Bars;
use super::render::{ViewArgs, check_image_path};
use super::{AtlasArgs, Quality, RunArgs, parse_rgb};

/// Writes `<stem>_reference<k>.exr` (mean `H/π`, dilated like bake pages) and
/// `<stem>_reference<k>_stderr.exr` (its per-texel standard error) for every page; with
/// `--view`, the image `-o` (mean radiance per pixel) and `<image stem>_stderr.<ext>`.
///
/// The texels are those of `lightbake bake` with the same scene and the same atlas options
/// (--quality, --texels-per-unit, --max-page-size, --padding, --uv, --instancing): unwrapping is
/// deterministic, so the reference and the bake's pages line up texel for texel.
#[derive(clap::Args)]
#[command(after_help = AFTER_HELP)]
pub struct Args {
    /// Input scene (.gltf or .glb): the one the bake was made from.
    scene: PathBuf,
    /// Output directory (created if missing); with --view the image (.exr linear, .png tone-mapped).
    #[arg(short, long)]
    output: PathBuf,
    /// Path-trace a camera view (the one `lightbake render` draws with the same camera options)
    /// instead of the texels.
    #[arg(long)]
    view: bool,
    /// Path-trace N random points on visible surfaces instead of the texels; -o is a CSV file
    /// for `lightbake compare`.
    #[arg(long, value_name = "N", conflicts_with = "view")]
    points: Option<usize>,
    /// With --points, draw all N points in a strip beside a plane: "x,y,z,nx,ny,nz,width" — a
    /// point of the plane, its normal towards the side measured, the strip's width (the
    /// junction strip along a wall, a texel wide; as `compare --strip` selects).
    #[arg(long, value_name = "X,Y,Z,NX,NY,NZ,W", requires = "points")]
    strip: Option<Strip>,
    /// Path-trace the light at points off the surfaces (lines x,y,z,nx,ny,nz, as `lightbake
    /// probes --at` reads them) instead of the texels: per point the irradiance over π about
    /// its normal, and the L2 projection of it a light probe can hold; -o is a CSV file. Not
    /// with --indirect-only (probes keep the light reaching them directly from emitters).
    #[arg(long, value_name = "FILE.csv", conflicts_with_all = ["view", "points", "indirect_only"])]
    probes_at: Option<PathBuf>,
    /// With --probes-at, leave out punctual lights' direct light (match a bake made with
    /// --probes-indirect-only).
    #[arg(long, requires = "probes_at")]
    probes_indirect_only: bool,
    #[command(flatten)]
    camera: ViewArgs,
    /// Exposure of a --view PNG in stops (ignored for EXR).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    exposure: f32,
    /// Preset whose texel density the reference uses (match the bake's): adjusted for the
    /// scene's surface area exactly as `lightbake bake` adjusts it (without --no-auto).
    #[arg(long, value_enum, default_value = "medium")]
    quality: Quality,
    #[command(flatten)]
    atlas: AtlasArgs,
    /// Paths per texel (per pixel with --view, per point with --points) at most; standard error shrinks like 1/√N.
    #[arg(long, default_value_t = 1024)]
    spp: u32,
    /// Paths per texel between stopping checks.
    #[arg(long, default_value_t = 16)]
    pass: u32,
    /// Stop when the relative RMS standard error √(Σσ²/Σμ²) over texels (pixels) is at most this.
    #[arg(long)]
    target_error: Option<f32>,
    /// Stop after the pass that crosses this many seconds.
    #[arg(long)]
    time: Option<f64>,
    /// Bounces per path at most (Russian roulette ends most paths long before).
    #[arg(long, default_value_t = 1024)]
    max_depth: u32,
    /// Uniform sky radiance R,G,B (W/sr/m²) for rays leaving the scene (match the bake's).
    #[arg(long, value_parser = parse_rgb, default_value = "0,0,0")]
    sky: Vec3,
    /// Keep texel sample points where they are even inside geometry (match a bake's --no-validity).
    #[arg(long)]
    no_validity: bool,
    /// Leave out light that arrives without a bounce (match a bake made with --indirect-only).
    #[arg(long)]
    indirect_only: bool,
    /// Write 32-bit float EXR pages instead of half floats.
    #[arg(long)]
    float: bool,
    /// Seed of the random paths (output depends on it, never on --threads).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    #[command(flatten)]
    run: RunArgs,
}

const AFTER_HELP: &str = "\
Writes <stem>_reference<k>.exr (H/π per texel, dilated like bake pages) and
<stem>_reference<k>_stderr.exr (its standard error) per page. The texels are a bake's when the
scene and the atlas options (--quality, --texels-per-unit, --max-page-size, --padding, --uv, --instancing,
--no-validity) are the same (the density is adjusted to the scene's size as bake adjusts it); give --sky and --indirect-only as the bake did. Tracing stops at
--spp paths per texel, at --target-error (relative RMS standard error √(Σσ²/Σμ²)), or after
--time seconds, whichever comes first.

With --view, -o is an image: the camera view that `lightbake render` draws with the same
--camera/--eye/--target/--fov/--size, path-traced: at the first hit of each jittered primary ray,
baseColor × (path-traced H/π) + emission, --spp paths per pixel. Writes the image (.exr linear
radiance, .png tone-mapped like render) and <image stem>_stderr.<ext>, its per-pixel standard
error. Compare it with `lightbake render` without --specular: the difference is the lightmap's
error. Rays that leave the scene see --sky (give render the same --background).
  lightbake reference scene.gltf --view --camera NAME --size 256x256 --spp 1024 -o ref.exr

With --points N, -o is a CSV file: N points drawn area-weighted on the input scene's surfaces
(points whose face looks into geometry are left out and counted), each with the path-traced
H/π there (about the shading normal) and its standard error: `#` comment lines, the header
x,y,z,nx,ny,nz,r,g,b,se_r,se_g,se_b,snx,sny,snz, one row per point (world position, unit face
normal, H/π, standard error, unit shading normal). Compare bakes with it:
  lightbake reference scene.gltf --points 4096 --spp 4096 --target-error 0.01 -o points.csv
  lightbake compare baked/scene.gltf --points points.csv
With --strip, every point lies in the strip (the dark side of a wall, one texel wide):
  lightbake reference two_rooms.gltf --points 2048 --strip 0,0,0,1,0,0,0.03 -o strip.csv
  lightbake compare baked/two_rooms.gltf --points strip.csv

With --probes-at FILE.csv (lines x,y,z,nx,ny,nz, world space), -o is a CSV file: per point,
in the input's order, the path-traced irradiance over π about its normal (r,g,b, what a surface
there receives) and the irradiance of its L2 projection (l2_r,l2_g,l2_b, what a light probe there
can hold at best), each with its standard error, --spp paths each. Check a bake's probes with it:
  lightbake probes out/scene.gltf --at points.csv > probes.csv
  lightbake reference scene.gltf --probes-at points.csv --spp 4096 -o reference.csv";

impl Args {
    fn config(&self) -> BakeConfig {
        let mut c = self.atlas.config(self.quality);
        c.transport.sky = self.sky;
        c.transport.indirect_only = self.indirect_only;
        c.transport.validity = !self.no_validity;
        c.transport.seed = self.seed;
        c.output.float = self.float;
        // The density a bake's automatic choice gives (nothing else of it applies here).
        c.auto = Some(AutoParams {
            target_error: self.quality.target_error(),
            keep: Keep {
                texels_per_unit: self.atlas.texels_per_unit.is_some(),
                ..Keep::default()
            },
        });
        c
    }

    fn params(&self, config: &BakeConfig) -> Result<ReferenceParams> {
        let time_limit = match self.time {
            Some(s) if s.is_finite() && s > 0.0 => Some(Duration::from_secs_f64(s)),
            Some(s) => bail!("--time must be a positive number of seconds, got {s}"),
            None => None,
        };
        Ok(ReferenceParams {
            samples_per_pass: self.pass,
            max_samples: self.spp,
            target_rel_error: self.target_error,
            time_limit,
            max_depth: self.max_depth,
            ..ReferenceParams::like(config)
        })
    }
}

pub fn run(args: &Args) -> Result<()> {
    args.run.start()?;
    let config = args.config();
    let params = args.params(&config)?;
    if args.view {
        return view(args, &config, &params);
    }
    if let Some(n) = args.points {
        return points(args, n, &config, &params);
    }
    if let Some(at) = &args.probes_at {
        return probes_at(args, at, &config, &params);
    }
    if args.camera.any() {
        bail!("--camera, --eye, --target, --fov and --size need --view");
    }
    let bars = Bars::new(args.run.quiet);
    let computed = reference::compute(&args.scene, &config, &params, &bars)
        .with_context(|| format!("tracing a reference for {} failed", args.scene.display()))?;
    let (texels, r) = (&computed.texels, &computed.reference);

    let stem = args
        .scene
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("scene");
    let radius = config.atlas.padding.max(2) * 2;
    let dilated = |values: &[Vec3]| {
        // Buried texels take their neighbours' values, as in a bake's pages.
        let mut values = values.to_vec();
        texels::validity::fill_invalid(texels, &mut values);
        let mut pages = LightmapPages::from_texels(texels, &values);
        lightmap::dilate(&mut pages, radius);
        pages
    };
    let (mean, std_error) = (dilated(&r.mean), dilated(&r.std_error));
    let mut staging = Staging::new(&args.output, std::slice::from_ref(&args.scene))?;
    for (k, (m, se)) in mean.pages.iter().zip(&std_error.pages).enumerate() {
        let exr = |page| output::write_exr(page, config.output.float, &args.scene);
        staging.write(&format!("{stem}_reference{k}.exr"), &exr(m)?)?;
        staging.write(&format!("{stem}_reference{k}_stderr.exr"), &exr(se)?)?;
    }
    if bars.aborted() {
        bail!("aborted");
    }
    let files = staging.commit()?;
    if !args.run.quiet {
        println!("{}", r.summary());
        println!("wrote {} file(s) to {}", files.len(), args.output.display());
    }
    Ok(())
}

/// `--view`: a path-traced image and its standard error.
fn view(args: &Args, config: &BakeConfig, params: &ReferenceParams) -> Result<()> {
    check_image_path(&args.output)?;
    let bars = Bars::new(args.run.quiet);
    let p = reference::prepare(&args.scene, config, &bars)
        .with_context(|| format!("loading {} failed", args.scene.display()))?;
    let (camera, width, height) = args.camera.resolve(&p.scene)?;
    let v = reference::trace_view(
        &p.scene, &p.texels, &p.tracer, &camera, width, height, params, &bars,
    )
    .with_context(|| {
        format!(
            "tracing a reference view of {} failed",
            args.scene.display()
        )
    })?;
    if bars.aborted() {
        bail!("aborted");
    }
    let stderr_path = {
        let stem = args
            .output
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or("view");
        let ext = args
            .output
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or("exr");
        args.output.with_file_name(format!("{stem}_stderr.{ext}"))
    };
    for (path, rgb) in [
        (&args.output, &v.pixels.mean),
        (&stderr_path, &v.pixels.std_error),
    ] {
        let image = Image {
            width,
            height,
            rgb: rgb.clone(),
            nonfinite: 0,
            rays: v.pixels.rays,
        };
        image
            .save(path, args.exposure)
            .with_context(|| format!("writing {} failed", path.display()))?;
    }
    if !args.run.quiet {
        println!("{}", v.summary());
        println!(
            "wrote {} and {}",
            args.output.display(),
            stderr_path.display()
        );
    }
    Ok(())
}

/// `--points`: a point reference file.
fn points(args: &Args, n: usize, config: &BakeConfig, params: &ReferenceParams) -> Result<()> {
    if n == 0 {
        bail!("--points must be at least 1");
    }
    let bars = Bars::new(args.run.quiet);
    let (points, traced) =
        reference::points::compute_in(&args.scene, config, params, n, args.strip.as_ref(), &bars)
            .with_context(|| format!("tracing points of {} failed", args.scene.display()))?;
    if bars.aborted() {
        bail!("aborted");
    }
    std::fs::write(&args.output, points.to_csv())
        .with_context(|| format!("writing {} failed", args.output.display()))?;
    if !args.run.quiet {
        println!(
            "{} points ({} hidden points left out), {} paths per point, {:.2} M rays, \
             relative RMS standard error {:.2}% ({}), {:.2}s",
            points.points.len(),
            points.hidden,
            traced.samples,
            traced.rays as f64 * 1e-6,
            traced.rms_rel_error * 100.0,
            traced.stop.reason(),
            traced.seconds
        );
        println!("wrote {}", args.output.display());
    }
    Ok(())
}

/// `--probes-at`: the light at free points, as the probes' yardstick (CSV).
fn probes_at(
    args: &Args,
    at: &std::path::Path,
    config: &BakeConfig,
    params: &ReferenceParams,
) -> Result<()> {
    let text =
        std::fs::read_to_string(at).with_context(|| format!("reading {} failed", at.display()))?;
    let at_points =
        super::probes::parse_points(&text).with_context(|| format!("in {}", at.display()))?;
    let params = ReferenceParams {
        no_punctual_direct: args.probes_indirect_only,
        ..params.clone()
    };
    let bars = Bars::new(args.run.quiet);
    let p = reference::prepare(&args.scene, config, &bars)
        .with_context(|| format!("loading {} failed", args.scene.display()))?;
    let surfaces = (&p.scene, &p.texels, &p.tracer);
    let points: Vec<Point> = (at_points.iter())
        .map(|&(position, normal)| Point::free(position, normal))
        .collect();
    let failed = || format!("tracing points of {} failed", args.scene.display());
    let truth = reference::points::trace_about(surfaces, &points, Normals::Shading, &params, &bars)
        .with_context(failed)?;
    let l2 = reference::trace_sh(surfaces, &at_points, &params, &bars).with_context(failed)?;
    if bars.aborted() {
        bail!("aborted");
    }
    let mut csv = format!(
        "# lightbake reference --probes-at {}: {} paths per point\n\
         x,y,z,nx,ny,nz,r,g,b,se_r,se_g,se_b,l2_r,l2_g,l2_b,l2_se_r,l2_se_g,l2_se_b\n",
        at.display(),
        truth.samples
    );
    for (k, (x, n)) in at_points.iter().enumerate() {
        let row = [
            *x,
            *n,
            truth.mean[k],
            truth.std_error[k],
            l2.mean[k],
            l2.std_error[k],
        ];
        let fields: Vec<String> = (row.iter().flat_map(|v| v.to_array()))
            .map(|c| c.to_string())
            .collect();
        csv.push_str(&fields.join(","));
        csv.push('\n');
    }
    // Written under a temporary name and renamed, never over the input.
    let dir = (args.output.parent())
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(std::path::Path::new("."));
    let mut staging = Staging::new(dir, std::slice::from_ref(&args.scene))?;
    let name = (args.output.file_name())
        .and_then(|f| f.to_str())
        .context("-o must name a file")?;
    staging.write(name, csv.as_bytes())?;
    staging.commit()?;
    if !args.run.quiet {
        println!(
            "{} points, {} paths per point, relative RMS standard error {:.2}% (irradiance) and {:.2}% (L2), {:.2} M rays, {:.2}s",
            at_points.len(),
            truth.samples,
            truth.rms_rel_error * 100.0,
            l2.rms_rel_error * 100.0,
            (truth.rays + l2.rays) as f64 * 1e-6,
            truth.seconds + l2.seconds
        );
        println!("wrote {}", args.output.display());
    }
    Ok(())
}
