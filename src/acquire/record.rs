//! An acquisition outcome -> a stack with its metadata, and the typed
//! record of the acquisition that goes with it (the stack's `acquisition`
//! metadata and `acquisition.json`).

use std::path::PathBuf;

use firmware_protocol::{Config, Identity, Totals};
use serde::{Deserialize, Serialize};

use super::accounting::AcquisitionAccounting;
use super::session::{Outcome, Plan, StopReason};
use crate::physics::{Sampling, Setup};
use crate::stack::{Stack, StackMeta};
use crate::tags::binning::Region;

/// What one acquisition was: the device, its configuration, the window,
/// why it ended and where every photon went.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AcquisitionRecord {
    /// The link the device was on.
    pub link: String,
    /// The device's identity.
    pub identity: Identity,
    /// The configuration the device applied.
    pub config: Config,
    /// Time zero: device micro time of the instrument's zero, ps.
    pub t0_ps: f64,
    /// Start of the first bin in device micro time (t0 + the plan's start), ps.
    pub window_start_device_ps: f64,
    /// The pixels binned.
    pub region: Region,
    /// Why the acquisition ended.
    pub stop: StopReason,
    /// From Start to the last batch, seconds.
    pub elapsed_s: f64,
    /// Where every photon went.
    pub accounting: AcquisitionAccounting,
    /// The device's totals, when it sent them.
    pub device_totals: Option<Totals>,
    /// The tag file written, if any (`raw` in records written before it
    /// was renamed).
    #[serde(alias = "raw")]
    pub tag_file: Option<PathBuf>,
}

impl Outcome {
    /// The record of this acquisition of `plan`.
    pub fn record(&self, plan: &Plan) -> AcquisitionRecord {
        AcquisitionRecord {
            link: self.link.clone(),
            identity: self.identity.clone(),
            config: self.config.clone(),
            t0_ps: plan.t0_ps,
            window_start_device_ps: self.window_ps.0,
            region: self.region,
            stop: self.stop.clone(),
            elapsed_s: self.elapsed.as_secs_f64(),
            accounting: self.accounting,
            device_totals: self.totals,
            tag_file: self.tag_file.clone(),
        }
    }

    /// The counts as a stack: bins from the plan (relative to t0), the
    /// acquisition's record in the metadata, and `setup` (the sample's
    /// physics on the whole sensor) cut to the binned region, so the stack
    /// reconstructs as it is. `source` says how it was made.
    pub fn stack(&self, plan: &Plan, setup: &Setup, source: String) -> Stack {
        let record = serde_json::to_value(self.record(plan)).expect("the record serialises");
        let mut meta = StackMeta::measured(
            plan.t_start_ps,
            plan.bin_width_ps,
            plan.bins,
            source,
            Some(record),
        );
        let setup = cropped(setup, self.region);
        meta.pixel_pitch_cm = setup.sensor.pixel_pitch_cm();
        meta.setup = Some(setup);
        meta.sampling = Some(Sampling::Integrated);
        Stack::from_counts(self.counts.view(), meta)
    }
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
