//! Building many scenes at once, as a game-asset build step does: a [`Manifest`] lists the
//! scenes and their options, [`build`] bakes each one not already baked (the content-addressed
//! `cache`), and a [`BuildReport`] says what happened in a form tools read (JSON, with a
//! schema in `src/build/report.schema.json`).
//!
//! Scenes the cache does not vouch for are baked side by side as memory allows: up to
//! [`Manifest::jobs`] at once, in manifest order, the next starting only when its expected peak
//! (`bake::memory::expected_peak`) fits beside those running within the memory available when
//! the build began. Each scene's memory limit is fixed then too, so what a bake chooses and
//! writes, and the report (in manifest order), do not depend on what ran beside it. A failing
//! scene is reported and the others still run. A scene is skipped when the hash of its input files, its effective options
//! and lightbake's version matches the record beside its outputs and the outputs are intact.

pub(crate) mod cache;
mod manifest;
pub mod options;

use std::path::PathBuf;
use std::sync::{Condvar, Mutex};
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::{BakeConfig, BakeReport, Progress, Result};

/// The scenes of a build.
#[derive(Clone, Debug)]
pub struct Manifest {
    /// The scenes, in manifest order.
    pub scenes: Vec<ManifestScene>,
    /// Bake every scene even where the cache says its outputs are up to date.
    pub force: bool,
    /// Most scenes baked at once (`None`: as many as the rayon pool has threads); fewer run
    /// when their expected peaks do not fit the memory available.
    pub jobs: Option<usize>,
}

/// One scene of a build.
#[derive(Clone, Debug)]
pub struct ManifestScene {
    /// The path as the manifest gives it (for reports).
    pub path: PathBuf,
    /// The input glTF or GLB.
    pub input: PathBuf,
    /// Output directory.
    pub output: PathBuf,
    /// The options it is baked with (the manifest's defaults and the scene's own).
    pub config: BakeConfig,
}

/// What became of one scene.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Status {
    /// The scene was baked and its outputs written.
    Baked,
    /// The scene changed only by node transforms since its last bake (kept with
    /// `keep-transport`): re-baked incrementally from it (`bake --since`), outputs written.
    Incremental,
    /// The cache matched: the outputs were left as they were.
    Skipped,
    /// The bake failed (see [`SceneReport::error`]).
    Failed,
}

/// The planner's estimate of the relative error a renderer will show (`None` parts were not
/// estimated: no pilot, or `no-auto`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct EstimatedError {
    /// Noise and resolution error in quadrature ([`crate::plan::Plan::predicted_error`]).
    pub total: Option<f32>,
    pub(crate) noise: Option<f32>,
    pub(crate) resolution: Option<f32>,
}

/// The figures of a finished bake, recorded with its outputs and reported again on a skip.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SceneResult {
    /// Texels baked.
    pub texels: Option<usize>,
    /// Lightmap pages written.
    pub pages: Option<usize>,
    /// The planner's estimate of the error a renderer will show.
    pub estimated_error: Option<EstimatedError>,
    /// The bake's warnings.
    pub warnings: Vec<String>,
}

/// One scene's line of the report.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneReport {
    /// The scene's path as the manifest gives it.
    pub path: PathBuf,
    /// Baked, skipped or failed.
    pub status: Status,
    /// Wall time of this scene in this build (hashing, and baking unless skipped).
    pub seconds: f64,
    /// The figures of the bake (a skipped scene's are its last bake's).
    #[serde(flatten)]
    pub result: SceneResult,
    /// Why the scene failed.
    pub error: Option<String>,
    /// What an incremental re-bake re-traced (`status: "incremental"` only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub incremental: Option<IncrementalFigures>,
}

/// What an incremental re-bake of a scene re-traced, for the report.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct IncrementalFigures {
    /// Rows (texels) of the bake.
    pub rows: usize,
    /// Rows traced again whole.
    pub retraced: usize,
    /// Rows patched (some rays traced again).
    pub patched: usize,
    /// The transport time saved against tracing every row, estimated at the bake's rate.
    pub seconds_saved: f64,
}

