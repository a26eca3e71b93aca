//! The project's tag files (`.sstags`, from `acquire --tags`): binned
//! onto the device's whole sensor in whole micro-time steps, every frame
//! summed.

use std::path::Path;
use std::time::Instant;

use super::BinsInMemory;
use super::RecordedFormat;
use crate::formats::becker_hickl::spc::SpcOptions;
use crate::formats::sstags::TagFile;
use crate::stack::StackMeta;
use crate::tags::binned::{
    BinSpec, BinnedFile, CountStack, Pixels, RecordedFileError, Recording, check_stack_memory,
    spec_error,
};
use crate::tags::binning::{Binner, FrameSelect, MAX_BINS, PixelMap, Region, TimeWindow};
use crate::tags::convert::{Conversion, ConvertError, from_tag_file};
use crate::tags::survey::{Survey, survey_tag_file};
use crate::tags::wire::bin_batch;
use std::sync::atomic::AtomicBool;

/// The project's tag files.
pub struct TagFiles;

impl BinsInMemory for TagFiles {
    /// Bins a tag file in memory: the device's whole sensor, micro time from
    /// the sync.
    fn bin_in_memory(
        &self,
        path: &Path,
        spec: &BinSpec,
    ) -> Result<BinnedFile<CountStack>, RecordedFileError> {
        let spec_err = |reason| spec_error(path, reason);
        if !matches!(spec.pixels, Pixels::Auto) || spec.frames != FrameSelect::Sum {
            return Err(spec_err(
            "a tag file is binned onto its sensor with every frame summed; pixel and frame mappings do not apply".into(),
        ));
        }
        let raw = TagFile::open(path)?;
        let header = raw.header.clone();
        let res_ps = f64::from(header.resolution_fs) / 1000.0;
        let width_ps = spec.bin_width_ps.unwrap_or(res_ps);
        let bins = spec.bins.unwrap_or_else(|| {
            TimeWindow::period_bins(
                header.sync_period_fs as f64 / 1000.0,
                spec.t_start_ps,
                width_ps,
            )
            .min(MAX_BINS)
        });
        let (w, h) = (usize::from(header.pixels_x), usize::from(header.pixels_y));
        if w == 0 || h == 0 {
            return Err(spec_err(format!("header sensor size {w} x {h} is empty")));
        }
        let window = TimeWindow::from_ps(spec.t_start_ps, width_ps, bins, res_ps)
            .and_then(|win| win.whole_steps(res_ps))
            .map_err(|e| spec_err(e.to_string()))?;
        let map = PixelMap::Sensor {
            sensor_width: w,
            region: Region {
                x: 0,
                y: 0,
                width: w,
                height: h,
            },
        };
        window
            .check_stack(&map)
            .map_err(|e| spec_err(e.to_string()))?;
        check_stack_memory(path, &window, &map)?;
        let mut binner = Binner::new(window, map, spec.channel, FrameSelect::Sum);
        let start = Instant::now();
        let summary = raw.read(|batch| bin_batch(batch, &mut binner))?;
        let seconds = start.elapsed().as_secs_f64();
        let (mut stacks, tally) = binner.finish();
        let counts_binned = stacks.swap_remove(0);
        let source = format!("{} ({} {})", path.display(), header.model, header.serial);
        let record = TagFileRecord {
            tag_file_header: header,
            totals_in_file: summary.totals.is_some(),
        };
        let shape = counts_binned.dim();
        // The device's sync is the laser's pulse train.
        let laser_hz = 1e15 / record.tag_file_header.sync_period_fs as f64;
        let mut meta = StackMeta::measured(
            window.start_ps(res_ps),
            window.width_ps(res_ps),
            window.bins,
            source,
            Some(serde_json::to_value(&record).expect("the record serialises")),
        );
        let laser = crate::tags::laser::stated(&[("sync period", Some(laser_hz))]);
        meta.laser_frequency_hz = laser.hz;
        meta.laser_notes = laser.notes;
        let stack = CountStack {
            counts: counts_binned,
            meta,
        };
        let truncated = summary
            .totals
            .is_none()
            .then(|| "no end frame: the recording was cut (crash or disconnect)".to_string());
        Ok(BinnedFile {
            recording: Recording::TagFile { summary },
            stacks: vec![stack],
            shape,
            counts: tally,
            window,
            resolution_ps: res_ps,
            records_per_s: tally.records as f64 / seconds.max(1e-9),
            notes: Vec::new(),
            truncated,
            time_unstated: false,
        })
    }
}

impl RecordedFormat for TagFiles {
    fn survey(&self, path: &Path, _spc: &SpcOptions) -> Result<Survey, RecordedFileError> {
        let (summary, s) = survey_tag_file(path)?;
        Ok(Survey::TagFile(Box::new(summary), s))
    }

    fn convert_to_ptu(
        &self,
        input: &Path,
        output: &Path,
        _allow_truncated: bool,
        _spc: &SpcOptions,
        stop: &AtomicBool,
    ) -> Result<Conversion, ConvertError> {
        from_tag_file(input, output, stop)
    }
}

/// What a stack binned from a tag file records about its source.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TagFileRecord {
    /// The file's header.
    pub tag_file_header: crate::formats::sstags::TagFileHeader,
    /// Whether the file ends with the device's totals (else it was cut).
    pub totals_in_file: bool,
}
