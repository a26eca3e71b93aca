//! One acquisition: identify, configure, start, bin batches as they come,
//! stop on the duration, on request (Ctrl-C) or when the device stops by
//! itself, and collect the device's totals.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use crate::formats::sstags::{TagFileError, TagFileHeader, TagFileWriter};
use firmware_protocol::{Config, EventBatch, Identity, Request, Response, Totals};
use ndarray::Array3;
use scatterscope_drivers::Link;
use scatterscope_drivers::client::{ClientError, Device};
use scatterscope_drivers::pipeline::{BatchRecorder, Delivery};
use serde::{Deserialize, Serialize};

use super::accounting::AcquisitionAccounting;
use crate::tags::binning::{Binner, FrameSelect, PixelMap, Region, TimeWindow};
use crate::tags::wire::{BatchCounts, bin_batch};

/// Accepted batches that may wait for the binner before the pipeline
/// pushes back on the device.
const QUEUE_DEPTH: usize = 256;
/// How long the device gets to send its last batches and totals after Stop.
const STOP_TIMEOUT: Duration = Duration::from_secs(10);
/// How often the progress callback runs.
const PROGRESS_EVERY: Duration = Duration::from_millis(100);

/// What to acquire and how to bin it.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    /// Start of the first bin after time zero, ps.
    pub t_start_ps: f64,
    /// Bin width, ps (a multiple of the micro-time unit).
    pub bin_width_ps: f64,
    /// Number of bins.
    pub bins: usize,
    /// Time zero: micro time of the instrument's zero, ps.
    pub t0_ps: f64,
    /// Pixels to bin (the whole sensor if `None`).
    pub region: Option<Region>,
    /// Stop after this long (`None`: when the device stops or on request).
    pub duration: Option<Duration>,
    /// Micro-time unit to configure, fs (`None`: the TDC resolution).
    pub resolution_fs: Option<u32>,
    /// Record every batch losslessly to this tag file (`.sstags`).
    pub tag_file: Option<PathBuf>,
    /// Name of the software, for the tag file's header.
    pub software: String,
}

/// Why the acquisition ended.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StopReason {
    /// The planned duration elapsed.
    Duration,
    /// The user asked (Ctrl-C or SIGTERM).
    Interrupted,
    /// The device stopped by itself (exposure or photon quota).
    DeviceStopped,
    /// The link ended: the device is gone.
    Disconnected(String),
    /// The device did not confirm Stop in time.
    NoStopAnswer,
}

impl StopReason {
    /// Why the acquisition ended, in words for the acquisition's summary.
    pub fn describe(&self) -> String {
        match self {
            Self::Duration => "the planned duration elapsed".into(),
            Self::Interrupted => "interrupted (Ctrl-C or SIGTERM)".into(),
            Self::DeviceStopped => {
                "the device stopped by itself (its exposure or photon quota)".into()
            }
            Self::Disconnected(e) => format!("the device disconnected: {e}"),
            Self::NoStopAnswer => "the device did not confirm Stop in time".into(),
        }
    }
}

/// Live counters for a progress display.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Progress {
    /// Since Start.
    pub elapsed: Duration,
    /// Photons received so far.
    pub received: u64,
    /// Photons received per second since the previous report.
    pub rate_hz: f64,
    /// Photons binned so far.
    pub binned: u64,
    /// Photons the device reported lost so far.
    pub lost_in_device: u64,
    /// Batches rejected or missing so far (CRC failures).
    pub damaged_frames: u64,
}

impl Progress {
    /// The counters in words, for a progress display.
    pub fn describe(&self) -> String {
        format!(
            "{} photons, {:.2} Mcps, lost in device {}, damaged frames {}",
            self.received,
            self.rate_hz / 1e6,
            self.lost_in_device,
            self.damaged_frames
        )
    }
}

