//! The one acquisition pipeline: a [`Source`] streams what its device sends
//! through the stages here, in order, on the caller's thread:
//!
//! ```text
//! source -> recordings (PTU, tag file) -> binner -> ledger -> progress
//! ```
//!
//! Every device kind runs this same code; what differs (a link of our own,
//! a vendor library, a mock) is behind the source. A live view is one more
//! stage reading the progress it hands out.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use ndarray::Array3;

use super::ledger::{Ledger, Recording};
use super::source::{
    Delivery, Layout, RateSample, RecordFormat, Source, SourceEnd, SourceError, SourceFacts,
    StartRequest, Until,
};
use crate::events::Tag;
use crate::files::Completion;
use crate::formats::picoquant::records::{Decoder, RecordType};
use crate::formats::picoquant::writer::{HeaderEntry, PtuWriter, WriterHeader};
use crate::formats::sstags::{TagFileError, TagFileHeader, TagFileWriter};
use crate::tags::bin_file::{BinSpec, Pixels, window_and_map};
use crate::tags::binning::{Binner, FrameSelect, PixelMap, Region, TimeWindow};
use crate::tags::convert::MAX_T3_CHANNELS;
use crate::tags::counts::Counts;
use crate::tags::wire::bin_batch;

/// How often the progress callback runs.
const PROGRESS_EVERY: Duration = Duration::from_millis(100);
/// How often a watching stage sees the counts.
const WATCH_EVERY: Duration = Duration::from_millis(250);

/// What to acquire and how to bin and record it.
#[derive(Debug, Clone, PartialEq)]
pub struct StreamPlan {
    /// Time zero: micro time of the instrument's zero, ps.
    pub t0_ps: f64,
    /// Start of the first bin after time zero, ps.
    pub t_start_ps: f64,
    /// Bin width, ps (`None`: the micro-time unit).
    pub bin_width_ps: Option<f64>,
    /// Number of bins (`None`: one sync period).
    pub bins: Option<usize>,
    /// Pixels of a sensor to bin (the whole sensor if `None`).
    pub region: Option<Region>,
    /// Keep only photons of this input (point detectors).
    pub channel: Option<u16>,
    /// How a point detector's photons map to pixels.
    pub pixels: Pixels,
    /// Stop after this long (`None`: when the device stops or on request).
    pub duration: Option<Duration>,
    /// Micro-time unit to configure, fs (`None`: the device's own).
    pub resolution_fs: Option<u32>,
    /// Record every batch losslessly to this tag file (our own devices).
    pub tag_file: Option<PathBuf>,
    /// Record every record to this PTU file.
    pub ptu: Option<PathBuf>,
    /// The software, for the recordings' headers.
    pub software: String,
}

impl Default for StreamPlan {
    fn default() -> Self {
        Self {
            t0_ps: 0.0,
            t_start_ps: 0.0,
            bin_width_ps: None,
            bins: None,
            region: None,
            channel: None,
            pixels: Pixels::Auto,
            duration: None,
            resolution_fs: None,
            tag_file: None,
            ptu: None,
            software: String::new(),
        }
    }
}

/// A micro-time unit of `ps` in the whole femtoseconds a device is asked
/// for ([`StreamPlan::resolution_fs`]): at least 1 fs and at most what 32 bits
/// hold (4.3 us), so that no value is cut or wrapped on the way.
pub fn resolution_fs(ps: f64) -> Result<u32, AcquireError> {
    let fs = (ps * 1000.0).round();
    if !(1.0..=f64::from(u32::MAX)).contains(&fs) {
        return Err(AcquireError::setting(
            "resolution_fs",
            format!(
                "micro-time unit {ps} ps: give one from 0.001 ps to {} ps",
                f64::from(u32::MAX) / 1000.0
            ),
        ));
    }
    Ok(fs as u32)
}

impl StreamPlan {
    /// Bins the window `bins` describes (a set-up's).
    pub fn set_window(&mut self, bins: &crate::physics::TimeBins) {
        self.t_start_ps = bins.start_ps;
        self.bin_width_ps = Some(bins.width_ps);
        self.bins = Some(bins.count);
    }
}

/// Live counters of a running acquisition.
#[derive(Debug, Clone, PartialEq)]
pub struct Progress {
    /// Since the start.
    pub elapsed: Duration,
    /// Where the records and photons read so far went.
    pub counts: Counts,
    /// Photons received per second since the previous report.
    pub rate_hz: f64,
    /// Frames rejected by their checks so far (a link of our own).
    pub damaged_frames: u64,
    /// The latest rates the device reported.
    pub rates: Option<RateSample>,
}

