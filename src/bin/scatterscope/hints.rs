//! The flags that change what a library error names: the library speaks of
//! its settings, the command line of its flags. One table, consulted once
//! in `main` for every command's error.

use scatterscope::calibrate::histogram::HistogramError;
use scatterscope::reconstruct::ReconstructError;
use scatterscope::reconstruct::problem::ProblemError;
use scatterscope::simulate::SimulateError;

/// The hints for the errors in `err`'s chain, one line each.
pub fn flag_hints(err: &anyhow::Error) -> Vec<&'static str> {
    let mut hints = Vec::new();
    for cause in err.chain() {
        let hint = if let Some(e) = cause.downcast_ref::<ProblemError>() {
            match e {
                ProblemError::SensorSize { .. } => Some("set the sensor size with --size"),
                ProblemError::BinWidth { .. } => Some("set the bin width with --bin-width"),
                _ => None,
            }
        } else if let Some(ReconstructError::NotWholeCounts { .. }) =
            cause.downcast_ref::<ReconstructError>()
        {
            Some("--rl-stop fixed stops Richardson-Lucy after a fixed count")
        } else if let Some(HistogramError::BinWidthUnknown { .. }) =
            cause.downcast_ref::<HistogramError>()
        {
            Some("give the bin width: --bin-ps (calibrate-slab), --irf-bin-ps (with --irf-from)")
        } else if let Some(SimulateError::NoBins { .. }) = cause.downcast_ref::<SimulateError>() {
            Some("lower --min-bin-photons or raise --photons")
        } else {
            None
        };
        if let Some(h) = hint.filter(|h| !hints.contains(h)) {
            hints.push(h);
        }
    }
    hints
}
