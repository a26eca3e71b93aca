//! Becker & Hickl files made from the documented layouts (B&H's
//! `SPC_data_file_structure.h`; field offsets as sdtfile's structure
//! definitions place them), not from our readers: `.spc` FIFO files of
//! each module family with every flag, and `.sdt` histogram files with
//! several blocks, data types and a zipped block. No file written by B&H
//! software is public; independent readers (tttrlib, sdtfile) judge these.

#![allow(dead_code)]

use std::io::Write;

/// The record layouts, by tttrlib's names for them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layout {
    /// SPC-130/140/150/830: 32 bits, markers.
    Spc130,
    /// SPC-600/630, 256 channels: 32 bits.
    Spc600_256,
    /// SPC-600/630, 4096 channels: 48 bits.
    Spc600_4096,
}

impl Layout {
    /// Our `--spc-module` name.
    pub fn ours(self) -> &'static str {
        match self {
            Layout::Spc130 => "spc-130",
            Layout::Spc600_256 => "spc-600-256",
            Layout::Spc600_4096 => "spc-600-4096",
        }
    }
    /// tttrlib's container name.
    pub fn tttrlib(self) -> &'static str {
        match self {
            Layout::Spc130 => "SPC-130",
            Layout::Spc600_256 => "SPC-600_256",
            Layout::Spc600_4096 => "SPC-600_4096",
        }
    }
}

/// A small deterministic generator (xorshift), so files are the same on
/// every run.
pub struct Rng(pub u64);

impl Rng {
    pub fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    pub fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
}

/// The header record: macro clock `clock` (0.1 ns units), `routing_bits`,
/// and (SPC-130) the markers flag.
pub fn header(layout: Layout, clock: u32, routing_bits: u8, markers: bool) -> Vec<u8> {
    match layout {
        Layout::Spc600_4096 => {
            let c = (clock as u16).to_le_bytes();
            vec![0, 0x10 | (routing_bits & 0xF), c[0], c[1], 0, 0]
        }
        _ => ((1u32 << 31)
            | (u32::from(routing_bits & 0xF) << 27)
            | (u32::from(markers) << 25)
            | (clock & 0xFF_FFFF))
            .to_le_bytes()
            .to_vec(),
    }
}

/// A photon record: `routing`, `adc`, `macro_time` (within one overflow
/// period), and its MTOV, GAP and INVALID flags.
pub fn photon(
    layout: Layout,
    routing: u32,
    adc: u32,
    macro_time: u32,
    mtov: bool,
    gap: bool,
    invalid: bool,
) -> Vec<u8> {
    let flags = (u32::from(invalid) << 31) | (u32::from(mtov) << 30) | (u32::from(gap) << 29);
    match layout {
        Layout::Spc130 => {
            (flags | ((adc & 0xFFF) << 16) | ((routing & 0xF) << 12) | (macro_time & 0xFFF))
                .to_le_bytes()
                .to_vec()
        }
        Layout::Spc600_256 => {
            (flags | ((routing & 0x7) << 25) | ((macro_time & 0x1_FFFF) << 8) | (adc & 0xFF))
                .to_le_bytes()
                .to_vec()
        }
        Layout::Spc600_4096 => {
            let b1 = (u8::from(gap) << 6)
                | (u8::from(mtov) << 5)
                | (u8::from(invalid) << 4)
                | ((adc >> 8) & 0xF) as u8;
            vec![
                adc as u8,
                b1,
                (macro_time >> 16) as u8,
                routing as u8,
                macro_time as u8,
                (macro_time >> 8) as u8,
            ]
        }
    }
}

/// An overflow count record (32-bit layouts): `count` overflows.
pub fn overflows(count: u32) -> Vec<u8> {
    (0xC000_0000 | (count & 0x0FFF_FFFF)).to_le_bytes().to_vec()
}

/// An SPC-130 marker record: marker `bits`, `macro_time`, MTOV.
pub fn marker(bits: u32, macro_time: u32, mtov: bool) -> Vec<u8> {
    (0x9000_0000 | (u32::from(mtov) << 30) | ((bits & 0xF) << 12) | (macro_time & 0xFFF))
        .to_le_bytes()
        .to_vec()
}

