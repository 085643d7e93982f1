//! The content-addressed cache: a scene's outputs carry the hash of everything they were
//! made from, and a build skips the scene while that hash matches and the outputs are intact.
//!
//! The key is BLAKE3 over lightbake's version, the effective [`BakeConfig`] (its `Debug` form,
//! which names every field), the input's file name (output names derive from it) and the bytes
//! of the input and of every external buffer and image it names ([`scene::external_files`]).
//! The record, [`RECORD`] in the output directory, holds the key, each output file with its own
//! hash (checked before a skip: an edited or deleted page means a re-bake), and the scene's
//! results, so a skipped scene reports the same figures and warnings as when it was baked.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::SceneResult;
use crate::{BakeConfig, Error, Result, scene};

/// File name of the record in a scene's output directory.
pub(crate) const RECORD: &str = "lightbake-build.json";

/// What a successful bake leaves beside its outputs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(super) struct Record {
    pub(crate) key: String,
    /// The key without the input's bytes ([`options_key`]): a record whose `options` match but
    /// whose `key` does not was made from another version of the input with the same options,
    /// which an incremental bake can start from. Empty in records that predate it.
    #[serde(default)]
    pub(crate) options: String,
    /// Output files relative to the output directory, with their BLAKE3 hashes.
    pub(crate) files: Vec<(PathBuf, String)>,
    pub(crate) result: SceneResult,
}

/// The cache key of baking `input` with `config`.
pub(super) fn key(input: &Path, config: &BakeConfig) -> Result<String> {
    let mut hasher = blake3::Hasher::new();
    hasher.update(concat!("lightbake ", env!("CARGO_PKG_VERSION"), "\n").as_bytes());
    hasher.update(format!("{config:?}\n").as_bytes());
    let name = input.file_name().unwrap_or_default().to_string_lossy();
    hasher.update(format!("{name}\n").as_bytes());
    for file in std::iter::once(input.to_path_buf()).chain(scene::external_files(input)?) {
        let bytes = std::fs::read(&file).map_err(|e| Error::io(&file, e))?;
        // Length-prefixed, so the boundary between files is part of the hash.
        hasher.update(&(bytes.len() as u64).to_le_bytes());
        hasher.update(&bytes);
    }
    Ok(hasher.finalize().to_hex().to_string())
}

/// The cache key without the input's content: lightbake's version, the effective options and
/// the input's file name.
pub(super) fn options_key(input: &Path, config: &BakeConfig) -> String {
    let mut hasher = blake3::Hasher::new();
    hasher.update(concat!("lightbake ", env!("CARGO_PKG_VERSION"), "\n").as_bytes());
    hasher.update(format!("{config:?}\n").as_bytes());
    let name = input.file_name().unwrap_or_default().to_string_lossy();
    hasher.update(format!("{name}\n").as_bytes());
    hasher.finalize().to_hex().to_string()
}

fn hash_file(path: &Path) -> Result<String> {
    let mut hasher = blake3::Hasher::new();
    hasher
        .update_reader(std::fs::File::open(path).map_err(|e| Error::io(path, e))?)
        .map_err(|e| Error::io(path, e))?;
    Ok(hasher.finalize().to_hex().to_string())
}

/// The record in `output` if every output it lists is as written (whatever its key).
pub(super) fn intact(output: &Path) -> Option<Record> {
    let text = std::fs::read(output.join(RECORD)).ok()?;
    let record: Record = serde_json::from_slice(&text).ok()?;
    let intact = record
        .files
        .iter()
        .all(|(file, hash)| hash_file(&output.join(file)).is_ok_and(|h| h == *hash));
    intact.then_some(record)
}

/// Writes the record of a bake of `files` (below `output`) with `key`.
pub(super) fn store(
    output: &Path,
    (key, options): (&str, &str),
    files: &[PathBuf],
    result: &SceneResult,
) -> Result<()> {
    let files = files
        .iter()
        .map(|f| {
            let relative = f.strip_prefix(output).unwrap_or(f).to_path_buf();
            Ok((relative, hash_file(f)?))
        })
        .collect::<Result<Vec<_>>>()?;
    let record = Record {
        key: key.to_string(),
        options: options.to_string(),
        files,
        result: result.clone(),
    };
    let path = output.join(RECORD);
    let text = serde_json::to_string_pretty(&record).expect("a record serialises");
    std::fs::write(&path, text).map_err(|e| Error::io(&path, e))
}
