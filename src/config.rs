//! Bake options. Every knob says what it trades; `BakeConfig::draft/medium/high` are
//! the named presets (tests iterate over all of them).

use glam::Vec3;

/// Where lightmap UVs come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum UvMode {
    /// Unwrap and pack new charts with xatlas (ignores any TEXCOORD_1 of the input).
    Unwrap,
    /// Reuse the input's TEXCOORD_1; a primitive without one, or with overlapping or
    /// out-of-range UVs, is an error.
    Existing,
    /// Reuse TEXCOORD_1 when every baked primitive has a valid one, else unwrap.
    Auto,
}

/// How a mesh placed by several nodes gets its lightmap UVs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Instancing {
    /// Each placement is unwrapped on its own and the output mesh is duplicated per node.
    #[default]
    Duplicate,
    /// The mesh is unwrapped once and written once; each node gets a rectangle of a page
    /// (`extras.lightmap.scale_offset` on the node, see `atlas::share`).
    Share,
}

/// Lightmap UV layout.
#[derive(Clone, Debug)]
pub struct AtlasParams {
    /// Unwrap, reuse the input's `TEXCOORD_1`, or choose.
    pub uv: UvMode,
    /// Texel density in texels per world unit (metre). Higher = sharper shadows, quadratically
    /// more texels, rays and memory.
    pub texels_per_unit: f32,
    /// A factor on `texels_per_unit` per scene instance (parallel to `Scene::instances`).
    /// Empty: one density everywhere. Unwrapped atlases only (reused `TEXCOORD_1` keeps its
    /// layout).
    pub(crate) instance_density: Vec<f32>,
    /// Adaptive density: a further factor per scene triangle (parallel to `Scene::triangles`),
    /// chosen by the automatic plan per density region from where the pilot's lookup error
    /// sits ([`crate::plan::density`]). Empty: 1 everywhere. Shared meshes
    /// (`--instancing share`) keep one layout and ignore it.
    pub triangle_density: Vec<f32>,
    /// Pages are at most this many texels on a side; more pages are made when charts do not fit.
    pub max_page_size: u32,
    /// Empty texels between charts (room for dilation and bilinear filtering). At least 1.
    pub padding: u32,
    /// Cut receivers where other surfaces meet them (`scene::junctions`), so no texel straddles
    /// a wall and lightmap charts end at every junction. Has no effect when the input's
    /// `TEXCOORD_1` is reused (its charts cannot change).
    pub split_junctions: bool,
    /// Cut receivers along the hard shadow outlines of punctual lights too
    /// (`scene::shadow_cuts`), so a renderer's filtering does not blur them over a texel. Part
    /// of the junction split: no effect without `split_junctions`.
    pub shadow_cuts: bool,
    /// Cut receivers along the outlines of near contacts too: surfaces facing them from less
    /// than a texel in front (a door's edge in its lining, a light's side in its recess;
    /// `scene::junctions`), so a slot's texels hold the slot's light, not the open surface's
    /// beside it; cut ends then snap at 1/16 texel instead of ¼. More charts and triangles. Part
    /// of the junction split: no effect without `split_junctions`. Off by default.
    pub near_contacts: bool,
    /// With near contacts, raise the texel density of slot faces (a surface facing another
    /// from a gap narrower than a texel) until a texel is no wider than the gap, up to ×16 and
    /// at most doubling the texels (`atlas::slots`): light in a slot falls over a length of the
    /// order of its gap, and a wider texel's lookup reads several times the light there. More
    /// texels on slot faces only. On by default; no effect without `near_contacts`.
    pub slot_faces: bool,
    /// Raise faces narrower than four texels within four of their widths (at most two texels)
    /// of an emitter (a
    /// light's border, a recess's band under a light) to four texels across, up to ×32 and at
    /// most doubling the texels (`atlas::slots`): light can change by its whole range across
    /// them, and one texel row reads its mean at both edges.
    /// Only the faces someone may see. On by default; part of the junction split: no effect
    /// without `split_junctions`.
    pub narrow_faces: bool,
    /// Meshes placed by several nodes: duplicated (each placement its own UVs) or shared (one
    /// unwrap, a page rectangle per node). Unwrapped atlases only.
    pub instancing: Instancing,
}

