//! What the two calibrations write and print: a stack's fitted time
//! profile ([`Calibration`]) and the slab fit to transmittance captures
//! ([`SlabFit`]): the measured and fitted counts as CSV, plots of both, the
//! fitted physics as a TOML file, and the fit in words. The fits
//! themselves are [`crate::calibrate`]'s; this module reads their inputs
//! and writes what they found.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::calibrate::histogram::TimeHistogram;
use crate::calibrate::measured_irf::MeasuredIrf;
use crate::calibrate::transmittance::{
    Capture, MediumEstimate, SlabFit, SlabFitOptions, fit_slab, predict_captures, read_captures,
};
use crate::calibrate::{CalibrateError, Calibration, Free, calibrate, time_profile};
use crate::config::{ConfigError, PhysicsOverrides, material_toml};
use crate::physics::Setup;
use crate::plot::{Series, chart};
use crate::stack::Stack;

fn io_error(path: &Path, e: impl std::fmt::Display) -> CalibrateError {
    CalibrateError::Invalid(format!("writing {}: {e}", path.display()))
}

fn write(path: &Path, text: &str) -> Result<(), CalibrateError> {
    crate::files::write_atomic(path, text).map_err(|e| io_error(path, e))
}

/// A stack file's calibration: the stack (with metadata), the physics it
/// started from, and the fit of its time profile.
pub struct StackCalibration {
    /// The stack as read.
    pub stack: Stack,
    /// The starting physics: the stack's record under the overrides.
    pub start: Setup,
    /// Start of the profile's first bin (ps).
    pub start_ps: f64,
    /// The fit.
    pub fit: Calibration,
}

