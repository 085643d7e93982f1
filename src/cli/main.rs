//! The `lightbake` command line: flags → [`BakeConfig`], progress bars, one-line summary.

mod build;
mod compare;
mod distributed;
mod interrupt;
mod probes;
mod progress;
mod reference;
mod relight;
mod render;
mod view;

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result};
use clap::{Parser, Subcommand, ValueEnum};
use glam::Vec3;
use lightbake::BakeConfig;
use lightbake::build::options::{Options, Probes, Rgb};
use lightbake::build::{Gate, SceneResult};
use lightbake::config::{AutoParams, Instancing, UvMode};
use progress::Bars;

#[derive(Parser)]
#[command(
    name = "lightbake",
    version,
    about = "Bake radiosity lightmaps for glTF scenes"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Bake lightmaps: writes <stem>.gltf + .bin (or .glb), and per page an EXR and a PNG preview.
    Bake(BakeArgs),
    /// Solve a bake kept with --keep-transport again with other light and material values, no
    /// ray cast: writes pages and the glTF as a bake does.
    Relight(relight::Args),
    /// Render a camera view of a baked scene (lightmap × albedo, optional specular layer).
    Render(render::Args),
    /// Path-trace reference lightmaps at the same texels as a bake (the accuracy yardstick), or
    /// with --view a reference image of a camera view, or with --points N a point reference
    /// (H/π at random points on visible surfaces, for `compare`).
    Reference(reference::Args),
    /// Compare a baked scene, read as a renderer reads it, with a point reference.
    Compare(compare::Args),
    /// Print the light a bake's probes give at points (irradiance over π, one r,g,b line each).
    Probes(probes::Args),
    /// Bake every scene a manifest (lightbake.toml) lists, skipping those whose outputs are up
    /// to date.
    Build(build::Args),
    /// Serve a viewer page of a baked scene on 127.0.0.1 (three.js, offline): lit, lightmap,
    /// albedo, texel density, chart borders and, with --points, the per-point error.
    View(view::Args),
}

#[derive(Clone, Copy, ValueEnum)]
enum Quality {
    /// 8 texels/m, aims at 8% error (--no-auto: 64 rays, 16 light samples, tolerance 1e-3).
    Draft,
    /// 16 texels/m, aims at 4% error (--no-auto: 256 rays, 64 light samples, tolerance 1e-4).
    Medium,
    /// 32 texels/m, aims at 2% error (--no-auto: 1024 rays, 256 light samples, tolerance 1e-5).
    High,
}

#[derive(Clone, Copy, ValueEnum)]
enum UvArg {
    /// Reuse the input's TEXCOORD_1 when every primitive has a valid one, else unwrap.
    Auto,
    /// Always unwrap new lightmap charts with xatlas.
    Unwrap,
    /// Reuse the input's TEXCOORD_1; fail if it is missing, overlapping or outside [0,1].
    Existing,
}

#[derive(Clone, Copy, ValueEnum)]
enum InstancingArg {
    /// Each node placing a mesh gets its own copy of the mesh with its own lightmap UVs.
    Duplicate,
    /// The mesh is unwrapped and written once; each node gets a rect of a page in its
    /// extras.lightmap.scale_offset (uv_page = uv * scale + offset).
    Share,
}

/// The names are [`Technique::METHODS`].
#[derive(Clone, Copy, ValueEnum)]
enum MethodArg {
    /// Monte Carlo hemisphere gathering with explicit light sampling: the general default.
    Montecarlo,
    /// Point-to-point differential form factors, all pairs: a baseline for small scenes.
    Point,
    /// Point-to-polygon (Lambert contour) form factors, all pairs: accurate at short range.
    Polygon,
    /// Hierarchical radiosity with clustering: large scenes, error-driven links.
    Hierarchical,
}

/// The names are [`Technique::SOLVERS`].
#[derive(Clone, Copy, ValueEnum)]
enum SolverArg {
    /// Parallel sweeps from the previous iterate.
    Jacobi,
    /// Serial in-place sweeps; fewer iterations.
    GaussSeidel,
    /// Progressive refinement: shoot the texel with the most unshot power first.
    Southwell,
    /// Matrix-free: re-cast gathering rays every bounce, store no rows.
    Gather,
}