/// A `.spc` file of `n` records after the header: photons on channels
/// below `2^routing_bits` with an ADC peak (a decay), MTOV flags, overflow
/// counts (32-bit layouts), INVALID records, a few GAP flags and (SPC-130)
/// markers; `seed` picks them.
pub fn random_spc(layout: Layout, n: usize, routing_bits: u8, seed: u64) -> Vec<u8> {
    let mut rng = Rng(seed | 1);
    let mut out = header(layout, 500, routing_bits, layout == Layout::Spc130);
    let channels = 1u64 << routing_bits;
    let (adc_max, wrap) = match layout {
        Layout::Spc130 => (4096, 4096),
        Layout::Spc600_256 => (256, 1 << 17),
        Layout::Spc600_4096 => (4096, 1 << 24),
    };
    let mut mt = 0u64;
    for _ in 0..n {
        mt += rng.below(wrap / 8) + 1;
        let mtov = mt >= wrap;
        if mtov {
            mt %= wrap;
        }
        let kind = rng.below(100);
        // A decay: ADC values counted back from the sync, most photons
        // early (large ADC values).
        let decay = (rng.below(adc_max) * rng.below(adc_max)) / adc_max;
        let adc = (adc_max - 1 - decay) as u32;
        let routing = rng.below(channels) as u32;
        let gap = rng.below(500) == 0;
        let rec = match kind {
            0..=2 if layout != Layout::Spc600_4096 => {
                // Overflows with no photon: the count entry, then the
                // time restarts.
                let k = rng.below(5) as u32 + 1;
                mt = rng.below(wrap);
                overflows(k)
            }
            // INVALID with MTOV is an overflow count in the 32-bit
            // layouts: an invalid record there carries no MTOV.
            3..=5 if !(mtov && layout != Layout::Spc600_4096) => {
                photon(layout, routing, adc, mt as u32, mtov, gap, true)
            }
            6..=8 if layout == Layout::Spc130 => marker(1 << rng.below(4), mt as u32, mtov),
            _ => photon(layout, routing, adc, mt as u32, mtov, gap, false),
        };
        out.extend(rec);
    }
    out
}

/// One `.sdt` data block.
pub struct SdtBlock {
    /// Curve values, curve after curve (`adc_re` points each).
    pub values: Vec<f64>,
    /// Stored type: 2 (u16), 4 (u32) or 8 (f64).
    pub item: usize,
    /// Zip-compressed.
    pub zipped: bool,
    /// Block contents code (bits 4-7 of the type: 0x00 decay, 0x10 page,
    /// 0x60 image, 0x20 FCS, ...).
    pub contents: u16,
    /// Measurement description block it refers to.
    pub measurement: u16,
}

/// One measurement description block's fields that matter.
pub struct SdtMeasurement {
    pub tac_r: f32,
    pub tac_g: i16,
    pub adc_re: i16,
    pub scan: (i32, i32),
    /// Scan repeats (`scan_rx`, `scan_ry`; 1 x 1 but in mosaics).
    pub repeats: (i32, i32),
    /// `mod_type`'s 16 bytes as a writer left them.
    pub module: &'static [u8],
    /// `date` (11 bytes; SPCM writes `YYYY-MM-DD`, Prairie View
    /// `MM:DD:YYYY`).
    pub date: &'static [u8],
    /// `StopInfo.min_sync_rate` and `max_sync_rate` (Hz; SPCM writes the
    /// rates the card measured).
    pub sync_rates: (f32, f32),
    /// `tac_ll` and `tac_lh` (percent of the ADC's range; 0 and 0 as a
    /// writer that leaves them out).
    pub tac_limits: (f32, f32),
}

impl SdtMeasurement {
    /// An SPC-150 measurement of one scan repeat.
    pub fn spc150(tac_r: f32, tac_g: i16, adc_re: i16, scan: (i32, i32)) -> Self {
        Self {
            tac_r,
            tac_g,
            adc_re,
            scan,
            repeats: (1, 1),
            module: b"SPC-150",
            date: b"2019-11-05",
            sync_rates: (80e6, 80e6),
            tac_limits: (0.0, 0.0),
        }
    }
}

/// An `.sdt` file of software revision 15 (module SPC-150) with `blocks`
/// described by `measurements`, zipped blocks deflated.
pub fn sdt_file(measurements: &[SdtMeasurement], blocks: &[SdtBlock]) -> Vec<u8> {
    sdt_file_zipped(measurements, blocks, zip::CompressionMethod::Deflated)
}

