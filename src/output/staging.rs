//! Atomic output: files are written into a hidden temporary directory inside the output
//! directory and renamed into place together at the end. A failed or cancelled bake leaves
//! nothing behind (the temporary directory is removed on drop), and a file that would overwrite
//! one of the input's own files is refused.

use std::fs;
use std::path::{Path, PathBuf};

use crate::{Error, Result};

/// Output files being written.
pub struct Staging {
    dir: PathBuf,
    tmp: PathBuf,
    names: Vec<String>,
    protected: Vec<PathBuf>,
    committed: bool,
}

impl Staging {
    /// Creates `dir` if needed and a temporary directory inside it. `protected` lists the input
    /// files that must never be overwritten.
    pub fn new(dir: &Path, protected: &[PathBuf]) -> Result<Staging> {
        fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        let dir = dir.canonicalize().map_err(|e| Error::io(dir, e))?;
        let tmp = dir.join(format!(".lightbake-tmp-{}", std::process::id()));
        if tmp.exists() {
            fs::remove_dir_all(&tmp).map_err(|e| Error::io(&tmp, e))?;
        }
        fs::create_dir(&tmp).map_err(|e| Error::io(&tmp, e))?;
        let protected = protected
            .iter()
            .filter_map(|p| p.canonicalize().ok())
            .collect();
        Ok(Staging {
            dir,
            tmp,
            names: Vec::new(),
            protected,
            committed: false,
        })
    }

    /// Stages `bytes` as `name` (a relative path with `/` separators, no `..`).
    pub fn write(&mut self, name: &str, bytes: &[u8]) -> Result<()> {
        let final_path = self.final_path(name)?;
        if self.protected.contains(&final_path) {
            return Err(Error::Option(format!(
                "refusing to overwrite the input file {} (choose another output directory)",
                final_path.display()
            )));
        }
        if self.names.iter().any(|n| n == name) {
            return Err(Error::Internal(format!(
                "output file {name} would be written twice"
            )));
        }
        let path = self.tmp.join(name);
        if let Some(parent) = path.parent() {
            fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
        }
        fs::write(&path, bytes).map_err(|e| Error::io(&path, e))?;
        self.names.push(name.to_string());
        Ok(())
    }

    /// The bytes staged as `name`.
    pub(crate) fn read(&self, name: &str) -> Result<Vec<u8>> {
        self.staged(name)?;
        let path = self.tmp.join(name);
        fs::read(&path).map_err(|e| Error::io(&path, e))
    }

    /// Stages `bytes` as `name` in place of what [`Staging::write`] staged under that name.
    pub(crate) fn replace(&mut self, name: &str, bytes: &[u8]) -> Result<()> {
        self.staged(name)?;
        let path = self.tmp.join(name);
        fs::write(&path, bytes).map_err(|e| Error::io(&path, e))
    }

    /// Whether `name` is staged.
    pub(crate) fn contains(&self, name: &str) -> bool {
        self.names.iter().any(|n| n == name)
    }

    fn staged(&self, name: &str) -> Result<()> {
        match self.contains(name) {
            true => Ok(()),
            false => Err(Error::Internal(format!(
                "output file {name} was not staged"
            ))),
        }
    }

    fn final_path(&self, name: &str) -> Result<PathBuf> {
        let rel = Path::new(name);
        if rel.is_absolute()
            || rel
                .components()
                .any(|c| !matches!(c, std::path::Component::Normal(_)))
        {
            return Err(Error::Internal(format!(
                "output file name {name:?} must be a plain relative path"
            )));
        }
        Ok(self.dir.join(rel))
    }

    /// Renames every staged file into place; returns the final paths.
    pub fn commit(mut self) -> Result<Vec<PathBuf>> {
        let mut done = Vec::with_capacity(self.names.len());
        for name in &self.names {
            let from = self.tmp.join(name);
            let to = self.final_path(name)?;
            if let Some(parent) = to.parent() {
                fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
            }
            fs::rename(&from, &to).map_err(|e| Error::io(&to, e))?;
            done.push(to);
        }
        self.committed = true;
        let _ = fs::remove_dir_all(&self.tmp);
        Ok(done)
    }
}

impl Drop for Staging {
    fn drop(&mut self) {
        if !self.committed {
            let _ = fs::remove_dir_all(&self.tmp);
        }
    }
}
