//! The live view's HTTP server: the page (served from the binary: no CDN,
//! a lab PC may be offline), the state as JSON (`/state`) and as
//! server-sent events (`/events`, one event per state, at most four a
//! second). Bound to 127.0.0.1 unless asked otherwise; on any other
//! address every request needs the random access token printed with the
//! address, so no one else on the network reads the run.
//!
//! tiny_http: a small, well-kept, synchronous server; the view has a handful
//! of clients and needs no async runtime.

use std::io::Write;
use std::net::{IpAddr, SocketAddr, ToSocketAddrs};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use ndarray::Array2;

use super::recon::Reconstructor;
use super::state::LiveState;
use crate::acquire::{Acquisition, Snapshot};
use crate::physics::Setup;

/// The page.
const PAGE: &str = include_str!("page.html");
/// Shortest time between two events to one browser.
const EVENT_EVERY: Duration = Duration::from_millis(250);
/// How often a snapshot is offered to the reconstruction.
const RECONSTRUCT_EVERY: Duration = Duration::from_secs(3);
/// Browsers served events at once; more are refused (503).
const MAX_CLIENTS: usize = 16;

/// Why the view could not start.
#[derive(Debug, thiserror::Error)]
pub enum LiveError {
    /// The address does not parse or resolve.
    #[error("--live {0}: give ADDRESS:PORT, e.g. 127.0.0.1:8080 or 0.0.0.0:8080")]
    Address(String),
    /// The port cannot be bound.
    #[error("--live {addr}: {reason}")]
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
    server: Arc<tiny_http::Server>,
    thread: Option<JoinHandle<()>>,
    url: String,
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
        let server = tiny_http::Server::http(socket).map_err(|e| LiveError::Bind {
            addr: text.to_string(),
            reason: e.to_string(),
        })?;
        let bound = server
            .server_addr()
            .to_ip()
            .ok_or_else(|| LiveError::Address(text.to_string()))?;
        let token = (!bound.ip().is_loopback()).then(random_token);
        let host = match bound.ip() {
            IpAddr::V4(ip) if ip.is_unspecified() => "0.0.0.0".to_string(),
            ip => ip.to_string(),
        };
        let url = format!(
            "http://{host}:{}/{}",
            bound.port(),
            token
                .as_ref()
                .map_or(String::new(), |t| format!("?token={t}"))
        );
        let shared = Arc::new(Shared {
            state: Arc::new(Mutex::new(LiveState::default())),
            token,
            closed: AtomicBool::new(false),
            clients: AtomicUsize::new(0),
        });
        let server = Arc::new(server);
        let thread = {
            let (server, shared) = (server.clone(), shared.clone());
            std::thread::spawn(move || {
                super::lower_priority();
                serve(&server, &shared)
            })
        };
        Ok(Self {
            shared,
            server,
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
    /// each snapshot into the state and offers one every 3 s to the
    /// reconstruction (`setup`: the sample's physics, without which there is
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
            reconstructor: setup
                .is_some()
                .then(|| Reconstructor::start(self.shared.state.clone(), truth)),
            setup,
            last_offer: None,
        }
    }

