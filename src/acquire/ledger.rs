//! Where every photon and record of an acquisition went, one ledger for
//! every source.
//!
//! ```text
//! detected by the device = photons received + lost in transit + lost in the device
//! photons received       = binned + outside the time window + on other channels
//!                          + outside the region
//! each recording         = every record read (a PTU, a tag file)
//! ```
//!
//! The first line needs the device's totals (our own devices send them with
//! their Stopped answer; a vendor library reports none); a device that only
//! flags a loss (a FIFO overrun, dropped counts) makes the run incomplete
//! without a count.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::tags::counts::Counts;

/// What the transport between the device and the host lost or repaired
/// (our own devices' links; a vendor library keeps its own).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Transit {
    /// Photons in batches that never arrived or arrived damaged.
    pub lost_photons: u64,
    /// Whether `lost_photons` is exact (else a lower bound: the device's
    /// totals are missing).
    pub exact: bool,
    /// Valid batches received.
    pub batches_received: u64,
    /// Batches lost or damaged.
    pub batches_lost: u64,
    /// Repeated batches discarded.
    pub batches_duplicate: u64,
    /// Batches that arrived late (kept).
    pub batches_out_of_order: u64,
    /// Bytes discarded while resynchronising.
    pub bytes_skipped: u64,
    /// Frames rejected by their checks.
    pub crc_errors: u64,
}

/// A file that recorded what the device sent, as it came.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Recording {
    /// The file.
    pub path: PathBuf,
    /// `ptu` or `sstags`.
    pub format: String,
    /// Records it holds (PTU: as written, overflows included; tag file:
    /// batches).
    pub records: u64,
    /// Whether it holds everything the device sent that was read.
    pub whole: bool,
    /// Why it stopped early or failed, when it did (the stack is saved
    /// either way).
    pub error: Option<String>,
}

/// The photon and record counts of one acquisition.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Ledger {
    /// Photons the device detected, from its totals.
    pub detected: Option<u64>,
    /// Its FIFO overran (how many records it lost it does not say).
    pub fifo_overrun: bool,
    /// It dropped counts before its FIFO (MultiHarp's `FLAG_CNTS_DROPPED`;
    /// how many it does not say).
    pub counts_dropped: bool,
    /// The transport's losses and repairs (a link of our own).
    pub transit: Option<Transit>,
    /// Where the records and photons read went (the device's own loss
    /// total, where it sends one, in `lost_in_device`).
    #[serde(flatten)]
    pub counts: Counts,
    /// The recordings.
    pub recordings: Vec<Recording>,
}

impl Ledger {
    /// Whether the device lost photons it only flagged: then no count says
    /// what it detected.
    pub fn lost_uncounted(&self) -> bool {
        self.fifo_overrun || self.counts_dropped
    }

    /// Photons lost in transit (0 without a link of our own).
    pub fn lost_in_transit(&self) -> u64 {
        self.transit.map_or(0, |t| t.lost_photons)
    }

    /// Whether every line of the balance holds (the first only when the
    /// device's totals are known).
    pub fn balances(&self) -> bool {
        let c = &self.counts;
        c.balances()
            && self
                .detected
                .is_none_or(|d| d == c.photons + self.lost_in_transit() + c.lost_in_device)
            && self.recordings.iter().all(|r| r.whole)
    }

