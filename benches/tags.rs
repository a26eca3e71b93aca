//! Decode + bin throughput of recorded tag files read from the page cache,
//! through [`bin_file`], the function `scatterscope bin` calls: a PicoQuant
//! T3 file and one of the project's raw tag files.

/// The command's allocator, so that the bench times what `scatterscope` runs.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

#[path = "common/photons.rs"]
mod photons;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use firmware_protocol::{Config, Identity};
use scatterscope::formats::picoquant;
use scatterscope::formats::picoquant::writer::{write_synthetic_flim, write_synthetic_t3};
use scatterscope::formats::sstags::{TagFileHeader, TagFileWriter};
use scatterscope::tags::bin_file::{BinSpec, bin_file, bin_file_counts};

const RECORDS: u64 = 20_000_000;

/// A raw tag file of the synthetic stream's `RECORDS` photons.
fn write_raw(path: &std::path::Path) {
    let identity = Identity {
        model: "bench".into(),
        serial: "0".into(),
        firmware: [0, 0, 0],
        protocol_version: firmware_protocol::PROTOCOL_VERSION,
        pixels_x: 256,
        pixels_y: 256,
        channels: 1,
        tdc_resolution_fs: 1000,
        sync_period_fs: 12_500_000,
    };
    let config = Config {
        sync_divider: 1,
        resolution_fs: 1000,
        time_window: 0,
        roi: None,
        exposure_ms: 0,
    };
    let header = TagFileHeader::new("bench", &identity, &config, "bench");
    let mut out = TagFileWriter::create(path, &header).unwrap();
    photons::batches(RECORDS, |payload| out.write_batch(payload));
    out.finish(None, scatterscope::files::Completion::Complete)
        .unwrap();
}

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
        b.iter(|| bin_file(&path, &spec).unwrap().counts.binned)
    });
    // A raw tag file onto its 256 x 256 sensor in the paper's 30 bins of
    // 4 ps (a 7.9 MB stack).
    let raw = dir.path().join("bench.sstags");
    write_raw(&raw);
    let spec = BinSpec {
        bin_width_ps: Some(4.0),
        bins: Some(30),
        ..BinSpec::default()
    };
    assert_eq!(bin_file(&raw, &spec).unwrap().counts.binned, RECORDS);
    g.throughput(Throughput::Elements(RECORDS));
    g.bench_function("decode_bin_raw_tag_file_from_page_cache", |b| {
        b.iter(|| bin_file(&raw, &spec).unwrap().counts.binned)
    });
    // A 256 x 256 FLIM image (two frames, summed) as Python's `bin_file`
    // bins it: the counts as binned, narrowed to u16.
    let flim = dir.path().join("flim.ptu");
    write_synthetic_flim(&flim, 256, 730_000).unwrap();
    let spec = BinSpec::default();
    let records = picoquant::open(&flim).unwrap().0.records_present;
    g.throughput(Throughput::Elements(records));
    g.bench_function("decode_bin_flim_image_u16_from_page_cache", |b| {
        b.iter(|| {
            let binned = bin_file_counts(&flim, &spec).unwrap();
            binned.stacks[0].narrowed::<u16>().unwrap().len()
        })
    });
    g.finish();
}

criterion_group!(tags, benches);
criterion_main!(tags);
