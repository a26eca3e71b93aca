//! Where every photon of an acquisition went.
//!
//! ```text
//! detected by the device = received + lost in transit + lost in the device
//! received               = binned + outside the time window + outside the region
//! ```
//!
//! The first line needs the device's totals (sent with its Stopped answer);
//! without them (a disconnect) the transit loss is a lower bound.

use serde::{Deserialize, Serialize};

/// The photon and batch counts of one acquisition.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct AcquisitionAccounting {
    /// Photons the device detected (sent + dropped), from its totals.
    pub detected: Option<u64>,
    /// Photon records that reached the host in valid batches.
    pub received: u64,
    /// Photons in a stack bin.
    pub binned: u64,
    /// Photons whose arrival time is outside the binned window.
    pub outside_window: u64,
    /// Photons on pixels outside the region of interest.
    pub outside_region: u64,
    /// Photons the device dropped (FIFO overflow).
    pub lost_in_device: u64,
    /// Photons in batches that never arrived or arrived damaged.
    pub lost_in_transit: u64,
    /// Whether `lost_in_transit` is exact (else a lower bound).
    pub transit_exact: bool,
    /// Valid batches received.
    pub batches_received: u64,
    /// Batches lost or damaged in transit.
    pub batches_lost: u64,
    /// Repeated batches discarded.
    pub batches_duplicate: u64,
    /// Batches that arrived late (kept).
    pub batches_out_of_order: u64,
    /// Bytes discarded while resynchronising.
    pub bytes_skipped: u64,
    /// Frames rejected by their checks.
    pub crc_errors: u64,
    /// Records with an unknown type (skipped).
    pub invalid_records: u64,
    /// Marker records.
    pub markers: u64,
}

impl AcquisitionAccounting {
    /// Whether both lines of the balance hold (the first only when the
    /// device's totals are known).
    pub fn balances(&self) -> bool {
        self.received == self.binned + self.outside_window + self.outside_region
            && self
                .detected
                .is_none_or(|d| d == self.received + self.lost_in_transit + self.lost_in_device)
    }

    /// A multi-line table for the terminal.
    pub fn table(&self) -> String {
        let mut s = String::new();
        let mut line = |name: &str, v: String| s.push_str(&format!("  {name:<28} {v:>14}\n"));
        line(
            "detected by the device",
            self.detected.map_or("unknown".into(), |d| d.to_string()),
        );
        line("lost in the device (FIFO)", self.lost_in_device.to_string());
        line(
            "lost in transit",
            format!(
                "{}{}",
                if self.transit_exact { "" } else { ">= " },
                self.lost_in_transit
            ),
        );
        line("received", self.received.to_string());
        line("  binned", self.binned.to_string());
        line("  outside the time window", self.outside_window.to_string());
        line("  outside the region", self.outside_region.to_string());
        line("batches received", self.batches_received.to_string());
        line("batches lost or damaged", self.batches_lost.to_string());
        line(
            "batches duplicated (dropped)",
            self.batches_duplicate.to_string(),
        );
        line(
            "batches out of order",
            self.batches_out_of_order.to_string(),
        );
        line("bytes skipped (resync)", self.bytes_skipped.to_string());
        line("frames failing checks", self.crc_errors.to_string());
        line("invalid records", self.invalid_records.to_string());
        s.push_str(if self.balances() {
            "  balance: every photon accounted for\n"
        } else {
            "  balance: DOES NOT BALANCE (please report)\n"
        });
        s
    }
}
