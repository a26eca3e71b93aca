//! A stack matched with the kernels of its physics: what every method needs.

use ndarray::{Array2, Array3};
use scatterscope_physics::{KernelStack, Sampling, Setup};

use crate::forward::{Boundary, ForwardModel};
use crate::stack::{Stack, ValueKind};

/// Kept bins where even an object explaining every count would send fewer
/// than this many counts per pixel count as "before the first light" for
/// the background estimate (their expected light is subtracted).
pub const DARK_COUNTS_PER_PIXEL: f64 = 1e-3;

/// How the background per pixel and bin is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum BackgroundChoice {
    /// Estimated from the bins before the first light; none without such bins.
    #[default]
    Auto,
    /// Not modelled.
    None,
    /// Given, counts per pixel and bin.
    Given(f64),
}

impl BackgroundChoice {
    /// Parses `auto`, `none` or a number of counts per pixel and bin.
    pub fn parse(s: &str) -> Result<Self, String> {
        match s {
            "auto" => Ok(Self::Auto),
            "none" => Ok(Self::None),
            _ => s
                .parse::<f64>()
                .ok()
                .filter(|b| b.is_finite() && *b >= 0.0)
                .map(Self::Given)
                .ok_or_else(|| {
                    format!("`{s}` is not auto, none or a number of counts >= 0 per pixel and bin")
                }),
        }
    }
}

/// Pearson dispersion z of the bins before the first light above which
/// they are taken to hold light.
pub const EARLY_LIGHT_Z: f64 = 10.0;

/// The background measured in the bins before the first light.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BackgroundEstimate {
    /// Mean counts per pixel and bin.
    pub per_pixel_per_bin: f64,
    /// Its Poisson standard error.
    pub standard_error: f64,
    /// How many bins it comes from.
    pub bins: usize,
    /// From the start of the first to the end of the last of them (ps).
    pub span_ps: (f64, f64),
}

/// Counts and the forward model of exactly the stack's bins.
pub struct Problem {
    /// Kernel spectra of the stack's bins, in stack order.
    pub model: ForwardModel,
    /// The counts, K x H x W.
    pub counts: Array3<f64>,
    /// Start of each bin (ps).
    pub bin_starts_ps: Vec<f64>,
    /// The physics used.
    pub setup: Setup,
    /// Stack bins left out because the ST-PSF puts no light in them (before
    /// the first photons can arrive): their start (ps) and the counts they
    /// held (dark counts, background).
    pub left_out: Vec<(f64, f64)>,
}

/// Why a stack and a physics setup do not fit together.
#[derive(Debug, thiserror::Error)]
pub enum ProblemError {
    /// More memory than the budget.
    #[error(transparent)]
    Memory(#[from] crate::memory::MemoryError),
    /// The mismatch, naming both values.
    #[error("{0}")]
    Mismatch(String),
    /// The stack's image size differs from the physics' sensor.
    #[error(
        "the stack is {} x {} pixels but the physics sensor is {} x {}",
        stack.0, stack.1, physics.0, physics.1
    )]
    SensorSize {
        /// The stack's rows and columns.
        stack: (usize, usize),
        /// The physics' sensor rows and columns.
        physics: (usize, usize),
    },
    /// The stack's bin width differs from the physics'.
    #[error("the stack's bins are {stack_ps} ps wide but the physics uses {physics_ps} ps")]
    BinWidth {
        /// The stack's bin width, ps.
        stack_ps: f64,
        /// The physics' bin width, ps.
        physics_ps: f64,
    },
    /// Invalid physics.
    #[error(transparent)]
    Param(#[from] scatterscope_physics::ParamError),
}

