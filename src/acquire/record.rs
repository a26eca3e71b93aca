//! An acquisition outcome -> a stack with its metadata, and the typed
//! record of the acquisition that goes with it (the stack's `acquisition`
//! metadata and `acquisition.json`). One record for every device kind;
//! what does not apply to a device is left out.

use firmware_protocol::{Config, Totals};
use serde::{Deserialize, Serialize};

use super::ledger::Ledger;
use super::pipeline::{Outcome, StreamPlan};
use super::source::{DeviceInfo, RateSample, RecordFormat, StopReason};
use crate::physics::{Sampling, Setup};
use crate::stack::{Stack, StackMeta};
use crate::tags::binning::Region;

/// What one acquisition was: the device, its configuration, the window,
/// why it ended and where every photon went.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AcquisitionRecord {
    /// The device.
    pub device: DeviceInfo,
    /// The configuration our own device applied.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub config: Option<Config>,
    /// Micro-time unit, ps.
    pub resolution_ps: f64,
    /// Sync rate the records' macro time counts, Hz.
    pub sync_rate_hz: f64,
    /// Time zero: device micro time of the instrument's zero, ps.
    pub t0_ps: f64,
    /// Start of the first bin in device micro time (t0 + the plan's start), ps.
    pub window_start_device_ps: f64,
    /// Bin width, ps.
    pub bin_width_ps: f64,
    /// Bins.
    pub bins: usize,
    /// The pixels of a sensor binned.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub region: Option<Region>,
    /// Why the acquisition ended.
    pub stop: StopReason,
    /// From the start to the last record, seconds.
    pub elapsed_s: f64,
    /// Records read per second.
    pub records_per_s: f64,
    /// Where every photon and record went.
    pub ledger: Ledger,
    /// The device's totals, when it sent them.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub device_totals: Option<Totals>,
    /// The rates read before the start, when the device reports them.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub rates_at_start: Option<RateSample>,
    /// The rates read during the run.
    #[serde(skip_serializing_if = "Vec::is_empty", default)]
    pub rates_during_run: Vec<RateSample>,
    /// What the device, its library or its flags warned about.
    #[serde(skip_serializing_if = "Vec::is_empty", default)]
    pub warnings: Vec<String>,
}

impl Outcome {
    /// The record of this acquisition of `plan`.
    pub fn record(&self, plan: &StreamPlan) -> AcquisitionRecord {
        let f = &self.facts;
        AcquisitionRecord {
            device: f.device.clone(),
            config: match &f.format {
                RecordFormat::Wire { config, .. } => Some(config.clone()),
                RecordFormat::T3(_) => None,
            },
            resolution_ps: f.resolution_ps,
            sync_rate_hz: 1e12 / f.sync_period_ps,
            t0_ps: plan.t0_ps,
            window_start_device_ps: self.window_ps.0,
            bin_width_ps: self.window_ps.1,
            bins: self.counts.shape()[0],
            region: self.region,
            stop: self.end.stop.clone(),
            elapsed_s: self.end.elapsed.as_secs_f64(),
            records_per_s: self.records_per_s(),
            ledger: self.ledger.clone(),
            device_totals: self.end.totals,
            rates_at_start: f.rates_at_start.clone(),
            rates_during_run: self.rates_during_run.clone(),
            warnings: self.warnings(),
        }
    }

    /// Every warning of the run: the device's at the start, then its
    /// flags' during it.
    pub fn warnings(&self) -> Vec<String> {
        self.facts
            .warnings
            .iter()
            .chain(&self.end.warnings)
            .cloned()
            .collect()
    }

    /// The counts as a stack: bins relative to t0, the acquisition's record
    /// in the metadata, and `setup` (the sample's physics on the whole
    /// sensor, when known) cut to the binned region, so the stack
    /// reconstructs as it is. `source` says how it was made.
    pub fn stack(&self, plan: &StreamPlan, setup: Option<&Setup>, source: String) -> Stack {
        let record = serde_json::to_value(self.record(plan)).expect("the record serialises");
        stack_of(
            self.counts.view(),
            self.window_ps,
            self.region,
            plan.t0_ps,
            setup,
            source,
            Some(record),
        )
    }
}

/// `counts` binned in the window `window_ps` (device micro time) as a stack
/// with bins relative to `t0_ps`, `setup` cut to `region` when known, and
/// `record` in the metadata: a finished acquisition's stack, or a live
/// view's snapshot.
pub fn stack_of(
    counts: ndarray::ArrayView3<'_, u32>,
    window_ps: (f64, f64),
    region: Option<Region>,
    t0_ps: f64,
    setup: Option<&Setup>,
    source: String,
    record: Option<serde_json::Value>,
) -> Stack {
    let bins = counts.shape()[0];
    let mut meta = StackMeta::measured(window_ps.0 - t0_ps, window_ps.1, bins, source, record);
    if let Some(setup) = setup {
        let mut setup = match region {
            Some(region) => cropped(setup, region),
            None => setup.clone(),
        };
        setup.bins.start_ps = window_ps.0 - t0_ps;
        setup.bins.width_ps = window_ps.1;
        setup.bins.count = bins;
        meta.set_pixel_pitch(setup.sensor.pixel_pitch_cm());
        meta.setup = Some(setup);
        meta.sampling = Some(Sampling::Integrated);
    }
    Stack::from_counts(counts, meta)
}

/// The same physics on `region` of `setup`'s sensor: the region's pixels at
/// the same pitch.
fn cropped(setup: &Setup, region: Region) -> Setup {
    let mut s = setup.clone();
    s.sensor.fov_cm = setup.sensor.fov_cm * region.width as f64 / setup.sensor.width_px as f64;
    s.sensor.width_px = region.width;
    s.sensor.height_px = region.height;
    s
}