/// What a build did, scene by scene in manifest order.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BuildReport {
    /// lightbake's version.
    pub(crate) lightbake: String,
    /// One line per scene, in manifest order.
    pub scenes: Vec<SceneReport>,
}

impl BuildReport {
    /// Some scene failed.
    pub fn failed(&self) -> bool {
        self.scenes.iter().any(|s| s.status == Status::Failed)
    }

    /// What fails `gate`, as `path: problem` lines (empty: the build passes). Failed scenes
    /// are not checked: [`BuildReport::failed`] says so.
    pub fn gate(&self, gate: &Gate) -> Vec<String> {
        self.scenes
            .iter()
            .filter(|s| s.status != Status::Failed)
            .flat_map(|s| {
                let path = s.path.display().to_string();
                let problems = gate.problems(&s.result);
                problems.into_iter().map(move |p| format!("{path}: {p}"))
            })
            .collect()
    }

    /// The report as JSON (the schema is `src/build/report.schema.json`).
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("a report serialises")
    }
}

/// The error gate: a bake is not good enough when its estimated error exceeds `max_error`
/// (or it has no estimate to check), or, with `deny_warnings`, when it warned.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Gate {
    /// The largest estimated error (relative) a bake may have; `None`: no limit.
    pub max_error: Option<f32>,
    /// A bake that warned fails.
    pub deny_warnings: bool,
}

impl Gate {
    /// Why `result` fails the gate (empty: it passes).
    pub fn problems(&self, result: &SceneResult) -> Vec<String> {
        let mut problems = Vec::new();
        if let Some(max) = self.max_error {
            match result.estimated_error.and_then(|e| e.total) {
                Some(e) if e <= max => {}
                Some(e) => problems.push(format!(
                    "estimated error {:.2}% exceeds the maximum {:.2}%",
                    e * 100.0,
                    max * 100.0
                )),
                None => problems.push("no estimated error to check (no-auto?)".to_string()),
            }
        }
        if self.deny_warnings && !result.warnings.is_empty() {
            problems.push(format!("{} warning(s)", result.warnings.len()));
        }
        problems
    }
}

impl SceneResult {
    /// The figures of `report`, with the `warnings` its bake gave.
    pub fn of(report: &BakeReport, warnings: Vec<String>) -> SceneResult {
        SceneResult {
            texels: Some(report.texels),
            pages: Some(report.pages),
            estimated_error: report.plan.as_ref().map(|p| EstimatedError {
                total: p.predicted_error(),
                noise: p.predicted_noise,
                resolution: p.predicted_resolution,
            }),
            warnings,
        }
    }
}

