//! Building many scenes at once, as a game-asset build step does: a [`Manifest`] lists the
//! scenes and their options, [`build`] bakes each one not already baked (the content-addressed
//! [`cache`]), and a [`BuildReport`] says what happened in a form tools read (JSON, with a
//! schema in `src/build/report.schema.json`).
//!
//! Scenes run one after another, each with all threads; a failing scene is reported and the
//! others still run. A scene is skipped when the hash of its input files, its effective options
//! and lightbake's version matches the record beside its outputs and the outputs are intact.

pub mod cache;
mod manifest;
pub mod options;

use std::path::PathBuf;
use std::sync::Mutex;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::{BakeConfig, BakeReport, Progress, Result};

/// The scenes of a build.
#[derive(Clone, Debug)]
pub struct Manifest {
    pub scenes: Vec<ManifestScene>,
    /// Bake every scene even where the cache says its outputs are up to date.
    pub force: bool,
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
    pub config: BakeConfig,
}

/// What became of one scene.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Status {
    Baked,
    /// The cache matched: the outputs were left as they were.
    Skipped,
    Failed,
}

/// The planner's estimate of the relative error a renderer will show (`None` parts were not
/// estimated: no pilot, or `no-auto`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct EstimatedError {
    /// Noise and resolution error in quadrature ([`crate::plan::Plan::predicted_error`]).
    pub total: Option<f32>,
    pub noise: Option<f32>,
    pub resolution: Option<f32>,
}

/// The figures of a finished bake, recorded with its outputs and reported again on a skip.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SceneResult {
    pub texels: Option<usize>,
    pub pages: Option<usize>,
    pub estimated_error: Option<EstimatedError>,
    pub warnings: Vec<String>,
}

/// One scene's line of the report.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneReport {
    /// The scene's path as the manifest gives it.
    pub path: PathBuf,
    pub status: Status,
    /// Wall time of this scene in this build (hashing, and baking unless skipped).
    pub seconds: f64,
    #[serde(flatten)]
    pub result: SceneResult,
    /// Why the scene failed.
    pub error: Option<String>,
}

/// What a build did, scene by scene in manifest order.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BuildReport {
    /// lightbake's version.
    pub lightbake: String,
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
    pub max_error: Option<f32>,
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
/// early: a scene's failure is in its report. Cancelling through `progress` fails the scene
/// under way and every scene after it.
pub fn build(manifest: &Manifest, progress: &dyn Progress) -> BuildReport {
    let scenes = manifest
        .scenes
        .iter()
        .map(|scene| {
            let start = Instant::now();
            let (status, result, error) = match build_scene(scene, manifest.force, progress) {
                Ok((status, result)) => (status, result, None),
                Err(e) => (Status::Failed, SceneResult::default(), Some(e.to_string())),
            };
            SceneReport {
                path: scene.path.clone(),
                status,
                seconds: start.elapsed().as_secs_f64(),
                result,
                error,
            }
        })
        .collect();
    BuildReport {
        lightbake: env!("CARGO_PKG_VERSION").to_string(),
        scenes,
    }
}

fn build_scene(
    scene: &ManifestScene,
    force: bool,
    progress: &dyn Progress,
) -> Result<(Status, SceneResult)> {
    if progress.aborted() {
        return Err(crate::Error::Aborted);
    }
    let key = cache::key(&scene.input, &scene.config)?;
    if !force && let Some(record) = cache::hit(&scene.output, &key) {
        return Ok((Status::Skipped, record.result));
    }
    // A record left from an earlier bake must not vouch for half-written new outputs.
    let _ = std::fs::remove_file(scene.output.join(cache::RECORD));
    let warnings = Warnings {
        inner: progress,
        seen: Mutex::default(),
    };
    let report = crate::bake(&scene.input, &scene.output, &scene.config, &warnings)?;
    let result = SceneResult::of(&report, warnings.seen.into_inner().unwrap_or_default());
    cache::store(&scene.output, &key, &report.files, &result)?;
    Ok((Status::Baked, result))
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
