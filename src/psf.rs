//! The ST-PSF of a setup as `psf` reports it: the kernels in both
//! discretisations (pixel- and bin-integrated, and point samples at the
//! centres), their per-bin table with the relative L1 difference between
//! the two, and the kernel stack written as a file.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use ndarray::ArrayView2;

use crate::formats::png::{SheetScale, write_contact_sheet};
use crate::physics::{KernelStack, ParamError, Sampling, Setup};
use crate::stack::{Stack, StackError, StackMeta, ValueKind};

/// The kernels of one setup in the chosen discretisation, compared with
/// the other where that is possible.
pub struct PsfReport {
    /// Pixel- and bin-integrated kernels.
    pub integrated: KernelStack,
    /// Point-sampled kernels; `None` with an instrument response (point
    /// samples cannot model one).
    pub point: Option<KernelStack>,
    /// The discretisation written.
    pub sampling: Sampling,
    /// Build time of each (integrated, point), seconds.
    pub seconds: (f64, Option<f64>),
}

/// Why the kernels cannot be reported.
#[derive(Debug, thiserror::Error)]
pub enum PsfError {
    /// More memory than the budget.
    #[error(transparent)]
    Memory(#[from] crate::memory::MemoryError),
    /// The physics is invalid.
    #[error(transparent)]
    Param(#[from] ParamError),
    /// No bin carries enough light to be kept.
    #[error("no bin carries at least {0} photons")]
    NoBins(f64),
    /// A file could not be written.
    #[error(transparent)]
    Output(#[from] StackError),
}

impl PsfReport {
    /// Builds both discretisations of `setup` (the point samples only
    /// without an instrument response, unless `sampling` asks for them).
    pub fn build(setup: &Setup, sampling: Sampling) -> Result<Self, PsfError> {
        setup.validate()?;
        crate::memory::check_setup(setup, crate::memory::PSF_BYTES, "the ST-PSF")?;
        let timed = |sampling| -> Result<(KernelStack, f64), ParamError> {
            let t = Instant::now();
            let k = KernelStack::build(setup, sampling)?;
            Ok((k, t.elapsed().as_secs_f64()))
        };
        let (integrated, t_int) = timed(Sampling::Integrated)?;
        let monte_carlo = setup.medium.model == scatterscope_physics::MediumModel::MonteCarlo;
        let point = match (&setup.irf, sampling) {
            (Some(_), Sampling::Integrated) => None,
            // Transport records each bin's light whole: no point samples.
            (None, Sampling::Integrated) if monte_carlo => None,
            _ => Some(timed(Sampling::Point)?),
        };
        Ok(Self {
            integrated,
            seconds: (t_int, point.as_ref().map(|p| p.1)),
            point: point.map(|p| p.0),
            sampling,
        })
    }

    /// The kernels written.
    pub fn chosen(&self) -> &KernelStack {
        match (&self.point, self.sampling) {
            (Some(p), Sampling::Point) => p,
            _ => &self.integrated,
        }
    }

    /// Relative L1 difference between the point-sampled and the integrated
    /// kernel of setup bin `index`, when both were kept.
    pub fn difference(&self, index: usize) -> Option<f64> {
        let point = self.point.as_ref()?;
        let (i, p) = self
            .integrated
            .position_of_bin(index)
            .zip(point.position_of_bin(index))?;
        Some(relative_l1(self.integrated.kernel(i), point.kernel(p)))
    }

    /// The per-bin table as printed text (a header line, then one line per
    /// bin) and as CSV.
    pub fn table(&self) -> (Vec<String>, String) {
        let mut csv = String::from(
            "bin,start_ps,end_ps,photons,kept,sigma_px,peak,support_radius_px,time_nodes,point_vs_integrated_rel_l1,monte_carlo_relative_error\n",
        );
        let mut lines = vec![format!(
            "{:>3} {:>13} {:>10} {:>5} {:>8} {:>10} {:>7} {:>5} {:>10} {:>8}",
            "bin",
            "time ps",
            "photons",
            "kept",
            "sigma px",
            "peak",
            "support",
            "nodes",
            "point-int",
            "MC error"
        )];
        for b in &self.chosen().bins {
            let diff = self.difference(b.index);
            lines.push(format!(
                "{:>3} {:>6.1}-{:<6.1} {:>10.4} {:>5} {:>8.3} {:>10.3e} {:>7} {:>5} {:>10} {:>8}",
                b.index,
                b.start_ps,
                b.end_ps,
                b.photons,
                b.kept,
                b.sigma_px,
                b.peak,
                b.support_radius_px,
                b.time_nodes,
                diff.map_or("-".to_string(), |d| format!("{d:.2e}")),
                b.relative_error
                    .map_or("-".to_string(), |e| format!("{:.2} %", 100.0 * e))
            ));
            writeln!(
                csv,
                "{},{},{},{},{},{},{},{},{},{},{}",
                b.index,
                b.start_ps,
                b.end_ps,
                b.photons,
                b.kept,
                b.sigma_px,
                b.peak,
                b.support_radius_px,
                b.time_nodes,
                diff.map_or(String::new(), |d| d.to_string()),
                b.relative_error.map_or(String::new(), |e| e.to_string())
            )
            .expect("writing to a String");
        }
        (lines, csv)
    }

    /// Run times and the largest difference between the discretisations.
    pub fn comparison(&self) -> Vec<String> {
        let t_int = self.seconds.0;
        let Some(point) = &self.point else {
            let why = if self.integrated.setup.medium.model
                == scatterscope_physics::MediumModel::MonteCarlo
            {
                "transport records each bin's light whole"
            } else {
                "it cannot model the instrument response"
            };
            return vec![format!(
                "run time: integrated {:.1} ms; point sampling not compared ({why}); written: integrated",
                t_int * 1e3
            )];
        };
        let worst = self
            .chosen()
            .bins
            .iter()
            .filter_map(|b| self.difference(b.index).map(|d| (d, b.index)))
            .fold((0.0, 0), |w, d| if d.0 > w.0 { d } else { w });
        let mut lines = vec![format!(
            "run time: integrated {:.1} ms, point {:.1} ms; largest point-vs-integrated relative L1 difference {:.3e} (bin {}); written: {}",
            t_int * 1e3,
            self.seconds.1.unwrap_or(0.0) * 1e3,
            worst.0,
            worst.1,
            self.sampling.name()
        )];
        if point.len() != self.integrated.len() {
            lines.push(format!(
                "note: point sampling keeps {} bins, integrated keeps {}",
                point.len(),
                self.integrated.len()
            ));
        }
        lines
    }

    /// Writes `psf.exr` (the chosen kernels, centred, as a stack),
    /// `psf_bins.csv` and `psf_sheet.png` into `dir`; returns the files.
    pub fn write(&self, dir: &Path, scale: SheetScale) -> Result<Vec<PathBuf>, PsfError> {
        let chosen = self.chosen();
        if chosen.is_empty() {
            return Err(PsfError::NoBins(chosen.setup.min_bin_photons));
        }
        std::fs::create_dir_all(dir).map_err(|e| StackError::io(dir, e))?;
        let csv_path = dir.join("psf_bins.csv");
        crate::files::write_atomic(&csv_path, self.table().1)
            .map_err(|e| StackError::io(&csv_path, e))?;
        let stack = Stack::new(
            chosen.kernels.mapv(|v| v as f32),
            StackMeta::simulated(chosen, ValueKind::Kernel, "ST-PSF kernels".into()),
        );
        let exr = dir.join("psf.exr");
        stack.save(&exr)?;
        let sheet = dir.join("psf_sheet.png");
        write_contact_sheet(&stack, scale, &sheet)?;
        Ok(vec![exr, csv_path, sheet])
    }
}

fn relative_l1(a: ArrayView2<f64>, b: ArrayView2<f64>) -> f64 {
    let diff: f64 = a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum();
    diff / a.sum()
}