/// Bakes every scene of `manifest` that is not up to date (see the module docs). Never stops
/// early: a scene's failure is in its report. Cancelling through `progress` fails the scenes
/// under way and every scene after them.
pub fn build(manifest: &Manifest, progress: &dyn Progress) -> BuildReport {
    let available = crate::bake::memory::limit(&BakeConfig::default());
    // Each scene's memory limit is fixed now: read as each bake starts, it would depend on
    // what the others running beside it hold (and the automatic choice on it).
    let configs: Vec<BakeConfig> = (manifest.scenes.iter())
        .map(|scene| BakeConfig {
            max_memory: Some(scene.config.max_memory.unwrap_or(available)),
            ..scene.config.clone()
        })
        .collect();
    let mut reports: Vec<Option<SceneReport>> = vec![None; manifest.scenes.len()];
    let mut pending = Vec::new();
    for (k, scene) in manifest.scenes.iter().enumerate() {
        let start = Instant::now();
        match look_up(scene, manifest.force, progress) {
            Ok(Lookup::Hit(result)) => {
                reports[k] = Some(scene_report(scene, start, Ok((Status::Skipped, result))))
            }
            Ok(Lookup::Miss(key, since)) => pending.push(Pending {
                scene: k,
                key,
                since,
                seconds: start.elapsed().as_secs_f64(),
            }),
            Err(e) => reports[k] = Some(scene_report(scene, start, Err(e))),
        }
    }
    let jobs = manifest.jobs.unwrap_or_else(rayon::current_num_threads);
    let jobs = jobs.clamp(1, pending.len().max(1));
    let bake = |p: &Pending| {
        let start = Instant::now();
        let scene = &manifest.scenes[p.scene];
        let result = bake_scene(scene, &configs[p.scene], &p.key, p.since.as_ref(), progress);
        let (result, figures) = match result {
            Ok((status, result, figures)) => (Ok((status, result)), figures),
            Err(e) => (Err(e), None),
        };
        let mut report = scene_report(scene, start, result);
        report.incremental = figures;
        report.seconds += p.seconds;
        report
    };
    if jobs == 1 {
        for p in &pending {
            reports[p.scene] = Some(bake(p));
        }
    } else {
        let peaks: Vec<u64> = (pending.iter())
            .map(|p| {
                let scene = &manifest.scenes[p.scene];
                crate::bake::memory::expected_peak(&scene.input, &configs[p.scene])
                    .unwrap_or(available)
            })
            .collect();
        for (p, report) in pending
            .iter()
            .zip(side_by_side(&pending, &peaks, available, jobs, bake))
        {
            reports[p.scene] = Some(report);
        }
    }
    BuildReport {
        lightbake: env!("CARGO_PKG_VERSION").to_string(),
        scenes: reports
            .into_iter()
            .map(|r| r.expect("every scene reported"))
            .collect(),
    }
}

/// A scene the cache did not vouch for: its key, and the seconds spent finding out.
struct Pending {
    scene: usize,
    key: String,
    /// The previous bake to start from incrementally, and its record.
    since: Option<(PathBuf, cache::Record)>,
    seconds: f64,
}

/// Runs `run` on every item, at most `jobs` at once, starting them in order: the next starts
/// when a slot is free and its expected peak (`peaks`) fits `budget` beside the peaks of those
/// running (or nothing runs: a scene above the budget runs alone). Results in item order. The
/// bakes share the global rayon pool: work stealing hands the threads of a finished or waiting
/// bake to those still running, where a fixed split would leave them idle.
fn side_by_side<T: Sync, R: Send>(
    items: &[T],
    peaks: &[u64],
    budget: u64,
    jobs: usize,
    run: impl Fn(&T) -> R + Sync,
) -> Vec<R> {
    let slots = Slots {
        state: Mutex::new((0, 0, 0)),
        changed: Condvar::new(),
    };
    let results: Vec<Mutex<Option<R>>> = items.iter().map(|_| Mutex::new(None)).collect();
    std::thread::scope(|s| {
        for _ in 0..jobs.min(items.len()) {
            s.spawn(|| {
                while let Some(k) = slots.take(peaks, budget, jobs) {
                    *results[k].lock().unwrap() = Some(run(&items[k]));
                    slots.give_back(peaks[k]);
                }
            });
        }
    });
    results
        .into_iter()
        .map(|r| r.into_inner().unwrap().expect("every item ran"))
        .collect()
}

/// The admission of [`side_by_side`]: (next item, items running, their peaks' sum).
struct Slots {
    state: Mutex<(usize, usize, u64)>,
    changed: Condvar,
}

impl Slots {
    /// Waits until the next item may start, and takes it (`None`: none is left).
    fn take(&self, peaks: &[u64], budget: u64, jobs: usize) -> Option<usize> {
        let mut state = self.state.lock().unwrap();
        loop {
            let (next, running, held) = *state;
            if next >= peaks.len() {
                return None;
            }
            if fits(held, peaks[next], budget, running, jobs) {
                *state = (next + 1, running + 1, held + peaks[next]);
                return Some(next);
            }
            state = self.changed.wait(state).unwrap();
        }
    }