/// The names are [`lightbake::config::RowStorage::NAMES`].
#[derive(Clone, Copy, ValueEnum)]
enum RowsArg {
    /// The planner's choice: f32 weights unless only ray counts fit the memory limit.
    Auto,
    /// f32 weights (the fastest sweeps).
    F32,
    /// Exact ray counts (the least memory; the same output).
    Counts,
}

/// The atlas options, shared by `bake` and `reference` so their texels line up.
#[derive(clap::Args)]
struct AtlasArgs {
    /// Lightmap texels per world unit (metre) [default: from --quality: 8 / 16 / 32, adjusted
    /// to keep the texel count within the preset's budget for the scene's surface area].
    #[arg(long)]
    texels_per_unit: Option<f32>,
    /// Largest page side in texels; more pages are made when charts do not fit.
    #[arg(long, default_value_t = 1024)]
    max_page_size: u32,
    /// Empty texels between charts, filled by dilation.
    #[arg(long, default_value_t = 2)]
    padding: u32,
    /// Where lightmap UVs come from.
    #[arg(long, value_enum, default_value = "auto")]
    uv: UvArg,
    /// Keep receivers whole where other surfaces meet them (texels under a wall then straddle
    /// it; the divided-texel cell map keeps their values right, a renderer's filtering does not).
    #[arg(long)]
    no_split_junctions: bool,
    /// Do not cut receivers along the hard shadow outlines of sun, point and spot lights (a
    /// renderer's filtering then blurs each such shadow edge over a texel on each side).
    #[arg(long)]
    no_shadow_cuts: bool,
    /// Cut receivers along the outlines of surfaces facing them from less than a texel away
    /// too (a door's edge in its lining, a light's side in its recess), so a slot's texels hold
    /// the slot's light; more charts and triangles.
    #[arg(long)]
    near_contacts: bool,
    /// With --near-contacts, keep slot faces at the plan's density instead of raising them
    /// until a texel is no wider than the slot's gap.
    #[arg(long)]
    no_slot_faces: bool,
    /// Keep faces narrower than four texels near an emitter at the plan's density instead of
    /// raising them to four texels across.
    #[arg(long)]
    no_narrow_faces: bool,
    /// A mesh placed by several nodes: duplicated per node, or written once with a page rect
    /// per node (its instances are then not junction-split).
    #[arg(long, value_enum, default_value = "duplicate")]
    instancing: InstancingArg,
}

impl AtlasArgs {
    /// The preset of `quality` with these atlas options.
    fn config(&self, quality: Quality) -> BakeConfig {
        let mut c = quality.preset();
        if let Some(t) = self.texels_per_unit {
            c.atlas.texels_per_unit = t;
        }
        c.atlas.max_page_size = self.max_page_size;
        c.atlas.padding = self.padding;
        c.atlas.uv = self.uv.mode();
        c.atlas.split_junctions = !self.no_split_junctions;
        c.atlas.shadow_cuts = !self.no_shadow_cuts;
        c.atlas.near_contacts = self.near_contacts;
        c.atlas.slot_faces = !self.no_slot_faces;
        c.atlas.narrow_faces = !self.no_narrow_faces;
        c.atlas.instancing = self.instancing.mode();
        c
    }
}

