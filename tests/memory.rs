//! The memory budget: no reader, and no job sized by its input, allocates
//! more than the budget, whatever a header or a size asks for. A counting
//! allocator measures this test process's peak; the budget is set small
//! (64 MiB) and forged files declare arrays of gigabytes to terabytes
//! (sparse, so they cost no disk).

#[path = "common/forged.rs"]
mod forged;

use std::alloc::{GlobalAlloc, Layout, System};
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};

use forged::{forged_exr, forged_npy};
use proptest::prelude::*;
use scatterscope::memory::{self, MemoryError};
use scatterscope::physics::{Preset, Sampling};
use scatterscope::stack::Stack;

/// The system allocator, counting the bytes live and their peak.
struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            let live = LIVE.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
            PEAK.fetch_max(live, Ordering::Relaxed);
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) };
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// The budget of these tests.
const BUDGET: u64 = 64 << 20;

/// Runs `f` and returns its result with the peak of the bytes it held
/// live beyond what was live before it.
fn peak_of<T>(f: impl FnOnce() -> T) -> (T, u64) {
    let before = LIVE.load(Ordering::Relaxed);
    PEAK.store(before, Ordering::Relaxed);
    let out = f();
    let peak = PEAK.load(Ordering::Relaxed).saturating_sub(before);
    (out, peak as u64)
}

fn assert_over_budget(e: &dyn std::error::Error, peak: u64) {
    let text = e.to_string();
    assert!(
        text.contains("more than the budget") && text.contains(memory::LIMIT_ENV),
        "{text}"
    );
    assert!(peak < BUDGET, "peak {peak} bytes with a budget of {BUDGET}");
}

#[test]
fn the_counting_allocator_sees_an_allocation() {
    let (v, peak) = peak_of(|| vec![1u8; 3 << 20]);
    assert!(peak >= 3 << 20 && v.len() == 3 << 20, "peak {peak}");
}

#[test]
fn a_stack_file_larger_than_the_budget_is_refused_before_it_is_read() {
    memory::set_limit(Some(BUDGET));
    let dir = tempfile::tempdir().unwrap();
    // 20 x 32768 x 32768 float32: 86 GB of (sparse) data.
    let big = dir.path().join("big.npy");
    forged_npy(&big, "<f4", &[20, 32768, 32768]);
    let (r, peak) = peak_of(|| Stack::read(&big));
    assert_over_budget(&r.unwrap_err(), peak);
    // A small one still reads.
    let small = dir.path().join("small.npy");
    forged_npy(&small, "<f4", &[2, 16, 16]);
    let ((data, _), _) = peak_of(|| Stack::read(&small).unwrap());
    assert_eq!(data.dim(), (2, 16, 16));
}

#[test]
fn an_exr_header_declaring_more_than_the_budget_is_refused_before_decoding() {
    memory::set_limit(Some(BUDGET));
    let dir = tempfile::tempdir().unwrap();
    // A real one-channel image, its data window then declared 131072 wide
    // and tall, padded to 17 MiB: the file could hold that much compressed,
    // but not the budget.
    let path = dir.path().join("forged.exr");
    forged_exr(&path, 131_072, 131_072, 17 << 20);
    let (r, peak) = peak_of(|| Stack::read(&path));
    let e = r.unwrap_err();
    assert!(peak < BUDGET, "peak {peak}");
    assert!(e.to_string().contains("forged.exr"), "{e}");
}

#[test]
fn jobs_sized_by_a_sensor_or_bin_count_are_refused_before_building() {
    memory::set_limit(Some(BUDGET));
    let mut setup = Preset::Paper.setup();
    (setup.sensor.width_px, setup.sensor.height_px) = (20_000, 20_000);
    setup.sensor.fov_cm = 50.0 * 20_000.0 / 256.0;
    let (r, peak) = peak_of(|| scatterscope::psf::PsfReport::build(&setup, Sampling::Integrated));
    assert_over_budget(&r.err().unwrap(), peak);
    let (r, peak) = peak_of(|| {
        scatterscope::simulate::simulate(
            &setup,
            &scatterscope::Scene::parse("disks"),
            Sampling::Integrated,
            Default::default(),
            0,
        )
    });
    assert_over_budget(&r.err().unwrap(), peak);
    // The budget's own error when the environment's limit is not a size.
    memory::set_limit(None);
    // SAFETY: this test's process runs one test (nextest); nothing else
    // reads the environment concurrently.
    unsafe { std::env::set_var(memory::LIMIT_ENV, "lots") };
    assert!(matches!(
        memory::budget(),
        Err(MemoryError::BadLimit { .. })
    ));
}