    fn give_back(&self, peak: u64) {
        let mut state = self.state.lock().unwrap();
        state.1 -= 1;
        state.2 -= peak;
        self.changed.notify_all();
    }
}

/// Whether a bake expected to peak at `peak` may start beside `running` bakes holding `held`.
fn fits(held: u64, peak: u64, budget: u64, running: usize, jobs: usize) -> bool {
    running == 0 || (running < jobs && held.saturating_add(peak) <= budget)
}

/// A scene's report line from what became of it.
fn scene_report(
    scene: &ManifestScene,
    start: Instant,
    outcome: Result<(Status, SceneResult)>,
) -> SceneReport {
    let (status, result, error) = match outcome {
        Ok((status, result)) => (status, result, None),
        Err(e) => (
            Status::Failed,
            SceneResult::default(),
            Some(e.with_causes()),
        ),
    };
    SceneReport {
        path: scene.path.clone(),
        status,
        seconds: start.elapsed().as_secs_f64(),
        result,
        error,
        incremental: None,
    }
}

/// What the cache says of a scene.
enum Lookup {
    /// Up to date: the recorded figures.
    Hit(SceneResult),
    /// To be baked: the key to record, and the previous bake an incremental bake can start
    /// from (its glTF and record).
    Miss(String, Option<(PathBuf, cache::Record)>),
}

fn look_up(scene: &ManifestScene, force: bool, progress: &dyn Progress) -> Result<Lookup> {
    if progress.aborted() {
        return Err(crate::Error::Aborted);
    }
    let key = cache::key(&scene.input, &scene.config)?;
    let record = cache::intact(&scene.output);
    match record {
        Some(record) if !force && record.key == key => Ok(Lookup::Hit(record.result)),
        Some(record) if !force => Ok(Lookup::Miss(key, since(scene, record))),
        _ => Ok(Lookup::Miss(key, None)),
    }
}

/// The previous bake of `scene` (intact, `record` its record) an incremental bake can start
/// from: one made with the same options, the transport kept (`keep-transport`). Whether the
/// input changed only by node transforms is for the incremental bake to find (it bakes in full
/// otherwise).
fn since(scene: &ManifestScene, record: cache::Record) -> Option<(PathBuf, cache::Record)> {
    if !scene.config.output.keep_transport
        || record.options != cache::options_key(&scene.input, &scene.config)
    {
        return None;
    }
    let stem = scene.input.file_stem()?.to_string_lossy().into_owned();
    let listed = |name: &str| record.files.iter().any(|(f, _)| f.as_os_str() == name);
    let gltf = [format!("{stem}.gltf"), format!("{stem}.glb")]
        .into_iter()
        .find(|g| listed(g))?;
    listed(&format!("{stem}.transport")).then(|| (scene.output.join(gltf), record))
}

/// Bakes `scene` with `config` (its own, the memory limit fixed), incrementally from `since`
/// when given, and records `key` with it.
fn bake_scene(
    scene: &ManifestScene,
    config: &BakeConfig,
    key: &str,
    since: Option<&(PathBuf, cache::Record)>,
    progress: &dyn Progress,
) -> Result<(Status, SceneResult, Option<IncrementalFigures>)> {
    if progress.aborted() {
        return Err(crate::Error::Aborted);
    }
    // A record left from an earlier bake must not vouch for half-written new outputs: an
    // interrupted bake (incremental or not) leaves no record, and the next build bakes in full.
    // An incremental bake reads the old outputs before it writes any file.
    let _ = std::fs::remove_file(scene.output.join(cache::RECORD));
    let warnings = Warnings {
        inner: progress,
        seen: Mutex::default(),
    };
    let report = match since {
        Some((gltf, _)) => {
            crate::incremental::bake_since(&scene.input, gltf, &scene.output, config, &warnings)?
        }
        None => crate::bake(&scene.input, &scene.output, config, &warnings)?,
    };
    let mut result = SceneResult::of(&report, warnings.seen.into_inner().unwrap_or_default());
    let incremental = report.incremental.as_ref().filter(|i| i.full.is_none());
    if let (Some(_), Some((_, record))) = (incremental, since) {
        // The incremental bake runs with the previous bake's settings: its estimate stands.
        result.estimated_error = record.result.estimated_error;
    }
    let options = cache::options_key(&scene.input, &scene.config);
    cache::store(&scene.output, (key, &options), &report.files, &result)?;
    Ok(match incremental {
        Some(i) => (
            Status::Incremental,
            result,
            Some(IncrementalFigures {
                rows: i.rows,
                retraced: i.retraced,
                patched: i.patched,
                seconds_saved: i.seconds_saved,
            }),
        ),
        None => (Status::Baked, result, None),
    })
}

