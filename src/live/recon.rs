//! The reconstruction of snapshots of a running acquisition, on a thread
//! of its own: the default method (`auto`) with the default prior, on the
//! stack accumulated so far; a snapshot offered while one runs is dropped
//! (the next one is newer), so the acquisition never waits for it. Its
//! threads run at the lowest scheduling priority, on all cores but one,
//! and the acquisition comes first: a snapshot is skipped while the
//! acquisition's own threads keep every core but half of one busy (even
//! in the idle class, a reconstruction at work beside an unpaced 2-core
//! acquisition cost it about 10 % of its rate, by the caches and the
//! wake-ups it shares; see BENCHMARKS.md), and the page says so. The whole
//! run's stack is reconstructed once it ends, whatever the load.

use std::path::Path;
use std::sync::mpsc::{SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Instant;

use ndarray::{Array2, ArrayView2};

use super::lower_priority;
use super::state::{Image, LiveReconstruction, LiveState, TracePoint};
use crate::denoise::prior::PriorSpec;
use crate::reconstruct::input::{InputSpec, prepare};
use crate::reconstruct::method::{Method, MethodOptions, run_method};
use crate::stack::Stack;

/// A snapshot to reconstruct.
struct Snapshot {
    stack: Stack,
    acquired_s: f64,
    photons: u64,
    /// The whole run's stack, reconstructed whatever the load.
    last: bool,
}

/// The reconstruction thread.
pub struct Reconstructor {
    tx: Option<SyncSender<Snapshot>>,
    thread: Option<JoinHandle<()>>,
}

/// Cores the acquisition leaves idle, at least, for a snapshot to be
/// reconstructed during the run.
const SPARE_CORES: f64 = 0.5;

/// Whether the acquisition's threads keep the machine's cores busy: the
/// CPU they used since the last look, against the cores there are.
struct Load {
    cores: f64,
    last: Option<(Instant, f64)>,
}

impl Load {
    fn new() -> Self {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get()) as f64;
        let mut load = Self { cores, last: None };
        load.busy_cores();
        load
    }

    /// Cores the acquisition kept busy since the last call (`None` the
    /// first time, or where it cannot be read).
    fn busy_cores(&mut self) -> Option<f64> {
        let now = (Instant::now(), super::acquisition_cpu_s()?);
        let busy = self.last.and_then(|(t, cpu)| {
            let wall = now.0.duration_since(t).as_secs_f64();
            // A thread that ended takes its CPU with it: never below 0.
            (wall > 0.05).then(|| (now.1 - cpu).max(0.0) / wall)
        });
        self.last = Some(now);
        busy
    }
}

/// PSNR of `image` against `truth` after the gain that best fits the truth
/// (least squares); `None` when the shapes differ or the image is dark.
pub fn psnr_fitted(image: ArrayView2<f64>, truth: ArrayView2<f64>) -> Option<f64> {
    if image.dim() != truth.dim() {
        return None;
    }
    let (xy, xx) = image
        .iter()
        .zip(truth.iter())
        .fold((0.0, 0.0), |(xy, xx), (&x, &y)| (xy + x * y, xx + x * x));
    if xx <= 0.0 {
        return None;
    }
    let scaled = image.mapv(|v| v * xy / xx);
    Some(crate::metrics::psnr(scaled.view(), truth))
}