#[test]
fn whole_file_reads_refuse_special_files_and_cap_sizes() {
    memory::set_limit(Some(BUDGET));
    let dir = tempfile::tempdir().unwrap();
    for (path, what) in [
        ("/dev/zero", "a character device"),
        (dir.path().to_str().unwrap(), "a directory"),
    ] {
        let (r, peak) = peak_of(|| {
            scatterscope::files::read_bounded(Path::new(path), 1 << 20, "configuration file")
        });
        let e = r.unwrap_err().to_string();
        assert!(e.contains(what) && e.contains(path), "{e}");
        assert!(peak < 1 << 20, "peak {peak}");
    }
    let big = dir.path().join("big.toml");
    std::fs::File::create(&big)
        .unwrap()
        .set_len(2 << 20)
        .unwrap();
    let e = scatterscope::files::read_bounded(&big, 1 << 20, "configuration file")
        .unwrap_err()
        .to_string();
    assert!(e.contains("big.toml") && e.contains("2.0 MiB"), "{e}");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// Whatever shape and type a `.npy` header declares, reading it never
    /// holds more than the budget: it reads, or it is refused first.
    #[test]
    fn no_npy_header_makes_the_reader_exceed_the_budget(
        dims in proptest::collection::vec(1usize..1 << 20, 3),
        descr in proptest::sample::select(vec!["<f4", "<f8", "|u1", "<u2", "<u4", "<u8"]),
    ) {
        memory::set_limit(Some(BUDGET));
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("any.npy");
        forged_npy(&path, descr, &dims);
        let (r, peak) = peak_of(|| Stack::read(&path));
        prop_assert!(peak <= BUDGET, "{dims:?} {descr}: peak {peak}");
        if memory::bytes_of(dims.iter().copied(), 16) > BUDGET {
            prop_assert!(r.is_err(), "{dims:?} {descr} read");
        }
    }

    /// Whatever data window an EXR header declares, and however much the
    /// file holds, reading it never holds more than the budget.
    #[test]
    fn no_exr_header_makes_the_reader_exceed_the_budget(
        w in 1i32..1 << 17,
        h in 1i32..1 << 17,
        len in 0u64..32 << 20,
    ) {
        memory::set_limit(Some(BUDGET));
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("any.exr");
        forged_exr(&path, w, h, len);
        let (_, peak) = peak_of(|| Stack::read(&path));
        prop_assert!(peak <= BUDGET, "{w} x {h} in {len} bytes: peak {peak}");
    }
}

/// Every method's plan declares its working memory: at two sensor sizes
/// the bytes a run holds beyond its problem stay within the declaration,
/// and the declaration within 2.5x of them (it sizes the budget check, so
/// it must not refuse jobs that fit by a wide margin; `auto`, which runs
/// `learned` or `rl-stack` as the stack asks, within 2.5x of the larger
/// of theirs); the problem's own bytes stay within
/// [`memory::PROBLEM_BYTES`] per pixel and bin.
#[test]
fn each_method_declares_the_working_memory_it_uses() {
    use scatterscope::denoise::tv::TotalVariation;
    use scatterscope::forward::poisson_counts;
    use scatterscope::reconstruct::method::{
        Acceleration, Method, MethodOptions, MethodPlan, RlStop, Solver, run_method,
    };
    use scatterscope::{
        Boundary, ForwardModel, KernelStack, Named, Problem, Scene, StackMeta, ValueKind,
    };
    for size in [32usize, 64] {
        let mut setup = Preset::Paper.setup();
        (setup.sensor.width_px, setup.sensor.height_px) = (size, size);
        setup.sensor.fov_cm = 50.0 * size as f64 / 256.0;
        let kernels = KernelStack::build(&setup, Sampling::Integrated).unwrap();
        let model = ForwardModel::new(&kernels, Boundary::Sensor);
        let truth = Scene::parse("disks").render(size, size).unwrap();
        let counts = poisson_counts(&model.expected_scene(truth.view()).counts, 7);
        let stack = Stack::new(
            counts.mapv(|c| c as f32),
            StackMeta::simulated(&kernels, ValueKind::Counts, "test".into()),
        );
        let (problem, peak) = peak_of(|| {
            Problem::new(&stack, &setup, Sampling::Integrated, Boundary::Sensor).unwrap()
        });
        let k = problem.counts.shape()[0];
        let declared = memory::bytes_of([k, size, size], memory::PROBLEM_BYTES);
        assert!(peak <= declared, "problem at {size}: {peak} > {declared}");
        let prior = TotalVariation::default();
        // What a process builds once and keeps is not a run's working
        // memory: the embedded network, the deviance's expectation table
        // and the GEMM's per-thread packing buffers (a first run of the
        // network at 32 px took 4.3 MB, every later one 1.2 MB).
        run_method(
            &problem,
            Method::Learned,
            None,
            &prior,
            &MethodOptions::default(),
            None,
            |_| {},
        )
        .unwrap();
        let mut peaks = std::collections::HashMap::new();
        for (method, solver, bin) in [
            (Method::Pnp, Solver::Split, None),
            (Method::Pnp, Solver::AdmmLbfgs, None),
            (Method::PnpSlice, Solver::Split, Some(3)),
            (Method::PnpSum, Solver::Split, None),
            (Method::Rl, Solver::Split, Some(3)),
            (Method::RlSum, Solver::Split, None),
            (Method::RlStack, Solver::Split, None),
            (Method::ScaledCounts, Solver::Split, None),
            (Method::Learned, Solver::Split, None),
            (Method::Auto, Solver::Split, None),
        ] {
            let mut opts = MethodOptions {
                solver,
                ..MethodOptions::default()
            };
            opts.split.max_iters = 4;
            opts.admm_lbfgs.max_iters = 4;
            opts.rl_stop = RlStop::CrossValidated {
                max_iters: 10,
                acceleration: Acceleration::None,
            };
            let declared = MethodPlan::new(method, bin, k, &prior, &opts)
                .unwrap()
                .working_bytes(&problem);
            let (r, peak) =
                peak_of(|| run_method(&problem, method, bin, &prior, &opts, None, |_| {}));
            r.unwrap();
            let what = format!("{} ({solver:?}) at {size}", method.name());
            assert!(
                peak <= declared,
                "{what}: used {peak} > declared {declared}"
            );
            let reference = match method {
                Method::Auto => peak
                    .max(peaks[Method::Learned.name()])
                    .max(peaks[Method::RlStack.name()]),
                _ => peak,
            };
            assert!(
                declared as f64 <= 2.5 * reference as f64,
                "{what}: declared {declared} > 2.5 x used {reference}"
            );
            peaks.insert(method.name(), peak);
        }
    }
}
