//! The exact-splitting solver and the sensor-with-edges model against
//! independent computations: a scalar minimiser for the Poisson prox, a
//! direct linear convolution and the adjoint identity for the padded model,
//! and Newton's method on a small problem for the solver itself.

#[path = "common/reconstruct.rs"]
mod common_reconstruct;

use common_reconstruct::reconstruct;
use ndarray::{Array2, Array3, Axis};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use scatterscope::denoise::tv::TotalVariation;
use scatterscope::denoise::{Denoiser, NoPrior};
use scatterscope::forward::{Boundary, EDGE_TAIL, ForwardModel, poisson_counts};
use scatterscope::physics::{KernelStack, Preset, Sampling, Setup};
use scatterscope::reconstruct::em::RlStop;
use scatterscope::reconstruct::likelihood::PoissonLikelihood;
use scatterscope::reconstruct::rl_sum::RlSum;
use scatterscope::reconstruct::split::{Split, SplitOptions, poisson_prox};

/// The split solver with `denoiser` as its prior.
fn split(denoiser: &dyn Denoiser, opts: SplitOptions) -> Split<'_> {
    Split { denoiser, opts }
}

fn setup(size: usize, pitch_cm: f64, photons: f64) -> Setup {
    let mut s = Preset::Paper.setup();
    s.sensor.width_px = size;
    s.sensor.height_px = size;
    s.sensor.fov_cm = pitch_cm * size as f64;
    s.total_photons = photons;
    s
}

/// Minimiser of `z - m log z + rho/2 (z - t)^2` on z >= 0 by bisection on
/// its (increasing) derivative.
fn prox_by_bisection(m: f64, t: f64, rho: f64) -> f64 {
    let d = |z: f64| 1.0 - m / z + rho * (z - t);
    if m == 0.0 {
        return (t - 1.0 / rho).max(0.0);
    }
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    while d(hi) < 0.0 {
        hi *= 2.0;
    }
    for _ in 0..2000 {
        let mid = 0.5 * (lo + hi);
        if mid == lo || mid == hi {
            break;
        }
        if d(mid) < 0.0 { lo = mid } else { hi = mid }
    }
    0.5 * (lo + hi)
}

#[test]
fn poisson_prox_matches_a_scalar_minimiser_on_zero_tiny_and_huge_counts() {
    for m in [0.0, 1e-12, 0.3, 1.0, 50.0, 1e12] {
        for t in [-5.0, 0.0, 1e-9, 0.5, 3.0, 1e6, 1e13] {
            for rho in [1e-6, 0.1, 1.0, 1e4] {
                let z = poisson_prox(m, t, rho);
                let want = prox_by_bisection(m, t, rho);
                assert!(z.is_finite() && z >= 0.0, "m {m} t {t} rho {rho}: {z}");
                // Where 1 - rho t nearly cancels, the root moves by about
                // 1e-16 / sqrt(rho m) relative; the stationarity residual is
                // the sharp test, the bisection a loose independent one.
                assert!(
                    (z - want).abs() <= 1e-6 * want.max(1e-300) + 1e-300,
                    "m {m} t {t} rho {rho}: {z} vs {want}"
                );
                if z > 0.0 {
                    let residual = 1.0 - m / z + rho * (z - t);
                    let scale = 1.0 + m / z + rho * (z.abs() + t.abs());
                    assert!(
                        residual.abs() <= 1e-14 * scale,
                        "m {m} t {t} rho {rho}: residual {residual}"
                    );
                }
                if m > 0.0 {
                    assert!(z > 0.0, "positive counts keep z > 0");
                }
            }
        }
    }
}

