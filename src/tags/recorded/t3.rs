//! Files of T3 records (a sync count and a micro time per photon), binned
//! in passes: the default window is one sync period with a margin, widened
//! to every micro time present (binned again when the margin does not
//! hold them); parts of a file bin on the cores at once where no pixel
//! depends on an earlier record.

use std::path::Path;
use std::time::Instant;

use ndarray::{Array3, s};
use rayon::prelude::*;

use crate::formats::becker_hickl::spc::CardFlags;
use crate::stack::{RecordedBins, StackMeta};
use crate::tags::binned::{
    BinSpec, BinnedFile, CountStack, RecordedFileError, Recording, check_stack_memory, spec_error,
    window_and_map,
};
use crate::tags::binning::{Binner, MAX_BINS, PastWindow, PixelMap, TimeWindow};
use crate::tags::counts::Counts;

/// A file of T3 records, read in consecutive parts.
pub(super) trait T3Records: Sync {
    /// Records to bin.
    fn records(&self) -> u64;

    /// Bins the `part`-th of `parts` consecutive ranges of the records
    /// with `binner`; the text of a truncation when the part ends early
    /// and `allow_truncated` lets it, and what the records flagged.
    fn bin_part(
        &self,
        path: &Path,
        part: usize,
        parts: usize,
        binner: Binner,
        allow_truncated: bool,
    ) -> Result<(Binner, Option<String>, CardFlags), RecordedFileError>;

    /// The file as a [`Recording`], with what its records flagged, and
    /// whether it leaves the micro-time unit unstated.
    fn into_recording(self, flags: CardFlags) -> (Recording, bool);
}

/// Bins a T3 file of `(micro-time unit, sync period)` in ps, whose default
/// window is one period, widened to every micro time present.
pub(super) fn bin<F: T3Records>(
    path: &Path,
    spec: &BinSpec,
    file: F,
    (res_ps, period_ps): (f64, f64),
    imaging: Option<crate::events::Imaging>,
    source: String,
    mut notes: Vec<String>,
) -> Result<BinnedFile<CountStack>, RecordedFileError> {
    let spec_err = |reason| spec_error(path, reason);
    let (window, map) =
        window_and_map(spec, res_ps, period_ps, imaging).map_err(|e| spec_err(e.to_string()))?;
    // A default window gets a margin past the sync period, so that micro
    // times just past it (a TAC range a little longer than the period, the
    // last step of a period) bin in one pass instead of two.
    let margin = if spec.bins.is_none() {
        (window.bins / 64 + 8).min(MAX_BINS.saturating_sub(window.bins))
    } else {
        0
    };
    let with_margin = TimeWindow {
        bins: window.bins + margin,
        ..window
    };
    let first = if margin > 0 && with_margin.check_stack(&map).is_ok() {
        with_margin
    } else {
        window
    };
    check_stack_memory(path, &first, &map)?;
    let mut pass = run_pass(path, &file, first, map, spec)?;
    // Photons past the period: in the margin (binned) and past it.
    let (in_margin, last_bin) = photons_from(&pass.stacks, window.bins);
    let past_photons = pass.past.photons + in_margin;
    if past_photons > 0 {
        let max_micro = if pass.past.photons > 0 {
            pass.past.max_micro
        } else {
            let k = last_bin.expect("photons in the margin have a bin") as f64;
            ((window.start + (k + 1.0) * window.width).ceil() - 1.0) as u32
        };
        let needed = window.bins_to_hold(max_micro);
        let where_ = format!(
            "{past_photons} photon(s) had micro times past the window's end ({:.6} ps), up to {max_micro} ({:.6} ps)",
            (window.start + window.width * window.bins as f64) * res_ps,
            f64::from(max_micro) * res_ps
        );
        let wider = TimeWindow {
            bins: needed,
            ..window
        };
        let fits = needed <= MAX_BINS && wider.check_stack(&map).is_ok();
        if spec.bins.is_none() && fits {
            // The default window holds every micro time present.
            if needed <= pass.window.bins {
                trim(&mut pass, needed);
            } else {
                pass = run_pass(path, &file, wider, map, spec)?;
            }
            notes.push(format!(
                "{where_}: the default window (one sync period, {} bins) was widened to {needed} bins to hold them",
                window.bins
            ));
        } else {
            if pass.window.bins != window.bins {
                // Count the margin's photons outside, as the window says.
                pass = run_pass(path, &file, window, map, spec)?;
            }
            notes.push(if spec.bins.is_none() {
                format!(
                    "{where_}: holding them would take {needed} bins, more than {MAX_BINS} or a stack of more than 2^30 counts; they are counted outside the window"
                )
            } else {
                format!("{where_}: they are counted outside the window; {needed} bins would hold them")
            });
        }
    } else if pass.window.bins != window.bins {
        trim(&mut pass, window.bins);
    }
    let Pass {
        stacks,
        counts: tally,
        window,
        records_per_s,
        truncated,
        flags,
        ..
    } = pass;
    if let (crate::tags::binning::FrameSelect::One(n), Some(_)) = (spec.frames, imaging)
        && n as u64 >= tally.frames
    {
        return Err(spec_error(
            path,
            match tally.frames {
                0 => format!("--frames {n}: the file holds no complete frame"),
                f => format!(
                    "--frames {n}: the file holds {f} frames, numbered 0 to {}",
                    f - 1
                ),
            },
        ));
    }
    if tally.over_budget > 0 {
        notes.push(format!(
            "{} photon(s) of frames past the first {} were not kept: the memory budget holds {} stacks of {} bins of {} x {} pixels (bin the frames summed, or one at a time)",
            tally.over_budget,
            stacks.len(),
            stacks.len(),
            window.bins,
            map.image_size().1,
            map.image_size().0,
        ));
    }
    let stacks = if let PixelMap::Channel { .. } = map {
        // Trim the channel row to the highest channel that saw a photon in
        // any kept frame (rows scanned contiguously: a column-wise scan of
        // the empty channels cost a sixth of the binning on small files).
        let width = stacks[0].dim().2;
        let mut seen = vec![0u32; width];
        for row in stacks.iter().flat_map(|s| {
            s.as_slice()
                .expect("the binner's stacks are contiguous")
                .chunks_exact(width)
        }) {
            seen.iter_mut().zip(row).for_each(|(a, &v)| *a |= v);
        }
        let used = seen.iter().rposition(|&v| v > 0).map_or(1, |p| p + 1);
        stacks
            .iter()
            .map(|s| s.slice(s![.., .., ..used]).to_owned())
            .collect()
    } else {
        stacks
    };
    let shape = stacks[0].dim();
    let stacks = stacks
        .into_iter()
        .map(|counts| {
            let mut meta = StackMeta::measured(
                window.start_ps(res_ps),
                window.width_ps(res_ps),
                window.bins,
                source.clone(),
                None,
            );
            // Micro times run from the sync to the next one: a bin past
            // the period's end holds a part of a bin's light, or none.
            // Photons past the period say the span is wider.
            if past_photons == 0 {
                meta.recorded_bins = RecordedBins::within(
                    &meta.bin_starts_ps,
                    meta.bin_width_ps,
                    (0.0, period_ps),
                    format!("micro times run from the sync to the next, {period_ps:.1} ps later"),
                );
            }
            CountStack { counts, meta }
        })
        .collect();
    let (recording, time_unstated) = file.into_recording(flags);
    Ok(BinnedFile {
        recording,
        stacks,
        shape,
        counts: tally,
        window,
        resolution_ps: res_ps,
        records_per_s,
        notes,
        truncated,
        time_unstated,
    })
}