impl Problem {
    /// Matches each bin of `stack` with the kernel of `setup` that starts at
    /// the same time, modelling the sensor's edges with `boundary`. Kernels
    /// are built for every bin of the setup (none
    /// dropped, so that the light budget normalisation is the recorded one)
    /// but only the stack's bins are transformed.
    pub fn new(
        stack: &Stack,
        setup: &Setup,
        sampling: Sampling,
        boundary: Boundary,
    ) -> Result<Self, ProblemError> {
        if stack.meta.kind == ValueKind::Kernel {
            return Err(ProblemError::Mismatch(
                "the stack holds ST-PSF kernels, not counts".into(),
            ));
        }
        if stack.meta.is_unstated(crate::stack::Unstated::TimeUnit) {
            return Err(ProblemError::Mismatch(
                "the stack's bins are micro-time channels of an unknown time unit (its recording did not state it): bin the recording again with its unit (--micro-unit) to reconstruct it".into(),
            ));
        }
        let (_, h, w) = stack.data.dim();
        if (setup.sensor.height_px, setup.sensor.width_px) != (h, w) {
            return Err(ProblemError::SensorSize {
                stack: (h, w),
                physics: (setup.sensor.height_px, setup.sensor.width_px),
            });
        }
        let width = setup.bins.width_ps;
        if (stack.meta.bin_width_ps - width).abs() > 1e-9 * width {
            return Err(ProblemError::BinWidth {
                stack_ps: stack.meta.bin_width_ps,
                physics_ps: width,
            });
        }
        setup.validate()?;
        crate::memory::check_setup(setup, crate::memory::PROBLEM_BYTES, "a reconstruction")?;
        let mut all = setup.clone();
        all.min_bin_photons = 0.0;
        let kernels = KernelStack::build(&all, sampling)?;
        let positions = stack
            .meta
            .bin_starts_ps
            .iter()
            .enumerate()
            .map(|(i, &start)| {
                let index = ((start - setup.bins.start_ps) / width).round();
                let matches = index >= 0.0
                    && (index as usize) < setup.bins.count
                    && (setup.bins.edges_ps(index as usize).0 - start).abs() <= 1e-6 * width;
                if matches {
                    Ok(kernels.position_of_bin(index as usize))
                } else {
                    Err(ProblemError::Mismatch(format!(
                        "stack bin {i} starts at {start} ps, which is not a bin of the physics ({} x {width} ps from {} ps)",
                        setup.bins.count, setup.bins.start_ps
                    )))
                }
            })
            .collect::<Result<Vec<_>, _>>()?;
        let kept: Vec<usize> = (0..positions.len())
            .filter(|&i| positions[i].is_some())
            .collect();
        if kept.is_empty() {
            return Err(ProblemError::Mismatch(format!(
                "the ST-PSF puts no light in any of the stack's {} bins ({} to {} ps)",
                positions.len(),
                stack.meta.bin_starts_ps.first().copied().unwrap_or(0.0),
                stack.meta.bin_starts_ps.last().copied().unwrap_or(0.0) + width
            )));
        }
        let left_out = (0..positions.len())
            .filter(|&i| positions[i].is_none())
            .map(|i| {
                let counts = stack
                    .data
                    .index_axis(ndarray::Axis(0), i)
                    .iter()
                    .map(|&v| f64::from(v))
                    .sum();
                (stack.meta.bin_starts_ps[i], counts)
            })
            .collect();
        let kernel_positions: Vec<usize> =
            kept.iter().map(|&i| positions[i].expect("kept")).collect();
        Ok(Self {
            model: ForwardModel::with_bins(&kernels, &kernel_positions, boundary),
            counts: stack.data.select(ndarray::Axis(0), &kept).mapv(f64::from),
            bin_starts_ps: kept.iter().map(|&i| stack.meta.bin_starts_ps[i]).collect(),
            setup: setup.clone(),
            left_out,
        })
    }

    /// The background from the bins before the first light: stack bins
    /// where the ST-PSF puts no light, and kept bins whose share of the
    /// kernels' light, times all the counts, is below
    /// [`DARK_COUNTS_PER_PIXEL`] per pixel; that light is subtracted from
    /// their counts (at most down to 0). `None` when there is no such bin.
    pub fn estimate_background(&self) -> Option<BackgroundEstimate> {
        let (_, h, w) = self.counts.dim();
        let (dark, their_light) = self.dark_bins();
        if dark.is_empty() {
            return None;
        }
        let cells = (dark.len() * h * w) as f64;
        let held: f64 = dark.iter().map(|(_, c)| c).sum();
        let counts = (held - their_light).max(0.0);
        let first = dark.iter().map(|(t, _)| *t).fold(f64::INFINITY, f64::min);
        let last = dark
            .iter()
            .map(|(t, _)| *t)
            .fold(f64::NEG_INFINITY, f64::max);
        Some(BackgroundEstimate {
            per_pixel_per_bin: counts / cells,
            standard_error: held.sqrt() / cells,
            bins: dark.len(),
            span_ps: (first, last + self.setup.bins.width_ps),
        })
    }

    /// The bins before the first light, `(start ps, counts)`: stack bins
    /// where the ST-PSF puts no light and kept bins where it puts under
    /// [`DARK_COUNTS_PER_PIXEL`] per pixel; and the light the kernels
    /// still put in the kept ones, for an object explaining every count
    /// (taken off, so that the earliest photons of the signal do not pass
    /// for background).
    fn dark_bins(&self) -> (Vec<(f64, f64)>, f64) {
        let dark = self.dark_bins_with_light();
        let their_light = dark.iter().map(|&(_, _, s)| s).sum();
        (
            dark.into_iter().map(|(t, c, _)| (t, c)).collect(),
            their_light,
        )
    }