/// How the form factors of stored rows are computed (see the `transport` module of each).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FormFactors {
    /// Cosine-distributed gathering rays per texel (sparse rows, ≤ K entries). The default.
    MonteCarlo,
    /// Differential point-to-point kernel with one visibility ray per pair (all pairs: small
    /// scenes only; unbounded as r → 0 — kept as a baseline).
    Point,
    /// Lambert's point-to-polygon contour integral over the source texel, visibility from
    /// shadow rays to points on the source (all pairs: small scenes only).
    Polygon,
}

/// Iterative method for a system of stored rows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RowSolver {
    /// All texels updated from the previous sweep; parallel over rows.
    Jacobi,
    /// Texels updated in place in order; about twice the convergence per sweep, serial.
    GaussSeidel,
    /// Southwell progressive refinement: shoot the texel with the most unshot power.
    Southwell,
}

/// How light is transported between texels and how the resulting system is solved: only the
/// combinations that exist (the matrix-free gatherer re-casts Monte Carlo rays, the hierarchy
/// iterates its links with Jacobi sweeps).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Technique {
    /// Rows of form factors built once and stored, then iterated.
    Stored {
        /// How the rows' form factors are computed.
        form_factors: FormFactors,
        /// How the rows are iterated.
        solver: RowSolver,
    },
    /// Matrix-free Monte Carlo: no stored rows; gathering rays are cast again every bounce.
    Gather,
    /// Hierarchical radiosity with clustering: links between texel blocks refined where the
    /// transfer error is large, iterated by Jacobi sweeps.
    Hierarchical,
}

impl Technique {
    /// Monte Carlo rows and Jacobi: the default.
    pub const DEFAULT: Technique = Technique::stored(FormFactors::MonteCarlo, RowSolver::Jacobi);
    /// The names [`Technique::method`] gives, for command lines.
    pub const METHODS: [&'static str; 4] = ["montecarlo", "point", "polygon", "hierarchical"];
    /// The names [`Technique::solver`] gives, for command lines.
    pub const SOLVERS: [&'static str; 4] = ["jacobi", "gauss-seidel", "southwell", "gather"];

    /// Stored rows of `form_factors`, iterated by `solver` (every pair exists).
    pub const fn stored(form_factors: FormFactors, solver: RowSolver) -> Technique {
        Technique::Stored {
            form_factors,
            solver,
        }
    }

    /// The transport's name: `montecarlo`, `point`, `polygon` or `hierarchical`.
    pub fn method(self) -> &'static str {
        match self {
            Technique::Stored {
                form_factors: FormFactors::MonteCarlo,
                ..
            }
            | Technique::Gather => "montecarlo",
            Technique::Stored {
                form_factors: FormFactors::Point,
                ..
            } => "point",
            Technique::Stored {
                form_factors: FormFactors::Polygon,
                ..
            } => "polygon",
            Technique::Hierarchical => "hierarchical",
        }
    }

    /// The solver's name: `jacobi`, `gauss-seidel`, `southwell` or `gather`.
    pub fn solver(self) -> &'static str {
        match self {
            Technique::Stored {
                solver: RowSolver::Jacobi,
                ..
            }
            | Technique::Hierarchical => "jacobi",
            Technique::Stored {
                solver: RowSolver::GaussSeidel,
                ..
            } => "gauss-seidel",
            Technique::Stored {
                solver: RowSolver::Southwell,
                ..
            } => "southwell",
            Technique::Gather => "gather",
        }
    }

