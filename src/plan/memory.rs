//! The estimate of a bake's peak memory, in one place: the bytes of each part a bake holds at
//! its peak ([`memory_estimate`] of [`MemoryInputs`]), and from a scene's sizes the peaks of
//! the bakes a configuration may run (`Sizes`: before the atlas or with the texels counted,
//! per process of a distributed bake, pilot runs held). The planner chooses the rows' storage
//! and may switch the solver from these estimates (`plan::choose_row_storage`,
//! `plan::fit_memory`); `bake::memory` checks them against the bake's limit.

use super::{PILOT_RAYS, surface_area};
use crate::config::{BakeConfig, FormFactors, RowSolver, Technique};
use crate::scene::{Scene, Source};
use crate::texels::Texels;

/// The sizes a bake's peak memory depends on ([`memory_estimate`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MemoryInputs {
    /// Bytes of the input files (the JSON and buffers stay loaded until the output is written).
    pub input_bytes: f64,
    /// Vertices of the loaded scene.
    pub vertices: f64,
    /// Triangles of the loaded scene.
    pub triangles: f64,
    /// Texels (radiosity patches).
    pub texels: f64,
    /// Texels of all pages, covered or not (width × height summed).
    pub page_texels: f64,
    /// Row entries held while the last rows are built (the pilot runs a final bake reuses).
    pub held_entries: f64,
    /// Row entries of the rows being built at the peak.
    pub built_entries: f64,
    /// Finished transports held besides the one being built (pilot runs): their per-texel
    /// vectors count too.
    pub held_runs: f64,
    /// Which solver iterates the rows: Southwell keeps a transposed copy of them.
    pub technique: Technique,
    /// Monte Carlo rows built as ray counts ([`crate::config::TransportParams::count_rows`]).
    pub count_rows: bool,
}

/// Estimated peak memory of a bake by part, in bytes ([`memory_estimate`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MemoryEstimate {
    /// The process, the input files and the loaded scene.
    pub scene: f64,
    /// The tracer's BVH and triangles.
    pub bvh: f64,
    /// The atlas stage's working set (xatlas' charting and packing), kept by the allocator.
    pub atlas: f64,
    /// Texels, their lightmap values and per-texel vectors of transport and solver.
    pub texels: f64,
    /// Lightmap pages (index, values, encoded files).
    pub pages: f64,
    /// Stored form-factor rows.
    pub rows: f64,
}

impl MemoryEstimate {
    /// The whole peak: the parts summed.
    pub fn total(&self) -> f64 {
        self.scene + self.bvh + self.atlas + self.texels + self.pages + self.rows
    }

    /// "1.2 GiB (rows 1.0 GiB, texels …)", for messages.
    pub(crate) fn describe(&self) -> String {
        format!(
            "{} (rows {}, texels {}, pages {}, BVH {}, atlas {}, scene {})",
            format_bytes(self.total()),
            format_bytes(self.rows),
            format_bytes(self.texels),
            format_bytes(self.pages),
            format_bytes(self.bvh),
            format_bytes(self.atlas),
            format_bytes(self.scene)
        )
    }
}

/// Bytes in binary units, three significant digits ("512 MiB", "1.25 GiB").
pub(crate) fn format_bytes(bytes: f64) -> String {
    let units = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut value = bytes;
    let mut unit = 0;
    while value >= 1024.0 && unit + 1 < units.len() {
        value /= 1024.0;
        unit += 1;
    }
    let digits = if value >= 100.0 || unit == 0 {
        0
    } else if value >= 10.0 {
        1
    } else {
        2
    };
    format!("{value:.digits$} {}", units[unit])
}

