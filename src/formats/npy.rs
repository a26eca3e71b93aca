//! `.npy` stack files with a JSON sidecar, for Python users.
//!
//! `NAME.npy` holds a C-order (K, H, W) array; `NAME.json` holds the same
//! metadata record as the EXR `scatterscope` attribute. Counts are written as
//! `uint32` when every value is a whole number in range (a recorded file's
//! binned counts as `uint16` when they all fit), everything else as
//! `float32`. Reading accepts float32, float64 and unsigned integer counts.

use std::fs::File;
use std::io::{BufReader, BufWriter, Read};
use std::path::{Path, PathBuf};

use ndarray::Array3;
use ndarray_npy::{ReadNpyExt, WriteNpyExt};

use crate::files::{ReadError, read_bounded};
use crate::memory::bytes_of;
use crate::stack::{CountsView, Stack, StackError, StackFile, StackMeta, ValueKind, counts_as_f32};

/// Largest sidecar read (the metadata of any stack is far smaller).
const MAX_SIDECAR: u64 = 64 << 20;

/// Path of the JSON sidecar that belongs to `npy`.
pub fn sidecar_path(npy: &Path) -> PathBuf {
    npy.with_extension("json")
}

/// Writes `array` as a bare `.npy` (no sidecar), whole or not at all.
pub fn write_array<A: WriteNpyExt + ?Sized>(array: &A, path: &Path) -> Result<(), StackError> {
    let file = crate::files::AtomicFile::create(path).map_err(|e| StackError::io(path, e))?;
    let mut out = BufWriter::new(file);
    array
        .write_npy(&mut out)
        .map_err(|e| StackError::format(path, format!("writing .npy: {e}")))?;
    crate::files::AtomicFile::commit_buffered(out).map_err(|e| StackError::io(path, e))?;
    Ok(())
}

/// Writes `stack` as `.npy` plus the JSON sidecar.
pub fn write(stack: &Stack, path: &Path) -> Result<(), StackError> {
    let file = crate::files::AtomicFile::create(path).map_err(|e| StackError::io(path, e))?;
    let mut out = BufWriter::new(file);
    let whole_counts = stack.meta.kind == ValueKind::Counts
        && stack
            .data
            .iter()
            .all(|&v| v >= 0.0 && v.fract() == 0.0 && v <= u32::MAX as f32);
    let written = if let Some(counts) = &stack.exact_counts {
        counts.write_npy(&mut out)
    } else if whole_counts {
        stack.data.mapv(|v| v as u32).write_npy(&mut out)
    } else {
        stack.data.write_npy(&mut out)
    };
    written.map_err(|e| StackError::format(path, format!("writing .npy: {e}")))?;
    crate::files::AtomicFile::commit_buffered(out).map_err(|e| StackError::io(path, e))?;
    write_sidecar(&stack.meta, path)
}

/// Writes photon `counts` with `meta` as `.npy` plus the JSON sidecar, in
/// the narrowest unsigned type that holds every count (16 or 32 bits):
/// a recorded file's 16-bit histograms go out as they came in, without a
/// wider copy.
pub fn write_counts(counts: CountsView, meta: &StackMeta, path: &Path) -> Result<(), StackError> {
    let file = crate::files::AtomicFile::create(path).map_err(|e| StackError::io(path, e))?;
    let mut out = BufWriter::with_capacity(1 << 20, file);
    let written = match counts {
        CountsView::U16(c) => c.write_npy(&mut out),
        CountsView::U32(c) if counts.max() <= u32::from(u16::MAX) => {
            c.mapv(|v| v as u16).write_npy(&mut out)
        }
        CountsView::U32(c) => c.write_npy(&mut out),
    };
    written.map_err(|e| StackError::format(path, format!("writing .npy: {e}")))?;
    crate::files::AtomicFile::commit_buffered(out).map_err(|e| StackError::io(path, e))?;
    write_sidecar(meta, path)
}

/// Writes `meta` as the JSON sidecar of the `.npy` file `path`.
fn write_sidecar(meta: &StackMeta, path: &Path) -> Result<(), StackError> {
    let side = sidecar_path(path);
    let json = serde_json::to_string_pretty(meta).expect("metadata serialises");
    crate::files::write_atomic(&side, json).map_err(|e| StackError::io(&side, e))
}