impl Progress {
    /// The counters in words, for a progress line.
    pub fn describe(&self) -> String {
        let c = &self.counts;
        let mut s = format!("{} photons, {:.2} Mcps", c.photons, self.rate_hz / 1e6);
        if c.records != c.photons {
            let secs = self.elapsed.as_secs_f64().max(1e-3);
            s.push_str(&format!(
                ", {} records ({:.1} M records/s)",
                c.records,
                c.records as f64 / secs / 1e6
            ));
        }
        if let Some(r) = &self.rates {
            let inputs: Vec<String> = r.inputs.iter().map(|c| format!("{c:.0}/s")).collect();
            s.push_str(&format!(
                "; sync {:.0}/s, inputs {}",
                r.sync_hz,
                inputs.join(" ")
            ));
        }
        s.push_str(&format!(", lost in device {}", c.lost_in_device));
        if self.damaged_frames > 0 {
            s.push_str(&format!(", damaged frames {}", self.damaged_frames));
        }
        s
    }
}

/// What a watching stage (a live view) sees every 250 ms: the progress and
/// the counts so far, read in place (the stage copies what it keeps).
pub struct Snapshot<'a> {
    /// The counters.
    pub progress: &'a Progress,
    /// Counts so far, K x H x W.
    pub counts: ndarray::ArrayView3<'a, u32>,
    /// The binned window in device micro time: (first bin start, width), ps.
    pub window_ps: (f64, f64),
    /// The pixels of a sensor binned.
    pub region: Option<Region>,
    /// Time zero, ps (device micro time).
    pub t0_ps: f64,
    /// What the source said it is.
    pub facts: &'a SourceFacts,
}

/// What the pipeline made of one acquisition.
#[derive(Debug, Clone)]
pub struct Outcome {
    /// What the source said it is.
    pub facts: SourceFacts,
    /// Counts, K x H x W.
    pub counts: Array3<u32>,
    /// The binned window in device micro time: (first bin start, width), ps.
    pub window_ps: (f64, f64),
    /// The pixels of a sensor binned.
    pub region: Option<Region>,
    /// How the source's stream ended.
    pub end: SourceEnd,
    /// Where every photon and record went.
    pub ledger: Ledger,
    /// The rates the device reported during the run.
    pub rates_during_run: Vec<RateSample>,
}

impl Outcome {
    /// Records read per second of measurement.
    pub fn records_per_s(&self) -> f64 {
        self.ledger.counts.records as f64 / self.end.elapsed.as_secs_f64().max(1e-9)
    }
}

/// Why an acquisition could not run.
#[derive(Debug, thiserror::Error)]
pub enum AcquireError {
    /// The source could not start.
    #[error(transparent)]
    Source(#[from] SourceError),
    /// A recording could not be created.
    #[error(transparent)]
    TagFile(TagFileError),
    /// The plan does not fit the device.
    #[error("{0}")]
    Plan(String),
    /// A PTU file cannot keep the pixel of each photon of this sensor.
    #[error(
        "PTU recording {}: the sensor has {width} x {height} = {} pixels; a PTU T3 record names at most {MAX_T3_CHANNELS} input channels, so the pixel of each photon cannot be kept",
        path.display(),
        usize::from(*width) * usize::from(*height)
    )]
    PtuPixels {
        /// The PTU file asked for.
        path: PathBuf,
        /// Sensor columns.
        width: u16,
        /// Sensor rows.
        height: u16,
    },
    /// A setting of the plan does not fit the device; `name` is the
    /// plan's field (the command line's hints name its flag).
    #[error("{message}")]
    Setting {
        /// The setting: a field of [`StreamPlan`] (`channel`, `pixels`,
        /// `region`, `tag_file`, `resolution_fs`).
        name: &'static str,
        /// What is wrong, with the value.
        message: String,
    },
}

impl AcquireError {
    /// An error about the plan's setting `name`.
    pub fn setting(name: &'static str, message: impl Into<String>) -> Self {
        Self::Setting {
            name,
            message: message.into(),
        }
    }
}

/// A binner with the window it bins, in device micro time: (first bin
/// start, width), ps, and the pixels of a sensor it bins.
type Binning = (Binner, (f64, f64), Option<Region>);

