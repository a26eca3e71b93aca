//! A stack file made ready to reconstruct, in one call: its counts read,
//! its physics resolved (the file's record under the caller's overrides,
//! or for a plain array the overrides alone with the bins one after
//! another), optionally fitted to its time profile, matched bin by bin with
//! the kernels, and its background chosen. What was assumed is returned
//! in words, so that every front end says the same.

use std::path::{Path, PathBuf};

use ndarray::{Array2, Array3};

use super::problem::{BackgroundChoice, Problem, ProblemError};
use crate::calibrate::{CalibrateError, Free, fit_stack_physics};
use crate::config::{ConfigError, PhysicsOverrides};
use crate::formats::detect::Format;
use crate::formats::image::read_image;
use crate::formats::stack_file::missing_meta;
use crate::forward::Boundary;
use crate::physics::{Preset, Sampling, Setup};
use crate::poisson::counts::{CountsError, check_light};
use crate::scene::{ImageError, Scene};
use crate::stack::{Stack, StackError, StackMeta, ValueKind};

/// How a stack file is matched with its physics.
#[derive(Debug, Clone, Default)]
pub struct InputSpec {
    /// Overrides of the recorded physics (or, for a file without any, the
    /// physics itself).
    pub physics: PhysicsOverrides,
    /// Fit these parameters to the stack's time profile first.
    pub fit_physics: Option<Free>,
    /// How the sensor's edges are modelled (default: the stack's record,
    /// else a sensor with edges).
    pub boundary: Option<Boundary>,
    /// Background counts per pixel and bin in the likelihood.
    pub background: BackgroundChoice,
}

/// A stack ready to reconstruct.
pub struct Input {
    /// The counts matched with their kernels, background included.
    pub problem: Problem,
    /// The stack as read (its bin starts moved by a fitted time zero).
    pub stack: Stack,
    /// What the file lacked and was assumed, one warning each.
    pub warnings: Vec<String>,
    /// What the reconstruction assumes (fitted physics, the model, the
    /// background, bins left out), one line each, for the output and the
    /// trace.
    pub assumed: Vec<String>,
}

