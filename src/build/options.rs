//! The `bake` options by their command-line long names (without dashes), as a manifest gives
//! them, and the [`BakeConfig`] they make. The command line's `bake` goes through the same
//! [`Options::config`], so a manifest entry and a `bake` call with the same options bake alike.

use glam::Vec3;
use serde::Deserialize;

use crate::config::{AutoParams, Instancing, Keep, LayerGroup, RowStorage, Technique, UvMode};
use crate::{BakeConfig, Error, Result};

/// The `probes` option: on (`true`, `--probes` without a number: the budget follows the bake,
/// `crate::probes::ProbeParams::budget_for`) or a budget (`--probes N`).
#[derive(Clone, Copy, Debug, PartialEq, Deserialize)]
#[serde(untagged)]
pub enum Probes {
    /// Probes or none; with probes, the budget follows the bake.
    On(bool),
    /// At most this many probes.
    Budget(u32),
}

/// Every option of `lightbake bake` that changes what is baked; `None` (left out) is the
/// command line's default. Unknown names are an error.
#[derive(Clone, Debug, Default, PartialEq, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub struct Options {
    /// `draft`, `medium` (the default) or `high`.
    pub quality: Option<String>,
    /// Relative RMSE to aim at instead of the preset's (0.02 = 2%).
    pub target_error: Option<f32>,
    /// Use the preset's settings as they are: no pilot, no automatic choice.
    pub no_auto: Option<bool>,
    /// Lightmap texels per world unit (default: from the preset, fitted to the scene).
    pub texels_per_unit: Option<f32>,
    /// Largest page side in texels.
    pub max_page_size: Option<u32>,
    /// Empty texels between charts.
    pub padding: Option<u32>,
    /// `auto` (the default), `unwrap` or `existing`.
    pub uv: Option<String>,
    /// Gathering rays per texel (default: chosen by the pilot for the target error).
    pub rays: Option<u32>,
    /// Shadow rays per texel towards emissive surfaces.
    pub light_samples: Option<u32>,
    /// One value for all channels or `[r, g, b]`.
    pub sky: Option<Rgb>,
    /// One of [`Technique::METHODS`].
    pub method: Option<String>,
    /// One of [`Technique::SOLVERS`].
    pub solver: Option<String>,
    /// Relative error at which the solver stops.
    pub tolerance: Option<f32>,
    /// Iteration cap of the solver.
    pub max_iterations: Option<u32>,
    /// Store indirect light only.
    pub indirect_only: Option<bool>,
    /// Write 32-bit float EXR pages instead of half floats.
    pub float: Option<bool>,
    /// Also write each page as an 8-bit RGBM PNG.
    pub rgbm: Option<bool>,
    /// Also write each page's per-texel error estimate.
    pub error_map: Option<bool>,
    /// Also write directional (L1 SH) pages.
    pub directional: Option<bool>,
    /// Hemisphere rays per texel of the directional gather.
    pub directional_rays: Option<u32>,
    /// Also bake light probes: `true` (a budget that follows the bake) or at most this many
    /// (see `crate::probes`).
    pub probes: Option<Probes>,
    /// Leave punctual lights' direct light out of the probes.
    pub probes_indirect_only: Option<bool>,
    /// Place the probes from this node of the scene: its children, or its box (implies probes).
    pub probes_from: Option<String>,
    /// Share of the probe budget kept for refining cells where light changes (0 to 1).
    pub probes_refine: Option<f32>,
    /// Keep receivers whole where other surfaces meet them.
    pub no_split_junctions: Option<bool>,
    /// Do not cut receivers along the hard shadow outlines of punctual lights.
    pub no_shadow_cuts: Option<bool>,
    /// Cut receivers along the outlines of near contacts too.
    pub near_contacts: Option<bool>,
    /// With near contacts, keep slot faces at the plan's density.
    pub no_slot_faces: Option<bool>,
    /// Keep narrow faces near emitters at the plan's density.
    pub no_narrow_faces: Option<bool>,
    /// `duplicate` (the default) or `share`.
    pub instancing: Option<String>,
    /// Keep texel sample points where they are, even inside geometry.
    pub no_validity: Option<bool>,
    /// Skip the edge-aware denoiser.
    pub no_denoise: Option<bool>,
    /// Leave UV seams unstitched.
    pub no_seams: Option<bool>,
    /// Exposure of the PNG previews, in stops.
    pub exposure: Option<f32>,
    /// Seed of the random sample streams.
    pub seed: Option<u64>,
    /// Memory the bake may use, e.g. `"512M"`, `"8G"` (binary units) or bytes.
    pub max_memory: Option<String>,
    /// How stored Monte Carlo rows are held: `auto` (the default: the planner's choice),
    /// `f32` or `counts`.
    pub rows: Option<String>,
    /// Also write `<stem>.transport` for `lightbake relight`.
    pub keep_transport: Option<bool>,
    /// Per-light layers: `[]` for a layer per light, or groups `"GROUP=NAME,NAME"`.
    pub layers: Option<Vec<String>>,
}

