//! Diagnostics for the regime in which the diffusion approximation holds.
//!
//! The approximation needs scattering to dominate absorption and times long
//! compared to the transport mean free time. Violations are reported as
//! warnings, never errors: the paper's own preset violates both.

use serde::Serialize;

use crate::diffusion::Diffusion;
use crate::params::Setup;

/// How many transport mean free times count as "a few".
pub const MIN_TRANSPORT_TIMES: f64 = 3.0;
/// How much larger the reduced scattering must be than absorption.
pub const MIN_SCATTERING_TO_ABSORPTION: f64 = 10.0;

/// One warning about the validity of the model for a setup.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Diagnostic {
    /// Stable short identifier (`weak-scattering`, `early-times`, `thin-slab`).
    pub code: &'static str,
    /// A sentence for the user, with the numbers that triggered it.
    pub message: String,
}

/// Checks a setup against the diffusion regime and returns the warnings.
pub fn diagnose(setup: &Setup, diffusion: &Diffusion) -> Vec<Diagnostic> {
    let mut out = Vec::new();
    let mu_a = diffusion.mu_a_per_cm;
    let mu_s_red = diffusion.mu_s_reduced_per_cm;
    if mu_s_red < MIN_SCATTERING_TO_ABSORPTION * mu_a {
        out.push(Diagnostic {
            code: "weak-scattering",
            message: format!(
                "reduced scattering (1-g) mu_s = {mu_s_red:.4} /cm is not >> mu_a = {mu_a:.4} /cm \
                 (ratio {:.3}, want >= {MIN_SCATTERING_TO_ABSORPTION}); the diffusion approximation \
                 is outside its regime",
                mu_s_red / mu_a
            ),
        });
    }
    let tau = diffusion.transport_mean_free_time_ps();
    let limit = MIN_TRANSPORT_TIMES * tau;
    let early = (0..setup.bins.count)
        .filter(|&k| setup.bins.edges_ps(k).0 < limit)
        .count();
    if early > 0 {
        out.push(Diagnostic {
            code: "early-times",
            message: format!(
                "{early} of {} bins start before {MIN_TRANSPORT_TIMES} transport mean free times \
                 ({limit:.1} ps, one is {tau:.1} ps); there the diffusion approximation is inaccurate",
                setup.bins.count
            ),
        });
    }
    let l_star = diffusion.transport_mean_free_path_cm();
    if diffusion.z0_cm < MIN_TRANSPORT_TIMES * l_star {
        out.push(Diagnostic {
            code: "thin-slab",
            message: format!(
                "slab thickness {:.3} cm is less than {MIN_TRANSPORT_TIMES} transport mean free paths \
                 ({:.3} cm each); light is not yet diffuse when it leaves the slab",
                diffusion.z0_cm, l_star
            ),
        });
    }
    out
}

/// What every physics-using command reports first, one line each: the
/// medium and model, the sensor and bins, the diffusion-regime warnings
/// (`warning [code]: ...`), and what the kernels left out (bins below the
/// photon threshold, pixels beyond the support).
pub fn describe_setup(setup: &Setup, kernels: &crate::KernelStack) -> Vec<String> {
    let m = &setup.medium;
    let d = &kernels.diffusion;
    let monte_carlo = m.model == crate::params::MediumModel::MonteCarlo;
    let first_bin = kernels
        .bins
        .iter()
        .find(|b| b.photons >= 0.01)
        .map_or(f64::NAN, |b| b.start_ps);
    let arrival = if monte_carlo {
        format!(
            "the first light crosses at n d / c = {:.1} ps; light in the bins from ~{first_bin:.0} ps",
            m.first_light_ps()
        )
    } else {
        format!(
            "D = {:.4} cm, light arrives from ~{first_bin:.0} ps, peak {:.1} ps",
            d.d_cm,
            d.peak_time_ps()
        )
    };
    let mut lines = vec![format!(
        "medium: mu_a {} /cm, mu_s {} /cm, g {}, n {}, thickness {} cm ({arrival})",
        m.mu_a_per_cm, m.mu_s_per_cm, m.g, m.refractive_index, m.thickness_cm,
    )];
    lines.push(format!("model: {}", setup.model_summary()));
    if let Some(s) = &d.slab {
        lines.push(format!(
            "slab: extrapolated boundaries {:.4} cm outside each face (n = {} against air), equivalent source {:.4} cm deep; transmitted flux",
            s.extrapolation_cm, m.refractive_index, s.source_depth_cm
        ));
    }
    lines.push(format!(
        "sensor: {} x {} px over {} cm ({:.4} cm/px); bins: {} x {} ps from {} ps; light budget {} photons",
        setup.sensor.width_px,
        setup.sensor.height_px,
        setup.sensor.fov_cm,
        setup.sensor.pixel_pitch_cm(),
        setup.bins.count,
        setup.bins.width_ps,
        setup.bins.start_ps,
        setup.total_photons
    ));
    // Diffusion's regime does not bind light as it travels: said, not
    // warned.
    let prefix = if monte_carlo {
        "note (diffusion would not hold; Monte Carlo transport is used)"
    } else {
        "warning"
    };
    let warnings = diagnose(setup, d);
    let measured = crate::diffusion_error::measured_line_where_outside(setup, &warnings);
    lines.extend(
        warnings
            .into_iter()
            .map(|w| format!("{prefix} [{}]: {}", w.code, w.message)),
    );
    lines.extend(measured);
    let dropped: Vec<_> = kernels.dropped_bins().collect();
    if !dropped.is_empty() {
        let photons: f64 = dropped.iter().map(|b| b.photons).sum();
        lines.push(format!(
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
        ));
    }
    if monte_carlo {
        let (worst, light) = kernels.kept_bins().fold((0.0f64, 0.0), |(w, l), b| {
            let e = b.relative_error.unwrap_or(0.0);
            (w.max(e), l + e * b.photons)
        });
        let kept: f64 = kernels.kept_bins().map(|b| b.photons).sum();
        lines.push(format!(
            "left out: light leaving the far face past the sensor's corners; the kernels' relative standard error: {:.2} % light-weighted, {:.2} % at worst ({} packets)",
            100.0 * light / kept.max(f64::MIN_POSITIVE),
            100.0 * worst,
            crate::transport::SETUP_PACKETS
        ));
        if let Some(cache) = &kernels.transport_cache {
            lines.push(format!("transport run: {cache}"));
        }
        return lines;
    }
    let full = (setup.sensor.height_px * setup.sensor.width_px) as f64;
    let evaluated: f64 = kernels
        .kept_bins()
        .map(|b| ((2 * b.support_radius_px + 1).pow(2) as f64).min(full))
        .sum();
    lines.push(format!(
        "left out: kernel pixels beyond {} sigma (evaluated {:.1}% of the pixels of the {} kept bins)",
        crate::kernel::SUPPORT_SIGMAS,
        100.0 * evaluated / (full * kernels.len() as f64),
        kernels.len()
    ));
    lines
}
