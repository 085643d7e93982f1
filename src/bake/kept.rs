//! The kept transport, `<stem>.transport`: what `lightbake relight` needs to solve a bake again
//! with other light and material values, without casting a ray ([`super::relight`]).
//!
//! ## Format (version 2)
//!
//! Little-endian throughout; `vec3` is three `f32`.
//!
//! | bytes             | what                                                                 |
//! |-------------------|----------------------------------------------------------------------|
//! | 20                | magic `LIGHTBAKE-TRANSPORT\n`                                         |
//! | u32               | format version (2)                                                   |
//! | 32                | scene hash: blake3 of the baked glTF (`.gltf` JSON then its `.bin`, or the `.glb`) and of the settings block |
//! | u64               | body length in bytes                                                 |
//! | body              | the sections below, in order                                         |
//! | 32                | blake3 of the body (a damaged or truncated copy is refused)          |
//!
//! Body sections:
//!
//! 1. settings: u64 length + UTF-8 JSON ([`Settings`]): the settings the bake ran with (the
//!    automatic choices applied: method, solver, rays, light samples, tolerance, density; a
//!    kept bake casts the chosen rays at every texel), the glTF it belongs to, the lights and materials by name with their
//!    baked values (the relit values are relative to them), and the input it was baked from
//!    ([`super::incremental::InputRecord`]: a hash of everything but the node transforms, and
//!    each node's transform as written), which `bake --since` compares the edited input with.
//! 2. texels: u32 texel count `n`, u32 source count `S`, u32 page count, then per page
//!    u32 width and height; then arrays of `n`: page (u32), x and y (2 × u32), position,
//!    normal, du, dv, albedo, emission (vec3 each), material (u32, an index into the settings'
//!    materials); then u32 count and the ids of the invalid texels. These are the texels after
//!    validity moved their sample points (that pass casts rays): the denoiser, the invalid-texel
//!    fill and the pages read them.
//! 3. rows: `n` escape fractions (f32), `n` row lengths (u32), then every row's entries in
//!    texel order as (u32 source texel, f32 form factor). Written through
//!    [`Transport::row`] and read back through `Transport::from_rows`, so the file does not
//!    depend on how rows are held in memory. Form factors are stored as f32, the precision the
//!    solver uses: a Monte Carlo entry is a hit count over the texel's ray count, which f32
//!    holds exactly enough for the count to be recovered (`round(f · K)`, K ≤ 2²⁰).
//! 4. direct light by source: `n × S` vec3, texel-major ([`Transport::direct_terms`]): sources
//!    are the scene's punctual lights, then its emissive materials
//!    ([`crate::transport::Sources`]). The sky's part is `π · sky · escape`.
//! 5. direct light as the bake summed it: `n` vec3 (`Transport::direct`, sky included). The
//!    sum of the terms of section 4 rounds differently; `bake --since` reuses a row unchanged
//!    only if it reuses its direct light bit for bit, so an unchanged scene re-bakes to the
//!    same bytes.
//! 6. seams: u32 count, then per sample u32 page × 2 and f32 uv × 4 (the seam samples the
//!    stitching reads, found from the scene and atlas at bake time).
//! 7. atlas: u32 0 (not kept: `--instancing share`), or 1 then f32 texels per unit, u32 page
//!    count and per page width and height, u32 instance count and per instance u32 vertex
//!    count, `xref` (u32 each), `uv` (2 × f32 each), u32 triangle count, `triangles`
//!    (3 × u32 each) and `triangle_page` (u32 each) ([`crate::atlas::InstanceUv`]). An
//!    incremental bake lays the old scene out again without unwrapping it (xatlas is most of
//!    that time); the kept texels check the result.
//! 8. what the validity pass left besides positions: `n` jitter fractions (f32), then u32
//!    count and per divided texel its id (u32) and cell map (64 × u32) ([`crate::texels`]'s
//!    cuts). With the positions and invalid texels above, an incremental bake has the old
//!    texels without running the old scene's validity pass again.
//!
//! Version 1 files (no input record, no direct light sums) are refused with the advice to bake
//! again; they held nothing an incremental bake could trust.
//!
//! Reading refuses, naming the file: another kind of file (magic), another format version, a
//! truncated or damaged file (lengths and body hash), and a stale or foreign one (the scene
//! hash does not match the glTF beside it: baked again, edited, or another scene's).

