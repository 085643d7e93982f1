//! [`bake`]: the whole pipeline, file in, files out.
//!
//! [`prepare`] (scene → tracer → atlas → texels, shared with the reference), then
//! [`compute`] (the automatic choice with its pilot runs in [`pilot`], light transport and its
//! solution through the one dispatch of [`light`], denoise, pages), then [`write`].

pub mod distributed;
pub mod incremental;
pub mod kept;
pub(crate) mod light;
pub(crate) mod memory;
pub(crate) mod pilot;
pub mod relight;

use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::Vec3;

use crate::config::{BakeConfig, FormFactors, Technique, TransportParams};
use crate::lightmap::{self, LightmapPages};
use crate::output::{self, PageFiles, Staging};
use crate::plan::{self, Plan};
use crate::shard::{Alone, Shards};
use crate::trace::Tracer;
use crate::transport::Surfaces;
use crate::{Error, Progress, Result, atlas, scene, solve, texels, transport};
use light::Processes;

/// Wall time of one pipeline stage.
#[derive(Clone, Debug)]
pub struct StageTime {
    /// The stage's name, as the summary prints it.
    pub stage: &'static str,
    /// Wall seconds it took.
    pub seconds: f64,
}

/// What a bake did, for the one-line summary and for build tools.
#[derive(Clone, Debug)]
pub struct BakeReport {
    pub(crate) triangles: usize,
    /// Texels baked (radiosity patches).
    pub texels: usize,
    /// Lightmap pages written.
    pub pages: usize,
    pub(crate) rays: u64,
    pub(crate) iterations: usize,
    pub(crate) residual: f32,
    /// False when the solver stopped on the iteration cap.
    pub(crate) converged: bool,
    /// Texel sample points moved out of geometry, and texels with none outside it.
    pub(crate) validity: texels::validity::ValidityReport,
    /// The automatic choice of settings and its reasons (`config.auto`).
    pub plan: Option<Plan>,
    /// Seam discontinuity before and after stitching (`None` when stitching is off).
    pub seams: Option<lightmap::seams::SeamReport>,
    /// What the junction split cut (`None` when it did not run).
    pub junctions: Option<scene::junctions::JunctionReport>,
    /// Meshes written once with a page rect per node (`--instancing share`; `None` otherwise).
    pub sharing: Option<atlas::ShareReport>,
    /// How the directional pages' reconstruction at the texel normals agrees with the lightmap
    /// (`None` without `config.output.directional`).
    pub(crate) directional: Option<lightmap::directional::Agreement>,
    /// Probes baked (all, valid) and their rays (`None` without `config.output.probes`).
    pub probes: Option<ProbeCount>,
    /// Wall time per stage, in pipeline order.
    pub stages: Vec<StageTime>,
    /// The files written, the glTF first.
    pub files: Vec<PathBuf>,
    /// What an incremental bake (`bake --since`, [`incremental`]) re-traced and reused
    /// (`None` for a plain bake).
    pub incremental: Option<incremental::Incremental>,
}

impl BakeReport {
    /// One line: texels, pages, rays, iterations, residual, seconds per stage.
    pub fn summary(&self) -> String {
        let stages: Vec<String> = self
            .stages
            .iter()
            .map(|s| format!("{} {:.2}s", s.stage, s.seconds))
            .collect();
        let total: f64 = self.stages.iter().map(|s| s.seconds).sum();
        let overhead = self.plan.as_ref().map_or(String::new(), |p| {
            format!(
                ", of which planning {:.2}s ({:.0}%)",
                p.overhead_seconds,
                100.0 * p.overhead_seconds / total.max(1e-9)
            )
        });
        let plan = self
            .plan
            .as_ref()
            .map_or(String::new(), |p| format!("; {}", p.brief));
        let seams = match &self.seams {
            Some(s) if s.before.edges > 0 => format!(
                "; seams: {} edges, max diff {:.1e} → {:.1e}",
                s.before.edges, s.before.max_abs_diff, s.after.max_abs_diff
            ),
            _ => String::new(),
        };
        let junctions = self
            .junctions
            .as_ref()
            .map_or(String::new(), |j| format!("; {}", j.brief()));
        let sharing = self
            .sharing
            .as_ref()
            .map_or(String::new(), |s| format!("; {}", s.brief()));
        let directional = self.directional.map_or(String::new(), |a| {
            format!(
                "; directional gather at the texel normals vs the lightmap: {:.1}% RMS, bias {:+.1}% (L1 reconstruction {:.1}%, {:+.1}%)",
                a.gathered_rmse * 100.0,
                a.gathered_bias * 100.0,
                a.l1_rmse * 100.0,
                a.l1_bias * 100.0
            )
        });
        let probes = self.probes.map_or(String::new(), |p| {
            format!(
                "; {} probes (budget {}{}; {} valid, {} moved off a surface), {:.2} M probe rays",
                p.probes,
                p.budget,
                if p.following {
                    " following the bake's rays"
                } else {
                    ""
                },
                p.valid,
                p.moved,
                p.rays as f64 * 1e-6
            )
        });
        let incremental = self
            .incremental
            .as_ref()
            .map_or(String::new(), |i| format!("; {}", i.brief()));
        format!(
            "{} texels ({} moved out of geometry, {} invalid, {} divided by a wall) on {} page(s), {} triangles, {:.2} M rays, {} iterations, residual {:.1e}{}{}{junctions}{sharing}{directional}{probes}{plan}{incremental}; {} (total {:.2}s{overhead})",
            self.texels,
            self.validity.moved,
            self.validity.invalid,
            self.validity.divided,
            self.pages,
            self.triangles,
            self.rays as f64 * 1e-6,
            self.iterations,
            self.residual,
            if self.converged {
                ""
            } else {
                " (NOT converged)"
            },
            seams,
            stages.join(", "),
            total
        )
    }
}

/// How many probes a bake placed, how many are valid (not buried in geometry), and the rays
/// placing and gathering them cast.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ProbeCount {
    /// Probes on the grid.
    pub probes: usize,
    /// Probes not buried in geometry.
    pub valid: usize,
    /// Probes moved away from a surface.
    pub moved: usize,
    /// Rays cast by placement and gathering.
    pub rays: u64,
    /// The budget they were placed within.
    pub budget: u32,
    /// The budget followed the bake's rays (no number was given).
    pub following: bool,
    /// The rays the bake cast for its lightmaps, pilots included (what a following budget
    /// reads).
    pub bake_rays: u64,
    /// Sphere rays per probe at most (as many light samples again).
    pub rays_per_probe: u32,
}

impl ProbeCount {
    fn of(
        p: &crate::probes::Probes,
        params: &crate::probes::ProbeParams,
        bake_rays: u64,
    ) -> ProbeCount {
        ProbeCount {
            probes: p.len(),
            valid: p.valid_count(),
            moved: p.moved,
            rays: p.rays,
            budget: p.budget,
            following: params.budget.is_none(),
            bake_rays,
            rays_per_probe: params.rays,
        }
    }

