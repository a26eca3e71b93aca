//! The instrument response: its distribution against independent formulas,
//! and kernels with an IRF against the fine-binned kernels without one,
//! convolved by hand.

use scatterscope_physics::irf::{InstrumentResponse, Irf, IrfTable, erfcx, normal_cdf};
use scatterscope_physics::kernel::bin_profile;
use scatterscope_physics::quadrature::adaptive_nodes;
use scatterscope_physics::{KernelStack, Preset, Sampling, Setup};

/// Integral of `f` over `[lo, hi]`, with panels of a tenth of `scale`
/// around 0 (where an IRF changes on that scale) and 200 across the range.
fn integrate(lo: f64, hi: f64, scale: f64, f: impl Fn(f64) -> f64) -> f64 {
    let mut breaks: Vec<f64> = (0..=200)
        .map(|i| lo + (hi - lo) * i as f64 / 200.0)
        .chain((-100..=100).map(|k| k as f64 * scale / 10.0))
        .filter(|x| (lo..=hi).contains(x))
        .collect();
    breaks.sort_by(f64::total_cmp);
    breaks.dedup();
    adaptive_nodes(&breaks, 1e-12, 100_000, |x| [f(x)]).integral[0]
}

#[test]
fn the_irf_is_a_distribution_with_its_stated_width_mean_and_tails() {
    for irf in [
        Irf {
            fwhm_ps: 50.0,
            tail_ps: 0.0,
        },
        Irf {
            fwhm_ps: 50.0,
            tail_ps: 30.0,
        },
        Irf {
            fwhm_ps: 5.0,
            tail_ps: 200.0,
        },
        Irf {
            fwhm_ps: 80.0,
            tail_ps: 0.5,
        },
    ] {
        let (lo, hi) = irf.support_ps();
        let w = irf.sigma_ps();
        let mass = integrate(lo, hi, w, |x| irf.density(x));
        assert!((mass - 1.0).abs() < 1e-9, "{irf:?}: mass {mass}");
        // Shifted by the FWHM so that the integral is not 0 (a relative
        // tolerance could not be met there).
        let shifted = integrate(lo, hi, w, |x| (x + irf.fwhm_ps) * irf.density(x));
        let mean = shifted - irf.fwhm_ps;
        assert!(
            (mean - irf.mean_ps()).abs() < 1e-6 * irf.fwhm_ps,
            "{irf:?}: mean {mean}"
        );
        for x in [-100.0, -10.0, 0.0, 7.0, 60.0, 500.0] {
            let c = irf.cdf(x);
            let by_density = integrate(lo.min(x), x, w, |y| irf.density(y));
            assert!(
                (c - by_density).abs() < 1e-9,
                "{irf:?} cdf({x}) {c} vs {by_density}"
            );
            assert!((c + irf.survival(x) - 1.0).abs() < 1e-15);
        }
        assert!(irf.cdf(lo) < 1e-15 && irf.survival(hi) < 1e-15, "{irf:?}");
        // Far tails stay finite and ordered, no NaN.
        for x in [-1e6, -1e3, 1e3, 1e6] {
            for v in [irf.cdf(x), irf.survival(x), irf.density(x)] {
                assert!(v.is_finite() && v >= 0.0, "{irf:?} at {x}: {v}");
            }
        }
    }
    // Without a tail the FWHM is the FWHM.
    let g = Irf {
        fwhm_ps: 50.0,
        tail_ps: 0.0,
    };
    assert!((g.density(25.0) / g.density(0.0) - 0.5).abs() < 1e-12);
    assert_eq!(g.cdf(3.0), normal_cdf(3.0 / g.sigma_ps()));
}

#[test]
fn erfcx_matches_reference_values_on_both_sides_of_its_switch() {
    // Reference values from SciPy's scipy.special.erfcx.
    for (y, want) in [
        (0.5, 0.615_690_344_192_925_8),
        (5.0, 0.110_704_637_733_068_61),
        (24.0, 0.023_487_546_063_682_644),
        (25.0, 0.022_549_572_432_641_357),
        (40.0, 0.014_100_335_983_377_815),
        (1000.0, 0.000_564_189_301_453_387_6),
    ] {
        let got = erfcx(y);
        assert!(
            (got - want).abs() < 1e-10 * want,
            "erfcx({y}) = {got}, want {want}"
        );
    }
}

