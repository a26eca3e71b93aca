//! A build without the `mock` feature: the spec exists, no mock opens.

use ndarray::Array2;

use super::super::open_error::OpenError;
use super::super::source::Source;
use crate::physics::Setup;

/// What a mock images: nothing in a build without the `mock` feature.
#[derive(Debug, Clone, Default)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct MockSpec {}

impl MockSpec {
    /// No scene, no file.
    pub fn scene_file(&self) -> Option<&std::path::Path> {
        None
    }
}

/// There is no mock to open in this build.
pub(crate) fn open_spec(
    _: &MockSpec,
    _: bool,
    _: &Setup,
) -> Result<(Box<dyn Source>, Array2<f64>), OpenError> {
    Err(OpenError::Usage(
        "this build has no mock device (it was built without the `mock` feature)".into(),
    ))
}

/// No mock, no scene.
pub(crate) fn scene_truth(_: &MockSpec, _: &Setup) -> Option<Array2<f64>> {
    None
}