    /// One line for `--explain`: the budget and the rule that set it.
    pub fn explain(&self) -> String {
        let rule = if self.following {
            format!(
                "following the bake: the probes whose rays are {:.0}% of its {:.2} M rays at \
                 {} per probe, within {}..={}",
                100.0 * crate::probes::RAY_SHARE,
                self.bake_rays as f64 * 1e-6,
                2 * self.rays_per_probe,
                crate::probes::DEFAULT_BUDGET,
                crate::probes::MAX_FOLLOWING_BUDGET
            )
        } else {
            "given".to_string()
        };
        format!(
            "probes: budget {} ({rule}); {} placed, {} valid, {:.2} M probe rays",
            self.budget,
            self.probes,
            self.valid,
            self.rays as f64 * 1e-6
        )
    }
}

/// Everything a bake computed, stage by stage, before anything is written.
#[derive(Clone, Debug)]
pub struct Baked {
    /// The scene as baked (after the junction split).
    pub scene: scene::Scene,
    pub(crate) source: scene::Source,
    /// The lightmap UV layout.
    pub atlas: atlas::Atlas,
    /// The radiosity patches, one per covered texel.
    pub texels: texels::Texels,
    /// Form factors and direct light (no rows for the matrix-free and hierarchical solvers).
    pub transport: transport::Transport,
    /// The solved irradiance per texel and the solver's history.
    pub solution: solve::Solution,
    /// `H/π` per texel (what the pages hold before dilation and seam stitching).
    pub lightmap: Vec<Vec3>,
    /// The lightmap pages as written: dilated into the gutters, seams stitched.
    pub pages: LightmapPages,
    /// Per page, each texel's estimated relative error: resolution, noise and total in R, G, B
    /// (`config.output.error_map`; `plan::error_map`).
    pub error_map: Option<LightmapPages>,
    /// The directional pages (`lightmap::directional::NAMES`), dilated and stitched like
    /// `pages`, their agreement with the lightmap and the gather's rays
    /// (`config.output.directional`).
    pub directional: Option<([LightmapPages; 4], lightmap::directional::Agreement, u64)>,
    /// The light probes (`config.output.probes`).
    pub probes: Option<crate::probes::Probes>,
    /// Texel sample points moved out of geometry, and texels with none outside it.
    pub validity: texels::validity::ValidityReport,
    /// The settings the bake ran with: `config` with the automatic choices applied.
    pub config: BakeConfig,
    /// The automatic choice of settings and its reasons (`config.auto`).
    pub plan: Option<Plan>,
    /// Seam discontinuity before and after stitching (`None` when stitching is off).
    pub seams: Option<lightmap::seams::SeamReport>,
    pub(crate) junctions: Option<scene::junctions::JunctionReport>,
    /// Per-light layers (`config.output.layers`; [`relight`]).
    pub layers: Vec<relight::LayerPages>,
    /// Wall time per stage, in pipeline order.
    pub stages: Vec<StageTime>,
    /// The node transforms the layout was made with, when they are not the input's (an
    /// incremental bake keeps the previous layout: [`incremental`]); recorded in a kept
    /// transport.
    pub(crate) layout_nodes: Option<Vec<serde_json::Value>>,
    /// The scene and atlas the glTF is written from when they are not `scene` and `atlas`: an
    /// incremental bake that removed nodes keeps their triangles and texels (unused), one
    /// that added nodes places their instances after the old ones; both write the input's
    /// instances in the input's order ([`incremental`]).
    pub(crate) written: Option<Box<(scene::Scene, atlas::Atlas)>>,
}

/// Bakes `input` (.gltf or .glb) into `out_dir`: `<stem>.gltf` + `<stem>.bin` (or `<stem>.glb`),
/// and per page `<stem>_lightmap<k>.exr` and a tone-mapped `<stem>_lightmap<k>.png`
/// (and `<stem>_lightmap<k>_rgbm.png` with `config.output.rgbm`).
pub fn bake(
    input: &Path,
    out_dir: &Path,
    config: &BakeConfig,
    progress: &dyn Progress,
) -> Result<BakeReport> {
    refuse_overwriting_input(input, out_dir)?;
    config.validate()?;
    let t = Instant::now();
    let (scene, source) = load(input, progress)?;
    if scene.triangles.is_empty() {
        return pass_through(&source, input, out_dir, progress, t);
    }
    let prepared = prepare_loaded(scene, source, input, config, &Alone, progress, t)?;
    let baked = compute_prepared(prepared, progress)?;
    write(baked, input, out_dir, config, progress)
}

/// A valid scene with nothing to bake (only points or lines, or only zero-area triangles) is
/// written through without lightmaps, with a warning: a build step bakes every level, and such
/// a level is not an error. The glTF goes out as a bake writes it (buffers merged into
/// `<stem>.bin`, external images copied), so what references it finds the same files.
fn pass_through(
    source: &scene::Source,
    input: &Path,
    out_dir: &Path,
    progress: &dyn Progress,
    load_start: Instant,
) -> Result<BakeReport> {
    let mut stages = Vec::new();
    timed(&mut stages, "load", load_start);
    progress.warn(&format!(
        "{}: nothing to bake (no triangle with an area): written through without lightmaps",
        input.display()
    ));
    let t = Instant::now();
    let nothing = scene::Scene::default();
    let no_atlas = atlas::Atlas {
        pages: Vec::new(),
        instances: Vec::new(),
        texels_per_unit: 0.0,
        reused_input_uvs: false,
        shared: Vec::new(),
    };
    let stem = output_stem(input);
    let mut staging = Staging::new(out_dir, &protected_files(input, source))?;
    output::write_gltf(&nothing, source, &no_atlas, &[], &mut staging, &stem)?;
    check_aborted(progress)?;
    let files = commit(staging)?;
    timed(&mut stages, "write", t);
    Ok(BakeReport {
        triangles: 0,
        texels: 0,
        pages: 0,
        rays: 0,
        iterations: 0,
        residual: 0.0,
        converged: true,
        validity: Default::default(),
        plan: None,
        seams: None,
        junctions: None,
        sharing: None,
        directional: None,
        probes: None,
        stages,
        files,
        incremental: None,
    })
}

/// The stages before light transport, shared by a bake and the reference (so their texels
/// cannot drift apart).
pub struct Prepared {
    /// The scene to bake (after the junction split).
    pub scene: scene::Scene,
    pub(crate) source: scene::Source,
    /// The BVH over the scene.
    pub tracer: Tracer,
    /// The lightmap UV layout.
    pub atlas: atlas::Atlas,
    /// The radiosity patches, sample points moved out of geometry.
    pub texels: texels::Texels,
    /// Texel sample points moved out of geometry, and texels with none outside it.
    pub(crate) validity: texels::validity::ValidityReport,
    /// `config` with the automatic texel density applied.
    pub(crate) config: BakeConfig,
    /// The automatic choice so far (the density), when `config.auto` asks for one.
    pub(crate) plan: Option<Plan>,
    /// What the density pilot measured that the transport choice starts from: its pair's
    /// noise and its sampled points' gathered light.
    pub(crate) density: pilot::Reused,
    /// What the junction split cut (`None` when it did not run).
    pub(crate) junctions: Option<scene::junctions::JunctionReport>,
    pub(crate) stages: Vec<StageTime>,
    /// Processes sharing the final bake's rows (1 on one machine): memory is checked per process.
    pub(crate) processes: usize,
}

impl Prepared {
    /// The automatic choice so far (the density and its reasons), when the config asks for one.
    pub fn plan(&self) -> Option<&Plan> {
        self.plan.as_ref()
    }