impl Reconstructor {
    /// Starts the thread; results go into `state`, scored against `truth`
    /// when it is known.
    pub fn start(state: Arc<Mutex<LiveState>>, truth: Option<Array2<f64>>) -> Self {
        let (tx, rx) = sync_channel::<Snapshot>(1);
        let thread = std::thread::spawn(move || {
            lower_priority();
            let threads = std::thread::available_parallelism()
                .map_or(1, |n| n.get().saturating_sub(1).max(1));
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .start_handler(|_| lower_priority())
                .build();
            let denoiser = PriorSpec::default().build();
            let mut load = Load::new();
            for snap in rx {
                let busy = load.busy_cores();
                if !snap.last
                    && let Some(busy) = busy.filter(|b| *b > load.cores - SPARE_CORES)
                {
                    let mut s = state.lock().unwrap_or_else(|e| e.into_inner());
                    s.reconstruction_paused = Some(format!(
                        "snapshots skipped while the acquisition keeps {busy:.1} of {} cores busy; the whole run is reconstructed when it ends",
                        load.cores
                    ));
                    s.version += 1;
                    continue;
                }
                let started = Instant::now();
                let result = denoiser
                    .as_ref()
                    .map_err(|e| e.to_string())
                    .and_then(|denoiser| {
                        let input = prepare(
                            snap.stack.data.clone(),
                            Some(snap.stack.meta.clone()),
                            Path::new("the live snapshot"),
                            &InputSpec::default(),
                        )
                        .map_err(|e| e.to_string())?;
                        let kept: Vec<usize> = input
                            .problem
                            .bin_starts_ps
                            .iter()
                            .filter_map(|&t| {
                                let m = &snap.stack.meta;
                                m.bin_starts_ps.iter().position(|&s| (s - t).abs() < 1e-6)
                            })
                            .collect();
                        let run = || {
                            run_method(
                                &input.problem,
                                Method::Auto,
                                None,
                                denoiser.as_ref(),
                                &MethodOptions::default(),
                                None,
                                |_| {},
                            )
                        };
                        let rec = match &pool {
                            Ok(pool) => pool.install(run),
                            Err(_) => run(),
                        }
                        .map_err(|e| e.to_string())?;
                        Ok((rec, kept, input.assumed))
                    });
                let run_s = started.elapsed().as_secs_f64();
                let mut s = state.lock().unwrap_or_else(|e| e.into_inner());
                match result {
                    Ok((rec, kept, assumed)) => {
                        let psnr_db = truth
                            .as_ref()
                            .and_then(|t| psnr_fitted(rec.image.view(), t.view()));
                        let (h, w) = rec.image.dim();
                        let mut notes = assumed;
                        notes.extend(rec.trace.notes.iter().cloned());
                        s.decay.kept = kept;
                        s.trace.push(TracePoint {
                            acquired_s: snap.acquired_s,
                            photons: snap.photons,
                            psnr_db,
                            run_s,
                        });
                        s.reconstruction = Some(LiveReconstruction {
                            acquired_s: snap.acquired_s,
                            photons: snap.photons,
                            method: rec.trace.method.clone(),
                            run_s,
                            image: Image {
                                width: w,
                                height: h,
                                values: rec.image.iter().map(|&v| v as f32).collect(),
                            },
                            notes,
                            psnr_db,
                        });
                        s.reconstruction_error = None;
                        s.reconstruction_paused = None;
                    }
                    Err(e) => s.reconstruction_error = Some(e),
                }
                s.version += 1;
            }
        });
        Self {
            tx: Some(tx),
            thread: Some(thread),
        }
    }

    /// Offers a snapshot; `false` when one is still being reconstructed
    /// (the snapshot is dropped: the next is newer).
    pub fn offer(&self, stack: Stack, acquired_s: f64, photons: u64) -> bool {
        let Some(tx) = &self.tx else {
            return false;
        };
        match tx.try_send(Snapshot {
            stack,
            acquired_s,
            photons,
            last: false,
        }) {
            Ok(()) => true,
            Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => false,
        }
    }

    /// Reconstructs the whole run's `stack` after any snapshot still at
    /// work (whatever the load: the acquisition has ended), then ends the
    /// thread.
    pub fn finish_with(mut self, stack: Stack, acquired_s: f64, photons: u64) {
        if let Some(tx) = self.tx.take() {
            let _ = tx.send(Snapshot {
                stack,
                acquired_s,
                photons,
                last: true,
            });
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_fitted_psnr_ignores_the_gain_and_sees_the_error() {
        let truth = Array2::from_shape_fn((8, 8), |(y, x)| ((x + y) % 3) as f64);
        let scaled = truth.mapv(|v| 7.0 * v);
        assert!(psnr_fitted(scaled.view(), truth.view()).unwrap() > 100.0);
        let mut off = scaled.clone();
        off[(2, 2)] += 5.0;
        let p = psnr_fitted(off.view(), truth.view()).unwrap();
        assert!(p.is_finite() && p < 60.0, "{p}");
        assert!(psnr_fitted(Array2::zeros((8, 8)).view(), truth.view()).is_none());
        assert!(psnr_fitted(Array2::ones((4, 8)).view(), truth.view()).is_none());
    }
}
