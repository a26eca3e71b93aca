//! The reconstruction of snapshots of a running acquisition, on a thread
//! of its own, with the default method (`auto`, as `reconstruct` runs it
//! on the saved stack, its check's search carried from one snapshot to
//! the next: [`crate::reconstruct::guard::CarriedSearch`]); a snapshot is
//! offered only when the last one is done, so the acquisition never waits
//! for it. Its threads run at the lowest scheduling priority, on every
//! core (they take only what the acquisition and other processes leave),
//! and the acquisition comes first: a snapshot is skipped while the
//! acquisition's own threads keep every core but half of one busy (even
//! in the idle class, a reconstruction at work beside an unpaced 2-core
//! acquisition cost it about 10 % of its rate, by the caches and the
//! wake-ups it shares; see BENCHMARKS.md), and the page says so. A second
//! thread (at nice 10) watches the CPU the reconstruction gets: when other
//! processes take every core and it gets none, the page says so and names
//! them. The whole run's stack is reconstructed once the acquisition ends
//! ([`Reconstructor::finish`]), at normal priority, by `auto` afresh, with
//! its progress and an estimate of the time left (from the last
//! snapshot's iterations), and a stop request (Ctrl-C) skips it.

use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc::{RecvTimeoutError, SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use ndarray::Array2;

use super::cpu::{Busy, OtherProcesses, VIEW_THREAD_PREFIX, describe, threads_cpu_s};
use super::state::{Image, LiveReconstruction, LiveState, TracePoint};
use super::{lower_priority, view_priority};
use crate::denoise::tv::TotalVariation;
use crate::reconstruct::guard::CarriedSearch;
use crate::reconstruct::input::{InputSpec, prepare};
use crate::reconstruct::method::{Method, MethodOptions, MethodPlan, run_method};
use crate::reconstruct::run::Reconstruction;
use crate::reconstruct::trace::TraceRow;
use crate::stack::Stack;

/// A snapshot to reconstruct.
struct Snapshot {
    stack: Stack,
    acquired_s: f64,
    photons: u64,
}

/// The reconstruction of snapshots: its thread, and what it shares with
/// the thread that watches it.
pub struct Reconstructor {
    tx: Option<SyncSender<Snapshot>>,
    shared: Arc<Shared>,
}

/// A snapshot offered and not yet shown (waiting for its thread, or being
/// reconstructed).
#[derive(Debug, Clone, Copy)]
struct Running {
    acquired_s: f64,
    photons: u64,
    started: Instant,
}

/// What the reconstruction's threads share.
struct Shared {
    state: Arc<Mutex<LiveState>>,
    truth: Option<Array2<f64>>,
    /// The snapshot offered and not yet done, if any.
    running: Mutex<Option<Running>>,
    /// Set when the acquisition has ended: no snapshot is taken any more,
    /// and the watcher stops.
    ended: AtomicBool,
    /// Set once the whole run's reconstruction is shown: a snapshot that
    /// ends later only adds its point to the curve.
    final_shown: AtomicBool,
    /// Iterations the whole run's reconstruction will take, about: the
    /// steps the carried search has taken from the flat object, or the last
    /// snapshot's rows.
    last_iterations: Mutex<Option<usize>>,
}

impl Shared {
    fn state(&self) -> MutexGuard<'_, LiveState> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn running(&self) -> MutexGuard<'_, Option<Running>> {
        self.running.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn last_iterations(&self) -> MutexGuard<'_, Option<usize>> {
        self.last_iterations
            .lock()
            .unwrap_or_else(|e| e.into_inner())
    }
}

/// How the whole run's reconstruction ended.
#[derive(Debug, Clone, PartialEq)]
pub enum FinalRun {
    /// Shown on the page; its run time, s.
    Shown {
        /// Seconds it took.
        run_s: f64,
        /// The method (`auto` says which it chose).
        method: String,
    },
    /// Skipped by a stop request (Ctrl-C): the page says so.
    Skipped,
    /// It failed; the page shows why.
    Failed(String),
}

impl FinalRun {
    /// How it ended, in words.
    pub fn describe(&self) -> String {
        match self {
            FinalRun::Shown { run_s, method } => {
                format!("the whole run reconstructed in {run_s:.1} s ({method})")
            }
            FinalRun::Failed(e) => format!("the whole run's reconstruction failed: {e}"),
            FinalRun::Skipped => {
                "the whole run's reconstruction skipped (Ctrl-C); every output is written".into()
            }
        }
    }
}

/// Where the whole run's reconstruction is, for a progress line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FinalProgress {
    /// Seconds since it started.
    pub elapsed_s: f64,
    /// Iterations done so far.
    pub iterations: usize,
    /// Iterations it will need, about: as many as the snapshots' carried
    /// search has taken (`None` without a snapshot).
    pub expected_iterations: Option<usize>,
}

