//! Live-acquisition throughput: decode + bin of the project's own event
//! records from memory (frames with CRC checks, and records alone), and the
//! sustained end-to-end rate of the mock device over the in-process USB
//! transport and over a pseudo-terminal (unpaced: as fast as the host takes
//! photons).

/// The command's allocator, so that the bench times what `scatterscope` runs.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

use std::sync::atomic::AtomicBool;

#[path = "common/photons.rs"]
mod photons;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use firmware_protocol::{EventBatch, FrameDecoder, FrameKind, encode_frame};
use scatterscope::acquire::StreamPlan;
use scatterscope::acquire::mock::{MockSetup, MockSource};
use scatterscope::physics::{KernelStack, Preset, Sampling};
use scatterscope::scene::Scene;
use scatterscope::tags::binning::{Binner, FrameSelect, PixelMap, Region, TimeWindow};
use scatterscope::tags::wire::bin_batch;
use scatterscope_drivers::pipeline::count_records;
use scatterscope_mocks::{EmitterOptions, MockOptions};

const EVENTS: u64 = 20_000_000;
/// Photons of one replayed end-to-end run.
const REPLAYED: u64 = 200_000_000;

/// The synthetic stream as a USB reader receives it: framed batches.
fn wire_stream() -> Vec<u8> {
    let mut wire = Vec::with_capacity(EVENTS as usize * 8 + (1 << 20));
    photons::batches(EVENTS, |payload| {
        encode_frame(FrameKind::Events, payload, &mut wire).unwrap()
    });
    wire
}

fn binner() -> Binner {
    // The paper's binning: 30 bins of 4 ps (a 7.9 MB stack).
    let window = TimeWindow {
        start: 0.0,
        width: 4.0,
        bins: 30,
    };
    let map = PixelMap::Sensor {
        sensor_width: 256,
        region: Region {
            x: 0,
            y: 0,
            width: 256,
            height: 256,
        },
    };
    Binner::new(window, map, None, FrameSelect::Sum)
}

fn mock_setup(device: MockOptions) -> MockSetup {
    let setup = Preset::Paper.setup();
    MockSetup {
        scene: Scene::parse("usaf").render(256, 256).unwrap(),
        kernels: KernelStack::build(&setup, Sampling::Integrated).unwrap(),
        emitter: EmitterOptions::default(),
        device,
    }
}

/// Unpaced: every photon drawn from the ST-PSF.
fn drawn(photons: u64) -> MockOptions {
    MockOptions {
        real_time: false,
        max_photons: photons,
        ..MockOptions::default()
    }
}

/// Unpaced replay of 16 drawn batches: the host path at full speed.
fn replayed(photons: u64) -> MockOptions {
    MockOptions {
        replay_batches: 16,
        ..drawn(photons)
    }
}

/// The mock on the in-process USB transport.
const USB: bool = false;
/// The mock behind a pseudo-terminal.
const SERIAL: bool = true;

/// One acquisition through the pipeline `acquire` runs; the photons binned.
fn run_mock(serial: bool, device: MockOptions) -> u64 {
    let setup = Preset::Paper.setup();
    let mut plan = StreamPlan {
        software: "bench".into(),
        ..StreamPlan::default()
    };
    plan.set_window(&setup.bins);
    plan.t_start_ps = 0.0;
    let mut source = MockSource::open(mock_setup(device), serial, setup.total_photons).unwrap();
    let out =
        scatterscope::acquire::run(&mut source, &plan, &AtomicBool::new(false), |_| {}).unwrap();
    source.join();
    assert!(out.ledger.balances() && out.ledger.counts.lost_in_device == 0);
    out.ledger.counts.binned
}

fn benches(c: &mut Criterion) {
    let wire = wire_stream();
    let mut g = c.benchmark_group("acquire");
    g.sample_size(10);
    g.throughput(Throughput::Elements(EVENTS));
    g.bench_function("decode_bin_frames_from_memory", |b| {
        b.iter(|| {
            let mut dec = FrameDecoder::new();
            let mut bin = binner();
            // Chunks as a USB reader delivers them.
            for chunk in wire.chunks(1 << 16) {
                dec.push_with(chunk, |f| {
                    bin_batch(&EventBatch::parse(f.payload).unwrap(), &mut bin);
                });
            }
            bin.finish().1.binned
        })
    });
    let mut payloads = Vec::new();
    let mut dec = FrameDecoder::new();
    dec.push(&wire);
    while let Some(f) = dec.next_frame() {
        payloads.push(f.payload.to_vec());
    }
    g.bench_function("bin_checked_batches_from_memory", |b| {
        b.iter(|| {
            let mut bin = binner();
            for p in &payloads {
                bin_batch(&EventBatch::parse(p).unwrap(), &mut bin);
            }
            bin.finish().1.binned
        })
    });
    // The ledger's own pass over the records in the pipeline's decoder
    // thread (the consumer decodes them again to bin them).
    g.bench_function("count_records_of_the_stream", |b| {
        b.iter(|| {
            payloads
                .iter()
                .map(|p| count_records(&EventBatch::parse(p).unwrap()).0)
                .sum::<u64>()
        })
    });
    g.throughput(Throughput::Bytes(wire.len() as u64));
    // The memory-bandwidth reference: one streaming read of the records.
    g.bench_function("sum_of_the_stream_words", |b| {
        b.iter(|| {
            wire.chunks_exact(8)
                .map(|c| u64::from_le_bytes(c.try_into().unwrap()))
                .fold(0u64, u64::wrapping_add)
        })
    });
    g.bench_function("crc32c_table_of_the_stream", |b| {
        b.iter(|| firmware_protocol::frame::CRC.checksum(&wire))
    });
    g.bench_function("crc32c_hardware_of_the_stream", |b| {
        b.iter(|| firmware_protocol::frame::crc32c(&wire))
    });
    g.throughput(Throughput::Elements(4_000_000));
    // The mock's own cost: drawing the photons, nothing sent.
    g.bench_function("mock_emitter_alone", |b| {
        let m = mock_setup(drawn(4_000_000));
        let scene: Vec<f64> = m.scene.iter().copied().collect();
        b.iter(|| {
            let mut e =
                scatterscope_mocks::Emitter::new(&scene, &m.kernels, m.emitter.clone()).unwrap();
            (0..4_000_000)
                .map(|_| u64::from(e.next_detection().pixel))
                .sum::<u64>()
        })
    });
    g.bench_function("mock_usb_end_to_end", |b| {
        b.iter(|| run_mock(USB, drawn(4_000_000)))
    });
    g.bench_function("mock_serial_end_to_end", |b| {
        b.iter(|| run_mock(SERIAL, drawn(4_000_000)))
    });
    // The whole host path at hardware rates: replayed batches through the
    // in-process USB transport, reader, frame decoder and binner.
    g.throughput(Throughput::Elements(REPLAYED));
    g.bench_function("mock_usb_replay_end_to_end", |b| {
        b.iter(|| run_mock(USB, replayed(REPLAYED)))
    });
    g.finish();
}

criterion_group!(acquire_benches, benches);
criterion_main!(acquire_benches);