use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};
use serde::{Deserialize, Serialize};

use crate::atlas::{Atlas, InstanceUv, PageSize};
use crate::config::{BakeConfig, Technique, UvMode};
use crate::lightmap::seams::{SeamSample, Seams};
use crate::scene::Scene;
use crate::texels::{NO_TEXEL, Texels};
use crate::transport::{Sources, Transport};
use crate::{Error, Result};

const MAGIC: &[u8; 20] = b"LIGHTBAKE-TRANSPORT\n";
/// The format version this lightbake writes and reads.
pub(crate) const VERSION: u32 = 2;

/// The settings block: how the bake ran, and the lights and materials it was baked with.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Settings {
    /// The lightbake that wrote the file.
    pub(crate) lightbake: String,
    /// The baked glTF (`.gltf` or `.glb`) beside the file, by name.
    pub(crate) gltf: String,
    pub(crate) method: String,
    pub(crate) solver: String,
    pub(crate) texels_per_unit: f32,
    pub(crate) instance_density: Vec<f32>,
    /// Per scene triangle (`AtlasParams::triangle_density`); empty in files that predate it.
    #[serde(default)]
    pub(crate) triangle_density: Vec<f32>,
    pub(crate) max_page_size: u32,
    pub(crate) padding: u32,
    pub(crate) uv: String,
    pub(crate) split_junctions: bool,
    pub(crate) shadow_cuts: bool,
    /// `--near-contacts` (left out when false, so files of bakes without it are as before).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub(crate) near_contacts: bool,
    /// `--no-slot-faces` (left out when false, so files of other bakes are as before).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub(crate) no_slot_faces: bool,
    /// `--no-narrow-faces` (left out when false, so files of other bakes are as before).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub(crate) no_narrow_faces: bool,
    /// `--instancing share`: shared meshes with a page rect per node (left out when false, so
    /// files of duplicate-mode bakes are as before).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub(crate) share_instances: bool,
    pub(crate) gather_rays: u32,
    pub(crate) light_samples: u32,
    pub(crate) sky: [f32; 3],
    pub(crate) indirect_only: bool,
    pub(crate) seed: u64,
    pub(crate) validity: bool,
    pub(crate) denoise: bool,
    /// The solver's tolerance: the relative error at which it stops.
    pub tolerance: f32,
    pub(crate) max_iterations: u32,
    pub(crate) float: bool,
    pub(crate) preview_exposure: f32,
    pub(crate) rgbm: bool,
    pub(crate) seams: bool,
    /// Monte Carlo rows held as ray counts (`--rows counts`, or the planner's memory choice).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub(crate) count_rows: bool,
    /// The input the bake read, for `bake --since` ([`super::incremental`]); set when the
    /// transport is kept.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(crate) input: Option<super::incremental::InputRecord>,
    /// The probe budget the bake used (left out without probes): an incremental bake whose
    /// budget follows the bake keeps it, as its own rays are only those it re-traced.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(crate) probe_budget: Option<u32>,
    /// The scene's punctual lights, in scene order (sources `0..lights.len()`).
    pub(crate) lights: Vec<LightEntry>,
    /// The scene's materials, in scene order.
    pub materials: Vec<MaterialEntry>,
    /// The emissive materials (indices into `materials`): sources `lights.len()..`.
    pub emissive: Vec<u32>,
}

