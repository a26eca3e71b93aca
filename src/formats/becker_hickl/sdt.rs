//! Becker & Hickl histogram files (`.sdt`): a file header, an info text, a
//! setup, measurement description blocks and data blocks, each block a
//! set of decay curves of `adc_re` points. Layout per B&H's
//! `SPC_data_file_structure.h` ("bhfile_header", "MeasureInfo",
//! "BHFileBlockHeader", the block type bits), all little-endian and
//! packed; a block whose type has the zip bit holds a zip archive whose
//! first member is the data.
//!
//! Decay curves (DECAY, PAGE and IMG blocks) are read; histograms of other
//! kinds (FCS, FIDA, FILDA, MCS, moments, intensity) carry no micro time
//! and are left out, by name. A block's curves form an image when the
//! measurement description's scan or image size holds them (as sdtfile
//! shapes them), else a row of curves. Times: curve point `k` is at
//! `k * tac_r / (tac_g * adc_re)`.

use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use ndarray::Array3;

/// Why an `.sdt` file cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum SdtError {
    /// Operating-system error.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// A field is missing or wrong.
    #[error("{path}: {field}: {reason}")]
    Field {
        /// The file.
        path: PathBuf,
        /// The field (structure and name, or block and field).
        field: String,
        /// What is wrong, with the value.
        reason: String,
    },
    /// More memory than the budget.
    #[error(transparent)]
    Memory(#[from] crate::memory::MemoryError),
}

/// The file header (`bhfile_header`, 42 bytes).
const HEADER_BYTES: usize = 42;
/// A data block header (either revision's layout).
const BLOCK_HEADER_BYTES: usize = 22;
/// Decay-curve block contents (block type bits 4-7) and their names.
const DECAY_CONTENTS: [(u16, &str); 3] = [(0x00, "DECAY"), (0x10, "PAGE"), (0x60, "IMG")];
/// Other block contents, left out.
const OTHER_CONTENTS: [(u16, &str); 10] = [
    (0x20, "FCS"),
    (0x30, "FIDA"),
    (0x40, "FILDA"),
    (0x50, "MCS"),
    (0x70, "MCSTA"),
    (0x80, "IMG_MCS"),
    (0x90, "MOM"),
    (0xA0, "IMG_INT"),
    (0xB0, "IMG_WF"),
    (0xC0, "IMG_LIFE"),
];

/// One data block of decay curves.
#[derive(Debug)]
pub struct SdtBlock {
    /// Position among the file's data blocks (from 0).
    pub index: usize,
    /// The block's own number (`lblock_no` bits 0-23).
    pub number: u32,
    /// Block contents (DECAY, PAGE, IMG).
    pub contents: &'static str,
    /// Stored value type (`u16`, `u32`, `f64`).
    pub stored_as: &'static str,
    /// Whether the block was zip-compressed.
    pub zipped: bool,
    /// Micro-time unit (s): `tac_r / (tac_g * adc_re)`.
    pub micro_unit_s: f64,
    /// The module that measured it (`mod_type`).
    pub module: String,
    /// Counts per curve point, row and column: `(adc_re, rows, columns)`.
    pub counts: Array3<u32>,
}

/// An `.sdt` file's decay-curve blocks and what was left out.
#[derive(Debug)]
pub struct SdtFile {
    /// The file.
    pub path: PathBuf,
    /// The file's identification (`ID` of its info text).
    pub id: String,
    /// Software revision (`revision` bits 0-3).
    pub revision: u16,
    /// Module type of the file header (`revision` bits 4-11), by name.
    pub module: String,
    /// The decay-curve blocks.
    pub blocks: Vec<SdtBlock>,
    /// Blocks left out (not decay curves), in words.
    pub left_out: Vec<String>,
}

