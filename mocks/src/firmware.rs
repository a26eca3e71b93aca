//! The emulated firmware: answers requests, turns detections into event
//! records through a bounded FIFO (overflow becomes a lost record, as in a
//! real device), batches them, injects faults on request, and keeps the
//! true counts so tests can check the host's accounting exactly.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use firmware_protocol::batch::MAX_RECORDS;
use firmware_protocol::{
    BatchEncoder, Config, DeviceError, Event, FrameDecoder, FrameKind, Identity, PROTOCOL_VERSION,
    Request, RequestFrame, Response, ResponseFrame, Status, Totals, encode_frame, from_payload,
    to_payload,
};

use crate::emitter::{Emitter, Origin};
use crate::{DevicePort, PortClosed};

/// How long a real-time stream that has emitted every detection due waits
/// for the host before its next step (a fifth of the default batch
/// interval).
const AHEAD_WAIT: Duration = Duration::from_millis(1);

/// Response id of messages the device sends on its own.
pub const UNSOLICITED_ID: u16 = 0xFFFF;

/// Faults to inject, each every n-th event batch (0 = never).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Faults {
    /// Remove 5 bytes from the middle of the frame.
    pub drop_bytes_every: u32,
    /// Flip one bit in the middle of the frame.
    pub corrupt_every: u32,
    /// Send the batch twice.
    pub duplicate_every: u32,
    /// Hold the batch back and send it after the next one.
    pub reorder_every: u32,
    /// Overflow the FIFO: drop the next `overflow_photons` detections.
    pub overflow_every: u32,
    /// Photons dropped per overflow.
    pub overflow_photons: u64,
    /// Close the link after this many batches (0 = never), mid-stream.
    pub disconnect_after: u32,
    /// 0: each fault hits every n-th batch. Otherwise the seed of a
    /// random schedule: each fault hits a batch with probability 1/n, at
    /// seeded random times (soak tests).
    pub random_seed: u64,
}

impl std::str::FromStr for Faults {
    type Err = String;

    /// Comma-separated `NAME=N`: `corrupt`, `drop-bytes`, `duplicate`,
    /// `reorder`, `disconnect` (every n-th batch), `overflow=EVERY:PHOTONS`,
    /// and `random=SEED` (each fault with probability 1/n per batch at
    /// seeded random times instead). Empty: no faults.
    fn from_str(s: &str) -> Result<Self, String> {
        let mut f = Faults::default();
        for item in s.split(',').map(str::trim).filter(|i| !i.is_empty()) {
            let (name, value) = item
                .split_once('=')
                .ok_or_else(|| format!("fault `{item}`: expected NAME=N"))?;
            let n = |v: &str| {
                v.parse::<u32>()
                    .map_err(|_| format!("fault `{item}`: `{v}` is not a count"))
            };
            match name {
                "corrupt" => f.corrupt_every = n(value)?,
                "drop-bytes" => f.drop_bytes_every = n(value)?,
                "duplicate" => f.duplicate_every = n(value)?,
                "reorder" => f.reorder_every = n(value)?,
                "disconnect" => f.disconnect_after = n(value)?,
                "random" => {
                    f.random_seed = value
                        .parse()
                        .map_err(|_| format!("fault `{item}`: `{value}` is not a seed"))?
                }
                "overflow" => {
                    let (every, photons) = value.split_once(':').ok_or_else(|| {
                        format!("fault `{item}`: expected overflow=EVERY:PHOTONS")
                    })?;
                    f.overflow_every = n(every)?;
                    f.overflow_photons = u64::from(n(photons)?);
                }
                other => {
                    return Err(format!(
                        "unknown fault `{other}` (corrupt, drop-bytes, duplicate, reorder, overflow, disconnect, random)"
                    ));
                }
            }
        }
        Ok(f)
    }
}

