//! Decode + bin throughput of a T3 file read from the page cache.

use std::path::Path;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use scatterscope::tags::Tag;
use scatterscope::tags::binning::{Binner, FrameSelect, PixelMap, TimeWindow};
use scatterscope::tags::picoquant;
use scatterscope::tags::picoquant::records::{Decoder, RecordType};
use scatterscope::tags::picoquant::writer::{PtuWriter, WriterHeader};

const RECORDS: u64 = 20_000_000;

fn make_file(path: &Path) {
    let h = WriterHeader {
        resolution_s: 4e-12,
        sync_rate_hz: 80e6,
        device: "bench".into(),
        imaging: None,
    };
    let mut w = PtuWriter::create(path, RecordType::GenericT3, &h).unwrap();
    let mut t = 0u64;
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    for _ in 0..RECORDS {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        t += state % 40; // about one photon per 20 syncs: overflows every ~50 records
        w.write_tag(Tag::Photon {
            channel: (state >> 40) as u16 % 4,
            macro_time: t,
            micro_time: (state >> 20) as u32 % 3125,
        })
        .unwrap();
    }
    w.finish().unwrap();
}

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
        decoder.decode_all(&chunk, |t| binner.push(t));
    }
    binner.finish().1.binned
}

fn benches(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bench.ptu");
    make_file(&path);
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