/// Why a stack file's calibration cannot run: its starting physics, or
/// the calibration itself.
#[derive(Debug, thiserror::Error)]
pub enum StackCalibrationError {
    /// The starting physics is invalid.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The stack cannot be read or its profile fitted.
    #[error(transparent)]
    Calibrate(#[from] CalibrateError),
}

/// Fits `free` to the time profile of the stack at `path`, starting from
/// its recorded physics under `physics`.
pub fn calibrate_file(
    path: &Path,
    physics: &PhysicsOverrides,
    free: Free,
) -> Result<StackCalibration, StackCalibrationError> {
    let (data, meta) = Stack::read(path).map_err(CalibrateError::from)?;
    let meta = meta.ok_or_else(|| {
        CalibrateError::Invalid(format!(
            "{} records no time bins; calibration needs a stack with metadata",
            path.display()
        ))
    })?;
    let stack = Stack::from_parts(data, meta, path).map_err(CalibrateError::from)?;
    let start = physics.resolve_over(stack.meta.setup.clone())?;
    let (start_ps, counts) = time_profile(&stack)?;
    let fit = calibrate(&counts, start_ps, &start, free)
        .map_err(|e| CalibrateError::Invalid(format!("calibrating {}: {e}", path.display())))?;
    Ok(StackCalibration {
        stack,
        start,
        start_ps,
        fit,
    })
}

impl StackCalibration {
    /// Writes the fit ([`Calibration::write`]) into `dir`; `source` names
    /// the calibrated stack.
    pub fn write(&self, dir: &Path, source: &Path) -> Result<Vec<PathBuf>, CalibrateError> {
        let width_ps = self.stack.meta.bin_width_ps;
        self.fit.write(dir, self.start_ps, width_ps, source)
    }
}

impl Calibration {
    /// Writes `profile.csv` and `profile.png` (the measured and fitted time
    /// profile, bins of `width_ps` from `start_ps`) and `physics.toml` (the
    /// fitted medium and IRF, for a config file) into `dir`; `source` names
    /// the calibrated stack in the TOML's header. Returns the files.
    pub fn write(
        &self,
        dir: &Path,
        start_ps: f64,
        width_ps: f64,
        source: &Path,
    ) -> Result<Vec<PathBuf>, CalibrateError> {
        std::fs::create_dir_all(dir).map_err(|e| io_error(dir, e))?;
        let mut csv = String::from("bin_start_ps,measured,fitted\n");
        for (i, (m, f)) in self.measured.iter().zip(&self.fitted).enumerate() {
            writeln!(csv, "{},{m},{f}", start_ps + i as f64 * width_ps)
                .expect("writing to a String");
        }
        let csv_path = dir.join("profile.csv");
        write(&csv_path, &csv)?;
        let series = |label: &str, values: &[f64]| Series {
            label: label.into(),
            points: values
                .iter()
                .enumerate()
                .map(|(i, &v)| (start_ps + (i as f64 + 0.5) * width_ps, v))
                .collect(),
        };
        let png = dir.join("profile.png");
        chart(
            &png,
            "time profile",
            "time (ps)",
            "counts per bin",
            &[series("measured", &self.measured)],
            &[series("fitted", &self.fitted)],
            false,
        )
        .map_err(|e| io_error(&png, e))?;
        let toml_path = dir.join("physics.toml");
        let shift = &self.parameters[2];
        let mut header = format!(
            "Medium and instrument fitted to the time profile of {} (chi-square per degree of freedom {:.3}).\nUse: scatterscope reconstruct STACK --config {}",
            source.display(),
            self.chi2_per_dof,
            toml_path.display()
        );
        if shift.fitted {
            header.push_str(&format!(
                "\nNot in this file: the fitted time-zero shift of {:.3} ps (reconstruct --fit-physics t0 applies it).",
                shift.value
            ));
        }
        write(&toml_path, &material_toml(&self.setup, &header))?;
        Ok(vec![csv_path, png, toml_path])
    }
}

impl SlabFit {
    /// The fit in words under `title`: the medium with its errors, the
    /// extrapolation distance, chi-square, and a row per capture.
    pub fn lines(&self, title: &str) -> Vec<String> {
        let mut lines = vec![title.to_string()];
        for (name, est, unit) in [
            ("mu_a", self.mu_a, "/cm"),
            ("mu_s'", self.mu_s_reduced, "/cm"),
            (
                "detector_offset",
                self.offset,
                "cm (detector from the laser's axis)",
            ),
        ] {
            let value = match (est.fitted, est.standard_error) {
                (true, Some(se)) => format!(
                    "{:.5} +- {:.1e} {unit} (Poisson), +- {:.1e} scaled by sqrt(chi2/dof)",
                    est.value,
                    se,
                    se * self.scatter_factor()
                ),
                (true, None) => format!("{:.5} {unit} (not determined by the data)", est.value),
                (false, _) => format!("{:.5} {unit} (fixed)", est.value),
            };
            lines.push(format!("  {name:<6} {value}"));
        }
        lines.push(format!(
            "  extrapolation distance {:.2} mm; chi-square per degree of freedom {:.2} ({} degrees of freedom)",
            10.0 * self.extrapolation_cm,
            self.chi2_per_dof,
            self.dof
        ));
        lines.push(
            "  capture              thickness   t0 (ps)        signal       background/bin  bins  left out  chi2/dof  (all bins)".into(),
        );
        for c in &self.captures {
            lines.push(format!(
                "  {:<20} {:>6.2} cm  {:>12.1}  {:>12.0}  {:>14.1}  {:>5}  {:>8}  {:>8.2}  {:>10.2}",
                c.label,
                c.thickness_cm,
                c.t0_ps,
                c.signal,
                c.background,
                c.measured.len(),
                c.left_out.len(),
                c.chi2_per_dof(),
                c.chi2_per_dof_window()
            ));
        }
        lines.extend(self.undetermined.iter().map(|u| format!("  note: {u}")));
        lines
    }
}

/// Writes `fit.csv` (every capture's window: measured, fitted, whether
/// the bin was in the fit) and a plot per capture, `fit_LABEL.png` (log
/// counts against the time since the pulse entered the slab), into `dir`,
/// for each group of captures with its fit and role (`fitted`,
/// `predicted`). Returns the files.
pub fn write_slab_fits(
    dir: &Path,
    groups: &[(&[Capture], &SlabFit, &str)],
) -> Result<Vec<PathBuf>, CalibrateError> {
    std::fs::create_dir_all(dir).map_err(|e| io_error(dir, e))?;
    let mut csv = String::from("capture,role,bin_start_ps,measured,fitted,in_fit\n");
    let mut files = Vec::new();
    for &(caps, fit, role) in groups {
        for (cap, c) in caps.iter().zip(&fit.captures) {
            let h = &cap.histogram;
            let first = c.window_start_ps(h.bin_width_ps, h.start_ps);
            let start = |i: usize| first + i as f64 * h.bin_width_ps;
            for (i, (m, u)) in c.measured.iter().zip(&c.fitted).enumerate() {
                let in_fit = u8::from(!c.left_out.contains(&i));
                writeln!(csv, "{},{role},{},{m},{u},{in_fit}", c.label, start(i))
                    .expect("writing to a String");
            }
            // Log counts against the time since the pulse entered the slab,
            // of the window's bins that `keep` picks.
            let points = |v: &[f64], keep: &dyn Fn(usize) -> bool| {
                v.iter()
                    .enumerate()
                    .filter(|(i, _)| keep(*i))
                    .map(|(i, &x)| {
                        (
                            start(i) + 0.5 * h.bin_width_ps - c.t0_ps,
                            x.max(0.5).log10(),
                        )
                    })
                    .collect()
            };
            let mut measured = vec![Series {
                label: "measured".into(),
                points: points(&c.measured, &|i| !c.left_out.contains(&i)),
            }];
            if !c.left_out.is_empty() {
                measured.push(Series {
                    label: "measured, left out of the fit".into(),
                    points: points(&c.measured, &|i| c.left_out.contains(&i)),
                });
            }
            let png = dir.join(format!("fit_{}.png", c.label));
            chart(
                &png,
                &format!(
                    "{} ({role}, {:.2} cm): chi2/dof {:.2}",
                    c.label,
                    c.thickness_cm,
                    c.chi2_per_dof()
                ),
                "time after the pulse enters the slab (ps)",
                "log10 counts per bin",
                &measured,
                &[Series {
                    label: "model".into(),
                    points: points(&c.fitted, &|_| true),
                }],
                false,
            )
            .map_err(|e| io_error(&png, e))?;
            files.push(png);
        }
    }
    let csv_path = dir.join("fit.csv");
    write(&csv_path, &csv)?;
    files.insert(0, csv_path);
    Ok(files)
}

/// How much of the reference recording is the instrument response.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum IrfExtent {
    /// The whole recorded period ([`MeasuredIrf::from_histogram_period`]).
    #[default]
    Period,
    /// The peak's run ([`MeasuredIrf::from_histogram`]).
    Peak,
}