/// The result of an acquisition.
#[derive(Debug, Clone)]
pub struct Outcome {
    /// Counts, K x H x W.
    pub counts: Array3<u32>,
    /// The device.
    pub identity: Identity,
    /// The configuration it applied.
    pub config: Config,
    /// Its totals, if it sent them.
    pub totals: Option<Totals>,
    /// Where every photon went.
    pub accounting: AcquisitionAccounting,
    /// Why it ended.
    pub stop: StopReason,
    /// From Start to the last batch.
    pub elapsed: Duration,
    /// The binned window in device micro time: (first bin start, width), ps.
    pub window_ps: (f64, f64),
    /// The pixels binned (the whole sensor unless the plan set a region).
    pub region: Region,
    /// The tag file written, if any.
    pub tag_file: Option<PathBuf>,
    /// The link.
    pub link: String,
}

/// Why an acquisition could not run.
#[derive(Debug, thiserror::Error)]
pub enum AcquireError {
    /// Control exchange or transport failure before streaming.
    #[error(transparent)]
    Client(#[from] ClientError),
    /// The tag file.
    #[error(transparent)]
    TagFile(TagFileError),
    /// The plan does not fit the device.
    #[error("{0}")]
    Plan(String),
}

/// Runs one acquisition on `link`. `stop` requests a clean stop (the
/// device's last batches and totals are still collected).
pub fn acquire(
    link: Link,
    plan: &Plan,
    stop: &AtomicBool,
    mut progress: impl FnMut(&Progress),
) -> Result<Outcome, AcquireError> {
    let link_name = link.description.clone();
    let mut device = Device::open(link, QUEUE_DEPTH);
    let identity = device.identify()?;
    let applied = device.configure(Config {
        sync_divider: 1,
        resolution_fs: plan.resolution_fs.unwrap_or(identity.tdc_resolution_fs),
        time_window: 0,
        roi: None,
        exposure_ms: 0,
    })?;
    let (mut binner, window_ps, region) = make_binner(plan, &identity, &applied)?;
    let tag_file = match &plan.tag_file {
        Some(path) => {
            let header = TagFileHeader::new(&link_name, &identity, &applied, &plan.software);
            let writer = TagFileWriter::create(path, &header).map_err(AcquireError::TagFile)?;
            let writer = Arc::new(Mutex::new(writer));
            device.record_to(Box::new(writer.clone()));
            Some(writer)
        }
        None => None,
    };
    device.start()?;
    let started = Instant::now();
    let mut counts = BatchCounts::default();
    let mut stop_sent: Option<Instant> = None;
    let (mut last_progress, mut last_received) = (Instant::now(), 0);
    let mut totals = None;
    let mut last_batch = started;
    let reason = loop {
        let elapsed = started.elapsed();
        if stop_sent.is_none() {
            let over = plan.duration.is_some_and(|d| elapsed >= d);
            if over || stop.load(Ordering::Relaxed) {
                device.send(Request::Stop)?;
                stop_sent = Some(Instant::now());
            }
        } else if stop_sent.is_some_and(|t| t.elapsed() > STOP_TIMEOUT) {
            break StopReason::NoStopAnswer;
        }
        match device.next(Duration::from_millis(20)) {
            Some(Delivery::Batch(b)) => {
                let batch = EventBatch::parse(&b.payload).expect("the pipeline checked the batch");
                counts += bin_batch(&batch, &mut binner);
                last_batch = Instant::now();
            }
            Some(Delivery::Response(r)) => {
                if let Response::Stopped(t) = r.response {
                    totals = Some(t);
                    break match stop_sent {
                        None => StopReason::DeviceStopped,
                        Some(_) if stop.load(Ordering::Relaxed) => StopReason::Interrupted,
                        Some(_) => StopReason::Duration,
                    };
                }
            }
            Some(Delivery::Ended(e)) => break StopReason::Disconnected(e.to_string()),
            None => {}
        }
        if last_progress.elapsed() >= PROGRESS_EVERY {
            let acc = device.accounting();
            let dt = last_progress.elapsed().as_secs_f64();
            progress(&Progress {
                elapsed: started.elapsed(),
                received: acc.photons_received,
                rate_hz: (acc.photons_received - last_received) as f64 / dt,
                binned: binner.accounting().binned,
                lost_in_device: acc.photons_lost_in_device,
                damaged_frames: acc.crc_errors,
            });
            last_progress = Instant::now();
            last_received = acc.photons_received;
        }
    };
    let elapsed = last_batch.duration_since(started);
    let link_acc = device.close();
    let tag_file = match tag_file {
        Some(shared) => {
            let writer = Arc::into_inner(shared)
                .expect("the closed pipeline let go of the writer")
                .into_inner()
                .expect("writer lock");
            let completion = if matches!(reason, StopReason::Duration | StopReason::DeviceStopped) {
                crate::files::Completion::Complete
            } else {
                crate::files::Completion::Interrupted
            };
            Some(
                writer
                    .finish(totals, completion)
                    .map_err(AcquireError::TagFile)?,
            )
        }
        None => None,
    };
    let (mut stacks, bin_acc) = binner.finish();
    let transit = link_acc.transit_loss(totals.as_ref());
    let accounting = AcquisitionAccounting {
        detected: totals.map(|t| t.photons_sent + t.photons_lost),
        received: bin_acc.received,
        binned: bin_acc.binned,
        outside_window: bin_acc.outside_window,
        outside_region: bin_acc.outside_region + bin_acc.other_channel,
        lost_in_device: totals.map_or(counts.lost_in_device, |t| t.photons_lost),
        lost_in_transit: transit.photons,
        transit_exact: transit.exact,
        batches_received: link_acc.batches_accepted,
        batches_lost: transit.batches,
        batches_duplicate: link_acc.batches_duplicate,
        batches_out_of_order: link_acc.batches_out_of_order,
        bytes_skipped: link_acc.bytes_skipped,
        crc_errors: link_acc.crc_errors,
        invalid_records: counts.invalid_records,
        markers: bin_acc.markers,
    };
    Ok(Outcome {
        counts: stacks.swap_remove(0),
        identity,
        config: applied,
        totals,
        accounting,
        stop: reason,
        elapsed,
        window_ps,
        region,
        tag_file,
        link: link_name,
    })
}

/// The binner for `plan` on this device: checks the window against the
/// micro-time unit and the region against the sensor. Returns it with the
/// window in device micro time and the region binned.
fn make_binner(
    plan: &Plan,
    identity: &Identity,
    config: &Config,
) -> Result<(Binner, (f64, f64), Region), AcquireError> {
    let res_ps = f64::from(config.resolution_fs) / 1000.0;
    let start_ps = plan.t0_ps + plan.t_start_ps;
    let window = TimeWindow::from_ps(start_ps, plan.bin_width_ps, plan.bins, res_ps)
        .and_then(|w| w.whole_steps(res_ps))
        .map_err(|e| {
            AcquireError::Plan(format!("{e} (the device's micro-time unit is {res_ps} ps)"))
        })?;
    let (w, h) = (
        usize::from(identity.pixels_x),
        usize::from(identity.pixels_y),
    );
    let region = plan.region.unwrap_or(Region {
        x: 0,
        y: 0,
        width: w,
        height: h,
    });
    if region.width == 0
        || region.height == 0
        || region.x + region.width > w
        || region.y + region.height > h
        || w == 0
    {
        return Err(AcquireError::Plan(format!(
            "region of interest {}x{} at ({}, {}) is not inside the device's {w}x{h} sensor",
            region.width, region.height, region.x, region.y
        )));
    }
    let map = PixelMap::Sensor {
        sensor_width: w,
        region,
    };
    window
        .check_stack(&map)
        .map_err(|e| AcquireError::Plan(e.to_string()))?;
    // The counts and, in the stack written, their float32 copy.
    crate::memory::check(
        crate::memory::bytes_of([window.bins, region.height, region.width], 8),
        || {
            format!(
                "a stack of {} bins of {} x {} pixels",
                window.bins, region.width, region.height
            )
        },
    )
    .map_err(|e| AcquireError::Plan(e.to_string()))?;
    Ok((
        Binner::new(window, map, None, FrameSelect::Sum),
        (start_ps, plan.bin_width_ps),
        region,
    ))
}

/// The tag file records what the pipeline accepts, batch by batch.
impl BatchRecorder for TagFileWriter {
    fn record_batch(&mut self, payload: &[u8]) {
        self.write_batch(payload);
    }
}