    /// The bins before the first light as `(start ps, counts, the light
    /// the kernels put there for an object explaining every count)`.
    fn dark_bins_with_light(&self) -> Vec<(f64, f64, f64)> {
        let (_, h, w) = self.counts.dim();
        let total_mass: f64 = (0..self.model.bins()).map(|k| self.model.mass(k)).sum();
        let total: f64 = self.counts.sum();
        let mut dark: Vec<(f64, f64, f64)> =
            self.left_out.iter().map(|&(t, c)| (t, c, 0.0)).collect();
        for k in 0..self.model.bins() {
            let most_signal = total * self.model.mass(k) / total_mass;
            if most_signal < DARK_COUNTS_PER_PIXEL * (h * w) as f64 {
                let counts = self.counts.index_axis(ndarray::Axis(0), k).sum();
                dark.push((self.bin_starts_ps[k], counts, most_signal));
            }
        }
        dark
    }

    /// A warning when the bins before the model's first light are not
    /// flat: their counts, less the faint light the kernels themselves put
    /// there, vary across the bins far beyond Poisson noise (Pearson's
    /// dispersion, z above [`EARLY_LIGHT_Z`]) and by more than a fifth of
    /// their mean. Then light arrives before the model says (a thinner
    /// slab, a lower index, an earlier time zero), and the background
    /// estimated from those bins holds signal.
    pub fn early_light(&self) -> Option<String> {
        let mut dark = self.dark_bins_with_light();
        if dark.len() < 3 {
            return None;
        }
        dark.sort_by(|a, b| a.0.total_cmp(&b.0));
        let n = dark.len() as f64;
        // The background level the bins share once the model's own light
        // is taken off; each bin is expected to hold it plus that light.
        let background = (dark.iter().map(|(_, c, s)| c - s).sum::<f64>() / n).max(0.0);
        let mean = dark.iter().map(|(_, c, _)| c).sum::<f64>() / n;
        if mean <= 0.0 {
            return None;
        }
        let chi2: f64 = dark
            .iter()
            .map(|(_, c, s)| {
                let expected = background + s;
                (c - expected).powi(2) / expected.max(1.0)
            })
            .sum();
        let z = (chi2 - (n - 1.0)) / (2.0 * (n - 1.0)).sqrt();
        let widest = dark
            .iter()
            .map(|(_, c, s)| (c - background - s).abs())
            .fold(0.0f64, f64::max);
        let (lo, hi) = dark
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(l, h), (_, c, _)| {
                (l.min(*c), h.max(*c))
            });
        (z > EARLY_LIGHT_Z && widest > 0.1 * mean).then(|| {
            format!(
                "the {} bins before the model's first light ({} to {} ps) are not flat (their counts range {lo:.0} to {hi:.0} per bin, dispersion z = {z:.0} after the model's own light there): light arrives earlier than the model says (a thinner slab, a lower index or an earlier time zero than stated), and the background taken from them holds signal",
                dark.len(),
                dark[0].0,
                dark[dark.len() - 1].0 + self.setup.bins.width_ps
            )
        })
    }

    /// Sets the background the methods fit (`Poisson(H o + b)`), from
    /// `choice`; returns the problem and a sentence saying what was used.
    pub fn with_background(
        mut self,
        choice: BackgroundChoice,
    ) -> Result<(Self, String), ProblemError> {
        let (b, said) = match choice {
            BackgroundChoice::None => (0.0, "none (not modelled)".to_string()),
            BackgroundChoice::Given(b) => {
                if !(b.is_finite() && b >= 0.0) {
                    return Err(ProblemError::Mismatch(format!(
                        "background = {b} counts per pixel and bin must be a finite number >= 0"
                    )));
                }
                (b, format!("{b:.4e} counts per pixel and bin (given)"))
            }
            BackgroundChoice::Auto => match self.estimate_background() {
                Some(e) => (
                    e.per_pixel_per_bin,
                    format!(
                        "{:.4e} +- {:.1e} counts per pixel and bin, estimated from the {} bin(s) before the first light ({} to {} ps)",
                        e.per_pixel_per_bin, e.standard_error, e.bins, e.span_ps.0, e.span_ps.1
                    ),
                ),
                None => (
                    0.0,
                    "none assumed: the stack has no bin before the first light to estimate it from (give it explicitly if there is one)".to_string(),
                ),
            },
        };
        self.model = self.model.with_background(b);
        Ok((self, said))
    }

    /// Indices of all bins, `0..K`.
    pub fn all_bins(&self) -> Vec<usize> {
        (0..self.counts.shape()[0]).collect()
    }

    /// The counts of bin `k` alone, as a 1 x H x W stack.
    pub fn single_bin(&self, k: usize) -> Array3<f64> {
        let img: Array2<f64> = self.counts.index_axis(ndarray::Axis(0), k).to_owned();
        img.insert_axis(ndarray::Axis(0))
    }
}