impl FinalProgress {
    /// Seconds left, about: the iterations still expected at the pace so
    /// far.
    pub fn left_s(&self) -> Option<f64> {
        let expected = self.expected_iterations?;
        (self.iterations > 0 && expected > self.iterations)
            .then(|| self.elapsed_s / self.iterations as f64 * (expected - self.iterations) as f64)
    }

    /// The progress in words: seconds, iterations, and the time left when
    /// known.
    pub fn describe(&self) -> String {
        let (elapsed, done) = (self.elapsed_s, self.iterations);
        match (self.expected_iterations, self.left_s()) {
            (Some(expected), Some(left)) => format!(
                "{elapsed:.0} s, {done} of about {expected} iterations, about {left:.0} s left"
            ),
            _ => format!("{elapsed:.0} s, {done} iterations"),
        }
    }
}

/// A snapshot's reconstruction by the default method, its rows counted
/// in `iterations`; the reconstruction, the bins it kept (indices into the
/// stack's bins) and what was assumed.
fn reconstruct(
    stack: &Stack,
    carried: Option<&CarriedSearch>,
    iterations: &AtomicUsize,
) -> Result<(Reconstruction, Vec<usize>, Vec<String>), String> {
    let input = prepare(
        stack.data.clone(),
        Some(stack.meta.clone()),
        Path::new("the live snapshot"),
        &InputSpec::default(),
    )
    .map_err(|e| e.to_string())?;
    let kept: Vec<usize> = input
        .problem
        .bin_starts_ps
        .iter()
        .filter_map(|&t| {
            let m = &stack.meta;
            m.bin_starts_ps.iter().position(|&s| (s - t).abs() < 1e-6)
        })
        .collect();
    let count = &mut |_: &TraceRow| {
        iterations.fetch_add(1, Ordering::Relaxed);
    };
    let opts = MethodOptions::default();
    let rec = match carried {
        Some(c) => {
            MethodPlan::auto_carrying(&opts, c).run_within_budget(&input.problem, None, count)
        }
        // `auto` runs no prior; the denoiser is the planner's formality.
        None => run_method(
            &input.problem,
            Method::Auto,
            None,
            &TotalVariation::default(),
            &opts,
            None,
            count,
        ),
    }
    .map_err(|e| e.to_string())?;
    Ok((rec, kept, input.assumed))
}

