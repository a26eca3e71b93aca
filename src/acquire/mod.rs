//! Live acquisition: open a device (hardware or a mock), configure it,
//! stream event batches through the drivers' pipeline, bin them into a
//! K x H x W stack, and account for every photon.
//!
//! - [`device`]: what `--device` names, and opening it (mocks included).
//! - [`session`]: one acquisition from Start to the device's totals.
//! - [`accounting`]: where every photon went; the totals balance exactly.
//! - [`record`]: the outcome as a stack, with the typed record of the
//!   acquisition.
//! - [`calibration`]: time zero from a reference measurement.

pub mod accounting;
pub mod calibration;
pub mod device;
pub mod record;
pub mod session;

pub use accounting::AcquisitionAccounting;
pub use device::{DeviceSpec, MockSetup, OpenedDevice, open_device};
pub use record::{AcquisitionRecord, MockReference};
pub use session::{AcquireError, Outcome, Plan, Progress, StopReason, acquire};
