//! The files a person reads from a reconstructed hidden volume: the
//! volume (`.npy` with a JSON sidecar, and OpenEXR), the depth map (`.npy`
//! and a PNG), and the three maximum-intensity projections as PNGs on
//! metric axes.

use std::path::{Path, PathBuf};

use ndarray::Array3;
use ndarray_npy::WriteNpyExt;
use serde::Serialize;

use super::ReportError;
use crate::confocal::poisson::PoissonTraceRow;
use crate::confocal::scan::DEFAULT_MAT_DATASET;
use crate::confocal::volume::{HiddenVolume, Projection};
use crate::confocal::{
    ConfocalError, ConfocalScan, HiddenMethod, HiddenResult, PoissonOptions, PublishedOptions,
    SlabOptics, hidden_warnings,
};
use crate::plot::{Heatmap, heatmap};
use crate::units::CM_PER_M;

/// One hidden-object reconstruction as asked for: the scan, its geometry
/// and the method (`scatterscope hidden`'s flags are these fields, their
/// docs the flags' help; lengths are given with their unit).
#[derive(Debug, Clone)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct HiddenRequest {
    /// The scan (.mat, .exr or .npy).
    pub scan: PathBuf,
    /// Side of the scanned square on the slab's face, first to last
    /// point, with its unit (e.g. 0.7m, 63.6cm).
    #[cfg_attr(feature = "cli", arg(long = "scan-side", value_name = "LENGTH", value_parser = crate::units::parse_positive_m))]
    pub side_m: f64,
    /// Slab thickness with its unit (e.g. 1in, 2.54cm).
    #[cfg_attr(feature = "cli", arg(long = "slab-thickness", value_name = "LENGTH", value_parser = crate::units::parse_positive_cm))]
    pub thickness_cm: f64,
    /// The slab's material: a material file (e.g. calibrate-slab's
    /// OUT/material.toml: mu_a, mu_s, g, n). Without it the published foam
    /// fit is assumed (n 1.12, mu_a 0.53 /m, mu_s' 262 /m, z_e 3.6 mm).
    #[cfg_attr(feature = "cli", arg(long, value_name = "FILE"))]
    pub material: Option<PathBuf>,
    /// Bin width of MATLAB files, which do not record it (default unit ps;
    /// e.g. 16ps).
    #[cfg_attr(feature = "cli", arg(long = "bin-width", value_name = "TIME", value_parser = crate::units::parse_ps))]
    pub bin_width_ps: Option<f64>,
    /// Dataset holding the counts in MATLAB files.
    #[cfg_attr(feature = "cli", arg(long, default_value = DEFAULT_MAT_DATASET))]
    pub dataset: String,
    /// Reconstruction method: auto (published, smoothed as the scan's own
    /// noise asks), published, or poisson (slower, and on the shared scans
    /// below auto at every light level; see the guide).
    #[cfg_attr(feature = "cli", arg(long, value_parser = crate::named::choice::<HiddenMethod>(), default_value = "auto"))]
    pub method: HiddenMethod,
    /// Wiener constant of the published method (the authors used 2.5e3
    /// to 2e4 per scene).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = PublishedOptions::default().snr))]
    pub snr: f64,
    /// Keep only this fraction of the photons (binomial thinning, seeded
    /// by --thin-seed): what a shorter exposure of the same scene gives.
    #[cfg_attr(feature = "cli", arg(long, value_name = "FRACTION"))]
    pub thin: Option<f64>,
    /// Seed of --thin.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 1, requires = "thin"))]
    pub thin_seed: u64,
    /// Depth behind the slab to reconstruct, with its unit.
    #[cfg_attr(feature = "cli", arg(long = "depth", value_name = "LENGTH", default_value = "1m", value_parser = crate::units::parse_positive_m))]
    pub depth_m: f64,
}

/// A hidden-object reconstruction done and written.
#[derive(Debug)]
pub struct HiddenDone {
    /// What makes the result doubtful, in words.
    pub warnings: Vec<String>,
    /// The files written.
    pub files: Vec<PathBuf>,
}