#[test]
fn padded_model_is_the_linear_convolution_and_its_adjoint_holds() {
    let k = KernelStack::build(&setup(24, 50.0 / 256.0, 450.0), Sampling::Integrated).unwrap();
    let model = ForwardModel::new(&k, Boundary::Sensor);
    let (gh, gw) = model.grid_shape();
    let (oy, ox) = model.sensor_offset();
    let r = model.margin();
    assert!(gh >= 24 + 2 * r && gw >= 24 + 2 * r && oy >= r && ox >= r);
    let mut rng = ChaCha8Rng::seed_from_u64(4);
    let x: Vec<f64> = (0..gh * gw).map(|_| rng.random::<f64>()).collect();
    let y: Vec<f64> = (0..24 * 24).map(|_| rng.random::<f64>() - 0.3).collect();
    for bin in [0, k.len() - 1] {
        // <H x, y> = <x, H^T y>.
        let hx = model.apply(bin, &x);
        let hty = model.adjoint(bin, &y);
        let lhs: f64 = hx.iter().zip(&y).map(|(a, b)| a * b).sum();
        let rhs: f64 = x.iter().zip(&hty).map(|(a, b)| a * b).sum();
        assert!((lhs - rhs).abs() < 1e-10 * lhs.abs(), "{lhs} vs {rhs}");
        // Direct linear convolution with the centred kernel within the margin.
        let kern = k.kernel(bin);
        let (kh, kw) = kern.dim();
        for (i, &got) in hx.iter().enumerate() {
            let (sy, sx) = (oy + i / 24, ox + i % 24);
            let mut want = 0.0;
            for ((ky, kx), &v) in kern.indexed_iter() {
                let (dy, dx) = (ky as i64 - (kh / 2) as i64, kx as i64 - (kw / 2) as i64);
                if dy.unsigned_abs().max(dx.unsigned_abs()) as usize > r {
                    continue;
                }
                let (py, px) = (sy as i64 - dy, sx as i64 - dx);
                want += v * x[py as usize * gw + px as usize];
            }
            assert!(
                (got - want).abs() < 1e-12 * want.abs().max(1.0),
                "{got} vs {want}"
            );
        }
    }
    // The margin keeps all but EDGE_TAIL of every kernel's light.
    for bin in 0..k.len() {
        let kern = k.kernel(bin);
        let (kh, kw) = kern.dim();
        let outside: f64 = kern
            .indexed_iter()
            .filter(|((ky, kx), _)| ky.abs_diff(kh / 2).max(kx.abs_diff(kw / 2)) > r)
            .map(|(_, v)| v)
            .sum();
        assert!(outside <= EDGE_TAIL * kern.sum(), "bin {bin}: {outside}");
    }
    // Sensitivity is H^T 1 summed over bins: the full mass deep inside.
    let bins: Vec<usize> = (0..k.len()).collect();
    let s = model.sensitivity(&bins);
    let mass: f64 = bins.iter().map(|&b| model.mass(b)).sum();
    let centre = (oy + 12) * gw + ox + 12;
    assert!((s[centre] - mass).abs() < 2.0 * EDGE_TAIL * mass + 1e-9);
    assert!(
        s[0] < 0.01 * mass,
        "a grid corner is nearly unseen: {}",
        s[0]
    );
}

