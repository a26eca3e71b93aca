//! Reconstruction: data term against independent formulas, baselines'
//! invariants, and stability on extreme inputs.

#[path = "common/reconstruct.rs"]
mod common_reconstruct;

use common_reconstruct::reconstruct;
use ndarray::{Array2, Array3, Axis};
use scatterscope::denoise::NoPrior;
use scatterscope::denoise::ffdnet::Ffdnet;
use scatterscope::denoise::ffdnet::source::embedded;
use scatterscope::denoise::tv::TotalVariation;
use scatterscope::forward::{Boundary, ForwardModel, poisson_counts};
use scatterscope::physics::{KernelStack, Preset, Sampling, Setup, TimeBins};
use scatterscope::reconstruct::admm_lbfgs::{AdmmLbfgs, AdmmLbfgsOptions};
use scatterscope::reconstruct::data::validate_counts;
use scatterscope::reconstruct::em::{Acceleration, RlStop};
use scatterscope::reconstruct::likelihood::{PoissonLikelihood, SurrogateLog};
use scatterscope::reconstruct::operator::Convolution;
use scatterscope::reconstruct::rl_stack::RlStack;
use scatterscope::reconstruct::rl_sum::RlSum;
use scatterscope::reconstruct::trace::TraceRow;
use scatterscope::reconstruct::{ReconstructError, Reconstruction, Reconstructor};
use scatterscope::scene::Scene;

fn setup(size: usize) -> Setup {
    let mut s = Preset::Paper.setup();
    s.sensor.width_px = size;
    s.sensor.height_px = size;
    s.sensor.fov_cm = 50.0 * size as f64 / 256.0;
    s
}

struct Case {
    model: ForwardModel,
    truth: Array2<f64>,
    counts: Array3<f64>,
    bins: Vec<usize>,
}

/// Richardson-Lucy's cross-validated stop searched up to 400 iterations.
const CV_400: RlStop = RlStop::CrossValidated {
    max_iters: 400,
    acceleration: Acceleration::None,
};

/// `method` run on the case's counts, scored against its truth.
fn scored(method: &dyn Reconstructor, c: &Case) -> Reconstruction {
    reconstruct(method, &c.model, &c.counts, &c.bins, Some(c.truth.view())).unwrap()
}

fn case(size: usize, scene: &str, seed: u64) -> Case {
    let k = KernelStack::build(&setup(size), Sampling::Integrated).unwrap();
    let model = ForwardModel::new(&k, Boundary::Periodic);
    let truth = Scene::parse(scene).render(size, size).unwrap();
    let counts = poisson_counts(&model.expected(truth.view()).counts, seed);
    let bins = (0..k.len()).collect();
    Case {
        model,
        truth,
        counts,
        bins,
    }
}

/// L(o) computed the plain way: every bin convolved, every pixel summed.
fn naive_value(c: &Case, o: &[f64], eps: f64) -> f64 {
    let kappa = SurrogateLog::new(eps);
    let mut total = 0.0;
    for (img, &k) in c.counts.axis_iter(Axis(0)).zip(&c.bins) {
        let y = Convolution::from_bins(&c.model, &[k]).apply(o);
        for (yj, &m) in y.iter().zip(img.iter()) {
            total += yj - m * kappa.value(*yj);
        }
    }
    total
}

#[test]
fn likelihood_matches_naive_sum_and_finite_differences() {
    let mut c = case(24, "disks", 1);
    // Make one bin all zeros: it must be skipped yet still counted.
    c.counts.index_axis_mut(Axis(0), 0).fill(0.0);
    let eps = 1e-3;
    let lik = PoissonLikelihood::new(&c.model, &c.counts, &c.bins, eps);
    assert_eq!(lik.skipped_bins(), 1);
    assert_eq!(lik.ffts_per_gradient(), 2 + 2 * (c.bins.len() - 1));
    let n = 24 * 24;
    // A point with some pixels deep in the surrogate region (tiny and negative o).
    let o: Vec<f64> = (0..n)
        .map(|i| {
            if i % 7 == 0 {
                -1e-3
            } else {
                0.05 + (i % 5) as f64 * 0.1
            }
        })
        .collect();
    let e = lik.evaluate(&o);
    let naive = naive_value(&c, &o, eps);
    assert!(
        (e.value - naive).abs() < 1e-9 * naive.abs(),
        "{} vs {naive}",
        e.value
    );
    for j in [0, 3, 100, 301, n - 1] {
        let h = 1e-6;
        let mut p = o.clone();
        p[j] += h;
        let mut m = o.clone();
        m[j] -= h;
        let fd = (lik.evaluate(&p).value - lik.evaluate(&m).value) / (2.0 * h);
        assert!(
            (fd - e.gradient[j]).abs() < 1e-4 * e.gradient[j].abs().max(1.0),
            "pixel {j}: {fd} vs {}",
            e.gradient[j]
        );
    }
}

