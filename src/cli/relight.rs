//! `lightbake relight`: a kept bake solved again with other light and material values (see
//! [`lightbake::relight`]), and the `--layers` option it shares with `bake`.

use std::path::PathBuf;

use anyhow::{Context, Result};
use glam::Vec3;
use lightbake::config::LayerGroup;
use lightbake::relight::Edits;

use super::RunArgs;
use super::progress::Bars;

#[derive(clap::Args)]
pub struct Args {
    /// The baked scene (<stem>.gltf or .glb written by `lightbake bake --keep-transport`, with
    /// <stem>.transport beside it).
    scene: PathBuf,
    /// Output directory (not the bake's own).
    #[arg(short, long)]
    output: PathBuf,
    /// A light's new value: NAME=SCALE multiplies its intensity, NAME=R,G,B multiplies each
    /// channel of its colour × intensity (repeatable).
    #[arg(long, value_name = "NAME=SCALE|NAME=R,G,B", value_parser = parse_rgb_edit)]
    light: Vec<(String, Vec3)>,
    /// An emissive material's emission times SCALE (repeatable).
    #[arg(long, value_name = "MATERIAL=SCALE", value_parser = parse_scale_edit)]
    emission: Vec<(String, f32)>,
    /// A material's new base colour factor (repeatable; a texture keeps multiplying it).
    #[arg(long, value_name = "MATERIAL=R,G,B", value_parser = parse_rgb_edit)]
    albedo: Vec<(String, Vec3)>,
    #[command(flatten)]
    layers: LayerArgs,
    #[command(flatten)]
    run: RunArgs,
}

/// `--layers`, shared by `bake` and `relight`.
#[derive(clap::Args)]
pub struct LayerArgs {
    /// Also write one set of pages per layer, <stem>_<layer>_lightmap<k>.exr, named in the
    /// glTF's extras.lightmap_layers: alone, one layer per light, one for the emissive
    /// materials and one for the sky; GROUP=NAME,NAME… (repeatable) puts lights, emissive
    /// materials, `emissive` or `sky` into one layer. The layers sum to the lightmap.
    #[arg(long, value_name = "GROUP=NAME,NAME", num_args = 0..=1, default_missing_value = "")]
    layers: Vec<String>,
}

impl LayerArgs {
    /// As a manifest gives it: `None` without `--layers`, else the groups given.
    pub fn specs(&self) -> Option<Vec<String>> {
        (!self.layers.is_empty()).then(|| {
            self.layers
                .iter()
                .filter(|s| !s.is_empty())
                .cloned()
                .collect()
        })
    }

    /// `None` without `--layers`, else the named groups.
    pub fn groups(&self) -> Result<Option<Vec<LayerGroup>>> {
        let specs = self
            .specs()
            .map(|s| s.iter().map(|s| LayerGroup::parse(s)).collect());
        Ok(specs.transpose()?)
    }
}

fn split_edit(s: &str) -> Result<(&str, &str), String> {
    match s.rsplit_once('=') {
        Some((name, value)) if !name.is_empty() => Ok((name, value)),
        _ => Err(format!("expected NAME=VALUE, got {s:?}")),
    }
}

fn parse_rgb_edit(s: &str) -> Result<(String, Vec3), String> {
    let (name, value) = split_edit(s)?;
    let v = super::parse_rgb(value)?;
    if !(v.is_finite() && v.min_element() >= 0.0) {
        return Err(format!("{s:?}: values must be finite and non-negative"));
    }
    Ok((name.to_string(), v))
}

fn parse_scale_edit(s: &str) -> Result<(String, f32), String> {
    let (name, value) = split_edit(s)?;
    match value.trim().parse::<f32>() {
        Ok(x) if x.is_finite() && x >= 0.0 => Ok((name.to_string(), x)),
        _ => Err(format!("{s:?}: expected a finite non-negative scale")),
    }
}

pub fn run(args: &Args) -> Result<()> {
    args.run.start()?;
    let edits = Edits {
        lights: args.light.clone(),
        emission: args.emission.clone(),
        albedo: args.albedo.clone(),
    };
    let groups = args.layers.groups()?;
    let bars = Bars::new(args.run.quiet);
    let report =
        lightbake::relight::relight(&args.scene, &args.output, &edits, groups.as_deref(), &bars)
            .with_context(|| format!("relighting {} failed", args.scene.display()))?;
    if !args.run.quiet {
        println!("{}", report.summary());
        if let Some(gltf) = report.files.first() {
            println!("wrote {}", gltf.display());
        }
    }
    Ok(())
}
