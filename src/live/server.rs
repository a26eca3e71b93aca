//! The live view's HTTP server: the page (served from the binary: no CDN,
//! a lab PC may be offline), the state as JSON (`/state`) and as
//! server-sent events (`/events`, one event per state, at most four a
//! second). Bound to 127.0.0.1 unless asked otherwise; on any other
//! address every request needs the random access token printed with the
//! address, so no one else on the network reads the run.
//!
//! axum on a tokio runtime of one thread (at nice 10, below the
//! acquisition): an idle keep-alive connection or a browser that
//! stops reading is a parked task, not a blocked thread, so many open pages
//! never stall a new one.

use std::convert::Infallible;
use std::net::{IpAddr, SocketAddr, ToSocketAddrs};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use axum::extract::State;
use axum::http::{StatusCode, Uri, header};
use axum::response::sse::{Event, Sse};
use axum::response::{IntoResponse, Response};
use ndarray::Array2;

use super::mean_time::MeanTimeMaps;
use super::recon::{FinalProgress, FinalRun, Reconstructor};
use super::state::LiveState;
use crate::acquire::{Acquisition, Snapshot};
use crate::physics::Setup;

/// The page.
const PAGE: &str = include_str!("page.html");
/// Shortest time between two events to one browser.
const EVENT_EVERY: Duration = Duration::from_millis(250);
/// The shortest time between two snapshots offered to the reconstruction
/// (one is offered only when the last is done).
const RECONSTRUCT_EVERY: Duration = Duration::from_millis(1000);
/// Browsers served events at once; more are refused (503).
const MAX_CLIENTS: usize = 16;

/// Why the view could not start.
#[derive(Debug, thiserror::Error)]
pub enum LiveError {
    /// The address does not parse or resolve.
    #[error("live view address {0}: give ADDRESS:PORT, e.g. 127.0.0.1:8080 or 0.0.0.0:8080")]
    Address(String),
    /// The port cannot be bound.
    #[error("live view address {addr}: {reason}")]
    Bind {
        /// The address.
        addr: String,
        /// Why.
        reason: String,
    },
}

/// What the server shares with its threads.
struct Shared {
    state: Arc<Mutex<LiveState>>,
    token: Option<String>,
    closed: AtomicBool,
    clients: AtomicUsize,
}

/// A running live view.
pub struct LiveView {
    shared: Arc<Shared>,
    shutdown: Option<tokio::sync::oneshot::Sender<()>>,
    thread: Option<JoinHandle<()>>,
    url: String,
}

/// The page's address on `bound`, with its token: an IPv6 address in
/// brackets, as a browser takes it.
fn page_url(bound: SocketAddr, token: Option<&str>) -> String {
    let host = match bound.ip() {
        IpAddr::V4(ip) => ip.to_string(),
        IpAddr::V6(ip) => format!("[{ip}]"),
    };
    let query = token.map_or(String::new(), |t| format!("?token={t}"));
    format!("http://{host}:{}/{query}", bound.port())
}

/// A random token of 32 hex digits.
fn random_token() -> String {
    use rand::RngExt;
    let mut rng = rand::rng();
    (0..16)
        .map(|_| format!("{:02x}", rng.random::<u8>()))
        .collect()
}

impl LiveView {
    /// Serves the view on `addr` (`None`: 127.0.0.1 on a free port). An
    /// address other than loopback gets an access token.
    pub fn start(addr: Option<&str>) -> Result<Self, LiveError> {
        let text = addr.unwrap_or("127.0.0.1:0");
        let socket: SocketAddr = text
            .to_socket_addrs()
            .ok()
            .and_then(|mut a| a.next())
            .ok_or_else(|| LiveError::Address(text.to_string()))?;
        let bind_error = |e: std::io::Error| LiveError::Bind {
            addr: text.to_string(),
            reason: e.to_string(),
        };
        let listener = std::net::TcpListener::bind(socket).map_err(bind_error)?;
        listener.set_nonblocking(true).map_err(bind_error)?;
        let bound = listener.local_addr().map_err(bind_error)?;
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_io()
            .enable_time()
            .build()
            .map_err(bind_error)?;
        let token = (!bound.ip().is_loopback()).then(random_token);
        let url = page_url(bound, token.as_deref());
        let shared = Arc::new(Shared {
            state: Arc::new(Mutex::new(LiveState::default())),
            token,
            closed: AtomicBool::new(false),
            clients: AtomicUsize::new(0),
        });
        let (shutdown, closing) = tokio::sync::oneshot::channel::<()>();
        let thread = {
            let app = axum::Router::new()
                .fallback(answer)
                .with_state(shared.clone());
            std::thread::Builder::new()
                .name(format!("{}server", super::cpu::VIEW_THREAD_PREFIX))
                .spawn(move || {
                    super::view_priority();
                    runtime.block_on(async move {
                        let Ok(listener) = tokio::net::TcpListener::from_std(listener) else {
                            return;
                        };
                        // Ends at `close`; the runtime's drop then ends every
                        // connection still open.
                        tokio::select! {
                            _ = axum::serve(listener, app) => {}
                            _ = closing => {}
                        }
                    });
                })
                .map_err(bind_error)?
        };
        Ok(Self {
            shared,
            shutdown: Some(shutdown),
            thread: Some(thread),
            url,
        })
    }

