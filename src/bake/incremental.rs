//! Incremental re-bake (`bake --since OLD/x.gltf`): after an edit that only moves, removes or
//! adds nodes, re-trace only the rays the edited nodes can have changed, reuse every other row
//! of the previous bake's kept transport ([`super::kept`]), and solve again.
//!
//! ## What the previous bake must have kept, and why it is enough
//!
//! A Monte Carlo row (`transport::montecarlo`) is a deterministic function of the texel, the
//! seed and the scene: its rays' origins and directions come from a stream seeded by
//! (seed, texel) and the texel's footprint, and only where each ray *ends* reads the geometry.
//! So the rays need not be stored: they are drawn again, with no tracing, exactly as the bake
//! drew them (`row_rays`). A ray whose line (gathering rays: the half-line; light samples and
//! punctual shadow rays: the segment to the light) meets neither the old nor the new bounds of
//! a moved node ends where it ended before: nothing else moved. Only the rays that meet those
//! bounds (the *flagged* rays) are traced again, once in the old scene (what they added to the
//! kept row) and once in the new (what they add now), and the row is patched: the old hit's
//! count down, the new hit's up, the escape count and the direct light moved by the
//! difference. Rows of texels that changed themselves (on a moved node, or whose validity pass
//! moved their sample point or divided them) are traced again whole. A conservative test is
//! cheap to make exact: a flagged ray that ends where it did changes nothing.
//!
//! A **removed** node is a moved one with no new place: its instances leave the BVH
//! (`Tracer::without`) but keep their triangle ids and texels, so that every other texel,
//! triangle and kept row keeps its index; rays meeting its old bounds are flagged as above;
//! its texels are invalid with empty rows (black, solved to nothing), and the glTF is written
//! from the input's instances only (`Baked::written`): no primitive reads them, their
//! atlas space stays unused. The input's node graph is matched against the previous one
//! (`InputRecord::graph`): the same nodes in order less the removed (renumbered), each kept
//! node's children and each scene's roots those of before less the removed, and everything
//! but the node graph unchanged (`InputRecord::content`).
//!
//! An **added** node is the other way round: the node graphs are matched by their longest
//! common run of nodes (each compared but for its transform and children), the input's others
//! are added (their children added too, each kept node's children and each scene's roots those
//! of before plus the added). The document may have grown with them: every array element of
//! before (meshes, accessors, buffer views, materials, ...) the same and new ones appended,
//! every binary file the old bytes and new ones after (`InputRecord::parts`). The added
//! instances go after the old ones in the scene (uncut: the junction split would cut old
//! receivers where they stand, and move old texels), so every old triangle keeps its id; they
//! alone are unwrapped (`append_charts`: xatlas on a scene of them, at the old bake's uniform
//! density, without per-region factors) onto pages after the old ones, and since texels are
//! numbered by (page, y, x) every old texel keeps its id, page and place. Their rows are traced
//! whole; rays of old rows that meet their bounds are flagged as above (before: what the old
//! scene gave; now: what the new one gives); the validity pass runs again near them. The glTF
//! is written in the input's instance order through `Baked::written`.
//!
//! So the kept file needs no per-ray record, only: the input it was baked from (a hash of
//! everything but node transforms, and each node's transform: [`InputRecord`]), the rows as
//! hit counts (already kept: `f · K` is exact in f32), and the direct light as the bake summed
//! it (so reused rows are reused bit for bit; the kept per-source terms round differently).
//! Two more sections only save time: the atlas (the old scene is laid out again without
//! unwrapping) and the validity pass's jitter and cell maps (the old texels are the kept ones,
//! with no validity pass over the old scene, and the new scene's pass runs only near what
//! moved: `texels::validity::fix_near`).
//!
//! ## What stays, and when it bakes in full instead
//!
//! The atlas is **not** a function of each mesh alone: the junction split cuts a floor where a
//! chair's legs meet it, and xatlas packs every chart of the scene together, so a fresh bake
//! of the edited scene may lay out every chart elsewhere. The incremental bake therefore keeps
//! the previous bake's geometry and layout: it lays the old scene out again (the old node
//! transforms put back, the old bake's fixed settings: deterministic, and checked texel by
//! texel against the kept texels), then moves the moved instances' vertices, cut vertices
//! included, to their new places. Every chart keeps its page and texels. The cuts stay where
//! the old bake made them: a moved chair's feet are not cut into the floor at their new place
//! (its legs stand on whole floor texels there, which the validity pass handles as for an
//! uncut scene) and the floor keeps the cuts where they stood. A plain `bake` cuts anew.
//!
//! It bakes in full (with the caller's settings, and says why) when the input changed in more
//! than node transforms, removals and additions (a mesh, accessor or material of before
//! changed, bytes changed rather than appended, a light), when nodes were re-parented, when a
//! moved, removed or added node carries a light or an emissive material (every row's direct
//! light would change), when the scene's extent changed (an added node beyond the old bounds:
//! every ray's offset changes), when the old bake cannot be laid out again to the same texels
//! (another lightbake, other settings), when it was itself an incremental bake that removed or
//! added nodes (its layout is not its input's node graph), when a removal or an addition meets
//! an atlas that shares meshes (an addition: or reuses the input's UVs), or when its technique
//! keeps no Monte Carlo rows. A changed node (its mesh or name) is matched as one removed and
//! one added.
//!
//! The incremental bake runs with the previous bake's settings (`kept::Settings::config`, the
//! automatic choices as they were made: no new plan), which a kept bake's single final run
//! (no pilot runs mixed in, `bake::light`) makes exact. With nothing moved every row is reused
//! and the output is the previous bake's, byte for byte.

use std::collections::BTreeMap;
use std::ops::Range;
use std::path::Path;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::time::Instant;

use glam::{Vec2, Vec3};
use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::kept::{self, Kept};
use super::{BakeReport, Lighting, Prepared, pilot, timed};
use crate::config::{BakeConfig, FormFactors, Technique};
use crate::lights::{Emitters, punctual_irradiance, triangle_point};
use crate::sampling::{Rng, cosine_hemisphere, frame, hammersley, power_weight};
use crate::scene::{self, LightKind, Scene};
use crate::shard::Alone;
use crate::texels::{RayEnd, Texels};
use crate::trace::Tracer;
use crate::transport::montecarlo::{self, Context, PUNCTUAL_GRID, RowScratch};
use crate::transport::rows::{self, ChunkRows};
use crate::transport::{Sources, Surfaces};
use crate::{Error, Progress, Result, solve, texels};

/// The transform keys of a glTF node.
const TRANSFORM_KEYS: [&str; 4] = ["matrix", "translation", "rotation", "scale"];

/// The input a bake read, as `bake --since` compares it: a hash of everything but the nodes'
/// transforms, and each node's transform as written.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct InputRecord {
    /// blake3 (hex) of the glTF JSON with every node's transform keys removed, a GLB's binary
    /// chunk and every external buffer and image.
    pub(crate) hash: String,
    /// Per glTF node: its `matrix`, `translation`, `rotation` and `scale` as written (an
    /// object holding those present).
    pub(crate) nodes: Vec<Value>,
    /// The node transforms the bake's layout (junction cuts, atlas) was made with, when not
    /// `nodes`: an incremental bake keeps the layout of the bake it started from, so the next
    /// one lays that out again.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(crate) layout: Option<Vec<Value>>,
    /// blake3 (hex) of everything but the node graph (the glTF JSON without `nodes`, `scenes`
    /// and `scene`, and the binary and external files, as `hash`): what must not change for an
    /// edit that removes nodes to be baked incrementally. Absent in files that predate it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(crate) content: Option<String>,
    /// The node graph as read: `{"nodes": [..], "scenes": [..], "scene": n}` (nodes whole,
    /// transforms included), so that the previous scene can be loaded again after nodes were
    /// removed from the input.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(crate) graph: Option<Value>,
    /// Everything but the node graph again, part by part ([`Parts`]): what an edit that adds
    /// nodes may append to (meshes, accessors, buffer bytes, ...) without changing what was
    /// there. Absent in files that predate it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(crate) parts: Option<Parts>,
}

/// The input but its node graph, hashed part by part, so that an edit that only appends to it
/// (the meshes, accessors, buffer views, materials and bytes of added nodes) is told from one
/// that changes what the previous bake read ([`Parts::grown_into`]).
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub(crate) struct Parts {
    /// Per top-level array of the glTF JSON but the node graph: each element's hash (a
    /// buffer's without its `byteLength`, which grows when bytes are appended to it).
    lists: BTreeMap<String, Vec<String>>,
    /// Per other top-level key but the node graph: its value's hash.
    values: BTreeMap<String, String>,
    /// The GLB binary chunk (empty when there is none), then every external file in document
    /// order: its length in bytes and its hash.
    files: Vec<(u64, String)>,
}

impl Parts {
    /// The parts of the document `json` (graph keys included or not: they are skipped) with
    /// its GLB chunk `blob` and external `files`.
    fn of(json: &Value, blob: &[u8], files: &[Vec<u8>]) -> Result<Parts> {
        let mut parts = Parts::default();
        let Some(obj) = json.as_object() else {
            return Ok(parts);
        };
        for (key, value) in obj
            .iter()
            .filter(|(k, _)| !GRAPH_KEYS.contains(&k.as_str()))
        {
            match value.as_array() {
                Some(list) => {
                    let hashes = (list.iter())
                        .map(|v| {
                            let mut v = v.clone();
                            if key == "buffers" {
                                v.as_object_mut().map(|o| o.remove("byteLength"));
                            }
                            json_hash(&v)
                        })
                        .collect::<Result<_>>()?;
                    parts.lists.insert(key.clone(), hashes);
                }
                None => {
                    parts.values.insert(key.clone(), json_hash(value)?);
                }
            }
        }
        parts.files = (std::iter::once(blob).chain(files.iter().map(Vec::as_slice)))
            .map(|b| (b.len() as u64, hex_hash(b)))
            .collect();
        Ok(parts)
    }

