//! MATLAB v7.3 files (HDF5 inside), read with the pure-Rust `hdf5-reader`,
//! so no system HDF5 library is needed. Errors are messages without the
//! path; callers name the file.

use std::path::Path;

use hdf5_reader::{Dataset, Hdf5File, OpenOptions};

/// Decoded bytes a dataset may hold per byte of its file, past
/// [`FREE_DECODED_BYTES`]: the shared confocal scans decode to 4.5-7 times
/// their file, and deflate cannot pass about 1000; a file that claims more
/// is a decompression bomb or declares data it does not store.
pub const MAX_EXPANSION: u64 = 64;
/// Decoded bytes any dataset may hold, whatever its file's size.
pub const FREE_DECODED_BYTES: u64 = 64 << 20;

/// An open MATLAB v7.3 file and its size.
pub struct MatFile {
    file: Hdf5File,
    bytes: u64,
}

impl std::ops::Deref for MatFile {
    type Target = Hdf5File;
    fn deref(&self) -> &Hdf5File {
        &self.file
    }
}

/// Opens a MATLAB v7.3 file after checking it is a regular file that fits
/// the memory budget and is not cut short. Reads keep no cache of their
/// own (the reader's chunk cache and its copy of hot arrays are off), and
/// no read may decode more than the budget.
pub fn open(path: &Path) -> Result<MatFile, String> {
    let (_, meta) = crate::files::open_regular(path, "MATLAB file").map_err(|e| e.to_string())?;
    crate::memory::check(meta.len(), || format!("reading {}", path.display()))
        .map_err(|e| e.to_string())?;
    if let Some(declared) = hdf5_declared_size(path)
        && declared > meta.len()
    {
        return Err(format!(
            "the file is cut: it holds {} bytes of the {declared} its HDF5 superblock declares",
            meta.len()
        ));
    }
    let budget = crate::memory::budget().map_err(|e| e.to_string())?;
    let options = OpenOptions::default()
        .with_chunk_cache_bytes(0)
        .with_max_read_bytes(usize::try_from(budget.bytes).unwrap_or(usize::MAX));
    let file = Hdf5File::open_with_options(path, options).map_err(|e| {
        format!(
            "not a MATLAB v7.3 (HDF5) file: {e} (older MATLAB formats are not read; save with -v7.3)"
        )
    })?;
    Ok(MatFile {
        file,
        bytes: meta.len(),
    })
}

/// Dataset `name` of `file`; the error lists the datasets there are, or
/// says the file's structure cannot be read when it lists none.
pub fn dataset(file: &MatFile, name: &str) -> Result<Dataset, String> {
    file.dataset(&format!("/{name}")).map_err(|e| {
        let names = file
            .root_group()
            .and_then(|g| g.member_names())
            .map(|(_, d)| d.join(", "))
            .unwrap_or_default();
        if names.is_empty() {
            format!(
                "no dataset `{name}`, and no dataset can be listed ({e}): the file is damaged or not a MATLAB v7.3 file"
            )
        } else {
            format!("no dataset `{name}` (datasets in the file: {names})")
        }
    })
}

/// The numbers of a dataset of `file` (floating point or integer, as
/// MATLAB stores counts) in the order HDF5 stores them (C order over
/// `ds.shape()`). Before anything is decoded, the dataset's decoded size
/// is held to [`MAX_EXPANSION`] times the file's (past
/// [`FREE_DECODED_BYTES`]), and what the read allocates (the decoded
/// values, their copy as numbers, and the caller's reordered copy) to the
/// memory budget.
pub fn numbers(file: &MatFile, ds: &Dataset) -> Result<Vec<f64>, String> {
    use hdf5_reader::messages::datatype::Datatype;
    fn all<T: hdf5_reader::H5Type + Copy>(
        ds: &Dataset,
        to: impl Fn(T) -> f64,
    ) -> Result<Vec<f64>, String> {
        ds.read_array::<T>()
            .map(|a| a.iter().map(|&v| to(v)).collect())
            .map_err(|e| e.to_string())
    }
    let elements: u64 = ds.shape().iter().fold(1u64, |n, &d| n.saturating_mul(d));
    let item = ds
        .raw_element_size()
        .map_or(8, |n| u64::try_from(n.max(1)).unwrap_or(u64::MAX));
    let decoded = elements.saturating_mul(item);
    let most = FREE_DECODED_BYTES.max(file.bytes.saturating_mul(MAX_EXPANSION));
    if decoded > most {
        return Err(format!(
            "the dataset of shape {:?} would decode to {} from a file of {}, more than {MAX_EXPANSION} times its size: a compressed file this far past what counts compress to is damaged or forged (a decompression bomb), or declares data it does not store",
            ds.shape(),
            crate::memory::size(decoded),
            crate::memory::size(file.bytes)
        ));
    }
    // The raw bytes and the decoded values (the item size each), the
    // numbers and the caller's reordered copy (8 bytes each).
    crate::memory::check(
        elements.saturating_mul(item.saturating_mul(2).saturating_add(16)),
        || format!("a dataset of shape {:?}", ds.shape()),
    )
    .map_err(|e| e.to_string())?;
    match *ds.dtype() {
        Datatype::FloatingPoint { size: 8, .. } => all::<f64>(ds, |v| v),
        Datatype::FloatingPoint { size: 4, .. } => all::<f32>(ds, f64::from),
        Datatype::FixedPoint { size, signed, .. } => match (size, signed) {
            (1, false) => all::<u8>(ds, f64::from),
            (2, false) => all::<u16>(ds, f64::from),
            (4, false) => all::<u32>(ds, f64::from),
            (8, false) => all::<u64>(ds, |v| v as f64),
            (2, true) => all::<i16>(ds, f64::from),
            (4, true) => all::<i32>(ds, f64::from),
            (8, true) => all::<i64>(ds, |v| v as f64),
            _ => Err(format!(
                "{size}-byte integers (signed: {signed}) are not read"
            )),
        },
        ref other => Err(format!("type {other:?} is not a number")),
    }
}

/// The size an HDF5 file declares (its superblock's end-of-file address),
/// when the file starts with an HDF5 superblock
/// where one may sit (byte 0, or after a user block of 512, 1024 or 2048
/// bytes, as MATLAB v7.3 writes them).
fn hdf5_declared_size(path: &Path) -> Option<u64> {
    const SIGNATURE: &[u8; 8] = b"\x89HDF\r\n\x1a\n";
    let mut head = vec![0u8; 2048 + 64];
    let mut file = std::fs::File::open(path).ok()?;
    let got = std::io::Read::read(&mut file, &mut head).ok()?;
    let head = &head[..got];
    let at = [0usize, 512, 1024, 2048]
        .into_iter()
        .find(|&o| head.get(o..o + 8) == Some(SIGNATURE))?;
    let sb = &head[at..];
    let word = |o: usize, n: usize| -> Option<u64> {
        let b = sb.get(o..o + n)?;
        let mut v = [0u8; 8];
        v[..n].copy_from_slice(b);
        Some(u64::from_le_bytes(v))
    };
    let (offsets, base_at) = match *sb.get(8)? {
        0 => (usize::from(*sb.get(13)?), 24),
        1 => (usize::from(*sb.get(13)?), 28),
        2 | 3 => (usize::from(*sb.get(9)?), 12),
        _ => return None,
    };
    if !(offsets == 4 || offsets == 8) {
        return None;
    }
    // After the base address: the free-space (v0, v1) or extension (v2,
    // v3) address, then the end-of-file address. MATLAB writes it as the
    // file's size, user block included (checked on the shared captures).
    word(base_at + 2 * offsets, offsets)
}
