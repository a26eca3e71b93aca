//! The one interface every reconstruction method implements
//! ([`Reconstructor`]) and the run it reports to ([`Run`]): the trace, the
//! timer, scoring against a known truth, notes, and the checked output.

use std::path::{Path, PathBuf};
use std::time::Instant;

use ndarray::{Array2, ArrayView2};

use super::data::Data;
use super::error::ReconstructError;
use super::trace::{Trace, TraceRow};
use crate::forward::{Boundary, ForwardModel};
use crate::metrics;
use crate::stack::{Stack, StackError};

/// A reconstructed image and how it was obtained.
#[derive(Debug, Clone)]
pub struct Reconstruction {
    /// The estimate of the object, finite and >= 0.
    pub image: Array2<f64>,
    /// Per-iteration trace.
    pub trace: Trace,
}

impl Reconstruction {
    /// Writes the image as `reconstruction.exr` (values as they are) and
    /// `reconstruction.png` (white at the larger of 1 and the image's
    /// maximum) and the trace as `trace.csv` and `trace.json` into `dir`
    /// (created if missing); returns the files written.
    pub fn write(&self, dir: &Path) -> Result<Vec<PathBuf>, StackError> {
        std::fs::create_dir_all(dir).map_err(|e| StackError::io(dir, e))?;
        let exr = dir.join("reconstruction.exr");
        crate::formats::exr::write_image(self.image.mapv(|v| v as f32).view(), &exr)?;
        let png = dir.join("reconstruction.png");
        let top = self.image.iter().fold(1.0f64, |m, &v| m.max(v));
        crate::formats::png::write_png(self.image.view(), Some(top), &png)?;
        self.trace
            .write(dir, "trace")
            .map_err(|e| StackError::io(&dir.join("trace.csv"), e))?;
        Ok(vec![
            exr,
            png,
            dir.join("trace.csv"),
            dir.join("trace.json"),
        ])
    }

    /// Writes the image as `reconstruction.ome.tif` into `dir` (a float
    /// OME-TIFF for Fiji or napari); its physical pixel size is `stack`'s
    /// pixel pitch when the image is on the stack's sensor grid (has its
    /// size) and the stack states it. Returns the file.
    pub fn write_ome_tiff(&self, dir: &Path, stack: &Stack) -> Result<PathBuf, StackError> {
        let (_, h, w) = stack.data.dim();
        let pitch = (self.image.dim() == (h, w)
            && !stack.meta.is_unstated(crate::stack::Unstated::PixelPitch))
        .then_some(stack.meta.pixel_pitch_cm);
        let tif = dir.join("reconstruction.ome.tif");
        crate::formats::ome_tiff::write_image(self.image.mapv(|v| v as f32).view(), pitch, &tif)?;
        Ok(tif)
    }

    /// How many of the run's notes warn (begin `warning:`: an output
    /// that explains the counts far worse than Poisson noise allows, ...):
    /// the command's exit status 4 when any.
    pub fn warnings(&self) -> usize {
        self.trace
            .notes
            .iter()
            .filter(|n| n.starts_with("warning:"))
            .count()
    }

    /// What the run did, one line each: the method and prior, iterations
    /// and time, its notes from the `skip`-th on, and with a truth the
    /// output's PSNR and SSIM and the best iteration by truth.
    pub fn summary(&self, skip: usize, truth: Option<ArrayView2<f64>>) -> Vec<String> {
        let t = &self.trace;
        let last = t.rows.last();
        let mut lines = vec![format!(
            "{}{}: {} iterations in {:.2} s",
            t.method,
            t.prior
                .as_ref()
                .map_or(String::new(), |p| format!(" with prior {p}")),
            last.map_or(0, |r| r.iteration),
            t.wall_s
        )];
        lines.extend(t.notes.iter().skip(skip).map(|n| format!("  {n}")));
        if let (Some(truth), Some(best)) = (truth, t.best_psnr()) {
            lines.push(format!(
                "  output PSNR {:.2} dB, SSIM {:.4}; best iteration by truth: {} ({:.2} dB)",
                metrics::psnr(self.image.view(), truth),
                metrics::ssim(self.image.view(), truth),
                best.iteration,
                best.psnr.unwrap_or(f64::NAN)
            ));
        }
        lines
    }
}