    /// Whether the document `json` (with `blob` and `files`) only appends to what `self`
    /// recorded: every array's elements those of before followed by new ones, every other
    /// value the same, every binary file the old bytes followed by new ones, or what changed.
    fn grown_into(&self, json: &Value, blob: &[u8], files: &[Vec<u8>]) -> Result<Fallback<()>> {
        let now = Parts::of(json, blob, files)?;
        if now.values != self.values {
            let key = (self.values.iter())
                .find(|(k, v)| now.values.get(*k) != Some(v))
                .or_else(|| {
                    now.values
                        .iter()
                        .find(|(k, _)| !self.values.contains_key(*k))
                })
                .map_or("", |(k, _)| k.as_str());
            return Ok(Err(format!("`{key}` changed")));
        }
        for (key, before) in &self.lists {
            let after = now.lists.get(key).map_or(&[][..], Vec::as_slice);
            if !after.starts_with(before) {
                return Ok(Err(format!("`{key}` changed, not only appended to")));
            }
        }
        let all: Vec<&[u8]> = std::iter::once(blob)
            .chain(files.iter().map(Vec::as_slice))
            .collect();
        if all.len() < self.files.len() {
            return Ok(Err("a binary file was removed".to_string()));
        }
        for ((len, hash), bytes) in self.files.iter().zip(all) {
            let len = *len as usize;
            if bytes.len() < len || hex_hash(&bytes[..len]) != *hash {
                return Ok(Err("binary data changed, not only appended to".to_string()));
            }
        }
        Ok(Ok(()))
    }
}

/// blake3 (hex) of `bytes`.
fn hex_hash(bytes: &[u8]) -> String {
    // 128 bits: the record holds one per array element.
    blake3::hash(bytes).to_hex()[..32].to_string()
}

/// blake3 (hex) of `value` as JSON.
fn json_hash(value: &Value) -> Result<String> {
    let bytes = serde_json::to_vec(value).map_err(|e| Error::Internal(e.to_string()))?;
    Ok(hex_hash(&bytes))
}

/// The glTF keys of the node graph ([`InputRecord::graph`]).
const GRAPH_KEYS: [&str; 3] = ["nodes", "scenes", "scene"];

/// The record of the input at `path`.
pub(crate) fn input_record(path: &Path) -> Result<InputRecord> {
    let (json, blob, files) = read_input(path)?;
    record_of(json, blob.as_deref(), &files)
}

/// A glTF document as read: its JSON, its GLB binary chunk and its external files' bytes.
type Document = (Value, Option<Vec<u8>>, Vec<Vec<u8>>);

/// The document at `path`.
fn read_input(path: &Path) -> Result<Document> {
    let (json, blob, _) = scene::read_document(path)?;
    let files: Vec<Vec<u8>> = (scene::external_files(path)?.iter())
        .map(|file| std::fs::read(file).map_err(|e| Error::io(file, e)))
        .collect::<Result<_>>()?;
    Ok((json, blob, files))
}

/// The record of the document `json` with its GLB chunk `blob` and external `files`.
fn record_of(mut json: Value, blob: Option<&[u8]>, files: &[Vec<u8>]) -> Result<InputRecord> {
    let parts = Parts::of(&json, blob.unwrap_or_default(), files)?;
    let graph: serde_json::Map<String, Value> = GRAPH_KEYS
        .iter()
        .filter_map(|&k| Some((k.to_string(), json.get(k)?.clone())))
        .collect();
    let mut rest = json.clone();
    if let Some(obj) = rest.as_object_mut() {
        GRAPH_KEYS.iter().for_each(|k| {
            obj.remove(*k);
        });
    }
    let mut nodes = Vec::new();
    if let Some(list) = json.get_mut("nodes").and_then(Value::as_array_mut) {
        for node in list {
            let mut t = serde_json::Map::new();
            if let Some(obj) = node.as_object_mut() {
                for key in TRANSFORM_KEYS {
                    if let Some(v) = obj.remove(key) {
                        t.insert(key.to_string(), v);
                    }
                }
            }
            nodes.push(Value::Object(t));
        }
    }
    let hash = |json: &Value| -> Result<String> {
        let mut h = blake3::Hasher::new();
        let mut part = |bytes: &[u8]| {
            h.update(&(bytes.len() as u64).to_le_bytes());
            h.update(bytes);
        };
        part(&serde_json::to_vec(json).map_err(|e| Error::Internal(e.to_string()))?);
        part(blob.unwrap_or_default());
        files.iter().for_each(|f| part(f));
        Ok(h.finalize().to_hex().to_string())
    };
    Ok(InputRecord {
        hash: hash(&json)?,
        nodes,
        layout: None,
        content: Some(hash(&rest)?),
        graph: Some(Value::Object(graph)),
        parts: Some(parts),
    })
}

/// What an incremental bake did ([`BakeReport::incremental`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Incremental {
    /// Why it baked in full instead (`None`: it re-traced only what the edit touched).
    pub full: Option<String>,
    /// glTF nodes whose transform changed (the input's indices).
    pub moved_nodes: Vec<u32>,
    /// glTF nodes of the previous bake's input that the input no longer has (its indices).
    pub removed_nodes: Vec<u32>,
    /// glTF nodes of the input that the previous bake's input did not have (the input's
    /// indices): their instances were unwrapped onto pages of their own.
    pub added_nodes: Vec<u32>,
    /// Rows (texels) in the bake.
    pub rows: usize,
    /// Rows traced again whole (texels that changed).
    pub retraced: usize,
    /// Rows patched: some of their rays traced again in the old and the new scene.
    pub patched: usize,
    /// Rays of the patched rows traced again (each in both scenes).
    pub flagged_rays: u64,
    /// The rows re-traced or patched, ascending.
    pub touched_rows: Vec<u32>,
    /// Rays the transport cast: the rows traced whole, and the flagged rays twice (old and new
    /// scene).
    pub rays: u64,
    /// Rays a full trace of every row casts.
    pub full_rays: u64,
    /// Seconds a full trace of every row would have taken at this bake's rate of the re-traced
    /// rows, less what the incremental transport took: the transport time saved (an estimate).
    pub seconds_saved: f64,
}

impl Incremental {
    /// One phrase for the summary.
    pub fn brief(&self) -> String {
        if let Some(why) = &self.full {
            return format!("incremental: baked in full ({why})");
        }
        format!(
            "incremental: {} node(s) moved, {} removed, {} added, {} of {} rows re-traced ({:.2}%) and {} patched ({} rays re-cast), {:.1}% of a full trace's rays, ~{:.1}s of transport saved",
            self.moved_nodes.len(),
            self.removed_nodes.len(),
            self.added_nodes.len(),
            self.retraced,
            self.rows,
            100.0 * self.retraced as f64 / self.rows.max(1) as f64,
            self.patched,
            self.flagged_rays,
            100.0 * self.rays as f64 / self.full_rays.max(1) as f64,
            self.seconds_saved
        )
    }
}

/// Bakes `input` into `out_dir` as [`super::bake`] does, re-using the bake `since` (a
/// `<stem>.gltf`/`.glb` written with `--keep-transport`) where the edit did not reach (see the
/// module docs). The incremental bake runs with `since`'s settings and `config`'s output
/// options; when it bakes in full it runs with `config`, and says why in the report.
pub fn bake_since(
    input: &Path,
    since: &Path,
    out_dir: &Path,
    config: &BakeConfig,
    progress: &dyn Progress,
) -> Result<BakeReport> {
    super::refuse_overwriting_input(input, out_dir)?;
    config.validate()?;
    match compute_since(input, since, config, Retrace::Edited, progress)? {
        Since::Incremental(baked, incremental) => {
            let out_config = baked.config.clone();
            let mut report = super::write(*baked, input, out_dir, &out_config, progress)?;
            report.incremental = Some(incremental);
            Ok(report)
        }
        Since::Full(why) => {
            progress.warn(&format!(
                "{}: incremental bake not possible ({why}): baking in full",
                input.display()
            ));
            let mut report = super::bake(input, out_dir, config, progress)?;
            report.incremental = Some(Incremental {
                full: Some(why),
                ..Default::default()
            });
            Ok(report)
        }
    }
}

/// Which rows an incremental bake traces again.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Retrace {
    /// The rows the edit can have changed (see the module docs).
    Edited,
    /// Every row, whole: a fresh bake on the previous bake's layout and seeds, the yardstick
    /// of the incremental one (tests).
    All,
}

/// An incremental bake in memory, or why it must bake in full.
#[derive(Debug)]
pub enum Since {
    /// The bake, and what it re-traced.
    Incremental(Box<super::Baked>, Incremental),
    /// Why the incremental bake cannot run (a full bake is the answer).
    Full(String),
}

/// Computes the incremental bake of `input` from the kept bake `since` (as [`bake_since`],
/// nothing written), re-tracing what `retrace` says.
pub fn compute_since(
    input: &Path,
    since: &Path,
    config: &BakeConfig,
    retrace: Retrace,
    progress: &dyn Progress,
) -> Result<Since> {
    let kept = kept::read(since)?;
    Ok(match plan(input, &kept, config, retrace, progress)? {
        Ok(Planned {
            prepared,
            incremental,
            mut lighting,
            layout_nodes,
            written,
        }) => {
            // A budget that follows the bake: the kept bake's, else what a full trace's rays
            // afford (this bake's own rays are only those it re-traced).
            if let Some(p) = lighting.config.output.probes.as_mut()
                && p.budget.is_none()
            {
                let full = || p.budget_for(incremental.full_rays);
                p.budget = Some(kept.settings.probe_budget.unwrap_or_else(full));
            }
            let mut baked = super::finish(prepared, lighting, progress)?;
            baked.layout_nodes = Some(layout_nodes);
            if let Some((of_input, input)) = written {
                baked.written = Some(Box::new(written_for_input(&baked, &of_input, &input)));
            }
            Since::Incremental(Box::new(baked), incremental)
        }
        Err(why) => Since::Full(why),
    })
}

