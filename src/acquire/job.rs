//! One acquisition as `acquire` runs it, for every device kind, from a
//! [`Job`] a caller fills: time zero, the device opened as a source, the
//! pipeline run, and the outputs written (the stack with its record,
//! `acquisition.json`, a contact sheet, and for a mock the truth image).
//! For a mock the stack's light budget is set from the known scene, so
//! reconstructions come out in its units.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use super::calibration::t0_from_reference;
use super::device::{DeviceSpec, open_device};
use super::open_error::OpenError;
use super::pipeline::{AcquireError, Outcome, Progress, Snapshot, StreamPlan, run_watched};
use super::source::{SourceReport, StopReason};
use crate::files::{FilePlan, PlanError};
use crate::formats::png::{SheetScale, write_contact_sheet};
use crate::physics::Setup;
use crate::stack::{Stack, StackError};

/// Time zero of the instrument: the micro time at which the pulse reaches
/// the object.
#[derive(Debug, Clone, PartialEq)]
pub enum TimeZero {
    /// At this micro time, ps.
    At(f64),
    /// The centre of the most populated micro-time step of a reference
    /// recording (a tag file) taken without the medium.
    FromReference(PathBuf),
}

/// Everything one acquisition needs.
#[derive(Debug, Clone)]
pub struct Job {
    /// The device, with what it needs beyond its address.
    pub device: DeviceSpec,
    /// The sample's physics on the whole sensor, when known: it goes into
    /// the stack's metadata and drives a mock (which needs it).
    pub setup: Option<Setup>,
    /// Time zero.
    pub t0: TimeZero,
    /// The window, the pixels, the duration and the recordings (its `t0_ps`
    /// is set from [`Self::t0`]).
    pub plan: StreamPlan,
    /// Output directory (created if missing).
    pub out: PathBuf,
    /// Also write the stack as OME-TIFF (`stack.ome.tif`).
    pub ome_tiff: bool,
}

/// A finished acquisition and what was written.
#[derive(Debug)]
pub struct Acquisition {
    /// What was planned (the window, time zero, the region).
    pub plan: StreamPlan,
    /// What happened (counts, ledger, why it ended).
    pub outcome: Outcome,
    /// What the source added (a mock's truth).
    pub report: SourceReport,
    /// The stack written, with its metadata.
    pub stack: Stack,
    /// What was assumed or derived on the way (time zero from a reference,
    /// the mock's light budget), one line each.
    pub notes: Vec<String>,
    /// The files written.
    pub files: Vec<PathBuf>,
}