#[derive(clap::Args)]
struct BakeArgs {
    /// Input scene (.gltf or .glb).
    scene: PathBuf,
    /// Output directory (created if missing; must not hold the input's own files).
    #[arg(short, long)]
    output: PathBuf,
    /// Quality preset: the texel density, and the error the automatic choice aims at
    /// (draft 8%, medium 4%, high 2%). Options given below override it.
    #[arg(long, value_enum, default_value = "medium")]
    quality: Quality,
    /// Aim at this relative RMSE of the lightmap (0.02 = 2%) instead of the preset's: a pilot
    /// bake measures the scene's noise and the rays per texel are chosen to reach it.
    #[arg(long, value_name = "E")]
    target_error: Option<f32>,
    /// Print the automatic choices and the measurements behind them.
    #[arg(long)]
    explain: bool,
    /// Use the preset's settings as they are: no pilot, no automatic choice.
    #[arg(long, conflicts_with_all = ["target_error", "explain"])]
    no_auto: bool,
    #[command(flatten)]
    atlas: AtlasArgs,
    /// Gathering rays per texel (form factors) [default: chosen by a pilot bake for the target
    /// error; with --no-auto from --quality: 64 / 256 / 1024].
    #[arg(long)]
    rays: Option<u32>,
    /// Shadow rays per texel towards emissive surfaces [default: a quarter of the rays; with
    /// --no-auto from --quality: 16 / 64 / 256].
    #[arg(long)]
    light_samples: Option<u32>,
    /// Uniform sky radiance R,G,B (W/sr/m²) for rays leaving the scene.
    #[arg(long, value_parser = parse_rgb, default_value = "0,0,0")]
    sky: Vec3,
    /// How form factors between texels are computed [default: chosen; montecarlo]. The
    /// hierarchical method takes no other solver than jacobi, the gather solver no other
    /// method than montecarlo.
    #[arg(long, value_enum)]
    method: Option<MethodArg>,
    /// Solver for the radiosity system [default: chosen; jacobi, or gather when the stored
    /// rows would exceed 4 GiB].
    #[arg(long, value_enum)]
    solver: Option<SolverArg>,
    /// Relative error at which the solver stops [default: a tenth of the target error; with
    /// --no-auto from --quality: 1e-3 / 1e-4 / 1e-5].
    #[arg(long)]
    tolerance: Option<f32>,
    /// Iteration cap of the solver (a warning says when it stops here).
    #[arg(long, default_value_t = 10_000)]
    max_iterations: u32,
    /// Store indirect light only (for engines that add direct light at runtime).
    #[arg(long)]
    indirect_only: bool,
    /// Write 32-bit float EXR pages instead of half floats.
    #[arg(long)]
    float: bool,
    /// Also write each page as an 8-bit RGBM PNG <stem>_lightmap<k>_rgbm.png (linear;
    /// decode rgb = RGB/255 · A/255 · 8).
    #[arg(long)]
    rgbm: bool,
    /// Also write each page's per-texel error estimate as <stem>_lightmap<k>_error.exr:
    /// relative resolution error, noise and total in R, G, B (see the guide, src/guide/baking.md).
    #[arg(long)]
    error_map: bool,
    /// Also write directional lightmaps: per page <stem>_lightmap<k>_{L0,L1x,L1y,L1z}.exr, L1
    /// spherical harmonics of the incident radiance (see the guide, src/guide/output.md).
    #[arg(long)]
    directional: bool,
    /// Hemisphere rays per texel of the directional gather.
    #[arg(long, value_name = "N", requires = "directional")]
    directional_rays: Option<u32>,
    /// Also place and bake light probes in the scene's empty space, at most N [default: the
    /// probes whose rays are 10% of the bake's, from 1024 to 8192]:
    /// <stem>_probes.json, named in the glTF's root extras (see the guide, src/guide/output.md).
    #[arg(long, value_name = "N", num_args = 0..=1)]
    probes: Option<Option<u32>>,
    /// Leave punctual lights' direct light out of the probes (for engines that light moving
    /// objects with the same lights at run time).
    #[arg(long)]
    probes_indirect_only: bool,
    /// Place the probes from the glTF node of this name instead of the automatic grid: one at
    /// each child's world position, or, if it has no children, a grid within the budget
    /// filling its box (the unit cube centred on the node, side 1, under its transform).
    /// Implies --probes.
    #[arg(long, value_name = "NODE")]
    probes_from: Option<String>,
    /// Share of the probe budget kept for refining the grid's cells where light changes, 0 to 1
    /// [default: 0.25]; 0 puts the whole budget on a uniform grid.
    #[arg(long, value_name = "SHARE")]
    probes_refine: Option<f32>,
    /// Keep texel sample points where they are even inside geometry (to measure leaks).
    #[arg(long)]
    no_validity: bool,
    /// Skip the edge-aware denoiser (Monte Carlo method only; see lightmap::denoise).
    #[arg(long)]
    no_denoise: bool,
    /// Leave UV seams unstitched (see lightbake::lightmap::seams).
    #[arg(long)]
    no_seams: bool,
    /// Exposure of the PNG previews, in stops.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    exposure: f32,
    /// Seed of the random sample streams (output depends on it, never on --threads).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Memory the bake may use, e.g. 512M or 8G (binary units) [default: the memory available
    /// when it starts]. A bake whose estimated peak exceeds it switches to the matrix-free
    /// gather solver when that fits (automatic choice only), or is refused before any heavy work.
    #[arg(long, value_name = "SIZE", value_parser = lightbake::build::options::parse_memory)]
    max_memory: Option<u64>,
    /// How stored Monte Carlo rows are held: auto (f32 weights, or exact ray counts when f32
    /// rows would not fit the memory limit and counts would), f32, or counts (the same output
    /// from 4.1–6.5× fewer row bytes; see the guide, src/guide/baking.md).
    #[arg(long, value_enum, default_value = "auto")]
    rows: RowsArg,
    /// Also write <stem>.transport beside the output: what `lightbake relight` needs to solve
    /// this bake again with other light and material values without casting a ray.
    #[arg(long)]
    keep_transport: bool,
    /// Re-bake incrementally from a previous bake of this scene (its .gltf/.glb, written with
    /// --keep-transport): after an edit that only moved, removed or added nodes, only the
    /// rays the edited nodes can reach (and an added node's own rows) are traced again. Runs
    /// with the previous bake's settings (not this command's quality options); bakes in full
    /// with this command's options, saying why, when the edit was more than that.
    #[arg(long, value_name = "OLD_GLTF", conflicts_with = "processes")]
    since: Option<PathBuf>,
    #[command(flatten)]
    layers: relight::LayerArgs,
    #[command(flatten)]
    gate: GateArgs,
    #[command(flatten)]
    run: RunArgs,
    #[command(flatten)]
    cluster: distributed::Args,
}

