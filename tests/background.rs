//! Background counts (dark counts, ambient light) in the data: estimated
//! from the bins before the first light, and fitted by every method.

use ndarray::{Array2, Array3, Axis};
use scatterscope::Named;
use scatterscope::denoise::NoPrior;
use scatterscope::forward::{Boundary, poisson_counts};
use scatterscope::physics::{Preset, Sampling, Setup};
use scatterscope::reconstruct::likelihood::PoissonLikelihood;
use scatterscope::reconstruct::method::{Method, MethodOptions, run_method};
use scatterscope::reconstruct::problem::{BackgroundChoice, Problem};
use scatterscope::stack::{Stack, StackMeta, ValueKind};

fn setup() -> Setup {
    let mut s = Preset::Paper.setup();
    s.sensor.width_px = 32;
    s.sensor.height_px = 32;
    s.sensor.fov_cm = 50.0 / 8.0;
    s.total_photons = 2e5;
    s
}

/// A 30-bin stack of a flat object with a background of `share` times the
/// mean signal count per pixel and bin in every bin, before the first
/// light too; returns the stack, the truth on the sensor and the
/// background.
fn stack_with_background(share: f64, seed: u64) -> (Stack, Array2<f64>, f64) {
    let s = setup();
    let meta = StackMeta::consecutive(&s, s.bins.count, ValueKind::Counts, "test".into()).unwrap();
    let path = std::path::Path::new("test");
    let zeros = Stack::from_parts(Array3::zeros((30, 32, 32)), meta.clone(), path).unwrap();
    let problem = Problem::new(&zeros, &s, Sampling::Integrated, Boundary::Sensor).unwrap();
    let truth = Array2::from_elem(problem.model.grid_shape(), 1.0);
    let signal = problem.model.expected(truth.view()).counts;
    let bg = share * signal.mean().unwrap();
    // Expected counts of every stack bin: signal where the ST-PSF has light.
    let mut mean = Array3::from_elem((30, 32, 32), bg);
    for (k, start) in problem.bin_starts_ps.iter().enumerate() {
        let i = meta.bin_starts_ps.iter().position(|t| t == start).unwrap();
        let mut dst = mean.index_axis_mut(Axis(0), i);
        dst += &signal.index_axis(Axis(0), k);
    }
    let counts = poisson_counts(&mean, seed).mapv(|v| v as f32);
    let stack = Stack::from_parts(counts, meta, path).unwrap();
    (stack, problem.model.crop(truth.view()), bg)
}

#[test]
fn the_background_is_estimated_from_the_bins_before_the_first_light() {
    for share in [0.0, 0.01, 0.3] {
        let (stack, _, bg) = stack_with_background(share, 11);
        let problem =
            Problem::new(&stack, &setup(), Sampling::Integrated, Boundary::Sensor).unwrap();
        let e = problem
            .estimate_background()
            .expect("the paper's first bins are dark");
        assert!(e.bins >= 3, "{e:?}");
        assert!(e.span_ps.0 == 0.0, "{e:?}");
        assert!(
            (e.per_pixel_per_bin - bg).abs() <= 4.0 * e.standard_error.max(1e-3 / 1024.0),
            "bg {bg}: {e:?}"
        );
        let (p, said) = problem.with_background(BackgroundChoice::Auto).unwrap();
        assert_eq!(p.model.background(), e.per_pixel_per_bin);
        assert!(said.contains("estimated from"), "{said}");
    }
    // Given and refused values.
    let (stack, _, _) = stack_with_background(0.0, 1);
    let problem = Problem::new(&stack, &setup(), Sampling::Integrated, Boundary::Sensor).unwrap();
    let (p, said) = problem
        .with_background(BackgroundChoice::Given(0.5))
        .unwrap();
    assert_eq!(p.model.background(), 0.5);
    assert!(said.contains("given"), "{said}");
    assert!(BackgroundChoice::parse("-1").is_err());
    assert!(BackgroundChoice::parse("NaN").is_err());
    assert_eq!(BackgroundChoice::parse("auto"), Ok(BackgroundChoice::Auto));
}

#[test]
fn every_method_fits_the_background_instead_of_brightening_the_object() {
    // Background of about a third of the mean signal count per pixel and
    // bin: ignored, it shows up as extra object brightness.
    let (stack, truth, _) = stack_with_background(0.3, 5);
    let level = truth.mean().unwrap();
    let opts = MethodOptions::default();
    for method in [Method::RlSum, Method::ScaledCounts, Method::Pnp] {
        let mean_level = |choice| {
            let problem =
                Problem::new(&stack, &setup(), Sampling::Integrated, Boundary::Sensor).unwrap();
            let (problem, _) = problem.with_background(choice).unwrap();
            let r = run_method(&problem, method, None, &NoPrior, &opts, None, |_| {}).unwrap();
            assert!(r.image.iter().all(|v| v.is_finite()));
            r.image.mean().unwrap()
        };
        let fitted = mean_level(BackgroundChoice::Auto);
        let ignored = mean_level(BackgroundChoice::None);
        assert!(
            (fitted - level).abs() < 0.1 * level,
            "{}: fitted {fitted} vs truth {level}",
            method.name()
        );
        assert!(
            ignored > 1.2 * level,
            "{}: ignoring the background gave {ignored} (truth {level})",
            method.name()
        );
    }
}

#[test]
fn the_likelihood_gradient_with_background_matches_finite_differences() {
    let (stack, truth, bg) = stack_with_background(0.3, 2);
    let problem = Problem::new(&stack, &setup(), Sampling::Integrated, Boundary::Sensor).unwrap();
    let (problem, _) = problem
        .with_background(BackgroundChoice::Given(bg))
        .unwrap();
    let bins = problem.all_bins();
    let lik = PoissonLikelihood::new(&problem.model, &problem.counts, &bins, 1e-12);
    let (gh, gw) = problem.model.grid_shape();
    let o: Vec<f64> = (0..gh * gw)
        .map(|i| truth.mean().unwrap() * (0.8 + 0.4 * ((i * 7) % 13) as f64 / 13.0))
        .collect();
    let g = lik.evaluate(&o).gradient;
    for j in [0, gh * gw / 2 + gw / 2, gh * gw - 1] {
        let h = 1e-4;
        let mut a = o.clone();
        a[j] += h;
        let mut b = o.clone();
        b[j] -= h;
        let fd = (lik.evaluate(&a).value - lik.evaluate(&b).value) / (2.0 * h);
        assert!(
            (fd - g[j]).abs() < 1e-5 * g[j].abs().max(1.0),
            "pixel {j}: {fd} vs {}",
            g[j]
        );
    }
}
