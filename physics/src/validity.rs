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
