//! The report's realistic instrument: ignoring the background must cost
//! reconstruction quality on data that have it.

use scatterscope::denoise::tv::TotalVariation;
use scatterscope::forward::Boundary;
use scatterscope::physics::{Irf, Preset};
use scatterscope::reconstruct::method::MethodOptions;
use scatterscope::report::instrument::instrument_costs;
use scatterscope::scene::Scene;

#[test]
fn ignoring_the_background_costs_psnr_and_every_variant_is_reported() {
    let mut s = Preset::Paper.setup();
    s.sensor.width_px = 32;
    s.sensor.height_px = 32;
    s.sensor.fov_cm = 50.0 * 32.0 / 256.0;
    s.total_photons = 4000.0;
    s.irf = Some(
        Irf {
            fwhm_ps: 60.0,
            tail_ps: 20.0,
        }
        .into(),
    );
    let tv = TotalVariation::default();
    let mut opts = MethodOptions::default();
    opts.split.max_iters = 40;
    let (b, rows) = instrument_costs(
        &Scene::parse("disks"),
        &s,
        1.0,
        Boundary::Sensor,
        1,
        &tv,
        &opts,
    )
    .unwrap();
    assert!(b > 0.0);
    let get = |model: &str, method: &str| {
        rows.iter()
            .find(|r| r.model == model && r.method == method)
            .unwrap()
            .psnr
    };
    for method in ["pnp", "rl-sum"] {
        let full = get("full model", method);
        let no_bg = get("background ignored", method);
        let no_irf = get("IRF ignored", method);
        eprintln!(
            "{method}: full {full:.2}, background ignored {no_bg:.2}, IRF ignored {no_irf:.2}"
        );
        assert!(full.is_finite() && no_bg.is_finite() && no_irf.is_finite());
    }
    // A background as strong as the mean signal, ignored, brightens the
    // object: both methods lose. (Ignoring the IRF costs the time-summed RL
    // almost nothing, 0.01 dB here, and is only reported.)
    for method in ["pnp", "rl-sum"] {
        let (full, no_bg) = (get("full model", method), get("background ignored", method));
        assert!(full > no_bg + 0.5, "{method}: {rows:?}");
    }
}
