//! The streaming pipeline: a reader thread moves bytes off the transport, a
//! decoder thread finds frames, routes responses, checks every event batch
//! (CRC, sequence, duplicates) and hands accepted batches to the consumer
//! and to a [`BatchRecorder`] (the host's tag file). All queues are bounded: a slow consumer slows
//! the reader, which leaves data in the device, whose FIFO overflow is then
//! reported in the stream as lost records. Nothing is dropped silently.

use std::collections::BTreeSet;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use crossbeam_channel::{Receiver, Sender, bounded};
use firmware_protocol::record::Record;
use firmware_protocol::{EventBatch, FrameDecoder, FromDevice, Response, ResponseFrame, Totals};
use serde::Serialize;

use crate::link::{ByteReader, Link, LinkError};

/// Where the pipeline records every accepted batch as it arrives, before
/// the consumer sees it (the host's lossless tag file). The file format is
/// the host's; the pipeline only hands over payloads.
pub trait BatchRecorder: Send {
    /// Appends one accepted batch payload (the frame's payload, unchanged).
    fn record_batch(&mut self, payload: &[u8]);
}

/// A recorder shared with its owner, who takes it back to close it once
/// the pipeline has let go of it.
impl<R: BatchRecorder> BatchRecorder for Arc<Mutex<R>> {
    fn record_batch(&mut self, payload: &[u8]) {
        self.lock().expect("recorder lock").record_batch(payload);
    }
}

/// Byte chunks queued between the reader and the decoder.
const BYTE_QUEUE: usize = 64;
/// Poll interval of the reader (how quickly it notices a shutdown).
const READ_POLL: Duration = Duration::from_millis(20);
/// Batches held for reordering before a gap is declared lost.
const REORDER_WINDOW: usize = 1024;

/// An event batch that passed every check.
#[derive(Debug, Clone)]
pub struct AcceptedBatch {
    /// The batch payload (header + records).
    pub payload: Arc<Vec<u8>>,
}

/// What the link delivered, counted by the decoder thread.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct LinkAccounting {
    /// Bytes read from the transport.
    pub bytes: u64,
    /// Bytes discarded while resynchronising (dropped or damaged data).
    pub bytes_skipped: u64,
    /// Frames rejected by a header check or CRC.
    pub crc_errors: u64,
    /// Event batches accepted.
    pub batches_accepted: u64,
    /// Batches received again (same sequence number) and discarded.
    pub batches_duplicate: u64,
    /// Batches that arrived after a later one (accepted).
    pub batches_out_of_order: u64,
    /// Batch payloads that did not parse.
    pub batches_malformed: u64,
    /// Photon records in accepted batches.
    pub photons_received: u64,
    /// Photons the device reported dropped (lost records).
    pub photons_lost_in_device: u64,
    /// Responses nobody waited for, or that did not decode.
    pub stray_responses: u64,
    /// Largest `photon_offset + photons` of any accepted batch: the device
    /// sent at least this many photons.
    pub photons_sent_at_least: u64,
}

/// Photons and batches that never reached the host, from the device's
/// totals when it sent them, else a lower bound.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct TransitLoss {
    /// Batches missing (lost, damaged).
    pub batches: u64,
    /// Photons in them.
    pub photons: u64,
    /// Whether the numbers are exact (the device's totals arrived) or lower
    /// bounds (it disconnected before saying).
    pub exact: bool,
}

impl LinkAccounting {
    /// Transit losses given the device's totals (if it sent them).
    pub fn transit_loss(&self, totals: Option<&Totals>) -> TransitLoss {
        match totals {
            Some(t) => TransitLoss {
                batches: u64::from(t.batches).saturating_sub(self.batches_accepted),
                photons: t.photons_sent.saturating_sub(self.photons_received),
                exact: true,
            },
            None => TransitLoss {
                batches: 0,
                photons: self
                    .photons_sent_at_least
                    .saturating_sub(self.photons_received),
                exact: false,
            },
        }
    }
}

/// Everything the pipeline hands to its owner.
pub enum Delivery {
    /// A checked batch.
    Batch(AcceptedBatch),
    /// A control response.
    Response(ResponseFrame),
    /// The link ended (disconnect or error); nothing follows.
    Ended(LinkError),
}