crate::named::named!(IrfExtent {
    Period => "period",
    Peak => "peak",
});

/// One slab calibration as `calibrate-slab` runs it: the response from a
/// reference without the slab, captures through slabs of known thickness
/// fitted jointly, and captures left out predicted by the fitted medium.
#[derive(Debug, Clone)]
pub struct SlabJob {
    /// The reference recording (the instrument response).
    pub irf_from: PathBuf,
    /// How much of it is the response.
    pub irf_extent: IrfExtent,
    /// Captures to fit, each `FILE=THICKNESS` ([`read_captures`]).
    pub captures: Vec<String>,
    /// Captures the fitted medium predicts, `FILE=THICKNESS`.
    pub predict: Vec<String>,
    /// Dataset holding the histogram in MATLAB files.
    pub dataset: String,
    /// Cell array of per-part histograms in MATLAB files, if any.
    pub parts: Option<String>,
    /// Bin width (ps) of MATLAB histograms, which do not record it.
    pub bin_width_ps: Option<f64>,
    /// The model's settings and starting values.
    pub options: SlabFitOptions,
}

/// Largest chi-square per degree of freedom of a fit taken as describing
/// the captures (a Poisson fit that describes them gives about 1; the
/// six shared foam captures fit jointly at 10.9, with thicknesses
/// swapped at 16 440).
pub const MAX_PLAUSIBLE_CHI2_PER_DOF: f64 = 20.0;
/// Absorption coefficients of scattering materials (1/cm): water and
/// tissue in the near infrared lie near 0.01-1.
pub const PLAUSIBLE_MU_A_PER_CM: (f64, f64) = (0.0, 10.0);
/// Reduced scattering coefficients of scattering materials (1/cm): tissue
/// and foam lie near 1-100.
pub const PLAUSIBLE_MU_S_REDUCED_PER_CM: (f64, f64) = (0.1, 1000.0);

