//! A new recorded format is one source behind `RecordedSource`, in its
//! own file, describing its file without a `Recording` variant of its own
//! (`Recording::Described`): here a toy format (one line per time bin,
//! its counts for a row of pixels) binned, its stacks handed on, and its
//! summary and warnings in the words of its own description.

use std::path::Path;

use ndarray::Array3;
use scatterscope::stack::{CountsView, StackMeta};
use scatterscope::tags::bin_file::{
    BinSpec, BinnedFile, RecordedFileError, Recording, StackCounts,
};
use scatterscope::tags::binned::DescribedRecording;
use scatterscope::tags::binning::TimeWindow;
use scatterscope::tags::counts::Counts;
use scatterscope::tags::recorded::{Handed, RecordedSource};

/// Lines of whitespace-separated counts, one line per 10 ps bin.
struct ToyFiles;

#[derive(Debug)]
struct ToyFile {
    lines: usize,
}

impl DescribedRecording for ToyFile {
    fn summary(&self, counts: &Counts, _records_per_s: f64) -> String {
        format!(
            "toy file of {} lines: {} photons",
            self.lines, counts.photons
        )
    }

    fn warnings(&self) -> Vec<String> {
        vec!["a toy file states no laser frequency".into()]
    }
}

impl RecordedSource for ToyFiles {
    fn bin(
        &self,
        path: &Path,
        _spec: &BinSpec,
        each: &mut dyn FnMut(Handed<'_>) -> Result<(), RecordedFileError>,
    ) -> Result<BinnedFile<()>, RecordedFileError> {
        let text = std::fs::read_to_string(path).unwrap();
        let rows: Vec<Vec<u32>> = text
            .lines()
            .map(|l| l.split_whitespace().map(|v| v.parse().unwrap()).collect())
            .collect();
        let (bins, width) = (rows.len(), rows[0].len());
        let counts = Array3::from_shape_fn((bins, 1, width), |(k, _, x)| rows[k][x]);
        let photons: u64 = counts.iter().map(|&c| u64::from(c)).sum();
        let meta = StackMeta::measured(0.0, 10.0, bins, path.display().to_string(), None);
        each(Handed::Lent(StackCounts {
            counts: CountsView::U32(counts.view()),
            meta: &meta,
            index: 0,
            of: 1,
        }))?;
        Ok(BinnedFile {
            recording: Recording::Described(Box::new(ToyFile { lines: bins })),
            stacks: vec![()],
            shape: counts.dim(),
            counts: Counts {
                records: photons,
                photons,
                binned: photons,
                ..Counts::default()
            },
            window: TimeWindow {
                start: 0.0,
                width: 1.0,
                bins,
            },
            resolution_ps: 10.0,
            records_per_s: 0.0,
            notes: Vec::new(),
            truncated: None,
            time_unstated: false,
        })
    }
}

#[test]
fn a_new_format_is_one_source_describing_its_own_files() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("decay.toy");
    std::fs::write(&path, "0 1 2\n5 7 9\n3 4 1\n").unwrap();
    let mut handed = Vec::new();
    let binned = ToyFiles
        .bin(&path, &BinSpec::default(), &mut |h| {
            let s = h.view();
            handed.push((s.counts.dim(), s.counts.bin_totals()));
            Ok(())
        })
        .unwrap();
    assert_eq!(handed, vec![((3, 1, 3), vec![3.0, 21.0, 8.0])]);
    assert!(binned.counts.balances(), "{:?}", binned.counts);
    let summary = binned.summary();
    assert_eq!(summary[0], "toy file of 3 lines: 32 photons");
    assert!(
        summary
            .iter()
            .any(|l| l == "warning: a toy file states no laser frequency"),
        "{summary:?}"
    );
}
