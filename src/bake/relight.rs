//! Relighting from a kept transport, and per-light layers.
//!
//! Radiosity is linear in the light put in: with the rows `F` and the albedo ρ fixed, the
//! irradiance solving `H = H_direct + F·(ρ ⊙ H)` is a linear function of `H_direct`, and direct
//! light is a sum over sources (each punctual light, each emissive material, the sky) of terms
//! linear in the source's intensity or emission. A bake that kept its rows and its direct
//! light by source ([`kept`], `bake --keep-transport`) can therefore be solved again for other
//! light values, or for one source at a time, without casting a ray:
//!
//! - **Relight** ([`relight`]): light intensities and colours and material emission scale
//!   their terms; a new base colour changes ρ (the rows are geometry: they do not depend on
//!   it). The result equals a fresh bake of the edited scene with the same fixed settings
//!   within the solver's tolerance, except where emitter sampling changes: a fresh bake draws
//!   its light samples from the emitters' power, so scaling one emissive material among
//!   several (or switching one off) moves samples between them there, and the two differ by
//!   the Monte Carlo noise of those samples, not by a bias. Scaling every emissive material by
//!   one factor keeps the sampling as it was. The texels are the bake's: the shadow cuts
//!   (`scene::shadow_cuts`) follow the outlines of the baked lights' shadows that carry at
//!   least a tenth of the light there, so when the balance of lights changes a fresh bake may
//!   cut other outlines (and lay out other texels); the relight keeps the baked cuts and warns.
//!   Measured (`tests/relight.rs`, draft, float pages): relit and fresh pages differ by 2e-8
//!   (relative L1; lights scaled and tinted one by one, a wall colour, shadow cuts off), 2e-8
//!   (both lights halved and a floor colour, shadow cuts on) and 6e-8 (the Cornell light ×3) —
//!   float rounding: the same system, solved with the same sweeps.
//! - **Layers** (`plan_layers`, `solve_layers`): one lightmap per light, one for the
//!   emissive materials and one for the sky, or named groups of them. Each layer's direct
//!   light is solved with the full solve's solver and, for Jacobi and Gauss–Seidel, exactly its
//!   number of sweeps: each sweep is linear, so the layers sum to the full solution within
//!   float rounding (Southwell's shooting order depends on the values: its layers stop at the
//!   tolerance each and sum to it within the tolerance). Denoising is not linear (its range
//!   kernel reads the values), so each layer is filtered with the weights of the full lightmap
//!   (`lightmap::denoise::denoise_guided`): the same linear filter for every layer, and the filtered layers sum
//!   to the filtered lightmap (up to the clamp of a plane fit below zero). The invalid-texel
//!   fill and dilation are linear; seam stitching is a least-squares solve stopped at a
//!   tolerance, so after it the pages sum within that tolerance.
//!
//! A relight of an automatic bake re-solves the final run's rows: with `--keep-transport` or
//! `--layers` the bake does not mix the pilot runs into its result (their rows are not kept),
//! so what is written is exactly what the kept transport describes.

use std::f32::consts::PI;
use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::Vec3;
use serde_json::Value;

use super::kept::{self, Kept, Settings};
use super::{StageTime, check_aborted, commit, output_stem, pages_of, stored_values, timed};
use crate::config::{BakeConfig, LayerGroup, RowSolver, Technique};
use crate::lightmap::LightmapPages;
use crate::lightmap::denoise::{self, DenoiseParams};
use crate::lightmap::seams::{self, Seams};
use crate::output::gltf_edit::{self, LayerExtras};
use crate::output::{self, Staging};
use crate::scene::MAX_ALBEDO;
use crate::solve::{self, Solution};
use crate::texels::Texels;
use crate::transport::Transport;
use crate::{Error, Progress, Result};

/// Changes to the baked light and material values, by the names [`kept::Settings`] gives them.
#[derive(Clone, Debug, Default)]
pub struct Edits {
    /// Light name → factor on its `color × intensity`, per channel (a colour or a scale).
    pub lights: Vec<(String, Vec3)>,
    /// Material name → factor on its emission.
    pub emission: Vec<(String, f32)>,
    /// Material name → its new base colour factor (RGB).
    pub albedo: Vec<(String, Vec3)>,
}

