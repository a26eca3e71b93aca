//! Physics parameters from a preset, a TOML file and overrides (a front
//! end's flags).
//!
//! Precedence: overrides over the TOML file over the preset. The TOML keys
//! are the override names (`mu_a`, `mu_s`, `g`, `n`, `thickness`, `medium`, `fov`,
//! `size`, `bin_width`, `t_start`, `bins`, `photons`, `min_bin_photons`,
//! `irf_fwhm`, `irf_tail`, `preset`). Lengths and times take plain numbers in the
//! documented unit (cm, ps) or strings with a unit (`"30mm"`, `"0.004ns"`).
//! A file may state the reduced scattering coefficient mu_s' = mu_s (1 - g)
//! as `mu_s_reduced` instead of `mu_s` (with `g`, or g = 0 when absent).

use std::path::{Path, PathBuf};

use scatterscope_physics::{InstrumentResponse, Irf, MediumModel, ParamError, Preset, Setup};
use serde::Deserialize;

use crate::units::{parse_cm_or_bare, parse_ps};

/// Parses a noise level on the [0, 1] scale: a number or a fraction such
/// as `25/255`; finite and not negative.
pub fn parse_noise_sigma(s: &str) -> Result<f64, String> {
    let number = |t: &str| {
        t.trim()
            .parse::<f64>()
            .map_err(|_| format!("`{s}`: `{t}` is not a number"))
    };
    let v = match s.split_once('/') {
        Some((a, b)) => number(a)? / number(b)?,
        None => number(s)?,
    };
    if v >= 0.0 && v.is_finite() {
        Ok(v)
    } else {
        Err(format!("`{s}`: sigma must be finite and not negative"))
    }
}

/// The medium and instrument of `setup` as a TOML file of this module's
/// keys (`mu_a`, `mu_s`, `g`, `n`, `thickness`, `medium`, `irf_fwhm`,
/// `irf_tail`), each value exact (shortest round-trip form), after the
/// comment lines of `header`: what `--config` reads back over a stack's
/// own sensor and bins. A measured IRF table has no keys: it is left out
/// (a comment says so), so the stack's own table stays in force.
pub fn material_toml(setup: &Setup, header: &str) -> String {
    let m = &setup.medium;
    let mut out: String = header.lines().map(|l| format!("# {l}\n")).collect();
    out.push_str(&format!(
        "mu_a = {:?}\nmu_s = {:?}\ng = {:?}\nn = {:?}\nthickness = {:?}\nmedium = \"{}\"\n",
        m.mu_a_per_cm,
        m.mu_s_per_cm,
        m.g,
        m.refractive_index,
        m.thickness_cm,
        m.model.name(),
    ));
    match &setup.irf {
        Some(InstrumentResponse::Measured(_)) => out.push_str(
            "# the instrument response is a measured table, recorded in the stack's metadata (no key here)\n",
        ),
        irf => {
            let (fwhm, tail) = irf
                .as_ref()
                .and_then(InstrumentResponse::parametric)
                .map_or((0.0, 0.0), |i| (i.fwhm_ps, i.tail_ps));
            out.push_str(&format!("irf_fwhm = {fwhm:?}\nirf_tail = {tail:?}\n"));
        }
    }
    out
}

/// A number, or a string with a unit.
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
enum Quantity {
    Number(f64),
    Text(String),
}

/// Overrides read from a TOML file; every key is optional.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct FileOverrides {
    preset: Option<String>,
    mu_a: Option<f64>,
    mu_s: Option<f64>,
    mu_s_reduced: Option<f64>,
    g: Option<f64>,
    n: Option<f64>,
    thickness: Option<Quantity>,
    medium: Option<String>,
    fov: Option<Quantity>,
    size: Option<usize>,
    bin_width: Option<Quantity>,
    t_start: Option<Quantity>,
    bins: Option<usize>,
    photons: Option<f64>,
    min_bin_photons: Option<f64>,
    irf_fwhm: Option<Quantity>,
    irf_tail: Option<Quantity>,
}