/// A punctual light as baked.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub(crate) struct LightEntry {
    /// Its glTF name, or `light <k>` (k its index in `KHR_lights_punctual.lights`).
    pub(crate) label: String,
    /// Its index in `KHR_lights_punctual.lights`.
    pub(crate) source: Option<u32>,
    /// `color × intensity`.
    pub(crate) intensity: [f32; 3],
}

/// A material as baked.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct MaterialEntry {
    /// Its glTF name, or `material <k>` (k its glTF index), or `default`.
    pub label: String,
    /// Its glTF material index.
    pub(crate) source: Option<u32>,
    pub(crate) base_color: [f32; 3],
    /// Whether a texture multiplies `base_color`.
    pub(crate) textured: bool,
    /// `emissiveFactor × emissiveStrength`.
    pub(crate) emission: [f32; 3],
}

impl Settings {
    /// The settings of a bake of `scene` with `config` (the automatic choices applied).
    pub(crate) fn new(scene: &Scene, config: &BakeConfig, gltf: &str) -> Self {
        let (t, a, o) = (&config.transport, &config.atlas, &config.output);
        let lights = (scene.lights.iter().enumerate())
            .map(|(k, l)| LightEntry {
                label: l.name.clone().unwrap_or_else(|| match l.source {
                    Some(s) => format!("light {s}"),
                    None => format!("light #{k}"),
                }),
                source: l.source,
                intensity: l.intensity.to_array(),
            })
            .collect();
        let materials = (scene.materials.iter())
            .map(|m| MaterialEntry {
                label: m.name.clone().unwrap_or_else(|| match m.source {
                    Some(s) => format!("material {s}"),
                    None => "default".to_string(),
                }),
                source: m.source,
                base_color: m.base_color.to_array(),
                textured: m.base_color_texture.is_some(),
                emission: m.emission.to_array(),
            })
            .collect();
        Settings {
            lightbake: env!("CARGO_PKG_VERSION").to_string(),
            gltf: gltf.to_string(),
            method: config.technique.method().to_string(),
            solver: config.technique.solver().to_string(),
            texels_per_unit: a.texels_per_unit,
            instance_density: a.instance_density.clone(),
            triangle_density: a.triangle_density.clone(),
            max_page_size: a.max_page_size,
            padding: a.padding,
            uv: match a.uv {
                UvMode::Unwrap => "unwrap",
                UvMode::Existing => "existing",
                UvMode::Auto => "auto",
            }
            .to_string(),
            split_junctions: a.split_junctions,
            shadow_cuts: a.shadow_cuts,
            near_contacts: a.near_contacts,
            no_slot_faces: !a.slot_faces,
            no_narrow_faces: !a.narrow_faces,
            share_instances: a.instancing == crate::config::Instancing::Share,
            gather_rays: t.gather_rays,
            light_samples: t.light_samples,
            sky: t.sky.to_array(),
            indirect_only: t.indirect_only,
            seed: t.seed,
            validity: t.validity,
            denoise: t.denoise,
            tolerance: config.solve.tolerance,
            max_iterations: config.solve.max_iterations,
            float: o.float,
            preview_exposure: o.preview_exposure,
            rgbm: o.rgbm,
            seams: o.seams,
            count_rows: t.count_rows,
            input: None,
            probe_budget: None,
            lights,
            materials,
            emissive: Sources::new(scene).emissive,
        }
    }

