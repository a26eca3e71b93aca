//! The confocal forward model in counts, and the Poisson reconstruction
//! and the default (`auto`) on scans simulated with it.

use ndarray::{Array3, s};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Poisson};
use scatterscope::confocal::forward::ConfocalModel;
use scatterscope::confocal::light_cone::ConeGrid;
use scatterscope::confocal::volume::{Projection, correlation};
use scatterscope::confocal::{
    ConfocalScan, PoissonOptions, PublishedOptions, SlabOptics, reconstruct_auto,
    reconstruct_poisson, reconstruct_published,
};

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

/// Sample of the plate's depth in [`plate_scan`].
const PLATE_DEPTH: usize = 50;

/// A square plate behind the slab at sample [`PLATE_DEPTH`] (about 36 cm),
/// simulated through the full model (light cone, slab kernel, background
/// 0.5 per point and bin in all, Poisson counts) with about `photons`
/// signal photons; the scan and the plate's front view.
fn plate_scan(photons: f64, seed: u64) -> (ConfocalScan, ndarray::Array2<f64>) {
    let g = grid();
    let m = model(g);
    let mut volume = Array3::<f64>::zeros((g.depths, g.rows, g.cols));
    volume.slice_mut(s![PLATE_DEPTH, 5..11, 4..9]).fill(1.0);
    let clean = m.forward(&volume);
    let scale = photons / clean.sum();
    let background = 0.5 * photons / 2e6;
    let mu = m.expected_counts(&(volume.clone() * scale), &vec![background; g.depths]);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let counts = mu.mapv(|l| {
        if l > 0.0 {
            Poisson::new(l).unwrap().sample(&mut rng)
        } else {
            0.0
        }
    });
    let plate = volume.index_axis(ndarray::Axis(0), PLATE_DEPTH).to_owned();
    (
        ConfocalScan::new(counts, BIN_PS, 0.0, 0.5, "plate").unwrap(),
        plate,
    )
}

/// The plate is found at its depth and in its place by the Poisson method.
#[test]
fn poisson_method_finds_a_plate_at_its_depth() {
    let g = grid();
    let (scan, plate) = plate_scan(2e6, 9);
    let opts = PoissonOptions {
        depth_m: g.depths as f64 * g.step_m,
        step_m: g.step_m,
        max_iters: 60,
    };
    let (vol, trace) = reconstruct_poisson(&scan, &SlabOptics::PUBLISHED_FOAM, &opts).unwrap();
    assert!(!trace.is_empty());
    let truth_m = (PLATE_DEPTH as f64 + 0.5) * g.step_m;
    let found = vol.object_depth().unwrap();
    assert!(
        (found - truth_m).abs() < 2.0 * g.step_m,
        "depth {found} m vs {truth_m} m"
    );
    let r = correlation(&vol.projection(Projection::Front), &plate);
    assert!(r > 0.7, "front projection against the plate: {r}");
}

/// The default's halves choose more blur at low light than at high light,
/// and at low light its front view is closer to the plate than the
/// published method's it starts from.
#[test]
fn auto_blurs_more_as_the_light_falls() {
    let opts = PublishedOptions {
        depth_m: 0.7,
        ..PublishedOptions::default()
    };
    let foam = SlabOptics::PUBLISHED_FOAM;
    let mut chosen = Vec::new();
    for photons in [2e7, 2e4] {
        let (scan, plate) = plate_scan(photons, 3);
        let (auto, choice) = reconstruct_auto(&scan, &foam, &opts).unwrap();
        let choice = choice.expect("whole counts are split");
        let published = reconstruct_published(&scan, &foam, &opts).unwrap();
        let front = |v: &scatterscope::confocal::HiddenVolume| {
            correlation(&v.projection(Projection::Front), &plate)
        };
        println!(
            "{photons:e} photons: blur {:?}, plate correlation auto {:.3}, published {:.3}",
            choice.blur,
            front(&auto),
            front(&published)
        );
        assert!(
            auto.notes
                .iter()
                .any(|n| n.starts_with("auto: blur chosen"))
        );
        if photons < 1e5 {
            assert!(front(&auto) > front(&published));
        }
        chosen.push(choice.blur.0);
    }
    assert!(chosen[1] > chosen[0], "blur at high, low light: {chosen:?}");
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