/// Everything about the emulated device.
#[derive(Debug, Clone, PartialEq)]
pub struct MockOptions {
    /// Model string in Identify.
    pub model: String,
    /// Serial number.
    pub serial: String,
    /// TDC resolution, femtoseconds.
    pub tdc_resolution_fs: u32,
    /// FIFO capacity, records.
    pub fifo_capacity: usize,
    /// Pace detections in real time at the emitter's rate (`false`: as
    /// fast as the link takes them, never overflowing).
    pub real_time: bool,
    /// Stop by itself after this many detections (0 = never).
    pub max_photons: u64,
    /// Close an event batch after this long even if not full.
    pub batch_interval: Duration,
    /// Faults to inject.
    pub faults: Faults,
    /// Replay mode for load tests at hardware rates (0 = off): this many
    /// full batches are drawn from the emitter once, at Start, and then
    /// served over and over with fresh sequence numbers, photon offsets and
    /// sync bases, so a batch costs the device a copy and a CRC instead of
    /// one random draw per photon. Unpaced, batches go out as fast as the
    /// link takes them; paced (`real_time`), at the emitter's rate, and a
    /// batch due while the link is full is a FIFO overflow: its photons
    /// are counted lost and reported in a lost record. Dark counts,
    /// afterpulses and exclusions are not counted per replayed batch.
    pub replay_batches: usize,
}

impl Default for MockOptions {
    fn default() -> Self {
        Self {
            model: "scatterscope mock time tagger".into(),
            serial: "MOCK-0001".into(),
            tdc_resolution_fs: 1000,
            fifo_capacity: 1 << 20,
            real_time: true,
            max_photons: 0,
            batch_interval: Duration::from_millis(5),
            faults: Faults::default(),
            replay_batches: 0,
        }
    }
}

/// The true counts of the emulated device, for checking the host.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Truth {
    /// Photons detected in the window and ROI (sent or dropped).
    pub photons_detected: u64,
    /// Dark counts among them.
    pub dark_counts: u64,
    /// Afterpulses among them.
    pub afterpulses: u64,
    /// Signal photons that landed off the sensor since Start (never detected).
    pub photons_off_sensor: u64,
    /// Detections the device's time window or ROI excluded (never recorded).
    pub photons_excluded: u64,
    /// Photons dropped by FIFO overflow.
    pub photons_lost_fifo: u64,
    /// Photon records in batches handed to the link.
    pub photons_sent: u64,
    /// Distinct batches handed to the link.
    pub batches_sent: u32,
    /// Batches damaged on purpose (dropped bytes, flipped bit).
    pub batches_damaged: u32,
    /// Photon records in damaged batches.
    pub photons_damaged: u64,
    /// Batches sent twice.
    pub batches_duplicated: u32,
    /// Batches sent late.
    pub batches_reordered: u32,
    /// Photon records in batches never sent (disconnect).
    pub photons_unsent: u64,
    /// The device closed the link on purpose.
    pub disconnected: bool,
}

/// A running emulated device.
pub struct MockHandle {
    truth: Arc<Mutex<Truth>>,
    thread: Option<JoinHandle<()>>,
}

impl MockHandle {
    /// The true counts so far.
    pub fn truth(&self) -> Truth {
        *self.truth.lock().expect("truth lock")
    }

    /// Waits for the device thread to end (it ends when the host closes the
    /// link) and returns the final counts.
    pub fn join(mut self) -> Truth {
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        self.truth()
    }
}

/// The emulated device, before it runs.
pub struct MockDevice {
    options: MockOptions,
    emitter: Emitter,
    sync_period_fs: u64,
}

impl MockDevice {
    /// A device emitting from `emitter`.
    pub fn new(options: MockOptions, emitter: Emitter, sync_period_ps: f64) -> Self {
        Self {
            options,
            emitter,
            sync_period_fs: (sync_period_ps * 1000.0).round() as u64,
        }
    }

    /// What Identify answers.
    pub fn identity(&self) -> Identity {
        let (w, h) = self.emitter.sensor();
        Identity {
            model: self.options.model.clone(),
            serial: self.options.serial.clone(),
            firmware: [0, 1, 0],
            protocol_version: PROTOCOL_VERSION,
            pixels_x: w as u16,
            pixels_y: h as u16,
            channels: (w * h) as u16,
            tdc_resolution_fs: self.options.tdc_resolution_fs,
            sync_period_fs: self.sync_period_fs,
        }
    }