/// The error gate of `bake` and `build`: exit code [`GATE_EXIT`] when a bake is not good enough.
#[derive(clap::Args)]
struct GateArgs {
    /// Exit with code 3 when a scene's estimated error (the planner's prediction of the error a
    /// renderer will show, noise and resolution) exceeds E (0.05 = 5%). A scene without an
    /// estimate (--no-auto) fails the gate too.
    #[arg(long, value_name = "E")]
    max_error: Option<f32>,
    /// Exit with code 3 when a bake gave a warning.
    #[arg(long)]
    deny_warnings: bool,
}

/// Exit code of a failed error gate (`--max-error`, `--deny-warnings`).
const GATE_EXIT: u8 = 3;

/// The error gate failed: the message says which scenes and why.
#[derive(Debug)]
struct GateFailed(String);

impl std::fmt::Display for GateFailed {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for GateFailed {}

impl GateArgs {
    fn gate(&self) -> Gate {
        Gate {
            max_error: self.max_error,
            deny_warnings: self.deny_warnings,
        }
    }
}

/// `Err(GateFailed)` naming `problems`, if any.
fn check_gate(problems: Vec<String>) -> Result<()> {
    match problems.is_empty() {
        true => Ok(()),
        false => Err(GateFailed(problems.join("; ")).into()),
    }
}

/// Threads and verbosity, shared by `bake` and `reference`.
#[derive(clap::Args)]
struct RunArgs {
    /// Worker threads [default: all cores].
    #[arg(long)]
    threads: Option<usize>,
    /// No progress bars and no summary; warnings and errors still go to stderr.
    #[arg(short, long)]
    quiet: bool,
}

impl RunArgs {
    /// Starts the worker threads (before any parallel work) and the handlers that turn SIGINT
    /// and SIGTERM into a cancelled run (the command checks them through its [`Bars`]).
    fn start(&self) -> Result<()> {
        interrupt::install()?;
        if let Some(n) = self.threads {
            rayon::ThreadPoolBuilder::new()
                .num_threads(n.max(1))
                .build_global()
                .with_context(|| format!("cannot start {n} threads"))?;
        }
        Ok(())
    }
}

fn parse_rgb(s: &str) -> Result<Vec3, String> {
    let parts: Vec<&str> = s.split(',').collect();
    let v: Vec<f32> = parts
        .iter()
        .map(|p| p.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("{s:?}: {e}"))?;
    match v[..] {
        [x] => Ok(Vec3::splat(x)),
        [r, g, b] => Ok(Vec3::new(r, g, b)),
        _ => Err(format!("expected R,G,B or a single value, got {s:?}")),
    }
}

impl Quality {
    fn preset(self) -> BakeConfig {
        match self {
            Quality::Draft => BakeConfig::draft(),
            Quality::Medium => BakeConfig::medium(),
            Quality::High => BakeConfig::high(),
        }
    }

