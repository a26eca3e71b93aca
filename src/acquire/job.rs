//! One acquisition as `acquire` runs it, from a [`Job`] a caller fills:
//! time zero, the device (a mock gets its scene rendered and its kernels
//! built), the stream binned into the plan's window, and the outputs
//! written (the stack with its record, `acquisition.json`, a contact sheet,
//! and for a mock the truth image). For a mock the stack's light budget is
//! set from the known scene, so reconstructions come out in its units.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use super::calibration::t0_from_reference;
use super::device::{DeviceSpec, OpenError, open_device};
use super::mock::MockSetup;
use super::session::{AcquireError, Outcome, Plan, Progress, StopReason, acquire};
use crate::formats::png::{SheetScale, write_contact_sheet};
use crate::physics::Setup;
use crate::stack::{Stack, StackError};
use crate::tags::binning::Region;

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

/// What the emulated device images, for `--device mock` (see
/// [`super::mock`]).
#[cfg(feature = "mock")]
#[derive(Debug, Clone)]
pub struct MockJob {
    /// The scene behind the medium.
    pub scene: crate::scene::Scene,
    /// Rates, delay, seed.
    pub emitter: scatterscope_mocks::EmitterOptions,
    /// Pacing, photon quota, faults.
    pub device: scatterscope_mocks::MockOptions,
}

/// Everything one acquisition needs.
#[derive(Debug, Clone)]
pub struct Job {
    /// The device.
    pub device: DeviceSpec,
    /// The sample's physics and the time window (its bins) on the whole
    /// sensor; it goes into the stack's metadata and drives a mock.
    pub setup: Setup,
    /// Time zero.
    pub t0: TimeZero,
    /// Pixels to bin (the whole sensor if `None`).
    pub region: Option<Region>,
    /// Stop after this long (`None`: when the device stops or on request).
    pub duration: Option<Duration>,
    /// Micro-time unit to configure, ps (`None`: the device's TDC step).
    pub resolution_ps: Option<f64>,
    /// Also record every batch losslessly to this tag file.
    pub tag_file: Option<PathBuf>,
    /// The software, for the tag file and the stack's provenance.
    pub software: String,
    /// What a mock images (ignored for hardware).
    #[cfg(feature = "mock")]
    pub mock: MockJob,
    /// Output directory (created if missing).
    pub out: PathBuf,
}

