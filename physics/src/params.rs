//! Physical and sampling parameters of a transient imaging setup.
//!
//! Every quantity carries its unit in its name: `_per_cm` for attenuation
//! coefficients, `_cm` for lengths, `_ps` for times.

use serde::{Deserialize, Serialize};

use crate::error::{ParamError, finite, non_negative, positive};
use crate::irf::InstrumentResponse;

/// Optical properties and thickness of the homogeneous scattering slab.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Medium {
    /// Absorption coefficient mu_a (1/cm).
    pub mu_a_per_cm: f64,
    /// Scattering coefficient mu_s (1/cm).
    pub mu_s_per_cm: f64,
    /// Scattering anisotropy g (mean cosine of the scattering angle), in [-1, 1].
    pub g: f64,
    /// Refractive index n; light travels at c/n in the medium.
    pub refractive_index: f64,
    /// Slab thickness z0 between object and sensor (cm).
    pub thickness_cm: f64,
    /// How the slab's faces are modelled (absent in older files: the
    /// paper's infinite medium).
    #[serde(default)]
    pub model: MediumModel,
}

/// How the diffusion model treats the slab's faces.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MediumModel {
    /// The paper's Eq. 6: the infinite-medium Green's function at distance
    /// z0, no faces.
    #[default]
    Infinite,
    /// A finite slab with extrapolated boundaries and image sources
    /// (Patterson, Chance and Wilson 1989; Contini, Martelli and Zaccanti
    /// 1997): transmitted flux through the far face, with the boundary
    /// reflection from the refractive-index mismatch to air.
    Slab,
    /// Light as it travels: Monte Carlo transport through the slab
    /// ([`crate::transport`]), each point of the object emitting into it
    /// by Lambert's law, Fresnel faces against air; where the diffusion
    /// approximation fails (thin or weakly scattering media, early
    /// photons).
    #[serde(rename = "monte-carlo")]
    MonteCarlo,
}

impl MediumModel {
    /// Every model, for help texts.
    pub const ALL: [MediumModel; 3] = [
        MediumModel::Infinite,
        MediumModel::Slab,
        MediumModel::MonteCarlo,
    ];

    /// The model's name in configuration files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            MediumModel::Infinite => "infinite",
            MediumModel::Slab => "slab",
            MediumModel::MonteCarlo => "monte-carlo",
        }
    }
}

/// The sensor plane: a square-pixel grid behind the slab.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Sensor {
    /// Horizontal field of view (cm); the pixel pitch is `fov_cm / width_px`.
    pub fov_cm: f64,
    /// Image width in pixels.
    pub width_px: usize,
    /// Image height in pixels.
    pub height_px: usize,
}

impl Sensor {
    /// Side length of one square pixel (cm).
    pub fn pixel_pitch_cm(&self) -> f64 {
        self.fov_cm / self.width_px as f64
    }
}

/// Uniform time bins `[start + k width, start + (k+1) width)`, k = 0..count.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TimeBins {
    /// Start of the first bin, relative to the laser pulse hitting the object (ps).
    pub start_ps: f64,
    /// Width of every bin (ps).
    pub width_ps: f64,
    /// Number of bins.
    pub count: usize,
}

impl TimeBins {
    /// Start and end (ps) of bin `k`.
    pub fn edges_ps(&self, k: usize) -> (f64, f64) {
        let t0 = self.start_ps + k as f64 * self.width_ps;
        (t0, t0 + self.width_ps)
    }

    /// End of the last bin (ps).
    pub fn end_ps(&self) -> f64 {
        self.start_ps + self.count as f64 * self.width_ps
    }
}

