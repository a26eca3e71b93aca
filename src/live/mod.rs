//! A live view of a running acquisition, served as a local web page:
//! count rates over the last minute, the decay histogram, the accumulated
//! image (and a FLIM scan's mean-arrival-time image), the ledger so far, and every few seconds the reconstruction of
//! the stack accumulated so far (the default method, on a snapshot, on a
//! thread of its own) with its error against run time when the truth is
//! known.
//!
//! It is one more stage of the acquisition pipeline
//! ([`crate::acquire::run_watched`]): every 250 ms it copies what it shows
//! under a short lock and returns, so a slow, stuck or closed browser
//! never stalls or changes an acquisition. The snapshots' reconstruction
//! runs in Linux's idle scheduling class (it gets a core only when nothing
//! else wants one); the server and the thread that watches the
//! reconstruction's CPU run at nice 10, so that the page is served and says
//! why no reconstruction shows when other processes take every core. Once
//! the acquisition has ended, the whole run's reconstruction runs at
//! normal priority with its progress. The page is pushed to the
//! browser as server-sent events (`/events`), each event the whole state,
//! so a browser that falls behind skips states instead of queueing them.
//!
//! - [`state`]: what the page shows, as JSON.
//! - [`server`]: the HTTP server (axum on one tokio thread), the page and its access token.
//! - [`recon`]: the reconstruction of snapshots, off the acquisition's path.
//! - [`cpu`]: where the machine's CPU goes (the acquisition, the view,
//!   other processes).

pub mod cpu;
pub mod mean_time;
pub mod recon;
pub mod server;
pub mod state;

pub use server::{LiveError, LiveView};

/// The calling thread below the acquisition but above idle: nice 10, so
/// that the page is still served while other processes keep every core
/// busy (a thread in the idle class then gets nothing), and its work is
/// light (a state copied and sent four times a second).
pub(crate) fn view_priority() {
    #[cfg(target_os = "linux")]
    // SAFETY: acts on the calling thread (0) with a valid nice value; it
    // only fails for lack of permission, and then nothing changes.
    unsafe {
        libc::setpriority(libc::PRIO_PROCESS, 0, 10);
    }
}

/// The calling thread at the lowest scheduling priority: Linux's idle
/// class (it runs only on a core nothing else wants, and yields at once),
/// and nice 19 where that class is refused (Linux schedules threads one by
/// one; elsewhere nothing changes).
pub(crate) fn lower_priority() {
    #[cfg(target_os = "linux")]
    // SAFETY: both calls act on the calling thread (0) with valid
    // arguments; they only fail for lack of permission.
    unsafe {
        let param = libc::sched_param { sched_priority: 0 };
        if libc::sched_setscheduler(0, libc::SCHED_IDLE, &param) != 0 {
            libc::setpriority(libc::PRIO_PROCESS, 0, 19);
        }
    }
}

pub use state::LiveState;