    /// The bake's configuration, with no automatic choice left to make (`auto: None`): what a
    /// fresh bake with the same fixed settings runs with.
    pub fn config(&self) -> Result<BakeConfig> {
        let mut c = BakeConfig::medium();
        c.technique = Technique::from_names(&self.method, &self.solver)?;
        let a = &mut c.atlas;
        a.texels_per_unit = self.texels_per_unit;
        a.instance_density = self.instance_density.clone();
        a.triangle_density = self.triangle_density.clone();
        a.max_page_size = self.max_page_size;
        a.padding = self.padding;
        a.uv = match self.uv.as_str() {
            "unwrap" => UvMode::Unwrap,
            "existing" => UvMode::Existing,
            _ => UvMode::Auto,
        };
        a.split_junctions = self.split_junctions;
        a.shadow_cuts = self.shadow_cuts;
        a.near_contacts = self.near_contacts;
        a.slot_faces = !self.no_slot_faces;
        a.narrow_faces = !self.no_narrow_faces;
        if self.share_instances {
            a.instancing = crate::config::Instancing::Share;
        }
        let t = &mut c.transport;
        t.gather_rays = self.gather_rays;
        t.light_samples = self.light_samples;
        t.sky = Vec3::from(self.sky);
        t.indirect_only = self.indirect_only;
        t.seed = self.seed;
        t.validity = self.validity;
        t.denoise = self.denoise;
        t.count_rows = self.count_rows;
        c.solve.tolerance = self.tolerance;
        c.solve.max_iterations = self.max_iterations;
        let o = &mut c.output;
        o.float = self.float;
        o.preview_exposure = self.preview_exposure;
        o.rgbm = self.rgbm;
        o.seams = self.seams;
        c.auto = None;
        Ok(c)
    }
}

/// A kept transport, read back.
#[derive(Clone, Debug)]
pub struct Kept {
    /// How the bake ran, and the lights and materials it was baked with.
    pub settings: Settings,
    /// The fields the solver, denoiser, fill and pages read (see the module docs); the others
    /// are empty.
    pub(crate) texels: Texels,
    /// Per texel: its material (an index into `settings.materials`).
    pub(crate) material: Vec<u32>,
    /// Rows, escape fractions, direct light by source (`direct` is empty: relight makes it).
    pub(crate) transport: Transport,
    /// Per texel, direct light as the bake summed it (section 5).
    pub(crate) direct: Vec<Vec3>,
    /// Seam samples only (`edges` is empty).
    pub(crate) seams: Seams,
    /// The bake's lightmap layout (section 7; `None` with shared meshes).
    pub(crate) atlas: Option<Atlas>,
    /// Per texel, the validity pass's jitter fraction (section 8; `texels.jitter` stays empty).
    pub(crate) jitter: Vec<f32>,
    /// The divided texels' cell maps (section 8; `texels.cuts` stays empty).
    pub(crate) cuts: crate::texels::Cuts,
}

/// Per texel: the material of its main triangle.
pub(crate) fn texel_materials(scene: &Scene, texels: &Texels) -> Vec<u32> {
    (texels.triangle.iter())
        .map(|&t| scene.instances[scene.triangle_instance[t as usize] as usize].material)
        .collect()
}

/// The scene hash: the baked glTF's files and the settings block.
fn scene_hash(gltf_files: &[&[u8]], settings: &[u8]) -> [u8; 32] {
    let mut h = blake3::Hasher::new();
    for bytes in gltf_files {
        h.update(&(bytes.len() as u64).to_le_bytes());
        h.update(bytes);
    }
    h.update(settings);
    *h.finalize().as_bytes()
}