/// Everything needed to build the ST-PSF kernel stack of an experiment.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Setup {
    /// The scattering slab.
    pub medium: Medium,
    /// The sensor grid.
    pub sensor: Sensor,
    /// The time binning.
    pub bins: TimeBins,
    /// Light budget: the discretised ST-PSF is scaled to carry this many
    /// photons in total over all bins (before any bin is dropped).
    pub total_photons: f64,
    /// Bins whose expected photon total (kernel mass) is below this are
    /// dropped as carrying no information; 0 keeps every bin.
    pub min_bin_photons: f64,
    /// The instrument's timing response; `None` for ideal timing (absent
    /// in older files).
    #[serde(default)]
    pub irf: Option<InstrumentResponse>,
}

/// Largest light budget accepted; Poisson sampling of larger means is not
/// supported and the values would exceed exact f32 counts long before.
pub const MAX_TOTAL_PHOTONS: f64 = 1e15;

/// Named parameter sets.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Preset {
    /// The paper's simulation: human-skin-like slab of 3 cm, 50 cm field of
    /// view at 256 x 256, 30 bins of 4 ps from 0 to 120 ps, 450 photons.
    Paper,
}

impl Preset {
    /// All presets, for help texts.
    pub const ALL: [Preset; 1] = [Preset::Paper];

    /// The preset's name as used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Preset::Paper => "paper",
        }
    }

    /// The parameter set.
    pub fn setup(self) -> Setup {
        match self {
            Preset::Paper => Setup {
                medium: Medium {
                    mu_a_per_cm: 1.0,
                    mu_s_per_cm: 5.0,
                    g: 0.99,
                    refractive_index: 1.4,
                    thickness_cm: 3.0,
                    model: MediumModel::Infinite,
                },
                sensor: Sensor {
                    fov_cm: 50.0,
                    width_px: 256,
                    height_px: 256,
                },
                bins: TimeBins {
                    start_ps: 0.0,
                    width_ps: 4.0,
                    count: 30,
                },
                total_photons: 450.0,
                min_bin_photons: 1.0,
                irf: None,
            },
        }
    }
}

impl Medium {
    /// When the first light can cross the slab: straight through at the
    /// speed of light in the medium, `n d / c` (ps).
    pub fn first_light_ps(&self) -> f64 {
        self.thickness_cm / crate::diffusion::light_speed_cm_per_ps(self.refractive_index)
    }

    /// Checks every field; the error names the first invalid one.
    pub fn validate(&self) -> Result<(), ParamError> {
        non_negative("mu_a_per_cm", self.mu_a_per_cm)?;
        non_negative("mu_s_per_cm", self.mu_s_per_cm)?;
        finite("g", self.g)?;
        if !(-1.0..=1.0).contains(&self.g) {
            return Err(ParamError::new(
                "g",
                self.g,
                "anisotropy must lie in [-1, 1]",
            ));
        }
        positive("refractive_index", self.refractive_index)?;
        if self.refractive_index < 1.0 {
            return Err(ParamError::new(
                "refractive_index",
                self.refractive_index,
                "a refractive index below 1 makes light travel faster than in vacuum (tissue and foam are 1.3-1.5)",
            ));
        }
        non_negative("thickness_cm", self.thickness_cm)?;
        if self.mu_s_per_cm * (1.0 - self.g) <= 0.0 {
            let (field, value) = if self.mu_s_per_cm == 0.0 {
                ("mu_s_per_cm", self.mu_s_per_cm)
            } else {
                ("g", self.g)
            };
            return Err(ParamError::new(
                field,
                value,
                format!(
                    "the reduced scattering (1 - g) mu_s = {} /cm: {}",
                    self.mu_s_per_cm * (1.0 - self.g),
                    if self.model == MediumModel::MonteCarlo {
                        "light crossing without scattering (ballistic light only, g = 1 or mu_s = 0) is not modelled, by Monte Carlo transport either; give g < 1 and mu_s > 0"
                    } else {
                        "a medium that does not scatter has no diffusion; the model describes scattering media"
                    }
                ),
            ));
        }
        let attenuation = self.mu_a_per_cm + (1.0 - self.g) * self.mu_s_per_cm;
        if attenuation <= 0.0 || !attenuation.is_finite() {
            let (field, value) = if self.mu_a_per_cm == 0.0 && self.g >= 1.0 {
                ("g", self.g)
            } else {
                ("mu_a_per_cm", self.mu_a_per_cm)
            };
            return Err(ParamError::new(
                field,
                value,
                format!(
                    "mu_a + (1 - g) mu_s = {attenuation} must be positive and finite, \
                     otherwise the diffusion coefficient D = 1/(3 (mu_a + (1 - g) mu_s)) is infinite"
                ),
            ));
        }
        let source_depth = 1.0 / attenuation;
        if self.model == MediumModel::Slab && self.thickness_cm <= source_depth {
            return Err(ParamError::new(
                "thickness_cm",
                self.thickness_cm,
                format!(
                    "the slab model needs a slab thicker than one transport mean free path, 1/(mu_a + (1 - g) mu_s) = {source_depth:.4} cm, where its equivalent source sits"
                ),
            ));
        }
        Ok(())
    }
}