/// One layer: the sources whose light it holds (indices into the transport's sources) and
/// whether the sky's.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Layer {
    /// The layer's name, also in its pages' file names (`<stem>_<name>_lightmap<k>.exr`).
    pub(crate) name: String,
    pub(crate) sources: Vec<usize>,
    pub(crate) sky: bool,
}

/// A layer's pages.
#[derive(Clone, Debug)]
pub struct LayerPages {
    pub(crate) layer: Layer,
    /// `H/π` per texel (denoised, invalid texels filled): what the pages hold before dilation.
    pub lightmap: Vec<Vec3>,
    pub(crate) pages: LightmapPages,
}

/// What a relight did.
#[derive(Clone, Debug)]
pub struct RelightReport {
    pub(crate) texels: usize,
    /// Per-light layers written (0 without layers).
    pub layers: usize,
    pub(crate) iterations: usize,
    pub(crate) residual: f32,
    /// False when the solver stopped on the iteration cap.
    pub converged: bool,
    pub(crate) stages: Vec<StageTime>,
    /// The files written, the glTF first.
    pub files: Vec<PathBuf>,
}

impl RelightReport {
    /// One line: texels, layers, iterations, seconds per stage.
    pub fn summary(&self) -> String {
        let stages: Vec<String> = (self.stages.iter())
            .map(|s| format!("{} {:.2}s", s.stage, s.seconds))
            .collect();
        let total: f64 = self.stages.iter().map(|s| s.seconds).sum();
        format!(
            "relit {} texels, {} layer(s), {} iterations, residual {:.1e}{}, no rays; {} (total {total:.2}s)",
            self.texels,
            self.layers,
            self.iterations,
            self.residual,
            if self.converged {
                ""
            } else {
                " (NOT converged)"
            },
            stages.join(", ")
        )
    }
}

/// Relights the bake `gltf` (a `<stem>.gltf` or `.glb` written by `bake --keep-transport`,
/// its `<stem>.transport` beside it) with `edits` into `out_dir`: pages and the glTF as a bake
/// writes them, the glTF's lights and materials carrying the edited values, and with `layers`
/// one set of pages per layer.
pub fn relight(
    gltf: &Path,
    out_dir: &Path,
    edits: &Edits,
    layers: Option<&[LayerGroup]>,
    progress: &dyn Progress,
) -> Result<RelightReport> {
    super::refuse_overwriting_input(gltf, out_dir)?;
    let mut stages = Vec::new();
    let t = Instant::now();
    let Kept {
        settings,
        mut texels,
        material,
        mut transport,
        seams,
        ..
    } = kept::read(gltf)?;
    let mut config = settings.config()?;
    config.output.layers = layers.map(<[LayerGroup]>::to_vec);
    timed(&mut stages, "read", t);

    let t = Instant::now();
    let scale = apply(&settings, edits, &mut texels, &material)?;
    let lights = &scale[..settings.lights.len()];
    if settings.split_junctions
        && settings.shadow_cuts
        && lights
            .iter()
            .any(|s| *s != lights[0] || s.min_element() != s.max_element())
    {
        progress.warn(&format!(
            "{}: the shadow cuts follow the baked lights' shadow outlines (those at least {:.0}% of the light there); with the lights' balance changed, a fresh bake may cut other outlines",
            gltf.display(),
            crate::scene::shadow_cuts::MIN_JUMP * 100.0
        ));
    }
    let planned = layers
        .map(|groups| plan_layers(&settings, groups))
        .transpose()?;
    let sky = config.transport.sky;
    transport.direct = direct_light(
        &transport,
        &scale,
        &(0..scale.len()).collect::<Vec<_>>(),
        sky,
    );
    let solver = row_solver(&config)?;
    let solution = solve::solve(&transport, &texels, solver, &config.solve, progress)?;
    timed(&mut stages, "solve", t);

    let t = Instant::now();
    let seams = config.output.seams.then_some(&seams);
    let mut lightmap = stored_values(
        &solution.irradiance,
        &transport.direct,
        config.transport.indirect_only,
    );
    let denoised = config.transport.denoise && config.technique.is_monte_carlo();
    let noise = denoised.then(|| {
        denoise::bake_noise(
            &texels,
            &transport.direct,
            &lightmap,
            (&config.transport, None),
        )
    });
    let guide = (noise.is_some() && planned.is_some()).then(|| lightmap.clone());
    if let Some(noise) = &noise {
        denoise::denoise(
            &texels,
            &mut lightmap,
            noise,
            &DenoiseParams::default(),
            progress,
        )?;
    }
    let pages = pages_stitched(&texels, &mut lightmap, &config, seams);
    let layer_pages = match &planned {
        Some(layers) => layer_pages(
            (&texels, &mut transport),
            &config,
            &solution,
            (&scale, layers),
            guide.as_deref().zip(noise.as_deref()),
            seams,
            progress,
        )?,
        None => Vec::new(),
    };
    timed(&mut stages, "pages", t);
    check_aborted(progress)?;

    let t = Instant::now();
    let stem = output_stem(gltf);
    let source_files = kept::gltf_files(gltf)?;
    let mut staging = Staging::new(out_dir, &[gltf.to_path_buf()])?;
    stage_pages(&mut staging, &stem, &pages, &config, gltf)?;
    let layer_files = stage_layers(&mut staging, &stem, &layer_pages, &config, gltf)?;
    let main = gltf_edit::edit_gltf(&source_files[0], gltf, |json| {
        write_edits(json, &settings, edits);
        add_layer_extras(json, &settings, &layer_files)
    })?;
    let name = gltf
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or("scene.gltf");
    staging.write(name, &main)?;
    let json = gltf_edit::json_of(&source_files[0], gltf)?;
    gltf_edit::copy_referenced(&mut staging, gltf, &json)?;
    check_aborted(progress)?;
    let files = commit(staging)?;
    timed(&mut stages, "write", t);
    Ok(RelightReport {
        texels: texels.len(),
        layers: layer_pages.len(),
        iterations: solution.history.len(),
        residual: solution.residual(),
        converged: solution.converged,
        stages,
        files,
    })
}

