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
use crate::confocal::volume::{HiddenVolume, Projection};
use crate::plot::{Heatmap, heatmap};

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
    let half_cm = 50.0 * volume.side_m;
    let first_cm = 100.0 * volume.first_depth_m;
    let depth_cm = first_cm + 100.0 * volume.depth_step_m * (nz - 1) as f64;
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
            100.0 * d
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