/// An incremental bake made ready for `finish`.
struct Planned {
    prepared: Prepared,
    incremental: Incremental,
    lighting: Lighting,
    /// The node transforms of the layout kept.
    layout_nodes: Vec<Value>,
    /// After a removal or an addition: per instance of the input as loaded, the baked
    /// instance, and the input as loaded, for the writer (`written_for_input`).
    written: Option<(Vec<usize>, Scene)>,
}

/// Why an incremental bake cannot run (the outer `Ok(Err(..))`).
type Fallback<T> = std::result::Result<T, String>;

/// The value of a `Fallback`, or a return from the enclosing `Result<Fallback<_>>` function
/// with its reason.
macro_rules! or_full {
    ($fallback:expr) => {
        match $fallback {
            Ok(value) => value,
            Err(why) => return Ok(Err(why)),
        }
    };
}

/// The incremental bake up to the solution, or why it must bake in full: the previous bake
/// laid out again, the edit placed on its layout, the rows it can have changed traced again,
/// solved.
fn plan(
    input: &Path,
    kept: &Kept,
    out: &BakeConfig,
    retrace: Retrace,
    progress: &dyn Progress,
) -> Result<Fallback<Planned>> {
    let Some(old) = &kept.settings.input else {
        return Ok(Err("the kept transport records no input".to_string()));
    };
    let (config, solver) = or_full!(kept_config(kept, out)?);
    let (json, blob, files) = read_input(input)?;
    let now = record_of(json.clone(), blob.as_deref(), &files)?;
    let nodes = or_full!(node_map(old, &now, &json, blob.as_deref(), &files)?);
    let moved_nodes: Vec<u32> = (0..now.nodes.len())
        .filter(|&k| nodes.of_new[k].is_some_and(|o| now.nodes[k] != old.nodes[o as usize]))
        .map(|k| k as u32)
        .collect();

    // The layout: the previous bake's node graph (the input's, when nothing was removed) with
    // the transforms the previous bake's layout was made with put back (the previous bake's
    // own, or those an incremental bake kept), laid out again with the old settings.
    // Deterministic, so it is the old layout; the previous scene is that layout with the
    // nodes moved since placed as the previous bake had them, checked against the kept texels.
    let t = Instant::now();
    let layout_nodes = old.layout.clone().unwrap_or_else(|| old.nodes.clone());
    if layout_nodes.len() != old.nodes.len() {
        return Ok(Err(
            "the previous bake's layout is not its input's node graph (an incremental bake after a removal or an addition)"
                .to_string(),
        ));
    }
    let (layout_loaded, layout_source) =
        scene::load_edited(input, &put_back(&layout_nodes, &old.graph))?;
    let (prev_loaded, _) = scene::load_edited(input, &put_back(&old.nodes, &old.graph))?;
    let (new_loaded, new_source) = super::load(input, progress)?;
    let edit = or_full!(edit_of(
        kept,
        &layout_loaded,
        &prev_loaded,
        &new_loaded,
        &nodes
    ));
    let layout = match &kept.atlas {
        Some(atlas) => or_full!(lay_out_again(
            layout_loaded,
            layout_source,
            atlas,
            &config,
            t
        )?),
        None => super::prepare_loaded(
            layout_loaded,
            layout_source,
            input,
            &config,
            &Alone,
            progress,
            t,
        )?,
    };
    let old = or_full!(previous_bake(layout, kept, &prev_loaded, &edit)?);
    let mut stages = old.stages.clone();
    let edited = or_full!(lay_out_edit(
        &old,
        (&new_loaded, &new_source),
        &edit,
        (&config, retrace),
        &mut stages,
        progress
    )?);
    let (changed, boxes) = retraced(&old, &edited, &edit, retrace);
    let base = Incremental {
        full: None,
        moved_nodes,
        removed_nodes: nodes.removed.clone(),
        added_nodes: nodes.added.clone(),
        ..Default::default()
    };
    let (transport, incremental) = or_full!(rebuild_transport(
        kept,
        &old,
        &edited,
        (&config, &changed, &boxes),
        base,
        &mut stages,
        progress
    )?);

    let t = Instant::now();
    let solution = solve::solve(&transport, &edited.texels, solver, &config.solve, progress)?;
    if !solution.converged {
        progress.warn(&format!(
            "the solver stopped on the iteration cap ({}) at residual {:.2e}, above the tolerance {:.1e}",
            solution.history.len(),
            solution.residual(),
            config.solve.tolerance
        ));
    }
    timed(&mut stages, "solve", t);
    let (k, l) = (config.transport.gather_rays, config.transport.light_samples);
    let n = edited.texels.len();
    let written = (!edit.removed.is_empty() || !edit.added.is_empty()).then(|| {
        let mut of_input = vec![usize::MAX; new_loaded.instances.len()];
        (edit.now_of.iter().enumerate()).for_each(|(k, m)| {
            if let Some(m) = m {
                of_input[*m] = k;
            }
        });
        (edit.added.iter().enumerate()).for_each(|(a, &m)| of_input[m] = edited.first_added + a);
        (of_input, new_loaded)
    });
    let prepared = Prepared {
        scene: edited.scene,
        source: new_source,
        tracer: edited.tracer,
        atlas: edited.atlas,
        texels: edited.texels,
        validity: edited.validity,
        config: config.clone(),
        plan: None,
        density: Default::default(),
        junctions: old.junctions,
        stages: Vec::new(),
        processes: 1,
    };
    let lighting = Lighting {
        config,
        plan: None,
        stages,
        last: pilot::FinalBake {
            transport,
            solution,
            gather_rays: k,
            light_samples: l,
            texel_gather_rays: vec![k as f32; n],
        },
    };
    Ok(Ok(Planned {
        prepared,
        incremental,
        lighting,
        layout_nodes,
        written,
    }))
}

/// The previous bake's settings with the caller's output options, and its solver: only a bake
/// that kept Monte Carlo rows can be continued.
fn kept_config(
    kept: &Kept,
    out: &BakeConfig,
) -> Result<Fallback<(BakeConfig, crate::config::RowSolver)>> {
    let mut config = kept.settings.config()?;
    let Technique::Stored {
        form_factors: FormFactors::MonteCarlo,
        solver,
    } = config.technique
    else {
        return Ok(Err(format!(
            "the previous bake's {} technique keeps no Monte Carlo rows",
            config.technique
        )));
    };
    // The output options are the caller's; everything that shapes the light is the old bake's.
    config.output = out.output.clone();
    config.max_memory = out.max_memory;
    config.transport.split_direct = true;
    Ok(Ok((config, solver)))
}

/// The input's nodes in the previous bake's graph, the nodes it no longer has and those it
/// has anew; `Err` when the input changed in more than that.
fn node_map(
    old: &InputRecord,
    now: &InputRecord,
    json: &Value,
    blob: Option<&[u8]>,
    files: &[Vec<u8>],
) -> Result<Fallback<NodeMap>> {
    Ok(match (&old.content, &old.graph, &now.graph) {
        (Some(content), Some(before), Some(after)) => {
            // Added nodes may bring meshes, accessors, materials and bytes of their own:
            // appended, with nothing the previous bake read changed.
            if now.content.as_ref() != Some(content) {
                let grown = match &old.parts {
                    Some(parts) => parts.grown_into(json, blob.unwrap_or_default(), files)?,
                    None => Err("the previous bake's record predates additions".to_string()),
                };
                if let Err(why) = grown {
                    return Ok(Err(format!(
                        "the input changed in more than node transforms, removals and additions ({why}: meshes, materials, lights or textures)"
                    )));
                }
            }
            match_nodes(before, after)
        }
        // A record from before removals were baked incrementally: moves only.
        _ if now.hash != old.hash || now.nodes.len() != old.nodes.len() => Err(
            "the input changed in more than node transforms (meshes, materials, lights, textures or nodes)"
                .to_string(),
        ),
        _ => Ok(NodeMap {
            of_new: (0..now.nodes.len() as u32).map(Some).collect(),
            removed: Vec::new(),
            added: Vec::new(),
        }),
    })
}

/// An edit of the input's glTF that puts back a node graph (`None`: the input's own) and the
/// node transforms `nodes`.
fn put_back(nodes: &[Value], graph: &Option<Value>) -> impl Fn(&mut Value) + use<> {
    let (nodes, graph) = (nodes.to_vec(), graph.clone());
    move |json: &mut Value| {
        if let (Some(obj), Some(Value::Object(graph))) = (json.as_object_mut(), &graph) {
            GRAPH_KEYS.iter().for_each(|k| {
                obj.remove(*k);
            });
            obj.extend(graph.iter().map(|(k, v)| (k.clone(), v.clone())));
        }
        let Some(list) = json.get_mut("nodes").and_then(Value::as_array_mut) else {
            return;
        };
        for (node, t) in list.iter_mut().zip(&nodes) {
            if let (Some(obj), Some(t)) = (node.as_object_mut(), t.as_object()) {
                TRANSFORM_KEYS.iter().for_each(|k| {
                    obj.remove(*k);
                });
                obj.extend(t.iter().map(|(k, v)| (k.clone(), v.clone())));
            }
        }
    }
}

