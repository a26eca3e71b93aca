//! The flags that change what a library error names: the library speaks of
//! its settings, the command line of its flags. One table, consulted once
//! in `main` for every command's error.

use scatterscope::acquire::JobError;
use scatterscope::calibrate::histogram::HistogramError;
use scatterscope::config::ConfigError;
use scatterscope::reconstruct::ReconstructError;
use scatterscope::reconstruct::problem::ProblemError;
use scatterscope::simulate::SimulateError;

/// The hints for the errors in `err`'s chain, one line each.
pub fn flag_hints(err: &anyhow::Error) -> Vec<String> {
    let mut hints: Vec<String> = Vec::new();
    for cause in err.chain() {
        let hint = if let Some(ConfigError::Param { key, .. }) = cause.downcast_ref::<ConfigError>()
        {
            Some(format!(
                "set it with --{} or `{key}` in a --config file",
                key.replace('_', "-")
            ))
        } else if let Some(e) = cause.downcast_ref::<ProblemError>() {
            match e {
                ProblemError::SensorSize { .. } => Some("set the sensor size with --size".into()),
                ProblemError::BinWidth { .. } => Some("set the bin width with --bin-width".into()),
                _ => None,
            }
        } else if let Some(ReconstructError::NotWholeCounts { .. }) =
            cause.downcast_ref::<ReconstructError>()
        {
            Some("--rl-stop fixed stops Richardson-Lucy after a fixed count".into())
        } else if let Some(HistogramError::BinWidthUnknown { .. }) =
            cause.downcast_ref::<HistogramError>()
        {
            Some(
                "give the bin width: --bin-ps (calibrate-slab), --irf-bin-ps (with --irf-from)"
                    .into(),
            )
        } else if let Some(SimulateError::NoBins { .. }) = cause.downcast_ref::<SimulateError>() {
            Some("lower --min-bin-photons or raise --photons".into())
        } else if let Some(JobError::SensorTooLarge { .. }) = cause.downcast_ref::<JobError>() {
            Some("a smaller --size".into())
        } else {
            None
        };
        if let Some(h) = hint.filter(|h| !hints.contains(h)) {
            hints.push(h);
        }
    }
    hints
}
