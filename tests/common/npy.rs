//! A `.npy` file's bytes built from the format description, independent of
//! the writers under test.

/// The bytes of a version 1.0 `.npy` file: header for a (k, h, w) array of
/// `descr`, then `payload` as given.
pub fn npy_bytes(descr: &str, shape: (usize, usize, usize), payload: &[u8]) -> Vec<u8> {
    let mut header = format!(
        "{{'descr': '{descr}', 'fortran_order': False, 'shape': ({}, {}, {}), }}",
        shape.0, shape.1, shape.2
    );
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend((header.len() as u16).to_le_bytes());
    bytes.extend(header.as_bytes());
    bytes.extend(payload);
    bytes
}
