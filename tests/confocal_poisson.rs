//! The confocal forward model in counts and the Poisson reconstruction on
//! scans simulated with it.

use ndarray::{Array3, s};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Poisson};
use scatterscope::confocal::forward::ConfocalModel;
use scatterscope::confocal::light_cone::ConeGrid;
use scatterscope::confocal::volume::{Projection, correlation};
use scatterscope::confocal::{ConfocalScan, PoissonOptions, SlabOptics, reconstruct_poisson};

const BIN_PS: f64 = 48.0;

fn grid() -> ConeGrid {
    ConeGrid {
        depths: 100,
        rows: 16,
        cols: 16,
        spacing_m: 0.5 / 15.0,
        step_m: 299_792_458.0 * BIN_PS * 1e-12 / 2.0,
    }
}

fn model(g: ConeGrid) -> ConfocalModel {
    ConfocalModel::new(g, BIN_PS, &SlabOptics::PUBLISHED_FOAM)
}

/// <M x, y> = <x, M^T y>: the operator from a hidden volume to counts and
/// its transpose.
#[test]
fn confocal_model_adjoint_identity() {
    let g = ConeGrid {
        depths: 30,
        rows: 6,
        cols: 7,
        ..grid()
    };
    let m = model(g);
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let uniform = rand_distr::Uniform::new(0.0, 1.0).unwrap();
    let x = Array3::from_shape_fn((30, 6, 7), |_| uniform.sample(&mut rng));
    let y = Array3::from_shape_fn((30, 6, 7), |_| uniform.sample(&mut rng));
    let lhs = (&m.forward(&x) * &y).sum();
    let rhs = (&x * &m.adjoint(&y)).sum();
    assert!((lhs - rhs).abs() <= 1e-9 * lhs.abs(), "{lhs} vs {rhs}");
}

/// The paired blur (two transients packed as one complex volume) equals
/// the blur of each alone, forward and adjoint, and the adjoint is the
/// forward's transpose.
#[test]
fn the_paired_slab_blur_is_two_blurs() {
    use scatterscope::confocal::forward::SlabBlur;
    let blur = SlabBlur::new(&SlabOptics::PUBLISHED_FOAM, 24, 30, 96.0, 6, 7, 0.5 / 6.0);
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let uniform = rand_distr::Uniform::new(0.0, 1.0).unwrap();
    let (a, b) = (
        Array3::from_shape_fn(blur.transient_dim(), |_| uniform.sample(&mut rng)),
        Array3::from_shape_fn(blur.transient_dim(), |_| uniform.sample(&mut rng)),
    );
    let close = |x: &Array3<f64>, y: &Array3<f64>| {
        let top = y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        x.dim() == y.dim() && x.iter().zip(y).all(|(p, q)| (p - q).abs() <= 1e-12 * top)
    };
    let (fa, fb) = blur.forward_pair(&a, &b);
    assert!(close(&fa, &blur.forward(&a)) && close(&fb, &blur.forward(&b)));
    let (ya, yb) = (
        Array3::from_shape_fn(fa.dim(), |_| uniform.sample(&mut rng)),
        Array3::from_shape_fn(fa.dim(), |_| uniform.sample(&mut rng)),
    );
    let (aa, ab) = blur.adjoint_pair(&ya, &yb);
    assert!(close(&aa, &blur.adjoint(&ya)) && close(&ab, &blur.adjoint(&yb)));
    let (lhs, rhs) = ((&fa * &ya).sum(), (&a * &aa).sum());
    assert!((lhs - rhs).abs() <= 1e-9 * lhs.abs(), "{lhs} vs {rhs}");
}

/// A square plate 36 cm behind the slab, simulated through the full model
/// (light cone, slab kernel, background, Poisson counts), is found at its
/// depth and in its place by the Poisson method.
#[test]
fn poisson_method_finds_a_plate_at_its_depth() {
    let g = grid();
    let m = model(g);
    let depth_sample = 50;
    let mut volume = Array3::<f64>::zeros((g.depths, g.rows, g.cols));
    volume.slice_mut(s![depth_sample, 5..11, 4..9]).fill(1.0);
    let clean = m.forward(&volume);
    let scale = 2e6 / clean.sum();
    let mu = m.expected_counts(&(volume.clone() * scale), &vec![0.5; g.depths]);
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let counts = mu.mapv(|l| {
        if l > 0.0 {
            Poisson::new(l).unwrap().sample(&mut rng)
        } else {
            0.0
        }
    });
    let scan = ConfocalScan::new(counts, BIN_PS, 0.0, 0.5, "plate").unwrap();
    let opts = PoissonOptions {
        depth_m: g.depths as f64 * g.step_m,
        step_m: g.step_m,
        max_iters: 60,
    };
    let (vol, trace) = reconstruct_poisson(&scan, &SlabOptics::PUBLISHED_FOAM, &opts).unwrap();
    assert!(!trace.is_empty());
    let truth_m = (depth_sample as f64 + 0.5) * g.step_m;
    let found = vol.object_depth().unwrap();
    assert!(
        (found - truth_m).abs() < 2.0 * g.step_m,
        "depth {found} m vs {truth_m} m"
    );
    let plate = volume.index_axis(ndarray::Axis(0), depth_sample).to_owned();
    let r = correlation(&vol.projection(Projection::Front), &plate);
    assert!(r > 0.7, "front projection against the plate: {r}");
}

#[test]
fn fractional_counts_are_refused() {
    let mut counts = Array3::<f64>::zeros((40, 4, 4));
    counts[[10, 1, 2]] = 2.5;
    let scan = ConfocalScan::new(counts, 16.0, 0.0, 0.5, "scaled.npy").unwrap();
    let e = reconstruct_poisson(
        &scan,
        &SlabOptics::PUBLISHED_FOAM,
        &PoissonOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("scaled.npy") && e.contains("2.5") && e.contains("photon counts"),
        "{e}"
    );
}