/// The file's bytes. `gltf_files` are the baked glTF's files as written (`.gltf` then `.bin`,
/// or the `.glb`); `transport` holds direct light by source.
pub(crate) fn encode(
    settings: &Settings,
    gltf_files: &[&[u8]],
    texels: &Texels,
    material: &[u32],
    transport: &Transport,
    seams: &Seams,
    atlas: &Atlas,
) -> Result<Vec<u8>> {
    let n = texels.len();
    let sources = transport.sources.len();
    if transport.direct_terms.len() != n * sources
        || transport.len() != n
        || transport.escape.len() != n
    {
        return Err(Error::Internal(
            "the transport holds no direct light by source: it cannot be kept".to_string(),
        ));
    }
    let json = serde_json::to_vec(settings)
        .map_err(|e| Error::Internal(format!("cannot serialise the bake's settings: {e}")))?;
    let mut w = Writer::default();
    w.u64(json.len() as u64);
    w.0.extend_from_slice(&json);
    w.u32(n as u32);
    w.u32(sources as u32);
    w.u32(texels.pages.len() as u32);
    for p in &texels.pages {
        w.u32(p.width);
        w.u32(p.height);
    }
    texels.page.iter().for_each(|&p| w.u32(p));
    texels.xy.iter().flatten().for_each(|&v| w.u32(v));
    for field in [
        &texels.position,
        &texels.normal,
        &texels.du,
        &texels.dv,
        &texels.albedo,
        &texels.emission,
    ] {
        field.iter().for_each(|&v| w.vec3(v));
    }
    material.iter().for_each(|&m| w.u32(m));
    w.u32(texels.invalid.len() as u32);
    texels.invalid.iter().for_each(|&i| w.u32(i));
    transport.escape.iter().for_each(|&e| w.f32(e));
    (0..n).for_each(|i| w.u32(transport.row(i).count() as u32));
    for i in 0..n {
        for (j, f) in transport.row(i) {
            w.u32(j);
            w.f32(f);
        }
    }
    transport.direct_terms.iter().for_each(|&v| w.vec3(v));
    transport.direct.iter().for_each(|&v| w.vec3(v));
    w.u32(seams.samples.len() as u32);
    for s in &seams.samples {
        s.page.iter().for_each(|&p| w.u32(p));
        s.uv.iter().for_each(|&uv| {
            w.f32(uv.x);
            w.f32(uv.y);
        });
    }
    if atlas.shared.is_empty() && !atlas.reused_input_uvs {
        w.u32(1);
        w.f32(atlas.texels_per_unit);
        w.u32(atlas.pages.len() as u32);
        for p in &atlas.pages {
            w.u32(p.width);
            w.u32(p.height);
        }
        w.u32(atlas.instances.len() as u32);
        for inst in &atlas.instances {
            w.u32(inst.xref.len() as u32);
            inst.xref.iter().for_each(|&x| w.u32(x));
            inst.uv.iter().for_each(|uv| {
                w.f32(uv.x);
                w.f32(uv.y);
            });
            w.u32(inst.triangles.len() as u32);
            inst.triangles.iter().flatten().for_each(|&v| w.u32(v));
            inst.triangle_page.iter().for_each(|&p| w.u32(p));
        }
    } else {
        w.u32(0);
    }
    (0..n).for_each(|i| w.f32(texels.jitter.get(i).copied().unwrap_or(1.0)));
    let divided: Vec<_> = texels.cuts.entries().collect();
    w.u32(divided.len() as u32);
    for (i, map) in divided {
        w.u32(i);
        map.iter().for_each(|&j| w.u32(j));
    }
    let body = w.0;
    let mut out = Vec::with_capacity(body.len() + 100);
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&VERSION.to_le_bytes());
    out.extend_from_slice(&scene_hash(gltf_files, &json));
    out.extend_from_slice(&(body.len() as u64).to_le_bytes());
    out.extend_from_slice(&body);
    out.extend_from_slice(blake3::hash(&body).as_bytes());
    Ok(out)
}

/// The files of the baked glTF `gltf` (`.gltf` then its `.bin`, or the `.glb`), as the scene
/// hash reads them.
pub(crate) fn gltf_files(gltf: &Path) -> Result<Vec<Vec<u8>>> {
    let main = std::fs::read(gltf).map_err(|e| Error::io(gltf, e))?;
    let mut files = vec![main];
    if gltf.extension().and_then(|e| e.to_str()) == Some("gltf") {
        let bin = gltf.with_extension("bin");
        if bin.exists() {
            files.push(std::fs::read(&bin).map_err(|e| Error::io(&bin, e))?);
        }
    }
    Ok(files)
}

/// `<stem>.transport` beside the baked glTF `gltf`.
pub fn path_beside(gltf: &Path) -> PathBuf {
    gltf.with_extension("transport")
}

