//! MATLAB level 5 MAT-files (what `save` writes by default up to v7, and
//! what labs publish most cubes in): numeric and logical arrays, plain or
//! zlib-compressed (v7), either byte order. The layout is MathWorks' "MAT-File
//! Format" document: a 128-byte header (text, subsystem offset, version
//! 0x0100, the endian indicator `MI`), then data elements, each an
//! 8-byte tag (type, byte count; or the 4-byte "small element" form) and
//! its data padded to 8 bytes; an `miMATRIX` element holds the array flags
//! (class), the dimensions, the name and the real (and imaginary) parts in
//! column-major order; an `miCOMPRESSED` element holds one zlib stream that
//! inflates to one element. Cells, structs, objects, sparse and character
//! arrays are listed by name and skipped. Errors are messages without the
//! path; callers name the file.

use std::io::Read;
use std::path::Path;

/// A numeric array of a MAT-file, in MATLAB's terms.
#[derive(Debug, Clone, PartialEq)]
pub struct MatArray {
    /// The variable's name.
    pub name: String,
    /// MATLAB's dimensions (rows first), at least two.
    pub dims: Vec<usize>,
    /// The values in column-major order (the first dimension fastest).
    pub values: Vec<f64>,
    /// MATLAB's class (`double`, `single`, `int32`, `logical`, ...).
    pub class: &'static str,
}

/// What a MAT-file holds: its numeric arrays, and the variables of other
/// classes, by name and class, that were skipped.
#[derive(Debug, Clone, Default)]
pub struct MatContents {
    /// Numeric and logical arrays, in file order.
    pub arrays: Vec<MatArray>,
    /// `name (class)` of every variable that is not a numeric array.
    pub skipped: Vec<String>,
}

/// Whether `head` (a file's first 128 bytes or more) is a level 5 header:
/// version 0x0100 and the endian indicator, and not an HDF5 (v7.3) file.
pub fn is_level5(head: &[u8]) -> bool {
    head.len() >= 128
        && (&head[126..128] == b"IM" && head[124..126] == [0x00, 0x01]
            || &head[126..128] == b"MI" && head[124..126] == [0x01, 0x00])
}

const MI_INT8: u32 = 1;
const MI_UINT8: u32 = 2;
const MI_INT16: u32 = 3;
const MI_UINT16: u32 = 4;
const MI_INT32: u32 = 5;
const MI_UINT32: u32 = 6;
const MI_SINGLE: u32 = 7;
const MI_DOUBLE: u32 = 9;
const MI_INT64: u32 = 12;
const MI_UINT64: u32 = 13;
const MI_MATRIX: u32 = 14;
const MI_COMPRESSED: u32 = 15;
const MI_UTF8: u32 = 16;

/// Reads every numeric array of the level 5 MAT-file `path`, inside the
/// memory budget: a compressed element is inflated only up to what the
/// budget allows, and a declared size past the file's end is refused.
pub fn read(path: &Path) -> Result<MatContents, String> {
    let (_, meta) = crate::files::open_regular(path, "MATLAB file").map_err(|e| e.to_string())?;
    crate::memory::check(meta.len(), || format!("reading {}", path.display()))
        .map_err(|e| e.to_string())?;
    let bytes = std::fs::read(path).map_err(|e| e.to_string())?;
    parse(&bytes)
}

