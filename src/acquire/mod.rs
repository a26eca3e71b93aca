//! Live acquisition: open a device (hardware or a mock), configure it,
//! stream event batches through the drivers' pipeline, bin them into a
//! K x H x W stack, and account for every photon.
//!
//! - [`device`]: what `--device` names, and opening it (mocks included).
//! - [`mock`]: the emulated time tagger (the `mock` feature).
//! - [`job`]: one acquisition as the `acquire` command runs it, outputs
//!   included.
//! - [`picoquant`]: a PicoQuant device through the vendor's library, its
//!   records streamed to a PTU file and binned.
//! - [`session`]: one acquisition from Start to the device's totals.
//! - [`accounting`]: where every photon went; the totals balance exactly.
//! - [`record`]: the outcome as a stack, with the typed record of the
//!   acquisition.
//! - [`calibration`]: time zero from a reference measurement.

pub mod accounting;
pub mod calibration;
pub mod device;
pub mod job;
pub mod mock;
pub mod picoquant;
pub mod record;
pub mod session;

pub use accounting::AcquisitionAccounting;
pub use device::{DeviceSpec, OpenedDevice, open_device};
#[cfg(feature = "mock")]
pub use job::MockJob;
pub use job::{Acquisition, Job, JobError, TimeZero};
pub use mock::MockSetup;
#[cfg(feature = "mock")]
pub use mock::{MockReference, Truth};
pub use record::AcquisitionRecord;
pub use session::{AcquireError, Outcome, Plan, Progress, StopReason, acquire};