/// Reads the transport kept beside the baked glTF `gltf` (see the module docs for what is
/// refused).
pub fn read(gltf: &Path) -> Result<Kept> {
    let path = path_beside(gltf);
    let bytes = std::fs::read(&path).map_err(|e| {
        Error::invalid(
            &path,
            format!("cannot read it ({e}): bake with --keep-transport to write it"),
        )
    })?;
    let bad = |what: String| Error::invalid(&path, what);
    if bytes.len() < MAGIC.len() || &bytes[..MAGIC.len()] != MAGIC {
        return Err(bad("not a lightbake transport file".to_string()));
    }
    let mut r = Reader {
        bytes: &bytes,
        at: MAGIC.len(),
    };
    let truncated = |_| bad(format!("truncated ({} bytes)", bytes.len()));
    let version = r.u32().map_err(truncated)?;
    if version != VERSION {
        return Err(bad(format!(
            "transport format version {version}; this lightbake reads version {VERSION}: bake again with --keep-transport"
        )));
    }
    let hash: [u8; 32] = r.take(32).map_err(truncated)?.try_into().unwrap();
    let body_len = r.u64().map_err(truncated)? as usize;
    let expected = r.at + body_len + 32;
    if bytes.len() != expected {
        return Err(bad(format!(
            "truncated or damaged: {} bytes, the header says {expected}",
            bytes.len()
        )));
    }
    let body = &bytes[r.at..r.at + body_len];
    if blake3::hash(body).as_bytes() != &bytes[expected - 32..] {
        return Err(bad(
            "damaged: the body's checksum does not match".to_string()
        ));
    }
    let mut r = Reader { bytes: body, at: 0 };
    let (kept, json) = decode(&mut r).map_err(|what| bad(format!("malformed: {what}")))?;
    let files = gltf_files(gltf)?;
    let files: Vec<&[u8]> = files.iter().map(Vec::as_slice).collect();
    if scene_hash(&files, json) != hash {
        return Err(bad(format!(
            "stale or foreign: it was not made with {} as it is now (baked again, edited, or another scene's); bake again with --keep-transport",
            gltf.display()
        )));
    }
    if kept.settings.gltf != gltf.file_name().and_then(|n| n.to_str()).unwrap_or("") {
        return Err(bad(format!(
            "foreign: it belongs to {}, not {}",
            kept.settings.gltf,
            gltf.display()
        )));
    }
    Ok(kept)
}

/// The body, parsed, and its settings block as written; an error says what is inconsistent.
/// The sections in the order [`encode`] writes them.
fn decode<'a>(r: &mut Reader<'a>) -> std::result::Result<(Kept, &'a [u8]), String> {
    let json_len = r.u64()? as usize;
    let json = r.take(json_len)?;
    let settings: Settings = serde_json::from_slice(json).map_err(|e| format!("settings: {e}"))?;
    let n = r.u32()? as usize;
    let sources = r.u32()? as usize;
    let pages = r.u32()? as usize;
    if sources != settings.lights.len() + settings.emissive.len() {
        return Err(format!(
            "{sources} sources, the settings name {}",
            settings.lights.len() + settings.emissive.len()
        ));
    }
    let (texels, material) = decode_texels(r, n, pages, settings.materials.len())?;
    let mut transport = decode_rows(r, n)?;
    transport.direct_terms = r.vec3s(n * sources)?;
    let direct = r.vec3s(n)?;
    transport.sources = Sources {
        lights: settings.lights.len(),
        emissive: settings.emissive.clone(),
        ..Default::default()
    };
    let seams = decode_seams(r, pages)?;
    let atlas = decode_atlas(r)?;
    let jitter = r.f32s(n)?;
    let cuts = decode_cuts(r, n)?;
    if r.at != r.bytes.len() {
        return Err(format!(
            "{} bytes after the last section",
            r.bytes.len() - r.at
        ));
    }
    let kept = Kept {
        settings,
        texels,
        material,
        transport,
        direct,
        seams,
        atlas,
        jitter,
        cuts,
    };
    Ok((kept, json))
}

