//! Stiff and extreme instruments: an IRF far narrower than a bin or far
//! wider than the time window, no background, a background far above the
//! signal. Every case gives finite kernels and finite reconstructions (or
//! a clear error), and the background is still found.

use ndarray::{Array2, Array3, Axis};
use scatterscope::Named;
use scatterscope::denoise::NoPrior;
use scatterscope::forward::{Boundary, poisson_counts};
use scatterscope::physics::{Irf, KernelStack, Preset, Sampling, Setup};
use scatterscope::reconstruct::method::{Method, MethodOptions, run_method};
use scatterscope::reconstruct::problem::{BackgroundChoice, Problem};
use scatterscope::stack::{Stack, StackMeta, ValueKind};

fn setup(irf: Option<Irf>) -> Setup {
    let mut s = Preset::Paper.setup();
    s.sensor.width_px = 32;
    s.sensor.height_px = 32;
    s.sensor.fov_cm = 50.0 / 8.0;
    s.total_photons = 2e5;
    s.irf = irf.map(Into::into);
    s
}

/// Every bin of `a` holds the light of `b`'s, to 1e-6 of `total`.
fn assert_same_light(a: &KernelStack, b: &KernelStack, total: f64) {
    for (x, y) in a.bins.iter().zip(&b.bins) {
        assert!(
            (x.photons - y.photons).abs() <= 1e-6 * total,
            "bin {}: {} vs {}",
            x.index,
            x.photons,
            y.photons
        );
    }
}

/// `setup` with an IRF of `fwhm_ps` and `tail_ps`.
fn with_irf(fwhm_ps: f64, tail_ps: f64) -> Setup {
    setup(Some(Irf { fwhm_ps, tail_ps }))
}

/// `setup` with an IRF of `fwhm_ps` and `tail_ps` and a window of `bins`
/// bins opening at `start_ps`, before time zero.
fn opening_early(fwhm_ps: f64, tail_ps: f64, start_ps: f64, bins: usize) -> Setup {
    let mut s = with_irf(fwhm_ps, tail_ps);
    s.bins.start_ps = start_ps;
    s.bins.count = bins;
    s
}

/// A stack of a flat object through `s` with `background` counts per pixel
/// and bin in every bin; the truth on the sensor.
fn measured(s: &Setup, background: f64, seed: u64) -> (Stack, Array2<f64>) {
    let meta = StackMeta::consecutive(s, s.bins.count, ValueKind::Counts, "test".into()).unwrap();
    let path = std::path::Path::new("test");
    let (k, h, w) = (s.bins.count, s.sensor.height_px, s.sensor.width_px);
    let zeros = Stack::from_parts(Array3::zeros((k, h, w)), meta.clone(), path).unwrap();
    let problem = Problem::new(&zeros, s, Sampling::Integrated, Boundary::Sensor).unwrap();
    let truth = Array2::from_elem(problem.model.grid_shape(), 1.0);
    let signal = problem.model.expected(truth.view()).counts;
    let mut mean = Array3::from_elem((k, h, w), background);
    for (i, start) in problem.bin_starts_ps.iter().enumerate() {
        let j = meta.bin_starts_ps.iter().position(|t| t == start).unwrap();
        let mut dst = mean.index_axis_mut(Axis(0), j);
        dst += &signal.index_axis(Axis(0), i);
    }
    let counts = poisson_counts(&mean, seed).mapv(|v| v as f32);
    (
        Stack::from_parts(counts, meta, path).unwrap(),
        problem.model.crop(truth.view()),
    )
}