    /// Runs the firmware on `port` in its own thread.
    pub fn spawn(self, port: Box<dyn DevicePort>) -> MockHandle {
        let truth = Arc::new(Mutex::new(Truth::default()));
        let t = truth.clone();
        let thread = std::thread::Builder::new()
            .name("mock-firmware".into())
            .spawn(move || {
                let mut fw = Firmware::new(self, port, t);
                // The loop ends when the host closes the link.
                let _ = fw.run();
            })
            .expect("spawning the mock firmware thread");
        MockHandle {
            truth,
            thread: Some(thread),
        }
    }
}

struct Firmware {
    device: MockDevice,
    identity: Identity,
    port: Box<dyn DevicePort>,
    truth: Arc<Mutex<Truth>>,
    config: Option<Config>,
    running: bool,
    started: Instant,
    exposure: Option<Duration>,
    fifo: VecDeque<Event>,
    pending_lost: u64,
    encoder: BatchEncoder,
    batch_opened: Instant,
    /// Frames waiting for room in the link.
    outbox: VecDeque<Vec<u8>>,
    held_back: Option<Vec<u8>>,
    overflow_left: u64,
    request_errors: u32,
    requests: FrameDecoder,
    local: Truth,
    /// Emitter time at Start, seconds.
    emit_origin: f64,
    /// Emitter's off-sensor count at Start.
    off_sensor_origin: u64,
    /// Replay mode's batches and where the stream stands.
    replay: Replay,
    /// State of the random fault schedule.
    fault_rng: u64,
}

/// One batch drawn for replay: its records relative to sync 0.
struct ReplayBatch {
    records: Vec<u8>,
    photons: u64,
    /// Syncs the batch covers (its last sync + 1).
    span: u64,
}

/// The replayed stream's state (replay mode).
#[derive(Default)]
struct Replay {
    batches: Vec<ReplayBatch>,
    next: usize,
    seq: u32,
    photons_before: u64,
    sync_base: u64,
}

impl Firmware {
    fn new(device: MockDevice, port: Box<dyn DevicePort>, truth: Arc<Mutex<Truth>>) -> Self {
        let identity = device.identity();
        let fault_rng = device.options.faults.random_seed;
        Self {
            device,
            identity,
            port,
            truth,
            config: None,
            running: false,
            started: Instant::now(),
            exposure: None,
            fifo: VecDeque::new(),
            pending_lost: 0,
            encoder: BatchEncoder::new(),
            batch_opened: Instant::now(),
            outbox: VecDeque::new(),
            held_back: None,
            overflow_left: 0,
            request_errors: 0,
            requests: FrameDecoder::new(),
            local: Truth::default(),
            emit_origin: 0.0,
            off_sensor_origin: 0,
            fault_rng,
            replay: Replay::default(),
        }
    }

    fn publish(&mut self) {
        self.local.photons_off_sensor = self.device.emitter.off_sensor() - self.off_sensor_origin;
        *self.truth.lock().expect("truth lock") = self.local;
    }

    fn run(&mut self) -> Result<(), PortClosed> {
        loop {
            // While streaming, poll the host quickly (waiting only while
            // ahead of schedule); idle, wait longer.
            let wait = if !self.outbox.is_empty() {
                Duration::ZERO
            } else if self.running {
                self.ahead_of_schedule()
            } else {
                Duration::from_millis(20)
            };
            if let Some(bytes) = self.port.recv(wait)? {
                self.requests.push(&bytes);
                let mut frames = Vec::new();
                while let Some(f) = self.requests.next_frame() {
                    frames.push((f.kind, f.payload.to_vec()));
                }
                for (kind, payload) in frames {
                    if kind == FrameKind::Request {
                        self.handle(&payload);
                    }
                }
            }
            if self.running {
                if self.replay.batches.is_empty() {
                    self.acquire();
                } else {
                    self.acquire_replay();
                }
            }
            self.flush_outbox()?;
            self.publish();
            if self.local.disconnected && self.outbox.is_empty() {
                return Err(PortClosed);
            }
            if self.running && !self.outbox.is_empty() {
                // The link is full: let the host catch up.
                std::thread::sleep(Duration::from_micros(200));
            }
        }
    }

