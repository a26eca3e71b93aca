//! Arguments shared by several commands: the physics flags (which the
//! library takes as [`PhysicsOverrides`]) and named choices.

use clap::builder::{PossibleValuesParser, TypedValueParser};
use indicatif::{ProgressBar, ProgressStyle};
use scatterscope::Named;
use scatterscope::config::PhysicsOverrides;
use scatterscope::physics::{MediumModel, Preset, Setup};
use scatterscope::units::parse_cm_or_bare;
use scatterscope::units::parse_ps;
use std::path::PathBuf;

/// A struct of the library's from the flags of the same names (cloned),
/// and any further fields given after them.
macro_rules! same_fields {
    ($from:expr => $ty:ident { $($f:ident),* $(,)? } $($more:tt)*) => {
        $ty { $($f: $from.$f.clone(),)* $($more)* }
    };
}
pub(crate) use same_fields;

/// A clap value parser for a [`Named`] choice: its names are the possible
/// values.
pub fn choice<T: Named + Clone>() -> impl TypedValueParser<Value = T> {
    PossibleValuesParser::new(T::names())
        .map(|name| T::from_name(&name).expect("clap checked the name"))
}

/// Physics flags shared by every command that needs an ST-PSF.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct PhysicsArgs {
    /// Parameter set to start from (`paper`: the paper's 3 cm skin-like slab).
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
    #[arg(long, value_name = "LENGTH", value_parser = parse_cm_or_bare, allow_negative_numbers = true)]
    pub thickness: Option<f64>,
    /// The medium: infinite (the paper's Eq. 6) or slab (extrapolated
    /// boundaries, image sources; transmitted flux).
    #[arg(long, value_name = "MODEL", value_parser = scatterscope::config::parse_medium)]
    pub medium: Option<MediumModel>,
    /// Horizontal field of view (default unit cm).
    #[arg(long, value_name = "LENGTH", value_parser = parse_cm_or_bare, allow_negative_numbers = true)]
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
    /// Instrument response: FWHM of its Gaussian (default unit ps; 0: ideal).
    #[arg(long, value_name = "TIME", value_parser = parse_ps, allow_negative_numbers = true)]
    pub irf_fwhm: Option<f64>,
    /// Instrument response: its exponential tail (default unit ps; 0: none).
    #[arg(long, value_name = "TIME", value_parser = parse_ps, allow_negative_numbers = true)]
    pub irf_tail: Option<f64>,
    /// Instrument response measured without the medium (a tag file, a
    /// stack, or a MATLAB histogram with --irf-bin-width), as a table.
    #[arg(long, value_name = "REF", conflicts_with_all = ["irf_fwhm", "irf_tail"])]
    pub irf_from: Option<PathBuf>,
    /// With --irf-from: fit the Gaussian-plus-exponential form instead.
    #[arg(long, requires = "irf_from")]
    pub irf_parametric: bool,
    /// Bin width of an --irf-from file that records none (default unit ps).
    #[arg(long, value_name = "TIME", value_parser = parse_ps, requires = "irf_from")]
    pub irf_bin_width: Option<f64>,
}

impl PhysicsArgs {
    /// The flags as the library's overrides.
    pub fn overrides(&self) -> PhysicsOverrides {
        same_fields!(self => PhysicsOverrides { preset, config, mu_a, mu_s, g, n, thickness,
            medium, fov, size, bin_width, t_start, bins, photons, min_bin_photons, irf_fwhm,
            irf_tail, irf_from, irf_parametric, irf_bin_width })
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

/// A progress display: a bar over `millis` when the end is known, else a
/// spinner; `{msg}` is the caller's.
pub fn progress(millis: Option<u128>) -> ProgressBar {
    let (bar, template) = match millis {
        Some(ms) => (
            ProgressBar::new(ms as u64),
            "{bar:30} {elapsed}/{duration} {msg}",
        ),
        None => (ProgressBar::new_spinner(), "{spinner} {elapsed} {msg}"),
    };
    bar.with_style(ProgressStyle::with_template(template).expect("template"))
}

/// The bin width of MATLAB files, which do not record theirs (`hidden`,
/// `calibrate-slab`).
#[derive(Debug, Clone, Default, clap::Args)]
pub struct FileBinWidthArgs {
    /// Bin width of MATLAB files, which do not record it (default unit ps;
    /// e.g. 16ps).
    #[arg(long, value_name = "TIME", value_parser = parse_ps)]
    pub bin_width: Option<f64>,
}

/// The flags given on the command line to `command` (as parsed: new
/// spellings, one `--flag=value` per value), leaving out the arguments
/// whose ids `skip` names and the positional ones.
pub fn given_flags(
    matches: &clap::ArgMatches,
    command: &clap::Command,
    skip: &[&str],
) -> Vec<String> {
    let mut out = Vec::new();
    for arg in command.get_arguments() {
        let id = arg.get_id().as_str();
        let given = matches.value_source(id) == Some(clap::parser::ValueSource::CommandLine);
        let Some(long) = arg.get_long().filter(|_| given && !skip.contains(&id)) else {
            continue;
        };
        match arg.get_action().takes_values() {
            true => out.extend(
                matches
                    .get_raw(id)
                    .into_iter()
                    .flatten()
                    .map(|v| format!("--{long}={}", v.to_string_lossy())),
            ),
            false => out.push(format!("--{long}")),
        }
    }
    out
}

/// Says on stderr which of `names`, given to `flag`, are old spellings of
/// a fitted parameter, and the new ones (the old still work).
pub fn note_renamed_parameters(flag: &str, names: &[String]) {
    for (old, new) in scatterscope::calibrate::renamed_in(names) {
        eprintln!("note: {flag} `{old}` is now `{new}`; the old name still works");
    }
}