/// The texels' section: `pages` page sizes, each of the `n` texels' page, place, raster values
/// and material (fewer than `materials`), and the invalid texels.
fn decode_texels(
    r: &mut Reader,
    n: usize,
    pages: usize,
    materials: usize,
) -> std::result::Result<(Texels, Vec<u32>), String> {
    let mut texels = Texels::default();
    for _ in 0..pages {
        let (width, height) = (r.u32()?, r.u32()?);
        texels.pages.push(PageSize { width, height });
        texels
            .index
            .push(vec![NO_TEXEL; width as usize * height as usize]);
    }
    texels.page = r.u32s(n)?;
    texels.xy = r.u32s(2 * n)?.chunks(2).map(|c| [c[0], c[1]]).collect();
    for i in 0..n {
        let (p, [x, y]) = (texels.page[i] as usize, texels.xy[i]);
        let size = texels
            .pages
            .get(p)
            .ok_or(format!("texel {i}: no page {p}"))?;
        if x >= size.width || y >= size.height {
            return Err(format!("texel {i} lies outside its page"));
        }
        texels.index[p][(y * size.width + x) as usize] = i as u32;
    }
    texels.position = r.vec3s(n)?;
    texels.normal = r.vec3s(n)?;
    texels.du = r.vec3s(n)?;
    texels.dv = r.vec3s(n)?;
    texels.albedo = r.vec3s(n)?;
    texels.emission = r.vec3s(n)?;
    let material = r.u32s(n)?;
    if material.iter().any(|&m| m as usize >= materials) {
        return Err("a texel's material is out of range".to_string());
    }
    let invalid = r.u32()? as usize;
    texels.invalid = r.u32s(invalid)?;
    if texels.invalid.iter().any(|&i| i as usize >= n) {
        return Err("an invalid texel id is out of range".to_string());
    }
    Ok((texels, material))
}

/// The rows' section: per texel its escaping share and its row of `(texel, factor)` pairs.
fn decode_rows(r: &mut Reader, n: usize) -> std::result::Result<Transport, String> {
    let escape = r.f32s(n)?;
    let lengths = r.u32s(n)?;
    let entries: usize = lengths.iter().map(|&l| l as usize).sum();
    let pairs = r.take(entries * 8)?;
    let mut at = 0;
    let rows = lengths.iter().map(|&len| {
        let row = &pairs[at..at + len as usize * 8];
        at += len as usize * 8;
        row.chunks_exact(8).map(|e| {
            let word = |k: usize| u32::from_le_bytes(e[k..k + 4].try_into().unwrap());
            (word(0), f32::from_bits(word(4)))
        })
    });
    let transport = Transport::from_rows(rows, escape);
    if (0..n).any(|i| transport.row(i).any(|(j, _)| j as usize >= n)) {
        return Err("a row names a texel out of range".to_string());
    }
    Ok(transport)
}

/// The seams' section: sample pairs on the `pages` pages.
fn decode_seams(r: &mut Reader, pages: usize) -> std::result::Result<Seams, String> {
    let samples = r.u32()? as usize;
    let mut seams = Seams::default();
    for _ in 0..samples {
        let page = [r.u32()?, r.u32()?];
        let v = r.f32s(4)?;
        if page.iter().any(|&p| p as usize >= pages) {
            return Err("a seam sample's page is out of range".to_string());
        }
        seams.samples.push(SeamSample {
            page,
            uv: [Vec2::new(v[0], v[1]), Vec2::new(v[2], v[3])],
        });
    }
    Ok(seams)
}