/// What the edit did to the layout's instances.
struct Edit {
    /// Per instance of the layout, the input's instance (`None`: its node was removed).
    now_of: Vec<Option<usize>>,
    /// The input's instances placed by added nodes.
    added: Vec<usize>,
    /// The layout's instances whose node was removed.
    removed: Vec<usize>,
    /// Instances the previous bake had placed away from the layout.
    moved_before: Vec<usize>,
    /// Instances the input places away from the layout.
    moved_now: Vec<usize>,
    /// Instances the input places away from where the previous bake had them.
    moved: Vec<usize>,
}

/// The edit from the layout (`layout`), the previous bake's scene (`prev`) and the input's
/// (`now`); `Err` for what an incremental bake cannot follow (emitters added or removed,
/// additions or removals on shared or reused atlases, other materials).
fn edit_of(
    kept: &Kept,
    layout: &Scene,
    prev: &Scene,
    now: &Scene,
    nodes: &NodeMap,
) -> Fallback<Edit> {
    let (now_of, added) = instance_map(layout, now, nodes)?;
    let same: Vec<Option<usize>> = (0..layout.instances.len()).map(Some).collect();
    let removed: Vec<usize> = (0..now_of.len()).filter(|&k| now_of[k].is_none()).collect();
    if !removed.is_empty()
        && let Some(atlas) = &kept.atlas
        && !atlas.shared.is_empty()
    {
        return Err("nodes were removed from a bake whose atlas shares meshes".to_string());
    }
    if !added.is_empty() {
        // The added instances' charts go onto pages of their own, after the old ones.
        if let Some(atlas) = &kept.atlas
            && (atlas.reused_input_uvs || !atlas.shared.is_empty())
        {
            return Err(
                "nodes were added to a bake whose atlas reuses the input's UVs or shares meshes"
                    .to_string(),
            );
        }
        if let Some(&m) = added.iter().find(|&&m| {
            let material = now.instances[m].material as usize;
            now.materials[material].emission.max_element() > 0.0
        }) {
            return Err(format!(
                "an emissive node ({}) was added",
                now.instances[m].node
            ));
        }
        if layout.materials.len() != now.materials.len() {
            return Err("the materials changed".to_string());
        }
    }
    let moved_before = moved_instances(layout, prev, &same)?;
    let moved_now = moved_instances(layout, now, &now_of)?;
    let moved = moved_instances(prev, now, &now_of)?;
    if let Some(&k) = removed.iter().find(|&&k| {
        let m = layout.instances[k].material as usize;
        layout.materials[m].emission.max_element() > 0.0
    }) {
        return Err(format!(
            "an emissive node ({}) was removed",
            layout.instances[k].node
        ));
    }
    Ok(Edit {
        now_of,
        added,
        removed,
        moved_before,
        moved_now,
        moved,
    })
}

/// The previous bake's scene: the `layout` with the instances the previous bake had moved
/// placed as it had them, and the validity pass's results it kept; `Err` when its texels
/// differ from the kept ones.
fn previous_bake(
    layout: Prepared,
    kept: &Kept,
    prev: &Scene,
    edit: &Edit,
) -> Result<Fallback<Prepared>> {
    let mut old = if edit.moved_before.is_empty() {
        layout
    } else {
        let t = Instant::now();
        let mut old = layout;
        let same: Vec<Option<usize>> = (0..old.scene.instances.len()).map(Some).collect();
        old.scene = place(&old.scene, prev, &same, &edit.moved_before);
        old.tracer = Tracer::new(&old.scene);
        old.texels = texels::build(&old.scene, &old.atlas)?;
        timed(&mut old.stages, "previous scene", t);
        old
    };
    // The validity pass's results are the previous bake's, as kept (sample points, jitter,
    // invalid texels, cell maps): what its rows were traced from. The raster's own values
    // (normals, texel steps, albedo, emission) check the layout below.
    if kept.atlas.is_some() && old.texels.len() == kept.texels.len() {
        old.texels.position = kept.texels.position.clone();
        old.texels.jitter = kept.jitter.clone();
        old.texels.invalid = kept.texels.invalid.clone();
        old.texels.cuts = kept.cuts.clone();
    }
    if let Some(why) = differs(&old.texels, &kept.texels) {
        return Ok(Err(format!(
            "the previous bake's texels could not be laid out again ({why}: another lightbake, or other settings)"
        )));
    }
    Ok(Ok(old))
}

/// The edited scene on the previous bake's layout.
struct Edited {
    /// The old scene (cuts and all) with the moved instances placed anew and the added ones
    /// after the old ones.
    scene: Scene,
    /// Its BVH, without the removed instances.
    tracer: Tracer,
    /// The old atlas, with the added instances' charts on pages after the old ones.
    atlas: crate::atlas::Atlas,
    texels: Texels,
    validity: texels::validity::ValidityReport,
    /// The first added instance of `scene`.
    first_added: usize,
    /// Texels of removed instances: unused, invalid, their rows empty.
    gone: Vec<bool>,
}

impl Edited {
    /// The added instances of `scene`.
    fn added(&self) -> Range<usize> {
        self.first_added..self.scene.instances.len()
    }
}

/// The edit placed on the previous bake's layout `old`: every old triangle keeps its id and
/// every old texel its place (`Err` otherwise); the validity pass runs again only near what
/// moved (`Retrace::All`, the yardstick, runs the full pass).
fn lay_out_edit(
    old: &Prepared,
    (now, source): (&Scene, &scene::Source),
    edit: &Edit,
    (config, retrace): (&BakeConfig, Retrace),
    stages: &mut Vec<super::StageTime>,
    progress: &dyn Progress,
) -> Result<Fallback<Edited>> {
    // The new scene: the old one (cuts and all) with the moved instances' vertices placed anew
    // and the added instances after the old ones (uncut: cutting where they meet the old
    // surfaces would move the old texels), so every old triangle keeps its id.
    let t = Instant::now();
    // Every instance placed away from the layout, before or now, takes its place now (one
    // moved back to where the layout has it included).
    let mut away: Vec<usize> = (edit.moved_before.iter().chain(&edit.moved_now))
        .copied()
        .collect();
    away.sort_unstable();
    away.dedup();
    let mut scene = place(&old.scene, now, &edit.now_of, &away);
    let first_added = append_instances(&mut scene, now, &edit.added);
    // A removed node's triangles keep their ids (and its texels their places) but leave the
    // BVH: no ray meets them. The ray offset stays the layout's (its extent).
    let tracer = Tracer::without(&scene, &edit.removed);
    if tracer.epsilon != old.tracer.epsilon {
        return Ok(Err(
            "the scene's extent changed, and with it every ray's offset".to_string(),
        ));
    }
    timed(stages, "incremental bvh", t);
    // The added instances' charts, on pages after the old ones: the texels are ordered by
    // page, so every old texel keeps its id.
    let atlas = if edit.added.is_empty() {
        old.atlas.clone()
    } else {
        let t = Instant::now();
        let atlas = append_charts(&old.atlas, now, source, &edit.added, config, progress)?;
        timed(stages, "incremental atlas", t);
        atlas
    };
    let t = Instant::now();
    let mut texels = texels::build(&scene, &atlas)?;
    // The validity pass again only near what moved, where it was and where it is: elsewhere
    // the previous pass's results hold (`validity::fix_near`).
    let validity = if config.transport.validity && retrace == Retrace::Edited {
        let instance_bounds =
            |s: &Scene, inst: usize| bounds(s, s.instances[inst].vertices.clone(), 0.0);
        let near: Vec<(Vec3, Vec3)> = (edit.moved.iter())
            .flat_map(|&inst| [&old.scene, &scene].map(|s| instance_bounds(s, inst)))
            .chain((edit.removed.iter()).map(|&inst| instance_bounds(&old.scene, inst)))
            .chain((first_added..scene.instances.len()).map(|inst| instance_bounds(&scene, inst)))
            .collect();
        let params = texels::validity::ValidityParams {
            seed: config.transport.seed,
            ..Default::default()
        };
        texels::validity::fix_near(
            &mut texels,
            &old.texels,
            &near,
            &scene,
            &tracer,
            &params,
            &Alone,
            progress,
        )?
    } else {
        super::fix_validity(&mut texels, &scene, &tracer, config, &Alone, progress)?
    };
    let n_old = old.texels.len();
    if texels.len() < n_old
        || texels.page[..n_old] != old.texels.page[..]
        || texels.xy[..n_old] != old.texels.xy[..]
    {
        return Ok(Err("the old texels changed places".to_string()));
    }
    // A removed node's texels: unused (no primitive of the output reads them), invalid, and
    // their rows empty (`Rebuild::rows`).
    let gone = removed_texels(&scene, &texels, &edit.removed);
    if gone.iter().any(|&g| g) {
        texels.invalid = (0..texels.len() as u32)
            .filter(|&i| gone[i as usize] || texels.invalid.binary_search(&i).is_ok())
            .collect();
    }
    timed(stages, "incremental texels", t);
    Ok(Ok(Edited {
        scene,
        tracer,
        atlas,
        texels,
        validity,
        first_added,
        gone,
    }))
}