/// Newton's method on the interior Poisson maximum-likelihood problem of a
/// small periodic model with background `bg` per pixel and bin (counts
/// ~ Poisson(H o + bg)), with dense matrices built column by column.
fn newton_ml(model: &ForwardModel, counts: &Array3<f64>, bg: f64) -> Vec<f64> {
    let (h, w) = model.grid_shape();
    let n = h * w;
    let bins = counts.shape()[0];
    let mut cols: Vec<Vec<Vec<f64>>> = vec![Vec::with_capacity(n); bins];
    for j in 0..n {
        let mut e = vec![0.0; n];
        e[j] = 1.0;
        for (k, col) in cols.iter_mut().enumerate() {
            col.push(model.apply(k, &e));
        }
    }
    let m: Vec<Vec<f64>> = counts
        .axis_iter(Axis(0))
        .map(|c| c.iter().copied().collect())
        .collect();
    let total: f64 = m.iter().flatten().sum();
    let mass: f64 = (0..bins).map(|k| model.mass(k)).sum();
    let mut o = vec![(total - bg * (bins * n) as f64) / (mass * n as f64); n];
    let value = |o: &[f64]| -> f64 {
        let mut v = 0.0;
        for k in 0..bins {
            for i in 0..n {
                let y: f64 = (0..n).map(|j| cols[k][j][i] * o[j]).sum::<f64>() + bg;
                v += y - m[k][i] * y.ln();
            }
        }
        v
    };
    for _ in 0..100 {
        let mut grad = vec![0.0; n];
        let mut hess = vec![vec![0.0; n]; n];
        for k in 0..bins {
            let y: Vec<f64> = (0..n)
                .map(|i| (0..n).map(|j| cols[k][j][i] * o[j]).sum::<f64>() + bg)
                .collect();
            for i in 0..n {
                let r = 1.0 - m[k][i] / y[i];
                let c = m[k][i] / (y[i] * y[i]);
                for a in 0..n {
                    let ha = cols[k][a][i];
                    grad[a] += ha * r;
                    for b in 0..n {
                        hess[a][b] += ha * c * cols[k][b][i];
                    }
                }
            }
        }
        // Solve hess * step = grad by Gaussian elimination.
        let mut aug: Vec<Vec<f64>> = hess
            .into_iter()
            .zip(&grad)
            .map(|(mut row, g)| {
                row.push(*g);
                row
            })
            .collect();
        for p in 0..n {
            let piv = (p..n)
                .max_by(|&a, &b| aug[a][p].abs().total_cmp(&aug[b][p].abs()))
                .unwrap();
            aug.swap(p, piv);
            let pivot_row = aug[p].clone();
            for row in aug.iter_mut().skip(p + 1) {
                let f = row[p] / pivot_row[p];
                row.iter_mut()
                    .zip(&pivot_row)
                    .skip(p)
                    .for_each(|(x, y)| *x -= f * y);
            }
        }
        let mut step = vec![0.0; n];
        for p in (0..n).rev() {
            let s: f64 = (p + 1..n).map(|c| aug[p][c] * step[c]).sum();
            step[p] = (aug[p][n] - s) / aug[p][p];
        }
        // Backtracking (Armijo) inside the positive orthant.
        let f0 = value(&o);
        let slope: f64 = grad.iter().zip(&step).map(|(g, s)| g * s).sum();
        let mut t = 1.0;
        loop {
            let trial: Vec<f64> = o.iter().zip(&step).map(|(a, s)| a - t * s).collect();
            if trial.iter().all(|v| *v > 0.0) && value(&trial) <= f0 - 1e-4 * t * slope {
                o = trial;
                break;
            }
            t *= 0.5;
            if t < 1e-12 {
                return o;
            }
        }
    }
    o
}

#[test]
fn split_solver_with_no_prior_reaches_the_maximum_likelihood_of_newtons_method() {
    // 6 x 6 periodic, two bins, kernels about a pixel wide, counts in the
    // thousands: the maximum-likelihood object is interior and unique. With
    // and without a background of about a fifth of the counts.
    let mut s = setup(6, 2.5, 2e6);
    s.bins.start_ps = 100.0;
    s.bins.count = 2;
    let k = KernelStack::build(&s, Sampling::Integrated).unwrap();
    let truth = Array2::from_shape_fn((6, 6), |(r, c)| {
        0.4 + 0.5 * (((r * 5 + c * 3) % 7) as f64 / 6.0)
    });
    let mean = ForwardModel::new(&k, Boundary::Periodic)
        .expected(truth.view())
        .counts
        .mean()
        .unwrap();
    for bg in [0.0, 0.25 * mean] {
        let model = ForwardModel::new(&k, Boundary::Periodic).with_background(bg);
        let expected = model.expected(truth.view()).counts.mapv(|y| y + bg);
        let counts = poisson_counts(&expected, 3);
        let want = newton_ml(&model, &counts, bg);
        let opts = SplitOptions {
            max_iters: 3000,
            patience: usize::MAX,
            ..Default::default()
        };
        let r = reconstruct(&split(&NoPrior, opts), &model, &counts, &[0, 1], None).unwrap();
        let got: Vec<f64> = r.image.iter().copied().collect();
        let scale = want.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for (g, w) in got.iter().zip(&want) {
            assert!((g - w).abs() < 1e-4 * scale, "background {bg}: {g} vs {w}");
        }
        // And the likelihood's gradient vanishes there.
        let lik = PoissonLikelihood::new(&model, &counts, &[0, 1], 1e-10);
        let g_ml = lik.evaluate(&got).gradient;
        let g_flat = lik
            .evaluate(&vec![got.iter().sum::<f64>() / 36.0; 36])
            .gradient;
        let norm = |g: &[f64]| g.iter().map(|v| v * v).sum::<f64>().sqrt();
        assert!(
            norm(&g_ml) < 1e-4 * norm(&g_flat),
            "background {bg}: {} vs {}",
            norm(&g_ml),
            norm(&g_flat)
        );
        if bg > 0.0 {
            // Ignoring the background gives a different, brighter object.
            let plain = ForwardModel::new(&k, Boundary::Periodic);
            let wrong =
                reconstruct(&split(&NoPrior, opts), &plain, &counts, &[0, 1], None).unwrap();
            let (a, b) = (wrong.image.sum(), r.image.sum());
            assert!(a > 1.2 * b, "without background {a}, with {b}");
        }
    }
}

