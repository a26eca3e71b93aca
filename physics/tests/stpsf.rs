//! Properties of the discretised ST-PSF against independent formulas.

use scatterscope_physics::diffusion::SPEED_OF_LIGHT_CM_PER_NS;
use scatterscope_physics::{Diffusion, KernelStack, Medium, Preset, Sampling, Setup, TimeBins};

fn paper() -> Setup {
    Preset::Paper.setup()
}

/// Closed-form antiderivative of t^(-1/2) exp(-a/t - b t) (a, b > 0):
/// F(t) = 1/2 sqrt(pi/b) [e^(-2 sqrt(ab)) erf(sqrt(bt) - sqrt(a/t)) + e^(2 sqrt(ab)) erf(sqrt(bt) + sqrt(a/t))].
fn antiderivative(a: f64, b: f64, t: f64) -> f64 {
    let r = (a * b).sqrt();
    let (p, q) = ((b * t).sqrt(), (a / t).sqrt());
    0.5 * (std::f64::consts::PI / b).sqrt()
        * ((-2.0 * r).exp() * libm::erf(p - q) + (2.0 * r).exp() * libm::erf(p + q))
}

/// Bin fractions of the light budget from the closed form, independent of
/// the crate's quadrature and of its constants.
fn closed_form_fractions(m: &Medium, bins: &TimeBins) -> Vec<f64> {
    let c = SPEED_OF_LIGHT_CM_PER_NS / 1000.0 / m.refractive_index;
    let d = 1.0 / (3.0 * (m.mu_a_per_cm + (1.0 - m.g) * m.mu_s_per_cm));
    let a = m.thickness_cm.powi(2) / (4.0 * d * c);
    let b = m.mu_a_per_cm * c;
    let masses: Vec<f64> = (0..bins.count)
        .map(|k| {
            let (t0, t1) = bins.edges_ps(k);
            let lo = if t0 <= 0.0 {
                0.0
            } else {
                antiderivative(a, b, t0)
            };
            // F(0+) = 1/2 sqrt(pi/b) [-e^(-2r) + e^(2r)] ... use the limit erf(-inf) = -1, erf(+inf) = 1.
            let lo = if t0 <= 0.0 {
                let r = (a * b).sqrt();
                0.5 * (std::f64::consts::PI / b).sqrt() * (-(-2.0 * r).exp() + (2.0 * r).exp())
            } else {
                lo
            };
            antiderivative(a, b, t1) - lo
        })
        .collect();
    let total: f64 = masses.iter().sum();
    masses.iter().map(|m| m / total).collect()
}

/// Midpoint rule with 20 000 steps per bin on T(t), written out here
/// independently of the crate (its own constants, no quadrature reuse).
fn midpoint_fractions(m: &Medium, bins: &TimeBins) -> Vec<f64> {
    let c = SPEED_OF_LIGHT_CM_PER_NS / 1000.0 / m.refractive_index;
    let d = 1.0 / (3.0 * (m.mu_a_per_cm + (1.0 - m.g) * m.mu_s_per_cm));
    let density = |t: f64| {
        c / (4.0 * std::f64::consts::PI * d * c * t).sqrt()
            * (-(m.thickness_cm.powi(2)) / (4.0 * d * c * t) - m.mu_a_per_cm * c * t).exp()
    };
    let steps = 20_000;
    let masses: Vec<f64> = (0..bins.count)
        .map(|k| {
            let (t0, t1) = bins.edges_ps(k);
            let h = (t1 - t0) / steps as f64;
            (0..steps)
                .map(|i| density(t0 + (i as f64 + 0.5) * h))
                .sum::<f64>()
                * h
        })
        .collect();
    let total: f64 = masses.iter().sum();
    masses.iter().map(|m| m / total).collect()
}

