//! The default method (`--method auto`): the learned reconstruction inside
//! the ranges its network was trained on, whole-stack Richardson-Lucy
//! (`rl-stack`, cross-validated stop) outside them; nothing run is thrown
//! away, and PnP never runs.
//!
//! The rule (R77b) was written before the learned network's benchmark
//! runs and applied on the tuning images only: `learned`'s mean margin
//! over Richardson-Lucy's truth-chosen best was above `rl-stack`'s at
//! every light level there (+0.85 / +0.84 / +0.42 dB against -0.05 /
//! -0.01 / +0.17 dB at 0.1x / 1x / 10x). The held-out run, read after
//! (BENCHMARKS.md), agrees on the means and shows the cost: single scenes
//! of sparse points at 10x lose up to 4 dB. The earlier rule (PnP when its
//! output deviance was high) lost up to 1.9 dB where it picked PnP and ran
//! both candidates; it is retired.

use super::data::Data;
use super::error::ReconstructError;
use super::learned::{Learned, Used};
use super::run::{Estimate, Reconstructor, Run, WorkShape};
use super::trace::Trace;

/// The learned reconstruction with `rl-stack` outside its trained ranges,
/// its choice named in the notes.
pub struct Auto<'a> {
    /// The learned reconstruction, its `outside` whole-stack
    /// Richardson-Lucy.
    pub learned: Learned<'a>,
}

/// The start of the note that names the chosen candidate.
const CHOSE: &str = "auto: chose ";

/// The candidate an `auto` run chose, from its trace's notes.
pub fn chosen(trace: &Trace) -> Option<&str> {
    trace.notes.iter().find_map(|n| n.strip_prefix(CHOSE))
}

impl Reconstructor for Auto<'_> {
    fn name(&self, _bins: usize) -> &'static str {
        "auto"
    }

    fn reconstruct(
        &self,
        data: &Data<'_>,
        run: &mut Run<'_>,
    ) -> Result<Estimate, ReconstructError> {
        let (out, used) = self.learned.reconstruct_which(data, run)?;
        let name = match used {
            Used::Network => self.learned.name(data.bins.len()),
            Used::Outside => self.learned.outside.name(data.bins.len()),
            Used::Neither => return Ok(out),
        };
        run.note(format!("{CHOSE}{name}"));
        Ok(out)
    }

    fn working_bytes(&self, shape: &WorkShape) -> u64 {
        self.learned.working_bytes(shape)
    }
}