    /// The technique a method and a solver name together ([`Technique::METHODS`] ×
    /// [`Technique::SOLVERS`]); a pair that does not exist is an error that says why.
    pub fn from_names(method: &str, solver: &str) -> crate::error::Result<Technique> {
        use crate::error::Error::Option;
        let rows = match solver {
            "jacobi" => Some(RowSolver::Jacobi),
            "gauss-seidel" => Some(RowSolver::GaussSeidel),
            "southwell" => Some(RowSolver::Southwell),
            "gather" => None,
            _ => return Err(Option(format!("unknown solver {solver:?}"))),
        };
        let form_factors = match method {
            "montecarlo" => FormFactors::MonteCarlo,
            "point" => FormFactors::Point,
            "polygon" => FormFactors::Polygon,
            "hierarchical" if solver == "jacobi" => return Ok(Technique::Hierarchical),
            "hierarchical" => {
                return Err(Option(format!(
                    "the hierarchical method iterates its own links with Jacobi sweeps: \
                     the {solver} solver does not apply (leave --solver out)"
                )));
            }
            _ => return Err(Option(format!("unknown method {method:?}"))),
        };
        match (form_factors, rows) {
            (_, Some(solver)) => Ok(Technique::stored(form_factors, solver)),
            (FormFactors::MonteCarlo, None) => Ok(Technique::Gather),
            (_, None) => Err(Option(format!(
                "the gather solver re-casts Monte Carlo gathering rays every bounce: it does not \
                 apply to the {method} method (use --method montecarlo, or another solver)"
            ))),
        }
    }

    /// True for the noisy Monte Carlo estimates (stored rows or matrix-free): what the pilot
    /// measures and the denoiser smooths.
    pub fn is_monte_carlo(self) -> bool {
        self.method() == "montecarlo"
    }
}

impl std::fmt::Display for Technique {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.method(), self.solver())
    }
}

/// How light is transported between texels.
#[derive(Clone, Debug)]
pub struct TransportParams {
    /// Cosine-distributed gathering rays per texel for the texel-to-texel form factors.
    /// More rays = less noise in indirect light, linearly more time and row storage.
    pub gather_rays: u32,
    /// Shadow rays per texel towards emissive surfaces (area lights). More = softer, less noisy
    /// direct light from emitters.
    pub light_samples: u32,
    /// Uniform sky radiance (W/(sr·m²) per channel) for rays that leave the scene.
    pub sky: Vec3,
    /// Leave direct light out of the lightmap (indirect only), for engines that add it at runtime.
    pub indirect_only: bool,
    /// Base seed of the per-texel random streams; output depends on it, never on thread count.
    pub seed: u64,
    /// Move texel sample points out of geometry and fill texels buried in it from their
    /// neighbours (`texels::validity`; 16 probe rays per texel). Off only to measure leaks.
    pub validity: bool,
    /// Edge-aware denoising of the lightmap (`lightmap::denoise`). Applies to the Monte Carlo
    /// method only (stored rows or matrix-free); point, polygon and hierarchical form factors
    /// are deterministic, so their errors are not the white noise it removes and it is skipped.
    pub denoise: bool,
    /// Keep direct light split by light source as well (`Transport::direct_terms`; Monte Carlo
    /// rows only): what relighting and per-light layers scale. Costs 12 bytes per texel and
    /// source; set by the bake when `output.keep_transport` or `output.layers` asks.
    pub(crate) split_direct: bool,
    /// Keep the punctual lights' part of direct light per texel as well
    /// (`Transport::punctual`; Monte Carlo only): what the planner's punctual sample reads.
    /// Costs 12 bytes per texel; set for the pilot runs only.
    pub(crate) keep_punctual: bool,
    /// Measure each texel's per-ray variance after the solve (`bake::light::Lit::ray_variance`;
    /// stored Monte Carlo rows only): where the final bake's rays go. Set for the pilot runs
    /// only.
    pub(crate) ray_variance: bool,
    /// Store Monte Carlo rows as their exact ray counts (`transport::Rows::Counts`): the same
    /// output from 4.1–6.5× fewer row bytes, sweeps somewhat slower ([`crate::guide::baking`], "Memory"). Set
    /// by `row_storage` when forced, else by the memory check (`bake::memory::fit`) when f32
    /// rows would not fit the memory limit and counts would.
    pub count_rows: bool,
    /// How stored Monte Carlo rows are held (`--rows`): the planner's choice, or forced.
    pub row_storage: RowStorage,
}

