//! A recorded file as an acquisition [`Source`]: a PTU (T3) or one of the
//! project's tag files, its records handed to the pipeline at the pace
//! they were recorded (or `speed` times faster), so that a lab can review a
//! run in the live view as it happened. The recording's own end is the
//! run's planned end.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use firmware_protocol::{Config, Identity};

use super::source::{
    Delivery, DeviceInfo, Layout, RecordFormat, Source, SourceEnd, SourceError, SourceFacts,
    StartRequest, StopReason, Until,
};
use crate::events::Tag;
use crate::formats::detect::is_tag_file;
use crate::formats::picoquant::records::Decoder;
use crate::formats::picoquant::{self, FileInfo, RecordReader};
use crate::formats::sstags::TagFile;

/// Records handed on at once: pacing is this fine.
const PIECE: usize = 1 << 15;

/// A recording to play back, as `--device replay:FILE` names it.
#[derive(Debug, Clone, PartialEq)]
pub struct ReplaySpec {
    /// The recording (a T3 PTU or a tag file).
    pub path: PathBuf,
    /// Times the recorded pace (1: as recorded).
    pub speed: f64,
}

/// A recording played back.
pub struct FileSource {
    path: PathBuf,
    speed: f64,
    opened: Option<Opened>,
}

enum Opened {
    Ptu(FileInfo, RecordReader),
    Tags(TagFile),
}

/// The slowest replay: a thousand times slower than recorded.
pub const MIN_SPEED: f64 = 1e-3;
/// The fastest paced replay: a million times faster than recorded (a
/// second of recording in a microsecond, faster than any file is read).
pub const MAX_SPEED: f64 = 1e6;

/// The clock of a replay: waits until a record's recorded time, `speed`
/// times faster, has come.
struct Pace {
    started: Instant,
    speed: f64,
}

impl Pace {
    /// Waits until `at_s` seconds into the recording; false when `stop`
    /// or `duration` ended the replay first.
    fn wait(&self, at_s: f64, stop: &AtomicBool, duration: Option<Duration>) -> bool {
        loop {
            if stop.load(Ordering::Relaxed) || duration.is_some_and(|d| self.started.elapsed() >= d)
            {
                return false;
            }
            // A recording hours long at the slowest speed is still far
            // inside a Duration; a value past it waits "forever".
            let due =
                Duration::try_from_secs_f64((at_s / self.speed).max(0.0)).unwrap_or(Duration::MAX);
            let now = self.started.elapsed();
            if now >= due {
                return true;
            }
            std::thread::sleep((due - now).min(Duration::from_millis(50)));
        }
    }
}

impl FileSource {
    /// `path` (a T3 PTU or a tag file), played at `speed` times its pace;
    /// refused if it is not a whole recording of a kind that replays.
    pub fn open(path: &Path, speed: f64) -> Result<Self, SourceError> {
        if !(MIN_SPEED..=MAX_SPEED).contains(&speed) {
            return Err(SourceError::setting(
                "speed",
                format!(
                    "replay speed {speed:e}: give a factor from {MIN_SPEED} to {MAX_SPEED:e} (1 plays the recorded pace)"
                ),
            ));
        }
        let err = |e: String| SourceError::Device(e);
        let opened = if is_tag_file(path) {
            Opened::Tags(TagFile::open(path).map_err(|e| err(e.to_string()))?)
        } else {
            let (info, reader) = picoquant::open(path).map_err(|e| err(e.to_string()))?;
            info.check_finished(false).map_err(|e| err(e.to_string()))?;
            if !info.record_type.is_t3() {
                return Err(SourceError::Plan(format!(
                    "{}: {} records carry no micro time; a replay bins T3 records",
                    path.display(),
                    info.record_type.name()
                )));
            }
            Opened::Ptu(info, reader)
        };
        Ok(Self {
            path: path.to_path_buf(),
            speed,
            opened: Some(opened),
        })
    }
}