/// [`sdt_file`] with zipped blocks' members compressed by `method`.
pub fn sdt_file_zipped(
    measurements: &[SdtMeasurement],
    blocks: &[SdtBlock],
    method: zip::CompressionMethod,
) -> Vec<u8> {
    const MEAS_LEN: usize = 512;
    let info = b"*IDENTIFICATION\r\n  ID        : SPC Setup & Data File\r\n  Title     : forged\r\n*END\r\n\r\n";
    let setup =
        b"*SETUP\r\nSYS_PARA_BEGIN:\r\n#SP [SP_TAC_R,F,5.0e-08]\r\nSYS_PARA_END:\r\n*END\r\n";
    let info_offs = 42;
    let setup_offs = info_offs + info.len();
    let meas_offs = setup_offs + setup.len();
    let data_offs = meas_offs + MEAS_LEN * measurements.len();
    let mut out = Vec::new();
    let revision: i16 = (0x28 << 4) | 15;
    out.extend(revision.to_le_bytes());
    out.extend((info_offs as i32).to_le_bytes());
    out.extend((info.len() as i16).to_le_bytes());
    out.extend((setup_offs as i32).to_le_bytes());
    out.extend((setup.len() as u16).to_le_bytes());
    out.extend((data_offs as i32).to_le_bytes());
    out.extend((blocks.len() as i16).to_le_bytes());
    let longest = blocks
        .iter()
        .map(|b| b.values.len() * b.item)
        .max()
        .unwrap_or(0);
    out.extend((longest as u32).to_le_bytes());
    out.extend((meas_offs as i32).to_le_bytes());
    out.extend((measurements.len() as i16).to_le_bytes());
    out.extend((MEAS_LEN as i16).to_le_bytes());
    out.extend(0x5555u16.to_le_bytes());
    out.extend((blocks.len() as u32).to_le_bytes());
    out.extend(0u16.to_le_bytes());
    out.extend(0x55AAu16.to_le_bytes());
    assert_eq!(out.len(), 42);
    out.extend(info);
    out.extend(setup);
    for m in measurements {
        let mut mi = vec![0u8; MEAS_LEN];
        mi[64..68].copy_from_slice(&m.tac_r.to_le_bytes());
        mi[68..70].copy_from_slice(&m.tac_g.to_le_bytes());
        mi[74..78].copy_from_slice(&m.tac_limits.0.to_le_bytes());
        mi[78..82].copy_from_slice(&m.tac_limits.1.to_le_bytes());
        mi[82..84].copy_from_slice(&m.adc_re.to_le_bytes());
        mi[9..9 + m.date.len()].copy_from_slice(m.date);
        mi[117..117 + m.module.len()].copy_from_slice(m.module);
        mi[173..177].copy_from_slice(&m.scan.0.to_le_bytes());
        mi[177..181].copy_from_slice(&m.scan.1.to_le_bytes());
        mi[181..185].copy_from_slice(&m.repeats.0.to_le_bytes());
        mi[185..189].copy_from_slice(&m.repeats.1.to_le_bytes());
        // StopInfo (a MeasStopInfo at byte 211): min_sync_rate at its
        // byte 20, max_sync_rate at 36.
        mi[231..235].copy_from_slice(&m.sync_rates.0.to_le_bytes());
        mi[247..251].copy_from_slice(&m.sync_rates.1.to_le_bytes());
        out.extend(mi);
    }
    for (i, b) in blocks.iter().enumerate() {
        let raw: Vec<u8> = b
            .values
            .iter()
            .flat_map(|&v| match b.item {
                2 => (v as u16).to_le_bytes().to_vec(),
                4 => (v as u32).to_le_bytes().to_vec(),
                _ => v.to_le_bytes().to_vec(),
            })
            .collect();
        let stored = if b.zipped {
            zip_member(&raw, method)
        } else {
            raw.clone()
        };
        let header_at = out.len();
        let data_at = header_at + 22;
        let next = data_at + stored.len();
        let dtype = match b.item {
            2 => 0x000,
            4 => 0x100,
            _ => 0x200,
        };
        let block_type: u16 = 0x1 | b.contents | dtype | if b.zipped { 0x1000 } else { 0 };
        out.extend([0u8, 0u8]);
        out.extend((data_at as u32).to_le_bytes());
        out.extend((next as u32).to_le_bytes());
        out.extend(block_type.to_le_bytes());
        out.extend((b.measurement as i16).to_le_bytes());
        out.extend(((i + 1) as u32).to_le_bytes());
        out.extend((raw.len() as u32).to_le_bytes());
        out.extend(stored);
    }
    out
}

/// `data` as the one member of a zip archive, compressed by `method`.
fn zip_member(data: &[u8], method: zip::CompressionMethod) -> Vec<u8> {
    let mut w = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let options = zip::write::SimpleFileOptions::default().compression_method(method);
    w.start_file("data_block", options).unwrap();
    w.write_all(data).unwrap();
    w.finish().unwrap().into_inner()
}