/// Why a hidden-object reconstruction failed.
#[derive(Debug, thiserror::Error)]
pub enum HiddenError {
    /// The scan, the material or a setting is unusable.
    #[error(transparent)]
    Confocal(#[from] ConfocalError),
    /// The outputs cannot be written.
    #[error(transparent)]
    Report(#[from] ReportError),
}

impl HiddenRequest {
    /// A request for the scan at `scan`, of a square `side_m` on a side,
    /// through a slab `thickness_cm` thick, every other setting at its
    /// default (those of `scatterscope hidden`).
    pub fn new(scan: PathBuf, side_m: f64, thickness_cm: f64) -> Self {
        Self {
            scan,
            side_m,
            thickness_cm,
            material: None,
            bin_width_ps: None,
            dataset: DEFAULT_MAT_DATASET.into(),
            method: HiddenMethod::Auto,
            snr: PublishedOptions::default().snr,
            thin: None,
            thin_seed: 1,
            depth_m: 1.0,
        }
    }

    /// Opens the scan (thinned as asked), reconstructs the volume with the
    /// slab's optics and writes it into `out`; `say` gets what was read,
    /// assumed and found, in words, as it comes.
    pub fn run(&self, out: &Path, mut say: impl FnMut(String)) -> Result<HiddenDone, HiddenError> {
        let mut scan =
            ConfocalScan::open(&self.scan, &self.dataset, self.bin_width_ps, self.side_m)?;
        if let Some(fraction) = self.thin.filter(|&f| f != 1.0) {
            scan = scan.thinned(fraction, self.thin_seed)?;
        }
        let optics = SlabOptics::for_slab(self.material.as_deref(), self.thickness_cm)?;
        let published = PublishedOptions {
            snr: self.snr,
            depth_m: self.depth_m,
            ..PublishedOptions::default()
        };
        let poisson = PoissonOptions {
            depth_m: self.depth_m,
            ..PoissonOptions::default()
        };
        say(format!("scan: {}", scan.describe()));
        say(match &self.material {
            Some(path) => format!("material: {} ({})", path.display(), optics.describe()),
            None => format!(
                "material: the published foam fit ({}); assumed, not measured here (--material)",
                optics.describe()
            ),
        });
        let started = std::time::Instant::now();
        let method = self.method.reconstructor(&published, &poisson);
        let HiddenResult { volume, trace, .. } = method.reconstruct(&scan, &optics)?;
        let wall_s = started.elapsed().as_secs_f64();
        volume.notes.iter().cloned().for_each(&mut say);
        volume
            .describe_object_depth()
            .into_iter()
            .for_each(&mut say);
        say(format!("reconstructed in {wall_s:.3} s"));
        let warnings = hidden_warnings(&scan, &volume, self.depth_m);
        let files = write_hidden(&volume, trace.as_deref(), out)?;
        Ok(HiddenDone { warnings, files })
    }
}

/// The geometry travelling with a written volume (the JSON sidecar and
/// the EXR's `scatterscope` attribute).
#[derive(Debug, Serialize)]
pub struct VolumeRecord<'a> {
    /// Axis order of the array.
    pub axes: &'a str,
    /// Depth between samples (m).
    pub depth_step_m: f64,
    /// Depth of sample 0 behind the slab's far face (m).
    pub first_depth_m: f64,
    /// Scanned side (m), first to last row and column.
    pub side_m: f64,
    /// What was done and assumed.
    pub notes: &'a [String],
}

/// Writes the volume and its readings into `dir`, and the Poisson
/// method's search as `trace.csv` when there is one; returns the paths.
pub fn write_hidden(
    volume: &HiddenVolume,
    trace: Option<&[PoissonTraceRow]>,
    dir: &Path,
) -> Result<Vec<PathBuf>, ReportError> {
    std::fs::create_dir_all(dir).map_err(|e| ReportError::Io(dir.display().to_string(), e))?;
    let mut written = Vec::new();
    let record = VolumeRecord {
        axes: "depth, row, column",
        depth_step_m: volume.depth_step_m,
        first_depth_m: volume.first_depth_m,
        side_m: volume.side_m,
        notes: &volume.notes,
    };
    let json = serde_json::to_string_pretty(&record).expect("record serialises");
    let data32: Array3<f32> = volume.data.mapv(|v| v as f32);

    let npy = dir.join("volume.npy");
    write_npy(&npy, |f| data32.write_npy(f))?;
    let sidecar = dir.join("volume.json");
    crate::files::write_atomic(&sidecar, &json)
        .map_err(|e| ReportError::Io(sidecar.display().to_string(), e))?;
    let exr = dir.join("volume.exr");
    crate::formats::exr::write_volume(
        data32.view(),
        "volume",
        "z",
        &[
            ("depthStepM", volume.depth_step_m),
            ("firstDepthM", volume.first_depth_m),
            ("scanSideM", volume.side_m),
        ],
        &json,
        &exr,
    )?;
    written.extend([npy, sidecar, exr]);

    let (depth, peak) = volume.depth_map();
    let depth_npy = dir.join("depth.npy");
    write_npy(&depth_npy, |f| depth.write_npy(f))?;
    written.push(depth_npy);

    let (nz, rows, cols) = volume.data.dim();
    let half_cm = 0.5 * CM_PER_M * volume.side_m;
    let first_cm = CM_PER_M * volume.first_depth_m;
    let depth_cm = first_cm + CM_PER_M * volume.depth_step_m * (nz - 1) as f64;
    let x = ("x on the slab (cm)", -half_cm, half_cm);
    let y = ("y on the slab (cm)", -half_cm, half_cm);
    let z = ("depth behind the slab (cm)", first_cm, depth_cm);
    let front = volume.projection(Projection::Front);
    let top = volume.projection(Projection::Top);
    let side = volume.projection(Projection::Side);
    // The depth map shows depth only where the object is (half the
    // brightest point, as the object depth's rule), 0 elsewhere.
    let top_peak = peak.iter().fold(0.0f64, |m, &v| m.max(v));
    let shown_depth = ndarray::Zip::from(&depth).and(&peak).map_collect(|&d, &p| {
        if p >= crate::confocal::volume::OBJECT_LEVEL * top_peak {
            CM_PER_M * d
        } else {
            0.0
        }
    });
    let maps = [
        (
            "mip_front.png",
            "maximum over depth (front view)",
            front.view(),
            x,
            y,
        ),
        ("mip_top.png", "maximum over y (top view)", top.view(), x, z),
        (
            "mip_side.png",
            "maximum over x (side view)",
            side.view(),
            y,
            z,
        ),
        (
            "depth.png",
            "depth of the brightest point (cm; bright = far)",
            shown_depth.view(),
            x,
            y,
        ),
    ];
    debug_assert_eq!(front.dim(), (rows, cols));
    for (name, title, values, x, y) in maps {
        let path = dir.join(name);
        heatmap(
            &path,
            &Heatmap {
                values,
                title,
                x,
                y,
            },
        )
        .map_err(ReportError::Plot)?;
        written.push(path);
    }
    if let Some(trace) = trace {
        let path = dir.join("trace.csv");
        let mut csv = String::from("iteration,wall_s,held_out_deviance\n");
        for r in trace {
            csv.push_str(&format!(
                "{},{:.4},{:.3}\n",
                r.iteration, r.wall_s, r.held_out_deviance
            ));
        }
        crate::files::write_atomic(&path, csv)
            .map_err(|e| ReportError::Io(path.display().to_string(), e))?;
        written.push(path);
    }
    Ok(written)
}

fn write_npy<E: std::fmt::Display>(
    path: &Path,
    write: impl FnOnce(&mut std::io::BufWriter<crate::files::AtomicFile>) -> Result<(), E>,
) -> Result<(), ReportError> {
    let io = |e| ReportError::Io(path.display().to_string(), e);
    let mut out = std::io::BufWriter::new(crate::files::AtomicFile::create(path).map_err(io)?);
    write(&mut out).map_err(|e| io(std::io::Error::other(e.to_string())))?;
    crate::files::AtomicFile::commit_buffered(out)
        .map(|_| ())
        .map_err(io)
}
