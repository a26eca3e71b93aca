//! The mock's timing jitter: recorded times drawn as arrival plus IRF delay
//! must follow the IRF-convolved kernels the reconstruction uses.

use scatterscope_mocks::{Emitter, EmitterOptions};
use scatterscope_physics::{Irf, KernelStack, Preset, Sampling, Setup};

fn setup(irf: Option<Irf>) -> Setup {
    let mut s = Preset::Paper.setup();
    s.sensor.width_px = 32;
    s.sensor.height_px = 32;
    s.bins.count = 40; // 0-160 ps
    s.min_bin_photons = 0.0;
    s.irf = irf.map(Into::into);
    s
}

/// Chi-square per bin of `n` recorded delays from `emitter` against the
/// bin masses of `expected`, over the expected kernels' window.
fn chi2_per_bin(emitter: &mut Emitter, expected: &KernelStack, t0: f64, n: usize) -> f64 {
    let bins = &expected.setup.bins;
    let mut hist = vec![0.0f64; bins.count];
    for _ in 0..n {
        let d = emitter.next_detection();
        let t = d.delay_ps - t0 - bins.start_ps;
        if t >= 0.0 && t < bins.count as f64 * bins.width_ps {
            hist[(t / bins.width_ps) as usize] += 1.0;
        }
    }
    let recorded: f64 = hist.iter().sum();
    let masses: Vec<f64> = expected.bins.iter().map(|b| b.photons).collect();
    let total: f64 = masses.iter().sum();
    let (mut chi2, mut used) = (0.0, 0);
    for (o, m) in hist.iter().zip(&masses) {
        let e = recorded * m / total;
        if e >= 20.0 {
            chi2 += (o - e) * (o - e) / e;
            used += 1;
        }
    }
    assert!(used >= 15, "only {used} well-filled bins");
    chi2 / used as f64
}

/// A point in the middle of the 32 x 32 sensor, the pulse 300 ps after
/// the sync, and the emitter's options with `seed`.
fn point_at_t0(seed: u64) -> (Vec<f64>, f64, EmitterOptions) {
    let mut scene = vec![0.0; 32 * 32];
    scene[16 * 32 + 16] = 1.0;
    let t0 = 300.0;
    let options = EmitterOptions {
        t0_delay_ps: t0,
        sync_period_ps: 12_500.0,
        seed,
        ..EmitterOptions::default()
    };
    (scene, t0, options)
}

#[test]
fn recorded_times_follow_the_irf_convolved_kernels() {
    let irf = Irf {
        fwhm_ps: 20.0,
        tail_ps: 10.0,
    };
    let with = KernelStack::build(&setup(Some(irf)), Sampling::Integrated).unwrap();
    let (scene, t0, options) = point_at_t0(7);
    let mut jittered = Emitter::new(&scene, &with, options.clone()).unwrap();
    let chi2 = chi2_per_bin(&mut jittered, &with, t0, 400_000);
    assert!(
        chi2 < 1.6,
        "chi-square per bin {chi2} against the IRF kernels"
    );
    // An emitter without the IRF fails the same comparison: the test can
    // tell the two apart.
    let ideal = KernelStack::build(&setup(None), Sampling::Integrated).unwrap();
    let mut sharp = Emitter::new(&scene, &ideal, options).unwrap();
    let chi2_ideal = chi2_per_bin(&mut sharp, &with, t0, 400_000);
    assert!(chi2_ideal > 20.0, "ideal timing gave {chi2_ideal}");
}

#[test]
fn recorded_times_follow_the_kernels_of_a_measured_table() {
    use scatterscope_physics::IrfTable;
    // A sharp peak, a slow tail and a late bump, on 4 ps bins from -12 ps.
    let weights: Vec<f64> = (0..30)
        .map(|j| {
            let d = -12.0 + 4.0 * (j as f64 + 0.5);
            (-0.5 * (d / 6.0).powi(2)).exp()
                + if d > 0.0 {
                    0.1 * (-d / 30.0).exp()
                } else {
                    0.0
                }
                + 0.08 * (-0.5 * ((d - 60.0) / 5.0).powi(2)).exp()
        })
        .collect();
    let table = IrfTable::new(4.0, -12.0, weights).unwrap();
    let mut s = setup(None);
    s.irf = Some(table.into());
    let with = KernelStack::build(&s, Sampling::Integrated).unwrap();
    let (scene, t0, options) = point_at_t0(11);
    let mut emitter = Emitter::new(&scene, &with, options.clone()).unwrap();
    let chi2 = chi2_per_bin(&mut emitter, &with, t0, 400_000);
    assert!(
        chi2 < 1.6,
        "chi-square per bin {chi2} against the table's kernels"
    );
    // The parametric IRF of the same width does not describe these times.
    let gauss = KernelStack::build(
        &setup(Some(Irf {
            fwhm_ps: 14.0,
            tail_ps: 0.0,
        })),
        Sampling::Integrated,
    )
    .unwrap();
    let mut emitter = Emitter::new(&scene, &with, options).unwrap();
    let chi2_gauss = chi2_per_bin(&mut emitter, &gauss, t0, 400_000);
    assert!(chi2_gauss > 20.0, "a Gaussian IRF gave {chi2_gauss}");
}