    /// The address to open (with its token when it has one).
    pub fn url(&self) -> &str {
        &self.url
    }

    /// The state the page shows.
    pub fn state(&self) -> Arc<Mutex<LiveState>> {
        self.shared.state.clone()
    }

    /// The watching stage for [`crate::acquire::Job::run_watched`]: copies
    /// each snapshot into the state and offers one to the reconstruction
    /// whenever it is idle, at most once a second (`setup`: the sample's physics, without which there is
    /// none; `truth`: the scene, for the error against run time).
    pub fn stage(&self, setup: Option<Setup>, truth: Option<Array2<f64>>) -> LiveStage {
        if setup.is_none() {
            let mut s = self.shared.state.lock().unwrap_or_else(|e| e.into_inner());
            s.reconstruction_error = Some(
                "none: the sample's physics are not known for this device (give them to `reconstruct`)"
                    .into(),
            );
        }
        LiveStage {
            state: self.shared.state.clone(),
            acquired: LiveState::default(),
            reconstructor: setup
                .is_some()
                .then(|| Reconstructor::start(self.shared.state.clone(), truth)),
            setup,
            last_offer: None,
            mean_time: MeanTimeMaps::start(self.shared.state.clone()),
            last_mean_time: None,
        }
    }

    /// Shows the finished acquisition: its final ledger and why it ended,
    /// and for a FLIM scan the whole run's mean-arrival-time image.
    pub fn finish(&self, done: &Acquisition) {
        let mut s = self.shared.state.lock().unwrap_or_else(|e| e.into_inner());
        if is_flim_scan(&done.outcome.facts) {
            s.final_mean_time(
                &done.stack,
                done.outcome.facts.sync_period_ps,
                done.outcome.end.elapsed.as_secs_f64(),
            );
        }
        s.done = true;
        s.ended = Some(done.outcome.end.stop.describe());
        s.ledger = Some(done.outcome.ledger.clone());
        s.ledger_table = done.outcome.ledger.table();
        s.counters.counts = done.outcome.ledger.counts;
        s.version += 1;
    }