/// The binner for `plan` on the source `facts` describe: the window
/// checked against the micro-time unit, the region against the sensor.
fn make_binner(plan: &StreamPlan, facts: &SourceFacts) -> Result<Binning, AcquireError> {
    let res_ps = facts.resolution_ps;
    let start_ps = plan.t0_ps + plan.t_start_ps;
    let plan_err = |e: String| {
        AcquireError::Plan(format!("{e} (the device's micro-time unit is {res_ps} ps)"))
    };
    match facts.layout {
        Layout::Sensor { width, height } => {
            for (name, given) in [
                ("channel", plan.channel.is_some()),
                ("pixels", plan.pixels != Pixels::Auto),
            ] {
                if given {
                    return Err(AcquireError::setting(
                        name,
                        format!(
                            "the {name} setting selects a point detector's inputs; this device is a {width} x {height} sensor (select its pixels with a region)"
                        ),
                    ));
                }
            }
            let width_ps = plan.bin_width_ps.unwrap_or(res_ps);
            let bins = plan.bins.unwrap_or_else(|| {
                TimeWindow::period_bins(facts.sync_period_ps, start_ps, width_ps)
            });
            let window = TimeWindow::from_ps(start_ps, width_ps, bins, res_ps)
                .and_then(|w| w.whole_steps(res_ps))
                .map_err(|e| plan_err(e.to_string()))?;
            let region = plan.region.unwrap_or(Region {
                x: 0,
                y: 0,
                width,
                height,
            });
            if region.width == 0
                || region.height == 0
                || region.x + region.width > width
                || region.y + region.height > height
            {
                return Err(AcquireError::Plan(format!(
                    "region of interest {}x{} at ({}, {}) is not inside the device's {width}x{height} sensor",
                    region.width, region.height, region.x, region.y
                )));
            }
            let map = PixelMap::Sensor {
                sensor_width: width,
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
                (start_ps, width_ps),
                Some(region),
            ))
        }
        Layout::Inputs { scan, .. } => {
            if plan.region.is_some() {
                return Err(AcquireError::setting(
                    "region",
                    "a region selects pixels of a sensor array; this device has inputs (select one with a channel, or an image with a scan)",
                ));
            }
            let spec = BinSpec {
                bin_width_ps: plan.bin_width_ps,
                t_start_ps: start_ps,
                bins: plan.bins,
                channel: plan.channel,
                pixels: plan.pixels,
                ..BinSpec::default()
            };
            let (window, map) = window_and_map(&spec, res_ps, facts.sync_period_ps, scan)
                .map_err(|e| plan_err(e.to_string()))?;
            Ok((
                Binner::new(window, map, plan.channel, FrameSelect::Sum),
                (window.start_ps(res_ps), window.width_ps(res_ps)),
                None,
            ))
        }
    }
}

/// The PTU recording: T3 records copied as the device wrote them, or a
/// wire device's events written as Generic T3 records (the sensor pixel
/// as the input channel).
struct PtuRecording {
    path: PathBuf,
    writer: Option<PtuWriter>,
    /// Photons and markers written (wire devices).
    events: u64,
    error: Option<String>,
}

/// A PTU recording checked against the device, not yet created.
struct PtuPlan {
    path: PathBuf,
    record_type: RecordType,
    header: WriterHeader,
}

impl PtuPlan {
    /// The record type and header for `facts`' device; refused when its
    /// records cannot be kept in a PTU file.
    fn new(plan: &StreamPlan, facts: &SourceFacts, path: &Path) -> Result<Self, AcquireError> {
        let mut extra = facts.ptu_tags.clone();
        extra.push((
            "CreatorSW_Name".into(),
            HeaderEntry::Text(plan.software.clone()),
        ));
        if let Some(d) = plan.duration {
            extra.push((
                "MeasDesc_AcquisitionTime".into(),
                HeaderEntry::Int(d.as_millis() as i64),
            ));
        }
        let (record_type, imaging) = match (&facts.format, facts.layout) {
            (RecordFormat::T3(t), Layout::Inputs { scan, .. }) => (*t, scan),
            (RecordFormat::T3(t), _) => (*t, None),
            (RecordFormat::Wire { identity, .. }, _) => {
                let pixels = usize::from(identity.pixels_x) * usize::from(identity.pixels_y);
                if pixels > MAX_T3_CHANNELS {
                    return Err(AcquireError::PtuPixels {
                        path: path.to_path_buf(),
                        width: identity.pixels_x,
                        height: identity.pixels_y,
                    });
                }
                extra.push((
                    "Scatterscope_Channels".into(),
                    HeaderEntry::Text(format!(
                        "input channel = sensor pixel (row-major, {} x {})",
                        identity.pixels_x, identity.pixels_y
                    )),
                ));
                (RecordType::GenericT3, None)
            }
        };
        let header = WriterHeader {
            resolution_s: facts.resolution_ps * 1e-12,
            sync_rate_hz: 1e12 / facts.sync_period_ps,
            device: facts.device.model.clone(),
            imaging,
            extra,
        };
        Ok(Self {
            path: path.to_path_buf(),
            record_type,
            header,
        })
    }