/// Overrides of a preset's physics (what a front end's flags set); every
/// field is optional. The command line's physics flags are these fields
/// (their docs are the flags' help).
#[derive(Debug, Clone, Default)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct PhysicsOverrides {
    /// Parameter set to start from (`paper`: the paper's 3 cm skin-like slab).
    #[cfg_attr(feature = "cli", arg(long, value_name = "NAME", value_parser = parse_preset))]
    pub preset: Option<Preset>,
    /// TOML file with any of the keys below (flags override it).
    #[cfg_attr(feature = "cli", arg(long, value_name = "FILE"))]
    pub config: Option<PathBuf>,
    /// Absorption coefficient mu_a in 1/cm.
    #[cfg_attr(
        feature = "cli",
        arg(long, value_name = "1/CM", allow_negative_numbers = true)
    )]
    pub mu_a: Option<f64>,
    /// Scattering coefficient mu_s in 1/cm.
    #[cfg_attr(
        feature = "cli",
        arg(long, value_name = "1/CM", allow_negative_numbers = true)
    )]
    pub mu_s: Option<f64>,
    /// Scattering anisotropy g in [-1, 1] (0.9-0.99 for tissue).
    #[cfg_attr(
        feature = "cli",
        arg(long, value_name = "G", allow_negative_numbers = true)
    )]
    pub g: Option<f64>,
    /// Refractive index of the medium (light speed is c/n).
    #[cfg_attr(
        feature = "cli",
        arg(long, value_name = "N", allow_negative_numbers = true)
    )]
    pub n: Option<f64>,
    /// Slab thickness z0 between object and sensor (default unit cm; e.g. 30mm).
    #[cfg_attr(feature = "cli", arg(long, value_name = "LENGTH", value_parser = parse_cm_or_bare, allow_negative_numbers = true))]
    pub thickness: Option<f64>,
    /// The medium: infinite (the paper's Eq. 6), slab (extrapolated
    /// boundaries, image sources; transmitted flux), monte-carlo (light
    /// as it travels: photon transport through the slab, where diffusion
    /// fails) or auto (slab where its measured error against transport
    /// is within a tenth of the light, else monte-carlo; said).
    #[cfg_attr(feature = "cli", arg(long, value_name = "MODEL", value_parser = parse_medium))]
    pub medium: Option<MediumChoice>,
    /// Horizontal field of view (default unit cm).
    #[cfg_attr(feature = "cli", arg(long, value_name = "LENGTH", value_parser = parse_cm_or_bare, allow_negative_numbers = true))]
    pub fov: Option<f64>,
    /// Image side in pixels (square images).
    #[cfg_attr(feature = "cli", arg(long, value_name = "PIXELS"))]
    pub size: Option<usize>,
    /// Time-bin width (default unit ps; e.g. 4ps, 0.004ns).
    #[cfg_attr(feature = "cli", arg(long, value_name = "TIME", value_parser = parse_ps, allow_negative_numbers = true))]
    pub bin_width: Option<f64>,
    /// Start of the first bin after the pulse reaches the object (default unit ps).
    #[cfg_attr(feature = "cli", arg(long, value_name = "TIME", value_parser = parse_ps, allow_negative_numbers = true))]
    pub t_start: Option<f64>,
    /// Number of time bins.
    #[cfg_attr(feature = "cli", arg(long, value_name = "COUNT"))]
    pub bins: Option<usize>,
    /// Light budget: expected photons in the whole ST-PSF over all bins.
    #[cfg_attr(
        feature = "cli",
        arg(long, value_name = "COUNT", allow_negative_numbers = true)
    )]
    pub photons: Option<f64>,
    /// Drop bins whose ST-PSF carries fewer expected photons (0 keeps all).
    #[cfg_attr(
        feature = "cli",
        arg(long, value_name = "COUNT", allow_negative_numbers = true)
    )]
    pub min_bin_photons: Option<f64>,
    /// Instrument response: FWHM of its Gaussian (default unit ps; 0: ideal).
    #[cfg_attr(feature = "cli", arg(long, value_name = "TIME", value_parser = parse_ps, allow_negative_numbers = true))]
    pub irf_fwhm: Option<f64>,
    /// Instrument response: its exponential tail (default unit ps; 0: none).
    #[cfg_attr(feature = "cli", arg(long, value_name = "TIME", value_parser = parse_ps, allow_negative_numbers = true))]
    pub irf_tail: Option<f64>,
    /// Instrument response measured without the medium (a tag file, a
    /// stack, or a MATLAB histogram with --irf-bin-width), as a table.
    #[cfg_attr(feature = "cli", arg(long, value_name = "REF", conflicts_with_all = ["irf_fwhm", "irf_tail"]))]
    pub irf_from: Option<PathBuf>,
    /// With --irf-from: fit the Gaussian-plus-exponential form instead.
    #[cfg_attr(feature = "cli", arg(long, requires = "irf_from"))]
    pub irf_parametric: bool,
    /// Bin width of an --irf-from file that records none (default unit ps).
    #[cfg_attr(feature = "cli", arg(long, value_name = "TIME", value_parser = parse_ps, requires = "irf_from"))]
    pub irf_bin_width: Option<f64>,
}