impl SdtFile {
    /// The file in words, one line each (what `info` prints).
    pub fn describe(&self) -> Vec<String> {
        let mut lines = vec![
            format!("file: {}", self.path.display()),
            format!(
                "container: Becker & Hickl histogram file (.sdt), revision {}; module {}; {}",
                self.revision, self.module, self.id
            ),
        ];
        for b in &self.blocks {
            let (k, h, w) = b.counts.dim();
            lines.push(format!(
                "block {} (number {}): {} curves of {k} points as {h} x {w} pixels, {}{}, {:.6} ps per point, module {}; {} photons",
                b.index,
                b.number,
                b.contents,
                b.stored_as,
                if b.zipped { " zipped" } else { "" },
                b.micro_unit_s * 1e12,
                b.module,
                b.counts.iter().map(|&c| u64::from(c)).sum::<u64>()
            ));
        }
        lines.extend(self.left_out.iter().map(|l| format!("left out: {l}")));
        lines
    }
}

/// Little-endian fields of a byte slice, each read naming its field.
struct Fields<'a> {
    path: &'a Path,
    what: String,
    bytes: &'a [u8],
}

impl Fields<'_> {
    fn get<const N: usize>(&self, at: usize, name: &str) -> Result<[u8; N], SdtError> {
        self.bytes
            .get(at..at + N)
            .map(|b| b.try_into().expect("N bytes"))
            .ok_or_else(|| SdtError::Field {
                path: self.path.to_owned(),
                field: format!("{}.{name}", self.what),
                reason: format!(
                    "missing: the structure holds {} bytes, the field ends at byte {}",
                    self.bytes.len(),
                    at + N
                ),
            })
    }
    fn u16(&self, at: usize, name: &str) -> Result<u16, SdtError> {
        self.get::<2>(at, name).map(u16::from_le_bytes)
    }
    fn i16(&self, at: usize, name: &str) -> Result<i16, SdtError> {
        self.get::<2>(at, name).map(i16::from_le_bytes)
    }
    fn u32(&self, at: usize, name: &str) -> Result<u32, SdtError> {
        self.get::<4>(at, name).map(u32::from_le_bytes)
    }
    fn i32(&self, at: usize, name: &str) -> Result<i32, SdtError> {
        self.get::<4>(at, name).map(i32::from_le_bytes)
    }
    fn f32(&self, at: usize, name: &str) -> Result<f32, SdtError> {
        self.get::<4>(at, name).map(f32::from_le_bytes)
    }
    /// An `i32` field, 0 when the structure ends before it (older files).
    fn i32_or_0(&self, at: usize) -> i32 {
        self.bytes
            .get(at..at + 4)
            .map_or(0, |b| i32::from_le_bytes(b.try_into().expect("4 bytes")))
    }
}

/// The fields of a measurement description block (`MeasureInfo`) that
/// shape and time a block's curves; byte offsets in the packed structure.
#[derive(Debug, Clone)]
struct Measurement {
    module: String,
    tac_r: f32,
    tac_g: i16,
    adc_re: usize,
    scan: (usize, usize, usize, usize),
    image: (usize, usize, usize, usize),
}

impl Measurement {
    fn parse(f: &Fields) -> Result<Self, SdtError> {
        let adc_re = match f.i16(82, "adc_re")? {
            // "0 means 65536" (the header's comment).
            0 => 65_536,
            v if v > 0 => v as usize,
            v => {
                return Err(SdtError::Field {
                    path: f.path.to_owned(),
                    field: format!("{}.adc_re", f.what),
                    reason: format!("{v} ADC channels"),
                });
            }
        };
        let dims = |at: usize| {
            let d = |i: usize| usize::try_from(f.i32_or_0(at + 4 * i)).unwrap_or(0);
            (d(0), d(1), d(2), d(3))
        };
        let module = f
            .bytes
            .get(117..133)
            .map(|b| {
                String::from_utf8_lossy(b)
                    .trim_end_matches('\0')
                    .trim()
                    .to_string()
            })
            .unwrap_or_default();
        Ok(Self {
            module,
            tac_r: f.f32(64, "tac_r")?,
            tac_g: f.i16(68, "tac_g")?,
            adc_re,
            scan: dims(173),
            image: dims(309),
        })
    }