fn small_setup() -> Setup {
    let mut s = Preset::Paper.setup();
    s.sensor.width_px = 48;
    s.sensor.height_px = 48;
    s.sensor.fov_cm = 20.0;
    s.min_bin_photons = 0.0;
    s
}

#[test]
fn kernels_with_an_irf_are_the_fine_kernels_convolved_by_hand() {
    // Independent route: kernels of 0.25 ps bins without an IRF, each
    // weighted by the chance that the IRF moves its photons into the coarse
    // bin, summed, and normalised like the stack.
    let irf = Irf {
        fwhm_ps: 20.0,
        tail_ps: 8.0,
    };
    let mut coarse = small_setup();
    coarse.bins.start_ps = 60.0;
    coarse.bins.width_ps = 8.0;
    coarse.bins.count = 12;
    coarse.irf = Some(irf.into());
    let with = KernelStack::build(&coarse, Sampling::Integrated).unwrap();

    let mut fine = small_setup();
    fine.bins.start_ps = 0.0;
    fine.bins.width_ps = 0.25;
    fine.bins.count = 1000; // 0-250 ps: every arrival the IRF can move into 60-156 ps
    let fine = KernelStack::build(&fine, Sampling::Integrated).unwrap();

    let mut by_hand: Vec<ndarray::Array2<f64>> = Vec::new();
    for k in 0..coarse.bins.count {
        let (ta, tb) = coarse.bins.edges_ps(k);
        let mut acc = ndarray::Array2::<f64>::zeros((48, 48));
        for (i, b) in fine.kept_bins().enumerate() {
            let t = 0.5 * (b.start_ps + b.end_ps);
            acc.scaled_add(irf.bin_weight(ta, tb, t), &fine.kernel(i));
        }
        by_hand.push(acc);
    }
    let total: f64 = by_hand.iter().map(|k| k.sum()).sum();
    let scale = coarse.total_photons / total;
    assert_eq!(with.len(), coarse.bins.count);
    for (k, want) in by_hand.iter().enumerate() {
        let got = with.kernel(k);
        let peak = want.iter().fold(0.0f64, |m, v| m.max(*v)) * scale;
        let worst = got
            .iter()
            .zip(want)
            .fold(0.0f64, |m, (g, w)| m.max((g - w * scale).abs()));
        assert!(
            worst < 2e-4 * peak,
            "bin {k}: off by {worst} of peak {peak}"
        );
        let (gm, wm) = (got.sum(), want.sum() * scale);
        assert!((gm - wm).abs() < 1e-4 * wm, "bin {k}: mass {gm} vs {wm}");
    }
}

#[test]
fn a_vanishing_irf_gives_the_ideal_kernels_and_a_wide_one_moves_light_earlier() {
    let ideal = KernelStack::build(&small_setup(), Sampling::Integrated).unwrap();
    let mut sharp = small_setup();
    sharp.irf = Some(
        Irf {
            fwhm_ps: 1e-3,
            tail_ps: 0.0,
        }
        .into(),
    );
    let sharp = KernelStack::build(&sharp, Sampling::Integrated).unwrap();
    for (a, b) in ideal.bins.iter().zip(&sharp.bins) {
        assert!(
            (a.photons - b.photons).abs() <= 1e-6 * a.photons.max(1e-12),
            "bin {}: {} vs {}",
            a.index,
            a.photons,
            b.photons
        );
    }
    // A 60 ps IRF records some light in bins that the ideal instrument
    // leaves out as dark, and the bins before the peak gain light.
    let mut wide = small_setup();
    wide.min_bin_photons = 1.0;
    wide.irf = Some(
        Irf {
            fwhm_ps: 60.0,
            tail_ps: 20.0,
        }
        .into(),
    );
    let wide = KernelStack::build(&wide, Sampling::Integrated).unwrap();
    let mut ideal_kept = small_setup();
    ideal_kept.min_bin_photons = 1.0;
    let ideal_kept = KernelStack::build(&ideal_kept, Sampling::Integrated).unwrap();
    assert!(
        wide.len() > ideal_kept.len(),
        "kept {} with the IRF, {} without",
        wide.len(),
        ideal_kept.len()
    );
    assert!(wide.bins[5].photons > 10.0 * ideal_kept.bins[5].photons);
}

