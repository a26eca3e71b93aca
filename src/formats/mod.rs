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
//! - [`mat5`]: MATLAB level 5 MAT-files (MATLAB's default before v7.3),
//!   e.g. SPAD-camera cubes as labs publish them; and a writer.
//! - [`lab_array`]: one named numeric array from any of those or `.npy`.
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
pub mod lab_array;
pub mod mat;
pub mod mat5;
pub mod npy;
pub mod ome_tiff;
pub mod picoquant;
pub mod png;
pub mod sstags;
pub mod stack_file;

/// Reads the next `n` fixed-size records into `out` as stored, replacing
/// its contents: straight into the records' buffer, one copy from the
/// page cache (zeroed only when it grows). PicoQuant's and Becker &
/// Hickl's record readers share it.
pub(crate) fn read_records<R: bytemuck::Pod + Default>(
    reader: &mut impl std::io::Read,
    out: &mut Vec<R>,
    n: usize,
) -> std::io::Result<()> {
    out.resize(n, R::default());
    reader.read_exact(bytemuck::cast_slice_mut(out.as_mut_slice()))
}

/// The `part`-th of `parts` consecutive ranges of `records` records of
/// `record_bytes` each, stored from byte `data_offset` of `path`: a
/// buffered reader of the file opened anew at the range's first record,
/// and the range (first record, end). PicoQuant's and Becker & Hickl's
/// record readers share it.
pub(crate) fn open_part(
    path: &std::path::Path,
    data_offset: u64,
    record_bytes: u64,
    records: u64,
    part: usize,
    parts: usize,
) -> std::io::Result<(std::io::BufReader<std::fs::File>, u64, u64)> {
    use std::io::Seek;
    let (part, parts) = (part as u64, parts.max(1) as u64);
    let (first, end) = (records * part / parts, records * (part + 1) / parts);
    let (mut file, _) = crate::files::open_regular(path, "recording")?;
    file.seek(std::io::SeekFrom::Start(data_offset + record_bytes * first))?;
    Ok((std::io::BufReader::with_capacity(1 << 20, file), first, end))
}

/// Little-endian 32-bit records, as stored, in the machine's order.
pub(crate) fn u32_from_le(records: &mut [u32]) {
    if cfg!(target_endian = "big") {
        records.iter_mut().for_each(|r| *r = u32::from_le(*r));
    }
}