/// What a method returns to its run: the estimate on the sensor window and
/// the iteration it comes from.
#[derive(Debug, Clone)]
pub struct Estimate {
    /// The estimate (checked and clamped to >= 0 by [`Run::finish`]).
    pub image: Array2<f64>,
    /// The iteration it was taken at.
    pub iteration: usize,
}

/// The sizes a method's working memory depends on: the bins it sees and
/// the model's sensor, grid and kernel spectra.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WorkShape {
    /// Bins of data the method sees.
    pub bins: usize,
    /// Sensor pixels (rows x columns).
    pub sensor: usize,
    /// Object grid (rows, columns).
    pub grid: (usize, usize),
    /// Complex values of one kernel spectrum.
    pub spectrum: usize,
}

impl WorkShape {
    /// The shape of `bins` bins of data on `model`.
    pub fn new(model: &ForwardModel, bins: usize) -> Self {
        let (h, w) = model.sensor_shape();
        Self {
            bins,
            sensor: h * w,
            grid: model.grid_shape(),
            spectrum: model.fft().spectrum_len(),
        }
    }

    /// `per_bin` bytes for every bin plus `shared` bytes, as vectors of
    /// the shape's sizes: each coefficient counts bytes per sensor pixel,
    /// grid pixel and spectrum value.
    pub fn bytes(&self, per_bin: [u64; 3], shared: [u64; 3]) -> u64 {
        let of = |[sensor, grid, spectrum]: [u64; 3]| {
            (sensor.saturating_mul(self.sensor as u64))
                .saturating_add(grid.saturating_mul((self.grid.0 * self.grid.1) as u64))
                .saturating_add(spectrum.saturating_mul(self.spectrum as u64))
        };
        of(per_bin)
            .saturating_mul(self.bins as u64)
            .saturating_add(of(shared))
    }
}

/// A reconstruction method: Richardson-Lucy, PnP-ADMM, ...
pub trait Reconstructor {
    /// The method's name in traces for `bins` bins of data (e.g. `rl` on
    /// one bin, `rl-sum` on several).
    fn name(&self, bins: usize) -> &'static str;

    /// Reconstructs the object from `data`, reporting every iteration and
    /// note to `run`.
    fn reconstruct(&self, data: &Data<'_>, run: &mut Run<'_>)
    -> Result<Estimate, ReconstructError>;

    /// The most bytes the method holds at once beyond its data and model
    /// (its state, scratch, trace and prior) on data of `shape`: the
    /// planner checks them against the memory budget before it runs.
    fn working_bytes(&self, shape: &WorkShape) -> u64;

    /// Runs the method on `data`: scores every iteration against `truth`
    /// when given, shows each trace row to `on_iter` as it is produced, and
    /// returns the checked image with its trace.
    fn run(
        &self,
        data: &Data<'_>,
        truth: Option<ArrayView2<'_, f64>>,
        on_iter: &mut dyn FnMut(&TraceRow),
    ) -> Result<Reconstruction, ReconstructError> {
        let mut run = Run::new(self.name(data.bins.len()), truth, on_iter);
        let estimate = self.reconstruct(data, &mut run)?;
        run.finish(estimate)
    }
}

/// One method's run: its trace, its clock, and the truth it is scored on.
pub struct Run<'a> {
    trace: Trace,
    start: Instant,
    truth: Option<ArrayView2<'a, f64>>,
    on_iter: &'a mut dyn FnMut(&TraceRow),
}

impl<'a> Run<'a> {
    /// A run of `method`, started now.
    pub fn new(
        method: &str,
        truth: Option<ArrayView2<'a, f64>>,
        on_iter: &'a mut dyn FnMut(&TraceRow),
    ) -> Self {
        Self {
            trace: Trace::new(method),
            start: Instant::now(),
            truth,
            on_iter,
        }
    }

