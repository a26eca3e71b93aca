//! Ctrl-C and SIGTERM for every command, one handler for the process. A
//! command that ends cleanly on its own at a signal (acquire, convert,
//! batch) takes [`stop_flag`] and polls it; any other command is ended at
//! once, the temporaries of the outputs it was writing removed first, with
//! exit status 130 (128 + SIGINT), so no signal leaves a partial file.

use std::sync::atomic::{AtomicBool, Ordering};

/// Set by the first signal, for the commands that poll it.
static STOP: AtomicBool = AtomicBool::new(false);
/// Whether the running command polls [`STOP`].
static POLLED: AtomicBool = AtomicBool::new(false);

/// Exit status of a command ended by a signal it does not poll.
pub const SIGNALLED: i32 = 130;

/// Installs the handler (once, at start).
pub fn install() -> anyhow::Result<()> {
    ctrlc::set_handler(|| {
        if POLLED.load(Ordering::SeqCst) {
            // A second Ctrl-C while stopping is ignored: the files must close.
            STOP.store(true, Ordering::SeqCst);
        } else {
            scatterscope::files::output::remove_unfinished();
            eprintln!("interrupted (Ctrl-C or SIGTERM): unfinished outputs removed");
            std::process::exit(SIGNALLED);
        }
    })
    .map_err(|e| anyhow::anyhow!("installing the Ctrl-C handler: {e}"))
}

/// The flag a signal sets, for a command that stops cleanly on its own;
/// from this call on a signal no longer ends the process.
pub fn stop_flag() -> &'static AtomicBool {
    POLLED.store(true, Ordering::SeqCst);
    &STOP
}

/// A command ended cleanly by a signal (exit status 3, so that a script can
/// tell it from the planned end); the text says what was kept.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct Interrupted(pub &'static str);

/// A command that finished and wrote its outputs, but whose result is
/// empty or implausible, or whose input is incomplete: its `warning:` lines
/// say what (exit status 4, so that a script does not take it for a clean
/// result).
#[derive(Debug, thiserror::Error)]
#[error("finished with {0} warning(s): the outputs are written, but see the warning lines")]
pub struct Warned(pub usize);

/// `Ok` without warnings, else [`Warned`].
pub fn warned(count: usize) -> anyhow::Result<()> {
    if count == 0 {
        Ok(())
    } else {
        Err(Warned(count).into())
    }
}