/// A colour given as one value or three.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize)]
#[serde(untagged)]
pub enum Rgb {
    /// The same value in R, G and B.
    Grey(f32),
    /// R, G, B.
    Rgb([f32; 3]),
}

impl From<Rgb> for Vec3 {
    fn from(c: Rgb) -> Vec3 {
        match c {
            Rgb::Grey(v) => Vec3::splat(v),
            Rgb::Rgb(c) => Vec3::from(c),
        }
    }
}

impl Options {
    /// The bake configuration: the quality preset, the options given on top, and the automatic
    /// choice (unless `no-auto`) keeping what was given.
    pub fn config(&self) -> Result<BakeConfig> {
        let quality = self.quality.as_deref().unwrap_or("medium");
        let preset = BakeConfig::PRESETS
            .into_iter()
            .find(|(name, _)| *name == quality);
        let mut c = match preset {
            Some((_, c)) => c,
            None => return Err(expected("quality", quality, &["draft", "medium", "high"])),
        };
        let no_auto = self.no_auto.unwrap_or(false);
        if no_auto && self.target_error.is_some() {
            return Err(Error::Option(
                "target-error asks for the automatic choice that no-auto turns off".into(),
            ));
        }
        if let Some(t) = self.texels_per_unit {
            c.atlas.texels_per_unit = t;
        }
        if let Some(m) = self.max_page_size {
            c.atlas.max_page_size = m;
        }
        if let Some(p) = self.padding {
            c.atlas.padding = p;
        }
        c.atlas.uv = match self.uv.as_deref().unwrap_or("auto") {
            "auto" => UvMode::Auto,
            "unwrap" => UvMode::Unwrap,
            "existing" => UvMode::Existing,
            other => return Err(expected("uv", other, &["auto", "unwrap", "existing"])),
        };
        c.atlas.instancing = match self.instancing.as_deref().unwrap_or("duplicate") {
            "duplicate" => Instancing::Duplicate,
            "share" => Instancing::Share,
            other => return Err(expected("instancing", other, &["duplicate", "share"])),
        };
        if let Some(r) = self.rays {
            c.transport.gather_rays = r;
        }
        if let Some(l) = self.light_samples {
            c.transport.light_samples = l;
        }
        c.transport.sky = self.sky.map_or(Vec3::ZERO, Vec3::from);
        c.transport.indirect_only = self.indirect_only.unwrap_or(false);
        c.transport.seed = self.seed.unwrap_or(0);
        if self.method.is_some() || self.solver.is_some() {
            // The one not given keeps the preset's part (the automatic choice may change it).
            let method = self.method.as_deref().unwrap_or(c.technique.method());
            let solver = self.solver.as_deref().unwrap_or(c.technique.solver());
            c.technique = Technique::from_names(method, solver)?;
        }
        if let Some(t) = self.tolerance {
            c.solve.tolerance = t;
        }
        c.solve.max_iterations = self.max_iterations.unwrap_or(10_000);
        c.output.float = self.float.unwrap_or(false);
        c.output.preview_exposure = self.exposure.unwrap_or(0.0);
        c.output.rgbm = self.rgbm.unwrap_or(false);
        c.output.error_map = self.error_map.unwrap_or(false);
        c.output.directional = self.directional.unwrap_or(false).then(|| {
            self.directional_rays
                .unwrap_or(crate::lightmap::directional::DEFAULT_RAYS)
        });
        // Probes asked for, with a budget or following the bake (`None` inside); a probe node
        // asks for them.
        let budget = match (self.probes, &self.probes_from) {
            (Some(Probes::Budget(n)), _) => Some(Some(n)),
            (Some(Probes::On(true)), _) | (None | Some(Probes::On(false)), Some(_)) => Some(None),
            (None | Some(Probes::On(false)), None) => None,
        };
        c.output.probes = budget.map(|budget| crate::probes::ProbeParams {
            budget,
            indirect_only: self.probes_indirect_only.unwrap_or(false),
            from: self.probes_from.clone(),
            refine: self.probes_refine.unwrap_or(crate::probes::DEFAULT_REFINE),
            ..Default::default()
        });
        if let Some(share) = self.probes_refine
            && !(0.0..=1.0).contains(&share)
        {
            return Err(Error::Option(format!(
                "probes-refine {share}: a share of the budget, from 0 (a uniform grid) to 1"
            )));
        }
        if self.probes_indirect_only == Some(true) && budget.is_none() {
            return Err(Error::Option(
                "probes-indirect-only needs probes: give probes or probes-from too".into(),
            ));
        }
        c.atlas.split_junctions = !self.no_split_junctions.unwrap_or(false);
        c.atlas.shadow_cuts = !self.no_shadow_cuts.unwrap_or(false);
        c.atlas.near_contacts = self.near_contacts.unwrap_or(false);
        c.atlas.slot_faces = !self.no_slot_faces.unwrap_or(false);
        c.atlas.narrow_faces = !self.no_narrow_faces.unwrap_or(false);
        c.transport.validity = !self.no_validity.unwrap_or(false);
        c.transport.denoise = !self.no_denoise.unwrap_or(false);
        if !no_auto {
            let preset_error = AutoParams::for_preset(quality).unwrap_or(0.04);
            c.auto = Some(AutoParams {
                target_error: self.target_error.unwrap_or(preset_error),
                keep: Keep {
                    texels_per_unit: self.texels_per_unit.is_some(),
                    method: self.method.is_some(),
                    solver: self.solver.is_some(),
                    rays: self.rays.is_some(),
                    light_samples: self.light_samples.is_some(),
                    tolerance: self.tolerance.is_some(),
                },
            });
        }
        c.output.seams = !self.no_seams.unwrap_or(false);
        c.output.keep_transport = self.keep_transport.unwrap_or(false);
        c.output.layers = (self.layers.iter())
            .map(|specs| specs.iter().map(|s| LayerGroup::parse(s)).collect())
            .next()
            .transpose()?;
        c.transport.row_storage = match self.rows.as_deref() {
            None => RowStorage::Auto,
            Some(name) => RowStorage::from_name(name)
                .ok_or_else(|| expected("rows", name, &RowStorage::NAMES))?,
        };
        c.transport.count_rows = c.transport.row_storage == RowStorage::Counts;
        let stores_monte_carlo_rows =
            |c: &BakeConfig| c.technique.is_monte_carlo() && c.technique != Technique::Gather;
        if c.transport.row_storage != RowStorage::Auto
            && (self.method.is_some() || self.solver.is_some())
            && !stores_monte_carlo_rows(&c)
        {
            return Err(Error::Option(format!(
                "rows {:?}: only Monte Carlo rows with a stored-row solver have a storage to \
                 choose, not {}",
                self.rows.as_deref().unwrap_or_default(),
                c.technique
            )));
        }
        if let Some(size) = &self.max_memory {
            c.max_memory =
                Some(parse_memory(size).map_err(|e| Error::Option(format!("max-memory {e}")))?);
        }
        Ok(c)
    }
}

