//! PSF generation and the forward model on the paper preset (256 x 256, 20 kept bins).

/// The command's allocator, so that the bench times what `scatterscope` runs.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

use criterion::{Criterion, criterion_group, criterion_main};
use scatterscope::fft2::Fft2;
use scatterscope::forward::{Boundary, ForwardModel, poisson_counts};
use scatterscope::physics::{KernelStack, Preset, Sampling};
use scatterscope::scene::Scene;

fn benches(c: &mut Criterion) {
    let setup = Preset::Paper.setup();
    c.bench_function("psf_integrated_paper", |b| {
        b.iter(|| KernelStack::build(&setup, Sampling::Integrated).unwrap())
    });
    c.bench_function("psf_point_paper", |b| {
        b.iter(|| KernelStack::build(&setup, Sampling::Point).unwrap())
    });
    let kernels = KernelStack::build(&setup, Sampling::Integrated).unwrap();
    c.bench_function("kernel_spectra_256x256x20", |b| {
        b.iter(|| ForwardModel::new(&kernels, Boundary::Periodic))
    });
    // One transform of the paper preset's padded grid (sensor with edges).
    let fft = Fft2::new(320, 320);
    let image: Vec<f64> = (0..320 * 320).map(|i| ((i * 37) % 101) as f64).collect();
    let mut spectrum = fft.forward(&image);
    let mut back = vec![0.0; 320 * 320];
    c.bench_function("fft2_forward_320x320", |b| {
        b.iter(|| fft.forward_into(&image, &mut spectrum))
    });
    c.bench_function("fft2_inverse_320x320", |b| {
        b.iter(|| fft.inverse_into(&mut spectrum.clone(), &mut back))
    });
    let model = ForwardModel::new(&kernels, Boundary::Periodic);
    let truth = Scene::Usaf.render(256, 256).unwrap();
    c.bench_function("forward_expected_256x256x20", |b| {
        b.iter(|| model.expected(truth.view()))
    });
    let expected = model.expected(truth.view()).counts;
    c.bench_function("poisson_256x256x20", |b| {
        b.iter(|| poisson_counts(&expected, 1))
    });
}

criterion_group!(forward, benches);
criterion_main!(forward);