/// The stored-row solver of `config`: relighting needs rows.
fn row_solver(config: &BakeConfig) -> Result<RowSolver> {
    match config.technique {
        Technique::Stored { solver, .. } => Ok(solver),
        t => Err(Error::Option(format!(
            "the {t} technique stores no rows: a transport cannot be kept (use --method montecarlo with a stored-row solver)"
        ))),
    }
}

/// Applies `edits` to the texels' albedo and emission; returns the factor on each source's
/// direct light. Unknown names are errors that list the known ones.
fn apply(
    settings: &Settings,
    edits: &Edits,
    texels: &mut Texels,
    material: &[u32],
) -> Result<Vec<Vec3>> {
    let lights = settings.lights.len();
    let mut scale = vec![Vec3::ONE; lights + settings.emissive.len()];
    for (name, factor) in &edits.lights {
        let matching = matches(settings.lights.iter().map(|l| &l.label), name, "light")?;
        for l in matching {
            scale[l] *= *factor;
        }
    }
    let emissive_names = || -> Vec<&String> {
        let emissive = settings.emissive.iter();
        emissive
            .map(|&m| &settings.materials[m as usize].label)
            .collect()
    };
    for (name, factor) in &edits.emission {
        for k in matches(emissive_names().into_iter(), name, "emissive material")? {
            scale[lights + k] *= *factor;
            let m = settings.emissive[k];
            for (e, _) in (texels.emission.iter_mut().zip(material)).filter(|(_, t)| **t == m) {
                *e *= *factor;
            }
        }
    }
    for (name, color) in &edits.albedo {
        let labels = settings.materials.iter().map(|m| &m.label);
        for m in matches(labels, name, "material")? {
            let entry = &settings.materials[m];
            let old = Vec3::from(entry.base_color);
            if entry.textured && (old.cmple(Vec3::ZERO).any()) {
                return Err(Error::Option(format!(
                    "material {name:?}: its base colour {old} is zero in a channel under a texture, so the texture's part of that channel is unknown: it cannot be given another base colour without a bake"
                )));
            }
            for (a, _) in (texels.albedo.iter_mut().zip(material)).filter(|(_, t)| **t == m as u32)
            {
                // A texture's texel stays: ρ = factor × texture.
                let rho = if entry.textured {
                    *a / old * *color
                } else {
                    *color
                };
                *a = rho.clamp(Vec3::ZERO, Vec3::splat(MAX_ALBEDO));
            }
        }
    }
    Ok(scale)
}