    /// Rows and columns of `curves` curves, as sdtfile shapes them: the
    /// scan, else the image, else a row; `Err` for several scan or image
    /// repeats (mosaics).
    fn layout(&self, curves: usize) -> Result<(usize, usize), String> {
        // Sizes come from the file: products that overflow match nothing.
        let product = |v: &[usize]| v.iter().try_fold(1usize, |a, &b| a.checked_mul(b));
        for (name, (x, y, rx, ry)) in [("scan", self.scan), ("image", self.image)] {
            let (plane, all) = (product(&[x, y]), product(&[x, y, rx, ry]));
            if plane == Some(curves) && curves > 0 {
                return Ok((y, x));
            }
            if all == Some(curves) && curves > 0 && plane != all {
                return Err(format!(
                    "its {curves} curves are a {name} of {x} x {y} pixels repeated {rx} x {ry} times (a mosaic), which is not read"
                ));
            }
        }
        Ok((1, curves))
    }
}

/// The file being read, each read checked against its size.
struct Source<'p> {
    file: std::fs::File,
    size: u64,
    path: &'p Path,
}

impl Source<'_> {
    /// The file positioned at `offset`, where `len` bytes (`what`) must lie
    /// within it.
    fn seek_to(
        &mut self,
        offset: u64,
        len: usize,
        what: &str,
    ) -> Result<&mut std::fs::File, SdtError> {
        if offset.saturating_add(len as u64) > self.size {
            return Err(SdtError::Field {
                path: self.path.to_owned(),
                field: what.into(),
                reason: format!(
                    "{len} bytes at byte {offset} reach past the file's end ({} bytes): the file is cut",
                    self.size
                ),
            });
        }
        self.file
            .seek(SeekFrom::Start(offset))
            .map_err(|source| SdtError::Io {
                path: self.path.to_owned(),
                source,
            })?;
        Ok(&mut self.file)
    }

    /// The `len` bytes (`what`) at `offset`.
    fn read_at(&mut self, offset: u64, len: usize, what: &str) -> Result<Vec<u8>, SdtError> {
        let path = self.path;
        // Checked against the file's size before the buffer is made: a
        // length from a damaged header must not allocate first (found by
        // fuzzing, RELIABILITY.md).
        let file = self.seek_to(offset, len, what)?;
        let mut buf = vec![0; len];
        file.read_exact(&mut buf).map_err(|source| SdtError::Io {
            path: path.to_owned(),
            source,
        })?;
        Ok(buf)
    }
}