/// Photons in bins `from` and later of every stack, and the last such bin
/// that holds any.
fn photons_from(stacks: &[Array3<u32>], from: usize) -> (u64, Option<usize>) {
    let mut total = 0u64;
    let mut last = None;
    for s in stacks {
        for (k, plane) in s.outer_iter().enumerate().skip(from) {
            let n: u64 = plane.iter().map(|&v| u64::from(v)).sum();
            if n > 0 {
                total += n;
                last = last.max(Some(k));
            }
        }
    }
    (total, last)
}

/// Keeps the first `bins` bins of a pass (the rest are empty).
fn trim(pass: &mut Pass, bins: usize) {
    for s in &mut pass.stacks {
        // In place: the first bins of a standard-layout array stay
        // contiguous, and nothing is copied.
        s.slice_collapse(s![..bins, .., ..]);
    }
    pass.window.bins = bins;
}

/// Records of the smallest part of a file binned on a core of its own.
const PART_RECORDS: u64 = 1 << 22;

/// One read -> decode -> bin pass over the records.
struct Pass {
    stacks: Vec<Array3<u32>>,
    counts: Counts,
    past: PastWindow,
    window: TimeWindow,
    records_per_s: f64,
    truncated: Option<String>,
    flags: CardFlags,
}

fn run_pass<F: T3Records>(
    path: &Path,
    file: &F,
    window: TimeWindow,
    map: PixelMap,
    spec: &BinSpec,
) -> Result<Pass, RecordedFileError> {
    let start = Instant::now();
    let binner = Binner::new(window, map, spec.channel, spec.frames);
    let records = file.records();
    // Parts of the file binned on the cores at once, where no photon's
    // pixel depends on an earlier record (every map but a scanned image's),
    // each part at least `PART_RECORDS` long and its stack within the
    // memory budget; the counts are sums, equal to one pass's.
    let parts = if binner.order_free() {
        rayon::current_num_threads()
            .min(usize::try_from(records / PART_RECORDS).unwrap_or(usize::MAX))
            .min(binner.max_stacks())
            .max(1)
    } else {
        1
    };
    let (binner, truncated, flags) = if parts > 1 {
        let done: Vec<_> = (0..parts)
            .into_par_iter()
            .map(|i| file.bin_part(path, i, parts, binner.clone(), spec.allow_truncated))
            .collect();
        let mut merged = binner;
        let mut truncated = None;
        let mut flags = CardFlags::default();
        for part in done {
            let (b, t, f) = part?;
            merged.absorb(b);
            truncated = truncated.or(t);
            flags += f;
        }
        (merged, truncated, flags)
    } else {
        file.bin_part(path, 0, 1, binner, spec.allow_truncated)?
    };
    let seconds = start.elapsed().as_secs_f64();
    let past = binner.past_window();
    let (stacks, tally) = binner.finish();
    Ok(Pass {
        records_per_s: tally.records as f64 / seconds.max(1e-9),
        stacks,
        counts: tally,
        past,
        window,
        truncated,
        flags,
    })
}