/// A finished acquisition and what was written.
#[derive(Debug)]
pub struct Acquisition {
    /// What was planned (the window, time zero, the region).
    pub plan: Plan,
    /// What happened (counts, accounting, why it ended).
    pub outcome: Outcome,
    /// The stack written, with its metadata.
    pub stack: Stack,
    /// What was assumed or derived on the way (time zero from a reference,
    /// the mock's light budget), one line each.
    pub notes: Vec<String>,
    /// The mock's own counts, for a mock.
    #[cfg(feature = "mock")]
    pub truth: Option<super::mock::Truth>,
    /// The mock's photon quota, for a mock that has one.
    #[cfg(feature = "mock")]
    pub mock_quota: Option<u64>,
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
    /// The sensor exceeds what the wire protocol addresses.
    #[error(
        "the sensor is {width} x {height} pixels; the protocol addresses at most {max} pixels (256 x 256)"
    )]
    SensorTooLarge {
        /// Columns.
        width: usize,
        /// Rows.
        height: usize,
        /// The protocol's limit.
        max: usize,
    },
    /// The physics cannot build the mock's kernels or its scene.
    #[error("the mock's physics or scene: {0}")]
    Mock(String),
    /// More memory than the budget.
    #[error(transparent)]
    Memory(#[from] crate::memory::MemoryError),
    /// An output could not be written.
    #[error(transparent)]
    Output(#[from] StackError),
    /// The output directory could not be made, or a record not written.
    #[error("{path}: {source}")]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
}

/// The most pixels a device of the wire protocol addresses (16-bit pixel
/// numbers).
pub const MAX_SENSOR_PIXELS: usize = firmware_protocol::record::MAX_PIXEL as usize + 1;

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
        let io = |path: &Path| {
            let path = path.to_path_buf();
            move |source| JobError::Io { path, source }
        };
        let (h, w) = (self.setup.sensor.height_px, self.setup.sensor.width_px);
        if h * w > MAX_SENSOR_PIXELS {
            return Err(JobError::SensorTooLarge {
                width: w,
                height: h,
                max: MAX_SENSOR_PIXELS,
            });
        }
        std::fs::create_dir_all(&self.out).map_err(io(&self.out))?;
        let device = self.device.to_string();
        let mut notes = Vec::new();
        let mut files = Vec::new();
        let t0_ps = match &self.t0 {
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
        let plan = Plan {
            t_start_ps: self.setup.bins.start_ps,
            bin_width_ps: self.setup.bins.width_ps,
            bins: self.setup.bins.count,
            t0_ps,
            region: self.region,
            duration: self.duration,
            resolution_fs: self.resolution_ps.map(|ps| (ps * 1000.0).round() as u32),
            tag_file: self.tag_file.clone(),
            software: self.software.clone(),
        };
        let mock = self.mock_setup(&mut files)?;
        #[cfg(feature = "mock")]
        let reference = mock.as_ref().map(super::mock::MockReference::new);
        let opened = open_device(&self.device, mock).map_err(|source| JobError::Open {
            device: device.clone(),
            source,
        })?;
        let outcome =
            acquire(opened.link, &plan, stop, progress).map_err(|source| JobError::Acquire {
                device: device.clone(),
                source,
            })?;
        #[cfg(feature = "mock")]
        let truth = opened.mock.map(|m| m.truth());
        #[cfg(feature = "mock")]
        let budget = match (&reference, &truth) {
            (Some(reference), Some(t)) => reference.light_budget(
                self.setup.total_photons,
                outcome.region,
                outcome.accounting.binned,
                t,
            ),
            _ => None,
        };
        #[cfg(not(feature = "mock"))]
        let budget: Option<f64> = None;
        let mut stack_setup = self.setup.clone();
        if let Some(budget) = budget {
            stack_setup.total_photons = budget;
            notes.push(format!(
                "light budget {budget:.4e} photons (mock: scaled so the object comes out in the scene's units)"
            ));
        }
        let mut stack = outcome.stack(
            &plan,
            &stack_setup,
            format!("{} acquire --device {device}", self.software),
        );
        stack.meta.seed = self.mock_seed();
        let stack_path = self.out.join("stack.exr");
        stack.save(&stack_path)?;
        files.push(stack_path);
        let sheet = self.out.join("stack.png");
        write_contact_sheet(&stack, SheetScale::Shared, &sheet)?;
        files.push(sheet);
        let json_path = self.out.join("acquisition.json");
        let json = serde_json::to_string_pretty(&outcome.record(&plan)).expect("record serialises");
        crate::files::write_atomic(&json_path, json + "\n").map_err(io(&json_path))?;
        files.push(json_path);
        files.extend(outcome.tag_file.clone());
        Ok(Acquisition {
            plan,
            outcome,
            stack,
            notes,
            #[cfg(feature = "mock")]
            mock_quota: (self.device.is_mock() && self.mock.device.max_photons > 0)
                .then_some(self.mock.device.max_photons),
            #[cfg(feature = "mock")]
            truth,
            files,
        })
    }

    /// The mock's set-up (its truth image written into the output) when
    /// the device is a mock.
    #[cfg(feature = "mock")]
    fn mock_setup(&self, files: &mut Vec<PathBuf>) -> Result<Option<MockSetup>, JobError> {
        use crate::physics::{KernelStack, Sampling};
        if !self.device.is_mock() {
            return Ok(None);
        }
        crate::memory::check_setup(&self.setup, crate::memory::PSF_BYTES, "the mock's kernels")?;
        let (h, w) = (self.setup.sensor.height_px, self.setup.sensor.width_px);
        let truth = self
            .mock
            .scene
            .render(h, w)
            .map_err(|e| JobError::Mock(e.to_string()))?;
        let exr = self.out.join("truth.exr");
        crate::formats::exr::write_image(truth.mapv(|v| v as f32).view(), &exr)?;
        let png = self.out.join("truth.png");
        crate::formats::png::write_png(truth.view(), Some(1.0), &png)?;
        files.extend([exr, png]);
        let kernels = KernelStack::build(&self.setup, Sampling::Integrated)
            .map_err(|e| JobError::Mock(e.to_string()))?;
        Ok(Some(MockSetup {
            scene: truth,
            kernels,
            emitter: self.mock.emitter.clone(),
            device: self.mock.device.clone(),
        }))
    }

    /// No mock in a build without the `mock` feature.
    #[cfg(not(feature = "mock"))]
    fn mock_setup(&self, _: &mut Vec<PathBuf>) -> Result<Option<MockSetup>, JobError> {
        Ok(None)
    }

    /// The mock's seed, recorded in the stack's metadata.
    fn mock_seed(&self) -> Option<u64> {
        #[cfg(feature = "mock")]
        if self.device.is_mock() {
            return Some(self.mock.emitter.seed);
        }
        None
    }
}