    /// Starts the file (its folder made if missing); a file that cannot be
    /// started is an error of the recording, said in the ledger.
    fn create(self) -> PtuRecording {
        let (writer, error) = match make_folder(&self.path)
            .and_then(|()| PtuWriter::create_recording(&self.path, self.record_type, &self.header))
        {
            Ok(w) => (Some(w), None),
            Err(e) => (None, Some(format!("creating {}: {e}", self.path.display()))),
        };
        PtuRecording {
            path: self.path,
            writer,
            events: 0,
            error,
        }
    }
}

/// Makes the folder `path` goes in, when it is missing.
fn make_folder(path: &Path) -> std::io::Result<()> {
    match path.parent() {
        Some(dir) if !dir.as_os_str().is_empty() => std::fs::create_dir_all(dir),
        _ => Ok(()),
    }
}

impl PtuRecording {
    fn fail(&mut self, e: std::io::Error) {
        self.error = Some(format!("writing {}: {e}", self.path.display()));
        self.writer = None;
    }

    fn records(&mut self, records: &[u32]) {
        if let Some(w) = self.writer.as_mut()
            && let Err(e) = w.write_records(records)
        {
            self.fail(e);
        }
    }

    fn batch(&mut self, batch: &firmware_protocol::EventBatch<'_>) {
        let Some(w) = self.writer.as_mut() else {
            return;
        };
        for event in batch.events() {
            // Losses are in the ledger; undecodable records too.
            let Some(tag) = event.ok().and_then(Tag::from_wire) else {
                continue;
            };
            if let Err(e) = w.write_tag(tag) {
                let e = std::io::Error::new(e.kind(), format!("batch {}: {e}", batch.header.seq));
                self.fail(e);
                return;
            }
            self.events += 1;
        }
    }

    /// Closes the file as `completion` says; `whole` says what it must
    /// hold to hold everything read.
    fn finish(self, completion: Completion, whole: impl Fn(u64, u64) -> bool) -> Recording {
        let mut error = self.error;
        let mut records = 0;
        if let Some(w) = self.writer {
            records = w.records();
            if let Err(e) = w.finish_as(completion) {
                error = Some(format!("closing {}: {e}", self.path.display()));
            }
        }
        Recording {
            whole: error.is_none() && whole(records, self.events),
            path: self.path,
            format: "ptu".into(),
            records,
            error,
        }
    }
}

/// Runs one acquisition of `plan` from `source`: starts it, streams every
/// delivery through the recordings and the binner, and returns the counts
/// with the ledger. `stop` ends it cleanly (the device's last records and
/// totals are still collected); `progress` sees it every 100 ms.
pub fn run(
    source: &mut dyn Source,
    plan: &StreamPlan,
    stop: &AtomicBool,
    progress: impl FnMut(&Progress),
) -> Result<Outcome, AcquireError> {
    run_watched(source, plan, stop, progress, &mut |_| {})
}

