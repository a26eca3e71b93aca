//! Reconstruction of the object from a transient stack.
//!
//! Every method implements one interface, [`run::Reconstructor`]: it takes
//! checked [`data::Data`] (a forward model and the counts of some of its
//! bins) and reports to a [`run::Run`] (trace, clock, scoring against a
//! known truth, notes), which returns the checked image with its trace.
//! [`method`] names them for users and runs one on a [`problem::Problem`];
//! [`input`] makes a stack file into one, its physics resolved.
//!
//! - [`auto`]: the default: per stack, whole-stack Richardson-Lucy or PnP
//!   with the learned prior, chosen without the truth.
//! - [`split`]: Poisson Plug-and-Play ADMM with exact splitting (P4IP), the
//!   default PnP solver: closed-form Poisson prox, exact o-update.
//! - [`admm_lbfgs`]: the paper's Algorithm 1 (L-BFGS o-update), with a
//!   data-driven stopping rule ([`discrepancy`]).
//! - [`rl_sum`]: the classical Richardson-Lucy baseline, on one bin or on
//!   the time-summed stack.
//! - [`rl_stack`]: Richardson-Lucy on the whole stack, every bin with its
//!   own kernel.
//! - [`scaled_counts`]: counts divided by kernel mass (no deblurring),
//!   for reference.
//! - [`learned`]: Richardson-Lucy's iterates on the time-summed stack
//!   corrected by a small CNN trained here on the project's own
//!   simulations.
//!
//! - [`time_axis`]: what the time axis adds, and when the default weighs
//!   whole-stack Richardson-Lucy.
//!
//! What they share sits beside them: [`em`] (the Richardson-Lucy step and
//! its stopping), [`likelihood`], [`discrepancy`] and [`operator`]; what
//! they share with the hidden-volume methods ([`crate::confocal`]) sits
//! below both, in [`crate::poisson`] (thinning into halves for a stop
//! without the truth, the Poisson deviance).

pub mod admm_lbfgs;
pub mod auto;
pub mod data;
pub mod discrepancy;
pub mod em;
pub mod error;
pub mod guard;
pub mod input;
pub mod learned;
pub mod likelihood;
pub mod method;
pub mod operator;
pub mod problem;
pub mod rl_stack;
pub mod rl_sum;
pub mod run;
pub mod scaled_counts;
pub mod split;
pub mod time_axis;
pub mod trace;

pub use data::Data;
pub use error::ReconstructError;
pub use run::{Reconstruction, Reconstructor, WorkShape};