    /// How long a real-time stream may wait before its next step:
    /// [`AHEAD_WAIT`] once it has emitted every detection due (zero when it
    /// runs behind, unpaced or replaying), so its detections leave in
    /// bursts of a millisecond, each with its own time, within the
    /// batches' 5 ms. A real device keeps time on its own clock; the
    /// emulated one waits instead of spinning, so it leaves the host's
    /// cores to the host (spinning, it kept one core busy whatever the
    /// rate, and starved the live view's reconstruction).
    fn ahead_of_schedule(&self) -> Duration {
        if !self.device.options.real_time || !self.replay.batches.is_empty() {
            return Duration::ZERO;
        }
        let ahead =
            self.device.emitter.time_s() - self.emit_origin - self.started.elapsed().as_secs_f64();
        if ahead > 0.0 {
            AHEAD_WAIT
        } else {
            Duration::ZERO
        }
    }

    /// Queues a response frame (sent with the batches, in order).
    fn respond(&mut self, id: u16, response: Response) {
        let payload = to_payload(&ResponseFrame { id, response }).expect("responses encode");
        let mut frame = Vec::new();
        encode_frame(FrameKind::Response, &payload, &mut frame).expect("responses are small");
        self.outbox.push_back(frame);
    }

    fn handle(&mut self, payload: &[u8]) {
        let Ok(RequestFrame { id, request }) = from_payload::<RequestFrame>(payload) else {
            self.request_errors += 1;
            return self.respond(UNSOLICITED_ID, Response::Error(DeviceError::Malformed));
        };
        let response = match request {
            Request::Identify => Response::Identity(self.identity.clone()),
            Request::Configure(_) if self.running => Response::Error(DeviceError::Busy),
            Request::Configure(c) => match self.validate(c) {
                Ok(c) => {
                    self.config = Some(c.clone());
                    Response::Configured(c)
                }
                Err(e) => Response::Error(e),
            },
            Request::Start => {
                if self.config.is_none() {
                    self.config = Some(
                        self.validate(default_config(&self.identity))
                            .expect("default config is valid"),
                    );
                }
                self.start();
                Response::Started
            }
            Request::Stop => {
                if self.running {
                    self.stop();
                }
                Response::Stopped(self.totals())
            }
            Request::Status => Response::Status(Status {
                running: self.running,
                totals: self.totals(),
                fifo_fill: self.fifo.len() as u32,
                fifo_capacity: self.device.options.fifo_capacity as u32,
                request_errors: self.request_errors,
            }),
        };
        self.respond(id, response)
    }

    fn validate(&self, c: Config) -> Result<Config, DeviceError> {
        let invalid = |field: &str, reason: String| DeviceError::InvalidConfig {
            field: field.into(),
            reason,
        };
        let tdc = self.identity.tdc_resolution_fs;
        if c.resolution_fs == 0 || !c.resolution_fs.is_multiple_of(tdc) {
            return Err(invalid(
                "resolution_fs",
                format!(
                    "{} fs is not a positive multiple of the TDC resolution {tdc} fs",
                    c.resolution_fs
                ),
            ));
        }
        if c.sync_divider == 0 {
            return Err(invalid("sync_divider", "0; must be at least 1".into()));
        }
        let period_units =
            self.identity.sync_period_fs * u64::from(c.sync_divider) / u64::from(c.resolution_fs);
        if period_units > u64::from(firmware_protocol::record::MAX_MICRO) {
            return Err(invalid(
                "resolution_fs",
                format!(
                    "{} fs makes the {} fs sync period {period_units} units, beyond the 20-bit micro time",
                    c.resolution_fs, self.identity.sync_period_fs
                ),
            ));
        }
        if let Some(r) = c.roi {
            let (w, h) = (
                u32::from(self.identity.pixels_x),
                u32::from(self.identity.pixels_y),
            );
            if r.width == 0
                || r.height == 0
                || u32::from(r.x) + u32::from(r.width) > w
                || u32::from(r.y) + u32::from(r.height) > h
            {
                return Err(invalid(
                    "roi",
                    format!(
                        "{}x{} at ({}, {}) is not inside the {w}x{h} sensor",
                        r.width, r.height, r.x, r.y
                    ),
                ));
            }
        }
        Ok(c)
    }

    fn totals(&self) -> Totals {
        Totals {
            batches: self.local.batches_sent,
            photons_sent: self.local.photons_sent,
            photons_lost: self.local.photons_lost_fifo,
        }
    }

