//! The reconstruction's hot path on the paper preset (256 x 256, 20 bins,
//! a sensor with edges): one likelihood value + gradient against the FFTs it
//! needs alone, a shortened Algorithm 1 run, one full default
//! reconstruction as `scatterscope reconstruct` runs it (split solver,
//! embedded FFDNet prior, its own stopping rule), and Richardson-Lucy's
//! cross-validated stop on the time-summed and on the whole stack.

/// The command's allocator, so that the bench times what `scatterscope` runs.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

use criterion::{Criterion, criterion_group, criterion_main};
use ndarray::parallel::prelude::*;
use rustfft::num_complex::Complex64;
use scatterscope::denoise::ffdnet::Ffdnet;
use scatterscope::denoise::ffdnet::source::embedded;
use scatterscope::denoise::tv::TotalVariation;
use scatterscope::denoise::{Denoiser, NoPrior};
use scatterscope::forward::{Boundary, ForwardModel, poisson_counts};
use scatterscope::physics::{KernelStack, Preset, Sampling};
use scatterscope::reconstruct::admm_lbfgs::{AdmmLbfgs, AdmmLbfgsOptions, PnpStop};
use scatterscope::reconstruct::likelihood::PoissonLikelihood;
use scatterscope::reconstruct::method::{Method, MethodOptions, run_method};
use scatterscope::reconstruct::problem::Problem;
use scatterscope::reconstruct::{Data, Reconstructor};
use scatterscope::scene::Scene;

fn benches(c: &mut Criterion) {
    let setup = Preset::Paper.setup();
    let kernels = KernelStack::build(&setup, Sampling::Integrated).unwrap();
    let model = ForwardModel::new(&kernels, Boundary::Sensor);
    let truth = Scene::Text.render(256, 256).unwrap();
    let object = model.embed(truth.view(), 0.0);
    let counts = poisson_counts(&model.expected(object.view()).counts, 1);
    let bins: Vec<usize> = (0..kernels.len()).collect();
    let lik = PoissonLikelihood::new(&model, &counts, &bins, 1e-10);
    let o: Vec<f64> = object.iter().map(|v| 0.5 * v + 0.2).collect();
    c.bench_function("likelihood_gradient_256x256x20_sensor", |b| {
        b.iter(|| lik.evaluate(&o))
    });
    // The same 42 transforms with the same parallel structure and nothing else.
    let fft = model.fft();
    c.bench_function("likelihood_ffts_only_256x256x20_sensor", |b| {
        b.iter(|| {
            let spec = fft.forward(&o);
            let parts: Vec<Vec<Complex64>> = bins
                .par_iter()
                .map(|_| fft.forward(&fft.inverse(spec.clone())))
                .collect();
            let mut acc = vec![Complex64::default(); fft.spectrum_len()];
            for p in &parts {
                acc.iter_mut().zip(p).for_each(|(a, s)| *a += s);
            }
            fft.inverse(acc)
        })
    });
    let opts = AdmmLbfgsOptions {
        max_iters: 10,
        stop: PnpStop::Iterations,
        ..Default::default()
    };
    let tv = TotalVariation::default();
    let mut group = c.benchmark_group("reconstruction");
    group.sample_size(10);
    group.bench_function("pnp_tv_256x256x20_10_iterations", |b| {
        let method = AdmmLbfgs {
            denoiser: &tv,
            opts,
        };
        let data = Data::new(&model, &counts, &bins).unwrap();
        b.iter(|| method.run(&data, None, &mut |_| {}).unwrap())
    });
    let problem = Problem {
        model,
        counts,
        bin_starts_ps: kernels.kept_bins().map(|b| b.start_ps).collect(),
        setup,
        left_out: Vec::new(),
    };
    let ffdnet = Ffdnet::new(embedded(), "embedded");
    let defaults = MethodOptions::default();
    // PnP (split solver, learned prior) at its defaults; the per-stack
    // choice between rl-stack and PnP (runs both); Richardson-Lucy on the
    // time-summed stack and on the whole stack (every bin with its own
    // kernel), both with the cross-validated stop.
    let cases: [(&str, Method, &dyn Denoiser, &MethodOptions); 4] = [
        (
            "pnp_split_ffdnet_256x256x20_default",
            Method::Pnp,
            &ffdnet,
            &defaults,
        ),
        ("auto_256x256x20", Method::Auto, &ffdnet, &defaults),
        ("rl_sum_cv_256x256x20", Method::RlSum, &NoPrior, &defaults),
        (
            "rl_stack_cv_256x256x20",
            Method::RlStack,
            &NoPrior,
            &defaults,
        ),
    ];
    for (name, method, prior, opts) in cases {
        group.bench_function(name, |b| {
            b.iter(|| run_method(&problem, method, None, prior, opts, None, |_| {}).unwrap())
        });
    }
    group.finish();
}

criterion_group!(reconstruct, benches);
criterion_main!(reconstruct);