impl Acquisition {
    /// The summary a lab reads: device, rate and window, why it ended,
    /// where every photon went, the mock's own counts, empty bins.
    pub fn summary(&self) -> Vec<String> {
        let (o, p) = (&self.outcome, &self.plan);
        let acc = &o.accounting;
        let secs = o.elapsed.as_secs_f64().max(1e-9);
        let mut lines = vec![
            format!(
                "{} ({} {}): {} photons in {:.2} s ({:.2} Mcps), {} bins of {} ps from {} ps after t0 = {} ps",
                o.link,
                o.identity.model,
                o.identity.serial,
                acc.received,
                secs,
                acc.received as f64 / secs / 1e6,
                p.bins,
                p.bin_width_ps,
                p.t_start_ps,
                p.t0_ps
            ),
            format!("  ended: {}", o.stop.describe()),
        ];
        #[cfg(feature = "mock")]
        if let (Some(quota), Some(duration)) = (self.mock_quota, self.plan.duration)
            && o.stop == StopReason::Duration
            && acc.received < quota
        {
            lines.push(format!(
                "  note: the duration ({duration:?}) ended the acquisition before the mock's photon quota ({quota}) was reached; without a duration it runs until the device stops"
            ));
        }
        lines.extend(acc.table().lines().map(str::to_string));
        #[cfg(feature = "mock")]
        if let Some(t) = &self.truth {
            lines.push(format!(
                "  mock truth: detected {} ({} dark, {} afterpulses), lost in FIFO {}, damaged in transit {}, never sent {}",
                t.photons_detected,
                t.dark_counts,
                t.afterpulses,
                t.photons_lost_fifo,
                t.photons_damaged,
                t.photons_unsent
            ));
        }
        let empty: Vec<usize> = (0..self.stack.bins())
            .filter(|&k| self.stack.bin(k).iter().all(|&v| v == 0.0))
            .collect();
        if !empty.is_empty() {
            lines.push(format!(
                "  {} of {} bins are empty (bins {:?})",
                empty.len(),
                self.stack.bins(),
                empty
            ));
        }
        lines
    }

    /// Whether the run is complete: an error when the device disconnected
    /// or never confirmed Stop (what was received is written all the same)
    /// or the photon accounting does not balance.
    pub fn verdict(&self) -> Result<(), String> {
        let acc = &self.outcome.accounting;
        match &self.outcome.stop {
            StopReason::Disconnected(e) => {
                return Err(format!(
                    "the device disconnected ({e}); the {} photons received before are in the outputs",
                    acc.received
                ));
            }
            StopReason::NoStopAnswer => {
                return Err("the device did not confirm Stop; its totals are unknown".into());
            }
            _ => {}
        }
        if acc.received == 0 {
            return Err(format!(
                "nothing was received from the device ({} frames failed their CRC, {} batches were lost); the outputs hold an empty stack",
                acc.crc_errors, acc.batches_lost
            ));
        }
        if !acc.balances() {
            return Err(format!(
                "photon accounting does not balance:\n{}",
                acc.table()
            ));
        }
        Ok(())
    }
}