/// [`read`] on the file's bytes.
pub fn parse(bytes: &[u8]) -> Result<MatContents, String> {
    if bytes.len() < 128 {
        return Err(format!(
            "{} bytes: shorter than a MAT-file's 128-byte header",
            bytes.len()
        ));
    }
    if !is_level5(bytes) {
        return Err(
            "not a MATLAB level 5 MAT-file (no version 0x0100 and endian indicator at bytes 124-127)"
                .into(),
        );
    }
    let order = if &bytes[126..128] == b"IM" {
        Order::Little
    } else {
        Order::Big
    };
    let budget = crate::memory::budget().map_err(|e| e.to_string())?.bytes;
    let mut contents = MatContents::default();
    let mut at = 128;
    while at < bytes.len() {
        if bytes.len() - at < 8 {
            // MATLAB pads nothing after the last element; a few stray bytes
            // are a cut file.
            return Err(format!(
                "the file ends inside an element's tag at byte {at}"
            ));
        }
        let (kind, n, data_at) = order.tag(&bytes[at..]);
        let data_at = at + data_at;
        let end = data_at
            .checked_add(n)
            .filter(|&e| e <= bytes.len())
            .ok_or_else(|| {
                format!(
                    "the element at byte {at} declares {n} bytes; the file ends {} bytes after it",
                    bytes.len() - data_at
                )
            })?;
        let data = &bytes[data_at..end];
        match kind {
            MI_COMPRESSED => {
                let inflated = inflate(data, budget)
                    .map_err(|e| format!("the compressed element at byte {at}: {e}"))?;
                if inflated.len() < 8 {
                    return Err(format!(
                        "the compressed element at byte {at} inflates to no element"
                    ));
                }
                let (inner, m, inner_at) = order.tag(&inflated);
                let inner_end = inner_at.saturating_add(m);
                if inner_end > inflated.len() {
                    return Err(format!(
                        "the compressed element at byte {at} holds an element of {m} bytes but inflates to {}",
                        inflated.len()
                    ));
                }
                if inner == MI_MATRIX {
                    matrix(&inflated[inner_at..inner_end], order, &mut contents)
                        .map_err(|e| format!("the compressed array at byte {at}: {e}"))?;
                }
                at = end;
            }
            MI_MATRIX => {
                matrix(data, order, &mut contents)
                    .map_err(|e| format!("the array at byte {at}: {e}"))?;
                at = padded(end, data_at);
            }
            _ => at = padded(end, data_at),
        }
    }
    Ok(contents)
}

/// The next element's start after one ending at `end`: elements are padded
/// to 8 bytes (a small element's 4 data bytes fill its 8).
fn padded(end: usize, data_at: usize) -> usize {
    let start = data_at - 8;
    let len = end - start;
    start + len.div_ceil(8) * 8
}

/// Inflates a zlib stream, refusing one that inflates past `budget` bytes.
fn inflate(data: &[u8], budget: u64) -> Result<Vec<u8>, String> {
    let mut out = Vec::new();
    flate2::read::ZlibDecoder::new(data)
        .take(budget.saturating_add(1))
        .read_to_end(&mut out)
        .map_err(|e| format!("not a zlib stream: {e}"))?;
    if out.len() as u64 > budget {
        return Err(format!(
            "it inflates past the memory budget of {}",
            crate::memory::size(budget)
        ));
    }
    Ok(out)
}

#[derive(Debug, Clone, Copy)]
enum Order {
    Little,
    Big,
}

impl Order {
    fn u32(self, b: &[u8]) -> u32 {
        let a = [b[0], b[1], b[2], b[3]];
        match self {
            Order::Little => u32::from_le_bytes(a),
            Order::Big => u32::from_be_bytes(a),
        }
    }

    /// An element's type, data length and where its data starts (4 for a
    /// small element, else 8), from the tag at the start of `b` (8 bytes).
    fn tag(self, b: &[u8]) -> (u32, usize, usize) {
        let first = self.u32(b);
        // Small data element: the byte count in the upper 16 bits of the
        // first word (which is the first two bytes read in file order).
        let small = first >> 16;
        if small != 0 {
            (first & 0xffff, small as usize, 4)
        } else {
            (first, self.u32(&b[4..]) as usize, 8)
        }
    }

    /// The numbers of a data element of type `kind`.
    fn numbers(self, kind: u32, b: &[u8]) -> Result<Vec<f64>, String> {
        fn each<const N: usize>(b: &[u8], f: impl Fn([u8; N]) -> f64) -> Vec<f64> {
            b.chunks_exact(N)
                .map(|c| f(c.try_into().expect("chunk of N")))
                .collect()
        }
        let big = matches!(self, Order::Big);
        macro_rules! num {
            ($t:ty) => {
                each(b, |a| {
                    (if big {
                        <$t>::from_be_bytes(a)
                    } else {
                        <$t>::from_le_bytes(a)
                    }) as f64
                })
            };
        }
        Ok(match kind {
            MI_INT8 => num!(i8),
            MI_UINT8 | MI_UTF8 => num!(u8),
            MI_INT16 => num!(i16),
            MI_UINT16 => num!(u16),
            MI_INT32 => num!(i32),
            MI_UINT32 => num!(u32),
            MI_SINGLE => num!(f32),
            MI_DOUBLE => num!(f64),
            MI_INT64 => num!(i64),
            MI_UINT64 => num!(u64),
            other => return Err(format!("data type {other} is not a number")),
        })
    }
}

