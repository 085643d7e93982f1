//! The memory check: a bake's estimated peak ([`plan::memory_estimate`]) against its limit
//! (`BakeConfig::max_memory`, or the memory the machine has available), before any heavy work:
//! before the atlas (texels predicted from the surface area), before light transport (texels
//! counted) and once the automatic choice has chosen the rays (where it may switch to the
//! matrix-free gather solver). A distributed bake's estimate is per process: its share of the
//! final rows, and whole what every process holds (scene, BVH, texels, pilot runs, the
//! radiosity vectors and the exchange's buffers).

use std::path::Path;

use crate::config::{BakeConfig, Technique};
use crate::plan::{self, MemoryEstimate, MemoryInputs, PILOT_RAYS, Plan, format_bytes};
use crate::texels::Texels;
use crate::{Error, Progress, Result, scene};

/// The memory a bake may use: `config.max_memory`, or what the machine has available now
/// (sysinfo; unlimited where it cannot tell).
pub fn limit(config: &BakeConfig) -> u64 {
    config.max_memory.unwrap_or_else(|| {
        let available = sysinfo::System::new().ok().map(|mut system| {
            system.refresh_memory();
            system.available_memory()
        });
        match available {
            Some(bytes) if bytes > 0 => bytes,
            _ => u64::MAX,
        }
    })
}

/// The sizes of a scene and its texels, before rows and pilot runs are counted in.
#[derive(Clone, Copy, Debug)]
pub struct Sizes {
    input_bytes: f64,
    vertices: f64,
    triangles: f64,
    texels: f64,
    page_texels: f64,
    /// Processes sharing the final bake's rows (1 on one machine).
    processes: f64,
}

/// Per texel of a distributed bake, on every process: the gathered vector of the first
/// exchange (direct light and sky fraction, 16 bytes) in the shares received, the gathered
/// copy and its split, with timely's serialised buffers; the sweeps' (12 bytes) are smaller.
const EXCHANGE_TEXEL_BYTES: f64 = 64.0;

impl Sizes {
    /// Before the atlas: texels from the surface area at the density, pages twice that
    /// (charts and gutters cover about half of a page).
    pub fn predicted(scene: &scene::Scene, source: &scene::Source, config: &BakeConfig) -> Sizes {
        let tpu = config.atlas.texels_per_unit as f64;
        let texels = plan::surface_area(scene) * tpu * tpu;
        Sizes {
            texels,
            page_texels: 2.0 * texels,
            ..Sizes::loaded(scene, source)
        }
    }

    /// Once the texels exist.
    pub fn counted(scene: &scene::Scene, source: &scene::Source, texels: &Texels) -> Sizes {
        Sizes {
            texels: texels.len() as f64,
            page_texels: (texels.pages.iter())
                .map(|p| p.width as f64 * p.height as f64)
                .sum(),
            ..Sizes::loaded(scene, source)
        }
    }

    fn loaded(scene: &scene::Scene, source: &scene::Source) -> Sizes {
        let json = source.json.to_string().len();
        let buffers: usize = source.buffers.iter().map(Vec::len).sum();
        Sizes {
            input_bytes: (json + buffers) as f64,
            vertices: scene.positions.len() as f64,
            triangles: scene.triangles.len() as f64,
            texels: 0.0,
            page_texels: 0.0,
            processes: 1.0,
        }
    }

    /// The sizes as one of `processes` processes of a distributed bake sees them.
    pub fn per_process(self, processes: usize) -> Sizes {
        Sizes {
            processes: processes.max(1) as f64,
            ..self
        }
    }

    fn distributed(&self) -> bool {
        self.processes > 1.0
    }

    /// The peak of a bake with `technique` at `rays` per texel (mean), holding `held` pilot
    /// runs of `held_rays` each while it builds its rows.
    fn estimate(
        &self,
        technique: Technique,
        rays: f64,
        held: f64,
        held_rays: f64,
    ) -> MemoryEstimate {
        self.estimate_rows(technique, false, rays, held, held_rays)
    }

    /// [`Sizes::estimate`] with Monte Carlo rows stored as ray counts when `count_rows`.
    fn estimate_rows(
        &self,
        technique: Technique,
        count_rows: bool,
        rays: f64,
        held: f64,
        held_rays: f64,
    ) -> MemoryEstimate {
        let n = self.texels;
        let mut estimate = plan::memory_estimate(&MemoryInputs {
            input_bytes: self.input_bytes,
            vertices: self.vertices,
            triangles: self.triangles,
            texels: n,
            page_texels: self.page_texels,
            held_entries: held * held_rays * n,
            // Each process builds the rows of its own texels only.
            built_entries: plan::entries_per_texel(technique, n, rays) * (n / self.processes),
            held_runs: held,
            technique,
            count_rows,
        });
        if self.distributed() {
            estimate.texels += EXCHANGE_TEXEL_BYTES * n;
        }
        estimate
    }