/// The texels that changed (their rows are traced whole; all of them for `Retrace::All`), and
/// the boxes whose rays are traced again: every moved, removed or added instance's, where it
/// was and where it is.
fn retraced(
    old: &Prepared,
    edited: &Edited,
    edit: &Edit,
    retrace: Retrace,
) -> (Vec<bool>, Vec<(Vec3, Vec3)>) {
    let mut changed = changed_texels(&old.texels, &edited.texels);
    if retrace == Retrace::All {
        changed.iter_mut().for_each(|c| *c = true);
    }
    // A ray that meets no moved bounds hits the same triangle at the same point, and the same
    // texel there, unless that texel's cell map changed (a moved surface now divides it, or no
    // longer does: `texels::Cuts`); such a texel lies within its own size of the moved surface,
    // so the bounds grow by the largest of them.
    let new = &edited.texels;
    let margin = (0..old.texels.len())
        .filter(|&i| old.texels.cuts.cells(i) != new.cuts.cells(i))
        .map(|i| {
            let size = |t: &Texels| t.du[i].length() + t.dv[i].length();
            size(&old.texels).max(size(new))
        })
        .fold(0.0f32, f32::max)
        + 8.0 * edited.tracer.epsilon;
    let mut boxes = Vec::new();
    for &inst in &edit.moved {
        for s in [&old.scene, &edited.scene] {
            boxes.push(bounds(s, s.instances[inst].vertices.clone(), margin));
        }
    }
    for &inst in &edit.removed {
        let s = &old.scene;
        boxes.push(bounds(s, s.instances[inst].vertices.clone(), margin));
    }
    // An added instance: rays of the old rows that meet its bounds may end on it now.
    for inst in edited.added() {
        let s = &edited.scene;
        boxes.push(bounds(s, s.instances[inst].vertices.clone(), margin));
    }
    (changed, boxes)
}

/// The edited bake's rows: the kept ones, traced again whole where `changed` and ray by ray
/// where a ray meets `boxes`; `base` with what was traced and reused filled in. `Err` when the
/// light sources changed.
fn rebuild_transport(
    kept: &Kept,
    old: &Prepared,
    edited: &Edited,
    (config, changed, boxes): (&BakeConfig, &[bool], &[(Vec3, Vec3)]),
    base: Incremental,
    stages: &mut Vec<super::StageTime>,
    progress: &dyn Progress,
) -> Result<Fallback<(crate::transport::Transport, Incremental)>> {
    let t = Instant::now();
    let n = edited.texels.len();
    let (k, l) = (config.transport.gather_rays, config.transport.light_samples);
    let scene = &edited.scene;
    let emitters = Emitters::new(scene, &edited.texels);
    let sources = Sources::new(scene);
    let was = &kept.transport.sources;
    if (sources.lights, &sources.emissive) != (was.lights, &was.emissive) {
        return Ok(Err("the light sources changed".to_string()));
    }
    let ctx = Context {
        surfaces: Surfaces {
            scene,
            texels: &edited.texels,
            tracer: &edited.tracer,
        },
        params: &config.transport,
        emitters: &emitters,
        texel_rays: None,
        sources: Some(&sources),
    };
    let rebuild = Rebuild {
        kept,
        old: old.surfaces(),
        new: &ctx,
        changed,
        gone: &edited.gone,
        boxes,
        count_rows: config.transport.count_rows,
        touched: Mutex::new(Vec::new()),
        flagged: AtomicUsize::new(0),
        busy: AtomicU64::new(0),
        traced_busy: AtomicU64::new(0),
    };
    let mut transport = rows::build(n, montecarlo::CHUNK, "transport", progress, |range, out| {
        rebuild.rows(range, out)
    })?;
    let mut touched = std::mem::take(&mut *rebuild.touched.lock().unwrap());
    touched.sort_unstable();
    let retraced = touched.iter().filter(|t| t.1).count();
    let patched = touched.len() - retraced;
    let flagged_rays = rebuild.flagged.load(Ordering::Relaxed) as u64;
    transport.sources = sources.clone();
    #[cfg(debug_assertions)]
    transport.validate();
    let seconds = t.elapsed().as_secs_f64();
    timed(stages, "incremental transport", t);
    let lights = scene.lights.len() as u64 * u64::from(PUNCTUAL_GRID * PUNCTUAL_GRID);
    let per_row = u64::from(k) + if emitters.is_empty() { 0 } else { u64::from(l) } + lights;
    // The transport time saved, estimated: the rows traced whole cost `traced_busy` thread
    // time, so every row would have cost about `n / retraced` times that; the thread time
    // of all chunks against the wall time gives the parallel speed-up. Unknown (0) when no
    // row was traced whole.
    let busy = rebuild.busy.load(Ordering::Relaxed) as f64 * 1e-9;
    let traced_busy = rebuild.traced_busy.load(Ordering::Relaxed) as f64 * 1e-9;
    let seconds_saved = match (retraced, busy > 0.0) {
        (0, _) | (_, false) => 0.0,
        (r, true) => {
            let full_wall = traced_busy * n as f64 / r as f64 * seconds / busy;
            (full_wall - seconds).max(0.0)
        }
    };
    let incremental = Incremental {
        rows: n,
        retraced,
        patched,
        flagged_rays,
        touched_rows: touched.iter().map(|t| t.0).collect(),
        rays: transport.rays,
        full_rays: n as u64 * per_row,
        seconds_saved,
        ..base
    };
    Ok(Ok((transport, incremental)))
}

/// The old bake's scene laid out again on its kept `atlas` (what `prepare_loaded` does with
/// the fixed settings `config`, without unwrapping): the junction split, the tracer and the
/// texels, before the validity pass (whose results the kept file holds). `Err` when the atlas
/// does not fit the split scene.
fn lay_out_again(
    loaded: Scene,
    source: scene::Source,
    atlas: &crate::atlas::Atlas,
    config: &BakeConfig,
    load_start: Instant,
) -> Result<Fallback<Prepared>> {
    let mut stages = Vec::new();
    timed(&mut stages, "load", load_start);
    let t = Instant::now();
    let (scene, junctions) = super::split_junctions(loaded, &source, config);
    if junctions.is_some() {
        timed(&mut stages, "junctions", t);
    }
    let fits = atlas.instances.len() == scene.instances.len()
        && (scene.instances.iter().zip(&atlas.instances)).all(|(inst, uv)| {
            let vertices = inst.vertices.len() as u32;
            uv.triangles.len() == inst.triangles.len()
                && uv.triangle_page.len() == uv.triangles.len()
                && uv.xref.len() == uv.uv.len()
                && uv.xref.iter().all(|&x| x < vertices)
        });
    if !fits {
        return Ok(Err(
            "the kept atlas does not fit the scene laid out again".to_string()
        ));
    }
    let t = Instant::now();
    let tracer = Tracer::new(&scene);
    timed(&mut stages, "bvh", t);
    let t = Instant::now();
    let texels = texels::build(&scene, atlas)?;
    timed(&mut stages, "texels", t);
    Ok(Ok(Prepared {
        scene,
        source,
        tracer,
        atlas: atlas.clone(),
        texels,
        validity: Default::default(),
        config: config.clone(),
        plan: None,
        density: Default::default(),
        junctions,
        stages,
        processes: 1,
    }))
}

/// The input's nodes in the previous bake's node graph ([`InputRecord::graph`]).
struct NodeMap {
    /// Per node of the input, its index in the previous graph (`None`: added).
    of_new: Vec<Option<u32>>,
    /// The previous graph's nodes the input no longer has, ascending.
    removed: Vec<u32>,
    /// The input's nodes the previous graph did not have, ascending.
    added: Vec<u32>,
}

/// Matches the node graph `after` (the input's) against `before` (the previous bake's): the
/// longest run of nodes the two share in order (each node compared whole but for its
/// transform and its children's indices, which a removal or an addition renumbers) are the
/// same nodes; the previous graph's others were removed, the input's others added. Each kept
/// node's children and each scene's roots must be those of before less the removed (and
/// plus the added), and an added node's children added ones, or it says why not.
fn match_nodes(before: &Value, after: &Value) -> Fallback<NodeMap> {
    let list = |g: &Value, key: &str| -> Vec<Value> {
        g.get(key)
            .and_then(Value::as_array)
            .cloned()
            .unwrap_or_default()
    };
    let (old_nodes, new_nodes) = (list(before, "nodes"), list(after, "nodes"));
    let indices = |v: Option<&Value>| -> Vec<u64> {
        v.and_then(Value::as_array)
            .map(|a| a.iter().filter_map(Value::as_u64).collect())
            .unwrap_or_default()
    };
    let bare = |node: &Value| {
        let mut node = node.clone();
        if let Some(obj) = node.as_object_mut() {
            for key in TRANSFORM_KEYS.iter().chain(&["children"]) {
                obj.remove(*key);
            }
        }
        serde_json::to_string(&node).unwrap_or_default()
    };
    let a: Vec<String> = old_nodes.iter().map(bare).collect();
    let b: Vec<String> = new_nodes.iter().map(bare).collect();
    let pairs = match common_subsequence(&a, &b) {
        Some(pairs) => pairs,
        None => return Err("too many nodes changed places to match them".to_string()),
    };
    let mut of_new = vec![None; b.len()];
    let mut kept = vec![false; a.len()];
    for (i, j) in pairs {
        of_new[j] = Some(i as u32);
        kept[i] = true;
    }
    let removed: Vec<u32> = (0..a.len() as u32).filter(|&k| !kept[k as usize]).collect();
    let added: Vec<u32> = (0..b.len() as u32)
        .filter(|&k| of_new[k as usize].is_none())
        .collect();
    let is_added = |c: u64| of_new.get(c as usize).is_some_and(Option::is_none);
    // Children and roots: the new ones but the added, in the old graph's indices, must be the
    // old ones less the removed (a node re-parented or a root dropped is neither).
    let same = |new: Vec<u64>, old: Vec<u64>| -> bool {
        let mapped: Option<Vec<u64>> = (new.iter())
            .filter(|&&c| !is_added(c))
            .map(|&c| of_new.get(c as usize).copied().flatten().map(u64::from))
            .collect();
        let kept_old: Vec<u64> = (old.into_iter())
            .filter(|&c| kept.get(c as usize).copied().unwrap_or(false))
            .collect();
        mapped == Some(kept_old)
    };
    let children = (new_nodes.iter().zip(&of_new)).all(|(n, k)| match k {
        Some(k) => same(
            indices(n.get("children")),
            indices(old_nodes[*k as usize].get("children")),
        ),
        None => indices(n.get("children")).into_iter().all(is_added),
    });
    let (old_scenes, new_scenes) = (list(before, "scenes"), list(after, "scenes"));
    let scenes = old_scenes.len() == new_scenes.len()
        && before.get("scene") == after.get("scene")
        && (old_scenes.iter().zip(&new_scenes)).all(|(o, n)| {
            let bare = |s: &Value| {
                let mut s = s.clone();
                s.as_object_mut().map(|o| o.remove("nodes"));
                s
            };
            bare(o) == bare(n) && same(indices(n.get("nodes")), indices(o.get("nodes")))
        });
    if !(children && scenes) {
        return Err(
            "the node hierarchy changed (not only moves, removals and additions)".to_string(),
        );
    }
    Ok(NodeMap {
        of_new,
        removed,
        added,
    })
}

