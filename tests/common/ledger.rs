//! The photon ledger of a mock acquisition, checked against the mock's true
//! counts.

use scatterscope::acquire::Outcome;
use scatterscope_mocks::Truth;

/// Every photon accounted for, each term equal to the mock's truth:
/// detected, lost in the device, lost in transit, received, and the stack's
/// sum equal to the binned photons. `ctx` is printed on failure.
pub fn assert_exact(out: &Outcome, truth: &Truth, ctx: &str) {
    let acc = &out.ledger;
    assert!(acc.balances(), "{ctx}");
    assert_eq!(acc.detected, Some(truth.photons_detected), "{ctx}");
    assert!(acc.transit.unwrap().exact, "{ctx}");
    assert_eq!(acc.counts.lost_in_device, truth.photons_lost_fifo, "{ctx}");
    assert_eq!(acc.lost_in_transit(), truth.photons_damaged, "{ctx}");
    assert_eq!(
        acc.counts.photons,
        truth.photons_sent - truth.photons_damaged,
        "{ctx}"
    );
    assert_eq!(
        out.counts.iter().map(|&c| u64::from(c)).sum::<u64>(),
        acc.counts.binned,
        "{ctx}"
    );
}