    /// What light transport reads.
    pub(crate) fn surfaces(&self) -> Surfaces<'_> {
        Surfaces {
            scene: &self.scene,
            texels: &self.texels,
            tracer: &self.tracer,
        }
    }
}

/// The junction split as a bake runs it on a loaded scene ([`scene::junctions`], cutting along
/// shadow outlines too when `config` asks for them), at `config`'s texel density; `None` for
/// the report when the split does not run (turned off, or the input's own UVs are kept).
pub fn split_junctions(
    scene: scene::Scene,
    source: &scene::Source,
    config: &BakeConfig,
) -> (scene::Scene, Option<scene::junctions::JunctionReport>) {
    if !config.atlas.split_junctions || atlas::reuses_input_uvs(&scene, source, &config.atlas) {
        return (scene, None);
    }
    let texel = 1.0 / config.atlas.texels_per_unit;
    // Shared meshes (`--instancing share`) cannot carry one node's cuts.
    let whole = atlas::shared_instances(&scene, source, &config.atlas);
    let near = config.atlas.near_contacts;
    let (scene, report) = if config.atlas.shadow_cuts && !scene.lights.is_empty() {
        // Shadow rays see the geometry as loaded: the split moves no surface.
        let tracer = Tracer::new(&scene);
        let lights = scene.lights.clone();
        let light_at = |l: usize, p: Vec3, n: Vec3| {
            crate::lights::punctual_irradiance(&lights[l], p + n * tracer.epsilon, n, &tracer)
                .element_sum()
                / 3.0
        };
        let cutter = scene::shadow_cuts::ShadowCutter::new(&scene, &light_at);
        scene::junctions::split_except(scene, texel, near, Some(&cutter), &whole)
    } else {
        scene::junctions::split_except(scene, texel, near, None, &whole)
    };
    (scene, Some(report))
}

fn timed(stages: &mut Vec<StageTime>, stage: &'static str, start: Instant) {
    stages.push(StageTime {
        stage,
        seconds: start.elapsed().as_secs_f64(),
    });
}

/// Loads `input` and builds the tracer, then (after the automatic density choice and a memory
/// check) the atlas and the texels, with sample points moved out of geometry.
pub fn prepare(input: &Path, config: &BakeConfig, progress: &dyn Progress) -> Result<Prepared> {
    config.validate()?;
    let t = Instant::now();
    let (scene, source) = load(input, progress)?;
    if scene.triangles.is_empty() {
        return Err(Error::invalid(input, "the scene has no triangles"));
    }
    prepare_loaded(scene, source, input, config, &Alone, progress, t)
}

/// Loads `input` and hands the loader's warnings to `progress`.
fn load(input: &Path, progress: &dyn Progress) -> Result<(scene::Scene, scene::Source)> {
    let (scene, source) = scene::load(input)?;
    for w in &scene.stats.warnings {
        progress.warn(w);
    }
    Ok((scene, source))
}

/// [`prepare`] from a loaded scene with triangles (loading began at `load_start`), on
/// `processes` (which share the density pilot and the validity pass).
fn prepare_loaded(
    scene: scene::Scene,
    source: scene::Source,
    input: &Path,
    config: &BakeConfig,
    processes: &dyn Processes,
    progress: &dyn Progress,
    load_start: Instant,
) -> Result<Prepared> {
    let mut config = config.clone();
    let mut plan = config.auto.map(|a| Plan {
        target_error: a.target_error,
        ..Default::default()
    });
    let mut stages = Vec::new();
    if !scene.has_light_sources() && config.transport.sky.max_element() <= 0.0 {
        progress.warn(&format!(
            "{}: the scene has no lights, no emissive materials and no sky: the lightmap will be black",
            input.display()
        ));
    }
    timed(&mut stages, "load", load_start);

    // A probe node that is missing fails now, not after the bake.
    if let Some(probes) = &config.output.probes {
        crate::probes::check(&scene, probes, input)?;
    }
    if let (Some(plan), Some(auto)) = (&mut plan, config.auto) {
        plan::choose_density(&scene, &mut config, plan, &auto.keep);
    }
    // The limit is read once: the machine's available memory changes as the bake allocates.
    config.max_memory = Some(memory::limit(&config));
    memory::check(
        input,
        &plan::memory::Sizes::predicted(&scene, &source, &config).per_process(processes.count()),
        &config,
        config.max_memory.unwrap_or(u64::MAX),
    )?;
    // Receivers are cut at the density's texel size, before the tracer sees their triangles.
    let t = Instant::now();
    let (scene, junctions) = split_junctions(scene, &source, &config);
    if junctions.is_some() {
        timed(&mut stages, "junctions", t);
    }

    let t = Instant::now();
    let tracer = Tracer::new(&scene);
    timed(&mut stages, "bvh", t);

    // Slot faces (near contacts only: their cuts keep the raise inside the slot) get texels at
    // their gap's scale, and narrow faces near emitters four texels across; the density
    // plan's factors are raised to these, never lowered below.
    let mut junctions = junctions;
    let slots = config.atlas.near_contacts && config.atlas.slot_faces;
    if (slots || config.atlas.narrow_faces)
        && let Some(report) = &mut junctions
    {
        let t = Instant::now();
        let tpu = config.atlas.texels_per_unit;
        let raise = atlas::slots::Raise {
            slots: slots.then(|| scene::junctions::near_distance(1.0 / tpu)),
            narrow: config.atlas.narrow_faces,
            sky: config.transport.sky.max_element() > 0.0,
        };
        let (factors, slots) = atlas::slots::density(&scene, &tracer, tpu, &raise);
        raise_to(&mut config.atlas.triangle_density, &factors);
        report.slots = Some(slots);
        timed(&mut stages, "narrow faces", t);
    }

    // Adaptive density (`density_pilot`): a density per region, and on a small scene perhaps
    // the final layout itself.
    let mut reused = pilot::Reused::default();
    let mut kept_layout = None;
    if let (Some(plan), Some(auto)) = (&mut plan, config.auto)
        && !auto.keep.texels_per_unit
        && !atlas::reuses_input_uvs(&scene, &source, &config.atlas)
        && pilot::density_measurable(&scene, &config)
    {
        let inputs = (&scene, &source, &tracer);
        (reused, kept_layout) =
            density_pilot(inputs, &mut config, plan, processes, progress, &mut stages)?;
    }
    let (atlas, texels, validity) = match kept_layout {
        Some(layout) => layout,
        None => lay_out(
            &scene,
            &source,
            &tracer,
            &config,
            processes,
            progress,
            &mut stages,
        )?,
    };

    Ok(Prepared {
        scene,
        source,
        tracer,
        atlas,
        texels,
        validity,
        config,
        plan,
        density: reused,
        junctions,
        stages,
        processes: processes.count(),
    })
}

/// An atlas, its texels and their validity pass.
type LaidOut = (
    atlas::Atlas,
    texels::Texels,
    texels::validity::ValidityReport,
);