/// A configuration problem, naming the file or key and the value.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The TOML file could not be read.
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause (in the message, not repeated as a source).
        error: std::io::Error,
    },
    /// The TOML file has a syntax error, an unknown key or a bad value.
    #[error("{path}: {reason}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// The file cannot be read whole (a special file, or too large).
    #[error(transparent)]
    Read(#[from] crate::files::ReadError),
    /// The reference recording of the instrument response cannot be used.
    #[error(transparent)]
    Reference(#[from] crate::calibrate::CalibrateError),
    /// The resulting parameters are not physical.
    #[error("{error} (key `{key}`{})", config.as_ref().map_or(String::new(), |p| format!(" in {}", p.display())))]
    Param {
        /// The physics crate's error, naming the field and value.
        error: scatterscope_physics::ParamError,
        /// The TOML key (and override) that sets the field.
        key: &'static str,
        /// The config file given, if any: it may hold the value.
        config: Option<PathBuf>,
    },
}

impl PhysicsOverrides {
    /// Resolves preset, file and overrides into a validated setup.
    pub fn resolve(&self) -> Result<Setup, ConfigError> {
        self.resolve_over(None)
    }

    /// Like [`Self::resolve`], starting from `base` (e.g. a stack's recorded
    /// physics) instead of the default preset; an explicit preset or a
    /// preset in the file still wins over `base`.
    pub fn resolve_over(&self, base: Option<Setup>) -> Result<Setup, ConfigError> {
        self.resolve_noted(base).map(|(setup, _)| setup)
    }

    /// Like [`Self::resolve_over`], with what an instrument response taken
    /// from a reference recording turned out to be, one line each.
    pub fn resolve_noted(&self, base: Option<Setup>) -> Result<(Setup, Vec<String>), ConfigError> {
        let (mut setup, mut notes) = self.resolve_flags(base)?;
        let Some(reference) = &self.irf_from else {
            return Ok((setup, notes));
        };
        if self.irf_parametric {
            let fit = crate::calibrate::irf_fit::irf_from_reference(reference, self.irf_bin_width)?;
            let se = |v: Option<f64>| v.map_or(String::new(), |e| format!(" +- {e:.2}"));
            notes.push(format!(
                "instrument response fitted to {}: Gaussian FWHM {:.2}{} ps, exponential tail {:.2}{} ps, centre at {:.2} ps on its clock, background {:.3} counts per bin, chi-square per degree of freedom {:.2}",
                reference.display(),
                fit.irf.fwhm_ps,
                se(fit.standard_errors_ps.0),
                fit.irf.tail_ps,
                se(fit.standard_errors_ps.1),
                fit.centre_ps,
                fit.background_per_bin,
                fit.chi2_per_dof
            ));
            if !fit.describes_reference() {
                notes.push(format!(
                    "note: the Gaussian-plus-exponential form does not describe {} (chi-square per degree of freedom {:.1}); the kernels use it as an approximation",
                    reference.display(),
                    fit.chi2_per_dof
                ));
            }
            setup.irf = Some(fit.irf.into());
        } else {
            let (measured, table) = crate::calibrate::measured_irf::measured_irf_from_reference(
                reference,
                self.irf_bin_width,
            )?;
            notes.push(format!(
                "instrument response measured in {}: {} bins of {} ps, FWHM {:.1} ps, mean delay {:.1} ps after its peak, time zero at {:.2} ps on its clock (the peak bin's centre), background {:.3} counts per bin subtracted, {:.0} counts in the response",
                reference.display(),
                measured.weights.len(),
                measured.bin_width_ps,
                measured.fwhm_ps(),
                measured.mean_delay_ps(),
                measured.zero_time_ps(),
                measured.background_per_bin,
                measured.signal_counts
            ));
            setup.irf = Some(table.into());
        }
        Ok((setup, notes))
    }

    /// Preset, file and the overrides other than the reference recording;
    /// with notes on `auto`'s medium and on a preset's bins moved to the
    /// first light.
    fn resolve_flags(&self, base: Option<Setup>) -> Result<(Setup, Vec<String>), ConfigError> {
        let file = match &self.config {
            Some(path) => Some((path.as_path(), read_file(path)?)),
            None => None,
        };
        let file_preset = match &file {
            Some((path, f)) => match &f.preset {
                Some(name) => Some(parse_preset(name).map_err(|reason| invalid(path, reason))?),
                None => None,
            },
            None => None,
        };
        let (preset, mut s) = match (self.preset.or(file_preset), base) {
            (Some(p), _) => (Some(p), p.setup()),
            (None, Some(b)) => (None, b),
            (None, None) => (Some(Preset::Paper), Preset::Paper.setup()),
        };
        let mut start_given = self.t_start.is_some();
        let mut medium = self.medium;
        if let Some((path, f)) = &file {
            let from_file = file_as_overrides(path, f)?;
            start_given |= from_file.t_start.is_some();
            medium = medium.or(from_file.medium);
            from_file.apply(&mut s);
        }
        self.apply(&mut s);
        let as_config = |error: ParamError| {
            let key = key_of(error.field);
            ConfigError::Param {
                error,
                key,
                config: self.config.clone(),
            }
        };
        let mut notes = Vec::new();
        if medium == Some(MediumChoice::Auto) {
            s.validate().map_err(as_config)?;
            notes.push(choose_medium(&mut s).map_err(as_config)?);
        }
        if let Some(p) = preset.filter(|_| !start_given) {
            notes.extend(bins_to_first_light(p, &mut s));
        }
        s.validate().map_err(as_config)?;
        Ok((s, notes))
    }

    fn apply(&self, s: &mut Setup) {
        let m = &mut s.medium;
        set(&mut m.mu_a_per_cm, self.mu_a);
        set(&mut m.mu_s_per_cm, self.mu_s);
        set(&mut m.g, self.g);
        set(&mut m.refractive_index, self.n);
        set(&mut m.thickness_cm, self.thickness);
        if let Some(MediumChoice::Model(model)) = self.medium {
            m.model = model;
        }
        set(&mut s.sensor.fov_cm, self.fov);
        if let Some(size) = self.size {
            s.sensor.width_px = size;
            s.sensor.height_px = size;
        }
        set(&mut s.bins.width_ps, self.bin_width);
        set(&mut s.bins.start_ps, self.t_start);
        set(&mut s.bins.count, self.bins);
        set(&mut s.total_photons, self.photons);
        set(&mut s.min_bin_photons, self.min_bin_photons);
        let recorded = s
            .irf
            .as_ref()
            .and_then(InstrumentResponse::parametric)
            .copied();
        match (self.irf_fwhm, self.irf_tail) {
            (Some(0.0), _) => s.irf = None,
            (Some(fwhm_ps), tail) => {
                let tail_ps = tail.or(recorded.map(|i| i.tail_ps)).unwrap_or(0.0);
                s.irf = Some(Irf { fwhm_ps, tail_ps }.into());
            }
            // A tail alone changes a recorded parametric IRF; without one
            // the zero FWHM is refused by validation, naming `irf_fwhm`.
            (None, Some(tail_ps)) => {
                let fwhm_ps = recorded.map_or(0.0, |i| i.fwhm_ps);
                s.irf = Some(Irf { fwhm_ps, tail_ps }.into());
            }
            (None, None) => {}
        }
    }
}

/// A preset's bins under Monte Carlo transport, when every one of them
/// ends before light can cross the slab (`n d / c`; the paper's preset
/// bins 0-120 ps, its light arrives from 140.1 ps): moved to start one
/// bin before the first light, on the preset's bin grid, and said. Bins a
/// user gave (`--t-start`, `t_start` in a file) or a stack recorded are
/// never moved.
fn bins_to_first_light(preset: Preset, s: &mut Setup) -> Option<String> {
    let first = s.medium.first_light_ps();
    let width = s.bins.width_ps;
    let end = s.bins.start_ps + s.bins.count as f64 * width;
    if s.medium.model != MediumModel::MonteCarlo
        || !(width > 0.0 && first.is_finite() && end <= first)
    {
        return None;
    }
    let from = s.bins.start_ps;
    s.bins.start_ps = ((first / width).floor() - 1.0).max(0.0) * width;
    Some(format!(
        "bins: the {} preset's bins ({from}-{end} ps) end before light can cross the slab (n d / c = {first:.1} ps); with the monte-carlo medium its {} bins of {width} ps start at {} ps instead (--t-start chooses)",
        preset.name(),
        s.bins.count,
        s.bins.start_ps
    ))
}

/// The TOML key (and override) that sets a [`Setup`] field.
fn key_of(field: &str) -> &'static str {
    match field {
        "mu_a_per_cm" => "mu_a",
        "mu_s_per_cm" => "mu_s",
        "g" => "g",
        "refractive_index" => "n",
        "thickness_cm" => "thickness",
        "model" => "medium",
        "fov_cm" => "fov",
        "width_px" | "height_px" => "size",
        "width_ps" => "bin_width",
        "start_ps" => "t_start",
        "min_bin_photons" => "min_bin_photons",
        "irf_fwhm_ps" => "irf_fwhm",
        "irf_tail_ps" => "irf_tail",
        "photons" => "photons",
        _ => "bins",
    }
}