    /// The error the automatic choice aims at.
    fn target_error(self) -> f32 {
        AutoParams::for_preset(&value_name(self)).unwrap_or(0.04)
    }
}

impl InstancingArg {
    fn mode(self) -> Instancing {
        match self {
            InstancingArg::Duplicate => Instancing::Duplicate,
            InstancingArg::Share => Instancing::Share,
        }
    }
}

impl UvArg {
    fn mode(self) -> UvMode {
        match self {
            UvArg::Auto => UvMode::Auto,
            UvArg::Unwrap => UvMode::Unwrap,
            UvArg::Existing => UvMode::Existing,
        }
    }
}

/// The name clap parses and prints for a value.
fn value_name(v: impl ValueEnum) -> String {
    v.to_possible_value()
        .map_or_else(String::new, |p| p.get_name().to_string())
}

impl BakeArgs {
    /// The flags as the library's options by name (the manifest's format), which make the
    /// configuration.
    fn options(&self) -> Options {
        Options {
            quality: Some(value_name(self.quality)),
            target_error: self.target_error,
            no_auto: Some(self.no_auto),
            texels_per_unit: self.atlas.texels_per_unit,
            max_page_size: Some(self.atlas.max_page_size),
            padding: Some(self.atlas.padding),
            uv: Some(value_name(self.atlas.uv)),
            no_split_junctions: Some(self.atlas.no_split_junctions),
            no_shadow_cuts: Some(self.atlas.no_shadow_cuts),
            near_contacts: Some(self.atlas.near_contacts),
            no_slot_faces: Some(self.atlas.no_slot_faces),
            no_narrow_faces: Some(self.atlas.no_narrow_faces),
            instancing: Some(value_name(self.atlas.instancing)),
            rays: self.rays,
            light_samples: self.light_samples,
            sky: Some(Rgb::Rgb(self.sky.to_array())),
            method: self.method.map(value_name),
            solver: self.solver.map(value_name),
            tolerance: self.tolerance,
            max_iterations: Some(self.max_iterations),
            indirect_only: Some(self.indirect_only),
            float: Some(self.float),
            rgbm: Some(self.rgbm),
            error_map: Some(self.error_map),
            directional: Some(self.directional),
            directional_rays: self.directional_rays,
            probes: (self.probes).map(|n| n.map_or(Probes::On(true), Probes::Budget)),
            probes_indirect_only: Some(self.probes_indirect_only),
            probes_from: self.probes_from.clone(),
            probes_refine: self.probes_refine,
            no_validity: Some(self.no_validity),
            no_denoise: Some(self.no_denoise),
            no_seams: Some(self.no_seams),
            exposure: Some(self.exposure),
            seed: Some(self.seed),
            max_memory: self.max_memory.map(|bytes| bytes.to_string()),
            rows: Some(value_name(self.rows)),
            keep_transport: Some(self.keep_transport),
            layers: self.layers.specs(),
        }
    }