/// A finished slab calibration.
#[derive(Debug, Clone)]
pub struct SlabCalibration {
    /// The measured instrument response.
    pub irf: MeasuredIrf,
    /// What was read, kept or assumed before the fit, one line each.
    pub notes: Vec<String>,
    /// The fitted captures.
    pub captures: Vec<Capture>,
    /// The joint fit.
    pub fit: SlabFit,
    /// The captures left out of the fit and their prediction.
    pub prediction: Option<(Vec<Capture>, SlabFit)>,
    /// Wall time of the joint fit, seconds.
    pub seconds: f64,
}

impl SlabJob {
    /// Reads the reference and the captures, fits, and predicts.
    pub fn run(&self) -> Result<SlabCalibration, CalibrateError> {
        let reference = TimeHistogram::read(&self.irf_from, &self.dataset, self.bin_width_ps)?;
        let specs: Vec<&str> = self
            .captures
            .iter()
            .chain(&self.predict)
            .map(String::as_str)
            .collect();
        let (mut captures, parts) = read_captures(
            &specs,
            &self.dataset,
            self.parts.as_deref(),
            self.bin_width_ps,
        )?;
        let held = captures.split_off(self.captures.len());
        let notes = parts.iter().map(|p| format!("parts: {p}")).collect();
        calibrate_slab(
            &reference,
            self.irf_extent,
            captures,
            held,
            &self.options,
            notes,
        )
    }
}

/// Fits the medium to `captures` through the instrument response measured
/// in `reference` (over `extent`) and predicts `held` with it: the step
/// `calibrate-slab` runs after reading its files, for histograms from
/// anywhere (arrays, stacks, tag files). `notes` come first in the result's.
pub fn calibrate_slab(
    reference: &TimeHistogram,
    extent: IrfExtent,
    captures: Vec<Capture>,
    held: Vec<Capture>,
    options: &SlabFitOptions,
    notes: Vec<String>,
) -> Result<SlabCalibration, CalibrateError> {
    let irf = match extent {
        IrfExtent::Period => MeasuredIrf::from_histogram_period(reference)?,
        IrfExtent::Peak => MeasuredIrf::from_histogram(reference)?,
    };
    let mut all_notes = vec![irf.describe()];
    all_notes.extend(notes);
    all_notes.push(format!("model: {}", options.describe_model(&irf)));
    let started = std::time::Instant::now();
    let fit = fit_slab(&captures, &irf, options)?;
    let seconds = started.elapsed().as_secs_f64();
    let prediction = if held.is_empty() {
        None
    } else {
        let pred = predict_captures(&held, &irf, &fit.fixed())?;
        Some((held, pred))
    };
    Ok(SlabCalibration {
        irf,
        notes: all_notes,
        captures,
        fit,
        prediction,
        seconds,
    })
}

impl SlabCalibration {
    /// The calibration in words: the notes, the joint fit, the prediction.
    pub fn lines(&self) -> Vec<String> {
        let mut lines = self.notes.clone();
        lines.extend(self.fit.lines(&format!(
            "joint fit of {} captures ({} single-capture model evaluations, {:.1} s):",
            self.captures.len(),
            self.fit.evaluations,
            self.seconds
        )));
        if let Some((_, pred)) = &self.prediction {
            lines.extend(pred.lines("prediction of captures left out of the fit (medium fixed):"));
        }
        lines
    }

