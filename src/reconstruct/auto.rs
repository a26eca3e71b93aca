//! The per-stack choice between whole-stack Richardson-Lucy (`rl-stack`,
//! cross-validated stop) and PnP (the split solver with the learned
//! prior), made without the truth.
//!
//! PnP runs first; its output is returned when its output deviance, in
//! noise standard deviations above the Poisson expectation, is at least
//! [`PNP_MISFIT_Z`], else `rl-stack` runs and its output is returned. The
//! rule and its threshold were chosen on the benchmark's tuning images
//! only (the eighteenth session's journal, BENCHMARKS.md): among the truth-free scores tried (statistics
//! of the `rl-stack` estimate, each candidate's held-out deviance on
//! thinned halves, PnP's training deviance) it was the only one that
//! gained on the tuning images, and it rests on three of them.

use super::data::Data;
use super::error::ReconstructError;
use super::rl_stack::RlStack;
use super::run::{Estimate, Reconstructor, Run, WorkShape};
use super::trace::Trace;

/// PnP's output deviance z at or above which its output is chosen.
pub const PNP_MISFIT_Z: f64 = 263.7;

/// Chooses between `rl-stack` and PnP per stack (see the module's
/// documentation).
pub struct Auto<'a> {
    /// PnP with the solver and prior the settings choose
    /// ([`super::method::MethodOptions::pnp`]). The threshold was chosen
    /// with the split solver, the default.
    pub pnp: Box<dyn Reconstructor + 'a>,
    /// Richardson-Lucy on the whole stack, with its stop.
    pub rl: RlStack,
}

/// PnP's output deviance minus its Poisson expectation over its standard
/// deviation, from the last trace row that has them.
pub fn deviance_z(trace: &Trace) -> Option<f64> {
    trace
        .rows
        .iter()
        .rev()
        .find_map(|r| Some((r.deviance? - r.expected_deviance?) / r.deviance_sd?))
        .filter(|z| z.is_finite())
}

/// The start of the note that names the chosen candidate.
const CHOSE: &str = "auto: chose ";

/// The candidate an `auto` run chose, from its trace's notes.
pub fn chosen(trace: &Trace) -> Option<&str> {
    trace.notes.iter().find_map(|n| n.strip_prefix(CHOSE))
}

/// Whether a PnP output with deviance z `z` is chosen.
pub fn chooses_pnp(z: Option<f64>) -> bool {
    z.is_some_and(|z| z >= PNP_MISFIT_Z)
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
        let (rl, pnp) = (&self.rl, self.pnp.as_ref());
        let (rl_name, pnp_name) = (rl.name(bins), pnp.name(bins));
        let mut candidate = |r: &dyn Reconstructor, name| -> Result<_, ReconstructError> {
            let from = run.elapsed_s();
            let mut sub = run.sub_run(name, true);
            let out = r.reconstruct(data, &mut sub)?;
            let seconds = sub.elapsed_s() - from;
            Ok((out, sub.into_trace(), seconds))
        };
        // PnP first: when its output is chosen, `rl-stack` (the slower of
        // the two on most stacks) is not run at all.
        let (pnp_out, pnp_trace, pnp_s) = candidate(pnp, pnp_name)?;
        let z = deviance_z(&pnp_trace);
        let z_text = z.map_or("none (never at its noise floor)".into(), |z| {
            format!("{z:.1}")
        });
        let mut notes = vec![format!(
            "auto: {pnp_name} took {pnp_s:.2} s; its output deviance z = {z_text} (chosen at {PNP_MISFIT_Z} or more)"
        )];
        let (out, trace) = if chooses_pnp(z) {
            notes.push(format!("auto: {rl_name} not run: {pnp_name} is chosen"));
            notes.push(format!("{CHOSE}{pnp_name}"));
            (pnp_out, pnp_trace)
        } else {
            let (rl_out, rl_trace, rl_s) = candidate(rl, rl_name)?;
            notes.push(format!("auto: {rl_name} took {rl_s:.2} s"));
            notes.push(format!("{CHOSE}{rl_name}"));
            (rl_out, rl_trace)
        };
        run.adopt(trace, notes);
        Ok(out)
    }

    /// The larger of its two candidates (they run one after the other)
    /// plus the first's output kept for the choice.
    fn working_bytes(&self, shape: &WorkShape) -> u64 {
        let kept = shape.bytes([0; 3], [16, 0, 0]);
        self.pnp
            .working_bytes(shape)
            .max(self.rl.working_bytes(shape))
            .saturating_add(kept)
    }
}
