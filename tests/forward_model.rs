//! Forward model against independent computations.

use ndarray::{Array2, Array3};
use scatterscope::forward::{Boundary, ForwardModel, poisson_counts};
use scatterscope::physics::{KernelStack, Preset, Sampling, Setup};

fn small_setup(size: usize) -> Setup {
    let mut s = Preset::Paper.setup();
    s.sensor.width_px = size;
    s.sensor.height_px = size;
    s.sensor.fov_cm = 50.0 * size as f64 / 256.0; // keep the paper's pixel pitch
    s
}

#[test]
fn convolution_conserves_photons_per_bin() {
    let s = small_setup(64);
    let k = KernelStack::build(&s, Sampling::Integrated).unwrap();
    let model = ForwardModel::new(&k, Boundary::Periodic);
    let object = Array2::from_shape_fn((64, 64), |(r, c)| ((r * 7 + c * 3) % 10) as f64 / 9.0);
    let e = model.expected(object.view());
    for (i, b) in k.kept_bins().enumerate() {
        let got: f64 = e.counts.index_axis(ndarray::Axis(0), i).sum();
        let want = b.photons * object.sum();
        assert!((got - want).abs() < 1e-9 * want, "bin {i}: {got} vs {want}");
    }
    assert!(e.counts.iter().all(|v| *v >= 0.0 && v.is_finite()));
}

#[test]
fn fft_convolution_matches_direct_circular_sum() {
    let s = small_setup(32);
    let k = KernelStack::build(&s, Sampling::Integrated).unwrap();
    let model = ForwardModel::new(&k, Boundary::Periodic);
    let n = 32usize;
    let object = Array2::from_shape_fn(
        (n, n),
        |(r, c)| if (r / 4 + c / 6) % 2 == 0 { 1.0 } else { 0.2 },
    );
    let e = model.expected(object.view());
    let bin = k.len() - 1;
    let kern = k.kernel(bin);
    // Direct periodic convolution with the centred kernel (offset 0 at n/2).
    let mut direct = Array2::<f64>::zeros((n, n));
    for y in 0..n {
        for x in 0..n {
            let mut acc = 0.0;
            for ky in 0..n {
                for kx in 0..n {
                    let (dy, dx) = (ky as i64 - (n / 2) as i64, kx as i64 - (n / 2) as i64);
                    let sy = (y as i64 - dy).rem_euclid(n as i64) as usize;
                    let sx = (x as i64 - dx).rem_euclid(n as i64) as usize;
                    acc += kern[[ky, kx]] * object[[sy, sx]];
                }
            }
            direct[[y, x]] = acc;
        }
    }
    let fft = e.counts.index_axis(ndarray::Axis(0), bin);
    let max = direct.iter().fold(0.0f64, |m, v| m.max(*v));
    for (a, b) in fft.iter().zip(&direct) {
        assert!((a - b).abs() < 1e-12 * max, "{a} vs {b}");
    }
}

#[test]
fn negative_round_off_is_clamped_and_counted() {
    // A single bright pixel on black: far pixels get |values| ~ 1e-17 of
    // either sign from FFT round-off.
    let s = small_setup(64);
    let k = KernelStack::build(&s, Sampling::Integrated).unwrap();
    let model = ForwardModel::new(&k, Boundary::Periodic);
    let mut object = Array2::<f64>::zeros((64, 64));
    object[[10, 10]] = 1.0;
    let e = model.expected(object.view());
    assert!(e.counts.iter().all(|v| *v >= 0.0));
    // Round-off made some far pixels negative; each became an exact zero.
    let zeros = e.counts.iter().filter(|v| **v == 0.0).count();
    assert!(
        e.clamped > 0 && e.clamped <= zeros,
        "{} clamped, {zeros} zeros",
        e.clamped
    );
    let max = e.counts.iter().fold(0.0f64, |m, v| m.max(*v));
    assert!(e.most_negative < 0.0 && e.most_negative > -1e-12 * max);
}

#[test]
fn poisson_sampler_mean_variance_and_seed() {
    let lambda = [0.0, 0.3, 3.7, 42.0, 1e6];
    let n = 40_000;
    let expected = Array3::from_shape_fn((lambda.len(), 1, n), |(k, _, _)| lambda[k]);
    let a = poisson_counts(&expected, 7);
    for (k, &l) in lambda.iter().enumerate() {
        let xs = a.index_axis(ndarray::Axis(0), k);
        let mean = xs.mean().unwrap();
        let var = xs.mapv(|x| (x - mean).powi(2)).sum() / (n as f64 - 1.0);
        assert!(xs.iter().all(|x| x.fract() == 0.0 && *x >= 0.0));
        if l == 0.0 {
            assert_eq!(mean, 0.0);
            continue;
        }
        // Standard error of the mean is sqrt(l/n); of the variance ~ l*sqrt(2/n).
        assert!(
            (mean - l).abs() < 5.0 * (l / n as f64).sqrt(),
            "mean {mean} for {l}"
        );
        assert!(
            (var - l).abs() < 6.0 * (l * l * 2.0 / n as f64 + l / n as f64).sqrt(),
            "var {var} for {l}"
        );
    }
    assert_eq!(a, poisson_counts(&expected, 7));
    assert_ne!(a, poisson_counts(&expected, 8));
}

#[test]
fn simulate_draws_poisson_counts_around_the_expected_stack_with_metadata() {
    use scatterscope::ValueKind;
    use scatterscope::simulate::{SimulateError, simulate};
    let mut setup = scatterscope::Preset::Paper.setup();
    setup.sensor.width_px = 48;
    setup.sensor.height_px = 48;
    setup.total_photons = 2e5;
    let scene = scatterscope::Scene::parse("disks");
    let sim = simulate(
        &setup,
        &scene,
        scatterscope::Sampling::Integrated,
        scatterscope::Boundary::Sensor,
        3,
    )
    .unwrap();
    let (e, c) = (&sim.expected, &sim.counts);
    assert_eq!(e.data.dim(), c.data.dim());
    assert_eq!(e.bins(), sim.kernels.len());
    assert_eq!(
        (e.meta.kind, c.meta.kind),
        (ValueKind::ExpectedCounts, ValueKind::Counts)
    );
    assert_eq!((e.meta.seed, c.meta.seed), (None, Some(3)));
    assert_eq!(c.meta.boundary, Some(scatterscope::Boundary::Sensor));
    assert!(c.data.iter().all(|&v| v >= 0.0 && v.fract() == 0.0));
    // The draw's total is Poisson around the expected total: within 5 sigma.
    let (te, tc) = (e.total(), c.total());
    assert!(te > 100.0, "{te}");
    assert!(
        (tc - te).abs() < 5.0 * te.sqrt(),
        "expected {te}, drew {tc}"
    );
    // The same seed draws the same counts.
    let again = simulate(
        &setup,
        &scene,
        scatterscope::Sampling::Integrated,
        scatterscope::Boundary::Sensor,
        3,
    )
    .unwrap();
    assert_eq!(again.counts.data, c.data);
    // A threshold no bin reaches is an error naming it.
    setup.min_bin_photons = 1e12;
    let err = simulate(
        &setup,
        &scene,
        scatterscope::Sampling::Integrated,
        scatterscope::Boundary::Sensor,
        3,
    )
    .err()
    .unwrap();
    assert!(matches!(err, SimulateError::NoBins { .. }), "{err}");
    assert!(err.to_string().contains("1000000000000"), "{err}");
}