/// The density pilot: a pilot on a uniform atlas of its own, charted quickly, at half the
/// preset's density and at most `plan::density::PILOT_TEXELS` texels, chooses a density per
/// region (`plan::density`) into
/// `config`; the atlas is then laid out at those densities. A scene small enough that its
/// pilot atlas is at the preset's density and whose charting is cheap is measured on the final
/// atlas itself ([`MEASURE_ON_FINAL_TRIANGLES`]): when the density stays uniform, or the
/// factors asked would move fewer than [`KEEP_MOVED_SHARE`] of its texels, that layout is
/// returned and its pilot pair is in the returned [`pilot::Reused`], so the pilot cost nothing
/// but its sample.
fn density_pilot(
    (scene, source, tracer): (&scene::Scene, &scene::Source, &Tracer),
    config: &mut BakeConfig,
    plan: &mut Plan,
    processes: &dyn Processes,
    progress: &dyn Progress,
    stages: &mut Vec<StageTime>,
) -> Result<(pilot::Reused, Option<LaidOut>)> {
    let t = Instant::now();
    let tpu = config.atlas.texels_per_unit;
    let uniform = plan::surface_area(scene) * f64::from(tpu).powi(2);
    let scale = (plan::density::PILOT_TEXELS / uniform.max(1.0))
        .sqrt()
        .min(1.0);
    let on_final = scale >= 1.0 && scene.triangles.len() <= MEASURE_ON_FINAL_TRIANGLES;
    // A pilot atlas of its own at the preset's density is measured at half of it.
    let scale = if scale >= 1.0 && !on_final {
        plan::density::QUICK_PILOT_SCALE
    } else {
        scale
    };
    let mut coarse = config.clone();
    coarse.atlas.texels_per_unit = tpu * scale as f32;
    let mut layout_stages = Vec::new();
    let layout = if on_final {
        let layout = lay_out(
            scene,
            source,
            tracer,
            config,
            processes,
            progress,
            &mut layout_stages,
        )?;
        Layout::Final(layout)
    } else {
        Layout::Pilot(pilot_layout(
            scene, source, tracer, &coarse, processes, progress,
        )?)
    };
    let laid_out = t.elapsed().as_secs_f64();
    let surfaces = Surfaces {
        scene,
        texels: layout.texels(),
        tracer,
    };
    let density = pilot::measure_density(surfaces, &coarse, tpu, plan, processes, progress)?;
    let mut reused = density.reused;
    let factors = density.triangle_factors.map(|mut factors| {
        // Slot faces keep their gap's density whatever the pilot judged of them.
        raise_to(&mut factors, &config.atlas.triangle_density);
        factors
    });
    let moved = factors
        .as_ref()
        .map(|f| moved_share(scene, f, &config.atlas.triangle_density));
    let factors = match (&layout, moved) {
        (Layout::Final(_), Some(moved)) if moved < KEEP_MOVED_SHARE => {
            plan.reasons.push(format!(
                "texel density kept uniform: the chosen densities would move {:.1}% of the \
                 measured atlas's texels, below {:.0}%; laying it out again and casting its \
                 pilot pair again would cost more than they move",
                100.0 * moved,
                100.0 * KEEP_MOVED_SHARE
            ));
            None
        }
        _ => factors,
    };
    match (layout, factors) {
        (Layout::Final(layout), None) => {
            // The bake's own atlas, texels and pair: only the pilot's sample is overhead.
            stages.extend(layout_stages);
            let measuring = t.elapsed().as_secs_f64() - laid_out;
            stages.push(StageTime {
                stage: "density pilot",
                seconds: measuring,
            });
            if let Some(pair) = &density.pair {
                plan.overhead_seconds += (measuring - pair.seconds).max(0.0);
            }
            reused.pair = density.pair;
            reused.punctual = density.punctual;
            plan.reasons.push(
                "atlas: the one the density pilot measured (uniform at the preset's \
                 density, charted in full), kept with its validity pass and pilot pair"
                    .into(),
            );
            Ok((reused, Some(layout)))
        }
        (_, factors) => {
            if let Some(factors) = factors {
                config.atlas.triangle_density = factors;
            }
            if let Some(pair) = density.pair {
                plan.discarded_rays += pair.runs.rays();
            }
            timed(stages, "density pilot", t);
            plan.overhead_seconds += t.elapsed().as_secs_f64();
            Ok((reused, None))
        }
    }
}

/// A density pilot that measured the final atlas keeps it, with its pilot pair, when the
/// densities it chose would move fewer than this share of the atlas's texels (added and
/// removed, by area): a new layout costs a validity pass and a pilot pair cast again (40 rays
/// and light samples a texel, half a `draft` bake's), more than 5% of the texels save; the
/// small scenes' plans that moved less were a few regions at ×⅛ or a small one raised to
/// its least texels.
const KEEP_MOVED_SHARE: f64 = 0.05;

/// The share of the texels of an atlas laid out at `laid` (per scene triangle, empty meaning
/// 1) that `chosen` adds or removes, by area.
fn moved_share(scene: &scene::Scene, chosen: &[f32], laid: &[f32]) -> f64 {
    let (mut moved, mut all) = (0.0, 0.0);
    for (t, &c) in chosen.iter().enumerate() {
        let area = scene.triangle_area(t);
        let was = f64::from(laid.get(t).copied().unwrap_or(1.0)).powi(2);
        moved += area * (f64::from(c).powi(2) - was).abs();
        all += area * was;
    }
    if all > 0.0 { moved / all } else { 0.0 }
}

/// Raises each of `factors` (per scene triangle, empty meaning 1) to at least `floor`'s.
fn raise_to(factors: &mut Vec<f32>, floor: &[f32]) {
    if floor.is_empty() {
        return;
    }
    if factors.len() != floor.len() {
        *factors = vec![1.0; floor.len()];
    }
    for (f, &g) in factors.iter_mut().zip(floor) {
        *f = f.max(g);
    }
}

/// The atlas, its texels and their validity pass (each stage timed into `stages`).
fn lay_out(
    scene: &scene::Scene,
    source: &scene::Source,
    tracer: &Tracer,
    config: &BakeConfig,
    shards: &dyn Shards,
    progress: &dyn Progress,
    stages: &mut Vec<StageTime>,
) -> Result<LaidOut> {
    let t = Instant::now();
    let atlas = atlas::build_with(scene, source, &config.atlas, progress)?;
    timed(stages, "atlas", t);
    check_aborted(progress)?;

    let t = Instant::now();
    let mut texels = texels::build(scene, &atlas)?;
    timed(stages, "texels", t);
    check_aborted(progress)?;

    let t = Instant::now();
    let validity = fix_validity(&mut texels, scene, tracer, config, shards, progress)?;
    timed(stages, "validity", t);
    Ok((atlas, texels, validity))
}

/// The validity pass over `texels` when `config` asks for it, its probes divided among `shards`.
fn fix_validity(
    texels: &mut texels::Texels,
    scene: &scene::Scene,
    tracer: &Tracer,
    config: &BakeConfig,
    shards: &dyn Shards,
    progress: &dyn Progress,
) -> Result<texels::validity::ValidityReport> {
    let grid = texels::validity::GRID;
    fix_validity_on_grid(texels, scene, tracer, config, grid, shards, progress)
}

/// [`fix_validity`] with `grid × grid` candidate points per buried texel.
fn fix_validity_on_grid(
    texels: &mut texels::Texels,
    scene: &scene::Scene,
    tracer: &Tracer,
    config: &BakeConfig,
    grid: u32,
    shards: &dyn Shards,
    progress: &dyn Progress,
) -> Result<texels::validity::ValidityReport> {
    if !config.transport.validity {
        return Ok(Default::default());
    }
    let params = texels::validity::ValidityParams {
        seed: config.transport.seed,
        grid,
        ..Default::default()
    };
    texels::validity::fix_sharded(texels, scene, tracer, &params, shards, progress)
}

