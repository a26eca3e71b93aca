//! Decode + bin throughput of a T3 file read from the page cache.

use std::path::Path;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use scatterscope::tags::binning::{Binner, FrameSelect, PixelMap, TimeWindow};
use scatterscope::tags::picoquant;
use scatterscope::tags::picoquant::records::Decoder;
use scatterscope::tags::picoquant::writer::write_synthetic_t3;

const RECORDS: u64 = 20_000_000;

fn bin_file(path: &Path) -> u64 {
    let (info, mut reader) = picoquant::open(path).unwrap();
    let window = TimeWindow {
        start: 0.0,
        width: 1.0,
        bins: 3125,
    };
    let mut binner = Binner::new(window, PixelMap::Single, None, FrameSelect::Sum);
    let mut decoder = Decoder::new(info.record_type);
    let mut chunk = Vec::new();
    while reader.next_chunk(&mut chunk).unwrap() {
        binner.bulk(|sink| decoder.decode_all(&chunk, sink));
    }
    binner.finish().1.binned
}

fn benches(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bench.ptu");
    write_synthetic_t3(&path, RECORDS).unwrap();
    let records = picoquant::open(&path).unwrap().0.records_present;
    let mut g = c.benchmark_group("tags");
    g.throughput(Throughput::Elements(records));
    g.sample_size(10);
    g.bench_function("decode_bin_generic_t3_from_page_cache", |b| {
        b.iter(|| bin_file(&path))
    });
    g.finish();
}

criterion_group!(tags, benches);
criterion_main!(tags);
