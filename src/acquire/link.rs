//! Our own time taggers on the wire protocol (USB, serial, and the mocks
//! behind the same transports) as an acquisition [`Source`]: identify,
//! configure, start, hand every accepted batch on as it comes, stop on the
//! duration, on request (Ctrl-C) or when the device stops by itself, and
//! collect the device's totals.

use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use firmware_protocol::{Config, EventBatch, Request, Response};
use scatterscope_drivers::Link;
use scatterscope_drivers::client::Device;
use scatterscope_drivers::pipeline::Delivery as LinkDelivery;

use super::ledger::Transit;
use super::source::{
    Delivery, DeviceInfo, Layout, RecordFormat, Source, SourceEnd, SourceError, SourceFacts,
    StartRequest, StopReason, Until,
};
use crate::formats::picoquant::writer::HeaderEntry;

/// Accepted batches that may wait for the stages before the pipeline
/// pushes back on the device.
const QUEUE_DEPTH: usize = 256;
/// How long the device gets to send its last batches and totals after Stop.
const STOP_TIMEOUT: Duration = Duration::from_secs(10);
/// How often, at most, the link's health is handed on while idle.
const IDLE_EVERY: Duration = Duration::from_millis(100);

/// A device of the wire protocol on an opened link.
pub struct LinkSource {
    device: Option<Device>,
    link: String,
}

impl LinkSource {
    /// The device on `link` (not yet identified).
    pub fn new(link: Link) -> Self {
        let name = link.description.clone();
        Self {
            device: Some(Device::open(link, QUEUE_DEPTH)),
            link: name,
        }
    }

    fn device(&mut self) -> &mut Device {
        self.device
            .as_mut()
            .expect("the link is open until the stream ends")
    }
}

fn device_error(e: impl std::fmt::Display) -> SourceError {
    SourceError::Device(e.to_string())
}

impl Source for LinkSource {
    fn start(&mut self, request: &StartRequest) -> Result<SourceFacts, SourceError> {
        let device = self.device();
        let identity = device.identify().map_err(device_error)?;
        let config = device
            .configure(Config {
                sync_divider: 1,
                resolution_fs: request.resolution_fs.unwrap_or(identity.tdc_resolution_fs),
                time_window: 0,
                roi: None,
                exposure_ms: 0,
            })
            .map_err(device_error)?;
        let (width, height) = (
            usize::from(identity.pixels_x),
            usize::from(identity.pixels_y),
        );
        if width == 0 || height == 0 {
            return Err(SourceError::Plan(format!(
                "the device reports a {width} x {height} sensor"
            )));
        }
        let v = identity.firmware;
        Ok(SourceFacts {
            device: DeviceInfo {
                link: self.link.clone(),
                model: identity.model.clone(),
                serial: identity.serial.clone(),
                version: format!("firmware {}.{}.{}", v[0], v[1], v[2]),
                library: None,
            },
            resolution_ps: f64::from(config.resolution_fs) / 1000.0,
            sync_period_ps: identity.sync_period_fs as f64 / 1000.0,
            layout: Layout::Sensor { width, height },
            ptu_tags: vec![(
                "HWSync_Divider".into(),
                HeaderEntry::Int(i64::from(config.sync_divider)),
            )],
            format: RecordFormat::Wire { identity, config },
            rates_at_start: None,
            warnings: Vec::new(),
        })
    }

    fn stream(&mut self, until: Until<'_>, sink: &mut dyn FnMut(Delivery<'_>)) -> SourceEnd {
        let Until { duration, stop } = until;
        let mut device = self.device.take().expect("streamed once");
        if let Err(e) = device.start() {
            return SourceEnd::ended(StopReason::Disconnected(e.to_string()));
        }
        let started = Instant::now();
        let mut stop_sent: Option<Instant> = None;
        let mut totals = None;
        let mut last_batch = started;
        let mut last_idle = started;
        let reason = loop {
            if stop_sent.is_none() {
                let over = duration.is_some_and(|d| started.elapsed() >= d);
                if over || stop.load(Ordering::Relaxed) {
                    if let Err(e) = device.send(Request::Stop) {
                        break StopReason::Disconnected(e.to_string());
                    }
                    stop_sent = Some(Instant::now());
                }
            } else if stop_sent.is_some_and(|t| t.elapsed() > STOP_TIMEOUT) {
                break StopReason::NoStopAnswer;
            }
            match device.next(Duration::from_millis(20)) {
                Some(LinkDelivery::Batch(b)) => {
                    let batch =
                        EventBatch::parse(&b.payload).expect("the pipeline checked the batch");
                    sink(Delivery::Batch {
                        payload: &b.payload,
                        batch: &batch,
                    });
                    last_batch = Instant::now();
                }
                Some(LinkDelivery::Response(r)) => {
                    if let Response::Stopped(t) = r.response {
                        totals = Some(t);
                        break match stop_sent {
                            None => StopReason::DeviceStopped,
                            Some(_) if stop.load(Ordering::Relaxed) => StopReason::Interrupted,
                            Some(_) => StopReason::Duration,
                        };
                    }
                }
                Some(LinkDelivery::Ended(e)) => break StopReason::Disconnected(e.to_string()),
                None => {}
            }
            if last_idle.elapsed() >= IDLE_EVERY {
                last_idle = Instant::now();
                sink(Delivery::Idle {
                    damaged_frames: device.accounting().crc_errors,
                });
            }
        };
        let link = device.close();
        let transit = link.transit_loss(totals.as_ref());
        SourceEnd {
            stop: reason,
            elapsed: last_batch.duration_since(started),
            detected: totals.map(|t| t.photons_sent + t.photons_lost),
            lost_in_device: totals.map(|t| t.photons_lost),
            totals,
            fifo_overrun: false,
            counts_dropped: false,
            transit: Some(Transit {
                lost_photons: transit.photons,
                exact: transit.exact,
                batches_received: link.batches_accepted,
                batches_lost: transit.batches,
                batches_duplicate: link.batches_duplicate,
                batches_out_of_order: link.batches_out_of_order,
                bytes_skipped: link.bytes_skipped,
                crc_errors: link.crc_errors,
            }),
            warnings: Vec::new(),
        }
    }
}