/// Shows a reconstruction of `acquired_s` seconds and `photons` photons
/// (or why it failed) on the page, scored against the truth when known.
/// A snapshot that ends after the whole run's reconstruction was shown
/// (`whole_run` false) only adds its point to the error-against-time
/// curve: the image stays the whole run's.
fn show(
    shared: &Shared,
    result: Result<(Reconstruction, Vec<usize>, Vec<String>), String>,
    (acquired_s, photons): (f64, u64),
    run_s: f64,
    whole_run: bool,
) {
    let mut s = shared.state();
    let superseded = !whole_run && shared.final_shown.load(Ordering::Relaxed);
    match result {
        Ok((rec, kept, assumed)) => {
            let psnr_db = shared
                .truth
                .as_ref()
                .and_then(|t| crate::metrics::psnr_fitted(rec.image.view(), t.view()));
            s.trace.push(TracePoint {
                acquired_s,
                photons,
                psnr_db,
                run_s,
            });
            s.trace
                .sort_by(|a, b| a.acquired_s.total_cmp(&b.acquired_s));
            if superseded {
                s.version += 1;
                return;
            }
            let (h, w) = rec.image.dim();
            let mut notes = assumed;
            notes.extend(rec.trace.notes.iter().cloned());
            s.decay.kept = kept;
            s.reconstruction = Some(LiveReconstruction {
                acquired_s,
                photons,
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
        Err(_) if superseded => return,
        Err(e) => s.reconstruction_error = Some(e),
    }
    // While the whole run's reconstruction works, its status stays.
    if whole_run || !shared.ended.load(Ordering::Relaxed) {
        s.reconstruction_status = None;
    }
    if whole_run {
        shared.final_shown.store(true, Ordering::Relaxed);
    }
    s.version += 1;
}

/// Seconds a snapshot runs before the watcher judges its CPU.
const STARVED_AFTER: Duration = Duration::from_secs(3);
/// Cores the reconstruction must have had since it started not to be
/// called starved.
const STARVED_BELOW_CORES: f64 = 0.1;

/// The watcher: once a second, says on the page what the snapshot offered
/// is doing, and when its threads have had (nearly) no CPU since it was
/// offered, who has the cores: the acquisition, and other processes by
/// name.
fn watch_cpu(shared: Arc<Shared>) {
    view_priority();
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let recon_threads = format!("{VIEW_THREAD_PREFIX}recon");
    let mut others = OtherProcesses::new();
    let mut acquisition = Load::new();
    // The snapshot last seen and its threads' CPU when it was first seen.
    let mut seen: Option<(Instant, f64)> = None;
    while !shared.ended.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_secs(1));
        let busy = others.look();
        let own = acquisition.busy_cores();
        let Some(r) = *shared.running() else {
            seen = None;
            set_status(&shared, None);
            continue;
        };
        let cpu_now = threads_cpu_s(&recon_threads);
        let cpu_then = match seen {
            Some((started, cpu)) if started == r.started => Some(cpu),
            _ => {
                seen = cpu_now.map(|c| (r.started, c));
                cpu_now
            }
        };
        let elapsed = r.started.elapsed().as_secs_f64();
        let had = cpu_now.zip(cpu_then).map(|(now, then)| now - then);
        let what = format!(
            "the snapshot of {} photons ({:.1} s of acquisition)",
            r.photons, r.acquired_s
        );
        let status = had
            .and_then(|had| starved(&what, had, elapsed, (own, cores), &busy))
            .unwrap_or_else(|| format!("reconstructing {what}: {elapsed:.0} s so far"));
        set_status(&shared, Some(status));
    }
}

/// The page's word when `what` (a snapshot) has had `had` s of CPU in
/// `elapsed` s: starved, and by whom (the acquisition's `own` busy cores
/// of `cores`, the `busy` other processes), when it has had less than
/// [`STARVED_BELOW_CORES`] of a core since [`STARVED_AFTER`]; else `None`.
fn starved(
    what: &str,
    had: f64,
    elapsed: f64,
    (own, cores): (Option<f64>, usize),
    busy: &[Busy],
) -> Option<String> {
    if elapsed < STARVED_AFTER.as_secs_f64() || had >= STARVED_BELOW_CORES * elapsed {
        return None;
    }
    let taken: f64 = busy.iter().map(|b| b.cores).sum();
    let mut by = Vec::new();
    if let Some(own) = own {
        by.push(format!(
            "the acquisition keeps {own:.1} of {cores} cores busy"
        ));
    }
    if !busy.is_empty() {
        by.push(format!("other processes {taken:.1}: {}", describe(busy, 3)));
    }
    Some(format!(
        "starved of CPU: {what} has had {had:.2} s of CPU in {elapsed:.0} s; {}. It runs only on a core nothing else wants, so the acquisition keeps its pace; the whole run is reconstructed when it ends",
        if by.is_empty() {
            "no other busy process can be seen".to_string()
        } else {
            by.join(", ")
        }
    ))
}

/// The watcher's word on the page, unless the acquisition has ended (the
/// whole run's reconstruction speaks then): checked under the state's
/// lock, which [`Reconstructor::finish`] takes after it sets `ended`.
fn set_status(shared: &Shared, status: Option<String>) {
    let mut s = shared.state();
    if !shared.ended.load(Ordering::Relaxed) && s.reconstruction_status != status {
        s.reconstruction_status = status;
        s.version += 1;
    }
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
        let now = (Instant::now(), super::cpu::acquisition_cpu_s()?);
        let busy = self.last.and_then(|(t, cpu)| {
            let wall = now.0.duration_since(t).as_secs_f64();
            // A thread that ended takes its CPU with it: never below 0.
            (wall > 0.05).then(|| (now.1 - cpu).max(0.0) / wall)
        });
        self.last = Some(now);
        busy
    }
}

