//! Terminal progress for the library's [`Progress`] callbacks.

use std::sync::Mutex;
use std::time::Duration;

use indicatif::{ProgressBar, ProgressStyle};
use lightbake::Progress;

/// Progress bars on a terminal (one per stage, with rate and ETA); nothing otherwise.
pub struct Bars {
    pub enabled: bool,
    pub bar: Mutex<Option<ProgressBar>>,
    /// Warnings shown so far (for `--deny-warnings`).
    pub warnings: Mutex<Vec<String>>,
}

impl Progress for Bars {
    fn begin(&self, stage: &str, total: u64) {
        if !self.enabled {
            return;
        }
        let bar = ProgressBar::new(total);
        bar.set_style(
            ProgressStyle::with_template("{prefix:>10} [{bar:30}] {pos}/{len} {per_sec} ETA {eta}")
                .unwrap()
                .progress_chars("=> "),
        );
        bar.set_prefix(stage.to_string());
        bar.enable_steady_tick(Duration::from_millis(200));
        // Scenes baked side by side (`build --jobs`) share the one bar: the latest stage shows.
        if let Some(old) = self.bar.lock().unwrap().replace(bar) {
            old.finish_and_clear();
        }
    }
    fn advance(&self, n: u64) {
        if let Some(bar) = &*self.bar.lock().unwrap() {
            bar.inc(n);
        }
    }
    fn end(&self) {
        if let Some(bar) = self.bar.lock().unwrap().take() {
            bar.finish_and_clear();
        }
    }
    fn warn(&self, message: &str) {
        self.warnings.lock().unwrap().push(message.to_string());
        match &*self.bar.lock().unwrap() {
            Some(bar) => bar.suspend(|| eprintln!("warning: {message}")),
            None => eprintln!("warning: {message}"),
        }
    }
    fn aborted(&self) -> bool {
        crate::interrupt::received().is_some()
    }
}

impl Bars {
    /// Bars only when asked for and stderr is a terminal.
    pub fn new(quiet: bool) -> Bars {
        use std::io::IsTerminal;
        Bars {
            enabled: !quiet && std::io::stderr().is_terminal(),
            bar: Mutex::new(None),
            warnings: Mutex::default(),
        }
    }
}