/// MATLAB's class names by class number (mxCELL_CLASS = 1 ...).
fn class_name(class: u8) -> &'static str {
    match class {
        1 => "cell",
        2 => "struct",
        3 => "object",
        4 => "char",
        5 => "sparse",
        6 => "double",
        7 => "single",
        8 => "int8",
        9 => "uint8",
        10 => "int16",
        11 => "uint16",
        12 => "int32",
        13 => "uint32",
        14 => "int64",
        15 => "uint64",
        16 => "function",
        17 => "opaque",
        _ => "unknown",
    }
}

/// Parses one `miMATRIX` element's data into `contents`.
fn matrix(data: &[u8], order: Order, contents: &mut MatContents) -> Result<(), String> {
    let mut sub = Subelements { data, at: 0, order };
    let (flags_kind, flags) = sub.next("array flags")?;
    if flags_kind != MI_UINT32 || flags.len() < 8 {
        return Err("its array flags are not two 32-bit words".into());
    }
    let word = order.u32(flags);
    let class = (word & 0xff) as u8;
    let complex = word & 0x0800 != 0;
    let logical = word & 0x0200 != 0;
    let (dims_kind, dims_bytes) = sub.next("dimensions")?;
    if dims_kind != MI_INT32 {
        return Err(format!(
            "its dimensions are of data type {dims_kind}, not int32"
        ));
    }
    let dims: Vec<i64> = dims_bytes
        .chunks_exact(4)
        .map(|c| order.u32(c) as i32 as i64)
        .collect();
    if dims.len() < 2 || dims.iter().any(|&d| d < 0) {
        return Err(format!("its dimensions {dims:?} are not an array's"));
    }
    let (_, name_bytes) = sub.next("array name")?;
    let name = String::from_utf8_lossy(name_bytes).into_owned();
    let class_label = if logical {
        "logical"
    } else {
        class_name(class)
    };
    if !(6..=15).contains(&class) {
        contents.skipped.push(format!("{name} ({class_label})"));
        return Ok(());
    }
    let dims: Vec<usize> = dims.iter().map(|&d| d as usize).collect();
    let elements = dims
        .iter()
        .try_fold(1usize, |n, &d| n.checked_mul(d))
        .ok_or_else(|| format!("`{name}`: dimensions {dims:?} overflow"))?;
    crate::memory::check((elements as u64).saturating_mul(8), || {
        format!("the array `{name}` of dimensions {dims:?}")
    })
    .map_err(|e| e.to_string())?;
    let (real_kind, real) = sub.next("real part")?;
    let values = order
        .numbers(real_kind, real)
        .map_err(|e| format!("`{name}`: {e}"))?;
    if values.len() != elements {
        return Err(format!(
            "`{name}` declares dimensions {dims:?} ({elements} values) but holds {}",
            values.len()
        ));
    }
    if complex {
        contents
            .skipped
            .push(format!("{name} (complex {class_label})"));
        return Ok(());
    }
    contents.arrays.push(MatArray {
        name,
        dims,
        values,
        class: class_label,
    });
    Ok(())
}

/// The subelements of an array element, in order.
struct Subelements<'a> {
    data: &'a [u8],
    at: usize,
    order: Order,
}

impl<'a> Subelements<'a> {
    fn next(&mut self, what: &str) -> Result<(u32, &'a [u8]), String> {
        let rest = &self.data[self.at.min(self.data.len())..];
        if rest.len() < 8 {
            return Err(format!("it ends before its {what}"));
        }
        let (kind, n, data_at) = self.order.tag(rest);
        let end = data_at
            .checked_add(n)
            .filter(|&e| e <= rest.len())
            .ok_or_else(|| format!("its {what} declares {n} bytes past the array's end"))?;
        let out = &rest[data_at..end];
        self.at += end.div_ceil(8) * 8;
        Ok((kind, out))
    }
}

