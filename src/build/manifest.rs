//! The manifest file (`lightbake.toml`): `[defaults]` and one `[[scene]]` per scene; the format
//! is documented in the guide ([`crate::guide::build`]).

use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::options::Options;
use super::{Manifest, ManifestScene};
use crate::{Error, Result};

/// The file as written; every table's unknown keys are refused by name.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    #[serde(default)]
    defaults: toml::Table,
    #[serde(default)]
    scene: Vec<toml::Table>,
}

impl Manifest {
    /// Reads a manifest file; paths in it are relative to its directory.
    pub fn load(path: &Path) -> Result<Manifest> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        Manifest::parse(&text, path.parent().unwrap_or(Path::new("")))
            .map_err(|message| Error::invalid(path, message))
    }

    /// Parses manifest text; paths in it are relative to `root`. The error says where.
    pub fn parse(text: &str, root: &Path) -> Result<Manifest, String> {
        let file: File = toml::from_str(text).map_err(|e| e.to_string())?;
        let defaults: Options = file
            .defaults
            .clone()
            .try_into()
            .map_err(|e| format!("[defaults]: {e}"))?;
        defaults.config().map_err(|e| format!("[defaults]: {e}"))?;
        let scenes = file
            .scene
            .into_iter()
            .enumerate()
            .map(|(k, table)| scene(k, table, &file.defaults, root))
            .collect::<Result<Vec<_>, String>>()?;
        if scenes.is_empty() {
            return Err("no [[scene]] entries".into());
        }
        Ok(Manifest {
            scenes,
            force: false,
            jobs: None,
        })
    }
}

/// Scene `k` (counted from 1 in messages): its paths and its options over the defaults.
fn scene(
    k: usize,
    mut table: toml::Table,
    defaults: &toml::Table,
    root: &Path,
) -> Result<ManifestScene, String> {
    let mut take_path = |key: &str| match table.remove(key) {
        Some(toml::Value::String(s)) => Ok(PathBuf::from(s)),
        Some(other) => Err(format!(
            "`{key}` must be a string, not {}",
            other.type_str()
        )),
        None => Err(format!("`{key}` is missing")),
    };
    let named = |e: String| format!("scene {} ([[scene]] number {}): {e}", k + 1, k + 1);
    let path = take_path("path").map_err(named)?;
    let output = take_path("output").map_err(named)?;
    let named = |e: String| format!("scene {} ({}): {e}", k + 1, path.display());
    let mut merged = defaults.clone();
    merged.extend(table);
    let options: Options = merged
        .try_into()
        .map_err(|e: toml::de::Error| named(e.to_string()))?;
    let config = options.config().map_err(|e| named(e.to_string()))?;
    Ok(ManifestScene {
        input: root.join(&path),
        output: root.join(output),
        path,
        config,
    })
}