impl Reconstructor {
    /// Starts the threads; results go into `state`, scored against `truth`
    /// when it is known.
    pub fn start(state: Arc<Mutex<LiveState>>, truth: Option<Array2<f64>>) -> Self {
        let (tx, rx) = sync_channel::<Snapshot>(1);
        let shared = Arc::new(Shared {
            state,
            truth,
            running: Mutex::new(None),
            ended: AtomicBool::new(false),
            final_shown: AtomicBool::new(false),
            last_iterations: Mutex::new(None),
        });
        let worker = shared.clone();
        let spawned = std::thread::Builder::new()
            .name(format!("{VIEW_THREAD_PREFIX}recon"))
            .spawn(move || {
                lower_priority();
                let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .thread_name(|i| format!("{VIEW_THREAD_PREFIX}recon-{i}"))
                    .start_handler(|_| lower_priority())
                    .build();
                let mut load = Load::new();
                let carried = CarriedSearch::new(CarriedSearch::LIVE_STEPS);
                for snap in rx {
                    if worker.ended.load(Ordering::Relaxed) {
                        break;
                    }
                    let busy = load.busy_cores();
                    if let Some(busy) = busy.filter(|b| *b > load.cores - SPARE_CORES) {
                        *worker.running() = None;
                        let mut s = worker.state();
                        s.reconstruction_paused = Some(format!(
                            "snapshots skipped while the acquisition keeps {busy:.1} of {} cores busy; the whole run is reconstructed when it ends",
                            load.cores
                        ));
                        s.version += 1;
                        continue;
                    }
                    let started = Instant::now();
                    let iterations = AtomicUsize::new(0);
                    let result = {
                        let run = || reconstruct(&snap.stack, Some(&carried), &iterations);
                        match &pool {
                            Ok(pool) => pool.install(run),
                            Err(_) => run(),
                        }
                    };
                    let run_s = started.elapsed().as_secs_f64();
                    if result.is_ok() {
                        // The whole run's search starts afresh: it goes
                        // about as far as the carried one has come.
                        let rows = iterations.load(Ordering::Relaxed);
                        *worker.last_iterations() = Some(carried.steps_taken().map_or(rows, |s| s.max(rows)));
                    }
                    show(&worker, result, (snap.acquired_s, snap.photons), run_s, false);
                    *worker.running() = None;
                }
            });
        let watcher = shared.clone();
        let watching = std::thread::Builder::new()
            .name(format!("{VIEW_THREAD_PREFIX}cpu"))
            .spawn(move || watch_cpu(watcher));
        if let Err(e) = spawned.as_ref().and(watching.as_ref()) {
            let mut s = shared.state();
            s.reconstruction_error = Some(format!("no thread for the reconstruction: {e}"));
        }
        Self {
            tx: spawned.is_ok().then_some(tx),
            shared,
        }
    }

    /// Whether no snapshot is being reconstructed (a held lock reads as
    /// busy: this never waits).
    pub fn idle(&self) -> bool {
        self.tx.is_some()
            && match self.shared.running.try_lock() {
                Ok(running) => running.is_none(),
                Err(std::sync::TryLockError::Poisoned(e)) => e.into_inner().is_none(),
                Err(std::sync::TryLockError::WouldBlock) => false,
            }
    }

    /// Offers a snapshot; `false` when one is still being reconstructed
    /// (the snapshot is dropped: the next is newer).
    pub fn offer(&self, stack: Stack, acquired_s: f64, photons: u64) -> bool {
        let Some(tx) = &self.tx else {
            return false;
        };
        // Set with the send, cleared by the thread when done. Never waits
        // on the lock (its other users run below the acquisition and may
        // be preempted holding it): a held lock drops this snapshot.
        let mut running = match self.shared.running.try_lock() {
            Ok(guard) => guard,
            Err(std::sync::TryLockError::Poisoned(e)) => e.into_inner(),
            Err(std::sync::TryLockError::WouldBlock) => return false,
        };
        if running.is_some() {
            return false;
        }
        match tx.try_send(Snapshot {
            stack,
            acquired_s,
            photons,
        }) {
            Ok(()) => {
                *running = Some(Running {
                    acquired_s,
                    photons,
                    started: Instant::now(),
                });
                true
            }
            Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => false,
        }
    }