/// Scenes of at most this many triangles are charted in full for the density pilot when its
/// atlas is at the preset's density, so that the bake can keep it: xatlas charts the corpus'
/// small scenes (up to 1 802 triangles) in at most 0.04 s, against 2.3 s for the furnished
/// interior's 70 772, less than the density pilot's own bakes. Measuring such a scene on its
/// final atlas whatever its size (not only within `PILOT_TEXELS`) was tried on 7 December on
/// the one corpus bake it changes, the courtyard at `high` (325k texels): with seed 0 the atlas
/// was kept (planning 29% → 22%, p95 14.0% → 13.5%), with seed 1 the sample at 32 /m read
/// 1.42% where the coarse pilot's carried 1.03%, raised ×1.14 and laid out again, throwing the
/// full-size pair away (10.8 → 14.6 s, 0.97% → 1.15%); not taken.
const MEASURE_ON_FINAL_TRIANGLES: usize = 20_000;

/// The density pilot's layout: the final atlas at uniform density, or a quick one of its own.
enum Layout {
    Final(LaidOut),
    Pilot(texels::Texels),
}

impl Layout {
    fn texels(&self) -> &texels::Texels {
        match self {
            Layout::Final((_, texels, _)) => texels,
            Layout::Pilot(texels) => texels,
        }
    }
}

/// Candidate points per side of a buried texel's footprint in the density pilot's validity
/// pass: 2 × 2 rather than the bake's [`texels::validity::GRID`], so that a texel buried in a
/// solid costs 5 probe sets rather than 17. The pilot only needs to tell buried from seen
/// surfaces and where contacts darken texels, not the best point within a texel.
const PILOT_VALIDITY_GRID: u32 = 2;

/// The density pilot's texels: a quickly charted atlas (`atlas::build_quick`) and its validity
/// pass.
fn pilot_layout(
    scene: &scene::Scene,
    source: &scene::Source,
    tracer: &Tracer,
    config: &BakeConfig,
    shards: &dyn Shards,
    progress: &dyn Progress,
) -> Result<texels::Texels> {
    let atlas = atlas::build_quick(scene, source, &config.atlas, progress)?;
    check_aborted(progress)?;
    let mut texels = texels::build(scene, &atlas)?;
    let grid = PILOT_VALIDITY_GRID;
    fix_validity_on_grid(&mut texels, scene, tracer, config, grid, shards, progress)?;
    Ok(texels)
}

/// Runs every stage up to the dilated pages, in memory.
pub fn compute(input: &Path, config: &BakeConfig, progress: &dyn Progress) -> Result<Baked> {
    compute_prepared(prepare(input, config, progress)?, progress)
}

/// [`compute`] from the prepared stages.
fn compute_prepared(mut prepared: Prepared, progress: &dyn Progress) -> Result<Baked> {
    let lit = light(&mut prepared, &Alone, progress)?;
    finish(prepared, lit, progress)
}

/// The settings chosen for the final bake and its light, before denoising.
pub(crate) struct Lighting {
    config: BakeConfig,
    plan: Option<Plan>,
    stages: Vec<StageTime>,
    last: pilot::FinalBake,
}

/// The automatic choice (pilot runs included) and the final bake, on `processes` (one, or
/// those of a [`distributed`] bake).
pub(crate) fn light(
    prepared: &mut Prepared,
    processes: &dyn Processes,
    progress: &dyn Progress,
) -> Result<Lighting> {
    let mut density = std::mem::take(&mut prepared.density);
    let (mut config, mut plan, mut stages) = (
        prepared.config.clone(),
        prepared.plan.clone(),
        prepared.stages.clone(),
    );

    let sizes_of = |p: &Prepared| {
        plan::memory::Sizes::counted(&p.scene, &p.source, &p.texels).per_process(p.processes)
    };
    let mut sizes = sizes_of(prepared);
    let limit = config.max_memory.unwrap_or(u64::MAX);
    memory::check(&prepared.source.path, &sizes, &config, limit)?;
    let mut pilot = None;
    if let (Some(auto), Some(plan)) = (config.auto, plan.as_mut()) {
        let before = plan.clone();
        let choose = |prepared: &Prepared,
                      config: &mut BakeConfig,
                      plan: &mut Plan,
                      density: &mut pilot::Reused,
                      stages: &mut Vec<StageTime>,
                      stage| {
            let t = Instant::now();
            let surfaces = prepared.surfaces();
            let keep = &auto.keep;
            let runs = pilot::choose_transport(
                surfaces, config, plan, keep, progress, density, processes,
            )?;
            config.validate()?;
            timed(stages, stage, t);
            Ok::<_, Error>(runs)
        };
        pilot = choose(
            prepared,
            &mut config,
            plan,
            &mut density,
            &mut stages,
            "plan",
        )?;
        // The laid-out atlas's own sample checks the density pilot's choice, once.
        if let Some((factors, why)) = (density.choice.take()).and_then(|c| c.raise_after(plan)) {
            let mut again = before;
            // The first plan's pilot runs were cast on an atlas the bake no longer uses.
            let spent = pilot.take().map_or(0, |runs| {
                runs.rays() + runs.earlier.as_ref().map_or(0, |e| e.rays())
            });
            again.discarded_rays = plan.discarded_rays + spent;
            again.overhead_seconds = plan.overhead_seconds + plan.pilot_seconds;
            again.reasons.push(why);
            let t = Instant::now();
            lay_out_again(prepared, factors, processes, progress)?;
            timed(&mut stages, "atlas again", t);
            again.overhead_seconds += t.elapsed().as_secs_f64();
            sizes = sizes_of(prepared);
            memory::check(&prepared.source.path, &sizes, &prepared.config, limit)?;
            config = prepared.config.clone();
            *plan = again;
            pilot = choose(
                prepared,
                &mut config,
                plan,
                &mut density,
                &mut stages,
                "plan again",
            )?;
        }
    }
    let surfaces = prepared.surfaces();
    let input = prepared.source.path.as_path();
    // A kept transport (and layers) must describe the lightmap written: one run's rows, so the
    // pilot runs are not mixed in (their rays are spent on the choice only), and every texel
    // casts the chosen rays, so the kept settings say all a fresh bake needs to cast the same
    // (`--no-auto` with them).
    let kept = config.output.keep_transport || config.output.layers.is_some();
    if kept {
        config.transport.split_direct = true;
        if let Some(plan) = plan.as_mut() {
            if let Some(runs) = pilot.take() {
                let earlier = runs.earlier.as_deref();
                plan.discarded_rays += runs.rays() + earlier.map_or(0, |e| e.rays());
                // The one run casts what the pilot pairs and the final bake would have together.
                let t = &mut config.transport;
                let own = !runs.enough as u32;
                let (k, l) = earlier.map_or((0, 0), |e| (e.gather_rays, e.light_samples));
                t.gather_rays = own * t.gather_rays + 2 * (runs.gather_rays + k);
                t.light_samples = own * t.light_samples + 2 * (runs.light_samples + l);
                plan.reasons.push(format!(
                    "kept transport: one bake at K={} and L={} (the pilot bakes' rays and the final bake's together), the pilot bakes not mixed in",
                    t.gather_rays, t.light_samples
                ));
            }
            plan.texel_rays = None;
        }
    }
    memory::fit(
        input,
        &sizes,
        &mut config,
        plan.as_mut(),
        pilot
            .as_ref()
            .map(|p| (p.gather_rays, p.enough, p.held_runs())),
        limit,
        progress,
    )?;
    if kept {
        config.validate()?; // the memory limit may have asked for the gather solver
    }

    let t = Instant::now();
    // With a plan, the pilot bakes are part of the result (a ray-weighted mean).
    let last = pilot::final_bake(surfaces, &config, plan.as_ref(), pilot, processes, progress)?;
    if !last.solution.converged {
        progress.warn(&format!(
            "the solver stopped on the iteration cap ({}) at residual {:.2e}, above the tolerance {:.1e}",
            last.solution.history.len(),
            last.solution.residual(),
            config.solve.tolerance
        ));
    }
    timed(&mut stages, "transport+solve", t);
    Ok(Lighting {
        config,
        plan,
        stages,
        last,
    })
}