    /// A table for the terminal, one line per count; lines that do not
    /// apply to this source are left out.
    pub fn table(&self) -> Vec<String> {
        let line = |name: &str, v: String| format!("  {name:<30} {v:>14}");
        let c = &self.counts;
        let mut t = Vec::new();
        if let Some(d) = self.detected {
            t.push(line("detected by the device", d.to_string()));
        }
        let flagged = |on: bool| if on { "yes, count unknown" } else { "0" };
        if self.fifo_overrun || c.lost_in_device > 0 || self.detected.is_some() {
            t.push(line(
                "lost in the device (FIFO)",
                if self.fifo_overrun {
                    flagged(true).into()
                } else {
                    c.lost_in_device.to_string()
                },
            ));
        }
        if self.counts_dropped {
            t.push(line("dropped in the device", flagged(true).into()));
        }
        if let Some(tr) = &self.transit {
            t.push(line(
                "lost in transit",
                format!("{}{}", if tr.exact { "" } else { ">= " }, tr.lost_photons),
            ));
        }
        t.push(line("records read", c.records.to_string()));
        t.push(line("  photons", c.photons.to_string()));
        t.push(line("    binned", c.binned.to_string()));
        t.push(line(
            "    outside the time window",
            c.outside_window.to_string(),
        ));
        if c.other_channel > 0 {
            t.push(line("    on other channels", c.other_channel.to_string()));
        }
        t.push(line("    outside the region", c.outside_region.to_string()));
        if c.over_budget > 0 {
            t.push(line(
                "    past the memory budget",
                c.over_budget.to_string(),
            ));
        }
        if c.markers > 0 {
            t.push(line("  markers", c.markers.to_string()));
        }
        if c.frames > 0 {
            t.push(line("  frames", c.frames.to_string()));
        }
        if c.invalid_records > 0 {
            t.push(line("  invalid records", c.invalid_records.to_string()));
        }
        if let Some(tr) = &self.transit {
            t.push(line("batches received", tr.batches_received.to_string()));
            t.push(line("batches lost or damaged", tr.batches_lost.to_string()));
            t.push(line(
                "batches duplicated (dropped)",
                tr.batches_duplicate.to_string(),
            ));
            t.push(line(
                "batches out of order",
                tr.batches_out_of_order.to_string(),
            ));
            t.push(line("bytes skipped (resync)", tr.bytes_skipped.to_string()));
            t.push(line("frames failing checks", tr.crc_errors.to_string()));
        }
        for r in &self.recordings {
            t.push(line(
                &format!("in {} ({})", file_name(r), r.format),
                format!(
                    "{} {}",
                    r.records,
                    if r.format == "sstags" {
                        "batches"
                    } else {
                        "records"
                    }
                ),
            ));
        }
        t.push(match (self.balances(), self.lost_uncounted()) {
            (true, false) => "  balance: every photon accounted for".into(),
            (true, true) => "  balance: every record read is accounted for, but the device lost photons it detected (how many it does not say): this is not the whole measurement".into(),
            (false, _) => "  balance: DOES NOT BALANCE (please report)".into(),
        });
        t
    }
}

fn file_name(r: &Recording) -> String {
    r.path.file_name().map_or_else(
        || r.path.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ledger_balances_only_when_every_photon_and_record_is_placed() {
        let mut l = Ledger {
            detected: Some(12),
            transit: Some(Transit {
                lost_photons: 2,
                exact: true,
                ..Transit::default()
            }),
            counts: Counts {
                records: 10,
                lost_in_device: 2,
                photons: 8,
                binned: 5,
                outside_window: 2,
                other_channel: 1,
                ..Counts::default()
            },
            ..Ledger::default()
        };
        assert!(l.balances());
        l.detected = Some(13);
        assert!(!l.balances(), "a photon the device detected is missing");
        l.detected = None;
        assert!(l.balances());
        l.counts.binned = 4;
        assert!(!l.balances(), "a photon received is in no category");
        l.counts.binned = 5;
        l.recordings.push(Recording {
            path: "a.ptu".into(),
            format: "ptu".into(),
            records: 9,
            whole: false,
            error: Some("disk full".into()),
        });
        assert!(!l.balances(), "a recording misses records");
        assert!(l.table().iter().any(|s| s.contains("DOES NOT BALANCE")));
    }

    #[test]
    fn a_flagged_loss_balances_but_says_the_measurement_is_not_whole() {
        let l = Ledger {
            counts: Counts {
                records: 3,
                photons: 3,
                binned: 3,
                ..Counts::default()
            },
            counts_dropped: true,
            ..Ledger::default()
        };
        assert!(l.balances() && l.lost_uncounted());
        let table = l.table().join("\n");
        assert!(table.contains("dropped in the device") && table.contains("not the whole"));
        assert!(!table.contains("lost in transit"), "{table}");
    }
}
