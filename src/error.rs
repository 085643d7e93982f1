//! Library errors, sorted by fault (as exrs does): the input is invalid, the input uses something
//! lightbake does not support, the bake would not fit in memory, the file system failed, a
//! process of a distributed bake failed or could not be reached, or the caller cancelled.

use std::path::PathBuf;

/// Everything that can stop a bake.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The input file (or an option) is wrong; the message says what and where.
    #[error("{}: {message}", path.display())]
    Invalid { path: PathBuf, message: String },

    /// The input is valid but uses something lightbake cannot bake.
    #[error("{}: unsupported: {message}", path.display())]
    Unsupported { path: PathBuf, message: String },

    /// An option is out of range or inconsistent.
    #[error("invalid option: {0}")]
    Option(String),

    /// Reading or writing a file failed.
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },

    /// The bake would need more memory than it may use (`BakeConfig::max_memory`); refused
    /// before any heavy work.
    #[error("{}: {message}", path.display())]
    Memory { path: PathBuf, message: String },

    /// A distributed bake lost a process or could not reach one; the message names it.
    #[error("distributed bake: {0}")]
    Cluster(String),

    /// The caller's [`crate::Progress::aborted`] returned true.
    #[error("aborted")]
    Aborted,
}

impl Error {
    pub fn invalid(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        Error::Invalid {
            path: path.into(),
            message: message.into(),
        }
    }
    pub fn unsupported(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        Error::Unsupported {
            path: path.into(),
            message: message.into(),
        }
    }
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }
}

pub type Result<T, E = Error> = std::result::Result<T, E>;
