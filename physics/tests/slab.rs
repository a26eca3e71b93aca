//! The finite slab with extrapolated boundaries against independent
//! formulas: its two series against each other, the steady-state transmitted
//! fraction, the Fresnel-based boundary term, and the early-time limit.

use scatterscope_physics::quadrature::adaptive_nodes;
use scatterscope_physics::slab::{SlabTransmittance, effective_reflection};
use scatterscope_physics::{Diffusion, KernelStack, Medium, MediumModel, Preset, Sampling};

/// A diffusive slab (mu_s' = 10/cm, 2 cm thick, n = 1.4).
fn medium(mu_a: f64) -> Medium {
    Medium {
        mu_a_per_cm: mu_a,
        mu_s_per_cm: 100.0,
        g: 0.9,
        refractive_index: 1.4,
        thickness_cm: 2.0,
        model: MediumModel::Slab,
    }
}

fn slab(mu_a: f64) -> SlabTransmittance {
    Diffusion::new(&medium(mu_a)).unwrap().slab.unwrap()
}

#[test]
fn image_sum_and_sine_series_agree_where_both_converge() {
    // The two are Poisson-summation duals; each is summed on its own. (By
    // D c t / L^2 = 2 the image sum has lost about 1e-9 to cancellation,
    // which is why the switch to the sine series sits at 0.3.)
    for mu_a in [0.0, 0.1] {
        let s = slab(mu_a);
        let l = s.extrapolated_thickness_cm();
        for tau in [0.02, 0.05, 0.1, 0.2, 0.3, 0.5, 1.0] {
            let t = tau * l * l / s.dc_cm2_per_ps;
            let (a, b) = (s.log_density_images(t), s.log_density_modes(t));
            assert!(
                (a - b).abs() < 1e-9,
                "mu_a {mu_a}, Dct/L^2 {tau}: images {a}, modes {b}"
            );
        }
    }
}

#[test]
fn without_absorption_the_slab_transmits_the_steady_state_fraction() {
    // Integral over time of the transmitted flux = (z_s + z_e) / (s + 2 z_e),
    // the diffusion equation's steady state with the same boundaries.
    let s = slab(0.0);
    let peak = s.peak_time_ps();
    let (lo, hi) = ((peak * 1e-3).ln(), (peak * 1e4).ln());
    let breaks: Vec<f64> = (0..=60).map(|i| lo + (hi - lo) * i as f64 / 60.0).collect();
    let r = adaptive_nodes(&breaks, 1e-11, 100_000, |x| {
        [s.log_density(x.exp()).exp() * x.exp()]
    });
    assert!(r.converged);
    let want = s.transmitted_fraction_without_absorption();
    assert!(
        (r.integral[0] - want).abs() < 1e-8 * want,
        "{} vs {want}",
        r.integral[0]
    );
    // Absorption only removes light.
    let a = slab(0.05);
    let r_abs = adaptive_nodes(&breaks, 1e-11, 100_000, |x| {
        [a.log_density(x.exp()).exp() * x.exp()]
    });
    assert!(r_abs.integral[0] < 0.9 * want);
}

#[test]
fn effective_reflection_vanishes_without_mismatch_and_matches_tabulated_values() {
    assert_eq!(effective_reflection(1.0), 0.0);
    // Values tabulated in the literature for the same integrals (Haskell et
    // al. 1994): 0.431 for water (n = 1.33), 0.493 for tissue (n = 1.4).
    for (n, want) in [(1.33, 0.431), (1.4, 0.493)] {
        let r = effective_reflection(n);
        assert!((r - want).abs() < 1e-3, "n {n}: {r} vs {want}");
    }
    // More mismatch reflects more.
    assert!(effective_reflection(1.5) > effective_reflection(1.4));
    assert!(effective_reflection(1.1) > 0.0);
}

#[test]
fn at_early_times_the_nearest_image_alone_gives_the_flux() {
    // As t -> 0 only the direct path s - z_s matters.
    let s = slab(0.1);
    let z = s.thickness_cm - s.source_depth_cm;
    for t in [1e-3, 1e-1, 1.0] {
        let direct = z.ln()
            - z * z / (4.0 * s.dc_cm2_per_ps * t)
            - (2.0 * (4.0 * std::f64::consts::PI * s.dc_cm2_per_ps).sqrt()).ln()
            - 1.5 * f64::ln(t)
            - s.absorption_per_ps * t;
        let got = s.log_density(t);
        assert!(got.is_finite(), "t {t}: {got}");
        assert!(
            (got - direct).abs() < 1e-12 * direct.abs(),
            "t {t}: {got} vs {direct}"
        );
    }
    // Past finite range: -inf, never NaN.
    for t in [0.0, -1.0, 1e-300, f64::NAN, f64::INFINITY, 1e12] {
        assert!(!s.log_density(t).is_nan(), "t {t}");
    }
}

#[test]
fn the_peak_is_a_maximum_of_the_transmitted_flux() {
    let s = slab(0.1);
    let p = s.peak_time_ps();
    let f = |t: f64| s.log_density(t);
    assert!(f(p) >= f(p * 0.99) && f(p) >= f(p * 1.01), "peak {p}");
}

#[test]
fn a_slab_thinner_than_its_source_depth_is_refused_naming_the_field() {
    let mut m = medium(0.1);
    m.thickness_cm = 0.05;
    let e = Diffusion::new(&m).unwrap_err();
    assert_eq!(e.field, "thickness_cm");
    assert!(e.to_string().contains("transport mean free path"), "{e}");
}

#[test]
fn the_slab_kernels_build_and_arrive_later_than_the_infinite_medium() {
    // Same medium, both models: the slab's extrapolated boundaries remove
    // light near the faces, and its source sits one transport mean free
    // path deep.
    let mut setup = Preset::Paper.setup();
    setup.medium = medium(0.1);
    setup.sensor.width_px = 64;
    setup.sensor.height_px = 64;
    setup.sensor.fov_cm = 12.0;
    setup.bins.width_ps = 40.0;
    setup.bins.count = 40;
    setup.min_bin_photons = 0.0;
    let slab = KernelStack::build(&setup, Sampling::Integrated).unwrap();
    setup.medium.model = MediumModel::Infinite;
    let infinite = KernelStack::build(&setup, Sampling::Integrated).unwrap();
    let masses =
        |k: &KernelStack| -> Vec<f64> { (0..k.len()).map(|i| k.kernel(i).sum()).collect() };
    let (ms, mi) = (masses(&slab), masses(&infinite));
    assert!(ms.iter().all(|m| m.is_finite() && *m >= 0.0));
    let argmax = |m: &[f64]| {
        m.iter()
            .enumerate()
            .fold((0, f64::MIN), |b, (i, &v)| if v > b.1 { (i, v) } else { b })
            .0
    };
    assert_ne!(ms, mi);
    assert!(argmax(&ms) >= 1, "slab peak bin {}", argmax(&ms));
}
