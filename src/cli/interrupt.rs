//! SIGINT and SIGTERM: the first asks the running command to stop at its next check point (the
//! library then returns `Error::Aborted` and its staged output is removed); a second one ends
//! the process at once, for a stage that does not check (its temporary files may then remain).

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use anyhow::{Context, Result};
use signal_hook::consts::{SIGINT, SIGTERM};
use signal_hook::flag;

/// The number of the signal received, 0 while none.
static SIGNAL: AtomicUsize = AtomicUsize::new(0);
/// Set by the first signal: arms the immediate exit on the second.
static RECEIVED: AtomicBool = AtomicBool::new(false);

/// Installs the handlers (for the commands that check [`received`] while they work).
pub fn install() -> Result<()> {
    for signal in [SIGINT, SIGTERM] {
        // The order matters: the exit only fires when an earlier signal has set the flag.
        flag::register_conditional_shutdown(signal, exit_code(signal), &RECEIVED)
            .and_then(|_| flag::register(signal, &RECEIVED))
            .and_then(|_| flag::register_usize(signal, &SIGNAL, signal as usize))
            .with_context(|| format!("cannot install a handler for signal {signal}"))?;
    }
    Ok(())
}

/// The signal received since [`install`], if any.
pub fn received() -> Option<i32> {
    match SIGNAL.load(Ordering::Relaxed) {
        0 => None,
        signal => Some(signal as i32),
    }
}

/// The shell's convention for a process ended by `signal`: 128 + its number (130 for SIGINT).
pub fn exit_code(signal: i32) -> i32 {
    128 + signal
}
