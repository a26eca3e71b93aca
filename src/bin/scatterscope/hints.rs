//! The flags that change what a library error names: the library speaks of
//! its settings, the command line of its flags. A setting an error names
//! is found among the command's flags by its id (the library's settings
//! types are the flags, their fields the ids); the other errors are in one
//! table. Consulted once in `main` for every command's error.

use std::error::Error;

use scatterscope::acquire::JobError;
use scatterscope::acquire::job::{PTU_ROLE, TAGS_ROLE};
use scatterscope::acquire::open_error::OpenError;
use scatterscope::acquire::pipeline::AcquireError;
use scatterscope::acquire::source::SourceError;
use scatterscope::calibrate::histogram::HistogramError;
use scatterscope::config::ConfigError;
use scatterscope::confocal::ConfocalError;
use scatterscope::denoise::ffdnet::source::ImportError;
use scatterscope::denoise::prior::PriorError;
use scatterscope::files::PlanError;
use scatterscope::formats::picoquant::{FileError, TtrError};
use scatterscope::live::server::LiveError;
use scatterscope::memory::LIMIT_ENV;
use scatterscope::poisson::thinning::CountError;
use scatterscope::psf::PsfError;
use scatterscope::reconstruct::ReconstructError;
use scatterscope::reconstruct::input::InputError;
use scatterscope::reconstruct::problem::ProblemError;
use scatterscope::report::calibration::StackCalibrationError;
use scatterscope::report::hidden::HiddenError;
use scatterscope::simulate::SimulateError;
use scatterscope::tags::bin_file::RecordedFileError;
use scatterscope_drivers::picoquant::VendorError;

/// The hints for the errors in `err`'s chain, one line each, with the
/// flags of `command` (the command that failed).
pub fn flag_hints(err: &anyhow::Error, command: &clap::Command) -> Vec<String> {
    let mut hints: Vec<String> = Vec::new();
    for cause in err.chain() {
        if let Some(h) = hint(cause, command).filter(|h| !hints.contains(h)) {
            hints.push(h);
        }
    }
    hints
}

/// The flag of `command` that sets the library's setting `name`.
fn flag_of(command: &clap::Command, name: &str) -> Option<String> {
    // Settings whose errors name them otherwise than their fields.
    let id = match name {
        "tag_file" => "tags",
        "t3_offset_ns" => "t3_offset_ps",
        other => other,
    };
    let arg = command.get_arguments().find(|a| a.get_id() == id)?;
    Some(format!("set it with --{}", arg.get_long()?))
}