    fn start(&mut self) {
        self.running = true;
        self.started = Instant::now();
        let c = self.config.as_ref().expect("configured before start");
        self.exposure =
            (c.exposure_ms > 0).then(|| Duration::from_millis(u64::from(c.exposure_ms)));
        self.encoder = BatchEncoder::new();
        self.batch_opened = Instant::now();
        self.fifo.clear();
        self.pending_lost = 0;
        self.local = Truth::default();
        // Detections continue from the emitter's current state; times and
        // off-sensor losses are counted from Start.
        self.emit_origin = self.device.emitter.time_s();
        self.off_sensor_origin = self.device.emitter.off_sensor();
        if self.device.options.replay_batches > 0 {
            self.draw_replay();
        }
    }

    /// Draws the replay batches: detections mapped as in [`Self::acquire`],
    /// encoded with room left for one lost record per batch.
    fn draw_replay(&mut self) {
        let mut batches = Vec::new();
        while batches.len() < self.device.options.replay_batches {
            let mut enc = BatchEncoder::new();
            let mut first = None;
            let mut last = 0;
            while enc.len() + 3 <= MAX_RECORDS {
                let d = self.device.emitter.next_detection();
                let Some(Event::Photon { pixel, micro, sync }) = self.detection_event(&d) else {
                    continue;
                };
                let origin = *first.get_or_insert(sync);
                last = sync - origin;
                enc.push(Event::Photon {
                    pixel,
                    micro,
                    sync: last,
                })
                .expect("replay events are in time order and in range");
            }
            let photons = enc.photons();
            let mut payload = Vec::new();
            enc.finish_batch(&mut payload);
            batches.push(ReplayBatch {
                records: payload.split_off(firmware_protocol::batch::HEADER_LEN),
                photons,
                span: last + 1,
            });
        }
        self.replay = Replay {
            batches,
            ..Replay::default()
        };
    }

    /// The event a detection becomes under the current configuration, or
    /// `None` if the device's time window or ROI excludes it.
    fn detection_event(&self, d: &crate::emitter::Detection) -> Option<Event> {
        let config = self.config.as_ref().expect("running implies configured");
        let res = u64::from(config.resolution_fs);
        let divider = u64::from(config.sync_divider.max(1));
        let window = u64::from(config.time_window);
        let width = u64::from(self.identity.pixels_x);
        let period_units = (self.identity.sync_period_fs * divider / res).max(1);
        let tdc = self.identity.tdc_resolution_fs as u64;
        let delay_fs = (d.delay_ps * 1000.0) as u64;
        // Arrivals after a full period belong to the next sync.
        let micro = ((delay_fs / tdc * tdc) / res) % period_units;
        let (x, y) = (u64::from(d.pixel) % width, u64::from(d.pixel) / width);
        let in_roi = config.roi.is_none_or(|r| {
            x >= u64::from(r.x)
                && x < u64::from(r.x) + u64::from(r.width)
                && y >= u64::from(r.y)
                && y < u64::from(r.y) + u64::from(r.height)
        });
        if (window > 0 && micro >= window) || !in_roi {
            return None;
        }
        Some(Event::Photon {
            pixel: d.pixel as u16,
            micro: micro as u32,
            sync: d.sync / divider,
        })
    }

    /// Replay mode's acquisition step: batches due go out while the link
    /// has room; paced batches due while it is full overflow the FIFO.
    fn acquire_replay(&mut self) {
        let (real_time, max_photons) = (
            self.device.options.real_time,
            self.device.options.max_photons,
        );
        let due = real_time
            .then(|| (self.started.elapsed().as_secs_f64() * self.device.emitter.rate_hz()) as u64);
        for _ in 0..64 {
            if max_photons > 0 && self.local.photons_detected >= max_photons {
                break;
            }
            let index = self.replay.next % self.replay.batches.len();
            let photons = self.replay.batches[index].photons;
            if due.is_some_and(|due| self.local.photons_detected + photons > due) {
                break;
            }
            let link_full = self.outbox.len() >= 4;
            if link_full && due.is_none() {
                break;
            }
            self.replay.next += 1;
            self.local.photons_detected += photons;
            if link_full || self.overflow_left > 0 {
                // The FIFO overflows: the batch's photons are dropped.
                self.overflow_left = self.overflow_left.saturating_sub(photons);
                self.pending_lost += photons;
                self.local.photons_lost_fifo += photons;
                continue;
            }
            self.send_replay_batch(Some(index));
        }
        let quota_met = max_photons > 0 && self.local.photons_detected >= max_photons;
        let exposure_over = self.exposure.is_some_and(|e| self.started.elapsed() >= e);
        if quota_met || exposure_over {
            self.stop();
            let totals = self.totals();
            self.respond(UNSOLICITED_ID, Response::Stopped(totals));
        }
    }