    /// What makes the fit doubtful, naming the value: a chi-square per
    /// degree of freedom far from 1 (the model does not describe the
    /// captures: thicknesses swapped, the reference and a capture swapped,
    /// the wrong bin width), or a fitted coefficient outside what any
    /// scattering material has ([`PLAUSIBLE_MU_A_PER_CM`],
    /// [`PLAUSIBLE_MU_S_REDUCED_PER_CM`]).
    pub fn warnings(&self) -> Vec<String> {
        let mut w = Vec::new();
        let fit = &self.fit;
        if fit.chi2_per_dof.is_nan() || fit.chi2_per_dof > MAX_PLAUSIBLE_CHI2_PER_DOF {
            w.push(format!(
                "chi2/dof = {:.1} over {} degrees of freedom (a fit that describes Poisson counts gives about 1, at most {MAX_PLAUSIBLE_CHI2_PER_DOF} here): the model does not describe the captures; check their thicknesses, that the reference is the reference, and the bin width",
                fit.chi2_per_dof, fit.dof
            ));
        }
        let outside = |name: &str, e: &MediumEstimate, (lo, hi): (f64, f64)| {
            (e.fitted && !(e.value >= lo && e.value <= hi)).then(|| {
                format!("fitted {name} = {:.4} 1/cm lies outside {lo} to {hi} 1/cm, where scattering materials lie", e.value)
            })
        };
        w.extend(outside("mu_a", &fit.mu_a, PLAUSIBLE_MU_A_PER_CM));
        w.extend(outside(
            "reduced scattering mu_s'",
            &fit.mu_s_reduced,
            PLAUSIBLE_MU_S_REDUCED_PER_CM,
        ));
        w
    }

    /// Writes `fit.csv` and the plots ([`write_slab_fits`]) into `dir`,
    /// and `material.toml` unless the fit is doubtful ([`Self::warnings`]):
    /// a material file is used without a second look.
    pub fn write(&self, dir: &Path) -> Result<Vec<PathBuf>, CalibrateError> {
        let mut groups = vec![(&self.captures[..], &self.fit, "fitted")];
        if let Some((held, pred)) = &self.prediction {
            groups.push((&held[..], pred, "predicted"));
        }
        let mut written = write_slab_fits(dir, &groups)?;
        if self.warnings().is_empty() {
            let path = dir.join("material.toml");
            write(&path, &self.material_toml())?;
            written.push(path);
        }
        Ok(written)
    }

    /// What [`Self::write`] wrote into `dir` (`files`), in words, and why
    /// there is no material file when there is none.
    pub fn describe_written(&self, dir: &Path, files: &[PathBuf]) -> Vec<String> {
        let names: Vec<String> = files
            .iter()
            .filter_map(|f| f.file_name().map(|n| n.to_string_lossy().into_owned()))
            .collect();
        let mut lines = vec![format!("wrote {}/{{{}}}", dir.display(), names.join(", "))];
        if !files.iter().any(|f| f.ends_with("material.toml")) {
            lines.push("material.toml not written: the fit is doubtful (see the warnings)".into());
        }
        lines
    }

    /// The fitted material as a configuration file (`mu_a`,
    /// `mu_s_reduced`, `n`, `medium = "slab"`), without a thickness:
    /// `scatterscope hidden --material` reads it for a slab of any
    /// thickness, `--config` for the reconstructions.
    pub fn material_toml(&self) -> String {
        let f = &self.fit;
        let thicknesses: Vec<String> = self
            .captures
            .iter()
            .map(|c| format!("{} cm", c.thickness_cm))
            .collect();
        format!(
            "# the material fitted by calibrate-slab to {} capture(s) ({}), IRF from {}\n# no thickness: give the slab's where the file is used\nmu_a = {:?}\nmu_s_reduced = {:?}\nn = {:?}\nmedium = \"slab\"\n",
            self.captures.len(),
            thicknesses.join(", "),
            self.irf.source,
            f.mu_a.value,
            f.mu_s_reduced.value,
            f.refractive_index
        )
    }
}