/// The atlas, texels and validity laid out again at the triangle density `factors`, when the
/// laid-out atlas's sample found the density pilot's choice short
/// (`plan::density::DensityChoice::raise_after`). Factors the atlas was laid out with stay a
/// floor (slot faces keep theirs); an atlas laid out uniform has none, and its hidden regions
/// then go to their ×⅛ like any new layout's.
fn lay_out_again(
    prepared: &mut Prepared,
    mut factors: Vec<f32>,
    shards: &dyn Shards,
    progress: &dyn Progress,
) -> Result<()> {
    raise_to(&mut factors, &prepared.config.atlas.triangle_density);
    prepared.config.atlas.triangle_density = factors;
    let (atlas, texels, validity) = lay_out(
        &prepared.scene,
        &prepared.source,
        &prepared.tracer,
        &prepared.config,
        shards,
        progress,
        &mut Vec::new(),
    )?;
    (prepared.atlas, prepared.texels, prepared.validity) = (atlas, texels, validity);
    Ok(())
}

/// The rays a bake cast for its lightmaps: the final transport's and the pilot bakes' not
/// mixed into it (what a probe budget that follows the bake reads).
pub(crate) fn lightmap_rays(transport_rays: u64, plan: Option<&Plan>) -> u64 {
    transport_rays + plan.map_or(0, |p| p.discarded_rays)
}

/// Denoising, dilation and seams of a lit bake, and the outputs gathered from its solution
/// (directional pages, probes, layers).
pub(crate) fn finish(prepared: Prepared, lit: Lighting, progress: &dyn Progress) -> Result<Baked> {
    let Lighting {
        config,
        plan,
        mut stages,
        last,
    } = lit;
    // Before denoising: the error map shows the noise the denoiser was given.
    let noise = (config.output.error_map).then(|| texel_noise(&prepared.texels, &config, &last));
    let pilot::FinalBake {
        mut transport,
        solution,
        gather_rays,
        light_samples,
        texel_gather_rays,
    } = last;
    let t = Instant::now();
    let directional = gather_directional(&prepared, &config, &solution, progress)?;
    if directional.is_some() {
        timed(&mut stages, "directional", t);
    }
    let t = Instant::now();
    let bake_rays = lightmap_rays(transport.rays, plan.as_ref());
    let probes = gather_probes(&prepared, &config, &solution, bake_rays, progress)?;
    if probes.is_some() {
        timed(&mut stages, "probes", t);
    }
    let Prepared {
        scene,
        source,
        atlas,
        texels,
        validity,
        junctions,
        ..
    } = prepared;

    let t = Instant::now();
    let noise_model = TransportParams {
        gather_rays,
        light_samples,
        ..config.transport.clone()
    };
    // Each texel's own rays where the plan moved rays between texels.
    let texel_rays = (plan.as_ref())
        .is_some_and(|p| p.texel_rays.is_some())
        .then_some(texel_gather_rays.as_slice());
    let Denoised {
        mut lightmap,
        denoised,
        layer_guide,
    } = denoised_lightmap(
        &texels,
        &transport,
        &solution,
        &config,
        (&noise_model, texel_rays),
        progress,
    )?;
    timed(&mut stages, "denoise", t);
    let t = Instant::now();
    let mut pages = pages_of(&texels, &mut lightmap, config.atlas.padding);
    let error_map = noise.map(|sigma| {
        let noise_level = plan.as_ref().and_then(|p| p.predicted_noise);
        let map = plan::error_map::error_map(&texels, &lightmap, &sigma, denoised, noise_level);
        LightmapPages::from_texels(&texels, &map)
    });
    timed(&mut stages, "dilate", t);
    let mut layers = Vec::new();
    if let Some(groups) = &config.output.layers {
        let t = Instant::now();
        let settings = kept::Settings::new(&scene, &config, "");
        let planned = relight::plan_layers(&settings, groups)?;
        let seams = (config.output.seams)
            .then(|| lightmap::seams::find(&scene, &atlas, &Default::default()));
        let guide = layer_guide
            .as_ref()
            .map(|(g, n)| (g.as_slice(), n.as_slice()));
        let scale = vec![Vec3::ONE; transport.sources.len()];
        layers = relight::layer_pages(
            (&texels, &mut transport),
            &config,
            &solution,
            (&scale, &planned),
            guide,
            seams.as_ref(),
            progress,
        )?;
        timed(&mut stages, "layers", t);
    }
    check_aborted(progress)?;
    let t = Instant::now();
    let seams = config
        .output
        .seams
        .then(|| lightmap::seams::stitch_bake(&scene, &atlas, &mut pages, &Default::default()));
    timed(&mut stages, "seams", t);
    check_aborted(progress)?;
    let directional = directional.map(|gathered| {
        let t = Instant::now();
        let pages = directional_pages(&scene, &atlas, &texels, &gathered, &config);
        let agreement = lightmap::directional::agreement(&texels, &gathered, &lightmap);
        timed(&mut stages, "directional pages", t);
        (pages, agreement, gathered.rays)
    });

    Ok(Baked {
        scene,
        source,
        atlas,
        texels,
        transport,
        solution,
        lightmap,
        pages,
        error_map,
        directional,
        probes,
        validity,
        config,
        plan,
        seams,
        junctions,
        layers,
        stages,
        layout_nodes: None,
        written: None,
    })
}

/// The directional lightmap's gather from the solution (`config.output.directional`).
fn gather_directional(
    prepared: &Prepared,
    config: &BakeConfig,
    solution: &solve::Solution,
    progress: &dyn Progress,
) -> Result<Option<lightmap::directional::Gathered>> {
    let Some(rays) = config.output.directional else {
        return Ok(None);
    };
    let params = lightmap::directional::DirectionalParams {
        rays,
        seed: config.transport.seed,
        sky: config.transport.sky,
        indirect_only: config.transport.indirect_only,
    };
    let surfaces = prepared.surfaces();
    lightmap::directional::gather(surfaces, &solution.irradiance, &params, progress).map(Some)
}

