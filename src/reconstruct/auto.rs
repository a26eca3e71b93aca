//! The default method (`--method auto`): the learned reconstruction inside
//! the ranges its network was trained on, kept only where a check against
//! the counts says it explains them as well as Richardson-Lucy with its
//! cross-validated stop ([`super::guard`], rule R82b), else that
//! Richardson-Lucy (`rl-sum`, whose output the check has already made);
//! whole-stack Richardson-Lucy (`rl-stack`) outside the trained ranges.
//! Every run says which it chose and why, with the figures, and warns when
//! its output explains the stack far worse than Poisson noise allows (a
//! slab, index, time zero or background other than the metadata say).
//!
//! The rules were written before the runs that chose their settings
//! (journal, forty-first session).

use super::data::Data;
use super::discrepancy::{DevianceCheck, ExpectedDeviance};
use super::em::{Acceleration, RlStop};
use super::error::ReconstructError;
use super::guard::{self, CarriedSearch, GUARD_TAU};
use super::learned::Learned;
use super::rl_stack::RlStack;
use super::run::{Estimate, Reconstructor, Run, WorkShape};
use super::trace::Trace;

/// The guarded learned reconstruction, `rl-stack` outside its trained
/// ranges, its choice named in the notes.
pub struct Auto<'a> {
    /// The learned reconstruction, its `outside` whole-stack
    /// Richardson-Lucy.
    pub learned: Learned<'a>,
    /// The check's Richardson-Lucy search: most iterations and their
    /// acceleration (`rl-sum`'s cross-validated stop).
    pub search: (usize, Acceleration),
    /// The search carried between snapshots of a growing acquisition, if
    /// any.
    pub carried: Option<&'a CarriedSearch>,
}

impl<'a> Auto<'a> {
    /// The default with the embedded network, its check searching as the
    /// cross-validated `stop` does (`rl-sum`'s default search when `stop`
    /// is a fixed count), `rl-stack` with `stop` outside the trained
    /// ranges; `carried` carries the search between snapshots.
    pub fn new(stop: RlStop, carried: Option<&'a CarriedSearch>) -> Self {
        Self {
            learned: Learned {
                net: super::learned::embedded(),
                outside: Box::new(RlStack { stop }),
            },
            search: match stop {
                RlStop::CrossValidated {
                    max_iters,
                    acceleration,
                } => (max_iters, acceleration),
                RlStop::After(_) => (RlStop::DEFAULT_MAX_ITERS, Acceleration::None),
            },
            carried,
        }
    }
}

/// The start of the note that names the chosen candidate.
const CHOSE: &str = "auto: chose ";

/// The deviance z-score of the output on the whole stack above which
/// `auto` warns that the model does not explain the stack: rule R82c's
/// smallest candidate (of 10, 20, 50, ... 1000) above every tuning
/// stack's (largest 3.4).
pub const Z_WARN: f64 = 10.0;

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
        let bins = data.bins.len();
        if data.counts.sum() <= 0.0 {
            return Ok(run.no_photons(data.model.sensor_shape()));
        }
        if let Some(why) = self.learned.outside_why(data) {
            run.note(format!(
                "learned: the stack lies outside what the network was trained on: {why}"
            ));
            let out = self.learned.outside.reconstruct(data, run)?;
            run.note(format!("{CHOSE}{}", self.learned.outside.name(bins)));
            return Ok(out);
        }
        let Some(verdict) = guard::check(self.learned.net, data, self.search, self.carried, run)?
        else {
            run.note("auto: a thinned half of the counts holds no photon: nothing to check the network against; Richardson-Lucy with its cross-validated stop instead");
            let out = self.learned.outside.reconstruct(data, run)?;
            run.note(format!("{CHOSE}{}", self.learned.outside.name(bins)));
            return Ok(out);
        };
        let figures = format!(
            "held-back deviance of the network {:.1} against Richardson-Lucy's {:.1} at its stop (difference {:+.1}, noise sd {:.1}: z = {:+.2}; kept at z <= {GUARD_TAU})",
            verdict.network,
            verdict.richardson_lucy,
            verdict.network - verdict.richardson_lucy,
            verdict.sigma,
            verdict.z()
        );
        if verdict.passes(GUARD_TAU) {
            run.note(format!(
                "auto: the network explains counts it was not given as well as Richardson-Lucy: {figures}"
            ));
            let Some(out) = self.learned.network(data, run)? else {
                return Ok(run.no_photons(data.model.sensor_shape()));
            };
            warn_unexplained(&out.check, run);
            run.note(format!("{CHOSE}learned"));
            return Ok(out.estimate);
        }
        run.note(format!(
            "auto: the network explains counts it was not given worse than Richardson-Lucy with its cross-validated stop, which is returned: {figures}"
        ));
        let check = ExpectedDeviance::shared().check(
            data.model,
            data.counts,
            data.bins,
            verdict.fallback_grid.view(),
        );
        run.note(format!(
            "rl-sum: output deviance {:.1}, Poisson noise alone {:.1} +- {:.1} (z = {:.1})",
            check.deviance,
            check.expected,
            check.sd,
            check.z()
        ));
        warn_unexplained(&check, run);
        run.note(format!("{CHOSE}rl-sum"));
        Ok(verdict.fallback)
    }

    /// The learned reconstruction's (the larger of the network's and the
    /// stand-in's) and half as much again: the check's `rl-sum` search
    /// on the halves, its network runs one at a time (measured:
    /// `tests/memory.rs`).
    fn working_bytes(&self, shape: &WorkShape) -> u64 {
        let one = self.learned.working_bytes(shape);
        one.saturating_add(one / 2)
    }
}

/// A warning when `check` says the output explains the stack far worse
/// than Poisson noise allows (rule R82c).
fn warn_unexplained(check: &DevianceCheck, run: &mut Run<'_>) {
    let z = check.z();
    if z > Z_WARN {
        let why = check.profile_departure().unwrap_or_else(|| {
            "the time profile matches the model's: the scene or the sensor may hold what the model leaves out".into()
        });
        run.note(format!(
            "warning: the output explains the counts far worse than Poisson noise allows (deviance z = {z:.0}, above {Z_WARN}): the slab, its index, time zero or a background may differ from what the metadata say; {why}"
        ));
    }
}