#[test]
fn split_solver_is_finite_on_extreme_inputs() {
    let k = KernelStack::build(&setup(32, 50.0 / 256.0, 450.0), Sampling::Integrated).unwrap();
    let model = ForwardModel::new(&k, Boundary::Sensor);
    let bins: Vec<usize> = (0..k.len()).collect();
    let shape = (k.len(), 32, 32);
    let opts = SplitOptions {
        max_iters: 15,
        ..Default::default()
    };
    let tv = TotalVariation::default();
    let mut per_count_at = None;
    let mut one_hot = Array3::<f64>::zeros(shape);
    one_hot[[k.len() - 1, 5, 7]] = 1.0;
    let mut early_only = Array3::<f64>::zeros(shape);
    early_only.index_axis_mut(Axis(0), 0).fill(3.0);
    for (name, counts) in [
        ("all zero", Array3::<f64>::zeros(shape)),
        ("one photon", one_hot),
        ("only the stiff first bin", early_only),
        ("saturated", Array3::from_elem(shape, 65535.0)),
        ("huge", Array3::from_elem(shape, 1e12)),
        // Counts at single precision's largest value: a transform of them
        // would overflow it unless scaled.
        ("far beyond any detector", Array3::from_elem(shape, 3e38)),
    ] {
        // Started from Richardson-Lucy on the summed stack too.
        let warm = SplitOptions {
            warm_start: 50,
            ..opts
        };
        let w = reconstruct(&split(&tv, warm), &model, &counts, &bins, None)
            .unwrap_or_else(|e| panic!("{name}, RL start: {e}"));
        assert!(
            w.image.iter().all(|v| v.is_finite() && *v >= 0.0),
            "{name}, RL start"
        );
        let r = reconstruct(&split(&tv, opts), &model, &counts, &bins, None)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(r.image.dim(), (32, 32), "{name}");
        assert!(r.image.iter().all(|v| v.is_finite() && *v >= 0.0), "{name}");
        if name == "all zero" {
            assert!(r.image.iter().all(|v| *v == 0.0));
        }
        // Uniform counts: the estimate per count is the same at every scale
        // (the prior's strength follows the light, so only roughly), not a
        // value lost to overflow.
        let level = counts[[0, 0, 0]];
        if level >= 65535.0 {
            let per_count = r.image.mean().unwrap() / level;
            let reference = *per_count_at.get_or_insert(per_count);
            assert!(
                (0.5..2.0).contains(&(per_count / reference)),
                "{name}: {per_count:e} per count against {reference:e} when saturated"
            );
        }
    }
    let mut bad = Array3::<f64>::zeros(shape);
    bad[[1, 2, 3]] = f64::NAN;
    let e = reconstruct(&split(&tv, opts), &model, &bad, &bins, None).unwrap_err();
    assert!(e.to_string().contains("bin 1, row 2, column 3"), "{e}");
}