#[test]
fn bin_masses_match_independent_numerical_integration() {
    let mut s = paper();
    s.min_bin_photons = 0.0;
    let k = KernelStack::build(&s, Sampling::Integrated).unwrap();
    for (b, f) in k.bins.iter().zip(midpoint_fractions(&s.medium, &s.bins)) {
        // The midpoint rule's own error is ~1e-9 relative at this step.
        assert!(
            (b.photons - 450.0 * f).abs() <= 1e-7 * 450.0 * f + 1e-12,
            "bin {}: {} vs {}",
            b.index,
            b.photons,
            450.0 * f
        );
    }
}

#[test]
fn paper_preset_keeps_twenty_bins_from_forty_ps() {
    let k = KernelStack::build(&paper(), Sampling::Integrated).unwrap();
    assert_eq!(k.len(), 20);
    let kept: Vec<_> = k.kept_bins().collect();
    assert_eq!(kept[0].start_ps, 40.0);
    assert_eq!(k.dropped_bins().count(), 10);
    assert!(
        k.dropped_bins()
            .all(|b| b.photons < 1.0 && b.end_ps <= 40.0)
    );
    let peak = k
        .bins
        .iter()
        .max_by(|a, b| a.photons.total_cmp(&b.photons))
        .unwrap();
    assert!(
        (108.0..=120.0).contains(&peak.end_ps),
        "peak bin ends at {}",
        peak.end_ps
    );
    let total: f64 = k.bins.iter().map(|b| b.photons).sum();
    assert!((total - 450.0).abs() < 1e-9, "{total}");
    // Per-bin mass equals the sum of the stored kernel.
    for (i, b) in k.kept_bins().enumerate() {
        assert!((k.kernel(i).sum() - b.photons).abs() < 1e-9 * b.photons);
    }
}

#[test]
fn vacuum_light_speed_arrives_earlier() {
    let mut s = paper();
    s.medium.refractive_index = 1.0;
    let k = KernelStack::build(&s, Sampling::Integrated).unwrap();
    assert_eq!(k.kept_bins().next().unwrap().start_ps, 28.0);
    let peak = k
        .bins
        .iter()
        .max_by(|a, b| a.photons.total_cmp(&b.photons))
        .unwrap();
    assert!((76.0..=84.0).contains(&peak.start_ps), "{}", peak.start_ps);
}

#[test]
fn bin_masses_match_closed_form() {
    for n in [1.0, 1.4] {
        let mut s = paper();
        s.medium.refractive_index = n;
        s.min_bin_photons = 0.0;
        let k = KernelStack::build(&s, Sampling::Integrated).unwrap();
        let expected = closed_form_fractions(&s.medium, &s.bins);
        for (b, f) in k.bins.iter().zip(&expected) {
            let want = f * 450.0;
            // The closed form cancels catastrophically (e^(2 sqrt(ab)) terms)
            // for bins far before the arrival, hence the absolute floor.
            let tol = 1e-7 * want + 1e-8;
            assert!(
                (b.photons - want).abs() <= tol,
                "n={n} bin {}: {} vs {want}",
                b.index,
                b.photons
            );
        }
    }
}

#[test]
fn kernels_are_symmetric_and_nearly_radial() {
    let k = KernelStack::build(&paper(), Sampling::Integrated).unwrap();
    let last = k.kernel(k.len() - 1);
    let (cy, cx) = (128usize, 128usize);
    let at = |dy: i64, dx: i64| last[[(cy as i64 + dy) as usize, (cx as i64 + dx) as usize]];
    for (dy, dx) in [(1, 2), (5, 7), (0, 13)] {
        let v = at(dy, dx);
        for w in [at(dx, dy), at(-dy, dx), at(dy, -dx), at(-dx, -dy)] {
            assert_eq!(v, w);
        }
    }
    // Same radius 5: (0, 5) and (3, 4) differ only by pixel-integration effects.
    let (a, b) = (at(0, 5), at(3, 4));
    assert!(((a - b) / a).abs() < 2e-3, "{a} {b}");
    // Monotone decrease along an axis.
    for r in 0..30 {
        assert!(at(0, r) > at(0, r + 1));
    }
}

