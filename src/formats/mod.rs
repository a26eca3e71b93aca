//! Every file format scatterscope reads or writes, side by side.
//!
//! Tags (what a source records):
//! - [`sstags`]: the project's tag file, a lossless recording of a live
//!   acquisition (event batches exactly as the device sent them).
//! - [`picoquant`]: PicoQuant PTU and the legacy PT3/HT3/PT2/HT2 files,
//!   read in constant memory, and a PTU writer.
//! - [`becker_hickl`]: Becker & Hickl FIFO files (`.spc`), read in
//!   constant memory, and their histogram files (`.sdt`).
//!
//! Stacks (what binning or simulation makes):
//! - [`exr`]: OpenEXR, one `f32` channel per bin, with the metadata.
//! - [`npy`]: NumPy `.npy` with a JSON sidecar.
//! - [`ome_tiff`]: OME-TIFF out (one page per bin, the lifetime modulo of
//!   T), for Fiji, napari and FLIMfit; also single reconstructions.
//! - [`stack_file`]: by the file: `Stack::load` (EXR, npy), `Stack::save`
//!   (EXR, npy, OME-TIFF).
//!
//! Measurements of other instruments:
//! - [`mat`]: MATLAB v7.3 (HDF5) datasets, e.g. the confocal diffuse
//!   tomography captures and scans.
//!
//! Which is which: [`detect`], by a file's first bytes, then its extension.
//!
//! Images (scenes, truths, reconstructions, previews):
//! - [`image`]: single images in and out (PNG, JPEG, EXR, `.npy`).
//! - [`png`]: 8-bit PNG previews and labelled contact sheets of a stack.

pub mod becker_hickl;
pub mod detect;
pub mod exr;
pub mod image;
pub mod mat;
pub mod npy;
pub mod ome_tiff;
pub mod picoquant;
pub mod png;
pub mod sstags;
pub mod stack_file;