fn set<T>(dst: &mut T, v: Option<T>) {
    if let Some(v) = v {
        *dst = v;
    }
}

/// Parses a preset name as TOML files (and the command line) spell it.
pub fn parse_preset(name: &str) -> Result<Preset, String> {
    parse_by_name(name, &Preset::ALL, Preset::name, "preset")
}

/// A medium model as users give it: one of the models, or `auto`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MediumChoice {
    /// This model.
    Model(MediumModel),
    /// The slab diffusion model where its error against Monte Carlo
    /// transport, measured for the setup, is within
    /// [`crate::physics::diffusion_error::AUTO_BOUND`]; else transport.
    Auto,
}

/// Parses a medium model name (`infinite`, `slab`, `monte-carlo`).
pub fn parse_medium_model(name: &str) -> Result<MediumModel, String> {
    parse_by_name(name, &MediumModel::ALL, MediumModel::name, "medium model")
}

/// Parses a medium as users give it: a model's name or `auto`.
pub fn parse_medium(name: &str) -> Result<MediumChoice, String> {
    if name.trim().eq_ignore_ascii_case("auto") {
        return Ok(MediumChoice::Auto);
    }
    parse_medium_model(name)
        .map(MediumChoice::Model)
        .map_err(|e| format!("{e} (or auto)"))
}

