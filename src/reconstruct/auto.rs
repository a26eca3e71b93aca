//! The default method (`--method auto`): the learned reconstruction inside
//! the ranges its network was trained on, kept only where a check against
//! the counts says it explains them as well as Richardson-Lucy with its
//! cross-validated stop ([`super::guard`], rule R82b), else that
//! Richardson-Lucy (`rl-sum`, whose output the check has already made);
//! whole-stack Richardson-Lucy (`rl-stack`) outside the trained ranges.
//! Where the time axis carries far more than the time-summed stack
//! ([`super::time_axis`], rule R90a), `rl-stack` is weighed too and
//! returned when it predicts counts it was not given better.
//! Every run says which it chose and why, with the figures, and warns when
//! its output explains the stack far worse than Poisson noise allows (a
//! slab, index, time zero or background other than the metadata say).
//!
//! The rules were written before the runs that chose their settings
//! (journal, forty-first session).

use super::data::Data;
use super::discrepancy::{DevianceCheck, ExpectedDeviance};
use super::em::{Acceleration, Keep, RlStop};
use super::error::ReconstructError;
use super::guard::{self, CarriedSearch, GUARD_TAU};
use super::learned::Learned;
use super::learned::net::LearnedNet;
use super::rl_stack::{self, RlStack};
use super::run::{Estimate, Reconstructor, Run, WorkShape};
use super::time_axis;
use super::trace::Trace;
use crate::poisson::thinning::THINNING_SEED;

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
    /// The default with `net`, its check searching as the cross-validated
    /// `stop` does (`rl-sum`'s default search when `stop` is a fixed
    /// count), `rl-stack` with `stop` outside the trained ranges;
    /// `carried` carries the search between snapshots.
    pub fn new(stop: RlStop, net: &'a LearnedNet, carried: Option<&'a CarriedSearch>) -> Self {
        Self {
            learned: Learned {
                net,
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

impl Auto<'_> {
    /// Rule R90a's first part: the time axis's information gain, said;
    /// where it reaches [`time_axis::MIN_GAIN`] (and no search is carried
    /// between snapshots), each bin's counts thinned into the two halves
    /// whole-stack RL and the check share.
    fn time_axis(
        &self,
        data: &Data<'_>,
        run: &mut Run<'_>,
    ) -> Result<Option<[Vec<Vec<f64>>; 2]>, ReconstructError> {
        let Some(gain) = time_axis::information_gain(data.model, data.bins) else {
            return Ok(None);
        };
        let said = format!(
            "auto: the time axis carries {gain:.2}x the time-summed stack's information where the summed kernel passes {:.0} % of the light",
            100.0 * time_axis::GAIN_TRANSFER
        );
        if gain < time_axis::MIN_GAIN {
            run.note(format!(
                "{said}: under {}, whole-stack Richardson-Lucy left out (it costs several times the time-summed search for little)",
                time_axis::MIN_GAIN
            ));
            return Ok(None);
        }
        if self.carried.is_some() {
            run.note(format!(
                "{said}; whole-stack Richardson-Lucy left out: the search is carried between snapshots of a growing acquisition, on the time-summed counts only"
            ));
            return Ok(None);
        }
        run.note(format!(
            "{said}: at least {}, whole-stack Richardson-Lucy is weighed",
            time_axis::MIN_GAIN
        ));
        Ok(Some(rl_stack::stack_halves(data)?))
    }

    /// Rule R90a's second part: whole-stack RL's cross-validated search on
    /// `halves`; its output when its halves predict the other half's
    /// counts in every bin better than the check's choice (`label`, its
    /// halves' `points`) does, its trace then the run's; else `None`.
    fn whole_stack(
        &self,
        data: &Data<'_>,
        halves: &[Vec<Vec<f64>>; 2],
        (label, points): (&str, &[Vec<f64>]),
        run: &mut Run<'_>,
    ) -> Result<Option<Estimate>, ReconstructError> {
        let mut sub = run.sub_run("rl-stack", true);
        let best = rl_stack::search_stack(
            data,
            halves,
            self.search,
            Keep {
                points: true,
                iterates: &[],
            },
            &mut sub,
        );
        let trace = sub.into_trace();
        let held = time_axis::held_back(
            data.model,
            data.bins,
            halves,
            [&best.points[0], &best.points[1]],
            [&points[0], &points[1]],
        );
        let figures = format!(
            "held-back deviance over every bin of rl-stack {:.1} at its stop (iteration {}) against {label}'s {:.1} (difference {:+.1}, noise sd {:.1}: z = {:+.2}; returned at z < -{})",
            held.stack,
            best.iteration,
            held.other,
            held.stack - held.other,
            held.sigma,
            held.z(),
            time_axis::STACK_TAU
        );
        if !held.stack_wins(time_axis::STACK_TAU) {
            run.note(format!(
                "auto: whole-stack Richardson-Lucy does not predict counts it was not given clearly better: {figures}"
            ));
            return Ok(None);
        }
        let grid = best.grid(data.model.grid_shape());
        let check =
            ExpectedDeviance::shared().check(data.model, data.counts, data.bins, grid.view());
        run.adopt(
            trace,
            vec![format!(
                "auto: whole-stack Richardson-Lucy predicts counts it was not given clearly better, and is returned: {figures}"
            )],
        );
        chose("rl-stack", &check, run);
        Ok(Some(Estimate {
            image: best.image,
            iteration: best.iteration,
        }))
    }
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
        let weighed = self.time_axis(data, run)?;
        let given = weighed.as_ref().map(|halves| {
            let summed = time_axis::summed_halves(halves, data.model.sensor_shape());
            let how = format!(
                "each bin's counts thinned into two halves (seed {THINNING_SEED:#x} plus the bin's index), summed over the bins: {} and {} photons",
                summed[0].sum(),
                summed[1].sum()
            );
            (summed, how)
        });
        let Some(verdict) = guard::check(
            self.learned.net,
            data,
            self.search,
            self.carried,
            given,
            run,
        )?
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
        let network = verdict.passes(GUARD_TAU);
        if network {
            run.note(format!(
                "auto: the network explains counts it was not given as well as Richardson-Lucy: {figures}"
            ));
        } else {
            run.note(format!(
                "auto: the network explains counts it was not given worse than Richardson-Lucy with its cross-validated stop: {figures}"
            ));
        }
        if let Some(halves) = &weighed {
            let (label, points) = if network {
                ("the network", &verdict.network_points[..])
            } else {
                ("rl-sum", &verdict.rl_points[..])
            };
            if let Some(out) = self.whole_stack(data, halves, (label, points), run)? {
                return Ok(out);
            }
        }
        if network {
            let Some(out) = self.learned.network(data, run)? else {
                return Ok(run.no_photons(data.model.sensor_shape()));
            };
            warn_unexplained(&out.check, run);
            run.note(format!("{CHOSE}learned"));
            return Ok(out.estimate);
        }
        let check = ExpectedDeviance::shared().check(
            data.model,
            data.counts,
            data.bins,
            verdict.fallback_grid.view(),
        );
        chose("rl-sum", &check, run);
        Ok(verdict.fallback)
    }

    /// The learned reconstruction's (the larger of the network's and the
    /// stand-in's) and half as much again: the check's `rl-sum` search
    /// on the halves, its network runs one at a time (measured:
    /// `tests/memory.rs`).
    /// Whole-stack RL's search, where the time axis is weighed, runs
    /// after the check: the larger of the two.
    fn working_bytes(&self, shape: &WorkShape) -> u64 {
        let one = self.learned.working_bytes(shape);
        let stack = RlStack {
            stop: RlStop::After(0),
        };
        one.saturating_add(one / 2).max(stack.working_bytes(shape))
    }
}

/// The chosen Richardson-Lucy's output deviance against Poisson noise's,
/// the warning when it is far worse ([`warn_unexplained`]), and the
/// choice, in the notes.
fn chose(method: &str, check: &DevianceCheck, run: &mut Run<'_>) {
    run.note(format!(
        "{method}: output deviance {:.1}, Poisson noise alone {:.1} +- {:.1} (z = {:.1})",
        check.deviance,
        check.expected,
        check.sd,
        check.z()
    ));
    warn_unexplained(check, run);
    run.note(format!("{CHOSE}{method}"));
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