#[test]
fn split_solver_starts_from_richardson_lucy_on_the_summed_stack_when_asked() {
    // A bright block on a sensor with edges: the warm start's first row is
    // the estimate an independent Richardson-Lucy run gives after as many
    // iterations, and the flat start's is not.
    let k = KernelStack::build(&setup(32, 50.0 / 256.0, 5e5), Sampling::Integrated).unwrap();
    let model = ForwardModel::new(&k, Boundary::Sensor);
    let bins: Vec<usize> = (0..k.len()).collect();
    let (gh, gw) = model.grid_shape();
    let (oy, ox) = model.sensor_offset();
    let grid = Array2::from_shape_fn((gh, gw), |(r, c)| {
        let inside = (oy + 8..oy + 20).contains(&r) && (ox + 10..ox + 26).contains(&c);
        if inside { 1.0 } else { 0.1 }
    });
    let truth = model.crop(grid.view());
    let counts = poisson_counts(&model.expected(grid.view()).counts, 11);
    let rl = reconstruct(
        &RlSum {
            stop: RlStop::After(30),
        },
        &model,
        &counts,
        &bins,
        Some(truth.view()),
    )
    .unwrap();
    let rl_psnr = rl.trace.rows.last().unwrap().psnr.unwrap();
    let first_row = |warm_start| {
        let opts = SplitOptions {
            warm_start,
            max_iters: 1,
            ..Default::default()
        };
        let r = reconstruct(
            &split(&NoPrior, opts),
            &model,
            &counts,
            &bins,
            Some(truth.view()),
        )
        .unwrap();
        (r.trace.rows[0].psnr.unwrap(), r.trace.notes)
    };
    let (warm, notes) = first_row(30);
    assert!((warm - rl_psnr).abs() < 1e-9, "{warm} vs {rl_psnr}");
    assert!(
        notes
            .iter()
            .any(|n| n.starts_with("start: 30 Richardson-Lucy iterations")),
        "{notes:?}"
    );
    let (flat, _) = first_row(0);
    assert!(
        rl_psnr > flat + 1.0,
        "RL {rl_psnr} dB, flat start {flat} dB"
    );
}

/// `average_prior_grid` averages only priors that unshuffle: TV gives the
/// same output bit for bit, FFDNet a different one, and the trace says so;
/// both stay finite and non-negative.
#[test]
fn prior_grid_average_touches_only_unshuffling_priors() {
    use scatterscope::denoise::ffdnet::{Ffdnet, source};
    let k = KernelStack::build(&setup(32, 50.0 / 256.0, 450.0), Sampling::Integrated).unwrap();
    let model = ForwardModel::new(&k, Boundary::Sensor);
    let bins: Vec<usize> = (0..k.len()).collect();
    let truth = Array2::from_shape_fn((32, 32), |(i, j)| {
        if (8..24).contains(&i) && (10..20).contains(&j) {
            1.0
        } else {
            0.2
        }
    });
    let counts = poisson_counts(&model.expected_scene(truth.view()).counts, 5);
    let fixed = SplitOptions {
        max_iters: 10,
        ..Default::default()
    };
    let averaged = SplitOptions {
        average_prior_grid: true,
        ..fixed
    };
    let note = "averaged over its 2x2 grid";
    let tv = TotalVariation::default();
    let a = reconstruct(&split(&tv, fixed), &model, &counts, &bins, None).unwrap();
    let b = reconstruct(&split(&tv, averaged), &model, &counts, &bins, None).unwrap();
    assert_eq!(a.image, b.image, "TV has no grid to average");
    assert!(!b.trace.notes.iter().any(|n| n.contains(note)));
    let ffdnet = Ffdnet::new(source::embedded(), "embedded");
    let c = reconstruct(&split(&ffdnet, fixed), &model, &counts, &bins, None).unwrap();
    let d = reconstruct(&split(&ffdnet, averaged), &model, &counts, &bins, None).unwrap();
    assert!(d.trace.notes.iter().any(|n| n.contains(note)));
    assert!(!c.trace.notes.iter().any(|n| n.contains(note)));
    assert!(d.image.iter().all(|v| v.is_finite() && *v >= 0.0));
    let diff = c
        .image
        .iter()
        .zip(&d.image)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max);
    assert!(diff > 0.0, "the averaged prior changed nothing");
}