/// The light probes gathered from the solution (`config.output.probes`), their budget
/// following the bake's `bake_rays` when none is given.
fn gather_probes(
    prepared: &Prepared,
    config: &BakeConfig,
    solution: &solve::Solution,
    bake_rays: u64,
    progress: &dyn Progress,
) -> Result<Option<crate::probes::Probes>> {
    let Some(params) = config.output.probes.as_ref() else {
        return Ok(None);
    };
    let bake = (
        config.transport.seed,
        config.transport.sky,
        prepared.source.path.as_path(),
        bake_rays,
    );
    crate::probes::bake(
        prepared.surfaces(),
        &solution.irradiance,
        params,
        bake,
        progress,
    )
    .map(Some)
}

/// The stored lightmap values, denoised where the bake denoises.
struct Denoised {
    lightmap: Vec<Vec3>,
    /// The denoiser ran (Monte Carlo transport with denoising on).
    denoised: bool,
    /// The values before denoising and their noise, which layers are denoised with (the
    /// lightmap's own weights; see `relight`), when the bake has layers.
    layer_guide: Option<(Vec<Vec3>, Vec<f32>)>,
}

/// The texels' stored values `H/π` from the solution, denoised with the noise model of the
/// rays cast (`noise_model`: the transport's rays, each texel's own where the plan moved rays).
fn denoised_lightmap(
    texels: &texels::Texels,
    transport: &transport::Transport,
    solution: &solve::Solution,
    config: &BakeConfig,
    noise_model: (&TransportParams, Option<&[f32]>),
    progress: &dyn Progress,
) -> Result<Denoised> {
    let indirect_only = config.transport.indirect_only;
    let mut lightmap = stored_values(&solution.irradiance, &transport.direct, indirect_only);
    let denoised = config.transport.denoise && config.technique.is_monte_carlo();
    // Layers are denoised with the lightmap's own weights (see `relight`).
    let layer_guide = (denoised && config.output.layers.is_some()).then(|| {
        let noise =
            lightmap::denoise::bake_noise(texels, &transport.direct, &lightmap, noise_model);
        (lightmap.clone(), noise)
    });
    if denoised {
        lightmap::denoise::denoise_bake(texels, transport, &mut lightmap, noise_model, progress)?;
    }
    Ok(Denoised {
        lightmap,
        denoised,
        layer_guide,
    })
}

/// The directional pages from their gather: dilated as the lightmap's pages are (at least
/// two texels a side), stitched across seams when the bake stitches (only the first page,
/// the ambient term, kept non-negative).
fn directional_pages(
    scene: &scene::Scene,
    atlas: &atlas::Atlas,
    texels: &texels::Texels,
    gathered: &lightmap::directional::Gathered,
    config: &BakeConfig,
) -> [LightmapPages; 4] {
    let mut pages = lightmap::directional::pages(texels, &gathered.sh);
    for (c, p) in pages.iter_mut().enumerate() {
        lightmap::dilate(p, config.atlas.padding.max(2) * 2);
        if config.output.seams {
            let params = lightmap::seams::SeamParams {
                non_negative: c == 0,
                ..Default::default()
            };
            lightmap::seams::stitch_bake(scene, atlas, p, &params);
        }
    }
    pages
}

/// What a texel stores, `H/π`, from the solved irradiance `h` and the direct light `direct`;
/// indirect-only leaves out light that arrived without a bounce.
pub(crate) fn stored_values(h: &[Vec3], direct: &[Vec3], indirect_only: bool) -> Vec<Vec3> {
    (h.iter().zip(direct))
        .map(|(h, d)| match indirect_only {
            true => (*h - *d).max(Vec3::ZERO),
            false => *h,
        } / std::f32::consts::PI)
        .collect()
}

/// Pages of `lightmap` (indexed like `texels`): invalid texels filled from their neighbours
/// (in `lightmap` too), then dilated into the gutters (`padding` sets the reach).
pub(crate) fn pages_of(
    texels: &texels::Texels,
    lightmap: &mut [Vec3],
    padding: u32,
) -> LightmapPages {
    texels::validity::fill_invalid(texels, lightmap);
    let mut pages = LightmapPages::from_texels(texels, lightmap);
    lightmap::dilate(&mut pages, padding.max(2) * 2);
    pages
}

/// Standard deviation per texel and channel of the stored values (`H/π`) of `bake` before
/// denoising, for the error map ([`plan::error_map`]): the texel's own variance where the bake
/// stored Monte Carlo rows, the denoiser's model for the matrix-free gatherer, none for the
/// deterministic methods.
fn texel_noise(texels: &texels::Texels, config: &BakeConfig, bake: &pilot::FinalBake) -> Vec<Vec3> {
    let h = &bake.solution.irradiance;
    let emitters = texels.emission.iter().any(|e| e.max_element() > 0.0);
    let sky = config.transport.sky;
    let sigma = match config.technique {
        Technique::Stored {
            form_factors: FormFactors::MonteCarlo,
            ..
        } => {
            let samples = plan::error_map::Samples {
                rays: &bake.texel_gather_rays,
                light_per_ray: match emitters {
                    true => bake.light_samples as f32 / bake.gather_rays.max(1) as f32,
                    false => 0.0,
                },
            };
            plan::error_map::gathering_noise(&bake.transport, texels, h, sky, &samples)
        }
        Technique::Gather => {
            // As the denoiser: without emitters and sky, direct light is exact.
            let sampled = emitters || sky.max_element() > 0.0;
            let l = if sampled {
                bake.light_samples.max(1)
            } else {
                0
            };
            plan::error_map::modelled_noise(h, &bake.transport.direct, bake.gather_rays, l)
        }
        _ => vec![Vec3::ZERO; h.len()],
    };
    sigma
        .into_iter()
        .map(|s| s / std::f32::consts::PI)
        .collect()
}

/// Writes a computed bake: EXR + PNG pages and the glTF, atomically.
pub fn write(
    mut baked: Baked,
    input: &Path,
    out_dir: &Path,
    config: &BakeConfig,
    progress: &dyn Progress,
) -> Result<BakeReport> {
    let t = Instant::now();
    let stem = output_stem(input);
    let mut staging = Staging::new(out_dir, &protected_files(input, &baked.source))?;
    let mut page_files = relight::stage_pages(&mut staging, &stem, &baked.pages, config, input)?;
    let layer_files = relight::stage_layers(&mut staging, &stem, &baked.layers, config, input)?;
    if let Some((pages, ..)) = &baked.directional {
        for (k, files) in page_files.iter_mut().enumerate() {
            let names = lightmap::directional::NAMES.map(|c| format!("{stem}_lightmap{k}_{c}.exr"));
            for (name, pages) in names.iter().zip(pages) {
                staging.write(
                    name,
                    &output::write_exr(&pages.pages[k], config.output.float, input)?,
                )?;
            }
            files.directional = Some(names);
        }
    }
    // Beside the pages, referenced by nothing in the glTF.
    for (k, page) in baked
        .error_map
        .iter()
        .flat_map(|m| m.pages.iter().enumerate())
    {
        staging.write(
            &format!("{stem}_lightmap{k}_error.exr"),
            &output::write_exr(page, false, input)?,
        )?;
    }
    let (scene, atlas) = match &baked.written {
        Some(written) => (&written.0, &written.1),
        None => (&baked.scene, &baked.atlas),
    };
    output::write_gltf(
        scene,
        &baked.source,
        atlas,
        &page_files,
        &mut staging,
        &stem,
    )?;
    if let Some(probes) = &baked.probes {
        stage_probes(probes, &baked.source, &mut staging, input, &stem)?;
    }
    if !layer_files.is_empty() || config.output.keep_transport {
        keep_with_gltf(&baked, &mut staging, input, &stem, &layer_files)?;
    }
    check_aborted(progress)?;
    let files = commit(staging)?;
    timed(&mut baked.stages, "write", t);

    let lightmap_rays = lightmap_rays(baked.transport.rays, baked.plan.as_ref());
    Ok(BakeReport {
        triangles: baked.scene.triangles.len(),
        texels: baked.texels.len(),
        pages: baked.pages.pages.len(),
        // Every ray cast, the pilot bakes that are not part of the result and the directional
        // gather included.
        rays: lightmap_rays
            + baked.directional.as_ref().map_or(0, |d| d.2)
            + baked.probes.as_ref().map_or(0, |p| p.rays),
        iterations: baked.solution.history.len(),
        residual: baked.solution.residual(),
        converged: baked.solution.converged,
        validity: baked.validity,
        plan: baked.plan,
        seams: baked.seams,
        junctions: baked.junctions,
        sharing: atlas::ShareReport::of(&baked.atlas),
        directional: baked.directional.map(|(_, a, _)| a),
        probes: (baked.probes.as_ref())
            .zip(config.output.probes.as_ref())
            .map(|(p, params)| ProbeCount::of(p, params, lightmap_rays)),
        stages: baked.stages,
        files,
        incremental: None,
    })
}

