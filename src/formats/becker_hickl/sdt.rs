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
    /// Micro-time unit (s), `tac_r / (tac_g * adc_re)`, or why the
    /// measurement states none (then the points are bins of unknown width).
    pub micro_unit_s: Result<f64, String>,
    /// The module that measured it (`mod_type`).
    pub module: String,
    /// The sync rates the card measured (Hz; `StopInfo.min_sync_rate`
    /// and `max_sync_rate`), as the file holds them (unchecked: some
    /// instruments write nonsense there; [`crate::tags::laser`] checks).
    pub sync_rates_hz: SyncRates,
    /// The TAC's lower and upper limits (`tac_ll`, `tac_lh`), percent of
    /// the ADC's range, where the measurement states a usable pair
    /// (`0 <= ll < lh <= 100`, not the whole range): the card recorded
    /// only photons between them.
    pub tac_limits_percent: Option<(f64, f64)>,
    /// Counts per curve point, row and column: `(adc_re, rows, columns)`.
    pub counts: BlockCounts,
}

/// A block's counts in the width the file stores them: 16-bit blocks stay
/// 16-bit (half the memory of a 32-bit copy; on a 512 x 512 x 256 FLIM
/// image the fresh pages of a wider copy were most of the read's time).
#[derive(Debug)]
pub enum BlockCounts {
    /// Stored as `u16`.
    U16(Array3<u16>),
    /// Stored as `u32`, or as whole `f64` counts.
    U32(Array3<u32>),
}

impl BlockCounts {
    /// `(points, rows, columns)`.
    pub fn dim(&self) -> (usize, usize, usize) {
        match self {
            BlockCounts::U16(c) => c.dim(),
            BlockCounts::U32(c) => c.dim(),
        }
    }

    /// The photons of every curve point.
    pub fn total(&self) -> u64 {
        fn sum<T: Copy + Into<u64>>(c: &Array3<T>) -> u64 {
            match c.as_slice_memory_order() {
                Some(flat) => flat.iter().map(|&v| v.into()).sum(),
                None => c.iter().map(|&v| v.into()).sum(),
            }
        }
        match self {
            BlockCounts::U16(c) => sum(c),
            BlockCounts::U32(c) => sum(c),
        }
    }
}

/// What a decay block held, without its counts (what `info` keeps).
#[derive(Debug, Clone)]
pub struct SdtBlockSummary {
    /// Position among the file's data blocks (from 0).
    pub index: usize,
    /// The block's own number.
    pub number: u32,
    /// Block contents (DECAY, PAGE, IMG).
    pub contents: &'static str,
    /// Stored value type.
    pub stored_as: &'static str,
    /// Whether the block was zip-compressed.
    pub zipped: bool,
    /// Micro-time unit (s), or why the measurement states none.
    pub micro_unit_s: Result<f64, String>,
    /// The module that measured it.
    pub module: String,
    /// `(points, rows, columns)`.
    pub shape: (usize, usize, usize),
    /// Photons in the block.
    pub photons: u64,
}

impl SdtBlock {
    /// The block without its counts.
    pub fn summary(&self) -> SdtBlockSummary {
        SdtBlockSummary {
            index: self.index,
            number: self.number,
            contents: self.contents,
            stored_as: self.stored_as,
            zipped: self.zipped,
            micro_unit_s: self.micro_unit_s.clone(),
            module: self.module.clone(),
            shape: self.counts.dim(),
            photons: self.counts.total(),
        }
    }
}