/// Reads a `.npy` array of shape (K, H, W) and its JSON sidecar when there
/// is one (a plain `np.save` array has none).
pub fn read(path: &Path) -> Result<StackFile, StackError> {
    let side = sidecar_path(path);
    let meta = match read_bounded(&side, MAX_SIDECAR, "stack's JSON sidecar") {
        Ok(json) => Some(
            serde_json::from_slice::<StackMeta>(&json)
                .map_err(|e| StackError::format(&side, format!("metadata: {e}")))?,
        ),
        Err(ReadError::Io { source, .. }) if source.kind() == std::io::ErrorKind::NotFound => None,
        Err(e) => return Err(e.into()),
    };
    let (descr, _) = checked_header(path, 3)?;
    let open = || {
        File::open(path)
            .map(BufReader::new)
            .map_err(|e| StackError::io(path, e))
    };
    let npy_err = |e: ndarray_npy::ReadNpyError| StackError::format(path, format!(".npy: {e}"));
    let mut exact = None;
    let data: Array3<f32> = match descr.as_str() {
        "<f4" => Array3::<f32>::read_npy(open()?).map_err(npy_err)?,
        "<f8" => Array3::<f64>::read_npy(open()?)
            .map_err(npy_err)?
            .mapv(|v| v as f32),
        "|u1" => Array3::<u8>::read_npy(open()?)
            .map_err(npy_err)?
            .mapv(f32::from),
        "<u2" => Array3::<u16>::read_npy(open()?)
            .map_err(npy_err)?
            .mapv(f32::from),
        "<u4" | "<u8" => {
            let counts = if descr == "<u4" {
                Array3::<u32>::read_npy(open()?).map_err(npy_err)?
            } else {
                exact_counts(path, Array3::<u64>::read_npy(open()?).map_err(npy_err)?)?
            };
            let data;
            (data, exact) = counts_as_f32(counts.view());
            data
        }
        other => {
            return Err(StackError::format(
                path,
                format!(
                    "dtype `{other}` is not supported; use float32, float64 or unsigned integers (little-endian)"
                ),
            ));
        }
    };
    Ok(StackFile {
        data,
        meta,
        exact_counts: exact,
    })
}

/// 64-bit counts as 32-bit ones, refusing any above 2^32 - 1.
fn exact_counts(path: &Path, counts: Array3<u64>) -> Result<Array3<u32>, StackError> {
    if let Some(big) = counts.iter().find(|&&c| c > u64::from(u32::MAX)) {
        return Err(StackError::format(
            path,
            format!(
                "count {big} exceeds {}, the largest count a stack holds",
                u32::MAX
            ),
        ));
    }
    Ok(counts.mapv(|c| c as u32))
}

/// The `descr` and `shape` of a `.npy` file of `ndim` dimensions, after
/// checking that the file holds every byte its shape needs and that the
/// array, its conversion and a float32 copy fit the memory budget: before
/// anything is allocated for them.
pub(crate) fn checked_header(path: &Path, ndim: usize) -> Result<(String, Vec<usize>), StackError> {
    let (descr, shape, data_start) = read_header(path)?;
    check_size(path, &descr, &shape, data_start, Some(ndim))?;
    let item: u64 = descr.get(2..).and_then(|n| n.parse().ok()).unwrap_or(1);
    crate::memory::check(bytes_of(shape.iter().copied(), item + 12), || {
        format!("the {shape:?} array of {}", path.display())
    })
    .map_err(ReadError::from)?;
    Ok((descr, shape))
}

/// Refuses arrays that are not `ndim`-D or whose shape needs more bytes
/// than the file holds after its header.
fn check_size(
    path: &Path,
    descr: &str,
    shape: &[usize],
    data_start: u64,
    ndim: Option<usize>,
) -> Result<(), StackError> {
    if let Some(ndim) = ndim
        && shape.len() != ndim
    {
        let what = if ndim == 3 {
            "a stack is a 3-D (bins, rows, columns) array"
        } else {
            "an image is a 2-D (rows, columns) array"
        };
        return Err(StackError::format(path, format!("shape {shape:?}: {what}")));
    }
    let item: u64 = descr.get(2..).and_then(|n| n.parse().ok()).unwrap_or(1);
    let held = std::fs::metadata(path)
        .map_err(|e| StackError::io(path, e))?
        .len()
        .saturating_sub(data_start);
    let needed = shape
        .iter()
        .try_fold(item, |acc, &d| acc.checked_mul(d as u64));
    match needed {
        Some(n) if n <= held => Ok(()),
        _ => Err(StackError::format(
            path,
            format!(
                "shape {shape:?} of `{descr}` needs {} bytes but the file holds {held} after its header",
                needed.map_or("more than 2^64".to_string(), |n| n.to_string())
            ),
        )),
    }
}