#[test]
fn bad_irf_values_and_point_sampling_are_refused_naming_the_field() {
    let mut s = small_setup();
    s.irf = Some(
        Irf {
            fwhm_ps: -1.0,
            tail_ps: 0.0,
        }
        .into(),
    );
    assert_eq!(s.validate().unwrap_err().field, "irf_fwhm_ps");
    s.irf = Some(
        Irf {
            fwhm_ps: 30.0,
            tail_ps: f64::NAN,
        }
        .into(),
    );
    assert_eq!(s.validate().unwrap_err().field, "irf_tail_ps");
    s.irf = Some(
        Irf {
            fwhm_ps: 1e300,
            tail_ps: 0.0,
        }
        .into(),
    );
    assert_eq!(s.validate().unwrap_err().field, "irf_fwhm_ps");
    s.irf = Some(
        Irf {
            fwhm_ps: 30.0,
            tail_ps: 1e7,
        }
        .into(),
    );
    assert_eq!(s.validate().unwrap_err().field, "irf_tail_ps");
    s.irf = Some(
        Irf {
            fwhm_ps: 30.0,
            tail_ps: 0.0,
        }
        .into(),
    );
    let e = KernelStack::build(&s, Sampling::Point).unwrap_err();
    assert_eq!(e.field, "irf_fwhm_ps");
    assert!(e.to_string().contains("point sampling"), "{e}");
}

