//! A FLIM scan's mean-arrival-time image during the run, on a thread of
//! its own at the lowest scheduling priority (as the reconstruction's):
//! the acquisition's watching stage hands it a copy of the counts at most
//! once per [`super::state::MEAN_TIME_EVERY`] and goes on; a copy offered
//! while one is being mapped is dropped (the next is newer).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{SyncSender, sync_channel};
use std::sync::{Arc, Mutex};

use ndarray::Array3;

use super::cpu::VIEW_THREAD_PREFIX;
use super::lower_priority;
use super::state::{LiveState, counts_mean_time};
use crate::acquire::pipeline::Snapshot;

/// One copy of the counts to map.
struct Job {
    counts: Array3<u32>,
    starts_ps: Vec<f64>,
    width_ps: f64,
    frequency_hz: f64,
    acquired_s: f64,
}

/// The thread that maps the counts, and whether it is busy.
pub struct MeanTimeMaps {
    tx: Option<SyncSender<Job>>,
    busy: Arc<AtomicBool>,
}

impl MeanTimeMaps {
    /// Starts the thread; its images go into `state`.
    pub fn start(state: Arc<Mutex<LiveState>>) -> Self {
        let (tx, rx) = sync_channel::<Job>(1);
        let busy = Arc::new(AtomicBool::new(false));
        let done = busy.clone();
        let spawned = std::thread::Builder::new()
            .name(format!("{VIEW_THREAD_PREFIX}mean-time"))
            .spawn(move || {
                lower_priority();
                for job in rx {
                    let mean_time = counts_mean_time(
                        job.counts.view(),
                        (&job.starts_ps, job.width_ps),
                        job.frequency_hz,
                        job.acquired_s,
                    );
                    {
                        // The whole run's image, once shown, stays.
                        let mut s = state.lock().unwrap_or_else(|e| e.into_inner());
                        if !s.done {
                            s.show_mean_time(mean_time);
                        }
                    }
                    done.store(false, Ordering::Release);
                }
            });
        Self {
            tx: spawned.is_ok().then_some(tx),
            busy,
        }
    }

    /// Offers the counts of snapshot `s`; `false` when the thread is still
    /// mapping the last ones (nothing is copied then).
    pub fn offer(&self, s: &Snapshot<'_>) -> bool {
        let Some(tx) = &self.tx else {
            return false;
        };
        if self.busy.swap(true, Ordering::AcqRel) {
            return false;
        }
        let k = s.counts.dim().0;
        let start = s.window_ps.0 - s.t0_ps;
        let job = Job {
            counts: s.counts.to_owned(),
            starts_ps: (0..k).map(|b| start + b as f64 * s.window_ps.1).collect(),
            width_ps: s.window_ps.1,
            frequency_hz: 1e12 / s.facts.sync_period_ps,
            acquired_s: s.progress.elapsed.as_secs_f64(),
        };
        if tx.try_send(job).is_err() {
            self.busy.store(false, Ordering::Release);
            return false;
        }
        true
    }
}
