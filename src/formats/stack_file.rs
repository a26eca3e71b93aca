//! A stack's file, whichever format: [`Stack::load`] and [`Stack::save`]
//! dispatch on [`Format`] to [`super::exr`] and [`super::npy`]. The
//! methods live here, above [`crate::stack`], so that the stack type does
//! not depend on its formats.

use std::path::Path;

use ndarray::Array3;

use super::detect::Format;
use crate::stack::{CountsView, Stack, StackError, StackFile, StackMeta};

/// Writes photon `counts` with `meta` to `path` as [`Stack::save`] writes
/// their stack, the format following the extension, without a float copy
/// of the counts ([`super::exr::write_counts`], [`super::npy::write_counts`],
/// [`super::ome_tiff::write_counts`]).
pub fn save_counts(counts: CountsView, meta: &StackMeta, path: &Path) -> Result<(), StackError> {
    match Format::of_extension(path) {
        Format::Exr => super::exr::write_counts(counts, meta, path),
        Format::Npy => super::npy::write_counts(counts, meta, path),
        Format::Tiff => super::ome_tiff::write_counts(counts, meta, path),
        _ => Err(StackError::format(
            path,
            "unknown stack format: use a .exr, .npy or .ome.tif file name",
        )),
    }
}

impl Stack {
    /// Writes the stack; the format follows the extension (`.exr` or `.npy`).
    pub fn save(&self, path: &Path) -> Result<(), StackError> {
        match Format::of_extension(path) {
            Format::Exr => super::exr::write(self, path),
            Format::Npy => super::npy::write(self, path),
            Format::Tiff => super::ome_tiff::write_stack(self, path),
            _ => Err(StackError::format(
                path,
                "unknown stack format: use a .exr, .npy or .ome.tif file name",
            )),
        }
    }

    /// Reads and validates a stack with its metadata; the format follows
    /// the file's first bytes, else its extension. A file without metadata
    /// (a plain `.npy`, an EXR from another tool) is refused: read it with
    /// [`Stack::read`] and give the metadata ([`StackMeta::consecutive`]).
    pub fn load(path: &Path) -> Result<Self, StackError> {
        let file = Self::read_file(path)?;
        match file.meta {
            Some(meta) => {
                let mut stack = Self::from_parts(file.data, meta, path)?;
                stack.exact_counts = file.exact_counts;
                Ok(stack)
            }
            None => Err(StackError::format(
                path,
                format!("has no metadata ({})", missing_meta(path)),
            )),
        }
    }

    /// Reads a stack file's values and, when the file has them, its
    /// metadata (the `.npy` sidecar, the EXR attribute); nothing is
    /// validated yet.
    pub fn read(path: &Path) -> Result<(Array3<f32>, Option<StackMeta>), StackError> {
        Self::read_file(path).map(|f| (f.data, f.meta))
    }

    /// [`Stack::read`] with the exact counts when the file stores counts
    /// above 2^24.
    pub fn read_file(path: &Path) -> Result<StackFile, StackError> {
        match Format::of_file(path) {
            Format::Exr => super::exr::read(path),
            Format::Npy => super::npy::read(path),
            Format::Tiff => Err(StackError::format(
                path,
                "OME-TIFF is written for other tools (Fiji, napari, FLIMfit), not read back: give the EXR or .npy stack written beside it",
            )),
            _ => Err(StackError::format(
                path,
                "not a stack: neither its first bytes nor its extension say OpenEXR or NumPy .npy",
            )),
        }
    }
}

/// Where a file of this kind keeps its metadata, for error messages.
pub fn missing_meta(path: &Path) -> String {
    match Format::of_file(path) {
        Format::Npy => format!("no sidecar {}", super::npy::sidecar_path(path).display()),
        _ => format!("no `{}` attribute", super::exr::META_ATTRIBUTE),
    }
}