/// Every method's output on `stack` with `choice`: finite, and its mean.
fn levels(stack: &Stack, s: &Setup, choice: BackgroundChoice) -> Vec<(Method, f64)> {
    let opts = MethodOptions::default();
    let mut out = Vec::new();
    for method in [Method::RlSum, Method::ScaledCounts, Method::Pnp] {
        let problem = Problem::new(stack, s, Sampling::Integrated, Boundary::Sensor).unwrap();
        let (problem, _) = problem.with_background(choice).unwrap();
        let mut o = opts;
        o.split.max_iters = 30;
        let r = run_method(&problem, method, None, &NoPrior, &o, None, |_| {}).unwrap();
        assert!(
            r.image.iter().all(|v| v.is_finite() && *v >= 0.0),
            "{}: non-finite or negative output",
            method.name()
        );
        out.push((method, r.image.mean().unwrap()));
    }
    out
}

#[test]
fn an_irf_far_narrower_than_a_bin_is_the_ideal_instrument() {
    // 0.01 ps against 4 ps bins: the kernels are the ideal ones.
    let narrow = with_irf(0.01, 0.0);
    let a = KernelStack::build(&narrow, Sampling::Integrated).unwrap();
    let b = KernelStack::build(&setup(None), Sampling::Integrated).unwrap();
    assert_eq!(a.len(), b.len());
    assert_same_light(&a, &b, narrow.total_photons);
    let (stack, truth) = measured(&narrow, 0.0, 3);
    for (method, level) in levels(&stack, &narrow, BackgroundChoice::None) {
        let t = truth.mean().unwrap();
        assert!(
            (level - t).abs() < 0.1 * t,
            "{}: {level} vs {t}",
            method.name()
        );
    }
}

#[test]
fn an_irf_far_wider_than_the_window_spreads_light_over_every_bin() {
    // 2 ns FWHM against a 120 ps window: every bin holds about the same
    // light, and the time axis carries almost no information; the kernels
    // stay finite and the reconstructions too.
    let wide = with_irf(2000.0, 500.0);
    let k = KernelStack::build(&wide, Sampling::Integrated).unwrap();
    assert_eq!(k.len(), 30, "every bin receives light");
    let masses: Vec<f64> = k.bins.iter().map(|b| b.photons).collect();
    assert!(masses.iter().all(|m| m.is_finite() && *m > 0.0));
    let (lo, hi) = masses
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(a, b), &m| (a.min(m), b.max(m)));
    assert!(hi < 1.1 * lo, "masses from {lo} to {hi}");
    let (stack, _) = measured(&wide, 0.0, 4);
    levels(&stack, &wide, BackgroundChoice::None);
    // Auto background finds no dark bin: light reaches all of them.
    let problem = Problem::new(&stack, &wide, Sampling::Integrated, Boundary::Sensor).unwrap();
    assert!(problem.estimate_background().is_none());
    let (_, said) = problem.with_background(BackgroundChoice::Auto).unwrap();
    assert!(said.contains("none assumed"), "{said}");
}

#[test]
fn a_background_far_above_the_signal_is_fitted_not_imaged() {
    // Background ten times the mean signal count per pixel and bin; the
    // window opens 100 ps early so that bins before the IRF-spread light
    // measure the background, as a lab would set it.
    let s = opening_early(20.0, 5.0, -100.0, 55);
    let (probe, _) = measured(&s, 0.0, 1);
    let lit: Vec<f64> = probe
        .data
        .outer_iter()
        .map(|b| b.sum() as f64)
        .filter(|&c| c > 0.0)
        .collect();
    let mean_signal = lit.iter().sum::<f64>() / (lit.len() * 32 * 32) as f64;
    let bg = 10.0 * mean_signal;
    let (stack, truth) = measured(&s, bg, 2);
    let problem = Problem::new(&stack, &s, Sampling::Integrated, Boundary::Sensor).unwrap();
    let e = problem
        .estimate_background()
        .expect("the first bins are dark");
    assert!(
        (e.per_pixel_per_bin - bg).abs() < 4.0 * e.standard_error,
        "{e:?} vs {bg}"
    );
    let t = truth.mean().unwrap();
    for (method, level) in levels(&stack, &s, BackgroundChoice::Auto) {
        assert!(
            (level - t).abs() < 0.25 * t,
            "{}: {level} vs truth {t}",
            method.name()
        );
    }
    for (method, level) in levels(&stack, &s, BackgroundChoice::None) {
        assert!(
            level > 3.0 * t,
            "{}: ignoring it gave {level} (truth {t})",
            method.name()
        );
    }
}