    /// A run of a part of this one (a start, a candidate): its rows reach
    /// the caller as they come, timed from this run's start and scored
    /// against the truth when `scored`; its trace is its own
    /// ([`Run::into_trace`]).
    pub fn sub_run(&mut self, method: &str, scored: bool) -> Run<'_> {
        Run {
            trace: Trace::new(method),
            start: self.start,
            truth: if scored { self.truth } else { None },
            on_iter: &mut *self.on_iter,
        }
    }

    /// The trace so far.
    pub fn into_trace(self) -> Trace {
        self.trace
    }

    /// Takes a sub-run's trace as this run's own (its rows, prior and
    /// notes), after `notes` of this run's own.
    pub fn adopt(&mut self, trace: Trace, notes: Vec<String>) {
        self.trace.rows = trace.rows;
        self.trace.prior = trace.prior;
        self.trace.notes.extend(notes);
        self.trace.notes.extend(trace.notes);
    }

    /// Seconds since the run started.
    pub fn elapsed_s(&self) -> f64 {
        self.start.elapsed().as_secs_f64()
    }

    /// Whether rows are scored against a truth (else estimates need not be
    /// formed for scoring).
    pub fn scores(&self) -> bool {
        self.truth.is_some()
    }

    /// A row for `iteration`, stamped with the time since the start.
    pub fn row(&self, iteration: usize) -> TraceRow {
        TraceRow {
            iteration,
            wall_s: self.elapsed_s(),
            ..Default::default()
        }
    }

    /// Fills the truth-dependent columns of `row`, scoring the estimate
    /// clamped to >= 0 as every method outputs it.
    pub fn score(&self, row: &mut TraceRow, estimate: ArrayView2<f64>) {
        if let Some(t) = self.truth {
            let clamped = estimate.mapv(|v| v.max(0.0));
            row.psnr = Some(metrics::psnr(clamped.view(), t));
            row.ssim = Some(metrics::ssim(clamped.view(), t));
        }
    }

    /// Shows `row` to the caller's callback and appends it to the trace.
    pub fn push(&mut self, row: TraceRow) {
        (self.on_iter)(&row);
        self.trace.rows.push(row);
    }

    /// The rows so far.
    pub fn rows(&self) -> &[TraceRow] {
        &self.trace.rows
    }

    /// Adds a note to the trace (what was assumed, left out, why it stopped).
    pub fn note(&mut self, note: impl Into<String>) {
        self.trace.notes.push(note.into());
    }

    /// Records the prior the method uses.
    pub fn set_prior(&mut self, prior: String) {
        self.trace.prior = Some(prior);
    }

    /// Says in the trace which background the likelihood holds, if any.
    pub fn note_background(&mut self, model: &ForwardModel) {
        let bg = model.background();
        if bg > 0.0 {
            self.note(format!(
                "background: {bg:.4e} counts per pixel and bin in the likelihood"
            ));
        }
    }

    /// The result for data without a single photon: the estimate is 0 and
    /// no iteration can change it.
    pub fn no_photons(&mut self, shape: (usize, usize)) -> Estimate {
        self.note("no photons: the maximum-likelihood object is 0 and no iteration can change it");
        let image = Array2::zeros(shape);
        let mut row = TraceRow::default();
        self.score(&mut row, image.view());
        self.trace.rows.push(row);
        Estimate {
            image,
            iteration: 0,
        }
    }

    /// The checked output: the estimate clamped to >= 0, or an error naming
    /// the iteration if any value is not finite.
    pub fn finish(mut self, estimate: Estimate) -> Result<Reconstruction, ReconstructError> {
        self.trace.wall_s = self.elapsed_s();
        if estimate.image.iter().any(|v| !v.is_finite()) {
            return Err(ReconstructError::NonFinite {
                method: self.trace.method,
                iteration: estimate.iteration,
            });
        }
        Ok(Reconstruction {
            image: estimate.image.mapv(|v| v.max(0.0)),
            trace: self.trace,
        })
    }

    /// An error for a non-finite value at `iteration` of this run.
    pub fn non_finite(&self, iteration: usize) -> ReconstructError {
        ReconstructError::NonFinite {
            method: self.trace.method.clone(),
            iteration,
        }
    }
}

/// What the model assumes of the sensor's edges, for a trace note.
pub fn grid_note(model: &ForwardModel) -> String {
    let (h, w) = model.sensor_shape();
    let (gh, gw) = model.grid_shape();
    match model.boundary() {
        Boundary::Periodic => {
            format!("boundary: periodic (wrap-around) on the {h} x {w} sensor grid")
        }
        Boundary::Sensor => format!(
            "boundary: sensor with edges; object estimated on a {gh} x {gw} grid, {} px beyond each sensor edge (the kernels carry < {:e} of their light farther out; farther object points left out), output is the {h} x {w} sensor window",
            model.margin(),
            crate::forward::EDGE_TAIL
        ),
    }
}