/// Stages `<stem>_probes.json` and, for probes on a grid, `<stem>_probes.ktx2` (Bevy's
/// irradiance volume) and names them in the staged glTF's root
/// `extras.light_probes = {"uri", "count", "irradiance_volume"}`.
fn stage_probes(
    probes: &crate::probes::Probes,
    source: &scene::Source,
    staging: &mut Staging,
    input: &Path,
    stem: &str,
) -> Result<()> {
    use crate::probes::volume;
    let uri = format!("{stem}_probes.json");
    staging.write(&uri, &crate::probes::file::to_json(probes)?)?;
    let mut extras = serde_json::json!({ "uri": uri, "count": probes.len() });
    // Bevy's irradiance volume of the same grid, with the Transform that places it (probes
    // placed one by one have no grid to make a 3D texture of).
    if let Some(grid) = &probes.grid {
        let volume_uri = format!("{stem}_probes.ktx2");
        staging.write(&volume_uri, &volume::to_ktx2(probes)?)?;
        let v = volume::placement(grid);
        extras[volume::EXTRAS_KEY] = serde_json::json!({
            "uri": volume_uri,
            "translation": v.translation.to_array(),
            "rotation": v.rotation,
            "scale": v.scale.to_array(),
            "resolution": v.resolution,
        });
    }
    let name = match source.is_glb {
        true => format!("{stem}.glb"),
        false => format!("{stem}.gltf"),
    };
    let gltf = staging.read(&name)?;
    let edited = output::gltf_edit::edit_gltf(&gltf, input, |json| {
        output::gltf_edit::set_root_extra(json, crate::probes::file::EXTRAS_KEY, extras.clone())
    })?;
    staging.replace(&name, &edited)
}

/// Names the layers' pages in the staged glTF's extras, and with `keep_transport` stages
/// `<stem>.transport` for that glTF as finally staged ([`kept`]).
fn keep_with_gltf(
    baked: &Baked,
    staging: &mut Staging,
    input: &Path,
    stem: &str,
    layer_files: &[(relight::Layer, Vec<PageFiles>)],
) -> Result<()> {
    let name = match baked.source.is_glb {
        true => format!("{stem}.glb"),
        false => format!("{stem}.gltf"),
    };
    let config = &baked.config;
    let mut settings = kept::Settings::new(&baked.scene, config, &name);
    settings.probe_budget = baked.probes.as_ref().map(|p| p.budget);
    if config.output.keep_transport {
        // What `bake --since` compares an edited input with.
        let mut record = incremental::input_record(input)?;
        // Recorded only where it is not the input's own (so an unmoved re-bake writes the
        // same file).
        record.layout = (baked.layout_nodes.clone()).filter(|nodes| *nodes != record.nodes);
        settings.input = Some(record);
    }
    if !layer_files.is_empty() {
        let gltf = staging.read(&name)?;
        let edited = output::gltf_edit::edit_gltf(&gltf, input, |json| {
            relight::add_layer_extras(json, &settings, layer_files)
        })?;
        staging.replace(&name, &edited)?;
    }
    if !config.output.keep_transport {
        return Ok(());
    }
    let mut files = vec![staging.read(&name)?];
    if !baked.source.is_glb
        && let Ok(bin) = staging.read(&format!("{stem}.bin"))
    {
        files.push(bin);
    }
    let files: Vec<&[u8]> = files.iter().map(Vec::as_slice).collect();
    let seams = match config.output.seams {
        true => lightmap::seams::find(&baked.scene, &baked.atlas, &Default::default()),
        false => Default::default(),
    };
    let material = kept::texel_materials(&baked.scene, &baked.texels);
    let bytes = kept::encode(
        &settings,
        &files,
        &baked.texels,
        &material,
        &baked.transport,
        &seams,
        &baked.atlas,
    )?;
    staging.write(&format!("{stem}.transport"), &bytes)
}

/// The output files' stem: the input's.
fn output_stem(input: &Path) -> String {
    input
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("scene")
        .to_string()
}

/// Moves the staged files into place; returns them, the glTF (or .glb) first, then pages in
/// order.
fn commit(staging: Staging) -> Result<Vec<PathBuf>> {
    let mut files = staging.commit()?;
    files.sort_by_key(|p| !matches!(p.extension().and_then(|e| e.to_str()), Some("gltf" | "glb")));
    Ok(files)
}

/// Fails early (before any work) when the output would replace the input file itself.
fn refuse_overwriting_input(input: &Path, out_dir: &Path) -> Result<()> {
    let (Ok(input_dir), Ok(out)) = (
        input.parent().unwrap_or(Path::new(".")).canonicalize(),
        out_dir.canonicalize(),
    ) else {
        return Ok(()); // a missing input is reported by the loader; a missing out_dir is created
    };
    if input_dir == out {
        let ext = input.extension().and_then(|e| e.to_str()).unwrap_or("");
        if ext == "gltf" || ext == "glb" {
            return Err(Error::Option(format!(
                "the output directory {} holds the input {}: baking there would overwrite it; choose another -o",
                out.display(),
                input.display()
            )));
        }
    }
    Ok(())
}

fn check_aborted(progress: &dyn Progress) -> Result<()> {
    if progress.aborted() {
        Err(Error::Aborted)
    } else {
        Ok(())
    }
}

/// The input glTF and every external file it references: the output must never overwrite them.
fn protected_files(input: &Path, source: &scene::Source) -> Vec<PathBuf> {
    let mut files = vec![input.to_path_buf()];
    let base = input.parent().unwrap_or(Path::new("."));
    for key in ["buffers", "images"] {
        if let Some(items) = source.json.get(key).and_then(|v| v.as_array()) {
            for item in items {
                if let Some(uri) = item.get("uri").and_then(|u| u.as_str())
                    && !uri.starts_with("data:")
                {
                    files.push(base.join(uri));
                }
            }
        }
    }
    files
}
