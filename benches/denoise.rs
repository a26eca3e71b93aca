//! FFDNet inference speed: one 256x256 call of the original architecture
//! (15 layers, 64 channels; the weights' values do not change the work, so
//! deterministic stand-ins are used and no download is needed), the embedded
//! network, one 64->64 layer alone (im2col + GEMM and Winograd), and TV for
//! comparison.

/// The command's allocator, so that the bench times what `scatterscope` runs.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

use std::collections::BTreeMap;
use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use ndarray::Array2;
use scatterscope::cnn::conv::{FeatureMap, conv3x3};
use scatterscope::cnn::winograd::{conv3x3_winograd, transform_weights};
use scatterscope::denoise::Denoiser;
use scatterscope::denoise::ffdnet::weights::{Architecture, FfdnetWeights, to_safetensors};
use scatterscope::denoise::ffdnet::{Ffdnet, source};
use scatterscope::denoise::tv::TotalVariation;

/// The architecture's stand-in weights, as a file of them loads.
fn stand_in(arch: &Architecture) -> FfdnetWeights {
    let bytes =
        to_safetensors(arch, &arch.stand_in_tensors(), &BTreeMap::new(), "bench").expect("valid");
    FfdnetWeights::from_bytes(&bytes, "bench").expect("valid")
}

fn image() -> Array2<f32> {
    Array2::from_shape_fn((256, 256), |(y, x)| ((x ^ y) % 17) as f32 / 16.0)
}

fn bench(c: &mut Criterion) {
    let img = image();
    let arch = Architecture::original();
    let original = Ffdnet::new(stand_in(&arch), "stand-in");
    let embedded = Ffdnet::new(source::embedded(), "embedded");
    println!(
        "ffdnet original architecture: {:.2} GFLOP per 256x256 call; embedded {}x{}: {:.2} GFLOP",
        arch.flops(256, 256) / 1e9,
        embedded.weights().arch.layers,
        embedded.weights().arch.channels,
        embedded.weights().arch.flops(256, 256) / 1e9
    );
    let mut g = c.benchmark_group("denoise");
    g.sample_size(20);
    g.bench_function("ffdnet_15x64_256x256", |b| {
        b.iter(|| black_box(original.run(img.view(), 25.0 / 255.0)))
    });
    g.bench_function("ffdnet_embedded_256x256", |b| {
        b.iter(|| black_box(embedded.run(img.view(), 25.0 / 255.0)))
    });
    // The split solver denoises the paper preset's padded grid.
    let grid = Array2::from_shape_fn((320, 320), |(y, x)| ((x ^ y) % 17) as f32 / 16.0);
    g.bench_function("ffdnet_embedded_320x320", |b| {
        b.iter(|| black_box(embedded.run(grid.view(), 25.0 / 255.0)))
    });
    let layer = &original.weights().layers[1];
    let mut input = FeatureMap::zeros(128, 128, 64);
    input
        .data
        .iter_mut()
        .enumerate()
        .for_each(|(i, v)| *v = (i % 13) as f32 / 13.0);
    let mut output = FeatureMap::zeros(128, 128, 64);
    g.bench_function("conv3x3_64x64_128x128", |b| {
        b.iter(|| conv3x3(layer, black_box(&input), &mut output))
    });
    let wino = transform_weights(layer);
    g.bench_function("conv3x3_64x64_128x128_winograd", |b| {
        b.iter(|| conv3x3_winograd(layer, &wino, black_box(&input), &mut output))
    });
    let tv = TotalVariation::default();
    let img64 = img.mapv(f64::from);
    g.bench_function("tv_256x256", |b| {
        b.iter(|| black_box(tv.denoise_unit(img64.view(), 25.0 / 255.0)))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