/// Passes everything on to `inner` and keeps the warnings.
struct Warnings<'a> {
    inner: &'a dyn Progress,
    seen: Mutex<Vec<String>>,
}

impl Progress for Warnings<'_> {
    fn begin(&self, stage: &str, total: u64) {
        self.inner.begin(stage, total);
    }
    fn advance(&self, n: u64) {
        self.inner.advance(n);
    }
    fn end(&self) {
        self.inner.end();
    }
    fn warn(&self, message: &str) {
        self.seen.lock().unwrap().push(message.to_string());
        self.inner.warn(message);
    }
    fn aborted(&self) -> bool {
        self.inner.aborted()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn result(total: Option<f32>, warnings: &[&str]) -> SceneResult {
        SceneResult {
            estimated_error: Some(EstimatedError {
                total,
                noise: total,
                resolution: None,
            }),
            warnings: warnings.iter().map(|w| w.to_string()).collect(),
            ..SceneResult::default()
        }
    }

    #[test]
    fn side_by_side_keeps_the_order_the_slots_and_the_budget() {
        use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
        // Peaks of 3, 3, 5, 1, 1 and 9 units in a budget of 8, at most 3 at once.
        let peaks = [3, 3, 5, 1, 1, 9];
        let (running, held) = (AtomicUsize::new(0), AtomicU64::new(0));
        let (most_running, most_held) = (AtomicUsize::new(0), AtomicU64::new(0));
        let items: Vec<usize> = (0..peaks.len()).collect();
        let out = side_by_side(&items, &peaks, 8, 3, |&k| {
            let r = running.fetch_add(1, Ordering::SeqCst) + 1;
            let h = held.fetch_add(peaks[k], Ordering::SeqCst) + peaks[k];
            most_running.fetch_max(r, Ordering::SeqCst);
            // The one above the budget runs alone.
            assert!(h <= 8 || r == 1, "item {k}: {r} running, {h} held");
            std::thread::sleep(std::time::Duration::from_millis(20));
            held.fetch_sub(peaks[k], Ordering::SeqCst);
            running.fetch_sub(1, Ordering::SeqCst);
            most_held.fetch_max(h, Ordering::SeqCst);
            10 * k
        });
        assert_eq!(out, [0, 10, 20, 30, 40, 50]);
        assert!(most_running.load(Ordering::SeqCst) >= 2);
        assert!(most_running.load(Ordering::SeqCst) <= 3);
        assert!(fits(0, 100, 8, 0, 1) && !fits(3, 6, 8, 1, 3) && !fits(1, 1, 8, 3, 3));
    }

    #[test]
    fn the_gate_checks_the_estimate_and_the_warnings() {
        let gate = Gate {
            max_error: Some(0.05),
            deny_warnings: true,
        };
        assert!(gate.problems(&result(Some(0.05), &[])).is_empty());
        let over = gate.problems(&result(Some(0.051), &[]));
        assert_eq!(over, ["estimated error 5.10% exceeds the maximum 5.00%"]);
        assert_eq!(gate.problems(&result(None, &[])).len(), 1);
        assert_eq!(
            gate.problems(&result(Some(0.01), &["no lights"])),
            ["1 warning(s)"]
        );
        // Off by default.
        assert!(Gate::default().problems(&result(None, &["x"])).is_empty());
    }
}