impl Sensor {
    /// Checks every field; the error names the first invalid one.
    pub fn validate(&self) -> Result<(), ParamError> {
        positive("fov_cm", self.fov_cm)?;
        if self.width_px == 0 {
            return Err(ParamError::new(
                "width_px",
                0,
                "image needs at least one column",
            ));
        }
        if self.height_px == 0 {
            return Err(ParamError::new(
                "height_px",
                0,
                "image needs at least one row",
            ));
        }
        const MAX_SIDE: usize = 1 << 15;
        if self.width_px > MAX_SIDE || self.height_px > MAX_SIDE {
            return Err(ParamError::new(
                "width_px",
                format!("{}x{}", self.width_px, self.height_px),
                format!("each side must be at most {MAX_SIDE} pixels"),
            ));
        }
        Ok(())
    }
}

impl TimeBins {
    /// Checks every field; the error names the first invalid one.
    pub fn validate(&self) -> Result<(), ParamError> {
        finite("start_ps", self.start_ps)?;
        positive("width_ps", self.width_ps)?;
        if self.count == 0 {
            return Err(ParamError::new("bins", 0, "need at least one time bin"));
        }
        const MAX_BINS: usize = 4096;
        if self.count > MAX_BINS {
            return Err(ParamError::new(
                "bins",
                self.count,
                format!("at most {MAX_BINS} time bins are supported"),
            ));
        }
        finite("start_ps + bins * width_ps", self.end_ps())?;
        Ok(())
    }
}

impl Setup {
    /// One line saying what the model assumes about the medium and the
    /// instrument, for outputs to state.
    pub fn model_summary(&self) -> String {
        let medium = match self.medium.model {
            MediumModel::Infinite => "infinite medium (the paper's Eq. 6)".to_string(),
            MediumModel::Slab => format!(
                "finite slab with extrapolated boundaries (n = {})",
                self.medium.refractive_index
            ),
            MediumModel::MonteCarlo => format!(
                "Monte Carlo transport through the slab (n = {} in air; each object point emitting by Lambert's law; {} packets)",
                self.medium.refractive_index,
                crate::transport::SETUP_PACKETS
            ),
        };
        let timing = match &self.irf {
            None => "ideal timing (no instrument response)".to_string(),
            Some(irf) => irf.describe(),
        };
        format!("{medium}; {timing}")
    }

    /// Checks every field; the error names the first invalid one.
    pub fn validate(&self) -> Result<(), ParamError> {
        self.medium.validate()?;
        self.sensor.validate()?;
        self.bins.validate()?;
        positive("photons", self.total_photons)?;
        if self.total_photons > MAX_TOTAL_PHOTONS {
            return Err(ParamError::new(
                "photons",
                self.total_photons,
                format!("at most {MAX_TOTAL_PHOTONS:e} photons (Poisson sampling limit)"),
            ));
        }
        non_negative("min_bin_photons", self.min_bin_photons)?;
        if let Some(irf) = &self.irf {
            irf.validate()?;
        }
        Ok(())
    }
}