/// `auto`'s choice for the resolved setup `s` (its model set), and the
/// sentence saying why.
fn choose_medium(s: &mut Setup) -> Result<String, ParamError> {
    use crate::physics::diffusion_error::{AUTO_BOUND, diffusion_error};
    // Where diffusion's regime holds (scattering dominant, every bin past
    // a few transport times, a slab of several transport lengths),
    // transport is left unmeasured: there it is slow (thousands of
    // scatterings per packet) and the slab model holds.
    let mut slab = s.medium;
    slab.model = MediumModel::Slab;
    if let Ok(d) = crate::physics::Diffusion::new(&slab)
        && crate::physics::validity::diagnose(s, &d).is_empty()
    {
        s.medium.model = MediumModel::Slab;
        return Ok("medium auto: diffusion's regime holds for this medium and these bins (scattering dominant, every bin past 3 transport times, a slab of 3 transport lengths or more): the slab model is used, not measured against transport".into());
    }
    let cost = crate::physics::diffusion_error::quick_scatterings(s);
    if cost > crate::physics::diffusion_error::MAX_QUICK_SCATTERINGS {
        s.medium.model = MediumModel::Slab;
        return Ok(format!(
            "medium auto: diffusion's regime does not hold everywhere, but transport was not measured (a packet could meet {cost:.0} scatterings in these bins): the slab model is used"
        ));
    }
    let (model, why) = match diffusion_error(s, MediumModel::Slab) {
        Ok(e) if e.transport_light > 0.0 && e.shape <= AUTO_BOUND => (
            MediumModel::Slab,
            format!("{e}: within {AUTO_BOUND}, the slab model is used"),
        ),
        Ok(e) => (
            MediumModel::MonteCarlo,
            format!("{e}: above {AUTO_BOUND}, Monte Carlo transport is used"),
        ),
        Err(e) if e.field == "thickness_cm" || e.field == "bins" => (
            MediumModel::MonteCarlo,
            format!(
                "the slab model cannot describe this setup ({e}): Monte Carlo transport is used"
            ),
        ),
        Err(e) => return Err(e),
    };
    s.medium.model = model;
    Ok(format!("medium auto: {why}"))
}

