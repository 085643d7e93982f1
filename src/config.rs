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

/// Lightmap UV layout.
#[derive(Clone, Debug)]
pub struct AtlasParams {
    pub uv: UvMode,
    /// Texel density in texels per world unit (metre). Higher = sharper shadows, quadratically
    /// more texels, rays and memory.
    pub texels_per_unit: f32,
    /// Pages are at most this many texels on a side; more pages are made when charts do not fit.
    pub max_page_size: u32,
    /// Empty texels between charts (room for dilation and bilinear filtering). At least 1.
    pub padding: u32,
}

/// How texel-to-texel form factors are computed (see the `transport` module of each).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    /// Cosine-distributed gathering rays per texel (sparse rows, ≤ K entries). The default.
    MonteCarlo,
    /// Differential point-to-point kernel with one visibility ray per pair (all pairs: small
    /// scenes only; unbounded as r → 0 — kept as a baseline).
    Point,
    /// Lambert's point-to-polygon contour integral over the source texel, visibility from
    /// shadow rays to points on the source (all pairs: small scenes only).
    Polygon,
    /// Hierarchical radiosity with clustering: links between texel blocks refined where the
    /// transfer error is large.
    Hierarchical,
}

/// How light is transported between texels.
#[derive(Clone, Debug)]
pub struct TransportParams {
    pub method: Method,
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
    /// method only (any solver, Gather included); point, polygon and hierarchical form factors
    /// are deterministic, so their errors are not the white noise it removes and it is skipped.
    pub denoise: bool,
    /// Gathering rays per texel where fewer than `gather_rays` suffice (emitters, black and
    /// unlit texels, measured by [`crate::plan`]'s pilot); `None`: `gather_rays` everywhere.
    /// Monte Carlo rows only (not the gather solver, not hierarchical).
    pub texel_rays: Option<TexelRays>,
}

/// Per-texel gathering rays (indexed like `Texels`); light samples scale with them.
#[derive(Clone, PartialEq, Eq)]
pub struct TexelRays(pub std::sync::Arc<[u32]>);

impl std::fmt::Debug for TexelRays {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let total: u64 = self.0.iter().map(|&k| k as u64).sum();
        write!(f, "TexelRays({} texels, {total} rays)", self.0.len())
    }
}

/// Iterative method for the stored radiosity system.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Solver {
    /// All texels updated from the previous sweep; parallel over rows.
    Jacobi,
    /// Texels updated in place in order; about twice the convergence per sweep, serial.
    GaussSeidel,
    /// Southwell progressive refinement: shoot the texel with the most unshot power.
    Southwell,
    /// Matrix-free: no stored rows; gathering rays are cast again every bounce.
    Gather,
}

/// How the radiosity system is iterated.
#[derive(Clone, Debug)]
pub struct SolveParams {
    pub solver: Solver,
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
    pub preview_exposure: f32,
    /// Also write each page as an 8-bit RGBM PNG (`output::rgbm`, range 8).
    pub rgbm: bool,
    /// Stitch UV seams after dilation (`lightmap::seams`): least squares on the texels along
    /// chart cuts through smooth surfaces, so both sides filter to the same value.
    pub seams: bool,
}

/// All options of a bake.
#[derive(Clone, Debug)]
pub struct BakeConfig {
    pub atlas: AtlasParams,
    pub transport: TransportParams,
    pub solve: SolveParams,
    pub output: OutputParams,
    /// Choose density, method, rays and tolerance from the scene for a target error
    /// ([`crate::plan`]); `None` uses the settings above as they are.
    pub auto: Option<crate::plan::AutoParams>,
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
                max_page_size: 1024,
                padding: 2,
            },
            transport: TransportParams {
                method: Method::MonteCarlo,
                gather_rays,
                light_samples,
                sky: Vec3::ZERO,
                indirect_only: false,
                seed: 0,
                validity: true,
                denoise: true,
                texel_rays: None,
            },
            solve: SolveParams {
                solver: Solver::Jacobi,
                tolerance,
                max_iterations: 10_000,
            },
            output: OutputParams {
                float: false,
                preview_exposure: 0.0,
                rgbm: false,
                seams: true,
            },
            auto: None,
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
    pub fn validate(&self) -> crate::Result<()> {
        use crate::Error::Option;
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