/// [`run`] with one more stage, `watch`, that sees the counts so far every
/// 250 ms on the pipeline's thread: it must return at once (a live view
/// copies what it shows and hands slow work to a thread of its own).
pub fn run_watched(
    source: &mut dyn Source,
    plan: &StreamPlan,
    stop: &AtomicBool,
    mut progress: impl FnMut(&Progress),
    watch: &mut dyn FnMut(&Snapshot<'_>),
) -> Result<Outcome, AcquireError> {
    let facts = source.start(&StartRequest {
        resolution_fs: plan.resolution_fs,
    })?;
    let (mut binner, window_ps, region) = make_binner(plan, &facts)?;
    // Every recording is checked against the device before any is started.
    let tags_header = match (&plan.tag_file, &facts.format) {
        (None, _) => None,
        (Some(path), RecordFormat::Wire { identity, config }) => Some((
            path,
            TagFileHeader::new(&facts.device.link, identity, config, &plan.software),
        )),
        (Some(path), RecordFormat::T3(_)) => {
            return Err(AcquireError::setting(
                "tag_file",
                format!(
                    "tag file {}: a tag file holds the event batches of our own devices; {} sends T3 records, which go to a PTU file",
                    path.display(),
                    facts.device.model
                ),
            ));
        }
    };
    let ptu_plan = match &plan.ptu {
        Some(path) => Some(PtuPlan::new(plan, &facts, path)?),
        None => None,
    };
    let mut tags = match tags_header {
        Some((path, header)) => Some(
            make_folder(path)
                .map_err(|e| {
                    AcquireError::TagFile(TagFileError::Io {
                        path: path.clone(),
                        source: e,
                    })
                })
                .and_then(|()| {
                    TagFileWriter::create(path, &header).map_err(AcquireError::TagFile)
                })?,
        ),
        None => None,
    };
    let mut ptu = ptu_plan.map(PtuPlan::create);
    let mut decoder = match facts.format {
        RecordFormat::T3(t) => Some(Decoder::new(t)),
        RecordFormat::Wire { .. } => None,
    };
    let mut rates_during_run = Vec::new();
    let mut latest_rates: Option<RateSample> = None;
    let mut damaged_frames = 0u64;
    let started = Instant::now();
    let (mut last_progress, mut last_photons) = (started, 0u64);
    let mut last_watch = started;
    let until = Until {
        duration: plan.duration,
        stop,
    };
    let end = source.stream(until, &mut |delivery| {
        match delivery {
            Delivery::Batch { payload, batch } => {
                if let Some(w) = tags.as_mut() {
                    w.write_batch(payload);
                }
                if let Some(p) = ptu.as_mut() {
                    p.batch(batch);
                }
                bin_batch(batch, &mut binner);
            }
            Delivery::Records(records) => {
                if let Some(p) = ptu.as_mut() {
                    p.records(records);
                }
                match decoder.as_mut() {
                    Some(d) => binner.bin_chunk(d, records),
                    // Records of a format this pipeline does not decode
                    // (none of today's sources sends them): read, counted
                    // and left unbinned.
                    None => binner.count_other_records(Counts {
                        records: records.len() as u64,
                        ..Counts::default()
                    }),
                }
            }
            Delivery::Rates(r) => {
                rates_during_run.push(r.clone());
                latest_rates = Some(r.clone());
            }
            Delivery::Idle { damaged_frames: d } => damaged_frames = d,
        }
        if last_progress.elapsed() >= PROGRESS_EVERY {
            let counts = binner.counts();
            let dt = last_progress.elapsed().as_secs_f64();
            let p = Progress {
                elapsed: started.elapsed(),
                counts,
                rate_hz: counts.photons.saturating_sub(last_photons) as f64 / dt,
                damaged_frames,
                rates: latest_rates.clone(),
            };
            progress(&p);
            last_progress = Instant::now();
            last_photons = counts.photons;
            if last_watch.elapsed() >= WATCH_EVERY
                && let Some(counts) = binner.counts_so_far()
            {
                last_watch = Instant::now();
                watch(&Snapshot {
                    progress: &p,
                    counts,
                    window_ps,
                    region,
                    t0_ps: plan.t0_ps,
                    facts: &facts,
                });
            }
        }
    });
    let completion = if end.stop.is_planned_end() {
        Completion::Complete
    } else {
        Completion::Interrupted
    };
    let (mut stacks, mut counts) = binner.finish();
    let mut recordings = Vec::new();
    if let Some(p) = ptu {
        let wire = decoder.is_none();
        let (photons, markers, records_read) = (counts.photons, counts.markers, counts.records);
        recordings.push(p.finish(completion, |records, events| {
            if wire {
                events == photons + markers
            } else {
                records == records_read
            }
        }));
    }
    if let (Some(w), Some(path)) = (tags, &plan.tag_file) {
        let batches = w.batches();
        let expected = end.transit.map_or(batches, |t| t.batches_received);
        let (error, path) = match w.finish(end.totals, completion) {
            Ok(p) => (None, p),
            Err(e) => (Some(e.to_string()), path.clone()),
        };
        recordings.push(Recording {
            whole: error.is_none() && batches == expected,
            path,
            format: "sstags".into(),
            records: batches,
            error,
        });
    }
    // The device's own loss total, where it sends one, over the losses its
    // records reported.
    counts.lost_in_device = end.lost_in_device.unwrap_or(counts.lost_in_device);
    let ledger = Ledger {
        detected: end.detected,
        fifo_overrun: end.fifo_overrun,
        counts_dropped: end.counts_dropped,
        transit: end.transit,
        counts,
        recordings,
    };
    Ok(Outcome {
        facts,
        counts: stacks.swap_remove(0),
        window_ps,
        region,
        end,
        ledger,
        rates_during_run,
    })
}