/// Reads every decay-curve block of the `.sdt` file at `path`.
pub fn read(path: &Path) -> Result<SdtFile, SdtError> {
    let io = |source| SdtError::Io {
        path: path.to_owned(),
        source,
    };
    let (file, meta) = crate::files::open_regular(path, "histogram file").map_err(io)?;
    let size = meta.len();
    let field = |field: &str, reason: String| SdtError::Field {
        path: path.to_owned(),
        field: field.into(),
        reason,
    };
    let mut source = Source { file, size, path };
    let head = source.read_at(0, HEADER_BYTES, "bhfile_header")?;
    let h = Fields {
        path,
        what: "bhfile_header".into(),
        bytes: &head,
    };
    let (valid, chksum) = (h.u16(32, "header_valid")?, h.u16(40, "chksum")?);
    // sdtfile's rule: either mark of a valid header will do.
    if valid != 0x5555 && chksum != 0x55AA {
        return Err(field(
            "bhfile_header.header_valid",
            format!(
                "0x{valid:04X} and chksum 0x{chksum:04X}: not a valid .sdt header (0x5555 or 0x55AA)"
            ),
        ));
    }
    let revision = h.u16(0, "revision")?;
    let offset = |v: i32, name: &str| {
        u64::try_from(v).map_err(|_| field(&format!("bhfile_header.{name}"), format!("{v}")))
    };
    let info_offs = offset(h.i32(2, "info_offs")?, "info_offs")?;
    let info_len = h.i16(6, "info_length")?.max(0) as usize;
    let info = source.read_at(info_offs, info_len, "info")?;
    let info = String::from_utf8_lossy(&info);
    let id = info
        .lines()
        .find_map(|l| {
            let (k, v) = l.split_once(':')?;
            (k.trim() == "ID").then(|| v.trim().to_string())
        })
        .ok_or_else(|| {
            field(
                "info.ID",
                "missing: the info text has no ID line (*IDENTIFICATION ... ID : ...)".into(),
            )
        })?;
    if id.contains("Setup Script") {
        return Err(field(
            "info.ID",
            format!("{id:?}: a setup file holds no data"),
        ));
    }
    let mut blocks_n = i64::from(h.i16(18, "no_of_data_blocks")?);
    if blocks_n == 0x7FFF {
        blocks_n = i64::from(h.u32(34, "reserved1")?);
    }
    // Each block has a 22-byte header in the file: a count past what the
    // file holds is refused before any block is read.
    if blocks_n < 0 || blocks_n as u64 > size / BLOCK_HEADER_BYTES as u64 {
        return Err(field(
            "bhfile_header.no_of_data_blocks",
            format!(
                "{blocks_n}: a {size}-byte file holds at most {} block headers",
                size / BLOCK_HEADER_BYTES as u64
            ),
        ));
    }
    let meas_offs = offset(h.i32(24, "meas_desc_block_offs")?, "meas_desc_block_offs")?;
    let meas_n = h.i16(28, "no_of_meas_desc_blocks")?.max(0) as usize;
    let meas_len = h.i16(30, "meas_desc_block_length")?.max(0) as usize;
    let mut measurements = Vec::with_capacity(meas_n);
    for i in 0..meas_n {
        let bytes = source.read_at(
            meas_offs + (i * meas_len) as u64,
            meas_len,
            &format!("measurement description block {i}"),
        )?;
        measurements.push(Measurement::parse(&Fields {
            path,
            what: format!("measurement description block {i}"),
            bytes: &bytes,
        })?);
    }
    let new_headers = revision & 0xF >= 15;
    let mut next = offset(h.i32(14, "data_block_offs")?, "data_block_offs")?;
    let mut blocks = Vec::new();
    let mut left_out = Vec::new();
    for index in 0..blocks_n as usize {
        let what = format!("data block {index}");
        let bh = source.read_at(next, BLOCK_HEADER_BYTES, &format!("{what} header"))?;
        let b = Fields {
            path,
            what: format!("{what} header"),
            bytes: &bh,
        };
        let (ext_data, ext_next) = if new_headers {
            (u64::from(bh[0]) << 32, u64::from(bh[1]) << 32)
        } else {
            (0, 0)
        };
        let data_offs = u64::from(b.u32(2, "data_offs")?) | ext_data;
        let next_offs = u64::from(b.u32(6, "next_block_offs")?) | ext_next;
        let block_type = b.u16(10, "block_type")?;
        let meas_no = b.i16(12, "meas_desc_block_no")?;
        let number = b.u32(14, "lblock_no")? & 0x00FF_FFFF;
        let length = b.u32(18, "block_length")? as usize;
        // The chain of headers runs forward through the file: a pointer
        // back (or to itself) would read the same blocks forever.
        if index + 1 < blocks_n as usize && next_offs <= next {
            return Err(field(
                &format!("{what} header.next_block_offs"),
                format!(
                    "{next_offs} does not lie past this header (byte {next}): the chain of blocks loops"
                ),
            ));
        }
        next = next_offs;
        let contents = block_type & 0xF0;
        let Some(&(_, name)) = DECAY_CONTENTS.iter().find(|(c, _)| *c == contents) else {
            let name = OTHER_CONTENTS
                .iter()
                .find(|(c, _)| *c == contents)
                .map_or("unknown", |(_, n)| n);
            left_out.push(format!(
                "{what} ({name} block, type 0x{block_type:04X}): not decay curves"
            ));
            continue;
        };
        let m = usize::try_from(meas_no)
            .ok()
            .and_then(|i| measurements.get(i))
            .ok_or_else(|| {
                field(
                    &format!("{what}.meas_desc_block_no"),
                    format!(
                        "{meas_no}, but the file has {} measurement description blocks",
                        measurements.len()
                    ),
                )
            })?;
        let (stored_as, item) = match block_type & 0xF00 {
            0x000 => ("u16", 2),
            0x100 => ("u32", 4),
            0x200 => ("f64", 8),
            other => {
                return Err(field(
                    &format!("{what}.block_type"),
                    format!(
                        "0x{block_type:04X}: data type bits 0x{other:03X} are not u16, u32 or f64"
                    ),
                ));
            }
        };
        let zipped = block_type & 0x1000 != 0;
        let curve_bytes = m.adc_re * item;
        if length == 0 || !length.is_multiple_of(curve_bytes) {
            return Err(field(
                &format!("{what}.block_length"),
                format!(
                    "{length} bytes is not a whole number of curves of {} {stored_as} points",
                    m.adc_re
                ),
            ));
        }
        let curves = length / curve_bytes;
        let (rows, cols) = m
            .layout(curves)
            .map_err(|reason| field(&format!("{what} (measurement {meas_no})"), reason))?;
        crate::memory::check(
            crate::memory::bytes_of([m.adc_re, rows, cols], 8 + item as u64),
            || {
                format!(
                    "{what} of {} ({curves} curves of {} points)",
                    path.display(),
                    m.adc_re
                )
            },
        )?;
        let points = if zipped {
            let end = if next_offs > data_offs {
                next_offs
            } else {
                size
            };
            // Offsets from the file: one past its end reads nothing and
            // fails in `read_at`, naming the block.
            let packed =
                source.read_at(data_offs, end.saturating_sub(data_offs) as usize, &what)?;
            let data = unzip_first(&packed, length).map_err(|reason| field(&what, reason))?;
            if data.len() != length {
                return Err(field(
                    &what,
                    format!(
                        "its zip member decompresses to {} bytes, the block header says {length}",
                        data.len()
                    ),
                ));
            }
            let mut rest = &data[..];
            decode_points(item, m.adc_re, curves, |buf| rest.read_exact(buf))
        } else {
            // Straight from the file, a few curves at a time: no copy of
            // the block (32 MB for a 256 x 256 x 256 u16 image) whose
            // fresh pages the kernel would zero.
            let file = source.seek_to(data_offs, length, &what)?;
            decode_points(item, m.adc_re, curves, |buf| file.read_exact(buf))
        }
        .map_err(|e| match e {
            PointsError::Value(reason) => field(&what, reason),
            PointsError::Read(e) => io(e),
        })?;
        let counts = Array3::from_shape_vec((m.adc_re, rows, cols), points)
            .expect("whole curves of the layout's size");
        let tac_g = if m.tac_g == 0 {
            1.0
        } else {
            f64::from(m.tac_g)
        };
        // tac_r is a float32 (12.5 ns arrives as 12.4999996 ns): keep the
        // 7 significant digits it carries, so bin widths come out round.
        let tac_r: f64 = format!("{:.6e}", m.tac_r).parse().unwrap_or(f64::NAN);
        let unit = tac_r / (tac_g * m.adc_re as f64);
        if !(unit.is_finite() && unit > 0.0) {
            return Err(field(
                &format!("measurement description block {meas_no}.tac_r"),
                format!(
                    "{} s with tac_g {}: no positive time per curve point",
                    m.tac_r, m.tac_g
                ),
            ));
        }
        blocks.push(SdtBlock {
            index,
            number,
            contents: name,
            stored_as,
            zipped,
            micro_unit_s: unit,
            module: m.module.clone(),
            counts,
        });
    }
    Ok(SdtFile {
        path: path.to_owned(),
        id,
        revision: revision & 0xF,
        module: module_name((revision >> 4) & 0xFF),
        blocks,
        left_out,
    })
}