/// A memory size as `--max-memory` takes it: `512M`, `8G` (binary units) or bytes.
pub fn parse_memory(s: &str) -> std::result::Result<u64, String> {
    parse_size::Config::new()
        .with_binary()
        .parse_size(s)
        .map_err(|e| format!("{s:?}: {e} (expected e.g. 512M or 8G)"))
}

fn expected(option: &str, value: &str, names: &[&str]) -> Error {
    Error::Option(format!(
        "{option} {value:?}: expected one of {}",
        names.join(", ")
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_options_are_the_medium_preset_with_the_automatic_choice() {
        let c = Options::default().config().unwrap();
        let medium = BakeConfig::medium();
        assert_eq!(c.atlas.texels_per_unit, medium.atlas.texels_per_unit);
        assert_eq!(c.auto.map(|a| a.target_error), Some(0.04));
        assert_eq!(c.auto.map(|a| a.keep), Some(Keep::default()));
    }

    #[test]
    fn given_options_are_kept_and_bad_names_named() {
        let o = Options {
            quality: Some("draft".into()),
            rays: Some(32),
            sky: Some(Rgb::Rgb([0.1, 0.2, 0.3])),
            solver: Some("gather".into()),
            ..Options::default()
        };
        let c = o.config().unwrap();
        assert_eq!(c.transport.gather_rays, 32);
        assert_eq!(c.transport.sky, Vec3::new(0.1, 0.2, 0.3));
        assert_eq!(c.technique.solver(), "gather");
        let auto = c.auto.unwrap();
        assert_eq!(auto.target_error, 0.08);
        assert!(auto.keep.rays && auto.keep.solver && !auto.keep.method);
        let bad = Options {
            uv: Some("sideways".into()),
            ..Options::default()
        };
        assert!(bad.config().unwrap_err().to_string().contains("sideways"));
    }

    /// `probes = true` (or a probe node alone) lets the budget follow the bake, `probes = N`
    /// gives it, `probes = false` asks for none.
    #[test]
    fn probes_take_a_budget_or_follow_the_bake() {
        let budget = |text: &str| {
            let o: Options = toml::from_str(text).unwrap();
            o.config().unwrap().output.probes.map(|p| p.budget)
        };
        assert_eq!(budget("probes = true"), Some(None));
        assert_eq!(budget("probes = 2048"), Some(Some(2048)));
        assert_eq!(budget("probes = false"), None);
        assert_eq!(budget(""), None);
        assert_eq!(budget("probes-from = \"Volume\""), Some(None));
        assert_eq!(
            budget("probes = 64\nprobes-from = \"Volume\""),
            Some(Some(64))
        );
    }

    #[test]
    fn the_probes_refine_share_is_kept_and_checked() {
        let o = |share: Option<f32>| Options {
            probes: Some(Probes::Budget(256)),
            probes_refine: share,
            ..Options::default()
        };
        let refine = |c: BakeConfig| c.output.probes.unwrap().refine;
        assert_eq!(
            refine(o(None).config().unwrap()),
            crate::probes::DEFAULT_REFINE
        );
        assert_eq!(refine(o(Some(0.0)).config().unwrap()), 0.0);
        let err = o(Some(1.5)).config().unwrap_err().to_string();
        assert!(err.contains("probes-refine 1.5"), "{err}");
    }
}