/// An `.sdt` file's decay-curve blocks, each summed as it was read (one
/// block in memory at a time), and what was left out.
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
    pub blocks: Vec<SdtBlockSummary>,
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
            let (k, h, w) = b.shape;
            let unit = match &b.micro_unit_s {
                Ok(s) => format!("{:.6} ps per point", s * 1e12),
                Err(why) => format!("time per point unknown ({why})"),
            };
            lines.push(format!(
                "block {} (number {}): {} curves of {k} points as {h} x {w} pixels, {}{}, {unit}, module {}; {} photons",
                b.index,
                b.number,
                b.contents,
                b.stored_as,
                if b.zipped { " zipped" } else { "" },
                b.module,
                b.photons
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

/// The lowest and highest sync rates a card measured during a block's
/// measurement (Hz), as the file holds them; `None` where it ends before.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SyncRates {
    /// `StopInfo.min_sync_rate`.
    pub min: Option<f64>,
    /// `StopInfo.max_sync_rate`.
    pub max: Option<f64>,
}

/// The fields of a measurement description block (`MeasureInfo`) that
/// shape and time a block's curves; byte offsets in the packed structure.
#[derive(Debug, Clone)]
struct Measurement {
    module: String,
    sync_rates_hz: SyncRates,
    tac_r: f32,
    tac_g: i16,
    tac_limits_percent: Option<(f64, f64)>,
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
        let module = f.bytes.get(117..133).map(c_text).unwrap_or_default();
        // StopInfo (a MeasStopInfo at byte 211) holds the sync rates the
        // card measured: min_sync_rate at its byte 20, max_sync_rate at
        // its byte 36; older files end before them.
        let rate = |at: usize| {
            f.bytes
                .get(at..at + 4)
                .map(|b| f64::from(f32::from_le_bytes(b.try_into().expect("4 bytes"))))
        };
        let sync_rates_hz = SyncRates {
            min: rate(231),
            max: rate(247),
        };
        Ok(Self {
            module,
            sync_rates_hz,
            tac_r: f.f32(64, "tac_r")?,
            tac_g: f.i16(68, "tac_g")?,
            tac_limits_percent: {
                // tac_ll at byte 74 and tac_lh at 78 (float32, percent).
                let (ll, lh) = (
                    f64::from(f.f32(74, "tac_ll")?),
                    f64::from(f.f32(78, "tac_lh")?),
                );
                (ll.is_finite()
                    && lh.is_finite()
                    && 0.0 <= ll
                    && ll < lh
                    && lh <= 100.0
                    && (ll > 0.0 || lh < 100.0))
                    .then_some((ll, lh))
            },
            adc_re,
            scan: dims(173),
            image: dims(309),
        })
    }

    /// Time per curve point (s), `tac_r / (tac_g * adc_re)`; `None` with
    /// the reason when the measurement does not state a usable one (a TAC
    /// gain of 0, as sdtfile then gives the points unscaled), an error for
    /// a unit no time tagger has.
    fn micro_unit_s(&self) -> Result<Result<f64, String>, String> {
        if self.tac_g <= 0 || !(self.tac_r.is_finite() && self.tac_r > 0.0) {
            return Ok(Err(format!(
                "tac_r {} s with tac_g {}: no positive time per curve point",
                self.tac_r, self.tac_g
            )));
        }
        // tac_r is a float32 (12.5 ns arrives as 12.4999996 ns): keep the
        // 7 significant digits it carries, so bin widths come out round.
        let tac_r: f64 = format!("{:.6e}", self.tac_r).parse().unwrap_or(f64::NAN);
        let ps = tac_r / (f64::from(self.tac_g) * self.adc_re as f64) * 1e12;
        let from = format!(
            "tac_r {tac_r} s / tac_g {} / adc_re {}",
            self.tac_g, self.adc_re
        );
        super::setup::check_micro_unit_ps(ps, &from).map(|ps| Ok(ps * 1e-12))
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

/// A fixed-size text field: its bytes up to the first NUL (a C string;
/// some writers, Bruker's Prairie View among them, leave other bytes after
/// it), printable ASCII kept, any other byte as `\xNN`, trimmed.
fn c_text(bytes: &[u8]) -> String {
    let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
    bytes[..end]
        .iter()
        .map(|&b| match b {
            0x20..=0x7E => char::from(b).to_string(),
            _ => format!("\\x{b:02X}"),
        })
        .collect::<String>()
        .trim()
        .to_string()
}

/// The file being read, each read checked against its size.
struct Source {
    file: std::fs::File,
    size: u64,
    path: PathBuf,
}

impl Source {
    fn io(&self, source: std::io::Error) -> SdtError {
        SdtError::Io {
            path: self.path.clone(),
            source,
        }
    }

    fn field(&self, field: &str, reason: String) -> SdtError {
        SdtError::Field {
            path: self.path.clone(),
            field: field.into(),
            reason,
        }
    }

    /// The file positioned at `offset`, where `len` bytes (`what`) must lie
    /// within it.
    fn seek_to(
        &mut self,
        offset: u64,
        len: usize,
        what: &str,
    ) -> Result<&mut std::fs::File, SdtError> {
        if offset.saturating_add(len as u64) > self.size {
            return Err(self.field(
                what,
                format!(
                    "{len} bytes at byte {offset} reach past the file's end ({} bytes): the file is cut",
                    self.size
                ),
            ));
        }
        if let Err(e) = self.file.seek(SeekFrom::Start(offset)) {
            return Err(self.io(e));
        }
        Ok(&mut self.file)
    }

    /// The `len` bytes (`what`) at `offset`.
    fn read_at(&mut self, offset: u64, len: usize, what: &str) -> Result<Vec<u8>, SdtError> {
        // Checked against the file's size before the buffer is made: a
        // length from a damaged header must not allocate first (found by
        // fuzzing, RELIABILITY.md).
        let file = self.seek_to(offset, len, what)?;
        let mut buf = vec![0; len];
        match file.read_exact(&mut buf) {
            Ok(()) => Ok(buf),
            Err(e) => Err(self.io(e)),
        }
    }
}

/// An `.sdt` file opened for its decay blocks, read one at a time
/// ([`SdtReader::next_block`]), so that a file of many large blocks needs
/// the memory of one.
pub struct SdtReader {
    source: Source,
    /// The file's identification (`ID` of its info text).
    pub id: String,
    /// Software revision (`revision` bits 0-3).
    pub revision: u16,
    /// Module type of the file header (`revision` bits 4-11), by name.
    pub module: String,
    /// Blocks passed over so far (not decay curves), in words.
    pub left_out: Vec<String>,
    /// Decay-curve blocks the chain of block headers names (what
    /// [`SdtReader::next_block`] will give, unless a block turns out bad).
    pub decay_blocks: usize,
    measurements: Vec<Measurement>,
    new_headers: bool,
    next: u64,
    index: usize,
    blocks: usize,
}

/// Opens the `.sdt` file at `path`: its header, info and measurement
/// descriptions, checked; the blocks follow with
/// [`SdtReader::next_block`].
pub fn open(path: &Path) -> Result<SdtReader, SdtError> {
    let io = |source| SdtError::Io {
        path: path.to_owned(),
        source,
    };
    let (file, meta) = crate::files::open_regular(path, "histogram file").map_err(io)?;
    let size = meta.len();
    let mut source = Source {
        file,
        size,
        path: path.to_owned(),
    };
    let head = source.read_at(0, HEADER_BYTES, "bhfile_header")?;
    let h = Fields {
        path,
        what: "bhfile_header".into(),
        bytes: &head,
    };
    let (valid, chksum) = (h.u16(32, "header_valid")?, h.u16(40, "chksum")?);
    // sdtfile's rule: either mark of a valid header will do.
    if valid != 0x5555 && chksum != 0x55AA {
        return Err(source.field(
            "bhfile_header.header_valid",
            format!(
                "0x{valid:04X} and chksum 0x{chksum:04X}: not a valid .sdt header (0x5555 or 0x55AA)"
            ),
        ));
    }
    let revision = h.u16(0, "revision")?;
    let offset = |v: i32, name: &str| {
        u64::try_from(v).map_err(|_| SdtError::Field {
            path: path.to_owned(),
            field: format!("bhfile_header.{name}"),
            reason: format!("{v}"),
        })
    };
    let info_offs = offset(h.i32(2, "info_offs")?, "info_offs")?;
    let info_len = h.i16(6, "info_length")?.max(0) as usize;
    let info = source.read_at(info_offs, info_len, "info")?;
    // One character per byte (Latin-1), so that each value's bytes are
    // at hand for `c_text`.
    let info: String = info.iter().map(|&b| char::from(b)).collect();
    let id = info
        .lines()
        .find_map(|l| {
            let (k, v) = l.split_once(':')?;
            (k.trim() == "ID").then(|| c_text(&v.chars().map(|c| c as u8).collect::<Vec<_>>()))
        })
        .ok_or_else(|| {
            source.field(
                "info.ID",
                "missing: the info text has no ID line (*IDENTIFICATION ... ID : ...)".into(),
            )
        })?;
    if id.contains("Setup Script") {
        return Err(source.field("info.ID", format!("{id:?}: a setup file holds no data")));
    }
    let mut blocks_n = i64::from(h.i16(18, "no_of_data_blocks")?);
    if blocks_n == 0x7FFF {
        blocks_n = i64::from(h.u32(34, "reserved1")?);
    }
    // Each block has a 22-byte header in the file: a count past what the
    // file holds is refused before any block is read.
    if blocks_n < 0 || blocks_n as u64 > size / BLOCK_HEADER_BYTES as u64 {
        return Err(source.field(
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
    let next = offset(h.i32(14, "data_block_offs")?, "data_block_offs")?;
    let new_headers = revision & 0xF >= 15;
    let decay_blocks = count_decay_blocks(&mut source, next, blocks_n as usize, new_headers);
    Ok(SdtReader {
        source,
        id,
        revision: revision & 0xF,
        module: module_name((revision >> 4) & 0xFF),
        left_out: Vec::new(),
        decay_blocks,
        measurements,
        new_headers,
        next,
        index: 0,
        blocks: blocks_n as usize,
    })
}

/// The decay-curve blocks among the first `blocks` of the chain of block
/// headers from `first`, read header by header (22 bytes each) until one
/// does not read or the chain turns back; the blocks themselves are
/// checked when read.
fn count_decay_blocks(source: &mut Source, first: u64, blocks: usize, new_headers: bool) -> usize {
    let (mut at, mut decay) = (first, 0);
    for i in 0..blocks {
        let Ok(bh) = source.read_at(at, BLOCK_HEADER_BYTES, "data block header") else {
            break;
        };
        let block_type = u16::from_le_bytes([bh[10], bh[11]]);
        decay += usize::from(DECAY_CONTENTS.iter().any(|(c, _)| *c == block_type & 0xF0));
        let ext = if new_headers {
            u64::from(bh[1]) << 32
        } else {
            0
        };
        let next = u64::from(u32::from_le_bytes([bh[6], bh[7], bh[8], bh[9]])) | ext;
        if i + 1 < blocks && next <= at {
            break;
        }
        at = next;
    }
    decay
}

/// Reads every decay-curve block of the `.sdt` file at `path`, keeping
/// what each held but not its counts.
pub fn read(path: &Path) -> Result<SdtFile, SdtError> {
    let mut reader = open(path)?;
    let mut blocks = Vec::new();
    let mut spare = None;
    while let Some(b) = reader.next_block(spare.take())? {
        blocks.push(b.summary());
        spare = Some(b.counts);
    }
    Ok(SdtFile {
        path: path.to_owned(),
        id: reader.id,
        revision: reader.revision,
        module: reader.module,
        blocks,
        left_out: reader.left_out,
    })
}

impl SdtReader {
    /// The next block of decay curves (blocks of other kinds are passed
    /// over and named in [`SdtReader::left_out`]), `None` after the last.
    /// `spare`, the counts of a block the caller no longer needs, lends its
    /// memory to this one when of the same width.
    pub fn next_block(&mut self, spare: Option<BlockCounts>) -> Result<Option<SdtBlock>, SdtError> {
        while self.index < self.blocks {
            let index = self.index;
            self.index += 1;
            if let Some(b) = self.block(index)? {
                return self.decode(b, spare).map(Some);
            }
        }
        Ok(None)
    }

    /// Block `index`'s header, checked; `None` (and a note) for a block
    /// that is not decay curves.
    fn block(&mut self, index: usize) -> Result<Option<BlockHead>, SdtError> {
        let what = format!("data block {index}");
        let at = self.next;
        let bh = self
            .source
            .read_at(at, BLOCK_HEADER_BYTES, &format!("{what} header"))?;
        let b = Fields {
            path: &self.source.path,
            what: format!("{what} header"),
            bytes: &bh,
        };
        let (ext_data, ext_next) = if self.new_headers {
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
        if index + 1 < self.blocks && next_offs <= at {
            return Err(self.source.field(
                &format!("{what} header.next_block_offs"),
                format!(
                    "{next_offs} does not lie past this header (byte {at}): the chain of blocks loops"
                ),
            ));
        }
        self.next = next_offs;
        let contents = block_type & 0xF0;
        let Some(&(_, name)) = DECAY_CONTENTS.iter().find(|(c, _)| *c == contents) else {
            let name = OTHER_CONTENTS
                .iter()
                .find(|(c, _)| *c == contents)
                .map_or("unknown", |(_, n)| n);
            self.left_out.push(format!(
                "{what} ({name} block, type 0x{block_type:04X}): not decay curves"
            ));
            return Ok(None);
        };
        let m = usize::try_from(meas_no)
            .ok()
            .and_then(|i| self.measurements.get(i))
            .cloned()
            .ok_or_else(|| {
                self.source.field(
                    &format!("{what}.meas_desc_block_no"),
                    format!(
                        "{meas_no}, but the file has {} measurement description blocks",
                        self.measurements.len()
                    ),
                )
            })?;
        let (stored_as, item) = match block_type & 0xF00 {
            0x000 => ("u16", 2),
            0x100 => ("u32", 4),
            0x200 => ("f64", 8),
            other => {
                return Err(self.source.field(
                    &format!("{what}.block_type"),
                    format!(
                        "0x{block_type:04X}: data type bits 0x{other:03X} are not u16, u32 or f64"
                    ),
                ));
            }
        };
        let curve_bytes = m.adc_re * item;
        if length == 0 || !length.is_multiple_of(curve_bytes) {
            return Err(self.source.field(
                &format!("{what}.block_length"),
                format!(
                    "{length} bytes is not a whole number of curves of {} {stored_as} points",
                    m.adc_re
                ),
            ));
        }
        let curves = length / curve_bytes;
        let (rows, cols) = m.layout(curves).map_err(|reason| {
            self.source
                .field(&format!("{what} (measurement {meas_no})"), reason)
        })?;
        let unit = m.micro_unit_s().map_err(|reason| {
            self.source.field(
                &format!("measurement description block {meas_no}.tac_r"),
                reason,
            )
        })?;
        Ok(Some(BlockHead {
            index,
            number,
            contents: name,
            stored_as,
            item,
            zipped: block_type & 0x1000 != 0,
            data_offs,
            next_offs,
            length,
            points: m.adc_re,
            rows,
            cols,
            unit,
            sync_rates_hz: m.sync_rates_hz,
            module: m.module,
            tac_limits_percent: m.tac_limits_percent,
        }))
    }

    /// Reads and decodes the block `b` describes, into `spare`'s memory
    /// when it fits.
    fn decode(&mut self, b: BlockHead, spare: Option<BlockCounts>) -> Result<SdtBlock, SdtError> {
        let what = format!("data block {}", b.index);
        let path = self.source.path.clone();
        // The decoded block (its width) and, for a zipped block, its
        // packed bytes: nothing else of its size is held.
        let out_item: u64 = if b.item == 2 { 2 } else { 4 };
        crate::memory::check(
            crate::memory::bytes_of([b.points, b.rows, b.cols], out_item),
            || {
                format!(
                    "{what} of {} ({} curves of {} points)",
                    path.display(),
                    b.rows * b.cols,
                    b.points
                )
            },
        )?;
        let curves = b.rows * b.cols;
        let shape = (b.points, b.rows, b.cols);
        let decoded = if b.zipped {
            let end = if b.next_offs > b.data_offs {
                b.next_offs
            } else {
                self.source.size
            };
            // Offsets from the file: one past its end reads nothing and
            // fails in `read_at`, naming the block.
            let packed = self.source.read_at(
                b.data_offs,
                end.saturating_sub(b.data_offs) as usize,
                &what,
            )?;
            let mut archive =
                zip::ZipArchive::new(std::io::Cursor::new(&packed[..])).map_err(|e| {
                    self.source
                        .field(&what, format!("its zip-compressed data do not open: {e}"))
                })?;
            let mut member = archive.by_index(0).map_err(|e| {
                self.source.field(
                    &what,
                    format!("its zip archive has no readable first member: {e}"),
                )
            })?;
            if member.size() != b.length as u64 {
                return Err(self.source.field(
                    &what,
                    format!(
                        "its zip member holds {} bytes, the block header says {}",
                        member.size(),
                        b.length
                    ),
                ));
            }
            // Inflated a few curves at a time, straight into the block's
            // points: no copy of the whole inflated block.
            let decoded = decode_points(b.item, b.points, curves, shape, spare, |buf| {
                member.read_exact(buf)
            });
            match decoded {
                Err(PointsError::Read(e)) => {
                    return Err(self.source.field(
                        &what,
                        format!("its zip-compressed data do not decompress to the {} bytes the header says: {e}", b.length),
                    ));
                }
                Ok(counts) => {
                    // The member's CRC-32 is checked when a read meets its
                    // end: the points were read exactly, so one more read.
                    let mut tail = [0u8; 1];
                    match member.read(&mut tail) {
                        Ok(0) => Ok(counts),
                        Ok(_) => {
                            return Err(self.source.field(
                                &what,
                                format!(
                                    "its zip member holds more than the {} bytes the header says",
                                    b.length
                                ),
                            ));
                        }
                        Err(e) => {
                            return Err(self.source.field(
                                &what,
                                format!("its zip member fails its CRC-32 check ({e}): the file is damaged"),
                            ));
                        }
                    }
                }
                other => other,
            }
        } else {
            // Straight from the file, a few curves at a time: no copy of
            // the block (32 MB for a 256 x 256 x 256 u16 image) whose
            // fresh pages the kernel would zero.
            let file = self.source.seek_to(b.data_offs, b.length, &what)?;
            decode_points(b.item, b.points, curves, shape, spare, |buf| {
                file.read_exact(buf)
            })
        };
        let counts = decoded.map_err(|e| match e {
            PointsError::Value(reason) => self.source.field(&what, reason),
            PointsError::Read(e) => self.source.io(e),
        })?;
        Ok(SdtBlock {
            index: b.index,
            number: b.number,
            contents: b.contents,
            stored_as: b.stored_as,
            zipped: b.zipped,
            micro_unit_s: b.unit,
            module: b.module,
            sync_rates_hz: b.sync_rates_hz,
            tac_limits_percent: b.tac_limits_percent,
            counts,
        })
    }
}

/// A decay block's header and measurement, checked, before its data.
struct BlockHead {
    index: usize,
    number: u32,
    contents: &'static str,
    stored_as: &'static str,
    item: usize,
    zipped: bool,
    data_offs: u64,
    next_offs: u64,
    length: usize,
    points: usize,
    rows: usize,
    cols: usize,
    unit: Result<f64, String>,
    module: String,
    sync_rates_hz: SyncRates,
    tac_limits_percent: Option<(f64, f64)>,
}

/// Why a block's points could not be decoded.
enum PointsError {
    /// A value that is no count.
    Value(String),
    /// The bytes could not be read.
    Read(std::io::Error),
}

/// Counts in (point, row, column) order, `shape`, from `curves` curves of
/// `points` little-endian values of `item` bytes (u16, u32, f64) stored
/// curve after curve, which `fill` delivers in order, a few curves to a
/// call (it fills the buffer it is given); an `f64` must be a whole count
/// of at most `u32::MAX`. `spare`'s memory is used when of the width.
fn decode_points(
    item: usize,
    points: usize,
    curves: usize,
    shape: (usize, usize, usize),
    spare: Option<BlockCounts>,
    fill: impl FnMut(&mut [u8]) -> std::io::Result<()>,
) -> Result<BlockCounts, PointsError> {
    fn shaped<T>(shape: (usize, usize, usize), v: Vec<T>) -> Array3<T> {
        Array3::from_shape_vec(shape, v).expect("whole curves of the layout's size")
    }
    match item {
        2 => {
            let out = match spare {
                Some(BlockCounts::U16(a)) => a.into_raw_vec_and_offset().0,
                _ => Vec::new(),
            };
            let v = transpose::<2, u16>(out, points, curves, fill)?;
            Ok(BlockCounts::U16(shaped(shape, v)))
        }
        _ => {
            let out = match spare {
                Some(BlockCounts::U32(a)) => a.into_raw_vec_and_offset().0,
                _ => Vec::new(),
            };
            let v = if item == 4 {
                transpose::<4, u32>(out, points, curves, fill)
            } else {
                transpose::<8, u32>(out, points, curves, fill)
            }?;
            Ok(BlockCounts::U32(shaped(shape, v)))
        }
    }
}

/// A stored value of `ITEM` bytes as a count of type `T`.
trait StoredCount<const ITEM: usize>: Copy + Default {
    fn from_stored(b: [u8; ITEM], at: usize) -> Result<Self, PointsError>;
}

impl StoredCount<2> for u16 {
    #[inline(always)]
    fn from_stored(b: [u8; 2], _: usize) -> Result<Self, PointsError> {
        Ok(u16::from_le_bytes(b))
    }
}

impl StoredCount<4> for u32 {
    #[inline(always)]
    fn from_stored(b: [u8; 4], _: usize) -> Result<Self, PointsError> {
        Ok(u32::from_le_bytes(b))
    }
}

impl StoredCount<8> for u32 {
    #[inline(always)]
    fn from_stored(b: [u8; 8], at: usize) -> Result<Self, PointsError> {
        let v = f64::from_le_bytes(b);
        if !(v.is_finite() && v >= 0.0 && v.fract() == 0.0 && v <= f64::from(u32::MAX)) {
            return Err(PointsError::Value(format!(
                "value {at} is {v}: a histogram point must be a whole count from 0 to 2^32 - 1"
            )));
        }
        Ok(v as u32)
    }
}

/// [`decode_points`] for values of `ITEM` bytes into `out` (its memory
/// reused): the curves read [`CURVES_PER_READ`] at a time (a buffer that
/// stays in cache), each point's values of those curves written side by
/// side. One loop per value width, so that the width is no branch in the
/// inner loop: `info` of a 256 x 256 x 256 u16 block took 0.19 s with
/// ndarray's transposing copy (a point-major walk over the whole file),
/// 0.11-0.13 s with a width-generic tiled loop, and 0.04 s so
/// (BENCHMARKS.md).
fn transpose<const ITEM: usize, T: StoredCount<ITEM>>(
    mut out: Vec<T>,
    points: usize,
    curves: usize,
    mut fill: impl FnMut(&mut [u8]) -> std::io::Result<()>,
) -> Result<Vec<T>, PointsError> {
    // Every element is written below: a reused buffer keeps its pages,
    // and a fresh one is zeroed once by the allocator.
    out.clear();
    out.resize(curves * points, T::default());
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
                *slot = T::from_stored(b, (c0 + c) * points + k)?;
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