fn relative_l1(a: ndarray::ArrayView2<f64>, b: ndarray::ArrayView2<f64>) -> f64 {
    let diff: f64 = a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum();
    diff / a.sum()
}

#[test]
fn point_sampling_agrees_only_where_the_kernel_is_wide() {
    let mut s = paper();
    s.min_bin_photons = 0.0;
    let integ = KernelStack::build(&s, Sampling::Integrated).unwrap();
    let point = KernelStack::build(&s, Sampling::Point).unwrap();
    assert_eq!(integ.len(), point.len());
    // Late bin: sigma ~ 6.5 px, 4 ps is short against the 113 ps peak time.
    let wide = relative_l1(integ.kernel(29), point.kernel(29));
    assert!(wide < 5e-3, "late bin differs by {wide}");
    // Early bin: the time profile is steep across the 4 ps.
    let steep = relative_l1(integ.kernel(6), point.kernel(6));
    assert!(steep > 0.05, "early bin differs by only {steep}");
    // Sub-pixel kernel (no slab, first picosecond): point samples miss the mass.
    s.medium.thickness_cm = 0.0;
    s.bins = TimeBins {
        start_ps: 0.5,
        width_ps: 0.01,
        count: 1,
    };
    let integ = KernelStack::build(&s, Sampling::Integrated).unwrap();
    let point = KernelStack::build(&s, Sampling::Point).unwrap();
    assert!(integ.bins[0].sigma_px < 0.5);
    let narrow = relative_l1(integ.kernel(0), point.kernel(0));
    assert!(narrow > 0.3, "sub-pixel bin differs by only {narrow}");
}

#[test]
fn extreme_times_and_coefficients_stay_finite() {
    let mut times = vec![0.0, -1.0, f64::INFINITY, f64::NAN];
    let mut t = 1e-6;
    while t <= 1e6 {
        times.push(t);
        t *= 1.7;
    }
    for (mu_a, mu_s, z0) in [
        (1.0, 5.0, 3.0),
        (0.0, 10.0, 3.0),
        (1.0, 1e4, 3.0),
        (1.0, 5.0, 0.0),
        (0.0, 1e4, 0.0),
    ] {
        let m = Medium {
            mu_a_per_cm: mu_a,
            mu_s_per_cm: mu_s,
            g: 0.9,
            refractive_index: 1.4,
            thickness_cm: z0,
            model: Default::default(),
        };
        let d = Diffusion::new(&m).unwrap();
        for &t in &times {
            for r2 in [0.0, 1.0, 1e6] {
                let v = d.log_psf(r2, t);
                assert!(!v.is_nan() && v < f64::INFINITY, "{m:?} t={t} r2={r2}: {v}");
            }
        }
    }
}

#[test]
fn extreme_bins_build_finite_non_negative_kernels() {
    let cases = [
        // Tiny bins right after t = 0 with no slab: the kernel is nearly a delta.
        (0.0, 1e-6, 8, 0.0, 5.0),
        // One enormous bin.
        (0.0, 1e6, 1, 3.0, 5.0),
        // Dense scattering.
        (0.0, 50.0, 20, 3.0, 1e4),
        // No absorption.
        (0.0, 40.0, 10, 3.0, 5.0),
    ];
    for (start, width, count, z0, mu_s) in cases {
        let mut s = paper();
        s.sensor.width_px = 64;
        s.sensor.height_px = 48;
        s.min_bin_photons = 0.0;
        s.medium.thickness_cm = z0;
        s.medium.mu_s_per_cm = mu_s;
        if width == 40.0 {
            s.medium.mu_a_per_cm = 0.0;
        }
        s.bins = TimeBins {
            start_ps: start,
            width_ps: width,
            count,
        };
        let k = KernelStack::build(&s, Sampling::Integrated)
            .unwrap_or_else(|e| panic!("{start} {width} {z0} {mu_s}: {e}"));
        assert!(k.kernels.iter().all(|v| v.is_finite() && *v >= 0.0));
        let total: f64 = k.kernels.sum();
        assert!((total - 450.0).abs() < 1e-6 * 450.0, "{total}");
    }
    // Nearly-delta case: the first bin puts essentially all of its mass in one pixel.
    let mut s = paper();
    s.medium.thickness_cm = 0.0;
    s.min_bin_photons = 0.0;
    s.bins = TimeBins {
        start_ps: 0.0,
        width_ps: 1e-3,
        count: 3,
    };
    let k = KernelStack::build(&s, Sampling::Integrated).unwrap();
    let first = k.kernel(0);
    assert!(first[[128, 128]] / first.sum() > 0.999);
}