    /// Reconstructs the whole run's `stack` (the acquisition has ended) at
    /// normal priority on a thread of its own, and shows it; a snapshot
    /// still at work goes on below it and, when it ends, adds its point to
    /// the error-against-time curve (the image stays the whole run's).
    /// `progress` sees it every quarter second on the calling thread;
    /// `stop` (Ctrl-C) skips it at once, and the page says so.
    pub fn finish(
        mut self,
        stack: Stack,
        acquired_s: f64,
        photons: u64,
        stop: &AtomicBool,
        mut progress: impl FnMut(&FinalProgress),
    ) -> FinalRun {
        self.shared.ended.store(true, Ordering::Relaxed);
        self.tx.take();
        let shared = self.shared.clone();
        drop(self);
        {
            let mut s = shared.state();
            s.reconstruction_status = Some(format!(
                "reconstructing the whole run ({photons} photons, {acquired_s:.1} s of acquisition)"
            ));
            s.version += 1;
        }
        if stop.load(Ordering::Relaxed) {
            return skipped(&shared);
        }
        let iterations = Arc::new(AtomicUsize::new(0));
        // The iterations it expects: about the last snapshot's.
        let expected = *shared.last_iterations();
        let (tx, rx) = sync_channel(1);
        let counted = iterations.clone();
        let started = Instant::now();
        let spawned = std::thread::Builder::new()
            .name("final-reconstruction".into())
            .spawn(move || {
                let _ = tx.send(reconstruct(&stack, None, &counted));
            });
        if let Err(e) = spawned {
            let e = format!("no thread for the whole run's reconstruction: {e}");
            shared.state().reconstruction_error = Some(e.clone());
            return FinalRun::Failed(e);
        }
        loop {
            match rx.recv_timeout(Duration::from_millis(250)) {
                Ok(result) => {
                    let run_s = started.elapsed().as_secs_f64();
                    let end = match &result {
                        Ok((rec, _, _)) => FinalRun::Shown {
                            run_s,
                            method: rec.trace.method.clone(),
                        },
                        Err(e) => FinalRun::Failed(e.clone()),
                    };
                    show(&shared, result, (acquired_s, photons), run_s, true);
                    return end;
                }
                Err(RecvTimeoutError::Timeout) if stop.load(Ordering::Relaxed) => {
                    return skipped(&shared);
                }
                Err(RecvTimeoutError::Timeout) => {
                    let p = FinalProgress {
                        elapsed_s: started.elapsed().as_secs_f64(),
                        iterations: iterations.load(Ordering::Relaxed),
                        expected_iterations: expected,
                    };
                    {
                        let mut s = shared.state();
                        s.reconstruction_status = Some(format!(
                            "reconstructing the whole run ({photons} photons, {acquired_s:.1} s of acquisition): {}",
                            p.describe()
                        ));
                        s.version += 1;
                    }
                    progress(&p);
                }
                Err(RecvTimeoutError::Disconnected) => {
                    let e = "the whole run's reconstruction ended without a result".to_string();
                    shared.state().reconstruction_error = Some(e.clone());
                    return FinalRun::Failed(e);
                }
            }
        }
    }
}

/// Says on the page that the whole run's reconstruction was skipped.
fn skipped(shared: &Shared) -> FinalRun {
    let mut s = shared.state();
    s.reconstruction_status =
        Some("the whole run's reconstruction was skipped (Ctrl-C); the stack is saved".into());
    s.version += 1;
    FinalRun::Skipped
}

impl Drop for Reconstructor {
    /// The view is going away: the threads stop at their next look and are
    /// not waited for.
    fn drop(&mut self) {
        self.shared.ended.store(true, Ordering::Relaxed);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The page says a snapshot is starved, and by whom, exactly when it
    /// has had less than a tenth of a core since three seconds.
    #[test]
    fn a_snapshot_without_cpu_is_called_starved_and_its_takers_named() {
        let busy = [Busy {
            pid: 42,
            name: "sh".into(),
            cores: 1.9,
        }];
        let said = starved("the snapshot", 0.2, 5.0, (Some(0.3), 2), &busy).unwrap();
        assert!(
            said.starts_with("starved of CPU: the snapshot has had 0.20 s of CPU in 5 s"),
            "{said}"
        );
        assert!(
            said.contains("the acquisition keeps 0.3 of 2 cores busy"),
            "{said}"
        );
        assert!(
            said.contains("other processes 1.9: sh (pid 42) 1.9 core"),
            "{said}"
        );
        // Enough CPU, or too early to tell: not starved.
        assert_eq!(starved("s", 0.6, 5.0, (None, 2), &busy), None);
        assert_eq!(starved("s", 0.0, 2.0, (None, 2), &busy), None);
        let alone = starved("s", 0.0, 4.0, (None, 2), &[]).unwrap();
        assert!(
            alone.contains("no other busy process can be seen"),
            "{alone}"
        );
    }
}