/// A longest common subsequence of `a` and `b` as index pairs `(i, j)`, ascending: the common
/// prefix and suffix matched directly, the rest by dynamic programming (`None` when that
/// middle is too large to tabulate).
fn common_subsequence<T: PartialEq>(a: &[T], b: &[T]) -> Option<Vec<(usize, usize)>> {
    let prefix = a.iter().zip(b).take_while(|(x, y)| x == y).count();
    let suffix = (a[prefix..].iter().rev())
        .zip(b[prefix..].iter().rev())
        .take_while(|(x, y)| x == y)
        .count();
    let (ma, mb) = (&a[prefix..a.len() - suffix], &b[prefix..b.len() - suffix]);
    let (n, m) = (ma.len(), mb.len());
    if (n + 1).saturating_mul(m + 1) > 1 << 26 {
        return None;
    }
    // `len[i][j]`: the longest common subsequence of `ma[i..]` and `mb[j..]`.
    let w = m + 1;
    let mut len = vec![0u32; (n + 1) * w];
    for i in (0..n).rev() {
        for j in (0..m).rev() {
            len[i * w + j] = match ma[i] == mb[j] {
                true => len[(i + 1) * w + j + 1] + 1,
                false => len[(i + 1) * w + j].max(len[i * w + j + 1]),
            };
        }
    }
    let mut pairs: Vec<(usize, usize)> = (0..prefix).map(|k| (k, k)).collect();
    let (mut i, mut j) = (0, 0);
    while i < n && j < m {
        if ma[i] == mb[j] && len[i * w + j] == len[(i + 1) * w + j + 1] + 1 {
            pairs.push((prefix + i, prefix + j));
            (i, j) = (i + 1, j + 1);
        } else if len[(i + 1) * w + j] >= len[i * w + j + 1] {
            i += 1;
        } else {
            j += 1;
        }
    }
    let (ea, eb) = (a.len() - suffix, b.len() - suffix);
    pairs.extend((0..suffix).map(|k| (ea + k, eb + k)));
    Some(pairs)
}

/// Per instance of `old` (the previous graph laid out), the instance of `new` (the input) that
/// places the same primitive by the same node, in order; `None` where `old`'s node was removed.
/// Then the instances of `new` placed by added nodes, ascending.
type InstanceMap = (Vec<Option<usize>>, Vec<usize>);

/// The [`InstanceMap`] of `old` and `new`, or why they do not match.
fn instance_map(old: &Scene, new: &Scene, nodes: &NodeMap) -> Fallback<InstanceMap> {
    let is_added = |b: &scene::Instance| nodes.added.binary_search(&b.node).is_ok();
    let added: Vec<usize> = (0..new.instances.len())
        .filter(|&m| is_added(&new.instances[m]))
        .collect();
    let mut from_before = (0..new.instances.len()).filter(|&m| !is_added(&new.instances[m]));
    let mut map = Vec::with_capacity(old.instances.len());
    for a in &old.instances {
        if nodes.removed.binary_search(&a.node).is_ok() {
            map.push(None);
            continue;
        }
        let next = from_before.next();
        let same = next.is_some_and(|m| {
            let b = &new.instances[m];
            nodes.of_new.get(b.node as usize).copied().flatten() == Some(a.node)
                && (b.mesh, b.primitive, b.back_of.is_some())
                    == (a.mesh, a.primitive, a.back_of.is_some())
        });
        if !same {
            return Err(
                "the input's instances are not the previous ones less the removed".to_string(),
            );
        }
        map.push(next);
    }
    if from_before.next().is_some() {
        return Err("the input places primitives the previous bake did not".to_string());
    }
    Ok((map, added))
}

/// The instances whose vertices moved between `old` and `new` (`map`: `old`'s instances in
/// `new`, `None` for a removed one), or why the difference is more than a move.
fn moved_instances(old: &Scene, new: &Scene, map: &[Option<usize>]) -> Fallback<Vec<usize>> {
    let mut moved = Vec::new();
    for (k, a) in old.instances.iter().enumerate() {
        let Some(b) = map[k].map(|m| &new.instances[m]) else {
            continue;
        };
        let local = |s: &Scene, i: &scene::Instance| -> Vec<[u32; 3]> {
            s.triangles[i.triangles.start as usize..i.triangles.end as usize]
                .iter()
                .map(|t| t.map(|v| v - i.vertices.start))
                .collect()
        };
        if a.vertices.len() != b.vertices.len()
            || a.material != b.material
            || local(old, a) != local(new, b)
        {
            return Err("a moved node's triangles changed (a mirroring transform?)".to_string());
        }
        let (ra, rb) = (
            a.vertices.start as usize..a.vertices.end as usize,
            b.vertices.start as usize..b.vertices.end as usize,
        );
        if old.positions[ra.clone()] != new.positions[rb.clone()]
            || old.normals[ra] != new.normals[rb]
        {
            if old.materials[a.material as usize].emission.max_element() > 0.0 {
                return Err("an emissive node moved".to_string());
            }
            moved.push(k);
        }
    }
    if format!("{:?}", old.lights) != format!("{:?}", new.lights) {
        return Err("a light moved, was removed or was added".to_string());
    }
    Ok(moved)
}

/// `old` (the old bake's scene, cut by the junction split) with the `moved` instances'
/// vertices taken from their instance in `new` (`map`; the input as loaded, uncut): a source
/// vertex is the loaded one, a cut vertex the same blend of the loaded ones.
fn place(old: &Scene, new: &Scene, map: &[Option<usize>], moved: &[usize]) -> Scene {
    let mut scene = old.clone();
    for &k in moved {
        let Some(m) = map[k] else { continue };
        let (cut, loaded) = (&old.instances[k], &new.instances[m]);
        let src = loaded.vertices.start as usize;
        let count = loaded.vertices.len();
        let first = cut.vertices.start as usize;
        for v in 0..count {
            scene.positions[first + v] = new.positions[src + v];
            scene.normals[first + v] = new.normals[src + v];
        }
        for (b, blend) in cut.split.blends.iter().enumerate() {
            let (mut p, mut n) = (Vec3::ZERO, Vec3::ZERO);
            for (&v, &w) in blend.vertices.iter().zip(&blend.weights) {
                if w != 0.0 {
                    p += new.positions[src + v as usize] * w;
                    n += new.normals[src + v as usize] * w;
                }
            }
            scene.positions[first + count + b] = p;
            scene.normals[first + count + b] = n.normalize_or_zero();
        }
    }
    scene
}

/// Per texel, whether it lies on one of the `removed` instances.
fn removed_texels(scene: &Scene, texels: &Texels, removed: &[usize]) -> Vec<bool> {
    (texels.triangle.iter())
        .map(|&t| {
            removed
                .binary_search(&(scene.triangle_instance[t as usize] as usize))
                .is_ok()
        })
        .collect()
}

/// The scene and atlas of `baked` as the glTF writer reads them after a removal or an
/// addition ([`super::Baked::written`]): per instance of the input as loaded (`input`), in its
/// order, the baked instance `of_input` names, placed by the input's node; the removed
/// instances left out, and the input's node tree. Triangles keep their ids (the writer reads
/// instances, not triangles); a removed one names no instance (`u32::MAX`).
fn written_for_input(
    baked: &super::Baked,
    of_input: &[usize],
    input: &Scene,
) -> (Scene, crate::atlas::Atlas) {
    let mut index_now = vec![u32::MAX; baked.scene.instances.len()];
    of_input
        .iter()
        .enumerate()
        .for_each(|(now, &k)| index_now[k] = now as u32);
    let mut scene = baked.scene.clone();
    scene.instances = (of_input.iter().zip(&input.instances))
        .map(|(&k, placed)| {
            let mut inst = baked.scene.instances[k].clone();
            inst.node = placed.node;
            inst.back = inst.back.map(|b| index_now[b as usize]);
            inst.back_of = inst.back_of.map(|b| index_now[b as usize]);
            inst
        })
        .collect();
    for i in &mut scene.triangle_instance {
        *i = index_now[*i as usize];
    }
    scene.nodes = input.nodes.clone();
    scene.cameras = input.cameras.clone();
    let mut atlas = baked.atlas.clone();
    atlas.instances = (of_input.iter())
        .map(|&k| baked.atlas.instances[k].clone())
        .collect();
    (scene, atlas)
}

