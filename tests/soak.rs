//! Soak: a long unpaced acquisition from the mock over the in-process USB
//! transport, every recoverable fault kind injected at seeded random
//! times, the consumer stalled at random. At the end the ledger must be
//! exact, and the process's memory must not grow.
//!
//! 30 s in the test suite; `SCATTERSCOPE_SOAK_S=600 cargo test --release
//! --test soak -- --nocapture` runs the 10-minute version (RELIABILITY.md).
//! A disconnect ends a run, so it is tested on its own (tests/acquisition.rs).

#[path = "common/ledger.rs"]
mod ledger;

use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use scatterscope::acquire::StreamPlan;
use scatterscope::acquire::mock::{MockSetup, MockSource};
use scatterscope::physics::{KernelStack, Preset, Sampling};
use scatterscope::scene::Scene;
use scatterscope_mocks::{EmitterOptions, Faults, MockOptions};

/// What the acquisition's bounded queue holds when full: 256 batches of
/// 64 KiB, MiB.
const QUEUE_HIGH_WATER_MIB: f64 = 16.0;

/// Resident set size of this process, MiB (Linux; `None` elsewhere).
fn rss_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let kb: f64 = status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))?
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()?;
    Some(kb / 1024.0)
}

#[test]
fn soak_with_every_fault_at_random_times_balances_and_stays_flat() {
    let seconds: u64 = std::env::var("SCATTERSCOPE_SOAK_S")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(30);
    let mut setup = Preset::Paper.setup();
    setup.sensor.width_px = 64;
    setup.sensor.height_px = 64;
    setup.sensor.fov_cm = 50.0 / 4.0;
    let faults = Faults {
        drop_bytes_every: 97,
        corrupt_every: 89,
        duplicate_every: 53,
        reorder_every: 61,
        overflow_every: 71,
        overflow_photons: 5_000,
        disconnect_after: 0,
        random_seed: 0x50A4,
    };
    let mock = MockSetup {
        scene: Scene::parse("usaf").render(64, 64).unwrap(),
        kernels: KernelStack::build(&setup, Sampling::Integrated).unwrap(),
        emitter: EmitterOptions {
            seed: 0x50A4,
            dark_rate_hz: 2e5,
            afterpulse_probability: 0.01,
            ..EmitterOptions::default()
        },
        device: MockOptions {
            real_time: false,
            faults: faults.clone(),
            ..MockOptions::default()
        },
    };
    let mut plan = StreamPlan {
        duration: Some(Duration::from_secs(seconds)),
        software: "soak".into(),
        ..StreamPlan::default()
    };
    plan.set_window(&setup.bins);
    let mut source = MockSource::open(mock, false, setup.total_photons).unwrap();
    let started = Instant::now();
    let mut rss = Vec::new();
    let mut last_sample = Instant::now();
    let mut stalls = (0u32, Duration::ZERO);
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let outcome = scatterscope::acquire::run(&mut source, &plan, &AtomicBool::new(false), |_| {
        if last_sample.elapsed() >= Duration::from_secs(1) {
            last_sample = Instant::now();
            if let Some(r) = rss_mib() {
                rss.push(r);
            }
        }
        // The consumer stalls now and then, up to 300 ms.
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        if state.is_multiple_of(20) {
            let pause = Duration::from_millis(state >> 40 & 0xFF).min(Duration::from_millis(300));
            std::thread::sleep(pause);
            stalls = (stalls.0 + 1, stalls.1 + pause);
        }
    })
    .unwrap();
    let truth = source.join();
    let acc = outcome.ledger.clone();
    let ctx = format!("{faults:?}\n{}\n{truth:?}", acc.table().join("\n"));
    println!(
        "soak: {:.0} s, {} photons detected ({:.2} M/s), {} batches, {} damaged, {} duplicated, {} reordered, {} photons lost in the FIFO; {} consumer stalls ({:.1} s)",
        started.elapsed().as_secs_f64(),
        truth.photons_detected,
        truth.photons_detected as f64 / started.elapsed().as_secs_f64() / 1e6,
        truth.batches_sent,
        truth.batches_damaged,
        truth.batches_duplicated,
        truth.batches_reordered,
        truth.photons_lost_fifo,
        stalls.0,
        stalls.1.as_secs_f64()
    );
    // The ledger: exact at the end.
    ledger::assert_exact(&outcome, &truth, &ctx);
    // Every fault kind happened.
    assert!(
        truth.batches_damaged > 0
            && truth.batches_duplicated > 0
            && truth.batches_reordered > 0
            && truth.photons_lost_fifo > 0
            && truth.dark_counts > 0
            && truth.afterpulses > 0
            && stalls.0 > 0,
        "{ctx}"
    );
    // Memory: bounded. While the consumer stalls, the pipeline's queue
    // fills with up to 256 batches of 64 KiB (16 MiB) plus the USB
    // transfers in flight; the allocator may keep that high-water mark
    // resident after the queue drains (glibc does not return freed arena
    // pages), so the floor can step up once by that much. A leak grows
    // without bound: the floor of the last quarter must stay within the
    // queue's capacity (+4 MiB) of the second quarter's, and no sample may
    // exceed the early floor by more than twice the buffers can hold.
    if rss.len() >= 8 {
        let floor = |v: &[f64]| v.iter().cloned().fold(f64::INFINITY, f64::min);
        let q = rss.len() / 4;
        let (early, late) = (floor(&rss[q..2 * q]), floor(&rss[3 * q..]));
        let peak = rss[q..].iter().cloned().fold(0.0, f64::max);
        println!(
            "RSS: {} samples; floor {early:.1} MiB in the second quarter, {late:.1} MiB in the last; peak {peak:.1} MiB",
            rss.len()
        );
        assert!(
            late <= early + QUEUE_HIGH_WATER_MIB + 4.0,
            "memory grew from {early:.1} to {late:.1} MiB, more than the queue holds: {rss:?}"
        );
        assert!(
            peak <= early + 2.0 * QUEUE_HIGH_WATER_MIB,
            "memory peaked at {peak:.1} MiB over {early:.1}: {rss:?}"
        );
    } else {
        println!(
            "{} RSS sample(s) (one per second from /proc/self/status): too few for the memory check",
            rss.len()
        );
    }
}
