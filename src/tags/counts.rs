//! Where the records and photons of a stream went: one count type from the
//! wire (a batch's records) through the binner to a binned file's summary
//! and the acquisition's ledger, with one word for each count.
//!
//! ```text
//! records = photons + markers + overflows + losses + invalid records
//! photons = binned + outside_window + other_channel + outside_region
//!           + over_budget
//! ```

use serde::{Deserialize, Serialize};

/// The record and photon counts of one stream.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Counts {
    /// Records read (photons, markers, overflows, losses, invalid ones).
    /// Ledgers written before this name read `records_read`.
    #[serde(alias = "records_read")]
    pub records: u64,
    /// Records with an unknown type (skipped).
    #[serde(default)]
    pub invalid_records: u64,
    /// Photons the device reported lost in its records (the ledger takes
    /// the device's own total where it sends one).
    #[serde(default)]
    pub lost_in_device: u64,
    /// Photon records. Binning summaries written before this name read
    /// `received`.
    #[serde(alias = "received")]
    pub photons: u64,
    /// Photons in a stack bin.
    pub binned: u64,
    /// Photons whose micro time falls outside the binned window.
    pub outside_window: u64,
    /// Photons on other inputs than the one selected.
    pub other_channel: u64,
    /// Photons on no pixel of the stack: outside the region binned (sensor
    /// maps), or before the first line, between lines, beyond the last line
    /// or frame (scanned images).
    pub outside_region: u64,
    /// Photons of frames kept apart past the most stacks the memory budget
    /// holds (written only when there are any).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub over_budget: u64,
    /// Marker records.
    pub markers: u64,
    /// Frames seen (scanned images).
    pub frames: u64,
}

fn is_zero(n: &u64) -> bool {
    *n == 0
}

impl std::ops::AddAssign for Counts {
    /// Counts of two parts of one stream, added.
    fn add_assign(&mut self, o: Counts) {
        self.records += o.records;
        self.invalid_records += o.invalid_records;
        self.lost_in_device += o.lost_in_device;
        self.photons += o.photons;
        self.binned += o.binned;
        self.outside_window += o.outside_window;
        self.other_channel += o.other_channel;
        self.outside_region += o.outside_region;
        self.over_budget += o.over_budget;
        self.markers += o.markers;
        self.frames += o.frames;
    }
}

impl Counts {
    /// Whether every photon is in exactly one category.
    pub fn balances(&self) -> bool {
        self.photons
            == self.binned
                + self.outside_window
                + self.other_channel
                + self.outside_region
                + self.over_budget
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn old_names_read_and_the_new_ones_are_written() {
        let old = r#"{"records_read": 9, "photons": 5, "binned": 3, "outside_window": 1,
            "other_channel": 0, "outside_region": 1, "markers": 4, "frames": 0}"#;
        let c: Counts = serde_json::from_str(old).unwrap();
        assert_eq!((c.records, c.photons, c.over_budget), (9, 5, 0));
        assert!(c.balances());
        let binning = r#"{"records": 2, "received": 2, "binned": 1, "outside_window": 0,
            "other_channel": 0, "outside_region": 0, "over_budget": 1, "markers": 0, "frames": 0}"#;
        let c: Counts = serde_json::from_str(binning).unwrap();
        assert_eq!(c.photons, 2);
        assert!(c.balances());
        let written = serde_json::to_value(c).unwrap();
        assert_eq!(written["photons"], 2);
        assert!(written.get("received").is_none() && written.get("records_read").is_none());
        let none_over = serde_json::to_value(Counts::default()).unwrap();
        assert!(none_over.get("over_budget").is_none());
    }

    #[test]
    fn a_photon_in_two_places_does_not_balance() {
        let c = Counts {
            photons: 1,
            binned: 1,
            outside_window: 1,
            ..Counts::default()
        };
        assert!(!c.balances());
    }
}
