//! A live view of a running acquisition, served as a local web page:
//! count rates over the last minute, the decay histogram, the accumulated
//! image, the ledger so far, and every few seconds the reconstruction of
//! the stack accumulated so far (the default method, on a snapshot, on a
//! thread of its own) with its error against run time when the truth is
//! known.
//!
//! It is one more stage of the acquisition pipeline
//! ([`crate::acquire::run_watched`]): every 250 ms it copies what it shows
//! under a short lock and returns, so a slow, stuck or closed browser
//! never stalls or changes an acquisition. The page is pushed to the
//! browser as server-sent events (`/events`), each event the whole state,
//! so a browser that falls behind skips states instead of queueing them.
//!
//! - [`state`]: what the page shows, as JSON.
//! - [`server`]: the HTTP server (tiny_http), the page and its access token.
//! - [`recon`]: the reconstruction of snapshots, off the acquisition's path.

pub mod recon;
pub mod server;
pub mod state;

pub use server::{LiveError, LiveView};
pub use state::LiveState;
