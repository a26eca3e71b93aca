//! What a recorded tag file holds, from one pass over its records, without
//! binning anything: events per kind and the measured duration (what
//! `scatterscope info` shows).

use std::collections::BTreeMap;
use std::path::Path;

use crate::formats::becker_hickl::sdt::SdtFile;
use crate::formats::becker_hickl::spc::{self, CardFlags, SpcFileError, SpcInfo, SpcOptions};
use crate::formats::sstags::{TagFileError, TagFileSummary, read_tag_file};
use firmware_protocol::Event;

use crate::events::Tag;
use crate::formats::picoquant::records::Decoder;
use crate::formats::picoquant::{FileError, FileInfo, TtrError, open};

/// The records of a PicoQuant file, counted by kind.
#[derive(Debug, Default)]
pub struct PicoQuantSurvey {
    /// Photons per input channel (as numbered in the records).
    pub photons_per_channel: BTreeMap<u16, u64>,
    /// Marker records.
    pub markers: u64,
    /// Sync records (T2 files only).
    pub syncs: u64,
    /// Overflow records (they only advance the time base).
    pub overflows: u64,
    /// Time of the last event, seconds (infinite past 2^64 ticks).
    pub last_event_s: f64,
    /// Why the pass ended before the announced record count (a cut file).
    pub cut: Option<TtrError>,
}

/// Events counted tag by tag, the same for every kind of recording:
/// photons per channel, markers, syncs and the last event's macro time.
#[derive(Default)]
struct Tally {
    photons_per_channel: BTreeMap<u16, u64>,
    markers: u64,
    syncs: u64,
    last_macro: u64,
}

impl Tally {
    fn add(&mut self, tag: Tag) {
        let macro_time = match tag {
            Tag::Photon {
                channel,
                macro_time,
                ..
            } => {
                *self.photons_per_channel.entry(channel).or_default() += 1;
                macro_time
            }
            Tag::Marker { macro_time, .. } => {
                self.markers += 1;
                macro_time
            }
            Tag::Sync { macro_time } => {
                self.syncs += 1;
                macro_time
            }
        };
        self.last_macro = macro_time;
    }
}

/// The last event's time (s) of a macro time `last` in units of `unit_s`:
/// infinite when the decoder saturated it (the overflow records add up past
/// 2^64 ticks, which no recording lasts).
fn last_event_s(last: u64, unit_s: f64) -> f64 {
    if last == u64::MAX {
        f64::INFINITY
    } else {
        last as f64 * unit_s
    }
}

/// The `info` line of a recording whose last event came at `s` seconds.
fn duration_line(s: f64) -> String {
    if s.is_finite() {
        format!("measured duration: {s:.6} s (last event)")
    } else {
        "warning: measured duration unknown: the overflow records add up past 2^64 macro-time ticks, which no recording lasts".into()
    }
}

/// Counts the records of a PicoQuant file (PTU, HT3, PT3; T2 or T3). A cut
/// file is counted up to the cut, which is reported, not an error.
pub fn survey_picoquant(path: &Path) -> Result<(FileInfo, PicoQuantSurvey), FileError> {
    let (info, mut reader) = open(path)?;
    let mut decoder = Decoder::new(info.record_type);
    let mut s = PicoQuantSurvey::default();
    let mut tally = Tally::default();
    let mut chunk = Vec::new();
    loop {
        match reader.next_chunk(&mut chunk) {
            Ok(true) => {}
            Ok(false) => break,
            Err(e) => {
                s.cut = Some(e);
                break;
            }
        }
        for &rec in &chunk {
            match decoder.decode(rec) {
                None => s.overflows += 1,
                Some(tag) => tally.add(tag),
            }
        }
    }
    s.photons_per_channel = tally.photons_per_channel;
    s.markers = tally.markers;
    s.syncs = tally.syncs;
    s.last_event_s = last_event_s(tally.last_macro, info.macro_unit_s);
    Ok((info, s))
}

/// The events of a tag file (`.sstags`), counted by kind.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct TagFileSurvey {
    /// Photon records.
    pub photons: u64,
    /// Marker records.
    pub markers: u64,
    /// Photons the device reported lost (lost records).
    pub lost_in_device: u64,
    /// Records that do not decode.
    pub invalid_records: u64,
    /// Time of the last event, seconds (from the sync count and period).
    pub last_event_s: f64,
}

/// Counts the events of a tag file (`.sstags`).
pub fn survey_tag_file(path: &Path) -> Result<(TagFileSummary, TagFileSurvey), TagFileError> {
    let mut s = TagFileSurvey::default();
    let mut last_sync = 0u64;
    let summary = read_tag_file(path, |batch| {
        for e in batch.events() {
            match e {
                Ok(Event::Photon { sync, .. }) => {
                    s.photons += 1;
                    last_sync = last_sync.max(sync);
                }
                Ok(Event::Marker { sync, .. }) => {
                    s.markers += 1;
                    last_sync = last_sync.max(sync);
                }
                Ok(Event::Lost { count }) => s.lost_in_device += count,
                Err(_) => s.invalid_records += 1,
            }
        }
    })?;
    s.last_event_s = last_sync as f64 * summary.header.sync_period_fs as f64 * 1e-15;
    Ok((summary, s))
}

/// The records of a Becker & Hickl FIFO file, counted by kind.
#[derive(Debug, Default)]
pub struct SpcSurvey {
    /// Photons per routing channel.
    pub photons_per_channel: BTreeMap<u16, u64>,
    /// Marker records.
    pub markers: u64,
    /// What the records flagged (GAP, INVALID, overflows).
    pub flags: CardFlags,
    /// Time of the last event, seconds (infinite past 2^64 ticks).
    pub last_event_s: f64,
}

