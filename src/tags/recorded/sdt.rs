//! Becker & Hickl histogram files (`.sdt`): each decay block a stack in
//! its own size and time unit, read and handed on one block at a time.

use std::path::Path;
use std::time::Instant;

use ndarray::Array3;

use super::RecordedFormat;
use super::{Handed, RecordedSource};
use crate::formats::becker_hickl::sdt::{self, BlockCounts};
use crate::formats::becker_hickl::spc::SpcOptions;
use crate::stack::{CountsView, RecordedBins, StackMeta, Unstated};
use crate::tags::binned::{
    BinSpec, BinnedFile, Pixels, RecordedFileError, Recording, StackCounts, check_stack_memory,
    spec_error,
};
use crate::tags::binning::{FrameSelect, MAX_BINS, PixelMap, TimeWindow};
use crate::tags::convert::{Conversion, ConvertError};
use crate::tags::counts::Counts;
use crate::tags::survey::Survey;
use std::sync::atomic::AtomicBool;

/// Becker & Hickl's histogram files: each decay block becomes a stack in
/// its own size and time unit, its curve points summed into the window's
/// bins (whole points only), and is handed to `each` before the next block
/// is read (one block in memory, its memory reused for the next); blocks
/// that are not decay curves are left out, by name. A block whose
/// measurement states no time unit is binned by curve point, marked so.
pub struct SdtFiles;

impl RecordedSource for SdtFiles {
    fn bin(
        &self,
        path: &Path,
        spec: &BinSpec,
        each: &mut dyn FnMut(Handed<'_>) -> Result<(), RecordedFileError>,
    ) -> Result<BinnedFile<()>, RecordedFileError> {
        let spec_err = |reason: &str| spec_error(path, reason.to_string());
        if spec.channel.is_some() {
            return Err(spec_err(
                "an .sdt file holds histograms, one data block per routing channel, and no photon's channel: --channel does not apply (each block becomes a stack)",
            ));
        }
        if spec.frames != FrameSelect::Sum {
            return Err(spec_err(
                "an .sdt file's decay blocks each become a stack (stack_f000, ...); --frames applies to scanned PicoQuant files",
            ));
        }
        if spec.pixels == Pixels::Channel {
            return Err(spec_err(
                "an .sdt file's curves are placed as its measurement description says (an image or a row of curves); --pixels channel does not apply (auto or single)",
            ));
        }
        let start = Instant::now();
        let mut reader = sdt::open(path)?;
        let mut tally = Counts::default();
        let mut stacks = Vec::new();
        // The first block's window and unit stand for the file's; every
        // block's shape and bins, to say when they differ.
        struct First {
            window: TimeWindow,
            unit_ps: f64,
            time_unstated: bool,
            shape: (usize, usize, usize),
        }
        let mut first: Option<First> = None;
        let mut shapes = Vec::new();
        let mut unstated = Vec::new();
        let mut spare = None;
        let mut misfits = Vec::new();
        while let Some(b) = reader.next_block(spare.take())? {
            // A window that is no whole number of this block's points leaves
            // the block out, by name (a file of two TAC settings may fit one).
            let (window, unit_ps) = match sdt_window(path, spec, &b)? {
                Ok(w) => w,
                Err(reason) => {
                    misfits.push(reason);
                    spare = Some(b.counts);
                    continue;
                }
            };
            if let Err(why) = &b.micro_unit_s {
                unstated.push(format!("data block {}: {why}", b.index));
            }
            let (binned, meta) = sdt_stack(path, spec, &b, window, unit_ps, &mut tally)?;
            let counts = match (&binned, &b.counts) {
                (Some(c), _) => CountsView::U32(c.view()),
                (None, BlockCounts::U16(c)) => CountsView::U16(c.view()),
                (None, BlockCounts::U32(c)) => CountsView::U32(c.view()),
            };
            first.get_or_insert(First {
                window,
                unit_ps,
                time_unstated: b.micro_unit_s.is_err(),
                shape: counts.dim(),
            });
            shapes.push(format!(
                "{} x {} x {} of {} {} bins",
                counts.dim().0,
                counts.dim().1,
                counts.dim().2,
                meta.bin_width_ps,
                if b.micro_unit_s.is_ok() {
                    "ps"
                } else {
                    "point"
                }
            ));
            each(Handed::Lent(StackCounts {
                counts,
                meta: &meta,
                index: stacks.len(),
                of: reader.decay_blocks,
            }))?;
            stacks.push(());
            spare = Some(b.counts);
        }
        let left_out = std::mem::take(&mut reader.left_out);
        let Some(First {
            window,
            unit_ps,
            time_unstated,
            shape,
        }) = first
        else {
            let why: Vec<_> = left_out.iter().chain(&misfits).cloned().collect();
            return Err(spec_err(&format!(
                "no block of decay curves to bin ({})",
                if why.is_empty() {
                    "the file holds no data blocks".to_string()
                } else {
                    why.join("; ")
                }
            )));
        };
        let seconds = start.elapsed().as_secs_f64();
        let mut notes: Vec<String> = left_out.iter().map(|l| format!("left out: {l}")).collect();
        if spec.pixels == Pixels::Single {
            notes.push("every curve of a block summed into one pixel (--pixels single)".into());
        }
        if shapes.iter().any(|s| *s != shapes[0]) {
            notes.push(format!(
                "the blocks differ in size or time unit, each its own stack: {}",
                shapes.join(", ")
            ));
        }
        Ok(BinnedFile {
            recording: Recording::BeckerHicklHistogram {
                id: format!("{}, module {}", reader.id, reader.module),
                left_out,
                unstated,
                misfits,
            },
            stacks,
            shape,
            counts: tally,
            window,
            resolution_ps: unit_ps,
            records_per_s: tally.records as f64 / seconds.max(1e-9),
            notes,
            truncated: None,
            time_unstated,
        })
    }
}

impl RecordedFormat for SdtFiles {
    fn survey(&self, path: &Path, _spc: &SpcOptions) -> Result<Survey, RecordedFileError> {
        Ok(Survey::BeckerHicklHistogram(Box::new(
            crate::formats::becker_hickl::sdt::read(path)?,
        )))
    }