/// How stored Monte Carlo rows are held in memory (`--rows`; [`TransportParams::count_rows`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum RowStorage {
    /// f32 weights, unless their estimated peak exceeds the memory limit and ray counts' does
    /// not (`plan::choose_row_storage`).
    #[default]
    Auto,
    /// f32 weights whatever the memory estimate (the bake may then switch to the gather
    /// solver or be refused).
    F32,
    /// Exact ray counts whatever the memory estimate.
    Counts,
}

impl RowStorage {
    /// The names `--rows` takes, in the order of the variants.
    pub(crate) const NAMES: [&'static str; 3] = ["auto", "f32", "counts"];

    /// The storage named `name` (one of [`RowStorage::NAMES`]).
    pub(crate) fn from_name(name: &str) -> Option<RowStorage> {
        match name {
            "auto" => Some(RowStorage::Auto),
            "f32" => Some(RowStorage::F32),
            "counts" => Some(RowStorage::Counts),
            _ => None,
        }
    }

    /// Whether Monte Carlo rows may be stored as counts: forced, or the planner's to choose.
    pub(crate) fn may_count(self) -> bool {
        self != RowStorage::F32
    }
}

/// How the radiosity system is iterated.
#[derive(Clone, Debug)]
pub struct SolveParams {
    /// Stop when the estimated relative error of the solution (the last update extrapolated
    /// over the remaining geometric series) falls below this.
    pub tolerance: f32,
    /// Stop after this many sweeps even if the tolerance is not reached (a warning says so).
    pub max_iterations: u32,
}

/// What is written.
#[derive(Clone, Debug)]
pub struct OutputParams {
    /// 32-bit float EXR pages instead of half floats.
    pub float: bool,
    /// Exposure (in stops) of the tone-mapped PNG previews.
    pub(crate) preview_exposure: f32,
    /// Also write each page as an 8-bit RGBM PNG (`output::rgbm`, range 8).
    pub rgbm: bool,
    /// Stitch UV seams after dilation (`lightmap::seams`): least squares on the texels along
    /// chart cuts through smooth surfaces, so both sides filter to the same value.
    pub seams: bool,
    /// Also write each page's per-texel error estimate (`plan::error_map`) as
    /// `<page>_error.exr`.
    pub error_map: bool,
    /// Also write directional pages (L1 spherical harmonics of the incident radiance,
    /// `lightmap::directional`) from a final gather with this many rays per texel.
    pub directional: Option<u32>,
    /// Also place and bake light probes (`crate::probes`) and write `<stem>_probes.json`.
    pub probes: Option<crate::probes::ProbeParams>,
    /// Also write `<stem>.transport`: the rows, direct light per source and the settings, from
    /// which `lightbake relight` re-solves with other light and material values without casting
    /// a ray (see the crate's `relight`). Monte Carlo rows only.
    pub keep_transport: bool,
    /// Write one set of pages per layer (`None`: no layers): each punctual light, the emissive
    /// materials together and the sky are a layer of their own unless a [`LayerGroup`] names
    /// them. The layers sum to the lightmap.
    pub layers: Option<Vec<LayerGroup>>,
}

/// Light sources baked into one layer: light names, emissive material names or `sky`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LayerGroup {
    /// The layer's name.
    pub name: String,
    /// Light names, emissive material names or `sky`.
    pub members: Vec<String>,
}

impl LayerGroup {
    /// A group as the command line and manifests give it: `NAME=MEMBER,MEMBER…`.
    pub fn parse(spec: &str) -> crate::error::Result<LayerGroup> {
        let bad =
            || crate::error::Error::Option(format!("layer {spec:?}: expected GROUP=NAME,NAME…"));
        let (name, members) = spec.split_once('=').ok_or_else(bad)?;
        let members: Vec<String> = (members.split(','))
            .map(|m| m.trim().to_string())
            .filter(|m| !m.is_empty())
            .collect();
        if name.trim().is_empty() || members.is_empty() {
            return Err(bad());
        }
        Ok(LayerGroup {
            name: name.trim().to_string(),
            members,
        })
    }
}