/// A case whose truth is given: smooth light or a built-in scene.
fn case_of(size: usize, truth: Array2<f64>, seed: u64) -> Case {
    let k = KernelStack::build(&setup(size), Sampling::Integrated).unwrap();
    let model = ForwardModel::new(&k, Boundary::Periodic);
    let counts = poisson_counts(&model.expected(truth.view()).counts, seed);
    Case {
        model,
        truth,
        counts,
        bins: (0..k.len()).collect(),
    }
}

#[test]
fn cross_validated_rl_stops_early_on_smooth_light_and_late_on_sharp_edges() {
    let size = 48;
    let smooth = Array2::from_shape_fn((size, size), |(r, c)| {
        let (y, x) = (r as f64 - 20.0, c as f64 - 26.0);
        0.2 + 0.8 * (-(y * y + x * x) / (2.0 * 12.0 * 12.0)).exp()
    });
    let disks = Scene::parse("disks").render(size, size).unwrap();
    let mut stops = Vec::new();
    for (name, truth) in [("smooth", smooth), ("disks", disks)] {
        let c = case_of(size, truth, 5);
        let cv = scored(&RlSum { stop: CV_400 }, &c);
        let k = cv
            .trace
            .output_iteration()
            .expect("the trace names its output");
        // The output is the iterate the trace names, and the sum of the two
        // halves' estimates still explains every count (RL keeps sum(H o)
        // = sum(m) on each half).
        let row = cv.trace.rows.iter().find(|r| r.iteration == k).unwrap();
        let psnr = scatterscope::metrics::psnr(cv.image.view(), c.truth.view());
        assert!((row.psnr.unwrap() - psnr).abs() < 1e-9, "{name}");
        let mass = Convolution::from_bins(&c.model, &c.bins).mass();
        let total = c.counts.sum();
        assert!(
            (cv.image.sum() * mass - total).abs() < 1e-6 * total,
            "{name}"
        );
        // Within a dB of plain RL's best iteration chosen with the truth.
        let plain = scored(
            &RlSum {
                stop: RlStop::After(400),
            },
            &c,
        );
        let best = plain.trace.best_psnr().unwrap();
        assert!(
            psnr > best.psnr.unwrap() - 1.0,
            "{name}: cross-validated stop at {k} gives {psnr:.2} dB, the truth's best ({}) {:.2} dB",
            best.iteration,
            best.psnr.unwrap()
        );
        stops.push(k);
    }
    assert!(
        stops[0] * 3 < stops[1],
        "smooth light should stop far earlier than sharp disks: {stops:?}"
    );
}

#[test]
fn cross_validated_rl_refuses_fractional_counts_and_keeps_zero_light_zero() {
    let c = case(24, "disks", 3);
    let mut scaled = c.counts.clone();
    scaled[[2, 5, 7]] += 0.5;
    let zeros = Array3::zeros(c.counts.dim());
    let stop = RlStop::CrossValidated {
        max_iters: 50,
        acceleration: Acceleration::None,
    };
    // The time-summed image names the pixel; the whole stack its bin too.
    let methods: [(&dyn Reconstructor, &str); 2] = [
        (&RlSum { stop }, "row 5, column 7"),
        (&RlStack { stop }, "row 5, column 7 of bin 2"),
    ];
    for (method, place) in methods {
        let err = reconstruct(method, &c.model, &scaled, &c.bins, None)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("whole photon counts") && err.contains(place),
            "{err}"
        );
        let r = reconstruct(method, &c.model, &zeros, &c.bins, None).unwrap();
        assert!(r.image.iter().all(|v| *v == 0.0));
        assert!(r.trace.notes.iter().any(|n| n.contains("no photons")));
    }
}