    fn config(&self) -> Result<BakeConfig> {
        Ok(self.options().config()?)
    }
}

fn bake(args: &BakeArgs) -> Result<()> {
    if let Some(n) = args.cluster.processes() {
        return distributed::spawn(n);
    }
    args.run.start()?;
    let config = args.config()?;
    let bars = Bars::new(args.run.quiet);
    let failed = || format!("baking {} failed", args.scene.display());
    let report = match (args.cluster.cluster()?, &args.since) {
        (None, Some(since)) => {
            lightbake::incremental::bake_since(&args.scene, since, &args.output, &config, &bars)
                .with_context(|| {
                    format!(
                        "baking {} incrementally from {} failed",
                        args.scene.display(),
                        since.display()
                    )
                })?
        }
        (None, None) => {
            lightbake::bake(&args.scene, &args.output, &config, &bars).with_context(failed)?
        }
        (Some(cluster), _) => {
            distributed::quiet_timely_panics();
            let shared =
                lightbake::distributed::bake(&args.scene, &args.output, &config, &cluster, &bars)
                    .with_context(failed)?;
            if !args.run.quiet {
                println!("{}", distributed::summary(&shared, cluster.process));
            }
            match shared.bake {
                Some(report) => report,
                None => return Ok(()),
            }
        }
    };
    if args.explain
        && let Some(plan) = &report.plan
    {
        println!(
            "automatic choice for a {:.1}% target:",
            plan.target_error * 100.0
        );
        for reason in &plan.reasons {
            println!("  - {reason}");
        }
    }
    if args.explain
        && let Some(junctions) = &report.junctions
    {
        println!("  - {}", junctions.brief());
    }
    if args.explain
        && let Some(sharing) = &report.sharing
    {
        println!(
            "  - {}; their instances are not junction-split or shadow-cut",
            sharing.brief()
        );
    }
    if args.explain
        && let Some(probes) = &report.probes
    {
        println!("  - {}", probes.explain());
    }
    if !args.run.quiet {
        println!("{}", report.summary());
        if let Some(gltf) = report.files.first() {
            println!("wrote {}", gltf.display());
        }
    }
    let result = SceneResult::of(&report, bars.warnings.lock().unwrap().clone());
    check_gate(args.gate.gate().problems(&result))
}

/// With this environment variable set, `lightbake` parses its command line and exits (0 when
/// it parses, 2 with clap's message when not): `tests/docs.rs` checks every command of the
/// README and the guide with it.
const PARSE_ONLY: &str = "LIGHTBAKE_PARSE_ONLY";

/// glibc serves buffers above its mmap threshold from fresh mappings and returns them when
/// freed, but it raises the threshold to the largest such buffer freed so far. A bake's stages
/// allocate and free large arrays one after another, so after the first ones the rest come
/// from the heap, where smaller live allocations pin their pages. Fixing the threshold at
/// glibc's starting 128 KiB cut peak memory to 0.69–0.83× on the courtyard and lamp room
/// at `high` and the furnished interior at `medium`, for about 2% more time (page faults).
fn fixed_mmap_threshold() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: `mallopt` only sets an allocator parameter; no other thread runs yet.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 128 * 1024);
    }
}

fn main() -> ExitCode {
    fixed_mmap_threshold();
    let cli = Cli::parse();
    if std::env::var_os(PARSE_ONLY).is_some() {
        return ExitCode::SUCCESS;
    }
    let result = match &cli.command {
        Command::Render(args) => render::run(args),
        Command::Reference(args) => reference::run(args),
        Command::Bake(args) => bake(args),
        Command::Relight(args) => relight::run(args),
        Command::Compare(args) => compare::run(args),
        Command::Probes(args) => probes::run(args),
        Command::View(args) => view::run(args),
        Command::Build(args) => build::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(_) if let Some(signal) = interrupt::received() => {
            eprintln!("interrupted");
            ExitCode::from(interrupt::exit_code(signal) as u8)
        }
        Err(e) if e.is::<GateFailed>() => {
            eprintln!("error: the bake is not good enough: {e}");
            ExitCode::from(GATE_EXIT)
        }
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