    fn convert_to_ptu(
        &self,
        input: &Path,
        _output: &Path,
        _allow_truncated: bool,
        _spc: &SpcOptions,
        _stop: &AtomicBool,
    ) -> Result<Conversion, ConvertError> {
        Err(ConvertError::Unsupported {
            path: input.to_owned(),
            reason: "a Becker & Hickl histogram file (.sdt) holds histograms, not photon records: bin it instead".into(),
        })
    }
}

/// The window `spec` asks of block `b`, in whole curve points of its own
/// time unit, and that unit (ps; 1 when the block states none, whose
/// window must then be the default); `Ok(Err(why))` when the window does
/// not fit this block (its points or its unknown unit), which is then
/// left out.
fn sdt_window(
    path: &Path,
    spec: &BinSpec,
    b: &sdt::SdtBlock,
) -> Result<Result<(TimeWindow, f64), String>, RecordedFileError> {
    let points = b.counts.dim().0;
    let unit_ps = match &b.micro_unit_s {
        Ok(s) => s * 1e12,
        Err(why) if spec.bin_width_ps.is_some() || spec.t_start_ps != 0.0 => {
            return Ok(Err(format!(
                "data block {}: --bin-width and --t-start are times, and its time unit is unknown ({why}): bin it by curve point without them",
                b.index
            )));
        }
        Err(_) => 1.0,
    };
    let whole = |ps: f64, what: &str| -> Result<usize, String> {
        let n = (ps / unit_ps).round();
        if (n * unit_ps - ps).abs() > 1e-6 * unit_ps.max(ps.abs()) || n < 0.0 {
            return Err(format!(
                "data block {}: {what} {ps} ps is not a whole number of its curve points ({unit_ps:.6} ps each): histograms are binned in whole points",
                b.index
            ));
        }
        Ok(n as usize)
    };
    let width = match spec
        .bin_width_ps
        .map(|w| whole(w, "the bin width"))
        .transpose()
    {
        Ok(width) => width.unwrap_or(1).max(1),
        Err(why) => return Ok(Err(why)),
    };
    let offset = match whole(spec.t_start_ps, "the window start") {
        Ok(offset) => offset,
        Err(why) => return Ok(Err(why)),
    };
    let bins = spec
        .bins
        .unwrap_or_else(|| points.saturating_sub(offset).div_ceil(width).max(1));
    if bins == 0 || bins > MAX_BINS {
        return Err(spec_error(
            path,
            format!("{bins} bins: give 1 to {MAX_BINS}"),
        ));
    }
    Ok(Ok((
        TimeWindow {
            start: offset as f64,
            width: width as f64,
            bins,
        },
        unit_ps,
    )))
}

/// Block `b`'s curve points summed into `window`'s bins (whole points) of
/// `unit_ps` points, counted into `tally`: `None` when the window is the
/// block itself (its counts are the stack's), and the stack's metadata.
fn sdt_stack(
    path: &Path,
    spec: &BinSpec,
    b: &sdt::SdtBlock,
    window: TimeWindow,
    unit_ps: f64,
    tally: &mut Counts,
) -> Result<(Option<Array3<u32>>, StackMeta), RecordedFileError> {
    let (points, h, w) = b.counts.dim();
    let (offset, width, bins) = (window.start as usize, window.width as usize, window.bins);
    let mut meta = StackMeta::measured(
        window.start_ps(unit_ps),
        window.width_ps(unit_ps),
        bins,
        sdt_source(path, b),
        None,
    );
    if b.micro_unit_s.is_err() {
        meta.unstated.push(Unstated::TimeUnit);
    }
    let laser = crate::tags::laser::stated(&[
        ("MEASURE_INFO.StopInfo.max_sync_rate", b.sync_rates_hz.max),
        ("MEASURE_INFO.StopInfo.min_sync_rate", b.sync_rates_hz.min),
    ]);
    meta.laser_frequency_hz = laser.hz;
    meta.laser_notes = laser.notes;
    if let Some((ll, lh)) = b.tac_limits_percent {
        let range = points as f64 * unit_ps;
        meta.recorded_bins = RecordedBins::within(
            &meta.bin_starts_ps,
            meta.bin_width_ps,
            (range * ll / 100.0, range * lh / 100.0),
            format!(
                "the TAC limits {ll:.2} % to {lh:.2} % of the ADC's range, measurement description's tac_ll and tac_lh"
            ),
        );
    }
    if offset == 0 && width == 1 && bins == points && spec.pixels != Pixels::Single {
        let sum = b.counts.total();
        tally.records += (points * h * w) as u64;
        tally.photons += sum;
        tally.binned += sum;
        return Ok((None, meta));
    }
    let (h, w) = if spec.pixels == Pixels::Single {
        (1, 1)
    } else {
        (h, w)
    };
    check_stack_memory(path, &window, &PixelMap::Channel { width: h * w })?;
    let mut counts = Array3::<u32>::zeros((bins, h, w));
    match &b.counts {
        BlockCounts::U16(c) => rebin(c, &mut counts, (offset, width), spec.pixels, tally),
        BlockCounts::U32(c) => rebin(c, &mut counts, (offset, width), spec.pixels, tally),
    }
    Ok((Some(counts), meta))
}

/// Sums the points of `block` from `offset` in groups of `width` into
/// `counts`' bins (every curve into one pixel for [`Pixels::Single`]),
/// counting where each point's photons went.
fn rebin<T: Copy + Into<u32>>(
    block: &Array3<T>,
    counts: &mut Array3<u32>,
    (offset, width): (usize, usize),
    pixels: Pixels,
    tally: &mut Counts,
) {
    let bins = counts.dim().0;
    for (point, plane) in block.outer_iter().enumerate() {
        let sum: u64 = plane.iter().map(|&c| u64::from(c.into())).sum();
        tally.records += plane.len() as u64;
        tally.photons += sum;
        let bin = point
            .checked_sub(offset)
            .map(|p| p / width)
            .filter(|&j| j < bins);
        let Some(bin) = bin else {
            tally.outside_window += sum;
            continue;
        };
        tally.binned += sum;
        let mut target = counts.index_axis_mut(ndarray::Axis(0), bin);
        if pixels == Pixels::Single {
            // Counts of a bin past u32 saturate; an .sdt point holds
            // at most 2^32 - 1 and a stack bin sums `width` planes.
            target[[0, 0]] = target[[0, 0]].saturating_add(u32::try_from(sum).unwrap_or(u32::MAX));
        } else {
            target.zip_mut_with(&plane, |t, &c| *t = t.saturating_add(c.into()));
        }
    }
}

/// Where a stack binned from an `.sdt` block came from, in words.
fn sdt_source(path: &Path, b: &sdt::SdtBlock) -> String {
    format!(
        "{} (Becker & Hickl {} block {}, module {})",
        path.display(),
        b.contents,
        b.index,
        b.module
    )
}