#[test]
fn whole_stack_rl_on_one_bin_is_richardson_lucy_and_its_likelihood_falls() {
    let c = case(32, "disks", 4);
    // One bin: the whole-stack iteration is plain RL on that bin.
    let k = 3;
    let one = c.counts.slice(ndarray::s![k..k + 1, .., ..]).to_owned();
    let on_one = |m: &dyn Reconstructor| reconstruct(m, &c.model, &one, &[k], None).unwrap();
    let stop = RlStop::After(25);
    let (stack, plain) = (on_one(&RlStack { stop }), on_one(&RlSum { stop }));
    let scale = plain.image.iter().fold(0.0f64, |a, &v| a.max(v));
    let diff = (&stack.image - &plain.image)
        .iter()
        .fold(0.0f64, |a, &v| a.max(v.abs()));
    assert!(diff < 1e-9 * scale, "max difference {diff} of {scale}");
    // Every bin: EM never raises the negative log-likelihood, and each step
    // keeps sum_k sum(H_k o) = sum(m) (periodic model: H^T 1 is the mass).
    let r = reconstruct(
        &RlStack {
            stop: RlStop::After(40),
        },
        &c.model,
        &c.counts,
        &c.bins,
        None,
    )
    .unwrap();
    let nll: Vec<f64> = r
        .trace
        .rows
        .iter()
        .map(|row| row.objective.unwrap())
        .collect();
    for pair in nll.windows(2) {
        assert!(pair[1] <= pair[0] + 1e-6 * pair[0].abs(), "{pair:?}");
    }
    let mass: f64 = c.bins.iter().map(|&k| c.model.mass(k)).sum();
    let total = c.counts.sum();
    assert!(
        (r.image.sum() * mass - total).abs() < 1e-8 * total,
        "{} vs {total}",
        r.image.sum() * mass
    );
}

#[test]
fn whole_stack_rl_uses_the_time_axis() {
    let c = case(48, "disks", 3);
    let stack = scored(&RlStack { stop: CV_400 }, &c);
    let summed = scored(&RlSum { stop: CV_400 }, &c);
    let psnr = |image: &Array2<f64>| scatterscope::metrics::psnr(image.view(), c.truth.view());
    // The early bins' narrower kernels carry detail the time-summed image
    // has lost.
    assert!(
        psnr(&stack.image) > psnr(&summed.image),
        "whole stack {:.2} dB, time-summed {:.2} dB",
        psnr(&stack.image),
        psnr(&summed.image)
    );
    let k = stack
        .trace
        .output_iteration()
        .expect("the trace names its output");
    let row = stack.trace.rows.iter().find(|r| r.iteration == k).unwrap();
    assert!((row.psnr.unwrap() - psnr(&stack.image)).abs() < 1e-9);
}

#[test]
fn richardson_lucy_conserves_counts_and_improves_on_raw() {
    let c = case(32, "disks", 2);
    let total: f64 = c.counts.sum();
    let op = Convolution::from_bins(&c.model, &c.bins);
    let r = scored(
        &RlSum {
            stop: RlStop::After(30),
        },
        &c,
    );
    // RL keeps sum(H o) = sum(m) after every step (H^T 1 = mass).
    assert!((r.image.sum() * op.mass() - total).abs() < 1e-8 * total);
    assert_eq!(r.trace.rows.len(), 30);
    let first = r.trace.rows[0].psnr.unwrap();
    let best = r.trace.best_psnr().unwrap().psnr.unwrap();
    assert!(best > first + 0.5, "RL did not improve: {first} -> {best}");
}

#[test]
fn pnp_on_the_stack_beats_richardson_lucy_on_the_sum() {
    let c = case(48, "disks", 3);
    let tv = TotalVariation::default();
    let pnp = scored(
        &AdmmLbfgs {
            denoiser: &tv,
            opts: AdmmLbfgsOptions::default(),
        },
        &c,
    );
    let rl = scored(
        &RlSum {
            stop: RlStop::After(200),
        },
        &c,
    );
    let p = scatterscope::metrics::psnr(pnp.image.view(), c.truth.view());
    let best_rl = rl.trace.best_psnr().unwrap().psnr.unwrap();
    assert!(p > best_rl, "pnp {p} dB vs best RL {best_rl} dB");
    assert!(pnp.trace.notes.iter().any(|n| n.starts_with("stopped:")));
    // TV fades to the identity at small sigma: auto stops on the deviance.
    assert!(
        pnp.trace
            .notes
            .iter()
            .any(|n| n.starts_with("stopping rule: deviance"))
    );
    assert_eq!(pnp.trace.prior.as_deref(), Some("tv(gain=0.5)"));
}