#[test]
fn zero_background_given_is_the_model_without_one() {
    let s = setup(None);
    let (stack, _) = measured(&s, 0.0, 9);
    let a = levels(&stack, &s, BackgroundChoice::Given(0.0));
    let b = levels(&stack, &s, BackgroundChoice::None);
    for ((m, x), (_, y)) in a.iter().zip(&b) {
        assert_eq!(x, y, "{}", m.name());
    }
}

#[test]
fn bins_lit_only_by_the_irf_far_tail_are_left_out_not_overflowed() {
    // A 50 ps IRF and a window opening 300 ps early: the first bins' kernels
    // carry 1e-30 of the light and less, and hold only background counts.
    // Their Poisson weights would overflow; they are left out instead.
    let mut s = opening_early(50.0, 0.0, -300.0, 105);
    s.min_bin_photons = 0.0;
    let (stack, truth) = measured(&s, 0.01, 6);
    let problem = Problem::new(&stack, &s, Sampling::Integrated, Boundary::Sensor).unwrap();
    let masses: Vec<f64> = (0..problem.model.bins())
        .map(|k| problem.model.mass(k))
        .collect();
    let total: f64 = masses.iter().sum();
    assert!(
        masses.iter().any(|&m| m < 1e-30 * total),
        "the test needs a bin lit only by the far tail"
    );
    let (problem, _) = problem.with_background(BackgroundChoice::Auto).unwrap();
    let mut opts = MethodOptions::default();
    opts.split.max_iters = 30;
    let r = run_method(&problem, Method::Pnp, None, &NoPrior, &opts, None, |_| {}).unwrap();
    let last = r.trace.rows.last().unwrap();
    for v in [last.deviance, last.primal_residual] {
        assert!(v.is_some_and(f64::is_finite), "{last:?}");
    }
    assert!(
        r.trace
            .notes
            .iter()
            .any(|n| n.contains("background explains")),
        "{:?}",
        r.trace.notes
    );
    let t = truth.mean().unwrap();
    let level = r.image.mean().unwrap();
    assert!((level - t).abs() < 0.1 * t, "{level} vs {t}");
}

#[test]
fn measured_tables_narrower_than_a_bin_or_wider_than_the_window_stay_exact_and_finite() {
    use scatterscope::physics::IrfTable;
    let ideal = KernelStack::build(&setup(None), Sampling::Integrated).unwrap();
    // One entry of 0.01 ps around time zero: the ideal instrument.
    let mut narrow = setup(None);
    narrow.irf = Some(IrfTable::new(0.01, -0.005, vec![1.0]).unwrap().into());
    let k = KernelStack::build(&narrow, Sampling::Integrated).unwrap();
    assert_eq!(k.len(), ideal.len());
    assert_same_light(&k, &ideal, narrow.total_photons);
    // A flat table 3 ns wide against the 120 ps window: every bin gets
    // about the same light, all finite.
    let mut wide = setup(None);
    wide.irf = Some(IrfTable::new(10.0, -1500.0, vec![1.0; 300]).unwrap().into());
    let k = KernelStack::build(&wide, Sampling::Integrated).unwrap();
    assert_eq!(k.len(), 30, "every bin receives light");
    let masses: Vec<f64> = k.bins.iter().map(|b| b.photons).collect();
    let (lo, hi) = masses
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(a, b), &m| (a.min(m), b.max(m)));
    assert!(
        lo > 0.0 && hi.is_finite() && hi < 1.1 * lo,
        "masses from {lo} to {hi}"
    );
    assert!(k.kernels.iter().all(|v| v.is_finite() && *v >= 0.0));
    let (stack, _) = measured(&wide, 0.0, 5);
    levels(&stack, &wide, BackgroundChoice::None);
}
