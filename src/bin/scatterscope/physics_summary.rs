//! What every physics-using command prints first: the setup, the validity
//! warnings, and the bins left out.

use scatterscope::physics::kernel::KernelStack;
use scatterscope::physics::validity::diagnose;
use scatterscope::physics::{Sampling, Setup};

/// Prints the setup and the diffusion-regime warnings to stderr.
pub fn print_setup(setup: &Setup, kernels: &KernelStack) {
    let m = &setup.medium;
    let d = &kernels.diffusion;
    eprintln!(
        "medium: mu_a {} /cm, mu_s {} /cm, g {}, n {}, thickness {} cm (D = {:.4} cm, light arrives from ~{:.0} ps, peak {:.1} ps)",
        m.mu_a_per_cm,
        m.mu_s_per_cm,
        m.g,
        m.refractive_index,
        m.thickness_cm,
        d.d_cm,
        kernels
            .bins
            .iter()
            .find(|b| b.photons >= 0.01)
            .map_or(f64::NAN, |b| b.start_ps),
        d.peak_time_ps(),
    );
    eprintln!("model: {}", setup.model_summary());
    if let Some(s) = &d.slab {
        eprintln!(
            "slab: extrapolated boundaries {:.4} cm outside each face (n = {} against air), equivalent source {:.4} cm deep; transmitted flux",
            s.extrapolation_cm, m.refractive_index, s.source_depth_cm
        );
    }
    eprintln!(
        "sensor: {} x {} px over {} cm ({:.4} cm/px); bins: {} x {} ps from {} ps; light budget {} photons",
        setup.sensor.width_px,
        setup.sensor.height_px,
        setup.sensor.fov_cm,
        setup.sensor.pixel_pitch_cm(),
        setup.bins.count,
        setup.bins.width_ps,
        setup.bins.start_ps,
        setup.total_photons
    );
    for w in diagnose(setup, d) {
        eprintln!("warning [{}]: {}", w.code, w.message);
    }
    let dropped: Vec<_> = kernels.dropped_bins().collect();
    if !dropped.is_empty() {
        let photons: f64 = dropped.iter().map(|b| b.photons).sum();
        eprintln!(
            "left out: {} bin(s) with fewer than {} expected photons each ({}), {:.3} photons in total ({:.3}% of the budget)",
            dropped.len(),
            setup.min_bin_photons,
            dropped
                .iter()
                .map(|b| format!("{}-{} ps", b.start_ps, b.end_ps))
                .collect::<Vec<_>>()
                .join(", "),
            photons,
            100.0 * photons / setup.total_photons
        );
    }
    let full = (setup.sensor.height_px * setup.sensor.width_px) as f64;
    let evaluated: f64 = kernels
        .kept_bins()
        .map(|b| ((2 * b.support_radius_px + 1).pow(2) as f64).min(full))
        .sum();
    eprintln!(
        "left out: kernel pixels beyond {} sigma (evaluated {:.1}% of the pixels of the {} kept bins)",
        scatterscope::physics::kernel::SUPPORT_SIGMAS,
        100.0 * evaluated / (full * kernels.len() as f64),
        kernels.len()
    );
}

/// Parses `integrated` or `point`.
pub fn parse_sampling(s: &str) -> Result<Sampling, String> {
    match s {
        "integrated" => Ok(Sampling::Integrated),
        "point" => Ok(Sampling::Point),
        other => Err(format!(
            "unknown sampling `{other}` (use integrated or point)"
        )),
    }
}