/// A running pipeline on an opened link.
pub struct Pipeline {
    /// Batches, responses and the end of the link, in arrival order.
    pub deliveries: Receiver<Delivery>,
    accounting: Arc<Mutex<LinkAccounting>>,
    shutdown: Arc<AtomicBool>,
    recorder: Arc<Mutex<Option<Box<dyn BatchRecorder>>>>,
    reader: Option<JoinHandle<()>>,
    decoder: Option<JoinHandle<()>>,
}

impl Pipeline {
    /// Starts the reader and decoder threads. Up to `queue_depth` accepted
    /// batches wait for the consumer before the pipeline pushes back.
    pub fn start(reader: Box<dyn ByteReader>, queue_depth: usize) -> Self {
        let recorder = Arc::new(Mutex::new(None));
        let (byte_tx, byte_rx) = bounded(BYTE_QUEUE);
        let (out_tx, out_rx) = bounded(queue_depth.max(1));
        let accounting = Arc::new(Mutex::new(LinkAccounting::default()));
        let shutdown = Arc::new(AtomicBool::new(false));
        let reader = {
            let shutdown = shutdown.clone();
            std::thread::Builder::new()
                .name("link-reader".into())
                .spawn(move || read_loop(reader, byte_tx, &shutdown))
                .expect("spawning the reader thread")
        };
        let decoder = {
            let accounting = accounting.clone();
            let recorder = recorder.clone();
            std::thread::Builder::new()
                .name("frame-decoder".into())
                .spawn(move || decode_loop(byte_rx, out_tx, &accounting, &recorder))
                .expect("spawning the decoder thread")
        };
        Self {
            deliveries: out_rx,
            accounting,
            shutdown,
            recorder,
            reader: Some(reader),
            decoder: Some(decoder),
        }
    }

    /// From now on, hands every accepted batch to `recorder` before the
    /// consumer sees it.
    pub fn record_to(&self, recorder: Box<dyn BatchRecorder>) {
        *self.recorder.lock().expect("recorder lock") = Some(recorder);
    }

    /// A snapshot of the counters.
    pub fn accounting(&self) -> LinkAccounting {
        *self.accounting.lock().expect("accounting lock")
    }

    /// Stops the threads, waits for them, lets go of the recorder, and
    /// returns the final counters.
    pub fn close(mut self) -> LinkAccounting {
        self.shutdown.store(true, Ordering::Relaxed);
        // Unblock a decoder waiting on a full queue.
        while self.deliveries.try_recv().is_ok() {}
        let deliveries = std::mem::replace(&mut self.deliveries, crossbeam_channel::never());
        drop(deliveries);
        if let Some(r) = self.reader.take() {
            let _ = r.join();
        }
        if let Some(d) = self.decoder.take() {
            let _ = d.join();
        }
        self.recorder.lock().expect("recorder lock").take();
        self.accounting()
    }
}

impl Drop for Pipeline {
    fn drop(&mut self) {
        self.shutdown.store(true, Ordering::Relaxed);
    }
}

/// Opens a pipeline on `link`, returning it and the link's writer.
pub fn start_on(link: Link, queue_depth: usize) -> (Pipeline, Box<dyn crate::ByteWriter>) {
    let Link { reader, writer, .. } = link;
    (Pipeline::start(reader, queue_depth), writer)
}

fn read_loop(
    mut reader: Box<dyn ByteReader>,
    tx: Sender<Result<Vec<u8>, LinkError>>,
    shutdown: &AtomicBool,
) {
    while !shutdown.load(Ordering::Relaxed) {
        match reader.read_chunk(READ_POLL) {
            Ok(None) => {}
            Ok(Some(chunk)) => {
                if tx.send(Ok(chunk)).is_err() {
                    return;
                }
            }
            Err(e) => {
                let _ = tx.send(Err(e));
                return;
            }
        }
    }
}

/// Sequence bookkeeping: which batches arrived, tolerating reordering
/// within [`REORDER_WINDOW`].
#[derive(Default)]
struct SeqTracker {
    /// Every batch below this arrived (or was given up as lost).
    next: u32,
    /// Batches at or above `next` that arrived.
    ahead: BTreeSet<u32>,
}