/// `scene` with the instances `which` of `from` appended (their vertices, triangles and
/// instances; materials are `scene`'s, which must be `from`'s). Returns the index of the first.
fn append_instances(scene: &mut Scene, from: &Scene, which: &[usize]) -> usize {
    let first = scene.instances.len();
    let mut index = vec![u32::MAX; from.instances.len()];
    which
        .iter()
        .enumerate()
        .for_each(|(k, &m)| index[m] = (first + k) as u32);
    for &m in which {
        let mut inst = from.instances[m].clone();
        let (v0, t0) = (scene.positions.len() as u32, scene.triangles.len() as u32);
        let (vs, ts) = (
            inst.vertices.start as usize..inst.vertices.end as usize,
            inst.triangles.start as usize..inst.triangles.end as usize,
        );
        scene
            .positions
            .extend_from_slice(&from.positions[vs.clone()]);
        scene.normals.extend_from_slice(&from.normals[vs.clone()]);
        scene.uv0.extend_from_slice(&from.uv0[vs.clone()]);
        scene.uv1.extend_from_slice(&from.uv1[vs]);
        let shift = v0 as i64 - i64::from(inst.vertices.start);
        scene.triangles.extend(
            from.triangles[ts.clone()]
                .iter()
                .map(|t| t.map(|v| (i64::from(v) + shift) as u32)),
        );
        let k = scene.instances.len() as u32;
        scene
            .triangle_instance
            .extend(std::iter::repeat_n(k, ts.len()));
        inst.vertices = v0..v0 + inst.vertices.len() as u32;
        inst.triangles = t0..t0 + ts.len() as u32;
        // A front and its back-face copy are added together (the same node).
        inst.back = inst.back.map(|b| index[b as usize]);
        inst.back_of = inst.back_of.map(|b| index[b as usize]);
        scene.instances.push(inst);
    }
    first
}

/// The atlas `old` with charts for the instances `which` of `from` (the input as loaded)
/// appended, as [`append_instances`] appends them: unwrapped on their own at the old bake's
/// uniform density (`config`'s texels per unit, no per-region factors) onto pages after the
/// old ones, so that every old chart, page and texel stays where it was.
fn append_charts(
    old: &crate::atlas::Atlas,
    from: &Scene,
    source: &scene::Source,
    which: &[usize],
    config: &BakeConfig,
    progress: &dyn Progress,
) -> Result<crate::atlas::Atlas> {
    let mut sub = Scene {
        materials: from.materials.clone(),
        textures: from.textures.clone(),
        ..Default::default()
    };
    append_instances(&mut sub, from, which);
    let params = crate::config::AtlasParams {
        uv: crate::config::UvMode::Unwrap,
        instancing: crate::config::Instancing::Duplicate,
        instance_density: Vec::new(),
        triangle_density: Vec::new(),
        ..config.atlas.clone()
    };
    let added = crate::atlas::build_with(&sub, source, &params, progress)?;
    let mut atlas = old.clone();
    let first_page = old.pages.len() as u32;
    atlas.pages.extend(added.pages);
    atlas
        .instances
        .extend(added.instances.into_iter().map(|mut uv| {
            uv.triangle_page.iter_mut().for_each(|p| *p += first_page);
            uv
        }));
    Ok(atlas)
}

/// What differs between the laid-out texels `a` and the kept texels `b` (the fields the kept
/// file holds), or `None`.
fn differs(a: &Texels, b: &Texels) -> Option<&'static str> {
    if a.len() != b.len() || a.pages != b.pages || a.page != b.page || a.xy != b.xy {
        return Some("texel count or places");
    }
    let fields = [
        (&a.position, &b.position),
        (&a.normal, &b.normal),
        (&a.du, &b.du),
        (&a.dv, &b.dv),
        (&a.albedo, &b.albedo),
        (&a.emission, &b.emission),
    ];
    if fields.iter().any(|(x, y)| bits(x) != bits(y)) {
        return Some("texel values");
    }
    (a.invalid != b.invalid).then_some("invalid texels")
}

fn bits(v: &[Vec3]) -> Vec<[u32; 3]> {
    v.iter().map(|v| v.to_array().map(f32::to_bits)).collect()
}

/// Per texel: whether anything its row reads of itself differs between `old` and `new` (a
/// texel `old` does not have, an added node's, is new).
fn changed_texels(old: &Texels, new: &Texels) -> Vec<bool> {
    let (old_valid, new_valid) = (old.valid_mask(), new.valid_mask());
    let same3 = |a: Vec3, b: Vec3| a.to_array().map(f32::to_bits) == b.to_array().map(f32::to_bits);
    let jitter = |t: &Texels, i: usize| t.jitter.get(i).copied().unwrap_or(1.0).to_bits();
    (0..new.len())
        .map(|i| {
            i >= old.len()
                || !(same3(old.position[i], new.position[i])
                    && same3(old.normal[i], new.normal[i])
                    && same3(old.du[i], new.du[i])
                    && same3(old.dv[i], new.dv[i])
                    && same3(old.albedo[i], new.albedo[i])
                    && same3(old.emission[i], new.emission[i])
                    && old.area[i].to_bits() == new.area[i].to_bits()
                    && old.triangle[i] == new.triangle[i]
                    && jitter(old, i) == jitter(new, i)
                    && old_valid[i] == new_valid[i]
                    && old.cuts.cells(i) == new.cuts.cells(i))
        })
        .collect()
}

/// Bounds of `scene`'s vertices `range`, grown by `margin`.
fn bounds(scene: &Scene, range: Range<u32>, margin: f32) -> (Vec3, Vec3) {
    let ps = &scene.positions[range.start as usize..range.end as usize];
    let lo = ps.iter().fold(Vec3::INFINITY, |a, &p| a.min(p));
    let hi = ps.iter().fold(Vec3::NEG_INFINITY, |a, &p| a.max(p));
    (lo - Vec3::splat(margin), hi + Vec3::splat(margin))
}

/// Whether the segment `origin + t·dir`, `t ∈ [0, t_max]`, meets any of `boxes` (slab test).
#[inline]
fn meets(boxes: &[(Vec3, Vec3)], origin: Vec3, dir: Vec3, t_max: f32) -> bool {
    let inv = dir.recip();
    boxes.iter().any(|&(lo, hi)| {
        let (a, b) = ((lo - origin) * inv, (hi - origin) * inv);
        let (near, far) = (a.min(b), a.max(b));
        // A NaN slab (0 · ∞: a ray in a box's face plane) is skipped by `max_element` and
        // `min_element`, which only widens the test: conservative.
        let t0 = near.max_element().max(0.0);
        let t1 = far.min_element().min(t_max);
        t0 <= t1
    })
}

/// One ray of a texel's row, drawn as `Context::texel_row` draws it.
#[derive(Clone, Copy)]
enum RowRay {
    /// A gathering ray; `cos` its cosine to the texel normal.
    Gather { origin: Vec3, dir: Vec3, cos: f32 },
    /// A light sample `u` from `origin`.
    Light { origin: Vec3, u: Vec2 },
    /// The shadow ray to punctual light `light` from footprint point `footprint`, or from the
    /// sample point where the surface between them is not clear (`Texels::punctual_point`,
    /// decided in each scene: an edit can open or close that gap).
    Punctual { footprint: Vec3, light: usize },
}

/// Draws texel `i`'s rays in `ctx` (the rays only: nothing is traced) and hands each to
/// `visit`, with the ray counts `(K, L)`. This must draw the same numbers in the same order as
/// `Context::texel_row`; `tests/incremental.rs` checks that every row a full trace changes is
/// one this finds.
fn row_rays(ctx: &Context, i: usize, mut visit: impl FnMut(RowRay)) -> (u32, u32) {
    let texels = ctx.surfaces.texels;
    let n = texels.normal[i];
    let (tx, ty) = frame(n);
    let p = ctx.params;
    let k = p.gather_rays.max(1);
    let l = if ctx.emitters.is_empty() || p.light_samples == 0 {
        0
    } else {
        p.light_samples
    };
    let mut rng = Rng::new(p.seed, i as u64, 0);
    let shift = rng.next_vec2();
    for s in 0..k {
        let local = cosine_hemisphere(hammersley(s, k, shift));
        let dir = tx * local.x + ty * local.y + n * local.z;
        let origin = ctx.footprint_point(i, rng.next_vec2());
        visit(RowRay::Gather {
            origin,
            dir,
            cos: local.z,
        });
    }
    let light_shift = rng.next_vec2();
    for s in 0..l {
        let u = hammersley(s, l, light_shift);
        let origin = ctx.footprint_point(i, rng.next_vec2());
        visit(RowRay::Light { origin, u });
    }
    let lights = ctx.surfaces.scene.lights.len();
    if lights > 0 {
        let g = PUNCTUAL_GRID;
        for s in 0..g * g {
            let u = (Vec2::new((s % g) as f32, (s / g) as f32) + rng.next_vec2()) / g as f32;
            let footprint = ctx.footprint_point(i, u);
            for light in 0..lights {
                visit(RowRay::Punctual { footprint, light });
            }
        }
    }
    (k, l)
}

/// Where one ray of a row ends, and the direct light it adds (to source `source`).
#[derive(Clone, Copy, PartialEq)]
struct Outcome {
    texel: Option<u32>,
    escaped: bool,
    light: Vec3,
    source: usize,
}

const NOTHING: Outcome = Outcome {
    texel: None,
    escaped: false,
    light: Vec3::ZERO,
    source: 0,
};

/// Rebuilds the rows: kept, patched or traced again.
struct Rebuild<'a> {
    kept: &'a Kept,
    old: Surfaces<'a>,
    new: &'a Context<'a>,
    changed: &'a [bool],
    /// Texels of removed nodes: their rows are empty.
    gone: &'a [bool],
    boxes: &'a [(Vec3, Vec3)],
    count_rows: bool,
    /// The rows re-traced (`true`) or patched (`false`), in no order.
    touched: Mutex<Vec<(u32, bool)>>,
    flagged: AtomicUsize,
    /// Thread time (ns) of all chunks, and of the rows traced whole (the time-saved estimate).
    busy: AtomicU64,
    traced_busy: AtomicU64,
}