#[test]
fn bins_before_any_arrival_are_an_error() {
    let mut s = paper();
    s.medium.mu_s_per_cm = 1e4; // photons need ~1000 ps through this slab
    s.bins = TimeBins {
        start_ps: -100.0,
        width_ps: 1.0,
        count: 50,
    };
    let e = KernelStack::build(&s, Sampling::Integrated).unwrap_err();
    assert_eq!(e.field, "bins");
    assert!(e.to_string().contains("no photons"), "{e}");
}

#[test]
fn invalid_parameters_name_the_field() {
    type Mutation = Box<dyn Fn(&mut Setup)>;
    let cases: Vec<(Mutation, &str)> = vec![
        (Box::new(|s| s.medium.mu_a_per_cm = -1.0), "mu_a_per_cm"),
        (Box::new(|s| s.medium.mu_s_per_cm = f64::NAN), "mu_s_per_cm"),
        (
            Box::new(|s| {
                s.medium.g = 1.0;
                s.medium.mu_a_per_cm = 0.0
            }),
            "g",
        ),
        (Box::new(|s| s.medium.g = 1.5), "g"),
        (
            Box::new(|s| s.medium.refractive_index = 0.0),
            "refractive_index",
        ),
        (
            Box::new(|s| s.medium.refractive_index = 0.5),
            "refractive_index",
        ),
        (Box::new(|s| s.medium.mu_s_per_cm = 0.0), "mu_s_per_cm"),
        (Box::new(|s| s.medium.g = 1.0), "g"),
        (
            Box::new(|s| s.medium.thickness_cm = f64::INFINITY),
            "thickness_cm",
        ),
        (Box::new(|s| s.sensor.fov_cm = -50.0), "fov_cm"),
        (Box::new(|s| s.sensor.width_px = 0), "width_px"),
        (Box::new(|s| s.bins.count = 0), "bins"),
        (Box::new(|s| s.bins.width_ps = 0.0), "width_ps"),
        (
            Box::new(|s| s.bins.start_ps = f64::NEG_INFINITY),
            "start_ps",
        ),
        (Box::new(|s| s.total_photons = 0.0), "photons"),
    ];
    for (mutate, field) in cases {
        let mut s = paper();
        mutate(&mut s);
        let e = KernelStack::build(&s, Sampling::Integrated).unwrap_err();
        assert_eq!(e.field, field, "{e}");
        assert!(
            e.to_string().starts_with(&format!("invalid {field} = ")),
            "{e}"
        );
    }
}

#[test]
fn paper_preset_is_flagged_outside_the_diffusion_regime() {
    let s = paper();
    let d = Diffusion::new(&s.medium).unwrap();
    let codes: Vec<_> = scatterscope_physics::validity::diagnose(&s, &d)
        .into_iter()
        .map(|w| w.code)
        .collect();
    assert!(codes.contains(&"weak-scattering"));
    assert!(codes.contains(&"early-times"));
    // A strongly scattering slab observed late is in the regime.
    let mut ok = s;
    ok.medium.g = 0.0;
    ok.medium.mu_s_per_cm = 100.0;
    ok.medium.mu_a_per_cm = 0.1;
    ok.bins.start_ps = 500.0;
    let d = Diffusion::new(&ok.medium).unwrap();
    assert!(scatterscope_physics::validity::diagnose(&ok, &d).is_empty());
}