    /// Frames replay batch `index` (`None`: a batch with only the lost
    /// record), a lost record first if photons were dropped since the last
    /// one, and hands it to the link; the stream moves past it.
    fn send_replay_batch(&mut self, index: Option<usize>) {
        let (records, photons, span): (&[u8], u64, u64) = match index {
            Some(i) => {
                let b = &self.replay.batches[i];
                (&b.records, b.photons, b.span)
            }
            None => (&[], 0, 0),
        };
        let r = &self.replay;
        let mut payload =
            Vec::with_capacity(firmware_protocol::batch::HEADER_LEN + 8 + records.len());
        payload.extend_from_slice(&r.seq.to_le_bytes());
        payload.extend_from_slice(&r.photons_before.to_le_bytes());
        payload.extend_from_slice(&r.sync_base.to_le_bytes());
        if self.pending_lost > 0 {
            let lost = firmware_protocol::record::Record::Lost {
                count: self.pending_lost,
            };
            payload.extend_from_slice(&lost.encode().to_le_bytes());
        }
        payload.extend_from_slice(records);
        self.pending_lost = 0;
        let seq = self.replay.seq;
        self.replay.seq = seq.wrapping_add(1);
        self.replay.photons_before += photons;
        self.replay.sync_base += span;
        let mut frame = Vec::with_capacity(payload.len() + 12);
        encode_frame(FrameKind::Events, &payload, &mut frame).expect("batches fit a frame");
        self.send_batch(frame, photons, seq);
    }

    fn stop(&mut self) {
        self.running = false;
        if !self.replay.batches.is_empty() && self.pending_lost > 0 {
            self.send_replay_batch(None);
        }
        while !self.fifo.is_empty() || self.pending_lost > 0 {
            self.drain_fifo(true);
        }
        if !self.encoder.is_empty() {
            self.close_batch();
        }
        if let Some(held) = self.held_back.take() {
            // Nothing came after it: it goes out in order after all.
            self.local.batches_reordered -= 1;
            self.outbox.push_back(held);
        }
    }

    /// Detections due by now go into the FIFO; the FIFO goes into batches.
    fn acquire(&mut self) {
        let opts = &self.device.options;
        let elapsed = self.started.elapsed();
        let cap = opts.fifo_capacity;
        let mut budget = 1 << 16;
        while budget > 0 {
            if opts.max_photons > 0 && self.local.photons_detected >= opts.max_photons {
                break;
            }
            let room = self.fifo.len() + usize::from(self.pending_lost > 0) < cap;
            if !opts.real_time && !room {
                break;
            }
            if opts.real_time
                && self.device.emitter.time_s() - self.emit_origin > elapsed.as_secs_f64()
            {
                break;
            }
            budget -= 1;
            let d = self.device.emitter.next_detection();
            let Some(event) = self.detection_event(&d) else {
                self.local.photons_excluded += 1;
                continue;
            };
            self.local.photons_detected += 1;
            self.local.dark_counts += u64::from(d.origin == Origin::Dark);
            self.local.afterpulses += u64::from(d.origin == Origin::Afterpulse);
            if self.overflow_left > 0 || !room {
                self.overflow_left = self.overflow_left.saturating_sub(1);
                self.pending_lost += 1;
                self.local.photons_lost_fifo += 1;
                continue;
            }
            if self.pending_lost > 0 {
                self.fifo.push_back(Event::Lost {
                    count: self.pending_lost,
                });
                self.pending_lost = 0;
            }
            self.fifo.push_back(event);
        }
        let exposure_over = self.exposure.is_some_and(|e| elapsed >= e);
        let quota_met = opts.max_photons > 0 && self.local.photons_detected >= opts.max_photons;
        self.drain_fifo(false);
        if exposure_over || quota_met {
            self.stop();
            let totals = self.totals();
            self.respond(UNSOLICITED_ID, Response::Stopped(totals));
        }
    }