impl Source for FileSource {
    fn start(&mut self, request: &StartRequest) -> Result<SourceFacts, SourceError> {
        request.refuse_micro_time_unit(
            "a micro-time unit configures a device; a recording keeps its own",
        )?;
        let link = format!("replay of {}", self.path.display());
        Ok(match self.opened.as_ref().expect("started once") {
            Opened::Ptu(info, _) => SourceFacts {
                device: DeviceInfo {
                    link,
                    model: info.device.clone(),
                    serial: String::new(),
                    version: format!("{} ({:?})", info.record_type.name(), info.container),
                    library: None,
                },
                resolution_ps: info.resolution_s * 1e12,
                sync_period_ps: info.macro_unit_s * 1e12,
                format: RecordFormat::T3(info.record_type),
                layout: Layout::Inputs {
                    count: 64,
                    scan: info.imaging,
                },
                rates_at_start: None,
                warnings: info.unread_note().into_iter().collect(),
                ptu_tags: Vec::new(),
            },
            Opened::Tags(file) => {
                let h = &file.header;
                let identity = Identity {
                    model: h.model.clone(),
                    serial: h.serial.clone(),
                    firmware: [0; 3],
                    protocol_version: firmware_protocol::PROTOCOL_VERSION,
                    pixels_x: h.pixels_x,
                    pixels_y: h.pixels_y,
                    channels: h.pixels_x.saturating_mul(h.pixels_y),
                    tdc_resolution_fs: h.resolution_fs,
                    sync_period_fs: h.sync_period_fs / u64::from(h.sync_divider.max(1)),
                };
                let config = Config {
                    sync_divider: h.sync_divider,
                    resolution_fs: h.resolution_fs,
                    time_window: h.time_window,
                    roi: None,
                    exposure_ms: 0,
                };
                SourceFacts {
                    device: DeviceInfo {
                        link,
                        model: h.model.clone(),
                        serial: h.serial.clone(),
                        version: format!("recorded by {} from {}", h.software, h.link),
                        library: None,
                    },
                    resolution_ps: f64::from(h.resolution_fs) / 1000.0,
                    sync_period_ps: h.sync_period_fs as f64 / 1000.0,
                    layout: Layout::Sensor {
                        width: usize::from(h.pixels_x),
                        height: usize::from(h.pixels_y),
                    },
                    format: RecordFormat::Wire { identity, config },
                    rates_at_start: None,
                    warnings: Vec::new(),
                    ptu_tags: Vec::new(),
                }
            }
        })
    }

    fn stream(&mut self, until: Until<'_>, sink: &mut dyn FnMut(Delivery<'_>)) -> SourceEnd {
        let Until { duration, stop } = until;
        let pace = Pace {
            started: Instant::now(),
            speed: self.speed,
        };
        let mut end = SourceEnd::ended(StopReason::EndOfRecording);
        let cut = |stop: &AtomicBool| {
            if stop.load(Ordering::Relaxed) {
                StopReason::Interrupted
            } else {
                StopReason::Duration
            }
        };
        match self.opened.take().expect("streamed once") {
            Opened::Ptu(info, mut reader) => {
                let period_s = info.macro_unit_s;
                let mut decoder = Decoder::new(info.record_type);
                let mut chunk = Vec::new();
                'file: loop {
                    match reader.next_chunk(&mut chunk) {
                        Ok(true) => {}
                        Ok(false) => break,
                        Err(e) => {
                            end.stop =
                                StopReason::DeviceError(format!("{}: {e}", self.path.display()));
                            break;
                        }
                    }
                    for piece in chunk.chunks(PIECE) {
                        // The recorded time of the piece's last tag.
                        let mut last = None;
                        for &r in piece {
                            if let Some(
                                Tag::Photon { macro_time, .. }
                                | Tag::Marker { macro_time, .. }
                                | Tag::Sync { macro_time },
                            ) = decoder.decode(r)
                            {
                                last = Some(macro_time);
                            }
                        }
                        if let Some(t) = last
                            && !pace.wait(t as f64 * period_s, stop, duration)
                        {
                            end.stop = cut(stop);
                            break 'file;
                        }
                        sink(Delivery::Records(piece));
                    }
                }
            }
            Opened::Tags(file) => {
                let period_s = file.header.sync_period_fs as f64 * 1e-15;
                let mut cut_at = None;
                let read = file.read_payloads(|payload, batch| {
                    if cut_at.is_some() {
                        return;
                    }
                    if !pace.wait(batch.header.sync_base as f64 * period_s, stop, duration) {
                        cut_at = Some(cut(stop));
                        return;
                    }
                    sink(Delivery::Batch { payload, batch });
                });
                match (read, cut_at) {
                    (_, Some(reason)) => end.stop = reason,
                    (Err(e), None) => end.stop = StopReason::DeviceError(e.to_string()),
                    (Ok(summary), None) => {
                        end.totals = summary.totals;
                        if summary.totals.is_none() {
                            end.warnings.push(
                                "the recording has no end frame: it was cut and may not hold the whole run".into(),
                            );
                        }
                    }
                }
            }
        }
        end.elapsed = pace.started.elapsed();
        end
    }
}