    /// Keeps serving the final page for `time`, or until `stop` (Ctrl-C).
    pub fn linger(&self, time: Duration, stop: &AtomicBool) {
        let until = Instant::now() + time;
        while Instant::now() < until && !stop.load(Ordering::Relaxed) {
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// Stops serving.
    pub fn close(mut self) {
        self.stop();
    }

    fn stop(&mut self) {
        self.shared.closed.store(true, Ordering::Relaxed);
        if let Some(s) = self.shutdown.take() {
            let _ = s.send(());
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for LiveView {
    fn drop(&mut self) {
        self.stop();
    }
}

/// Whether a source is a FLIM scan: a point detector clocked by a
/// scanner's markers.
fn is_flim_scan(facts: &crate::acquire::SourceFacts) -> bool {
    matches!(
        facts.layout,
        crate::acquire::source::Layout::Inputs { scan: Some(_), .. }
    )
}

/// The live view's stage of the pipeline.
pub struct LiveStage {
    state: Arc<Mutex<LiveState>>,
    /// What the acquisition has shown so far, the stage's own copy.
    acquired: LiveState,
    reconstructor: Option<Reconstructor>,
    setup: Option<Setup>,
    last_offer: Option<Instant>,
    /// The FLIM scan's mean-arrival-time images, on their own thread.
    mean_time: MeanTimeMaps,
    last_mean_time: Option<Instant>,
}

impl LiveStage {
    /// Takes in one snapshot (see [`crate::acquire::run_watched`]).
    pub fn watch(&mut self, s: &Snapshot<'_>) {
        // Never waits on the lock: its other users run below the
        // acquisition's priority and may be preempted holding it; when it is held, this snapshot
        // is shown with the next one.
        self.acquired.update(s);
        if is_flim_scan(s.facts)
            && s.progress.counts.binned > 0
            && self
                .last_mean_time
                .is_none_or(|t| t.elapsed() >= super::state::MEAN_TIME_EVERY)
            && self.mean_time.offer(s)
        {
            self.last_mean_time = Some(Instant::now());
        }
        match self.state.try_lock() {
            Ok(mut shown) => shown.show_acquisition(&self.acquired),
            Err(std::sync::TryLockError::Poisoned(e)) => {
                e.into_inner().show_acquisition(&self.acquired)
            }
            Err(std::sync::TryLockError::WouldBlock) => {}
        }
        if let Some(r) = &self.reconstructor
            && self
                .last_offer
                .is_none_or(|t| t.elapsed() >= RECONSTRUCT_EVERY)
            && s.progress.counts.binned > 0
            && r.idle()
        {
            let stack = crate::acquire::record::stack_of(
                s.counts,
                s.window_ps,
                s.region,
                s.t0_ps,
                self.setup.as_ref(),
                "live snapshot".into(),
                None,
            );
            if r.offer(
                stack,
                s.progress.elapsed.as_secs_f64(),
                s.progress.counts.photons,
            ) {
                self.last_offer = Some(Instant::now());
            }
        }
    }

    /// Reconstructs the whole run's stack and shows it, so that a
    /// lingering page shows it ([`Reconstructor::finish`]: normal priority,
    /// `progress` as it goes, `stop` skips it); `None` when the view has no
    /// reconstruction (the sample's physics are not known).
    pub fn finish(
        self,
        done: &Acquisition,
        stop: &AtomicBool,
        progress: impl FnMut(&FinalProgress),
    ) -> Option<FinalRun> {
        let r = self.reconstructor?;
        Some(r.finish(
            done.stack.clone(),
            done.outcome.end.elapsed.as_secs_f64(),
            done.outcome.ledger.counts.photons,
            stop,
            progress,
        ))
    }
}

/// Every request: the token first (off loopback), then the path.
async fn answer(State(shared): State<Arc<Shared>>, uri: Uri) -> Response {
    let token_ok = shared.token.as_ref().is_none_or(|t| {
        uri.query()
            .unwrap_or("")
            .split('&')
            .any(|kv| kv.strip_prefix("token=") == Some(t.as_str()))
    });
    if !token_ok {
        return (
            StatusCode::FORBIDDEN,
            "this live view needs its access token",
        )
            .into_response();
    }
    match uri.path() {
        "/" => ([(header::CONTENT_TYPE, "text/html; charset=utf-8")], PAGE).into_response(),
        "/state" => {
            // Copied under the lock, written out after it.
            let state = shared
                .state
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .clone();
            (
                [(header::CONTENT_TYPE, "application/json")],
                to_json(&state),
            )
                .into_response()
        }
        "/events" => match Slot::take(&shared) {
            Some(slot) => Sse::new(events(slot)).into_response(),
            None => (
                StatusCode::SERVICE_UNAVAILABLE,
                [(header::CONNECTION, "close")],
                "too many browsers on this live view\n",
            )
                .into_response(),
        },
        _ => (StatusCode::NOT_FOUND, "not found").into_response(),
    }
}

/// One browser's place among the [`MAX_CLIENTS`] served events; given
/// back when its stream ends (the view closes or the browser goes).
struct Slot(Arc<Shared>);

impl Slot {
    fn take(shared: &Arc<Shared>) -> Option<Self> {
        if shared.clients.fetch_add(1, Ordering::Relaxed) >= MAX_CLIENTS {
            shared.clients.fetch_sub(1, Ordering::Relaxed);
            return None;
        }
        Some(Self(shared.clone()))
    }
}

impl Drop for Slot {
    fn drop(&mut self) {
        self.0.clients.fetch_sub(1, Ordering::Relaxed);
    }
}

/// The event stream of one browser: the latest state when it changed, at
/// most every [`EVENT_EVERY`]; ends when the view closes. A browser that
/// stops reading holds back only its own stream (the next state is made
/// when it reads again), never another browser or the acquisition.
fn events(slot: Slot) -> impl futures_util::Stream<Item = Result<Event, Infallible>> {
    futures_util::stream::unfold((slot, None), |(slot, sent)| async move {
        loop {
            if sent.is_some() {
                tokio::time::sleep(EVENT_EVERY).await;
            }
            if slot.0.closed.load(Ordering::Relaxed) {
                return None;
            }
            // The version and the state sent under one lock.
            let newer = {
                let state = slot.0.state.lock().unwrap_or_else(|e| e.into_inner());
                (sent != Some(state.version)).then(|| state.clone())
            };
            if let Some(state) = newer {
                let event = Event::default().data(to_json(&state));
                return Some((Ok(event), (slot, Some(state.version))));
            }
        }
    })
}

/// The state as the page reads it.
fn to_json(state: &LiveState) -> String {
    serde_json::to_string(state).expect("the state serialises")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_ipv6_address_is_bracketed_in_the_url() {
        let v6: SocketAddr = "[::]:8080".parse().unwrap();
        assert_eq!(page_url(v6, None), "http://[::]:8080/");
        let loop6: SocketAddr = "[::1]:9".parse().unwrap();
        assert_eq!(page_url(loop6, Some("ab")), "http://[::1]:9/?token=ab");
        let v4: SocketAddr = "0.0.0.0:80".parse().unwrap();
        assert_eq!(page_url(v4, None), "http://0.0.0.0:80/");
    }
}