#[test]
fn the_whole_plane_profile_is_the_kernels_masses_on_a_sensor_that_holds_the_light() {
    for irf in [
        None,
        Some(Irf {
            fwhm_ps: 30.0,
            tail_ps: 10.0,
        }),
    ] {
        let mut s = small_setup();
        s.sensor.fov_cm = 40.0; // every kernel well inside the sensor
        s.irf = irf.map(Into::into);
        let profile = scatterscope_physics::kernel::bin_profile(&s).unwrap();
        let k = KernelStack::build(&s, Sampling::Integrated).unwrap();
        let total: f64 = k.bins.iter().map(|b| b.photons).sum();
        assert!((profile.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        for (p, b) in profile.iter().zip(&k.bins) {
            let want = b.photons / total;
            assert!(
                (p - want).abs() < 1e-6 * want.max(1e-9),
                "{irf:?} bin {}: {p} vs {want}",
                b.index
            );
        }
    }
}

/// A measured-looking response: a sharp peak with a slow diffusion tail
/// and a small bump, on `bin_ps` bins from `start_ps` (not normalised).
fn spad_like_table(bin_ps: f64, start_ps: f64, count: usize) -> IrfTable {
    let weights = (0..count)
        .map(|j| {
            let d = start_ps + (j as f64 + 0.5) * bin_ps;
            let peak = (-0.5 * (d / 9.0).powi(2)).exp();
            let tail = if d > 0.0 {
                0.08 * (-d / 40.0).exp()
            } else {
                0.0
            };
            let bump = 0.05 * (-0.5 * ((d - 70.0) / 6.0).powi(2)).exp();
            peak + tail + bump
        })
        .collect();
    IrfTable::new(bin_ps, start_ps, weights).unwrap()
}

/// `setup`'s kernels built by hand: kernels of 0.25 ps bins without an
/// IRF over 0-250 ps, each weighted by the chance that `irf` moves its
/// photons into each bin, normalised like the stack.
fn convolved_by_hand(setup: &Setup, irf: &InstrumentResponse) -> Vec<ndarray::Array2<f64>> {
    let mut fine = small_setup();
    fine.bins.start_ps = 0.0;
    fine.bins.width_ps = 0.25;
    fine.bins.count = 1000;
    let fine = KernelStack::build(&fine, Sampling::Integrated).unwrap();
    let mut by_hand: Vec<ndarray::Array2<f64>> = (0..setup.bins.count)
        .map(|k| {
            let (ta, tb) = setup.bins.edges_ps(k);
            let mut acc = ndarray::Array2::<f64>::zeros((48, 48));
            for (i, b) in fine.kept_bins().enumerate() {
                let t = 0.5 * (b.start_ps + b.end_ps);
                acc.scaled_add(irf.bin_weight(ta, tb, t), &fine.kernel(i));
            }
            acc
        })
        .collect();
    let total: f64 = by_hand.iter().map(|k| k.sum()).sum();
    by_hand
        .iter_mut()
        .for_each(|k| *k *= setup.total_photons / total);
    by_hand
}

/// Largest difference of any bin's kernel from `want`'s, relative to the
/// largest kernel value of all.
fn worst_relative(got: &KernelStack, want: &[ndarray::Array2<f64>]) -> f64 {
    let peak = want
        .iter()
        .flat_map(|k| k.iter())
        .fold(0.0f64, |m, v| m.max(*v));
    (0..want.len())
        .map(|k| {
            got.kernel(k)
                .iter()
                .zip(&want[k])
                .fold(0.0f64, |m, (g, w)| m.max((g - w).abs()))
        })
        .fold(0.0, f64::max)
        / peak
}

#[test]
fn kernels_with_a_measured_table_are_the_fine_kernels_convolved_by_hand() {
    let mut coarse = small_setup();
    coarse.bins.start_ps = 60.0;
    coarse.bins.width_ps = 8.0;
    coarse.bins.count = 12;
    // On the stack's lattice (4 ps steps from a multiple of 4).
    let aligned = InstrumentResponse::from(spad_like_table(4.0, -24.0, 40));
    coarse.irf = Some(aligned.clone());
    let got = KernelStack::build(&coarse, Sampling::Integrated).unwrap();
    assert_eq!(got.len(), coarse.bins.count);
    let worst = worst_relative(&got, &convolved_by_hand(&coarse, &aligned));
    assert!(worst < 2e-4, "aligned table: off by {worst} of the peak");
    // Off the lattice (3 ps bins from -25 ps): cells end where the table's
    // edges fall, and the sums stay exact.
    let offset = InstrumentResponse::from(spad_like_table(3.0, -25.0, 55));
    coarse.irf = Some(offset.clone());
    let got = KernelStack::build(&coarse, Sampling::Integrated).unwrap();
    let worst = worst_relative(&got, &convolved_by_hand(&coarse, &offset));
    assert!(worst < 2e-4, "offset table: off by {worst} of the peak");
    // The time profile calibrate fits is the kernels' masses.
    let profile = bin_profile(&coarse).unwrap();
    let masses: Vec<f64> = (0..got.len()).map(|k| got.kernel(k).sum()).collect();
    let total: f64 = masses.iter().sum();
    for (p, m) in profile.iter().zip(&masses) {
        assert!(
            (p - m / total).abs() < 1e-9,
            "profile {p} vs kernels {}",
            m / total
        );
    }
}

#[test]
fn a_measured_table_is_a_distribution_and_bad_tables_are_refused_by_field() {
    let t = spad_like_table(3.0, -25.0, 55);
    assert!((t.weights().iter().sum::<f64>() - 1.0).abs() < 1e-12);
    let (lo, hi) = t.support_ps();
    assert_eq!((lo, hi), (-25.0, -25.0 + 165.0));
    for x in [-30.0, -25.0, -10.0, 0.0, 0.7, 33.3, 139.9, 140.0, 200.0] {
        let (c, s) = (t.cdf(x), t.survival(x));
        assert!((c + s - 1.0).abs() < 1e-14, "at {x}: {c} + {s}");
        // The inverse distribution returns the delay.
        if x > lo && x < hi {
            assert!((t.delay_for(c) - x).abs() < 1e-9, "at {x}");
        }
    }
    // A setup carrying it survives a round trip through its stored form.
    let mut s = small_setup();
    s.irf = Some(t.clone().into());
    let json = serde_json::to_string(&s).unwrap();
    let back: Setup = serde_json::from_str(&json).unwrap();
    assert_eq!(back, s);
    for (weights, field, value) in [
        (vec![1.0, f64::NAN], "irf_table_weights", "NaN"),
        (vec![1.0, -0.5], "irf_table_weights", "-0.5"),
        (vec![0.0, 0.0], "irf_table_weights", "0"),
        (vec![], "irf_table_weights", "0"),
    ] {
        let e = IrfTable::new(4.0, 0.0, weights).unwrap_err().to_string();
        assert!(e.contains(field) && e.contains(value), "{e}");
    }
    let e = IrfTable::new(0.0, 0.0, vec![1.0]).unwrap_err().to_string();
    assert!(e.contains("irf_table_bin_ps"), "{e}");
    // A stored table with a bad entry is refused when read back.
    let bad = json.replacen("\"weights\":[", "\"weights\":[-1.0,", 1);
    let e = serde_json::from_str::<Setup>(&bad).unwrap_err().to_string();
    assert!(e.contains("irf_table_weights"), "{e}");
}