/// Any numeric `.npy` array (integers of any width and sign, floats,
/// booleans; either byte order; C or Fortran order) as `f64` in its own
/// shape, after checking that the file holds every byte its shape needs and
/// that the array and its conversion fit the memory budget.
pub fn read_numbers(path: &Path) -> Result<ndarray::ArrayD<f64>, StackError> {
    use ndarray::ArrayD;
    let (descr, shape, data_start) = read_header(path)?;
    check_size(path, &descr, &shape, data_start, None)?;
    let item: u64 = descr.get(2..).and_then(|n| n.parse().ok()).unwrap_or(1);
    crate::memory::check(bytes_of(shape.iter().copied(), item + 8), || {
        format!("the {shape:?} array of {}", path.display())
    })
    .map_err(ReadError::from)?;
    let open = || {
        File::open(path)
            .map(BufReader::new)
            .map_err(|e| StackError::io(path, e))
    };
    let npy_err = |e: ndarray_npy::ReadNpyError| StackError::format(path, format!(".npy: {e}"));
    macro_rules! as_f64 {
        ($t:ty) => {
            ArrayD::<$t>::read_npy(open()?)
                .map_err(npy_err)?
                .mapv(|v| v as f64)
        };
    }
    Ok(match descr.get(1..).unwrap_or("") {
        "f8" => ArrayD::<f64>::read_npy(open()?).map_err(npy_err)?,
        "f4" => as_f64!(f32),
        "i1" => as_f64!(i8),
        "u1" => as_f64!(u8),
        "i2" => as_f64!(i16),
        "u2" => as_f64!(u16),
        "i4" => as_f64!(i32),
        "u4" => as_f64!(u32),
        "i8" => as_f64!(i64),
        "u8" => as_f64!(u64),
        "b1" => ArrayD::<bool>::read_npy(open()?)
            .map_err(npy_err)?
            .mapv(|v| f64::from(u8::from(v))),
        _ => {
            return Err(StackError::format(
                path,
                format!(
                    "dtype `{descr}` is not a real number type (integers, floats and booleans are read)"
                ),
            ));
        }
    })
}

/// The `descr` and `shape` entries of a `.npy` header (e.g. `<f4`,
/// `[20, 256, 256]`) and where the data start.
fn read_header(path: &Path) -> Result<(String, Vec<usize>, u64), StackError> {
    let (mut f, _) = crate::files::open_input(path, "stack")?;
    let mut head = [0u8; 12];
    f.read_exact(&mut head)
        .map_err(|_| StackError::format(path, "too short for a .npy header"))?;
    if &head[..6] != b"\x93NUMPY" {
        return Err(StackError::format(
            path,
            "missing the \\x93NUMPY magic: not a .npy file",
        ));
    }
    let (len, start) = match head[6] {
        1 => (u16::from_le_bytes([head[8], head[9]]) as usize, 10),
        2 | 3 => (
            u32::from_le_bytes([head[8], head[9], head[10], head[11]]) as usize,
            12,
        ),
        v => {
            return Err(StackError::format(
                path,
                format!(".npy format version {v} is not supported"),
            ));
        }
    };
    if !(16..=1 << 20).contains(&len) {
        return Err(StackError::format(
            path,
            format!(".npy header length {len} is implausible"),
        ));
    }
    let mut header = vec![0u8; len];
    let already = &head[start..];
    header[..already.len()].copy_from_slice(already);
    f.read_exact(&mut header[already.len()..])
        .map_err(|_| StackError::format(path, "truncated .npy header"))?;
    let text = String::from_utf8_lossy(&header);
    let after = text
        .split_once("'descr':")
        .map(|(_, rest)| rest.trim_start())
        .ok_or_else(|| StackError::format(path, ".npy header has no 'descr'"))?;
    let descr = after
        .strip_prefix('\'')
        .and_then(|r| r.split_once('\''))
        .map(|(d, _)| d.to_string())
        .ok_or_else(|| StackError::format(path, ".npy header 'descr' is not a string"))?;
    let shape = text
        .split_once("'shape':")
        .and_then(|(_, rest)| rest.trim_start().strip_prefix('('))
        .and_then(|rest| rest.split_once(')'))
        .map(|(dims, _)| {
            dims.split(',')
                .map(str::trim)
                .filter(|d| !d.is_empty())
                .map(str::parse::<usize>)
                .collect::<Result<Vec<_>, _>>()
        })
        .ok_or_else(|| StackError::format(path, ".npy header has no 'shape' tuple"))?
        .map_err(|e| StackError::format(path, format!(".npy header 'shape': {e}")))?;
    Ok((descr, shape, (start + len) as u64))
}
