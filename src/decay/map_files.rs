//! What the decay maps (`lifetime`) and the fits (`fit`) write alike:
//! each stack's file names, the refusal to overwrite an input, the
//! channels as a float32 OME-TIFF and `.npy`, and the lifetime image
//! coloured and weighted by photons.

use std::path::{Path, PathBuf};

use ndarray::{Array2, Array3, ArrayView2, Axis};

use crate::files::input::same_file;
use crate::plot::quantile;
use crate::stack::{StackError, StackMeta, Unstated};
use crate::tags::binned::StackCounts;

/// The tail of stack `s`'s file names: `_f000`, ... when the file gives
/// several stacks, else nothing.
pub(crate) fn stack_tail(s: &StackCounts<'_>) -> String {
    if s.of > 1 {
        format!("_f{:03}", s.index)
    } else {
        String::new()
    }
}

/// The note that says which bins a stack's maps or fit keep by default:
/// those the instrument recorded whole ([`crate::stack::RecordedBins`]),
/// or every bin when `all_bins` asks; `None` when the recording states
/// nothing.
pub(crate) fn recorded_note(meta: &StackMeta, all_bins: bool) -> Option<String> {
    let r = meta.recorded_bins.as_ref()?;
    let bins = meta.bin_starts_ps.len();
    Some(if all_bins {
        format!(
            "every bin kept (asked), also those outside {}",
            r.describe(bins)
        )
    } else {
        format!(
            "time window {}; the other bins left out (--all-bins keeps them)",
            r.describe(bins)
        )
    })
}

/// A note on outputs of an earlier run left in `dir` beside stack `s`'s
/// (named `{stem}.npy` or `{stem}_fNNN.npy`): the single stack's name
/// beside several stacks', or a stack past this run's last. They are left
/// as they are.
pub(crate) fn stale_note(dir: &Path, stem: &str, s: &StackCounts<'_>) -> Option<String> {
    let other = if s.of > 1 {
        (s.index == 0).then(|| dir.join(format!("{stem}.npy")))
    } else {
        Some(dir.join(format!("{stem}_f000.npy")))
    };
    let past =
        (s.index + 1 == s.of && s.of > 1).then(|| dir.join(format!("{stem}_f{:03}.npy", s.of)));
    let found: Vec<String> = other
        .into_iter()
        .chain(past)
        .filter(|p| p.exists())
        .map(|p| p.display().to_string())
        .collect();
    (!found.is_empty()).then(|| {
        format!(
            "{} in the folder come from an earlier run (not this file's stacks): left as they are",
            found.join(", ")
        )
    })
}

/// Refuses to write any of `files` that is one of `reads` (by identity,
/// not spelling).
pub(crate) fn refuse_inputs(files: &[PathBuf], reads: &[PathBuf]) -> Result<(), StackError> {
    if let Some(f) = files.iter().find(|f| reads.iter().any(|r| same_file(f, r))) {
        return Err(StackError::format(
            f,
            "is a file the command reads: writing it would destroy it; choose another --out",
        ));
    }
    // Each output's place, checked before the first is written (a folder
    // named as one was found only after the others were written).
    for f in files {
        crate::files::output::check_destination(f).map_err(|e| StackError::io(f, e))?;
    }
    Ok(())
}

/// A stack's metadata as a sidecar states it: a pitch the recording did
/// not state is null, not the placeholder.
pub(crate) fn stated_meta(meta: &StackMeta) -> serde_json::Value {
    let mut v = serde_json::to_value(meta).expect("the metadata serialises");
    if meta.is_unstated(Unstated::PixelPitch) {
        v["pixel_pitch_cm"] = serde_json::Value::Null;
    }
    v
}

/// Writes the named `channels` (each rows x columns) as float32 planes:
/// `tif` (OME-TIFF, one named channel each, the pixel size when `meta`
/// states it) and `npy` (channels x rows x columns), each whole or not at
/// all.
pub(crate) fn write_channels(
    channels: &[(String, ArrayView2<'_, f64>)],
    meta: &StackMeta,
    tif: &Path,
    npy: &Path,
) -> Result<(), StackError> {
    let (h, w) = channels.first().map_or((0, 0), |(_, m)| m.dim());
    let mut stacked = Array3::<f32>::zeros((channels.len(), h, w));
    for (mut plane, (_, m)) in stacked.axis_iter_mut(Axis(0)).zip(channels) {
        plane.zip_mut_with(m, |p, &v| *p = v as f32);
    }
    let pitch = (!meta.is_unstated(Unstated::PixelPitch)).then_some(meta.pixel_pitch_cm);
    let named: Vec<(String, ArrayView2<f32>)> = channels
        .iter()
        .zip(stacked.axis_iter(Axis(0)))
        .map(|((n, _), p)| (n.clone(), p))
        .collect();
    crate::formats::ome_tiff::write_named_images(&named, pitch, tif)?;
    crate::formats::npy::write_array(&stacked, npy)
}

/// The finite values of `values` where `mask` is false.
pub(crate) fn unmasked_finite(values: &Array2<f64>, mask: &Array2<bool>) -> Vec<f64> {
    values
        .iter()
        .zip(mask)
        .filter(|(v, m)| !**m && v.is_finite())
        .map(|(v, _)| *v)
        .collect()
}

/// A lifetime image to draw.
pub(crate) struct LifetimeImage<'a> {
    /// The lifetimes, NaN where masked (drawn black).
    pub values: ArrayView2<'a, f64>,
    /// Their unmasked, finite values.
    pub unmasked: &'a [f64],
    /// Photons per pixel: the brightness.
    pub photons: &'a Array2<f64>,
    /// The title.
    pub title: &'a str,
    /// The colour bar's label.
    pub bar_label: &'a str,
}

/// Draws `image` to `path`: colours spanning the 2nd to 98th percentile of
/// the unmasked lifetimes, brightness the photons up to their 99th
/// percentile, with its colour bar.
pub(crate) fn draw_lifetime(path: &Path, image: &LifetimeImage<'_>) -> Result<(), StackError> {
    let unmasked = image.unmasked;
    let range = match (
        quantile(unmasked.to_vec(), 0.02),
        quantile(unmasked.to_vec(), 0.98),
    ) {
        (Some(a), Some(b)) if b > a => (a, b),
        (Some(a), _) => (a - 1.0, a + 1.0),
        _ => (0.0, 1.0),
    };
    let top = quantile(image.photons.iter().copied().collect(), 0.99)
        .filter(|t| *t > 0.0)
        .unwrap_or(1.0);
    let brightness = image.photons.mapv(|n| (n / top).min(1.0));
    crate::plot::coloured_map(
        path,
        &crate::plot::ColouredMap {
            values: image.values,
            brightness: brightness.view(),
            range,
            title: image.title,
            bar_label: image.bar_label,
        },
    )
    .map_err(|e| StackError::format(path, format!("drawing: {e}")))
}
