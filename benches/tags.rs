//! Decode + bin throughput of a T3 file read from the page cache, through
//! [`bin_file`], the function `scatterscope bin` calls.

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use scatterscope::tags::bin_file::{BinSpec, bin_file};
use scatterscope::tags::picoquant;
use scatterscope::tags::picoquant::writer::write_synthetic_t3;

const RECORDS: u64 = 20_000_000;

fn benches(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bench.ptu");
    write_synthetic_t3(&path, RECORDS).unwrap();
    let records = picoquant::open(&path).unwrap().0.records_present;
    // The default window: one sync period at the file's resolution (3125
    // bins, single pixel).
    let spec = BinSpec::default();
    let first = bin_file(&path, &spec).unwrap();
    assert_eq!(first.window.bins, 3125, "no photon past the period");
    let mut g = c.benchmark_group("tags");
    g.throughput(Throughput::Elements(records));
    g.sample_size(10);
    g.bench_function("decode_bin_generic_t3_from_page_cache", |b| {
        b.iter(|| bin_file(&path, &spec).unwrap().accounting.binned)
    });
    g.finish();
}

criterion_group!(tags, benches);
criterion_main!(tags);