impl Rebuild<'_> {
    fn rows(&self, range: Range<usize>, out: &mut ChunkRows) {
        let chunk = Instant::now();
        let mut scratch = RowScratch::default();
        let mut flagged = Vec::new();
        for i in range {
            if self.gone[i] {
                let start = out.col.len();
                push_row(
                    out,
                    std::iter::empty(),
                    self.ray_counts().0,
                    self.count_rows,
                );
                let sources = self.kept.transport.sources.len();
                out.terms.extend(std::iter::repeat_n(Vec3::ZERO, sources));
                out.end_row(start, 0.0, Vec3::ZERO);
                continue;
            }
            if self.changed[i] {
                let t = Instant::now();
                self.new.texel_row(i, &mut scratch, out);
                let ns = t.elapsed().as_nanos() as u64;
                self.traced_busy.fetch_add(ns, Ordering::Relaxed);
                self.touched.lock().unwrap().push((i as u32, true));
                continue;
            }
            flagged.clear();
            if self.faces_away(i) {
                // No ray of this row can reach a moved node: reuse the row as kept.
                self.row(i, &flagged, self.ray_counts(), out);
                continue;
            }
            let (k, l) = row_rays(self.new, i, |ray| {
                if self.flags(i, ray) {
                    flagged.push(ray);
                }
            });
            self.row(i, &flagged, (k, l), out);
        }
        let ns = chunk.elapsed().as_nanos() as u64;
        self.busy.fetch_add(ns, Ordering::Relaxed);
    }

    /// Whether every moved bounds lies below texel `i`'s plane, beyond its footprint: a row's
    /// rays start within `|du| + |dv|` of the texel's position (its footprint, lifted by the ray
    /// epsilon) and only those going up its hemisphere count (gathering rays by construction,
    /// light samples and punctual lights are zero when `cos_i ≤ 0`), so none reaches such bounds.
    fn faces_away(&self, i: usize) -> bool {
        let t = self.new.surfaces.texels;
        let (p, n) = (t.position[i], t.normal[i]);
        let reach = t.du[i].length() + t.dv[i].length() + 4.0 * self.new.surfaces.tracer.epsilon;
        self.boxes.iter().all(|&(lo, hi)| {
            let (centre, half) = ((lo + hi) * 0.5, (hi - lo) * 0.5);
            (centre - p).dot(n) + half.dot(n.abs()) < -reach
        })
    }

    /// The row's gathering rays and light samples, as `row_rays` counts them.
    fn ray_counts(&self) -> (u32, u32) {
        let p = self.new.params;
        let l = match self.new.emitters.is_empty() {
            true => 0,
            false => p.light_samples,
        };
        (p.gather_rays.max(1), l)
    }

    /// Whether `ray` of texel `i` can end differently: its line meets a moved node's old or new
    /// bounds (for a punctual light: the segment across the footprint, or the shadow ray from
    /// either end of it).
    fn flags(&self, i: usize, ray: RowRay) -> bool {
        match ray {
            RowRay::Gather { origin, dir, .. } => meets(self.boxes, origin, dir, f32::INFINITY),
            RowRay::Light { origin, u } => {
                let emitters = self.new.emitters;
                let (tri, u0) = emitters.pick_stratified(u.x);
                let bary = crate::sampling::triangle_point(Vec2::new(u0, u.y));
                let (point, _) = triangle_point(self.new.surfaces.scene, tri, bary);
                meets(self.boxes, origin, point - origin, 1.0)
            }
            RowRay::Punctual { footprint, light } => {
                let Surfaces { texels, tracer, .. } = self.new.surfaces;
                let (a, b) = texels.punctual_segment(tracer, i, footprint);
                let light = &self.new.surfaces.scene.lights[light];
                meets(self.boxes, a, b - a, 1.0)
                    || [footprint, texels.sample_point(tracer, i)]
                        .into_iter()
                        .any(|p| match light.kind {
                            LightKind::Directional => {
                                meets(self.boxes, p, -light.direction, f32::INFINITY)
                            }
                            _ => meets(self.boxes, p, light.position - p, 1.0),
                        })
            }
        }
    }

    /// Where `ray` of texel `i` ends in `surfaces`, with `(K, L)` for the MIS weights.
    fn outcome(&self, surfaces: Surfaces, i: usize, ray: RowRay, (k, l): (u32, u32)) -> Outcome {
        let Surfaces {
            scene,
            texels,
            tracer,
        } = surfaces;
        let (kf, lf) = (k as f32, l as f32);
        let emitters = self.new.emitters;
        let sources = self.new.sources.expect("split sources");
        let n = texels.normal[i];
        match ray {
            RowRay::Gather { origin, dir, cos } => match texels.ray_end(tracer, origin, dir) {
                RayEnd::Escaped => Outcome {
                    escaped: true,
                    ..NOTHING
                },
                RayEnd::Absorbed => NOTHING,
                RayEnd::Texel(hit, j) => {
                    let le = texels.emission[j as usize];
                    let mut light = Vec3::ZERO;
                    if le.max_element() > 0.0 {
                        let p_gather = cos / std::f32::consts::PI;
                        let (_, n_l) = triangle_point(scene, hit.triangle, hit.bary);
                        let p_light = emitters.pdf_toward(hit.triangle, n_l, dir, hit.t);
                        light = le * (cos * power_weight(kf * p_gather, lf * p_light));
                    }
                    Outcome {
                        texel: Some(j),
                        escaped: false,
                        light,
                        source: if light == Vec3::ZERO {
                            0
                        } else {
                            sources.of_texel(scene, texels, j)
                        },
                    }
                }
            },
            RowRay::Light { origin, u } => {
                let Some(x) = emitters.sample_from((scene, texels, tracer), origin, Some(n), u)
                else {
                    return NOTHING;
                };
                let p_gather = x.cos_i / std::f32::consts::PI;
                Outcome {
                    light: x.le * (x.cos_i * power_weight(lf * x.pdf_solid_angle(), kf * p_gather)),
                    source: sources.of_texel(scene, texels, x.texel),
                    ..NOTHING
                }
            }
            RowRay::Punctual { footprint, light } => {
                let p = texels.punctual_point(tracer, i, footprint);
                let g2 = (PUNCTUAL_GRID * PUNCTUAL_GRID) as f32;
                Outcome {
                    light: punctual_irradiance(&scene.lights[light], p, n, tracer) / g2,
                    source: light,
                    ..NOTHING
                }
            }
        }
    }

    /// Row `i`: the kept row, patched by the `flagged` rays that end differently now.
    fn row(&self, i: usize, flagged: &[RowRay], (k, l): (u32, u32), out: &mut ChunkRows) {
        let kept = &self.kept.transport;
        let count = kept.sources.len();
        let terms = &kept.direct_terms[i * count..(i + 1) * count];
        let kf = k as f32;
        // The kept row as hit counts: `f = hits / K` in f32 gives the count back exactly.
        let mut counts: Vec<(u32, i64)> = kept
            .row(i)
            .map(|(j, f)| (j, (f * kf).round() as i64))
            .collect();
        let mut escaped = (kept.escape[i] * kf).round() as i64;
        let mut direct = self.kept.direct[i];
        let mut new_terms = terms.to_vec();
        let mut touched = false;
        for &ray in flagged {
            let before = self.outcome(self.old, i, ray, (k, l));
            let after = self.outcome(self.new.surfaces, i, ray, (k, l));
            if before == after {
                continue;
            }
            touched = true;
            for (o, sign) in [(before, -1i64), (after, 1)] {
                if let Some(j) = o.texel {
                    match counts.binary_search_by_key(&j, |e| e.0) {
                        Ok(at) => counts[at].1 += sign,
                        Err(at) => counts.insert(at, (j, sign)),
                    }
                }
                escaped += sign * i64::from(o.escaped);
                let e = o.light * sign as f32;
                direct += e;
                if o.light != Vec3::ZERO {
                    new_terms[o.source] += e;
                }
            }
        }
        self.flagged.fetch_add(flagged.len(), Ordering::Relaxed);
        let start = out.col.len();
        if !touched {
            // Bit for bit what the bake kept.
            push_row(out, counts.iter().copied(), k, self.count_rows);
            out.terms.extend_from_slice(terms);
            out.end_row(start, kept.escape[i], direct);
            out.rays += 2 * flagged.len() as u64;
            return;
        }
        self.touched.lock().unwrap().push((i as u32, false));
        // Rounding can leave a count off by one where a grazing ray ends differently in the
        // laid-out-again old scene; a count never goes below zero.
        counts.retain(|e| e.1 > 0);
        let escaped = escaped.clamp(0, i64::from(k));
        let escape_old = kept.escape[i];
        let escape = escaped as f32 / kf;
        let sky = self.new.params.sky * std::f32::consts::PI;
        direct += sky * (escape - escape_old);
        let direct = direct.max(Vec3::ZERO);
        for t in &mut new_terms {
            *t = t.max(Vec3::ZERO);
        }
        push_row(out, counts.iter().copied(), k, self.count_rows);
        out.terms.extend_from_slice(&new_terms);
        out.end_row(start, escape, direct);
        out.rays += 2 * flagged.len() as u64;
    }
}

/// Appends a row of `(texel, hits)` in texel order to `out`: `F = hits / K` as the bake stores
/// it, as f32 weights or as ray counts.
fn push_row(
    out: &mut ChunkRows,
    counts: impl Iterator<Item = (u32, i64)>,
    k: u32,
    count_rows: bool,
) {
    if count_rows {
        let hits: Vec<u32> = counts
            .flat_map(|(j, c)| std::iter::repeat_n(j, c.max(0) as usize))
            .collect();
        out.counts.push_row(&hits, k);
    } else {
        for (j, c) in counts {
            out.col.push(j);
            out.f.push(c as f32 / k as f32);
        }
    }
}
