//! The emulated time tagger behind `--device mock` and `mock-serial`: what
//! it images ([`MockSpec`]), its set-up (scene, kernels, rates, faults),
//! and opening it as an acquisition source on an in-process USB transport
//! or a pseudo-terminal, which knows its own truth. Built with the `mock`
//! feature (on by default); without it the spec exists but opening a mock
//! says the build has none. These two lines are the only places the
//! feature decides anything in acquisition.

#[cfg_attr(feature = "mock", path = "mock/emulated.rs")]
#[cfg_attr(not(feature = "mock"), path = "mock/absent.rs")]
mod imp;

pub use imp::*;