/// Which settings the user fixed; the automatic choice ([`crate::plan`]) leaves those alone.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Keep {
    /// The texel density.
    pub texels_per_unit: bool,
    /// The transport of [`Technique`] (its [`Technique::method`]).
    pub method: bool,
    /// The solver of [`Technique`] (its [`Technique::solver`]).
    pub solver: bool,
    /// Gathering rays per texel.
    pub rays: bool,
    /// Emitter light samples per texel.
    pub light_samples: bool,
    /// The solver's tolerance.
    pub tolerance: bool,
}

/// Ask for an automatic choice aiming at a relative RMSE of the lightmap.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AutoParams {
    /// Target relative RMSE against a converged reference (0.04 = 4%).
    pub target_error: f32,
    /// The settings the user fixed.
    pub keep: Keep,
}

impl AutoParams {
    /// The error each quality preset aims at: draft 8%, medium 4%, high 2%.
    pub fn for_preset(preset: &str) -> Option<f32> {
        match preset {
            "draft" => Some(0.08),
            "medium" => Some(0.04),
            "high" => Some(0.02),
            _ => None,
        }
    }
}

/// All options of a bake.
#[derive(Clone, Debug)]
pub struct BakeConfig {
    /// Lightmap UV layout.
    pub atlas: AtlasParams,
    /// Which transport and solver: see [`Technique`].
    pub technique: Technique,
    /// Rays, light samples, sky and the other transport settings.
    pub transport: TransportParams,
    /// Tolerance and iteration cap of the solver.
    pub solve: SolveParams,
    /// What is written and how.
    pub output: OutputParams,
    /// Choose density, method, rays and tolerance from the scene for a target error
    /// ([`crate::plan`]); `None` uses the settings above as they are.
    pub auto: Option<AutoParams>,
    /// Bytes the bake may use at its peak ([`crate::plan::memory_estimate`]); `None`: the
    /// memory the machine has available when the bake starts.
    pub max_memory: Option<u64>,
}

