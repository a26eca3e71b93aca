//! The kernels' time basis against every bin's own kernel.

use scatterscope::forward::{Boundary, ForwardModel};
use scatterscope::physics::{KernelStack, Preset, Sampling, Setup};
use scatterscope::time_basis::{BASIS_TOLERANCE, TimeBasis};

fn model(size: usize) -> ForwardModel {
    let mut s: Setup = Preset::Paper.setup();
    s.sensor.width_px = size;
    s.sensor.height_px = size;
    s.sensor.fov_cm = 50.0 * size as f64 / 256.0;
    let k = KernelStack::build(&s, Sampling::Integrated).unwrap();
    ForwardModel::new(&k, Boundary::Sensor)
}

/// A grid image with structure at every scale (no symmetry to hide an error).
fn object(n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| 0.1 + ((i * 7919) % 101) as f64 / 101.0)
        .collect()
}

fn sensor_images(model: &ForwardModel) -> Vec<Vec<f64>> {
    let (h, w) = model.sensor_shape();
    (0..model.bins())
        .map(|k| {
            (0..h * w)
                .map(|i| ((i * 31 + k * 17) % 23) as f64 / 23.0)
                .collect()
        })
        .collect()
}

fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0, |m, x| m.max(x.abs()))
}

#[test]
fn basis_matches_each_bins_own_kernel_with_fewer_transforms() {
    let model = model(64);
    let bins: Vec<usize> = (0..model.bins()).collect();
    let basis = TimeBasis::new(&model, &bins, BASIS_TOLERANCE);
    assert!(
        3 * basis.rank() < 2 * bins.len(),
        "the ST-PSF's {} kernels should need under two thirds as many basis kernels, got {}",
        bins.len(),
        basis.rank()
    );
    assert!(basis.worst_error() <= BASIS_TOLERANCE && basis.worst_error() > 0.0);
    let (gh, gw) = model.grid_shape();
    let o = object(gh * gw);
    for (k, y) in basis.forward(&o).iter().enumerate() {
        let exact = model.apply(k, &o);
        let diff: Vec<f64> = y.iter().zip(&exact).map(|(a, b)| a - b).collect();
        // A kernel error of 1e-9 of its norm moves H_k o by about that
        // much of its largest value (the object is of order 1 everywhere).
        assert!(
            max_abs(&diff) <= 1e-8 * max_abs(&exact),
            "bin {k}: {:e} of {:e}",
            max_abs(&diff),
            max_abs(&exact)
        );
    }
    let r: Vec<Option<Vec<f64>>> = sensor_images(&model).into_iter().map(Some).collect();
    let got = basis.adjoint_sum(&r);
    let mut exact = vec![0.0; gh * gw];
    for (k, rk) in r.iter().enumerate() {
        let a = model.adjoint(k, rk.as_ref().unwrap());
        exact.iter_mut().zip(&a).for_each(|(e, x)| *e += x);
    }
    let diff: Vec<f64> = got.iter().zip(&exact).map(|(a, b)| a - b).collect();
    assert!(max_abs(&diff) <= 1e-8 * max_abs(&exact));
    assert!(
        basis
            .note()
            .contains(&format!("spanned by {} orthonormal kernels", basis.rank()))
    );
}

#[test]
fn basis_operator_and_its_adjoint_agree_on_an_odd_sensor() {
    // 37 px: the pixel blocks of the combination end in a partial group.
    let model = model(37);
    let bins: Vec<usize> = (0..model.bins()).collect();
    let basis = TimeBasis::new(&model, &bins, BASIS_TOLERANCE);
    assert!(basis.rank() < bins.len());
    let (gh, gw) = model.grid_shape();
    let x = object(gh * gw);
    let mut r: Vec<Option<Vec<f64>>> = sensor_images(&model).into_iter().map(Some).collect();
    // A bin without counts back-projects nothing.
    r[3] = None;
    let hx = basis.forward(&x);
    let lhs: f64 = hx
        .iter()
        .zip(&r)
        .filter_map(|(y, rk)| {
            rk.as_ref()
                .map(|rk| y.iter().zip(rk).map(|(a, b)| a * b).sum::<f64>())
        })
        .sum();
    let rhs: f64 = x
        .iter()
        .zip(basis.adjoint_sum(&r))
        .map(|(a, b)| a * b)
        .sum();
    assert!(
        (lhs - rhs).abs() <= 1e-12 * lhs.abs(),
        "<Hx, r> {lhs} vs <x, H^T r> {rhs}"
    );
}

#[test]
fn zero_tolerance_keeps_every_bins_own_kernel() {
    let model = model(32);
    let bins: Vec<usize> = (0..model.bins()).collect();
    let basis = TimeBasis::new(&model, &bins, 0.0);
    assert_eq!(basis.rank(), bins.len());
    assert_eq!(basis.worst_error(), 0.0);
    assert!(
        basis
            .note()
            .contains("each transformed with its own kernel"),
        "{}",
        basis.note()
    );
    let (gh, gw) = model.grid_shape();
    let o = object(gh * gw);
    for (k, y) in basis.forward(&o).iter().enumerate() {
        assert_eq!(y, &model.apply(k, &o), "bin {k}");
    }
}