/// Indices of `labels` equal to `name`; none is an error listing the labels (`what` names them).
fn matches<'a>(
    labels: impl Iterator<Item = &'a String> + Clone,
    name: &str,
    what: &str,
) -> Result<Vec<usize>> {
    let found: Vec<usize> = (labels.clone().enumerate())
        .filter(|(_, l)| *l == name)
        .map(|(k, _)| k)
        .collect();
    if found.is_empty() {
        let mut known: Vec<&String> = labels.collect();
        known.sort();
        known.dedup();
        let known: Vec<String> = known.iter().map(|l| format!("{l:?}")).collect();
        return Err(Error::Option(format!(
            "no {what} is named {name:?}; the {what}s are: {}",
            if known.is_empty() {
                "(none)".to_string()
            } else {
                known.join(", ")
            }
        )));
    }
    Ok(found)
}

/// Direct light of `sources` (each scaled by `scale`), plus the sky's when `sky` is not zero:
/// `Σ_s scale_s ⊙ term_s + π · sky · escape`, per texel.
pub(crate) fn direct_light(
    transport: &Transport,
    scale: &[Vec3],
    sources: &[usize],
    sky: Vec3,
) -> Vec<Vec3> {
    let count = transport.sources.len();
    (transport.escape.iter().enumerate())
        .map(|(i, &escape)| {
            let terms = &transport.direct_terms[i * count..(i + 1) * count];
            let lit = sources
                .iter()
                .fold(Vec3::ZERO, |acc, &s| acc + terms[s] * scale[s]);
            lit + sky * (PI * escape)
        })
        .collect()
}

/// The layers of a bake: one per named group (`groups`), then one per light name, one for
/// the emissive materials (`emissive`) and one for the sky (`sky`, when the bake has one) for
/// the sources no group took. Members are light names, emissive material names, `emissive`
/// or `sky`; an unknown or twice-grouped member is an error.
pub(crate) fn plan_layers(settings: &Settings, groups: &[LayerGroup]) -> Result<Vec<Layer>> {
    let lights = settings.lights.len();
    let has_sky = Vec3::from(settings.sky).max_element() > 0.0;
    let emissive: Vec<usize> = (lights..lights + settings.emissive.len()).collect();
    let label = |s: usize| match s < lights {
        true => &settings.lights[s].label,
        false => &settings.materials[settings.emissive[s - lights] as usize].label,
    };
    let mut taken = vec![false; lights + emissive.len()];
    let mut sky_taken = false;
    let mut layers = Vec::new();
    for group in groups {
        let mut layer = Layer {
            name: file_safe(&group.name),
            sources: Vec::new(),
            sky: false,
        };
        for member in &group.members {
            let sources: Vec<usize> = match member.as_str() {
                "sky" if has_sky => {
                    layer.sky = !std::mem::replace(&mut sky_taken, true);
                    if !layer.sky {
                        return Err(twice(member));
                    }
                    continue;
                }
                "emissive" if !emissive.is_empty() => emissive.clone(),
                _ => (0..taken.len()).filter(|&s| label(s) == member).collect(),
            };
            if sources.is_empty() {
                let mut known: Vec<String> = (0..taken.len())
                    .map(|s| format!("{:?}", label(s)))
                    .collect();
                known.extend(
                    ["\"emissive\"".to_string()]
                        .into_iter()
                        .filter(|_| !emissive.is_empty()),
                );
                known.extend(["\"sky\"".to_string()].into_iter().filter(|_| has_sky));
                known.dedup();
                return Err(Error::Option(format!(
                    "layer {:?}: no light or emissive material is named {member:?}; the known names are: {}",
                    group.name,
                    known.join(", ")
                )));
            }
            for s in sources {
                if std::mem::replace(&mut taken[s], true) {
                    return Err(twice(member));
                }
                layer.sources.push(s);
            }
        }
        layers.push(layer);
    }
    // Every source no group took: a layer per light name, the emissive materials, the sky.
    for s in 0..lights {
        if taken[s] {
            continue;
        }
        let same: Vec<usize> = (s..lights)
            .filter(|&t| !taken[t] && label(t) == label(s))
            .collect();
        same.iter().for_each(|&t| taken[t] = true);
        layers.push(Layer {
            name: file_safe(label(s)),
            sources: same,
            sky: false,
        });
    }
    let rest: Vec<usize> = emissive.into_iter().filter(|&s| !taken[s]).collect();
    if !rest.is_empty() {
        layers.push(Layer {
            name: "emissive".to_string(),
            sources: rest,
            sky: false,
        });
    }
    if has_sky && !sky_taken {
        layers.push(Layer {
            name: "sky".to_string(),
            sources: Vec::new(),
            sky: true,
        });
    }
    // File names must differ.
    for k in 1..layers.len() {
        while layers[..k].iter().any(|l| l.name == layers[k].name) {
            layers[k].name.push('_');
        }
    }
    Ok(layers)
}