/// The atlas' section, when the bake kept its atlas: page sizes and each instance's charts.
fn decode_atlas(r: &mut Reader) -> std::result::Result<Option<Atlas>, String> {
    if r.u32()? == 0 {
        return Ok(None);
    }
    let texels_per_unit = r.f32s(1)?[0];
    let pages = r.u32()? as usize;
    let sizes = r.u32s(2 * pages)?;
    let pages: Vec<PageSize> = sizes
        .chunks(2)
        .map(|c| PageSize {
            width: c[0],
            height: c[1],
        })
        .collect();
    let count = r.u32()? as usize;
    let mut instances = Vec::with_capacity(count.min(1 << 20));
    for _ in 0..count {
        let verts = r.u32()? as usize;
        let xref = r.u32s(verts)?;
        let uv = r.f32s(2 * verts)?;
        let uv = uv.chunks(2).map(|c| Vec2::new(c[0], c[1])).collect();
        let tris = r.u32()? as usize;
        let corners = r.u32s(3 * tris)?;
        let triangles: Vec<[u32; 3]> = corners.chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
        if triangles.iter().flatten().any(|&v| v as usize >= verts) {
            return Err("an atlas triangle names a vertex out of range".to_string());
        }
        let triangle_page = r.u32s(tris)?;
        if triangle_page.iter().any(|&p| p as usize >= pages.len()) {
            return Err("an atlas triangle's page is out of range".to_string());
        }
        instances.push(InstanceUv {
            xref,
            uv,
            triangles,
            triangle_page,
        });
    }
    Ok(Some(Atlas {
        pages,
        instances,
        texels_per_unit,
        reused_input_uvs: false,
        shared: Vec::new(),
    }))
}

/// The cell maps of the divided texels, in texel order.
fn decode_cuts(r: &mut Reader, n: usize) -> std::result::Result<crate::texels::Cuts, String> {
    let divided = r.u32()? as usize;
    let mut entries = Vec::with_capacity(divided.min(n));
    for _ in 0..divided {
        let i = r.u32()?;
        let cells = r.u32s(64)?;
        let prior = entries.last().map(|e: &(u32, [u32; 64])| e.0);
        if i as usize >= n || cells.iter().any(|&j| j as usize >= n) || prior >= Some(i) {
            return Err("a divided texel's cell map is out of range or order".to_string());
        }
        entries.push((i, cells.try_into().unwrap()));
    }
    Ok(crate::texels::Cuts::from_entries(n, entries))
}

#[derive(Default)]
struct Writer(Vec<u8>);

impl Writer {
    fn u32(&mut self, v: u32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn u64(&mut self, v: u64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn f32(&mut self, v: f32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn vec3(&mut self, v: Vec3) {
        v.to_array().iter().for_each(|&c| self.f32(c));
    }
}

struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, len: usize) -> std::result::Result<&'a [u8], String> {
        let end = self.at.checked_add(len).filter(|&e| e <= self.bytes.len());
        let end = end.ok_or_else(|| format!("a section runs past the end at byte {}", self.at))?;
        let out = &self.bytes[self.at..end];
        self.at = end;
        Ok(out)
    }
    fn u32(&mut self) -> std::result::Result<u32, String> {
        Ok(u32::from_le_bytes(self.take(4)?.try_into().unwrap()))
    }
    fn u64(&mut self) -> std::result::Result<u64, String> {
        Ok(u64::from_le_bytes(self.take(8)?.try_into().unwrap()))
    }
    fn u32s(&mut self, n: usize) -> std::result::Result<Vec<u32>, String> {
        let bytes = self.take(n.checked_mul(4).ok_or("length overflows")?)?;
        Ok(bytes
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes(c.try_into().unwrap()))
            .collect())
    }
    fn f32s(&mut self, n: usize) -> std::result::Result<Vec<f32>, String> {
        Ok(self.u32s(n)?.into_iter().map(f32::from_bits).collect())
    }
    fn vec3s(&mut self, n: usize) -> std::result::Result<Vec<Vec3>, String> {
        let v = self.f32s(n.checked_mul(3).ok_or("length overflows")?)?;
        Ok(v.chunks_exact(3).map(Vec3::from_slice).collect())
    }
}