/// Counts the records of a Becker & Hickl `.spc` file read as `options`
/// say; a cut tail is reported by [`SpcInfo::describe`], not an error.
pub fn survey_spc(path: &Path, options: &SpcOptions) -> Result<(SpcInfo, SpcSurvey), SpcFileError> {
    let info = spc::open(path, options)?;
    let mut tally = Tally::default();
    let reader = info.records_part(0, 1)?;
    let flags = spc::decode_each(&info, reader, |tag| {
        if let Some(tag) = tag {
            tally.add(tag);
        }
        Ok::<(), SpcFileError>(())
    })?;
    let s = SpcSurvey {
        photons_per_channel: tally.photons_per_channel,
        markers: tally.markers,
        flags,
        last_event_s: last_event_s(tally.last_macro, info.macro_clock_s),
    };
    Ok((info, s))
}

/// What `info` shows of a recorded file: its header and its events
/// counted by kind.
#[derive(Debug)]
pub enum Survey {
    /// A PicoQuant file.
    PicoQuant(Box<FileInfo>, PicoQuantSurvey),
    /// The project's tag file.
    TagFile(Box<TagFileSummary>, TagFileSurvey),
    /// A Becker & Hickl FIFO file.
    BeckerHicklFifo(Box<SpcInfo>, SpcSurvey),
    /// A Becker & Hickl histogram file.
    BeckerHicklHistogram(Box<SdtFile>),
}

impl Survey {
    /// The survey in words, one line each; warnings start with `warning:`.
    pub fn lines(&self) -> Vec<String> {
        match self {
            Survey::BeckerHicklFifo(info, s) => {
                let mut lines = info.describe();
                if info.trailing_bytes > 0 {
                    lines.push(format!("warning: {}", info.cut()));
                }
                lines.push(format!("photons per channel: {:?}", s.photons_per_channel));
                let f = &s.flags;
                lines.push(format!(
                    "markers: {}; INVALID records (dropped): {}; overflow count records: {} ({} macro-time overflows in all)",
                    s.markers, f.invalid, f.overflow_entries, f.overflows
                ));
                lines.push(duration_line(s.last_event_s));
                if f.gaps > 0 {
                    lines.push(format!(
                        "warning: {} record(s) carry the GAP flag: the card's FIFO was full and photons before each were lost in the card",
                        f.gaps
                    ));
                }
                // Routing channels the header says were not used hint at
                // another module's layout.
                let used = 1u32 << info.routing_bits;
                let beyond: u64 = s
                    .photons_per_channel
                    .range(used.min(u32::from(u16::MAX)) as u16..)
                    .map(|(_, n)| n)
                    .sum();
                if beyond > 0 && info.routing_bits < 8 {
                    lines.push(format!(
                        "warning: {beyond} photon(s) on routing channels from {used} up, though the header declares {} routing bit(s): the records may be another module's layout (--spc-module)",
                        info.routing_bits
                    ));
                }
                lines
            }
            Survey::BeckerHicklHistogram(file) => file.describe(),
            Survey::PicoQuant(info, s) => {
                let mut lines = info.describe();
                lines.extend(info.unread_note().map(|n| format!("warning: {n}")));
                lines.extend(info.completeness_note().map(|n| format!("warning: {n}")));
                lines.push(format!("photons per channel: {:?}", s.photons_per_channel));
                lines.push(format!(
                    "markers: {}, syncs: {}, overflow records: {}",
                    s.markers, s.syncs, s.overflows
                ));
                lines.push(duration_line(s.last_event_s));
                if let Some(e) = &s.cut {
                    lines.push(format!("warning: {e}"));
                }
                lines
            }
            Survey::TagFile(summary, s) => {
                let h = &summary.header;
                let mut lines = vec![
                    format!("file: {}", summary.path.display()),
                    format!(
                        "container: scatterscope tag file v{}; written by {}",
                        h.format_version, h.software
                    ),
                    format!("device: {} {} via {}", h.model, h.serial, h.link),
                    format!(
                        "sensor: {} x {} pixels; micro-time unit {} fs; sync period {} fs (divider {})",
                        h.pixels_x, h.pixels_y, h.resolution_fs, h.sync_period_fs, h.sync_divider
                    ),
                    format!(
                        "batches: {}; photons: {}; markers: {}; lost in the device: {}; invalid records: {}",
                        summary.batches, s.photons, s.markers, s.lost_in_device, s.invalid_records
                    ),
                    duration_line(s.last_event_s),
                ];
                lines.push(match summary.totals {
                    Some(t) => format!(
                        "device totals: {} batches, {} photons sent, {} lost in the device{}",
                        t.batches,
                        t.photons_sent,
                        t.photons_lost,
                        if t.photons_sent == s.photons {
                            ""
                        } else {
                            " (the file misses some: lost in transit)"
                        }
                    ),
                    None => {
                        "warning: no end frame: the recording was cut (crash or disconnect)".into()
                    }
                });
                if summary.interrupted {
                    lines.push(
                        "warning: the run that wrote it was interrupted before its planned end (its end frame says so)".into(),
                    );
                }
                if summary.bytes_skipped > 0 {
                    lines.push(format!(
                        "warning: {} bytes did not form valid frames (damage or a cut last batch)",
                        summary.bytes_skipped
                    ));
                }
                lines
            }
        }
    }
}
