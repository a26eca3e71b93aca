//! Files whose headers promise more than they hold: the memory guards'
//! test inputs. The data is a hole (sparse), so a forged file of terabytes
//! takes no disk.

use std::io::Write;
use std::path::Path;

/// A `.npy` file declaring `shape` of `descr` (e.g. `<f4`), sparse.
#[allow(dead_code)]
pub fn forged_npy(path: &Path, descr: &str, shape: &[usize]) {
    let dims: Vec<String> = shape.iter().map(usize::to_string).collect();
    let mut header = format!(
        "{{'descr': '{descr}', 'fortran_order': False, 'shape': ({},), }}",
        dims.join(", ")
    );
    while !(10 + header.len() + 1).is_multiple_of(64) {
        header.push(' ');
    }
    header.push('\n');
    let mut f = std::fs::File::create(path).unwrap();
    f.write_all(b"\x93NUMPY\x01\x00").unwrap();
    f.write_all(&(header.len() as u16).to_le_bytes()).unwrap();
    f.write_all(header.as_bytes()).unwrap();
    let item: u64 = descr[2..].parse().unwrap();
    let data = shape
        .iter()
        .try_fold(item, |n, &d| n.checked_mul(d as u64))
        .unwrap_or(u64::MAX);
    // Files past a few TiB exceed what filesystems allow: such a header
    // then promises more than its file holds, which is refused too.
    f.set_len((10 + header.len()) as u64 + data.min(1 << 40))
        .unwrap();
}

/// A 4 x 4 one-channel EXR whose data window is then declared `w` x `h`,
/// zero-padded to `len` bytes.
#[allow(dead_code)]
pub fn forged_exr(path: &Path, w: i32, h: i32, len: u64) {
    let img = ndarray::Array2::<f32>::zeros((4, 4));
    scatterscope::formats::exr::write_image(img.view(), path).unwrap();
    let mut bytes = std::fs::read(path).unwrap();
    let window = b"dataWindow\0box2i\0\x10\0\0\0";
    let at = bytes
        .windows(window.len())
        .position(|win| win == window)
        .unwrap()
        + window.len();
    // xMin, yMin, xMax, yMax.
    bytes[at + 8..at + 12].copy_from_slice(&(w - 1).to_le_bytes());
    bytes[at + 12..at + 16].copy_from_slice(&(h - 1).to_le_bytes());
    std::fs::write(path, &bytes).unwrap();
    let f = std::fs::OpenOptions::new().write(true).open(path).unwrap();
    f.set_len(len.max(bytes.len() as u64)).unwrap();
}
