//! Progress reporting and cancellation. The library never prints: it tells a caller-supplied
//! [`Progress`] what it is doing, and stops with [`crate::Error::Aborted`] when asked to.

/// Receives progress from the pipeline. Implementations must be cheap and thread-safe:
/// `advance` is called from worker threads (once per chunk of work, not per ray).
pub trait Progress: Sync {
    /// A stage starts; `total` units of work follow (0 when unknown).
    fn begin(&self, stage: &str, total: u64) {
        let _ = (stage, total);
    }
    /// `n` more units of the current stage are done.
    fn advance(&self, n: u64) {
        let _ = n;
    }
    /// The current stage ended.
    fn end(&self) {}
    /// A warning the user should see (the library never prints it itself).
    fn warn(&self, message: &str) {
        let _ = message;
    }
    /// Return true to cancel the bake at the next check point.
    fn aborted(&self) -> bool {
        false
    }
}

/// Ignores everything; never aborts.
pub struct NoProgress;
impl Progress for NoProgress {}

/// Shows nothing of a sub-run (a pilot bake) but stops it when `0` is aborted.
pub(crate) struct CancelOnly<'a>(pub(crate) &'a dyn Progress);
impl Progress for CancelOnly<'_> {
    fn aborted(&self) -> bool {
        self.0.aborted()
    }
}

/// Collects warnings (for tests and build tools that want them as data).
#[derive(Default)]
pub struct CollectWarnings(pub std::sync::Mutex<Vec<String>>);
impl Progress for CollectWarnings {
    fn warn(&self, message: &str) {
        self.0.lock().unwrap().push(message.to_string());
    }
}