/// Bytes of one stored f32 row entry: the source texel (u32) and its form factor (f32).
pub(crate) const ROW_ENTRY_BYTES: f64 = 8.0;
/// Bytes per gathering ray of Monte Carlo rows stored as ray counts ([`crate::transport::Rows`]),
/// their headers included, besides `TEXEL_BYTES`' per-row part (a row's start, 2.25 bytes):
/// measured 0.67 (Cornell box, K = 1024), 0.71 and 0.82 (64k-triangle furnished interior,
/// K = 256 and 64), 1.12 (two rooms, K = 1024, whose rays land farther apart;
/// `examples/dev/row_storage.rs`).
pub const COUNT_BYTES_PER_RAY: f64 = 1.0;
/// Rows are built in chunks and then concatenated: both copies exist for a moment, and a
/// chunk's vectors grow by doubling.
const ROW_BUILD_FACTOR: f64 = 2.5;
/// Per texel: `Texels` (96 bytes of positions, normals, area, albedo, emission, page, xy,
/// triangle, footprint, jitter), a transport's escape, direct light and row start (20; rows as
/// ray counts keep `K` in their bytes, with a 2.25-byte start),
/// the solver's iterates and solution (4 RGB vectors, 48), the lightmap and the denoiser's
/// copies (36): 200, rounded up.
const TEXEL_BYTES: f64 = 210.0;
/// Per texel of a finished transport and solution that is kept (a pilot run).
const HELD_RUN_TEXEL_BYTES: f64 = 32.0;
/// Per page texel: the texel index (4), the page's values and validity (13), dilation's copy
/// (12), the EXR and PNG encodings (up to 16).
const PAGE_TEXEL_BYTES: f64 = 48.0;
/// Per vertex: position, normal, two UV sets, and the atlas's copy with its remap.
const VERTEX_BYTES: f64 = 64.0;
/// Per triangle: indices and instance (the scene), per-triangle texel lookups (32), the
/// atlas's charts.
const TRIANGLE_BYTES: f64 = 96.0;
/// Per triangle of the tracer: the CWBVH nodes and the precomputed triangles in BVH order.
const BVH_TRIANGLE_BYTES: f64 = 128.0;
/// Per triangle of the atlas stage: xatlas' charting and packing working set. Measured (RSS
/// sampled every 50 ms, `furnished_interior.glb`, 71 624 triangles): +104 MiB at draft (48k
/// texels) and +112 MiB at medium (155k texels) in the stage's last seconds, whatever the
/// texels, from ~90 MiB; the resident memory stays up afterwards (glibc keeps the freed heap,
/// one arena or many alike) and later stages reuse only part of it. With this figure the
/// estimate ÷ measured peak is 0.94 and 0.99 there, 0.81 and 0.77 on the Cornell box and two
/// rooms at high (the guide, `src/guide/performance.md`, "Memory").
const ATLAS_TRIANGLE_BYTES: f64 = 2560.0;
/// The input as read and as decoded (JSON tree, buffers).
const INPUT_FACTOR: f64 = 2.0;
/// The process itself: code, thread stacks, allocator.
const PROCESS_BYTES: f64 = 8.0 * 1024.0 * 1024.0;

/// Peak memory of a bake of `m`, before light transport starts: every part a bake holds at
/// once when its last rows are built (stages before are smaller: the atlas's and validity's
/// working sets are per chart and per texel). Checked against measured peaks in the guide
/// ("Memory").
pub fn memory_estimate(m: &MemoryInputs) -> MemoryEstimate {
    let transposed = matches!(
        m.technique,
        Technique::Stored {
            solver: RowSolver::Southwell,
            ..
        }
    );
    // Southwell's transpose holds f32 entries whatever the rows are stored as.
    let built = m.built_entries
        * (ROW_BUILD_FACTOR * row_entry_bytes(m.technique, m.count_rows)
            + if transposed { ROW_ENTRY_BYTES } else { 0.0 });
    MemoryEstimate {
        scene: PROCESS_BYTES
            + INPUT_FACTOR * m.input_bytes
            + VERTEX_BYTES * m.vertices
            + TRIANGLE_BYTES * m.triangles,
        bvh: BVH_TRIANGLE_BYTES * m.triangles,
        atlas: ATLAS_TRIANGLE_BYTES * m.triangles,
        texels: TEXEL_BYTES * m.texels + HELD_RUN_TEXEL_BYTES * m.held_runs * m.texels,
        pages: PAGE_TEXEL_BYTES * m.page_texels,
        // Held entries are pilot runs: Monte Carlo rows, built before the storage is chosen (f32).
        rows: ROW_ENTRY_BYTES * m.held_entries + built,
    }
}

/// Bytes per entry of [`entries_per_texel`]: Monte Carlo rows stored as ray counts
/// (`count_rows`; entries counted as rays), otherwise f32 form factors (the hierarchy's links
/// counted alike).
pub(crate) fn row_entry_bytes(technique: Technique, count_rows: bool) -> f64 {
    match technique {
        Technique::Stored {
            form_factors: FormFactors::MonteCarlo,
            ..
        } if count_rows => COUNT_BYTES_PER_RAY,
        _ => ROW_ENTRY_BYTES,
    }
}

/// Row entries per texel that `technique` stores at `gather_rays` (all pairs store up to one per
/// other texel; the hierarchy's links are counted like Monte Carlo rows; gather stores none).
pub(crate) fn entries_per_texel(technique: Technique, texels: f64, gather_rays: f64) -> f64 {
    match technique {
        Technique::Stored {
            form_factors: FormFactors::MonteCarlo,
            ..
        }
        | Technique::Hierarchical => gather_rays,
        Technique::Stored { .. } => (texels - 1.0).max(0.0),
        Technique::Gather => 0.0,
    }
}

/// The sizes of a scene and its texels, before rows and pilot runs are counted in.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Sizes {
    input_bytes: f64,
    vertices: f64,
    triangles: f64,
    pub(crate) texels: f64,
    page_texels: f64,
    /// Processes sharing the final bake's rows (1 on one machine).
    pub(crate) processes: f64,
}