/// Writes `arrays` (name, MATLAB dimensions, column-major values) as an
/// uncompressed level 5 MAT-file of doubles, whole or not at all (a
/// temporary name, then a rename): what `scipy.io.loadmat` and MATLAB's
/// `load` read.
pub fn write(path: &Path, arrays: &[(&str, &[usize], &[f64])]) -> std::io::Result<()> {
    let mut out = Vec::new();
    let mut header = format!(
        "MATLAB 5.0 MAT-file, Platform: scatterscope {}, written by scatterscope",
        env!("CARGO_PKG_VERSION")
    )
    .into_bytes();
    header.resize(116, b' ');
    out.extend_from_slice(&header);
    out.extend_from_slice(&[0u8; 8]);
    out.extend_from_slice(&0x0100u16.to_le_bytes());
    out.extend_from_slice(b"IM");
    for (name, dims, values) in arrays {
        let elements: usize = dims.iter().product();
        if elements != values.len() || dims.len() < 2 {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                format!(
                    "array `{name}`: dimensions {dims:?} for {} values",
                    values.len()
                ),
            ));
        }
        let mut body = Vec::new();
        element(&mut body, MI_UINT32, &[6u32.to_le_bytes(), [0; 4]].concat());
        let dims_bytes: Vec<u8> = dims
            .iter()
            .flat_map(|&d| (d as i32).to_le_bytes())
            .collect();
        element(&mut body, MI_INT32, &dims_bytes);
        element(&mut body, MI_INT8, name.as_bytes());
        let data: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        element(&mut body, MI_DOUBLE, &data);
        element(&mut out, MI_MATRIX, &body);
    }
    crate::files::write_atomic(path, out)
}

/// Appends a data element (tag, data, padding to 8 bytes).
fn element(out: &mut Vec<u8>, kind: u32, data: &[u8]) {
    out.extend_from_slice(&kind.to_le_bytes());
    out.extend_from_slice(&(data.len() as u32).to_le_bytes());
    out.extend_from_slice(data);
    out.resize(out.len().div_ceil(8) * 8, 0);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_written_file_reads_back_with_its_dimensions_and_order() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("cube.mat");
        let values: Vec<f64> = (0..24).map(|v| v as f64 - 3.5).collect();
        write(
            &path,
            &[
                ("cube", &[2, 3, 4], &values),
                ("x", &[1, 3], &[1.0, 2.0, 3.0]),
            ],
        )
        .unwrap();
        let got = read(&path).unwrap();
        assert_eq!(got.arrays.len(), 2);
        assert_eq!(got.arrays[0].name, "cube");
        assert_eq!(got.arrays[0].dims, vec![2, 3, 4]);
        assert_eq!(got.arrays[0].values, values);
        assert_eq!(got.arrays[1].values, vec![1.0, 2.0, 3.0]);
    }

    #[test]
    fn a_cut_file_is_refused_with_where_it_ends() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("cube.mat");
        let values = vec![1.0; 100];
        write(&path, &[("cube", &[10, 10], &values)]).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let err = parse(&bytes[..bytes.len() - 40]).unwrap_err();
        assert!(err.contains("declares"), "{err}");
        let err = parse(&bytes[..100]).unwrap_err();
        assert!(err.contains("128-byte header"), "{err}");
    }

    #[test]
    fn a_big_endian_small_element_name_is_read() {
        // A big-endian file by hand: one 1 x 2 int16 array named `ab`,
        // its name and data in the small element form.
        let mut b = vec![b' '; 116];
        b.extend_from_slice(&[0; 8]);
        b.extend_from_slice(&[0x01, 0x00]);
        b.extend_from_slice(b"MI");
        let mut body = Vec::new();
        body.extend_from_slice(&6u32.to_be_bytes());
        body.extend_from_slice(&8u32.to_be_bytes());
        body.extend_from_slice(&[0, 0, 0, 10, 0, 0, 0, 0]); // int16 class
        body.extend_from_slice(&5u32.to_be_bytes());
        body.extend_from_slice(&8u32.to_be_bytes());
        body.extend_from_slice(&1i32.to_be_bytes());
        body.extend_from_slice(&2i32.to_be_bytes());
        // Small element: 2 bytes of int8 name.
        body.extend_from_slice(&[0, 2, 0, 1, b'a', b'b', 0, 0]);
        // Small element: 4 bytes of int16 data.
        body.extend_from_slice(&[0, 4, 0, 3]);
        body.extend_from_slice(&(-2i16).to_be_bytes());
        body.extend_from_slice(&7i16.to_be_bytes());
        b.extend_from_slice(&14u32.to_be_bytes());
        b.extend_from_slice(&(body.len() as u32).to_be_bytes());
        b.extend_from_slice(&body);
        let got = parse(&b).unwrap();
        assert_eq!(got.arrays[0].name, "ab");
        assert_eq!(got.arrays[0].class, "int16");
        assert_eq!(got.arrays[0].values, vec![-2.0, 7.0]);
    }
}
