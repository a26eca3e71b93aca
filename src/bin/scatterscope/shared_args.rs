//! Arguments shared by several commands: the physics flags (which the
//! library takes as [`PhysicsOverrides`]) and named choices.

use clap::builder::{PossibleValuesParser, TypedValueParser};
use scatterscope::Named;
use scatterscope::config::{PhysicsOverrides, parse_cm, parse_ps};
use scatterscope::physics::{MediumModel, Preset, Setup};
use std::path::PathBuf;

/// A clap value parser for a [`Named`] choice: its names are the possible
/// values.
pub fn choice<T: Named + Clone>() -> impl TypedValueParser<Value = T> {
    PossibleValuesParser::new(T::names())
        .map(|name| T::from_name(&name).expect("clap checked the name"))
}

/// Physics flags shared by every command that needs an ST-PSF.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct PhysicsArgs {
    /// Parameter set to start from (`paper`: the paper's skin-like 3 cm slab,
    /// 50 cm field, 256x256, 30 bins of 4 ps, 450 photons).
    #[arg(long, value_name = "NAME", value_parser = scatterscope::config::parse_preset)]
    pub preset: Option<Preset>,
    /// TOML file with any of the keys below (flags override it).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Absorption coefficient mu_a in 1/cm.
    #[arg(long, value_name = "1/CM", allow_negative_numbers = true)]
    pub mu_a: Option<f64>,
    /// Scattering coefficient mu_s in 1/cm.
    #[arg(long, value_name = "1/CM", allow_negative_numbers = true)]
    pub mu_s: Option<f64>,
    /// Scattering anisotropy g in [-1, 1] (0.9-0.99 for tissue).
    #[arg(long, value_name = "G", allow_negative_numbers = true)]
    pub g: Option<f64>,
    /// Refractive index of the medium (light speed is c/n).
    #[arg(long, value_name = "N", allow_negative_numbers = true)]
    pub n: Option<f64>,
    /// Slab thickness z0 between object and sensor (default unit cm; e.g. 30mm).
    #[arg(long, value_name = "LENGTH", value_parser = parse_cm, allow_negative_numbers = true)]
    pub thickness: Option<f64>,
    /// How the slab's faces are modelled: infinite (the paper's Eq. 6, no
    /// faces) or slab (extrapolated boundaries with the refractive-index
    /// mismatch, image sources; transmitted flux).
    #[arg(long, value_name = "MODEL", value_parser = scatterscope::config::parse_medium)]
    pub medium: Option<MediumModel>,
    /// Horizontal field of view (default unit cm).
    #[arg(long, value_name = "LENGTH", value_parser = parse_cm, allow_negative_numbers = true)]
    pub fov: Option<f64>,
    /// Image side in pixels (square images).
    #[arg(long, value_name = "PIXELS")]
    pub size: Option<usize>,
    /// Time-bin width (default unit ps; e.g. 4ps, 0.004ns).
    #[arg(long, value_name = "TIME", value_parser = parse_ps, allow_negative_numbers = true)]
    pub bin_width: Option<f64>,
    /// Start of the first bin after the pulse reaches the object (default unit ps).
    #[arg(long, value_name = "TIME", value_parser = parse_ps, allow_negative_numbers = true)]
    pub t_start: Option<f64>,
    /// Number of time bins.
    #[arg(long, value_name = "COUNT")]
    pub bins: Option<usize>,
    /// Light budget: expected photons in the whole ST-PSF over all bins.
    #[arg(long, value_name = "COUNT", allow_negative_numbers = true)]
    pub photons: Option<f64>,
    /// Drop bins whose ST-PSF carries fewer expected photons (0 keeps all).
    #[arg(long, value_name = "COUNT", allow_negative_numbers = true)]
    pub min_bin_photons: Option<f64>,
    /// Instrument response: FWHM of its Gaussian part (default unit ps;
    /// 0: ideal timing). The kernels are the ST-PSF convolved in time with
    /// it; time zero is the Gaussian's centre.
    #[arg(long, value_name = "TIME", value_parser = parse_ps, allow_negative_numbers = true)]
    pub irf_fwhm: Option<f64>,
    /// Instrument response: time constant of its exponential tail (default
    /// unit ps; 0: none).
    #[arg(long, value_name = "TIME", value_parser = parse_ps, allow_negative_numbers = true)]
    pub irf_tail: Option<f64>,
    /// Instrument response measured in a reference recording without the
    /// medium (.sstags, .ptu, .pt3, .ht3 tag file, an .exr/.npy stack, or
    /// a MATLAB .mat histogram with --irf-bin-ps):
    /// its histogram less the background, as a table (time zero at the
    /// centre of its fullest bin); the kernels are the ST-PSF convolved
    /// with it.
    #[arg(long, value_name = "REF", conflicts_with_all = ["irf_fwhm", "irf_tail"])]
    pub irf_from: Option<PathBuf>,
    /// With --irf-from: fit the Gaussian-plus-exponential form to the
    /// reference (Poisson maximum likelihood; the fit and its chi-square
    /// are printed) and use that instead of the measured table.
    #[arg(long, requires = "irf_from")]
    pub irf_parametric: bool,
    /// Bin width of an --irf-from reference that does not record one (a
    /// MATLAB .mat histogram; default unit ps).
    #[arg(long, value_name = "TIME", value_parser = parse_ps, requires = "irf_from")]
    pub irf_bin_ps: Option<f64>,
}

impl PhysicsArgs {
    /// The flags as the library's overrides.
    pub fn overrides(&self) -> PhysicsOverrides {
        PhysicsOverrides {
            preset: self.preset,
            config: self.config.clone(),
            mu_a: self.mu_a,
            mu_s: self.mu_s,
            g: self.g,
            n: self.n,
            thickness: self.thickness,
            medium: self.medium,
            fov: self.fov,
            size: self.size,
            bin_width: self.bin_width,
            t_start: self.t_start,
            bins: self.bins,
            photons: self.photons,
            min_bin_photons: self.min_bin_photons,
            irf_fwhm: self.irf_fwhm,
            irf_tail: self.irf_tail,
            irf_from: self.irf_from.clone(),
            irf_parametric: self.irf_parametric,
            irf_bin_ps: self.irf_bin_ps,
        }
    }

    /// Resolves preset, config file and flags into a validated setup,
    /// printing what a reference recording's instrument response is.
    pub fn resolve(&self) -> anyhow::Result<Setup> {
        self.resolve_over(None)
    }

    /// Like [`Self::resolve`], starting from `base` (a stack's recorded
    /// physics) instead of the default preset.
    pub fn resolve_over(&self, base: Option<Setup>) -> anyhow::Result<Setup> {
        let (setup, notes) = self.overrides().resolve_noted(base)?;
        for note in notes {
            println!("{note}");
        }
        Ok(setup)
    }
}