/// The value of `all` called `name`, or an error listing the known names.
fn parse_by_name<T: Copy>(
    name: &str,
    all: &[T],
    name_of: fn(T) -> &'static str,
    what: &str,
) -> Result<T, String> {
    all.iter()
        .copied()
        .find(|&v| name_of(v) == name)
        .ok_or_else(|| {
            let known: Vec<_> = all.iter().map(|&v| name_of(v)).collect();
            format!("unknown {what} `{name}` (known: {})", known.join(", "))
        })
}

fn invalid(path: &Path, reason: impl Into<String>) -> ConfigError {
    ConfigError::Invalid {
        path: path.to_owned(),
        reason: reason.into(),
    }
}

/// A material file: the optics of a medium as a configuration file
/// states them (e.g. the `material.toml` that `calibrate-slab` writes):
/// `mu_a`, `n` and `mu_s_reduced` (or `mu_s`) required, `g` (0 when
/// absent) and `thickness` optional.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MaterialFile {
    /// Absorption coefficient (1/cm).
    pub mu_a_per_cm: f64,
    /// Scattering coefficient (1/cm).
    pub mu_s_per_cm: f64,
    /// Scattering anisotropy.
    pub g: f64,
    /// Refractive index.
    pub refractive_index: f64,
    /// Slab thickness the file names, if any (cm).
    pub thickness_cm: Option<f64>,
}

/// Reads a material file (the medium keys of a configuration file); a
/// missing required key is named.
pub fn read_material(path: &Path) -> Result<MaterialFile, ConfigError> {
    let o = file_as_overrides(path, &read_file(path)?)?;
    let need = |key: &str, v: Option<f64>| {
        v.ok_or_else(|| {
            invalid(
                path,
                format!(
                    "key `{key}` is missing: a material file states mu_a, mu_s_reduced (or mu_s with g) and n"
                ),
            )
        })
    };
    Ok(MaterialFile {
        mu_a_per_cm: need("mu_a", o.mu_a)?,
        mu_s_per_cm: need("mu_s_reduced", o.mu_s)?,
        g: o.g.unwrap_or(0.0),
        refractive_index: need("n", o.n)?,
        thickness_cm: o.thickness,
    })
}

/// Largest configuration file read (any real one is a few hundred bytes).
const MAX_CONFIG: u64 = 1 << 20;

fn read_file(path: &Path) -> Result<FileOverrides, ConfigError> {
    let bytes = crate::files::read_bounded(path, MAX_CONFIG, "configuration file")?;
    let text =
        String::from_utf8(bytes).map_err(|e| invalid(path, format!("not UTF-8 text: {e}")))?;
    toml::from_str(&text).map_err(|e| invalid(path, e.to_string()))
}