/// Why a stack file cannot be made ready.
#[derive(Debug, thiserror::Error)]
pub enum InputError {
    /// The file cannot be read.
    #[error(transparent)]
    Stack(#[from] StackError),
    /// The physics overrides are invalid.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The physics for a file without metadata is invalid.
    #[error("the physics for {path}: {source}")]
    Physics {
        /// The file.
        path: PathBuf,
        /// Why.
        source: crate::physics::ParamError,
    },
    /// The physics could not be fitted to the stack.
    #[error("fitting the physics of {path}: {source}")]
    Fit {
        /// The file.
        path: PathBuf,
        /// Why.
        source: CalibrateError,
    },
    /// The stack and its physics do not fit together.
    #[error("matching {path} with its physics: {source}")]
    Match {
        /// The file.
        path: PathBuf,
        /// Why.
        source: ProblemError,
    },
    /// The stack holds less than one photon: nothing to reconstruct.
    #[error("{path}: {source}")]
    Counts {
        /// The file.
        path: PathBuf,
        /// Why.
        source: CountsError,
    },
    /// The background cannot be used.
    #[error("the background of {path}: {source}")]
    Background {
        /// The file.
        path: PathBuf,
        /// Why.
        source: ProblemError,
    },
}

/// Reads the stack at `path` and makes it ready to reconstruct as `spec`
/// says.
pub fn load(path: &Path, spec: &InputSpec) -> Result<Input, InputError> {
    let (data, meta) = Stack::read(path)?;
    prepare(data, meta, path, spec)
}

/// Makes counts `data` with their metadata (if any) ready to reconstruct
/// as `spec` says; `path` names their source in messages (a file, or a
/// caller's array).
pub fn prepare(
    data: Array3<f32>,
    meta: Option<StackMeta>,
    path: &Path,
    spec: &InputSpec,
) -> Result<Input, InputError> {
    let mut warnings = Vec::new();
    let mut assumed = Vec::new();
    let physics = &spec.physics;
    let (mut stack, mut setup) = match meta {
        Some(meta) => {
            let stack = Stack::from_parts(data, meta, path)?;
            if stack.meta.setup.is_none() && physics.preset.is_none() && physics.config.is_none() {
                warnings.push(format!(
                    "{} records no physics; using the {} preset with the overrides",
                    path.display(),
                    Preset::Paper.name()
                ));
            }
            let (setup, notes) = physics.resolve_noted(stack.meta.setup.clone())?;
            assumed.extend(notes);
            (stack, setup)
        }
        None => {
            // A plain array (np.save, another tool's EXR): physics and
            // time window from the overrides, the bins one after another.
            let (setup, notes) = physics.resolve_noted(None)?;
            assumed.extend(notes);
            let meta = StackMeta::consecutive(
                &setup,
                data.dim().0,
                ValueKind::Counts,
                format!("{} (no metadata)", path.display()),
            )
            .map_err(|source| InputError::Physics {
                path: path.into(),
                source,
            })?;
            let setup = meta
                .setup
                .clone()
                .expect("consecutive metadata holds its physics");
            warnings.push(format!(
                "{} has {}; assumed: photon counts in {} consecutive bins of {} ps from {} ps (the physics' time window and photon budget), {} x {} pixels of {} cm, physics from {}",
                path.display(),
                missing_meta(path),
                setup.bins.count,
                setup.bins.width_ps,
                setup.bins.start_ps,
                setup.sensor.height_px,
                setup.sensor.width_px,
                meta.pixel_pitch_cm,
                match (&physics.preset, &physics.config) {
                    (Some(p), _) => format!("the {} preset and the overrides", p.name()),
                    (None, Some(c)) => format!("{} and the overrides", c.display()),
                    (None, None) => format!(
                        "the {} preset (default) and the overrides",
                        Preset::Paper.name()
                    ),
                }
            ));
            (Stack::from_parts(data, meta, path)?, setup)
        }
    };
    // Each value was checked as a count when the stack was made.
    let total: f64 = stack.data.iter().map(|&v| f64::from(v)).sum();
    check_light(total, stack.data.len()).map_err(|source| InputError::Counts {
        path: path.into(),
        source,
    })?;
    if let Some(free) = spec.fit_physics {
        let cal =
            fit_stack_physics(&mut stack, &setup, free).map_err(|source| InputError::Fit {
                path: path.into(),
                source,
            })?;
        assumed.push(format!(
            "physics fitted to the stack's time profile ({})",
            free.names().join(", ")
        ));
        assumed.extend(cal.lines());
        setup = cal.setup;
    }
    let sampling = stack.meta.sampling.unwrap_or(Sampling::Integrated);
    let boundary = spec.boundary.or(stack.meta.boundary).unwrap_or_default();
    let problem =
        Problem::new(&stack, &setup, sampling, boundary).map_err(|source| InputError::Match {
            path: path.into(),
            source,
        })?;
    let (problem, background) =
        problem
            .with_background(spec.background)
            .map_err(|source| InputError::Background {
                path: path.into(),
                source,
            })?;
    assumed.push(format!("model: {}", setup.model_summary()));
    if let Ok(diffusion) = crate::physics::Diffusion::new(&setup.medium) {
        let outside = crate::physics::validity::diagnose(&setup, &diffusion);
        let measured =
            crate::physics::diffusion_error::measured_line_where_outside(&setup, &outside);
        assumed.extend(
            outside
                .into_iter()
                .map(|d| format!("model: {} ({})", d.message, d.code)),
        );
        assumed.extend(measured.map(|line| format!("model: {line}")));
    }
    assumed.push(format!("background: {background}"));
    assumed.extend(problem.early_light().map(|w| format!("warning: {w}")));
    if let (Some(first), Some(last)) = (problem.left_out.first(), problem.left_out.last()) {
        let counts: f64 = problem.left_out.iter().map(|(_, c)| c).sum();
        assumed.push(format!(
            "left out {} bins ({} ps to {} ps) where the ST-PSF puts no light; they held {counts} counts",
            problem.left_out.len(),
            first.0,
            last.0 + stack.meta.bin_width_ps
        ));
    }
    Ok(Input {
        problem,
        stack,
        warnings,
        assumed,
    })
}

impl Input {
    /// The truth image at `path` on the stack's sensor, to score against
    /// (a `.npy` of the sensor's size with its own values, any other image
    /// as a scene), and a warning when it had to be resampled to the
    /// sensor's size.
    pub fn truth(&self, path: &Path) -> Result<(Array2<f64>, Option<String>), ImageError> {
        let (_, h, w) = self.stack.data.dim();
        let image = read_image(path)?;
        let (nh, nw) = image.dim();
        // A .npy truth holds the object's own values: kept as they are
        // when it is the sensor's size.
        if (nh, nw) == (h, w) && Format::of_file(path) == Format::Npy {
            return Ok((image, None));
        }
        let note = ((nh, nw) != (h, w)).then(|| {
            format!(
                "the truth {} is {nw} x {nh} pixels; resampled to the {w} x {h} sensor (Lanczos), so its PSNR and SSIM are against an approximation",
                path.display()
            )
        });
        Ok((Scene::File(path.to_path_buf()).render(h, w)?, note))
    }

    /// The setup the stack is matched with.
    pub fn setup(&self) -> &Setup {
        &self.problem.setup
    }
}
