//! Live acquisition: one pipeline for every device. A device is opened as
//! a [`Source`] (our own time taggers on the wire protocol, the mocks
//! behind the same transports, PicoQuant devices through the vendor's
//! library); the pipeline streams what it sends through the recordings
//! and the binner into a K x H x W stack, and accounts for every photon.
//!
//! - [`device`]: what `--device` names, and opening it as a source.
//! - [`open_error`]: why a device cannot be opened.
//! - [`source`]: the source interface, and what a source says about itself.
//! - [`link`]: our own devices on the wire protocol.
//! - [`picoquant`]: PicoQuant devices through the vendor's library.
//! - [`mock`]: the emulated time tagger (the `mock` feature).
//! - [`replay`]: a recorded file played back at its recorded pace.
//! - [`pipeline`]: the stages every source's stream runs through.
//! - [`ledger`]: where every photon and record went; the totals balance.
//! - [`record`]: the outcome as a stack, with the typed record of the
//!   acquisition.
//! - [`request`]: one acquisition as every front end asks for it, checked
//!   once (every device default and refusal) into a [`Job`].
//! - [`job`]: one acquisition as it runs, outputs included.
//! - [`calibration`]: time zero from a reference measurement.

pub mod calibration;
pub mod device;
pub mod job;
pub mod ledger;
pub mod link;
pub mod mock;
pub mod open_error;
pub mod picoquant;
pub mod pipeline;
pub mod record;
pub mod replay;
pub mod request;
pub mod source;

pub use device::{DeviceSpec, OpenedDevice, open_device};
pub use job::{Acquisition, Job, JobError, TimeZero};
pub use ledger::{Ledger, Recording};
pub use mock::MockSpec;
pub use pipeline::{AcquireError, Outcome, Progress, Snapshot, StreamPlan, run, run_watched};
pub use record::AcquisitionRecord;
pub use source::{Source, SourceFacts, StopReason};