    /// Moves FIFO records into the open batch while the link has room;
    /// closes batches when full or old (`all`: regardless of the link).
    fn drain_fifo(&mut self, all: bool) {
        if self.pending_lost > 0 && (all || self.fifo.len() < self.device.options.fifo_capacity) {
            self.fifo.push_back(Event::Lost {
                count: self.pending_lost,
            });
            self.pending_lost = 0;
        }
        while all || self.outbox.len() < 4 {
            let Some(e) = self.fifo.pop_front() else {
                break;
            };
            if !self.encoder.has_room(2) {
                self.close_batch();
            }
            self.encoder
                .push(e)
                .expect("device events are in time order and in range");
        }
        if !self.encoder.is_empty()
            && (self.encoder.len() + 2 > MAX_RECORDS
                || self.batch_opened.elapsed() >= self.device.options.batch_interval)
        {
            self.close_batch();
        }
    }

    fn close_batch(&mut self) {
        let photons_before = self.encoder.photons();
        let mut payload = Vec::new();
        let header = self.encoder.finish_batch(&mut payload);
        self.batch_opened = Instant::now();
        let photons = photons_before - header.photon_offset;
        let mut frame = Vec::with_capacity(payload.len() + 12);
        encode_frame(FrameKind::Events, &payload, &mut frame).expect("batches fit a frame");
        self.send_batch(frame, photons, header.seq);
    }

    /// Hands a batch frame to the link, with the faults due at its
    /// sequence number, and keeps the truth.
    fn send_batch(&mut self, mut frame: Vec<u8>, photons: u64, seq: u32) {
        let f = self.device.options.faults.clone();
        let n = seq + 1;
        let mut rng = self.fault_rng;
        let mut every = |k: u32| {
            if f.random_seed == 0 {
                k > 0 && n.is_multiple_of(k)
            } else {
                // xorshift64*: one draw per fault kind and batch.
                rng ^= rng >> 12;
                rng ^= rng << 25;
                rng ^= rng >> 27;
                let draw = rng.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 32;
                k > 0 && draw.is_multiple_of(u64::from(k))
            }
        };
        let (overflow, drop_bytes, corrupt, duplicate, reorder) = (
            every(f.overflow_every),
            every(f.drop_bytes_every),
            every(f.corrupt_every),
            every(f.duplicate_every),
            every(f.reorder_every),
        );
        self.fault_rng = rng;
        if f.disconnect_after > 0 && n > f.disconnect_after {
            // The cable is pulled: this batch and everything after is gone.
            self.local.photons_unsent += photons;
            self.local.disconnected = true;
            self.running = false;
            return;
        }
        self.local.batches_sent += 1;
        self.local.photons_sent += photons;
        if overflow {
            self.overflow_left += f.overflow_photons;
        }
        if drop_bytes {
            let mid = frame.len() / 2;
            frame.drain(mid..mid + 5);
            self.damaged(photons);
        } else if corrupt {
            let mid = frame.len() / 2;
            frame[mid] ^= 0x10;
            self.damaged(photons);
        }
        if duplicate {
            self.local.batches_duplicated += 1;
            self.outbox.push_back(frame.clone());
        }
        if reorder && self.held_back.is_none() {
            self.local.batches_reordered += 1;
            self.held_back = Some(frame);
            return;
        }
        self.outbox.push_back(frame);
        if let Some(held) = self.held_back.take() {
            self.outbox.push_back(held);
        }
    }

    fn damaged(&mut self, photons: u64) {
        self.local.batches_damaged += 1;
        self.local.photons_damaged += photons;
    }

    fn flush_outbox(&mut self) -> Result<(), PortClosed> {
        while let Some(frame) = self.outbox.front() {
            if !self.port.send(frame)? {
                break;
            }
            self.outbox.pop_front();
        }
        Ok(())
    }
}

/// The configuration a Start without Configure uses: TDC resolution, whole
/// period, full sensor, no exposure limit.
pub fn default_config(identity: &Identity) -> Config {
    Config {
        sync_divider: 1,
        resolution_fs: identity.tdc_resolution_fs,
        time_window: 0,
        roi: None,
        exposure_ms: 0,
    }
}