/// Why an acquisition job failed.
#[derive(Debug, thiserror::Error)]
pub enum JobError {
    /// The device could not be opened.
    #[error("opening {device}: {source}")]
    Open {
        /// The device.
        device: String,
        /// Why.
        source: OpenError,
    },
    /// The acquisition itself failed.
    #[error("acquiring from {device}: {source}")]
    Acquire {
        /// The device.
        device: String,
        /// Why.
        source: AcquireError,
    },
    /// An output could not be written.
    #[error(transparent)]
    Output(#[from] StackError),
    /// The files named cannot be used as named (checked before the run).
    #[error(transparent)]
    Files(#[from] PlanError),
    /// The output directory could not be made, or a record not written.
    #[error("{path}: {source}")]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
}

impl Job {
    /// Runs the acquisition until its duration, the device's own stop or
    /// `stop` (e.g. Ctrl-C), showing `progress` as it goes, and writes the
    /// outputs into `self.out`. A disconnect mid-run still writes what was
    /// received; [`Acquisition::verdict`] says whether the run is complete.
    pub fn run(
        &self,
        stop: &AtomicBool,
        progress: impl FnMut(&Progress),
    ) -> Result<Acquisition, JobError> {
        self.run_watched(stop, progress, &mut |_| {})
    }

    /// [`Self::run`] with a watching stage (a live view): see
    /// [`super::pipeline::run_watched`].
    pub fn run_watched(
        &self,
        stop: &AtomicBool,
        progress: impl FnMut(&Progress),
        watch: &mut dyn FnMut(&Snapshot<'_>),
    ) -> Result<Acquisition, JobError> {
        let io = |path: &Path| {
            let path = path.to_path_buf();
            move |source| JobError::Io { path, source }
        };
        let device = self.device.to_string();
        self.files().check()?;
        let mut notes = Vec::new();
        let mut plan = self.plan.clone();
        plan.t0_ps = match &self.t0 {
            TimeZero::At(t) => *t,
            TimeZero::FromReference(reference) => {
                let t0 = t0_from_reference(reference).map_err(|source| JobError::Acquire {
                    device: device.clone(),
                    source,
                })?;
                notes.push(format!(
                    "t0 = {t0:.3} ps from reference {}",
                    reference.display()
                ));
                t0
            }
        };
        let opened =
            open_device(&self.device, self.setup.as_ref()).map_err(|source| JobError::Open {
                device: device.clone(),
                source,
            })?;
        let truth = opened.truth;
        let mut source = opened.source;
        let outcome =
            run_watched(source.as_mut(), &plan, stop, progress, watch).map_err(|source| {
                JobError::Acquire {
                    device: device.clone(),
                    source,
                }
            })?;
        let report = source.report(&outcome.ledger, outcome.region, &outcome.end.stop);
        drop(source);
        // Nothing is written before the run has run: a refused run leaves
        // no file behind.
        std::fs::create_dir_all(&self.out).map_err(io(&self.out))?;
        let mut files = Vec::new();
        if let Some(truth) = &truth {
            let exr = self.out.join(TRUTH_EXR);
            crate::formats::exr::write_image(truth.mapv(|v| v as f32).view(), &exr)?;
            let png = self.out.join(TRUTH_PNG);
            crate::formats::png::write_png(truth.view(), Some(1.0), &png)?;
            files.extend([exr, png]);
        }
        let mut setup = self.setup.clone();
        if let (Some(budget), Some(s)) = (report.light_budget, setup.as_mut()) {
            s.total_photons = budget;
            notes.push(format!(
                "light budget {budget:.4e} photons (mock: scaled so the object comes out in the scene's units)"
            ));
        }
        let mut stack = outcome.stack(
            &plan,
            setup.as_ref(),
            format!("{} acquire --device {device}", plan.software),
        );
        stack.meta.seed = report.seed;
        // OpenEXR's library opens no file of more channels than this: a
        // longer stack goes out as .npy (with its sidecar), said so.
        let stack_path = if stack.bins() > crate::formats::exr::MAX_CHANNELS {
            let npy = self.out.join(STACK_EXR).with_extension("npy");
            notes.push(format!(
                "the stack's {} bins are more than an OpenEXR file opens ({}): written as {} with its JSON sidecar instead of {STACK_EXR}",
                stack.bins(),
                crate::formats::exr::MAX_CHANNELS,
                npy.display()
            ));
            npy
        } else {
            self.out.join(STACK_EXR)
        };
        stack.save(&stack_path)?;
        files.push(stack_path);
        if self.ome_tiff {
            let tif = self.out.join(STACK_OME_TIFF);
            stack.save(&tif)?;
            files.push(tif);
        }
        let sheet = self.out.join(STACK_PNG);
        write_contact_sheet(&stack, SheetScale::Shared, &sheet)?;
        files.push(sheet);
        let json_path = self.out.join(RECORD_JSON);
        let json = serde_json::to_string_pretty(&outcome.record(&plan)).expect("record serialises");
        crate::files::write_atomic(&json_path, json + "\n").map_err(io(&json_path))?;
        files.push(json_path);
        files.extend(outcome.ledger.recordings.iter().map(|r| r.path.clone()));
        Ok(Acquisition {
            plan,
            outcome,
            report,
            stack,
            notes,
            files,
        })
    }

    /// Every file the job reads and writes, checked together before the
    /// device is opened ([`FilePlan::check`]): the recordings, the stack,
    /// its sheet, the record and a mock's truth in [`Self::out`], against
    /// each other and against the recording replayed, the reference for
    /// time zero, a mock's scene image and the vendor's library.
    pub fn files(&self) -> FilePlan {
        let mut files = FilePlan::new();
        match &self.device {
            DeviceSpec::Replay(r) => {
                files.input("recording replayed", &r.path);
            }
            DeviceSpec::PicoQuant(d) => {
                if let Some(lib) = &d.library {
                    files.input("vendor library", lib);
                }
            }
            DeviceSpec::Mock(m) | DeviceSpec::MockSerial(m) => {
                if let Some(path) = m.scene_file() {
                    files.input("scene image", path);
                }
            }
            DeviceSpec::Serial(_) | DeviceSpec::Usb(_) => {}
        }
        if let TimeZero::FromReference(reference) = &self.t0 {
            files.input("reference recording", reference);
        }
        if let Some(ptu) = &self.plan.ptu {
            files.output(PTU_ROLE, ptu);
        }
        if let Some(tags) = &self.plan.tag_file {
            files.output(TAGS_ROLE, tags);
        }
        files
            .folder(&self.out)
            .output("stack", &self.out.join(STACK_EXR))
            .output("stack's contact sheet", &self.out.join(STACK_PNG))
            .output("acquisition record", &self.out.join(RECORD_JSON));
        if self.ome_tiff {
            files.output("stack as OME-TIFF", &self.out.join(STACK_OME_TIFF));
        }
        if self.device.is_mock() {
            files
                .output("truth image", &self.out.join(TRUTH_EXR))
                .output("truth image", &self.out.join(TRUTH_PNG));
        }
        files
    }
}

/// What [`Job::files`] calls the PTU recording (a [`PlanError`] names it).
pub const PTU_ROLE: &str = "PTU recording";
/// What [`Job::files`] calls the tag file.
pub const TAGS_ROLE: &str = "tag file";

/// The stack an acquisition writes in its output folder.
pub const STACK_EXR: &str = "stack.exr";
/// The stack as OME-TIFF, when asked for.
pub const STACK_OME_TIFF: &str = "stack.ome.tif";
/// The stack's contact sheet.
pub const STACK_PNG: &str = "stack.png";
/// The record of the acquisition.
pub const RECORD_JSON: &str = "acquisition.json";
/// A mock's scene, as an image.
pub const TRUTH_EXR: &str = "truth.exr";
/// A mock's scene, as a picture.
pub const TRUTH_PNG: &str = "truth.png";

impl Acquisition {
    /// The summary a lab reads: the device, its rates and window, why it
    /// ended, where every photon went, the recordings, what the source
    /// knows (a mock's truth), empty bins.
    pub fn summary(&self) -> Vec<String> {
        let (o, p) = (&self.outcome, &self.plan);
        let f = &o.facts;
        let d = &f.device;
        let l = &o.ledger;
        let secs = o.end.elapsed.as_secs_f64().max(1e-9);
        let mut lines = vec![format!(
            "{} ({} {}, {}{}): {:.0} ps micro-time unit, sync {:.3} MHz; {} bins of {} ps from {} ps after t0 = {} ps",
            d.link,
            d.model,
            d.serial,
            d.version,
            d.library
                .as_ref()
                .map_or(String::new(), |lib| format!(", library {lib}")),
            f.resolution_ps,
            1e6 / f.sync_period_ps,
            o.counts.shape()[0],
            o.window_ps.1,
            o.window_ps.0 - p.t0_ps,
            p.t0_ps
        )];
        if let Some(r) = &f.rates_at_start {
            lines.push(format!(
                "count rates at the start: {}",
                r.inputs
                    .iter()
                    .enumerate()
                    .map(|(i, c)| format!("input {i} {c:.0}/s"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
        }
        lines.extend(o.warnings().iter().map(|w| format!("warning: {w}")));
        lines.push(format!(
            "ended: {} after {secs:.2} s ({} photons, {:.2} Mcps; {:.1} M records/s)",
            o.end.stop.describe(),
            l.counts.photons,
            l.counts.photons as f64 / secs / 1e6,
            o.records_per_s() / 1e6
        ));
        lines.extend(l.table());
        for r in &l.recordings {
            lines.push(match &r.error {
                None => format!("{}: {} ({} records)", r.format, r.path.display(), r.records),
                Some(e) => format!(
                    "{} INCOMPLETE: {} holds the first {} records: {e}",
                    r.format,
                    r.path.display(),
                    r.records
                ),
            });
        }
        lines.extend(self.report.notes.iter().map(|n| format!("  {n}")));
        let empty: Vec<usize> = (0..self.stack.bins())
            .filter(|&k| self.stack.bin(k).iter().all(|&v| v == 0.0))
            .collect();
        if !empty.is_empty() {
            lines.push(format!(
                "  {} of {} bins are empty (bins {})",
                empty.len(),
                self.stack.bins(),
                index_ranges(&empty, 8)
            ));
        }
        lines
    }

    /// Whether the run is complete: an error when the device disconnected,
    /// failed, overran or never confirmed Stop, when a recording is not
    /// whole, when the device dropped counts or when the ledger does not
    /// balance (what was received is written all the same).
    pub fn verdict(&self) -> Result<(), String> {
        let l = &self.outcome.ledger;
        match &self.outcome.end.stop {
            StopReason::Disconnected(e) => {
                return Err(format!(
                    "the device disconnected ({e}); the {} photons received before are in the outputs",
                    l.counts.photons
                ));
            }
            StopReason::NoStopAnswer => {
                return Err("the device did not confirm Stop; its totals are unknown".into());
            }
            StopReason::FifoOverrun => return Err(self.outcome.end.stop.describe()),
            StopReason::DeviceError(e) => {
                return Err(format!(
                    "the device failed mid-run ({e}); what was read is saved"
                ));
            }
            _ => {}
        }
        if let Some(r) = l.recordings.iter().find(|r| r.error.is_some()) {
            return Err(format!(
                "the {} file {} is incomplete: {}",
                r.format,
                r.path.display(),
                r.error.as_deref().unwrap_or_default()
            ));
        }
        if l.counts.photons == 0 {
            let transit = l.transit.map_or(String::new(), |t| {
                format!(
                    " ({} frames failed their checks, {} batches were lost)",
                    t.crc_errors, t.batches_lost
                )
            });
            return Err(format!(
                "no photon was received from the device{transit}; the outputs hold an empty stack"
            ));
        }
        if !l.balances() {
            return Err(format!(
                "photon accounting does not balance:\n{}",
                l.table().join("\n")
            ));
        }
        if l.counts_dropped {
            return Err(
                "the device dropped counts (its flags say so; how many it does not say): the stack and recordings hold what it sent".into(),
            );
        }
        Ok(())
    }
}

/// Sorted indices as ranges (`0-1999, 2010, 2020-2499`), at most `most`
/// of them, then how many more: a line whatever the count.
pub fn index_ranges(sorted: &[usize], most: usize) -> String {
    let mut runs: Vec<(usize, usize)> = Vec::new();
    for &i in sorted {
        match runs.last_mut() {
            Some((_, end)) if *end + 1 == i => *end = i,
            _ => runs.push((i, i)),
        }
    }
    let mut words: Vec<String> = runs
        .iter()
        .take(most)
        .map(|&(a, b)| {
            if a == b {
                a.to_string()
            } else {
                format!("{a}-{b}")
            }
        })
        .collect();
    if runs.len() > most {
        words.push(format!("and {} more runs", runs.len() - most));
    }
    words.join(", ")
}

#[cfg(test)]
mod tests {
    use super::index_ranges;

    #[test]
    fn indices_read_as_ranges_in_a_short_line() {
        let mut v: Vec<usize> = (0..2000).collect();
        v.extend([2010, 2011, 2020]);
        v.extend(2030..2500);
        assert_eq!(index_ranges(&v, 8), "0-1999, 2010-2011, 2020, 2030-2499");
        let every_other: Vec<usize> = (0..2500).step_by(2).collect();
        let text = index_ranges(&every_other, 8);
        assert!(text.ends_with("and 1242 more runs"), "{text}");
        assert!(text.len() < 80, "{text}");
        assert_eq!(index_ranges(&[], 8), "");
    }
}