fn twice(member: &str) -> Error {
    Error::Option(format!(
        "{member:?} is in two layers: the layers must sum to the lightmap"
    ))
}

/// `name` with every character but ASCII letters, digits, `-` and `_` replaced by `_`.
fn file_safe(name: &str) -> String {
    let safe: String = (name.chars())
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect();
    if safe.is_empty() {
        "layer".to_string()
    } else {
        safe
    }
}

/// Each layer's `H/π` per texel (before denoising): its direct light (sources scaled by
/// `scale`) solved on `transport`'s rows with the solver of `config` — for Jacobi and
/// Gauss–Seidel exactly `full`'s number of sweeps, so the layers sum to `full` within float
/// rounding. `transport.direct` is restored afterwards.
pub(crate) fn solve_layers(
    (texels, transport): (&Texels, &mut Transport),
    config: &BakeConfig,
    full: &Solution,
    scale: &[Vec3],
    layers: &[Layer],
    progress: &dyn Progress,
) -> Result<Vec<Vec<Vec3>>> {
    let solver = row_solver(config)?;
    let params = match solver {
        // No tolerance: the full solve's sweeps, no more and no fewer.
        RowSolver::Jacobi | RowSolver::GaussSeidel => crate::config::SolveParams {
            tolerance: 0.0,
            max_iterations: full.history.len() as u32,
        },
        RowSolver::Southwell => config.solve.clone(),
    };
    let full_direct = std::mem::take(&mut transport.direct);
    let mut out = Vec::with_capacity(layers.len());
    for layer in layers {
        let sky = if layer.sky {
            config.transport.sky
        } else {
            Vec3::ZERO
        };
        transport.direct = direct_light(transport, scale, &layer.sources, sky);
        let solved = solve::solve(transport, texels, solver, &params, progress);
        let solved = match solved {
            Ok(s) => s,
            Err(e) => {
                transport.direct = full_direct;
                return Err(e);
            }
        };
        out.push(stored_values(
            &solved.irradiance,
            &transport.direct,
            config.transport.indirect_only,
        ));
    }
    transport.direct = full_direct;
    Ok(out)
}

/// Each layer's pages: its lightmap ([`solve_layers`]) denoised with the weights of the full
/// lightmap (`guide`: the full lightmap before denoising and its noise; `None` when the bake
/// is not denoised), invalid texels filled, dilated and, with `seams`, stitched.
pub(crate) fn layer_pages(
    (texels, transport): (&Texels, &mut Transport),
    config: &BakeConfig,
    full: &Solution,
    (scale, layers): (&[Vec3], &[Layer]),
    guide: Option<(&[Vec3], &[f32])>,
    seams: Option<&Seams>,
    progress: &dyn Progress,
) -> Result<Vec<LayerPages>> {
    let maps = solve_layers((texels, transport), config, full, scale, layers, progress)?;
    let mut out = Vec::with_capacity(maps.len());
    for (mut map, layer) in maps.into_iter().zip(layers) {
        if let Some((guide, noise)) = guide {
            let params = DenoiseParams::default();
            denoise::denoise_guided(texels, guide, &mut map, noise, &params, progress)?;
        }
        let pages = pages_stitched(texels, &mut map, config, seams);
        out.push(LayerPages {
            layer: layer.clone(),
            lightmap: map,
            pages,
        });
    }
    Ok(out)
}

/// [`pages_of`], stitched along `seams`.
fn pages_stitched(
    texels: &Texels,
    lightmap: &mut [Vec3],
    config: &BakeConfig,
    seams: Option<&Seams>,
) -> LightmapPages {
    let mut pages = pages_of(texels, lightmap, config.atlas.padding);
    if let Some(seams) = seams {
        seams::stitch(seams, &mut pages, &Default::default());
    }
    pages
}