/// The agreement rule, recomputed from the trace: the output is the
/// iterate with the smallest primal residual among those whose deviance is
/// within one noise standard deviation of the smallest deviance up to the
/// stop and passes the discrepancy test, and the run ends `patience`
/// iterations after that pick.
#[test]
fn agreement_rule_returns_the_iterate_the_trace_says_it_should() {
    let c = case(32, "text", 5);
    let prior = Ffdnet::new(embedded(), "embedded");
    let opts = AdmmLbfgsOptions {
        patience: Some(4),
        ..Default::default()
    };
    let r = scored(
        &AdmmLbfgs {
            denoiser: &prior,
            opts,
        },
        &c,
    );
    // The learned prior does not fade to the identity: auto picks agreement.
    assert!(
        r.trace
            .notes
            .iter()
            .any(|n| n.starts_with("stopping rule: agreement"))
    );
    let rows = &r.trace.rows[1..];
    let last = rows.last().unwrap();
    assert!(last.iteration < opts.max_iters, "the rule never stopped");
    let dmin = rows
        .iter()
        .map(|r| r.deviance.unwrap())
        .fold(f64::INFINITY, f64::min);
    // Eligible: within one noise standard deviation of the smallest
    // deviance and at most two above the deviance the noise gives.
    let eligible = |r: &&TraceRow| {
        let (d, sd) = (r.deviance.unwrap(), r.deviance_sd.unwrap());
        assert!(sd > 0.0 && sd.is_finite());
        d <= (dmin + sd).min(r.expected_deviance.unwrap() + 2.0 * sd)
    };
    let pick = rows
        .iter()
        .filter(eligible)
        .min_by(|a, b| a.primal_residual.partial_cmp(&b.primal_residual).unwrap())
        .unwrap();
    assert_eq!(last.iteration, pick.iteration + 4);
    let note = format!("output: iteration {}", pick.iteration);
    assert!(r.trace.notes.contains(&note), "{:?}", r.trace.notes);
    let p = scatterscope::metrics::psnr(r.image.view(), c.truth.view());
    assert!((p - pick.psnr.unwrap()).abs() < 1e-9);
}

fn finite_non_negative(a: &Array2<f64>) -> bool {
    a.iter().all(|v| v.is_finite() && *v >= 0.0)
}