/// The setting a library error names, when it names one.
fn setting(cause: &(dyn Error + 'static)) -> Option<&'static str> {
    if let Some(ReconstructError::Setting { name, .. }) = cause.downcast_ref::<ReconstructError>() {
        return Some(name);
    }
    if let Some(ConfocalError::Setting { name, .. }) = cause.downcast_ref::<ConfocalError>() {
        return Some(name);
    }
    if let Some(AcquireError::Setting { name, .. }) = cause.downcast_ref::<AcquireError>() {
        return Some(name);
    }
    match cause.downcast_ref::<SourceError>() {
        Some(SourceError::Setting { name, .. }) => Some(name),
        _ => None,
    }
}

/// The hint for one error; errors that only wrap another (and display it
/// as their own) are looked through.
fn hint(cause: &(dyn Error + 'static), command: &clap::Command) -> Option<String> {
    let hint = |e: &(dyn Error + 'static)| hint(e, command);
    match setting(cause) {
        // Our own devices' unit and a PicoQuant device's are two flags.
        Some("resolution_fs") => {
            return Some(
                "--micro-time-unit sets our own devices' micro-time unit; --binning a PicoQuant device's"
                    .into(),
            );
        }
        Some(name) => return flag_of(command, name),
        None => {}
    }
    if let Some(e) = cause.downcast_ref::<InputError>() {
        return match e {
            InputError::Config(e) => hint(e),
            InputError::Match { source, .. } | InputError::Background { source, .. } => {
                hint(source)
            }
            _ => None,
        };
    }
    if let Some(RecordedFileError::File(e)) = cause.downcast_ref::<RecordedFileError>() {
        return hint(e);
    }
    if let Some(StackCalibrationError::Config(e)) = cause.downcast_ref::<StackCalibrationError>() {
        return hint(e);
    }
    if let Some(HiddenError::Confocal(e)) = cause.downcast_ref::<HiddenError>() {
        return hint(e);
    }
    if let Some(e) = cause.downcast_ref::<ConfigError>() {
        return match e {
            ConfigError::Param { key, .. } => Some(format!(
                "set it with --{} or `{key}` in a --config file",
                key.replace('_', "-")
            )),
            _ => None,
        };
    }
    if let Some(e) = cause.downcast_ref::<ProblemError>() {
        return match e {
            ProblemError::SensorSize { .. } => Some("set the sensor size with --size".into()),
            ProblemError::BinWidth { .. } => Some("set the bin width with --bin-width".into()),
            _ => None,
        };
    }
    if let Some(JobError::Files(e)) = cause.downcast_ref::<JobError>() {
        return hint(e);
    }
    if let Some(e) = cause.downcast_ref::<PlanError>() {
        let flag = match e.output_role() {
            PTU_ROLE => "--ptu names the PTU recording",
            TAGS_ROLE => "--tags names the tag file",
            _ => "--out names the output folder",
        };
        return Some(flag.into());
    }
    if let Some(e) = cause.downcast_ref::<AcquireError>() {
        return match e {
            AcquireError::Source(e) => hint(e),
            AcquireError::PtuPixels { .. } => Some(
                "--tags records every pixel losslessly; a PTU file takes a sensor of at most 63 pixels (e.g. --size 7)"
                    .into(),
            ),
            _ => None,
        };
    }
    if let Some(OpenError::Replay(e) | OpenError::Setting(e)) = cause.downcast_ref::<OpenError>() {
        return hint(e);
    }
    // No library of a family, or of any family when none was named (the
    // families' messages joined).
    if let Some(OpenError::Vendor(e)) = cause.downcast_ref::<OpenError>()
        && (matches!(e, VendorError::NotInstalled { .. })
            || e.to_string().contains("library found"))
    {
        return Some("--vendor-lib names the library file".into());
    }
    if cause.downcast_ref::<LiveError>().is_some() {
        return Some("the address is --live's".into());
    }
    if let Some(PriorError::Setting(_)) = cause.downcast_ref::<PriorError>() {
        return Some("--tv-gain is TV's gain; --weights applies to --denoiser ffdnet".into());
    }
    // Many errors carry a memory error as their own text (transparently):
    // the budget's variable in the text marks it.
    if cause.to_string().contains(LIMIT_ENV) {
        return Some("--memory-limit sets the budget".into());
    }
    let text = if let Some(ReconstructError::Counts(CountError::NotWholeCounts { .. })) =
        cause.downcast_ref::<ReconstructError>()
    {
        "--rl-stop fixed stops Richardson-Lucy after a fixed count"
    } else if let Some(HistogramError::BinWidthUnknown { .. }) =
        cause.downcast_ref::<HistogramError>()
    {
        "give the bin width: --bin-width (calibrate-slab), --irf-bin-width (with --irf-from)"
    } else if let Some(FileError {
        error: TtrError::Truncated { .. } | TtrError::Unfinished { .. },
        ..
    }) = cause.downcast_ref::<FileError>()
    {
        "--allow-truncated bins the complete records"
    } else if let Some(SimulateError::NoBins { .. }) = cause.downcast_ref::<SimulateError>() {
        "lower --min-bin-photons or raise --photons"
    } else if let Some(PsfError::NoBins(_)) = cause.downcast_ref::<PsfError>() {
        "lower --min-bin-photons"
    } else if let Some(ImportError::NoDataDir) = cause.downcast_ref::<ImportError>() {
        "pass --out"
    } else if let Some(JobError::Open {
        source: OpenError::SensorTooLarge { .. },
        ..
    }) = cause.downcast_ref::<JobError>()
    {
        "a smaller --size"
    } else {
        return None;
    };
    Some(text.into())
}