/// Per texel of a distributed bake, on every process: the gathered vector of the first
/// exchange (direct light and sky fraction, 16 bytes) in the shares received, the gathered
/// copy and its split, with timely's serialised buffers; the sweeps' (12 bytes) are smaller.
const EXCHANGE_TEXEL_BYTES: f64 = 64.0;

impl Sizes {
    /// Before the atlas: texels from the surface area at the density, pages twice that
    /// (charts and gutters cover about half of a page).
    pub(crate) fn predicted(scene: &Scene, source: &Source, config: &BakeConfig) -> Sizes {
        let tpu = config.atlas.texels_per_unit as f64;
        let texels = surface_area(scene) * tpu * tpu;
        Sizes {
            texels,
            page_texels: 2.0 * texels,
            ..Sizes::loaded(scene, source)
        }
    }

    /// Once the texels exist.
    pub(crate) fn counted(scene: &Scene, source: &Source, texels: &Texels) -> Sizes {
        Sizes {
            texels: texels.len() as f64,
            page_texels: (texels.pages.iter())
                .map(|p| p.width as f64 * p.height as f64)
                .sum(),
            ..Sizes::loaded(scene, source)
        }
    }

    fn loaded(scene: &Scene, source: &Source) -> Sizes {
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
    pub(crate) fn per_process(self, processes: usize) -> Sizes {
        Sizes {
            processes: processes.max(1) as f64,
            ..self
        }
    }

    pub(crate) fn distributed(&self) -> bool {
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
        let mut estimate = memory_estimate(&MemoryInputs {
            input_bytes: self.input_bytes,
            vertices: self.vertices,
            triangles: self.triangles,
            texels: n,
            page_texels: self.page_texels,
            // Each process builds (and holds) the rows of its own texels only, the pilots' too.
            held_entries: held * held_rays * (n / self.processes),
            built_entries: entries_per_texel(technique, n, rays) * (n / self.processes),
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
    /// rays, its second pair's second run while the first pair and the other run are held
    /// (counted with the rows of the first pair's second run, though `choose_transport` drops
    /// them before the second pair: a conservative estimate, left as measured).
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
    pub(crate) fn least(&self, config: &BakeConfig) -> MemoryEstimate {
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

    /// The peak a bake of `config` is expected to reach for running bakes side by side
    /// (`bake::memory::expected_peak`; `limit`: the bake's).
    pub(crate) fn expected(&self, config: &BakeConfig, limit: f64) -> MemoryEstimate {
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

    /// Once the rays are chosen, the peaks of a final bake of `technique` at `rays` per texel
    /// (mean) with its rows stored as f32 and as ray counts and with the gather solver
    /// (`pilot`: gathering rays of each reused pilot run, and whether no further bake follows).
    /// Each is at least the pilot's peak: that is past, but the estimate is the bake's.
    pub(crate) fn final_peaks(
        &self,
        technique: Technique,
        rays: f64,
        pilot: Option<(u32, bool, usize)>,
    ) -> FinalPeaks {
        // The pilot runs' rows are dropped before a final bake builds its own
        // (`pilot::final_bake`); when they suffice, the last run's are the result's.
        let (held, held_rays, more) = match pilot {
            Some((k, enough, runs)) => {
                let held_rays = if enough { k as f64 / 2.0 } else { 0.0 };
                (runs as f64, held_rays, !enough)
            }
            None => (0.0, 0.0, true),
        };
        let rays = if more { rays } else { 0.0 };
        let pilot_peak = pilot.map(|(k, _, _)| self.pilot_peak(k > PILOT_RAYS));
        let with_pilot = |e: MemoryEstimate| pilot_peak.map_or(e, |p| larger(p, e));
        let stored_as =
            |counts| with_pilot(self.estimate_rows(technique, counts, rays, held, held_rays));
        FinalPeaks {
            f32_rows: stored_as(false),
            count_rows: stored_as(true),
            gather: with_pilot(self.estimate(Technique::Gather, rays, held, held_rays)),
        }
    }
}

/// A final bake's estimated peaks by how it holds its rows ([`Sizes::final_peaks`]).
pub(crate) struct FinalPeaks {
    pub(crate) f32_rows: MemoryEstimate,
    pub(crate) count_rows: MemoryEstimate,
    pub(crate) gather: MemoryEstimate,
}

impl FinalPeaks {
    /// With stored rows, as ray counts when `count_rows`.
    pub(crate) fn stored(&self, count_rows: bool) -> MemoryEstimate {
        if count_rows {
            self.count_rows
        } else {
            self.f32_rows
        }
    }
}

/// The one of `a` and `b` with the larger total.
fn larger(a: MemoryEstimate, b: MemoryEstimate) -> MemoryEstimate {
    if a.total() >= b.total() { a } else { b }
}