enum SeqVerdict {
    New { out_of_order: bool },
    Duplicate,
}

impl SeqTracker {
    fn accept(&mut self, seq: u32) -> SeqVerdict {
        if seq < self.next || self.ahead.contains(&seq) {
            return SeqVerdict::Duplicate;
        }
        // Out of order: a later batch is already here.
        let out_of_order = self.ahead.last().is_some_and(|&last| last > seq);
        self.ahead.insert(seq);
        while self.ahead.remove(&self.next) {
            self.next += 1;
        }
        if self.ahead.len() > REORDER_WINDOW
            && let Some(&first) = self.ahead.first()
        {
            // Give up on the gap: those batches are lost.
            self.next = first;
            while self.ahead.remove(&self.next) {
                self.next += 1;
            }
        }
        SeqVerdict::New { out_of_order }
    }
}

/// Photon records in `batch`, and photons its lost records say the device
/// dropped: what the ledger needs from each batch. The consumer decodes the
/// records again to bin them, on its own thread; this pass costs about 6 %
/// of what binning costs (BENCHMARKS.md, `count_records_of_the_stream`),
/// so it is kept rather than coupling the two threads.
pub fn count_records(batch: &EventBatch<'_>) -> (u64, u64) {
    let (mut photons, mut lost) = (0u64, 0u64);
    for r in batch.raw_records() {
        match Record::decode(r) {
            Ok(Record::Photon { .. }) => photons += 1,
            Ok(Record::Lost { count }) => lost += count,
            _ => {}
        }
    }
    (photons, lost)
}

fn decode_loop(
    rx: Receiver<Result<Vec<u8>, LinkError>>,
    tx: Sender<Delivery>,
    accounting: &Mutex<LinkAccounting>,
    recorder: &Mutex<Option<Box<dyn BatchRecorder>>>,
) {
    let mut decoder = FrameDecoder::new();
    let mut seqs = SeqTracker::default();
    let mut ended = None;
    for msg in rx.iter() {
        let chunk = match msg {
            Ok(c) => c,
            Err(e) => {
                decoder.end_stream();
                ended = Some(e);
                Vec::new()
            }
        };
        let mut deliveries = Vec::new();
        {
            let mut acc = accounting.lock().expect("accounting lock");
            let acc = &mut *acc;
            acc.bytes += chunk.len() as u64;
            decoder.push_with(&chunk, |frame| match FromDevice::parse(frame) {
                FromDevice::Events(batch) => {
                    match seqs.accept(batch.header.seq) {
                        SeqVerdict::Duplicate => {
                            acc.batches_duplicate += 1;
                            return;
                        }
                        SeqVerdict::New { out_of_order } => {
                            acc.batches_out_of_order += u64::from(out_of_order);
                        }
                    }
                    let (photons, lost) = count_records(&batch);
                    acc.batches_accepted += 1;
                    acc.photons_received += photons;
                    acc.photons_lost_in_device += lost;
                    acc.photons_sent_at_least = acc
                        .photons_sent_at_least
                        .max(batch.header.photon_offset + photons);
                    let payload = Arc::new(frame.payload.to_vec());
                    if let Some(r) = recorder.lock().expect("recorder lock").as_mut() {
                        r.record_batch(&payload);
                    }
                    deliveries.push(Delivery::Batch(AcceptedBatch { payload }));
                }
                FromDevice::Response(r) => {
                    if matches!(r.response, Response::Started) {
                        // A new run numbers its batches from 0.
                        seqs = SeqTracker::default();
                    }
                    deliveries.push(Delivery::Response(r));
                }
                FromDevice::MalformedBatch(_) => acc.batches_malformed += 1,
                FromDevice::Stray => acc.stray_responses += 1,
            });
            let s = decoder.stats();
            acc.bytes_skipped = s.bytes_skipped;
            acc.crc_errors = s.crc_errors;
        }
        for d in deliveries {
            if tx.send(d).is_err() {
                return;
            }
        }
        if let Some(e) = ended {
            let _ = tx.send(Delivery::Ended(e));
            return;
        }
    }
}
