//! The command-line program the tests run: one place that names it.

use std::process::Command;

/// A `scatterscope` command, built for this test run, with no arguments
/// yet.
pub fn scatterscope() -> Command {
    Command::new(env!("CARGO_BIN_EXE_scatterscope"))
}
