//! Photon time tags: the events every source (recorded file, device)
//! produces before they are binned into a stack.
//!
//! The events themselves are [`crate::events`]; the files that hold them
//! are read in [`crate::formats`] (PicoQuant's and the project's own
//! `.sstags`).
//!
//! - [`wire`]: event batches of the wire protocol (live, or from the
//!   project's tag files) -> the binner.
//! - [`binning`]: tags -> K x H x W transient stack (single pixel, pixel
//!   per channel, scanned images from line/frame markers, or a sensor).
//! - [`binned`]: what binning a recorded file is asked and gives.
//! - [`bin_file`]: a recorded file -> stacks, in one call.
//! - [`recorded`]: each recorded format's source (PicoQuant, Becker &
//!   Hickl `.spc` and `.sdt`, `.sstags`) behind one interface.
//! - [`survey`]: what a recorded file holds, counted by kind.
//! - [`counts`]: where the records and photons of a stream went.
//! - [`convert`]: a recorded file -> PTU, photon for photon.
//! - [`table`]: a recorded file's tags as columns (array front ends).

pub mod bin_file;
pub mod binned;
pub mod binning;
pub mod convert;
pub mod counts;
pub mod laser;
pub mod recorded;
pub mod survey;
pub mod table;
pub mod wire;