/// Stages each page of `pages` as `<prefix>_lightmap<k>.exr` and `.png` (and the RGBM PNG
/// when `config` asks); returns the EXR and PNG names.
pub(crate) fn stage_pages(
    staging: &mut Staging,
    prefix: &str,
    pages: &LightmapPages,
    config: &BakeConfig,
    input: &Path,
) -> Result<Vec<output::PageFiles>> {
    let mut files = Vec::with_capacity(pages.pages.len());
    for (k, page) in pages.pages.iter().enumerate() {
        let names = output::PageFiles {
            exr: format!("{prefix}_lightmap{k}.exr"),
            png: format!("{prefix}_lightmap{k}.png"),
            directional: None,
        };
        staging.write(
            &names.exr,
            &output::write_exr(page, config.output.float, input)?,
        )?;
        let png = output::write_png_preview(page, config.output.preview_exposure)?;
        staging.write(&names.png, &png)?;
        if config.output.rgbm {
            let png = output::write_rgbm_png(page, output::rgbm::DEFAULT_RANGE)?;
            staging.write(&format!("{prefix}_lightmap{k}_rgbm.png"), &png)?;
        }
        files.push(names);
    }
    Ok(files)
}

/// Stages every layer's pages (`<stem>_<layer>_lightmap<k>`); returns each layer with its
/// files.
pub(crate) fn stage_layers(
    staging: &mut Staging,
    stem: &str,
    layers: &[LayerPages],
    config: &BakeConfig,
    input: &Path,
) -> Result<Vec<(Layer, Vec<output::PageFiles>)>> {
    (layers.iter())
        .map(|l| {
            let prefix = format!("{stem}_{}", l.layer.name);
            let files = stage_pages(staging, &prefix, &l.pages, config, input)?;
            Ok((l.layer.clone(), files))
        })
        .collect()
}

/// Names the `layers` in the glTF's root `extras.lightmap_layers` (their lights and emissive
/// materials by the names `settings` gives them) for an engine to mix.
pub(crate) fn add_layer_extras(
    json: &mut Value,
    settings: &Settings,
    layers: &[(Layer, Vec<output::PageFiles>)],
) -> Result<()> {
    let lights = settings.lights.len();
    let extras: Vec<LayerExtras> = (layers.iter())
        .map(|(layer, files)| {
            let (mut light_names, mut materials) = (Vec::new(), Vec::new());
            for &s in &layer.sources {
                match s < lights {
                    true => light_names.push(settings.lights[s].label.clone()),
                    false => materials.push(
                        settings.materials[settings.emissive[s - lights] as usize]
                            .label
                            .clone(),
                    ),
                }
            }
            light_names.dedup();
            LayerExtras {
                name: &layer.name,
                lights: light_names,
                emissive_materials: materials,
                sky: layer.sky,
                pages: files,
            }
        })
        .collect();
    gltf_edit::set_layer_extras(json, &extras)
}

/// Writes the edited values into the glTF, by the names `settings` gives its lights and
/// materials: a light's colour and intensity, a material's emissive strength and base colour
/// factor. The lightmap copies of a material (`<name> (lightmap k)`) are edited with it.
fn write_edits(json: &mut Value, settings: &Settings, edits: &Edits) {
    let mut done = Vec::new();
    for (name, factor) in &edits.lights {
        for entry in settings.lights.iter().filter(|l| &l.label == name) {
            let Some(k) = entry.source.filter(|k| !done.contains(&(*k, name))) else {
                continue;
            };
            done.push((k, name));
            gltf_edit::scale_light(json, k as usize, *factor);
        }
    }
    for (name, factor) in &edits.emission {
        for m in material_copies(json, settings, name) {
            gltf_edit::scale_emission(json, m, *factor);
        }
    }
    for (name, color) in &edits.albedo {
        for m in material_copies(json, settings, name) {
            gltf_edit::set_base_color(json, m, *color);
        }
    }
}

/// The glTF materials that are `name` or its lightmap copies.
fn material_copies(json: &Value, settings: &Settings, name: &str) -> Vec<usize> {
    let sources: Vec<u32> = (settings.materials.iter())
        .filter(|m| m.label == name)
        .filter_map(|m| m.source)
        .collect();
    gltf_edit::material_copies(json, &sources, name)
}