#[test]
fn extreme_inputs_give_finite_images() {
    let c = case(24, "text", 4);
    let tv = TotalVariation::default();
    let opts = AdmmLbfgsOptions {
        max_iters: 8,
        ..Default::default()
    };
    let run = |counts: &Array3<f64>, opts: &AdmmLbfgsOptions| {
        reconstruct(
            &AdmmLbfgs {
                denoiser: &tv,
                opts: *opts,
            },
            &c.model,
            counts,
            &c.bins,
            None,
        )
        .unwrap()
    };
    // All-zero stack: the estimate is exactly 0 and no iteration runs.
    let zeros = Array3::zeros(c.counts.dim());
    let r = run(&zeros, &opts);
    assert!(r.image.iter().all(|v| *v == 0.0));
    assert!(r.trace.notes.iter().any(|n| n.contains("no photons")));
    let rl = reconstruct(
        &RlSum {
            stop: RlStop::After(5),
        },
        &c.model,
        &zeros,
        &c.bins,
        None,
    )
    .unwrap();
    assert!(rl.image.iter().all(|v| *v == 0.0));
    // A single photon.
    let mut one = Array3::zeros(c.counts.dim());
    one[[5, 12, 12]] = 1.0;
    assert!(finite_non_negative(&run(&one, &opts).image));
    assert!(finite_non_negative(
        &reconstruct(
            &RlSum {
                stop: RlStop::After(20)
            },
            &c.model,
            &one,
            &c.bins,
            None
        )
        .unwrap()
        .image
    ));
    // 1e9 photons per pixel.
    let bright = c.counts.mapv(|m| m * 1e9 / 20.0);
    assert!(finite_non_negative(&run(&bright, &opts).image));
    // Huge lambda: the o-update is pinned to v - u.
    let stiff = AdmmLbfgsOptions {
        lambda0: 1e12,
        ..opts
    };
    assert!(finite_non_negative(&run(&c.counts, &stiff).image));
    // Identity prior.
    let r = reconstruct(
        &AdmmLbfgs {
            denoiser: &NoPrior,
            opts,
        },
        &c.model,
        &c.counts,
        &c.bins,
        None,
    )
    .unwrap();
    assert!(finite_non_negative(&r.image));
    // Whole-stack RL on one photon and on
    // 1e9 per pixel; its cross-validated stop on one photon.
    for counts in [&one, &bright] {
        let r = reconstruct(
            &RlStack {
                stop: RlStop::After(20),
            },
            &c.model,
            counts,
            &c.bins,
            None,
        )
        .unwrap();
        assert!(finite_non_negative(&r.image));
        assert!(r.image.sum() > 0.0);
    }
    let r = reconstruct(
        &RlStack {
            stop: RlStop::CrossValidated {
                max_iters: 50,
                acceleration: Acceleration::None,
            },
        },
        &c.model,
        &one,
        &c.bins,
        None,
    )
    .unwrap();
    assert!(finite_non_negative(&r.image));
}

#[test]
fn nearly_delta_kernel_recovers_the_object() {
    // No slab, first picoseconds: the kernel is almost a delta.
    let mut s = setup(32);
    s.medium.thickness_cm = 0.0;
    s.bins = TimeBins {
        start_ps: 0.0,
        width_ps: 0.01,
        count: 4,
    };
    s.total_photons = 4e4;
    let k = KernelStack::build(&s, Sampling::Integrated).unwrap();
    let model = ForwardModel::new(&k, Boundary::Periodic);
    let truth = Scene::Disks.render(32, 32).unwrap();
    let counts = poisson_counts(&model.expected(truth.view()).counts, 9);
    let bins: Vec<usize> = (0..k.len()).collect();
    let r = reconstruct(
        &AdmmLbfgs {
            denoiser: &TotalVariation::default(),
            opts: AdmmLbfgsOptions::default(),
        },
        &model,
        &counts,
        &bins,
        Some(truth.view()),
    )
    .unwrap();
    let p = scatterscope::metrics::psnr(r.image.view(), truth.view());
    assert!(p > 25.0, "{p} dB");
    // Whole-stack RL with its own stop: no prior, so only the photon noise
    // limits it (measured 53.0 dB).
    let rl = reconstruct(
        &RlStack {
            stop: RlStop::CrossValidated {
                max_iters: 200,
                acceleration: Acceleration::None,
            },
        },
        &model,
        &counts,
        &bins,
        Some(truth.view()),
    )
    .unwrap();
    let p = scatterscope::metrics::psnr(rl.image.view(), truth.view());
    assert!(p > 45.0, "{p} dB");
}

#[test]
fn nan_and_negative_counts_are_rejected_with_position() {
    let c = case(16, "disks", 5);
    let mut bad = c.counts.clone();
    bad[[2, 3, 4]] = f64::NAN;
    let e = validate_counts(&bad).unwrap_err();
    assert!(matches!(
        e,
        ReconstructError::InvalidCount {
            bin: 2,
            row: 3,
            col: 4,
            ..
        }
    ));
    assert!(
        e.to_string().contains("bin 2, row 3, column 4 is NaN"),
        "{e}"
    );
    bad[[2, 3, 4]] = f64::INFINITY;
    let tv = TotalVariation::default();
    assert!(
        reconstruct(
            &AdmmLbfgs {
                denoiser: &tv,
                opts: AdmmLbfgsOptions::default()
            },
            &c.model,
            &bad,
            &c.bins,
            None
        )
        .is_err()
    );
    bad[[2, 3, 4]] = -1.0;
    assert!(
        reconstruct(
            &RlSum {
                stop: RlStop::After(3)
            },
            &c.model,
            &bad,
            &c.bins,
            None
        )
        .is_err()
    );
}