impl BakeConfig {
    const fn with(
        texels_per_unit: f32,
        gather_rays: u32,
        light_samples: u32,
        tolerance: f32,
    ) -> Self {
        BakeConfig {
            atlas: AtlasParams {
                uv: UvMode::Auto,
                texels_per_unit,
                instance_density: Vec::new(),
                triangle_density: Vec::new(),
                max_page_size: 1024,
                padding: 2,
                split_junctions: true,
                shadow_cuts: true,
                near_contacts: false,
                slot_faces: true,
                narrow_faces: true,
                instancing: Instancing::Duplicate,
            },
            technique: Technique::DEFAULT,
            transport: TransportParams {
                gather_rays,
                light_samples,
                sky: Vec3::ZERO,
                indirect_only: false,
                seed: 0,
                validity: true,
                denoise: true,
                split_direct: false,
                keep_punctual: false,
                ray_variance: false,
                count_rows: false,
                row_storage: RowStorage::Auto,
            },
            solve: SolveParams {
                tolerance,
                max_iterations: 10_000,
            },
            output: OutputParams {
                float: false,
                preview_exposure: 0.0,
                rgbm: false,
                seams: true,
                error_map: false,
                keep_transport: false,
                layers: None,
                directional: None,
                probes: None,
            },
            auto: None,
            max_memory: None,
        }
    }
    /// Fast look at the lighting: coarse texels, few rays.
    pub const fn draft() -> Self {
        Self::with(8.0, 64, 16, 1e-3)
    }
    /// The default: good for most asset builds.
    pub const fn medium() -> Self {
        Self::with(16.0, 256, 64, 1e-4)
    }
    /// Final quality: dense texels, many rays, tight tolerance.
    pub const fn high() -> Self {
        Self::with(32.0, 1024, 256, 1e-5)
    }
    /// All presets, for tests and benchmarks.
    pub const PRESETS: [(&'static str, BakeConfig); 3] = [
        ("draft", Self::draft()),
        ("medium", Self::medium()),
        ("high", Self::high()),
    ];

    /// Checks option ranges before any work is done.
    pub fn validate(&self) -> crate::error::Result<()> {
        use crate::error::Error::Option;
        let a = &self.atlas;
        if !(a.texels_per_unit.is_finite() && a.texels_per_unit > 0.0) {
            return Err(Option(format!(
                "texels per unit must be a positive number, got {}",
                a.texels_per_unit
            )));
        }
        if a.texels_per_unit > 100_000.0 {
            return Err(Option(format!(
                "texels per unit {} is absurdly high (max 100000)",
                a.texels_per_unit
            )));
        }
        if !(16..=16384).contains(&a.max_page_size) {
            return Err(Option(format!(
                "max page size must be within 16..=16384, got {}",
                a.max_page_size
            )));
        }
        if a.padding == 0 || a.padding > 64 {
            return Err(Option(format!(
                "padding must be within 1..=64 texels, got {}",
                a.padding
            )));
        }
        let t = &self.transport;
        if t.gather_rays == 0 || t.gather_rays > 1 << 20 {
            return Err(Option(format!(
                "gather rays must be within 1..=1048576, got {}",
                t.gather_rays
            )));
        }
        if let Some(rays) = self.output.directional
            && (rays == 0 || rays > 1 << 20)
        {
            return Err(Option(format!(
                "directional rays must be within 1..=1048576, got {rays}"
            )));
        }
        if let Some(p) = &self.output.probes
            && (p.budget.is_some_and(|b| b == 0 || b > 1 << 24) || p.rays == 0 || p.rays > 1 << 20)
        {
            return Err(Option(format!(
                "probes must be within 1..=16777216 and probe rays within 1..=1048576, got {} and {}",
                p.budget
                    .map_or("a budget following the bake".into(), |b| b.to_string()),
                p.rays
            )));
        }
        if t.light_samples > 1 << 20 {
            return Err(Option(format!(
                "light samples must be at most 1048576, got {}",
                t.light_samples
            )));
        }
        if !(t.sky.is_finite() && t.sky.min_element() >= 0.0) {
            return Err(Option(format!(
                "sky radiance must be finite and non-negative, got {}",
                t.sky
            )));
        }
        let o = &self.output;
        let stored_monte_carlo = matches!(
            self.technique,
            Technique::Stored {
                form_factors: FormFactors::MonteCarlo,
                ..
            }
        );
        if (o.keep_transport || o.layers.is_some()) && !stored_monte_carlo {
            return Err(Option(format!(
                "keeping the transport and per-light layers need stored Monte Carlo rows (direct light split by light), but this bake uses {}: use --method montecarlo and a stored-row solver (jacobi, gauss-seidel, southwell)",
                self.technique
            )));
        }
        let s = &self.solve;
        if !(s.tolerance.is_finite() && s.tolerance > 0.0 && s.tolerance < 1.0) {
            return Err(Option(format!(
                "tolerance must be within (0, 1), got {}",
                s.tolerance
            )));
        }
        if s.max_iterations == 0 {
            return Err(Option("max iterations must be at least 1".into()));
        }
        if let Some(auto) = &self.auto
            && !(auto.target_error.is_finite()
                && auto.target_error > 0.0
                && auto.target_error < 1.0)
        {
            return Err(Option(format!(
                "target error must be within (0, 1), e.g. 0.02 for 2%, got {}",
                auto.target_error
            )));
        }
        if !self.output.preview_exposure.is_finite() {
            return Err(Option("preview exposure must be finite".into()));
        }
        Ok(())
    }
}

impl Default for BakeConfig {
    fn default() -> Self {
        Self::medium()
    }
}