    /// The pilot's peak: its second run built while the first is held (its solution; a pilot
    /// run's rows go once it is solved, `PilotRuns::bake`), or with a `second` pilot at 4× the
    /// rays, its second pair's second run while the first pair (the rows of its second run)
    /// and the other run are held.
    fn pilot_peak(&self, second: bool) -> MemoryEstimate {
        let k = PILOT_RAYS as f64;
        // Every process of a distributed bake runs the pilots whole, before any exchange.
        let whole = Sizes {
            processes: 1.0,
            ..*self
        };
        match second {
            false => whole.estimate(Technique::DEFAULT, k, 1.0, 0.0),
            true => whole.estimate(Technique::DEFAULT, 4.0 * k, 3.0, k / 3.0),
        }
    }

    /// The least a bake of `config` can need: with the automatic choice of rays, its pilot
    /// (the first pair held while the second is built, the worst case) and a final bake with
    /// the gather solver when the solver may switch; otherwise the configured bake (Monte Carlo
    /// rows as ray counts, the smaller storage `fit` may choose, unless `--rows f32`).
    fn least(&self, config: &BakeConfig) -> MemoryEstimate {
        let k = PILOT_RAYS as f64;
        let may_count = config.transport.row_storage.may_count();
        let configured = self.estimate_rows(
            config.technique,
            may_count,
            config.transport.gather_rays as f64,
            0.0,
            0.0,
        );
        let Some(auto) = config.auto else {
            return configured;
        };
        // The automatic choice makes the method Monte Carlo unless the user fixed it.
        let monte_carlo = config.technique.is_monte_carlo() || !auto.keep.method;
        let pilot = !auto.keep.rays && monte_carlo;
        let worst_pilot = self.pilot_peak(true);
        let last = if monte_carlo && !auto.keep.solver {
            Technique::Gather
        } else {
            config.technique
        };
        let rays = config.transport.gather_rays as f64;
        match pilot {
            true => larger(
                worst_pilot,
                self.estimate_rows(last, may_count, rays, 2.0, 4.0 * k),
            ),
            false => self.estimate_rows(last, may_count, rays, 0.0, 0.0),
        }
    }
}

/// The peak a bake of `input` with `config` is expected to reach, in bytes, for running bakes
/// side by side (`build`): texels predicted from the surface area at the automatic density, a
/// pilot pair held while the final rows are built at the configured rays (the automatic choice
/// may choose others), the gather solver's peak where those rows would not fit the bake's limit
/// and it may switch; never above that limit (a bake that would exceed it is refused).
pub fn expected_peak(input: &Path, config: &BakeConfig) -> Result<u64> {
    let (scene, source) = scene::load(input)?;
    let mut config = config.clone();
    if let Some(auto) = config.auto {
        plan::choose_density(&scene, &mut config, &mut Plan::default(), &auto.keep);
    }
    let limit = limit(&config);
    let sizes = Sizes::predicted(&scene, &source, &config);
    let expected = sizes.expected(&config, limit as f64).total();
    Ok((expected.ceil() as u64).min(limit))
}

impl Sizes {
    /// See [`expected_peak`].
    fn expected(&self, config: &BakeConfig, limit: f64) -> MemoryEstimate {
        let rays = config.transport.gather_rays as f64;
        // Forced counts (`--rows counts`) are known here; the planner's choice is not yet.
        let counts = config.transport.count_rows;
        let Some(auto) = config.auto else {
            return self.estimate_rows(config.technique, counts, rays, 0.0, 0.0);
        };
        // The automatic choice makes the method Monte Carlo unless the user fixed it.
        let technique = match auto.keep.method || config.technique.is_monte_carlo() {
            true => config.technique,
            false => Technique::DEFAULT,
        };
        let monte_carlo = technique.is_monte_carlo();
        let pilot = !auto.keep.rays && monte_carlo;
        // A pilot pair's solutions are held while the final rows are built; its rows are not.
        let (held, held_rays) = if pilot { (2.0, 0.0) } else { (0.0, 0.0) };
        let mut last = self.estimate_rows(technique, counts, rays, held, held_rays);
        if last.total() > limit && monte_carlo && !auto.keep.solver {
            last = self.estimate(Technique::Gather, rays, held, held_rays);
        }
        match pilot {
            true => larger(self.pilot_peak(false), last),
            false => last,
        }
    }
}

