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
//! never stalls or changes an acquisition. Every thread of the view (the
//! server, each browser's events, the reconstruction) runs in Linux's idle
//! scheduling class: it gets a core only when the acquisition leaves one. The page is pushed to the
//! browser as server-sent events (`/events`), each event the whole state,
//! so a browser that falls behind skips states instead of queueing them.
//!
//! - [`state`]: what the page shows, as JSON.
//! - [`server`]: the HTTP server (axum on one tokio thread), the page and its access token.
//! - [`recon`]: the reconstruction of snapshots, off the acquisition's path.

pub mod recon;
pub mod server;
pub mod state;

pub use server::{LiveError, LiveView};

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

/// CPU seconds spent so far by this process's threads outside the idle
/// class (the acquisition's: every thread of the view runs in it), read
/// from `/proc/self/task`; `None` where that cannot be read.
pub(crate) fn acquisition_cpu_s() -> Option<f64> {
    #[cfg(target_os = "linux")]
    {
        // SAFETY: sysconf has no preconditions.
        let tick = unsafe { libc::sysconf(libc::_SC_CLK_TCK) };
        if tick <= 0 {
            return None;
        }
        let mut ticks = 0u64;
        for task in std::fs::read_dir("/proc/self/task").ok()?.flatten() {
            let Ok(stat) = std::fs::read_to_string(task.path().join("stat")) else {
                continue; // the thread ended
            };
            // Fields after the command's closing parenthesis: state is
            // field 3, utime 14, stime 15, policy 41.
            let Some((_, rest)) = stat.rsplit_once(')') else {
                continue;
            };
            let f: Vec<&str> = rest.split_whitespace().collect();
            let field = |n: usize| f.get(n - 3).and_then(|v| v.parse::<u64>().ok());
            if field(41) == Some(libc::SCHED_IDLE as u64) {
                continue;
            }
            ticks += field(14).unwrap_or(0) + field(15).unwrap_or(0);
        }
        Some(ticks as f64 / tick as f64)
    }
    #[cfg(not(target_os = "linux"))]
    None
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use super::*;

    /// Busy work for `ms` of wall time on the calling thread.
    fn spin(ms: u64) -> u64 {
        let until = std::time::Instant::now() + std::time::Duration::from_millis(ms);
        let mut x = 1u64;
        while std::time::Instant::now() < until {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(1);
        }
        x
    }

    /// CPU seconds the acquisition's threads spend while a thread (in the
    /// idle class or not) spins for 0.4 s, read while it is alive (an
    /// ended thread leaves `/proc/self/task`).
    fn spent_while_spinning(idle: bool) -> f64 {
        let (spun, read) = (std::sync::mpsc::channel(), std::sync::mpsc::channel::<()>());
        let before = acquisition_cpu_s().unwrap();
        let t = std::thread::spawn(move || {
            if idle {
                lower_priority();
            }
            spin(400);
            spun.0.send(()).unwrap();
            read.1.recv().unwrap();
        });
        spun.1.recv().unwrap();
        let spent = acquisition_cpu_s().unwrap() - before;
        read.0.send(()).unwrap();
        t.join().unwrap();
        spent
    }

    /// CPU spent in the idle class is not the acquisition's; CPU spent by
    /// an ordinary thread is.
    #[test]
    fn the_acquisitions_cpu_leaves_out_the_idle_class() {
        let idle = spent_while_spinning(true);
        let busy = spent_while_spinning(false);
        assert!(busy > 0.2, "an ordinary thread's 0.4 s: {busy}");
        assert!(idle < busy / 2.0, "idle class {idle} s against {busy} s");
    }
}