/// The file's keys as overrides, units resolved, so that the file and the
/// caller's overrides are applied by the same code.
fn file_as_overrides(path: &Path, f: &FileOverrides) -> Result<PhysicsOverrides, ConfigError> {
    let q = |key: &str, v: &Option<Quantity>, parse: fn(&str) -> Result<f64, String>| {
        v.as_ref()
            .map(|q| match q {
                Quantity::Number(x) => Ok(*x),
                Quantity::Text(t) => {
                    parse(t).map_err(|e| invalid(path, format!("key `{key}`: {e}")))
                }
            })
            .transpose()
    };
    let (mu_s, g) = match (f.mu_s, f.mu_s_reduced) {
        (Some(_), Some(_)) => {
            return Err(invalid(
                path,
                "keys `mu_s` and `mu_s_reduced` are both given: state one (mu_s' = mu_s (1 - g))"
                    .to_string(),
            ));
        }
        (None, Some(reduced)) => {
            // mu_s' states the medium with g as given, isotropic without.
            let g = f.g.unwrap_or(0.0);
            if g.is_nan() || g >= 1.0 {
                return Err(invalid(
                    path,
                    format!("key `g` = {g} with `mu_s_reduced`: g must be below 1"),
                ));
            }
            (Some(reduced / (1.0 - g)), Some(g))
        }
        (mu_s, None) => (mu_s, f.g),
    };
    Ok(PhysicsOverrides {
        preset: None,
        config: None,
        mu_a: f.mu_a,
        mu_s,
        g,
        n: f.n,
        thickness: q("thickness", &f.thickness, parse_cm_or_bare)?,
        medium: f
            .medium
            .as_deref()
            .map(parse_medium)
            .transpose()
            .map_err(|e| invalid(path, format!("key `medium`: {e}")))?,
        fov: q("fov", &f.fov, parse_cm_or_bare)?,
        size: f.size,
        bin_width: q("bin_width", &f.bin_width, parse_ps)?,
        t_start: q("t_start", &f.t_start, parse_ps)?,
        bins: f.bins,
        photons: f.photons,
        min_bin_photons: f.min_bin_photons,
        irf_fwhm: q("irf_fwhm", &f.irf_fwhm, parse_ps)?,
        irf_tail: q("irf_tail", &f.irf_tail, parse_ps)?,
        ..PhysicsOverrides::default()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_states_reduced_scattering_by_its_own_name() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("material.toml");
        std::fs::write(&path, "mu_a = 0.01\nmu_s_reduced = 5.0\nn = 1.12\n").unwrap();
        let m = read_material(&path).unwrap();
        assert_eq!((m.mu_s_per_cm, m.g), (5.0, 0.0));
        // With g, mu_s = mu_s' / (1 - g).
        std::fs::write(
            &path,
            "mu_a = 0.01\nmu_s_reduced = 5.0\ng = 0.9\nn = 1.12\n",
        )
        .unwrap();
        let m = read_material(&path).unwrap();
        assert!((m.mu_s_per_cm - 50.0).abs() < 1e-9 && m.g == 0.9, "{m:?}");
        // The old spelling (mu_s with g = 0) reads the same medium.
        std::fs::write(&path, "mu_a = 0.01\nmu_s = 5.0\ng = 0.0\nn = 1.12\n").unwrap();
        assert_eq!(read_material(&path).unwrap().mu_s_per_cm, 5.0);
        for (text, needle) in [
            (
                "mu_a = 0.01\nmu_s = 5.0\nmu_s_reduced = 5.0\nn = 1.12\n",
                "both given",
            ),
            (
                "mu_a = 0.01\nmu_s_reduced = 5.0\ng = 1.0\nn = 1.12\n",
                "below 1",
            ),
            ("mu_a = 0.01\nn = 1.12\n", "`mu_s_reduced` is missing"),
        ] {
            std::fs::write(&path, text).unwrap();
            let e = read_material(&path).unwrap_err().to_string();
            assert!(e.contains("material.toml") && e.contains(needle), "{e}");
        }
    }

    #[test]
    fn precedence_is_flags_over_file_over_preset() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("lab.toml");
        std::fs::write(&path, "mu_s = 7.5\nthickness = \"20mm\"\nbin_width = 2\n").unwrap();
        let args = PhysicsOverrides {
            config: Some(path.clone()),
            bin_width: Some(8.0),
            ..Default::default()
        };
        let s = args.resolve().unwrap();
        assert_eq!(s.medium.mu_s_per_cm, 7.5);
        assert_eq!(s.medium.thickness_cm, 2.0);
        assert_eq!(s.bins.width_ps, 8.0);
        assert_eq!(s.medium.mu_a_per_cm, 1.0); // from the preset
        std::fs::write(&path, "mu_z = 1\n").unwrap();
        let e = args.resolve().unwrap_err().to_string();
        assert!(e.contains("lab.toml") && e.contains("mu_z"), "{e}");
    }

    /// `--medium auto` (or `medium = "auto"` in a file) picks the model
    /// and says why: the paper's preset, whose own bins hold no light as
    /// it travels, gets Monte Carlo transport (and its bins moved to the
    /// first light); a medium and bins inside diffusion's regime get the
    /// slab model without a transport run; a slab of two transport
    /// lengths in bins from its first light gets transport, measured.
    #[test]
    fn auto_picks_the_medium_and_says_why() {
        assert_eq!(parse_medium("Auto"), Ok(MediumChoice::Auto));
        assert_eq!(
            parse_medium("slab"),
            Ok(MediumChoice::Model(MediumModel::Slab))
        );
        assert!(parse_medium("slap").unwrap_err().contains("(or auto)"));
        let args = PhysicsOverrides {
            medium: Some(MediumChoice::Auto),
            ..Default::default()
        };
        let (s, notes) = args.resolve_noted(None).unwrap();
        assert_eq!(s.medium.model, MediumModel::MonteCarlo);
        assert_eq!(s.bins.start_ps, 136.0);
        assert!(
            notes[0].starts_with("medium auto:") && notes[0].contains("put no light in these bins"),
            "{notes:?}"
        );
        assert!(notes[1].starts_with("bins:"), "{notes:?}");

        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("lab.toml");
        std::fs::write(
            &path,
            "medium = \"auto\"\nmu_s = 100\ng = 0\nmu_a = 0.1\nthickness = 2\nt_start = 2000\nbin_width = 500\n",
        )
        .unwrap();
        let args = PhysicsOverrides {
            config: Some(path.clone()),
            ..Default::default()
        };
        let (s, notes) = args.resolve_noted(None).unwrap();
        assert_eq!(s.medium.model, MediumModel::Slab);
        assert!(notes[0].contains("regime holds"), "{notes:?}");

        let args = PhysicsOverrides {
            medium: Some(MediumChoice::Auto),
            mu_s: Some(10.0),
            g: Some(0.0),
            mu_a: Some(0.1),
            thickness: Some(0.2),
            t_start: Some(0.0),
            bin_width: Some(5.0),
            bins: Some(40),
            fov: Some(10.0),
            size: Some(32),
            ..Default::default()
        };
        let (s, notes) = args.resolve_noted(None).unwrap();
        assert_eq!(s.medium.model, MediumModel::MonteCarlo);
        assert!(
            notes[0].contains("the slab model puts") && notes[0].contains("above 0.1"),
            "{notes:?}"
        );
    }

    #[test]
    fn the_medium_model_comes_from_the_file_and_bad_names_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("lab.toml");
        std::fs::write(&path, "medium = \"slab\"\nmu_s = 200\ng = 0.9\n").unwrap();
        let args = PhysicsOverrides {
            config: Some(path.clone()),
            ..Default::default()
        };
        assert_eq!(args.resolve().unwrap().medium.model, MediumModel::Slab);
        assert_eq!(
            Preset::Paper.setup().medium.model,
            MediumModel::Infinite,
            "the paper's model stays the default"
        );
        std::fs::write(&path, "medium = \"slap\"\n").unwrap();
        let e = args.resolve().unwrap_err().to_string();
        assert!(
            e.contains("lab.toml")
                && e.contains("`medium`")
                && e.contains("slap")
                && e.contains("infinite, slab"),
            "{e}"
        );
        // A slab too thin for its source is refused naming the key.
        std::fs::write(&path, "medium = \"slab\"\nthickness = 0.5\n").unwrap();
        let e = args.resolve().unwrap_err().to_string();
        assert!(
            e.contains("thickness") && e.contains("transport mean free path"),
            "{e}"
        );
    }

    #[test]
    fn the_irf_comes_from_flags_or_the_file_and_zero_turns_it_off() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("lab.toml");
        std::fs::write(&path, "irf_fwhm = \"0.05ns\"\nirf_tail = 20\n").unwrap();
        let mut args = PhysicsOverrides {
            config: Some(path.clone()),
            ..Default::default()
        };
        let irf = args.resolve().unwrap().irf.unwrap();
        assert_eq!(
            irf,
            Irf {
                fwhm_ps: 50.0,
                tail_ps: 20.0
            }
            .into()
        );
        // A flag's FWHM keeps the file's tail; 0 turns the IRF off.
        args.irf_fwhm = Some(30.0);
        let irf = args.resolve().unwrap().irf.unwrap();
        assert_eq!(
            irf,
            Irf {
                fwhm_ps: 30.0,
                tail_ps: 20.0
            }
            .into()
        );
        args.irf_fwhm = Some(0.0);
        assert_eq!(args.resolve().unwrap().irf, None);
        // A tail without a width is refused, naming the key to set.
        std::fs::write(&path, "irf_tail = 20\n").unwrap();
        args.irf_fwhm = None;
        let e = args.resolve().unwrap_err();
        assert!(
            matches!(&e, ConfigError::Param { key, .. } if *key == "irf_fwhm"),
            "{e}"
        );
    }

    #[test]
    fn invalid_values_name_field_and_key() {
        let args = PhysicsOverrides {
            mu_a: Some(-1.0),
            ..Default::default()
        };
        let e = args.resolve().unwrap_err().to_string();
        assert!(
            e.contains("invalid mu_a_per_cm = -1") && e.contains("key `mu_a`") && !e.contains("--"),
            "{e}"
        );
    }
}
