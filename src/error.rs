//! Library errors, sorted by fault (as exrs does): the input is malformed, the input uses
//! something lightbake does not support, an option is wrong, the file system failed, the bake
//! would not fit in memory, a process of a distributed bake failed or could not be reached,
//! lightbake broke its own invariant (a bug), or the caller cancelled.
//!
//! Each message says its own part once: an error with a cause (`Io`) leaves the cause's text to
//! [`std::error::Error::source`], so printing the chain (anyhow's `{:#}`, or
//! [`Error::with_causes`]) says every part exactly once.

use std::path::PathBuf;

/// Everything that can stop a bake.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The input file is malformed; the message says what and where (`mesh 0 primitive 1: …`).
    #[error("{}: {message}", path.display())]
    Invalid {
        /// The input file.
        path: PathBuf,
        /// What is wrong, and where in the file.
        message: String,
    },

    /// The input is valid but uses something lightbake cannot bake.
    #[error("{}: unsupported: {message}", path.display())]
    Unsupported {
        /// The input file.
        path: PathBuf,
        /// What it uses that lightbake cannot bake.
        message: String,
    },

    /// An option is out of range or inconsistent, or names something the scene does not have
    /// (a camera, a light to relight).
    #[error("invalid option: {0}")]
    Option(String),

    /// Reading or writing a file (or listening on a socket) failed: `path` names it, `source`
    /// says why (it is not repeated in this error's own message).
    #[error("{}", path.display())]
    Io {
        /// The file, directory or address.
        path: PathBuf,
        /// Why it failed.
        #[source]
        source: std::io::Error,
    },

    /// The bake would need more memory than it may use (`BakeConfig::max_memory`); refused
    /// before any heavy work.
    #[error("{}: {message}", path.display())]
    Memory {
        /// The input file.
        path: PathBuf,
        /// The estimate, the limit and what to change.
        message: String,
    },

    /// A distributed bake lost a process or could not reach one; the message names it.
    #[error("distributed bake: {0}")]
    Cluster(String),

    /// lightbake broke one of its own invariants: a bug, whatever the input (please report it
    /// with the input and the options).
    #[error("internal error (a bug in lightbake): {0}")]
    Internal(String),

    /// The caller's [`crate::Progress::aborted`] returned true.
    #[error("aborted")]
    Aborted,
}

impl Error {
    pub(crate) fn invalid(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        Error::Invalid {
            path: path.into(),
            message: message.into(),
        }
    }
    pub(crate) fn unsupported(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        Error::Unsupported {
            path: path.into(),
            message: message.into(),
        }
    }
    /// An [`Error::Io`] on `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }

    /// The message followed by its causes, `a: b: c` — the whole text for a report or a log
    /// line (this error's `Display` leaves the causes to [`std::error::Error::source`]).
    pub fn with_causes(&self) -> String {
        let mut text = self.to_string();
        let mut cause = std::error::Error::source(self);
        while let Some(c) = cause {
            text.push_str(": ");
            text.push_str(&c.to_string());
            cause = c.source();
        }
        text
    }
}

/// A result whose error is lightbake's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_io_error_says_its_cause_once() {
        let missing = std::fs::read("/nonexistent/x.gltf").unwrap_err();
        let os = missing.to_string();
        let e = Error::io("/nonexistent/x.gltf", missing);
        assert_eq!(e.to_string(), "/nonexistent/x.gltf");
        assert_eq!(e.with_causes(), format!("/nonexistent/x.gltf: {os}"));
        assert_eq!(
            Error::Option("rays 0".into()).with_causes(),
            "invalid option: rays 0"
        );
    }
}
