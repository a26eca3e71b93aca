//! Confocal scans of hidden objects behind a scattering slab.
//!
//! A pulsed laser and a single-photon detector look at the same point of
//! the slab's near face; galvo mirrors move that point over a grid. Light
//! diffuses through the slab, crosses free space to a hidden object, comes
//! back and diffuses through the slab again; each scan point records a time
//! histogram. The data flow: a [`scan::ConfocalScan`] (counts per scan point
//! and bin) is reconstructed into a [`volume::HiddenVolume`] (x, y, depth
//! behind the slab), which is read as projections and a depth map.
//!
//! Units: the scan's and the volume's lengths are metres, as the published
//! scans state them; the slab's optics ([`SlabOptics`]) are in the physics
//! crate's cm and 1/cm, so nothing converts between this module and the
//! physics crate, and the scan's metres become cm
//! ([`crate::units::CM_PER_M`]) only where the slab kernel is sampled.
//!
//! - [`scan`]: the measurement and its checks (MATLAB files, project stacks).
//! - [`slab_kernel`]: the slab's diffusion kernel for light going in and out.
//! - [`fft3`]: three-dimensional FFTs.
//! - [`light_cone`]: confocal free-space propagation as a linear operator
//!   (light-cone transform) with its adjoint.
//! - [`stolt`]: f-k (Stolt) migration of confocal free-space propagation.
//! - [`forward`]: the forward model in counts (slab kernel, light cone,
//!   background).
//! - [`poisson`]: the Poisson reconstruction, stopped by cross-validation.
//! - [`published`]: the published reconstruction (Lindell and Wetzstein,
//!   Nature Communications 11, 4517 (2020)): Wiener deconvolution of the
//!   slab kernel, then f-k migration.
//! - [`auto`]: the default: the published method smoothed by a width its
//!   own thinned halves choose.
//! - [`volume`]: the reconstructed volume, its projections and depth map.

pub mod auto;
pub mod fft3;
pub mod forward;
pub mod light_cone;
pub mod poisson;
pub mod published;
pub mod scan;
pub mod slab_kernel;
pub mod stolt;
pub mod volume;

pub use auto::{AutoChoice, reconstruct_auto};
pub use poisson::{PoissonOptions, reconstruct_poisson};
pub use published::{LIGHT_SPEED, PublishedOptions, reconstruct_published};
pub use scan::ConfocalScan;
pub use slab_kernel::SlabOptics;
pub use volume::HiddenVolume;

/// How a hidden volume is reconstructed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HiddenMethod {
    /// [`auto::AutoBlur`].
    Auto,
    /// [`published::Published`].
    Published,
    /// [`poisson::PoissonEm`].
    Poisson,
}

crate::named::named!(HiddenMethod {
    Auto => "auto",
    Published => "published",
    Poisson => "poisson",
});

impl HiddenMethod {
    /// The method with its settings, behind the one interface.
    pub fn reconstructor(
        self,
        published: &PublishedOptions,
        poisson: &PoissonOptions,
    ) -> Box<dyn VolumeReconstructor> {
        match self {
            HiddenMethod::Auto => Box::new(auto::AutoBlur(*published)),
            HiddenMethod::Published => Box::new(published::Published(*published)),
            HiddenMethod::Poisson => Box::new(poisson::PoissonEm(*poisson)),
        }
    }
}

/// A hidden-volume method: the confocal counterpart of the 2-D methods'
/// [`crate::reconstruct::Reconstructor`], one interface for the command,
/// the benchmark and code.
pub trait VolumeReconstructor {
    /// Reconstructs the volume behind a slab of `optics` from `scan`.
    fn reconstruct(
        &self,
        scan: &ConfocalScan,
        optics: &SlabOptics,
    ) -> Result<HiddenResult, ConfocalError>;
}

/// A reconstructed volume and what its method reports beside it.
#[derive(Debug, Clone)]
pub struct HiddenResult {
    /// The volume.
    pub volume: HiddenVolume,
    /// The Poisson method's search, one row per iteration.
    pub trace: Option<Vec<poisson::PoissonTraceRow>>,
    /// The default's choice of blur (none where the counts cannot be
    /// thinned).
    pub choice: Option<AutoChoice>,
}

impl HiddenResult {
    /// A volume with nothing reported beside it.
    pub fn volume(volume: HiddenVolume) -> Self {
        Self {
            volume,
            trace: None,
            choice: None,
        }
    }
}

/// What makes a reconstruction of `scan` to `depth_m` (m behind the slab)
/// doubtful, in words naming the file, the setting and the value: a scan
/// shorter than the depth asked (the rest is zeros, and depth reads
/// shallower), or a volume with nothing in it (a slab or medium that lets
/// no light through).
pub fn hidden_warnings(scan: &ConfocalScan, volume: &HiddenVolume, depth_m: f64) -> Vec<String> {
    let mut w = Vec::new();
    let wanted = published::crop_bins(depth_m, scan.bin_width_ps);
    let held = (0..wanted)
        .take_while(|&k| scan.bin_after_zero(k).is_some())
        .count();
    if held < wanted {
        let reach_m = held as f64 * scan.bin_width_ps * 1e-12 * LIGHT_SPEED / 2.0;
        w.push(format!(
            "{}: the scan holds {held} bins after time zero, {reach_m:.3} m of depth, but the depth asked is {depth_m} m ({wanted} bins): the missing {} bins are taken as zero counts, which pulls depths shallower",
            scan.source,
            wanted - held
        ));
    }
    let peak = volume.data.iter().fold(0.0f64, |m, &v| m.max(v));
    // `max` passes over NaN, so `peak` is finite or zero.
    if peak <= 0.0 || volume.data.iter().any(|v| !v.is_finite()) {
        w.push(format!(
            "{}: the reconstructed volume is {}: the slab's model lets no light through at these settings, or the scan holds none",
            scan.source,
            if peak > 0.0 { "not finite everywhere" } else { "all zero" }
        ));
    }
    w
}

/// Why a confocal scan cannot be read or reconstructed.
#[derive(Debug, thiserror::Error)]
pub enum ConfocalError {
    /// The scan, a file or a setting is not usable; the message names it.
    #[error("{source_name}: {message}")]
    Input {
        /// The file or setting at fault.
        source_name: String,
        /// What is wrong, with the value.
        message: String,
    },
    /// A setting's value is not usable; `name` is the library's name for it
    /// (the command line's hints name its flag).
    #[error("{message}")]
    Setting {
        /// The setting (a field name, e.g. `snr`, `side_m`).
        name: &'static str,
        /// What is wrong, with the value.
        message: String,
    },
    /// The work does not fit the memory budget.
    #[error(transparent)]
    Memory(#[from] crate::memory::MemoryError),
}

impl ConfocalError {
    /// An error about the setting `name`.
    pub fn setting(name: &'static str, message: impl Into<String>) -> Self {
        Self::Setting {
            name,
            message: message.into(),
        }
    }

    /// An input error about `source_name`.
    pub fn input(source_name: impl Into<String>, message: impl Into<String>) -> Self {
        Self::Input {
            source_name: source_name.into(),
            message: message.into(),
        }
    }
}