fn larger(a: MemoryEstimate, b: MemoryEstimate) -> MemoryEstimate {
    if a.total() >= b.total() { a } else { b }
}

/// Refuses a bake of `sizes` that cannot fit in `limit` whatever the automatic choice does.
pub fn check(input: &Path, sizes: &Sizes, config: &BakeConfig, limit: u64) -> Result<()> {
    let least = sizes.least(config);
    refuse_above(input, sizes, &least, limit, config)
}

/// Once the rays are chosen (`pilot`: gathering rays of each reused pilot run, and whether
/// no further bake follows; the plan's per-texel rays count when it has them): switches the automatic choice to the gather solver when the stored
/// rows do not fit and it does (with a warning), and refuses what still does not fit.
pub fn fit(
    input: &Path,
    sizes: &Sizes,
    config: &mut BakeConfig,
    plan: Option<&mut Plan>,
    pilot: Option<(u32, bool)>,
    limit: u64,
    progress: &dyn Progress,
) -> Result<()> {
    // The pilot pair's rows are dropped before a final bake builds its own
    // (`pilot::final_bake`); when they suffice, they are the result's.
    let (held, held_rays, more) = match pilot {
        Some((k, enough)) => (2.0, if enough { k as f64 / 2.0 } else { 0.0 }, !enough),
        None => (0.0, 0.0, true),
    };
    let texel_rays = plan.as_ref().and_then(|p| p.texel_rays.as_ref());
    let rays = match texel_rays {
        Some(r) if !r.0.is_empty() => r.0.iter().map(|&k| k as f64).sum::<f64>() / r.0.len() as f64,
        _ => config.transport.gather_rays as f64,
    };
    let rays = if more { rays } else { 0.0 };
    // The pilot's own peak is past, but it counts: the estimate is the bake's.
    let pilot_peak = pilot.map(|(k, _)| sizes.pilot_peak(k > PILOT_RAYS));
    let with_pilot = |e: MemoryEstimate| pilot_peak.map_or(e, |p| larger(p, e));
    let technique = config.technique;
    let stored_as =
        |counts| with_pilot(sizes.estimate_rows(technique, counts, rays, held, held_rays));
    let (f32_rows, count_rows) = (stored_as(false), stored_as(true));
    let gather = with_pilot(sizes.estimate(Technique::Gather, rays, held, held_rays));
    let mut plan = plan;
    if let (Some(plan), true) = (plan.as_deref_mut(), sizes.distributed()) {
        plan.reasons.push(format!(
            "memory: per process of {}: its share of the final rows, the rest whole (scene, \
             BVH, texels, pilot runs, radiosity vectors, exchange buffers)",
            sizes.processes
        ));
    }
    let storage =
        plan::choose_row_storage(&f32_rows, &count_rows, limit as f64, sizes.texels, config);
    if let Some(plan) = plan.as_deref_mut() {
        plan.reasons.extend(storage);
    }
    let stored = stored_as(config.transport.count_rows);
    if let (Some(plan), Some(auto)) = (plan, config.auto)
        && let Some(message) =
            plan::fit_memory(&stored, &gather, limit as f64, config, plan, &auto.keep)
    {
        progress.warn(&format!("{}: {message}", input.display()));
    }
    let chosen = if config.technique == Technique::Gather {
        gather
    } else {
        stored
    };
    refuse_above(input, sizes, &chosen, limit, config)
}

fn refuse_above(
    input: &Path,
    sizes: &Sizes,
    estimate: &MemoryEstimate,
    limit: u64,
    config: &BakeConfig,
) -> Result<()> {
    if estimate.total() <= limit as f64 {
        return Ok(());
    }
    let per_process = match sizes.distributed() {
        true => format!(" per process of {}", sizes.processes),
        false => String::new(),
    };
    let hint = if config.technique.is_monte_carlo() && config.technique != Technique::Gather {
        "lower --texels-per-unit or --rays, use --solver gather, or raise --max-memory"
    } else {
        "lower --texels-per-unit or --rays, or raise --max-memory"
    };
    Err(Error::Memory {
        path: input.to_path_buf(),
        message: format!(
            "the bake would need about {}{per_process} at its peak, above the memory limit \
             {} ({hint})",
            estimate.describe(),
            format_bytes(limit as f64)
        ),
    })
}