/// The first member of a zip archive, which must hold `length` bytes.
fn unzip_first(packed: &[u8], length: usize) -> Result<Vec<u8>, String> {
    let mut archive = zip::ZipArchive::new(std::io::Cursor::new(packed))
        .map_err(|e| format!("its zip-compressed data do not open: {e}"))?;
    let mut member = archive
        .by_index(0)
        .map_err(|e| format!("its zip archive has no readable first member: {e}"))?;
    if member.size() != length as u64 {
        return Err(format!(
            "its zip member holds {} bytes, the block header says {length}",
            member.size()
        ));
    }
    let mut out = Vec::with_capacity(length);
    member
        .read_to_end(&mut out)
        .map_err(|e| format!("its zip-compressed data do not decompress: {e}"))?;
    Ok(out)
}

/// Why a block's points could not be decoded.
enum PointsError {
    /// A value that is no count.
    Value(String),
    /// The bytes could not be read.
    Read(std::io::Error),
}

/// Counts in (point, curve) order from `curves` curves of `points`
/// little-endian values of `item` bytes (u16, u32, f64) stored curve after
/// curve, which `fill` delivers in order, a few curves to a call (it fills
/// the buffer it is given); an `f64` must be a whole count of at most
/// `u32::MAX`.
fn decode_points(
    item: usize,
    points: usize,
    curves: usize,
    fill: impl FnMut(&mut [u8]) -> std::io::Result<()>,
) -> Result<Vec<u32>, PointsError> {
    match item {
        2 => transpose::<2>(points, curves, fill),
        4 => transpose::<4>(points, curves, fill),
        _ => transpose::<8>(points, curves, fill),
    }
}