    /// Shows the finished acquisition: its final ledger and why it ended.
    pub fn finish(&self, done: &Acquisition) {
        let mut s = self.shared.state.lock().unwrap_or_else(|e| e.into_inner());
        s.done = true;
        s.ended = Some(done.outcome.end.stop.describe());
        s.ledger = Some(done.outcome.ledger.clone());
        s.ledger_table = done.outcome.ledger.table();
        s.counters.photons = done.outcome.ledger.photons;
        s.counters.binned = done.outcome.ledger.binned;
        s.counters.records = done.outcome.ledger.records_read;
        s.counters.markers = done.outcome.ledger.markers;
        s.counters.lost_in_device = done.outcome.ledger.lost_in_device;
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
        self.server.unblock();
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

/// The live view's stage of the pipeline.
pub struct LiveStage {
    state: Arc<Mutex<LiveState>>,
    reconstructor: Option<Reconstructor>,
    setup: Option<Setup>,
    last_offer: Option<Instant>,
}

impl LiveStage {
    /// Takes in one snapshot (see [`crate::acquire::run_watched`]).
    pub fn watch(&mut self, s: &Snapshot<'_>) {
        self.state
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .update(s);
        if let Some(r) = &self.reconstructor
            && self
                .last_offer
                .is_none_or(|t| t.elapsed() >= RECONSTRUCT_EVERY)
            && s.progress.binned > 0
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
            if r.offer(stack, s.progress.elapsed.as_secs_f64(), s.progress.photons) {
                self.last_offer = Some(Instant::now());
            }
        }
    }

    /// Reconstructs the final stack too (the whole run) and waits for it,
    /// so that a lingering page shows it.
    pub fn finish(self, done: &Acquisition) {
        if let Some(r) = self.reconstructor {
            let acquired_s = done.outcome.end.elapsed.as_secs_f64();
            // A snapshot may still run: the final one waits its turn.
            let mut stack = Some(done.stack.clone());
            while let Some(s) = stack.take() {
                if !r.offer(s.clone(), acquired_s, done.outcome.ledger.photons) {
                    std::thread::sleep(Duration::from_millis(50));
                    stack = Some(s);
                }
            }
            r.finish();
        }
    }
}

fn serve(server: &tiny_http::Server, shared: &Arc<Shared>) {
    for request in server.incoming_requests() {
        if shared.closed.load(Ordering::Relaxed) {
            break;
        }
        let url = request.url().to_string();
        let (path, query) = url.split_once('?').unwrap_or((&url, ""));
        let token_ok = shared.token.as_ref().is_none_or(|t| {
            query
                .split('&')
                .any(|kv| kv.strip_prefix("token=") == Some(t.as_str()))
        });
        let header = |k: &str, v: &str| {
            tiny_http::Header::from_bytes(k.as_bytes(), v.as_bytes()).expect("a valid header")
        };
        if !token_ok {
            let _ = request.respond(
                tiny_http::Response::from_string("this live view needs its access token")
                    .with_status_code(403),
            );
            continue;
        }
        match path {
            "/" => {
                let _ = request.respond(
                    tiny_http::Response::from_string(PAGE)
                        .with_header(header("Content-Type", "text/html; charset=utf-8")),
                );
            }
            "/state" => {
                let json = state_json(shared);
                let _ = request.respond(
                    tiny_http::Response::from_string(json)
                        .with_header(header("Content-Type", "application/json")),
                );
            }
            "/events" => {
                if shared.clients.fetch_add(1, Ordering::Relaxed) >= MAX_CLIENTS {
                    shared.clients.fetch_sub(1, Ordering::Relaxed);
                    // Answered and closed on a thread of its own: the loop
                    // goes on at once.
                    std::thread::spawn(move || {
                        let mut out = request.into_writer();
                        let body = "too many browsers on this live view\n";
                        let _ = write!(
                            out,
                            "HTTP/1.1 503 Service Unavailable\r\nContent-Type: text/plain\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
                            body.len()
                        );
                        let _ = out.flush();
                    });
                    continue;
                }
                let shared = shared.clone();
                // Each browser on its own thread: a stuck one blocks only
                // itself.
                std::thread::spawn(move || {
                    super::lower_priority();
                    let _ = stream_events(request.into_writer(), &shared);
                    shared.clients.fetch_sub(1, Ordering::Relaxed);
                });
            }
            _ => {
                let _ = request
                    .respond(tiny_http::Response::from_string("not found").with_status_code(404));
            }
        }
    }
}

fn state_json(shared: &Shared) -> String {
    let state = shared
        .state
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .clone();
    serde_json::to_string(&state).expect("the state serialises")
}

/// The event stream of one browser: the latest state when it changed, at
/// most every [`EVENT_EVERY`], each event flushed; ends when the view
/// closes or the browser goes.
fn stream_events(mut out: Box<dyn Write + Send>, shared: &Shared) -> std::io::Result<()> {
    out.write_all(
        b"HTTP/1.1 200 OK\r\nContent-Type: text/event-stream\r\nCache-Control: no-cache\r\nConnection: close\r\n\r\n",
    )?;
    out.flush()?;
    let mut sent = None;
    while !shared.closed.load(Ordering::Relaxed) {
        let version = shared
            .state
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .version;
        if sent != Some(version) {
            sent = Some(version);
            out.write_all(format!("data: {}\n\n", state_json(shared)).as_bytes())?;
            out.flush()?;
        }
        std::thread::sleep(EVENT_EVERY);
    }
    Ok(())
}
