//! `.npy` stack files with a JSON sidecar, for Python users.
//!
//! `NAME.npy` holds a C-order (K, H, W) array; `NAME.json` holds the same
//! metadata record as the EXR `scatterscope` attribute. Counts are written as
//! `uint32` when every value is a whole number in range, everything else as
//! `float32`. Reading accepts float32, float64 and unsigned integer counts.

use std::fs::File;
use std::io::{BufReader, BufWriter, Read};
use std::path::{Path, PathBuf};

use ndarray::Array3;
use ndarray_npy::{ReadNpyExt, WriteNpyExt};

use super::{Stack, StackError, StackMeta, ValueKind};

/// Largest integer every `f32` represents exactly (2^24).
const F32_EXACT_INT: u64 = 1 << 24;

/// Path of the JSON sidecar that belongs to `npy`.
pub fn sidecar_path(npy: &Path) -> PathBuf {
    npy.with_extension("json")
}

/// Writes `stack` as `.npy` plus the JSON sidecar.
pub fn write(stack: &Stack, path: &Path) -> Result<(), StackError> {
    let file = File::create(path).map_err(|e| StackError::io(path, e))?;
    let out = BufWriter::new(file);
    let whole_counts = stack.meta.kind == ValueKind::Counts
        && stack
            .data
            .iter()
            .all(|&v| v >= 0.0 && v.fract() == 0.0 && v <= u32::MAX as f32);
    let written = if whole_counts {
        stack.data.mapv(|v| v as u32).write_npy(out)
    } else {
        stack.data.write_npy(out)
    };
    written.map_err(|e| StackError::format(path, format!("writing .npy: {e}")))?;
    let side = sidecar_path(path);
    let json = serde_json::to_string_pretty(&stack.meta).expect("metadata serialises");
    std::fs::write(&side, json).map_err(|e| StackError::io(&side, e))
}

/// Reads a `.npy` stack and its JSON sidecar.
pub fn read(path: &Path) -> Result<Stack, StackError> {
    let side = sidecar_path(path);
    let json = std::fs::read_to_string(&side).map_err(|e| StackError::io(&side, e))?;
    let meta: StackMeta = serde_json::from_str(&json)
        .map_err(|e| StackError::format(&side, format!("metadata: {e}")))?;
    let descr = read_descr(path)?;
    let open = || {
        File::open(path)
            .map(BufReader::new)
            .map_err(|e| StackError::io(path, e))
    };
    let npy_err = |e: ndarray_npy::ReadNpyError| StackError::format(path, format!(".npy: {e}"));
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
        "<u4" => exact_counts(
            path,
            Array3::<u32>::read_npy(open()?)
                .map_err(npy_err)?
                .mapv(u64::from),
        )?,
        "<u8" => exact_counts(path, Array3::<u64>::read_npy(open()?).map_err(npy_err)?)?,
        other => {
            return Err(StackError::format(
                path,
                format!(
                    "dtype `{other}` is not supported; use float32, float64 or unsigned integers (little-endian)"
                ),
            ));
        }
    };
    Ok(Stack { data, meta })
}

fn exact_counts(path: &Path, counts: Array3<u64>) -> Result<Array3<f32>, StackError> {
    if let Some(big) = counts.iter().find(|&&c| c > F32_EXACT_INT) {
        return Err(StackError::format(
            path,
            format!(
                "count {big} exceeds {F32_EXACT_INT}, the largest count a float32 stack holds exactly"
            ),
        ));
    }
    Ok(counts.mapv(|c| c as f32))
}

/// The `descr` entry of a `.npy` header, e.g. `<f4`.
fn read_descr(path: &Path) -> Result<String, StackError> {
    let mut f = File::open(path).map_err(|e| StackError::io(path, e))?;
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
    Ok(descr)
}