/// [`decode_points`] for values of `ITEM` bytes: the curves read
/// [`CURVES_PER_READ`] at a time (a buffer that stays in cache), each
/// point's values of those curves written side by side. One loop per
/// value width, so that the width is no branch in the inner loop: `info`
/// of a 256 x 256 x 256 u16 block took 0.19 s with ndarray's transposing
/// copy (a point-major walk over the whole file), 0.11-0.13 s with a
/// width-generic tiled loop, and 0.04 s so (BENCHMARKS.md).
fn transpose<const ITEM: usize>(
    points: usize,
    curves: usize,
    mut fill: impl FnMut(&mut [u8]) -> std::io::Result<()>,
) -> Result<Vec<u32>, PointsError> {
    let mut out = vec![0u32; curves * points];
    let mut data = vec![0u8; CURVES_PER_READ * points * ITEM];
    for c0 in (0..curves).step_by(CURVES_PER_READ) {
        let n = CURVES_PER_READ.min(curves - c0);
        let data = &mut data[..n * points * ITEM];
        fill(data).map_err(PointsError::Read)?;
        for k in 0..points {
            let row = &mut out[k * curves + c0..k * curves + c0 + n];
            for (c, slot) in row.iter_mut().enumerate() {
                let at = (c * points + k) * ITEM;
                let b: [u8; ITEM] = data[at..at + ITEM].try_into().expect("ITEM bytes");
                *slot = match ITEM {
                    2 => u32::from(u16::from_le_bytes([b[0], b[1]])),
                    4 => u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
                    _ => {
                        let v = f64::from_le_bytes(b[..8].try_into().expect("8 bytes"));
                        if !(v.is_finite()
                            && v >= 0.0
                            && v.fract() == 0.0
                            && v <= f64::from(u32::MAX))
                        {
                            return Err(PointsError::Value(format!(
                                "value {} is {v}: a histogram point must be a whole count from 0 to 2^32 - 1",
                                (c0 + c) * points + k
                            )));
                        }
                        v as u32
                    }
                };
            }
        }
    }
    Ok(out)
}

/// Curves [`transpose`] reads at a time.
const CURVES_PER_READ: usize = 128;

/// The module of a file header's `revision` bits 4-11, per the header's
/// list (hex code when unlisted).
fn module_name(code: u16) -> String {
    let name = match code {
        0x20 => "SPC-130",
        0x21 => "SPC-600",
        0x22 => "SPC-630",
        0x23 => "SPC-700",
        0x24 => "SPC-730",
        0x25 => "SPC-830",
        0x26 => "SPC-140",
        0x27 => "SPC-930",
        0x28 => "SPC-150",
        0x29 => "DPC-230",
        0x2A => "SPC-130EM",
        _ => return format!("0x{code:02X}"),
    };
    name.into()
}
