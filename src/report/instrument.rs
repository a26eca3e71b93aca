//! What ignoring the instrument costs: one scene measured with an IRF and
//! background counts, reconstructed with the full model, without the IRF
//! and without the background.

use scatterscope_physics::{Irf, Sampling, Setup};

use super::ReportError;
use crate::denoise::Denoiser;
use crate::forward::{Boundary, poisson_counts};
use crate::metrics::psnr;
use crate::reconstruct::method::{Method, MethodOptions, run_method};
use crate::reconstruct::problem::{BackgroundChoice, Problem};
use crate::scene::Scene;
use crate::simulate::simulate;
use crate::stack::Stack;

/// The IRF a realistic instrument gets when its physics has none.
pub const REALISTIC_IRF: Irf = Irf {
    fwhm_ps: 50.0,
    tail_ps: 20.0,
};

/// `setup` as a realistic instrument measures it: its own IRF, else
/// [`REALISTIC_IRF`].
pub fn realistic(setup: &Setup) -> Setup {
    let mut s = setup.clone();
    s.irf.get_or_insert(REALISTIC_IRF.into());
    s
}

/// One reconstruction of the realistic measurement.
#[derive(Debug, Clone, PartialEq)]
pub struct InstrumentCost {
    /// Scene name.
    pub scene: String,
    /// Which model the reconstruction assumed.
    pub model: &'static str,
    /// Method name.
    pub method: &'static str,
    /// PSNR of the output against the truth (dB).
    pub psnr: f64,
    /// Wall time (s).
    pub wall_s: f64,
}

/// Simulates `scene` with `setup` (its IRF, else [`REALISTIC_IRF`]) plus a background of
/// `background_share` times the mean expected count per pixel and bin, and
/// reconstructs it with PnP and RL-sum three ways: the full model, the IRF
/// ignored, the background ignored. Returns the background used (counts
/// per pixel and bin) and the results.
pub fn instrument_costs(
    scene: &Scene,
    setup: &Setup,
    background_share: f64,
    boundary: Boundary,
    seed: u64,
    denoiser: &dyn Denoiser,
    opts: &MethodOptions,
) -> Result<(f64, Vec<InstrumentCost>), ReportError> {
    if !(background_share.is_finite() && background_share >= 0.0) {
        return Err(ReportError::Input(format!(
            "background share = {background_share} must be a finite number >= 0"
        )));
    }
    let setup = &realistic(setup);
    let sim = simulate(setup, scene, Sampling::Integrated, boundary, seed)?;
    let expected = sim.expected.data.mapv(f64::from);
    let background = background_share * expected.mean().unwrap_or(0.0);
    let counts =
        poisson_counts(&expected.mapv(|v| v + background), seed ^ 0x5eed).mapv(|v| v as f32);
    let stack = Stack::new(counts, sim.counts.meta.clone());
    let mut ideal = setup.clone();
    ideal.irf = None;
    let run =
        |problem: &Problem, model: &'static str| -> Result<Vec<InstrumentCost>, ReportError> {
            [Method::Pnp, Method::RlSum]
                .into_iter()
                .map(|method| {
                    let r = run_method(problem, method, None, denoiser, opts, None, |_| {})?;
                    Ok(InstrumentCost {
                        scene: scene.name(),
                        model,
                        method: if method == Method::Pnp {
                            "pnp"
                        } else {
                            "rl-sum"
                        },
                        psnr: psnr(r.image.view(), sim.truth.view()),
                        wall_s: r.trace.wall_s,
                    })
                })
                .collect()
        };
    // The full model and the one without background share their kernels:
    // built once, the background set twice.
    let given = BackgroundChoice::Given(background);
    let (full, _) =
        Problem::new(&stack, setup, Sampling::Integrated, boundary)?.with_background(given)?;
    let mut out = run(&full, "full model")?;
    let (no_irf, _) =
        Problem::new(&stack, &ideal, Sampling::Integrated, boundary)?.with_background(given)?;
    out.extend(run(&no_irf, "IRF ignored")?);
    let (no_background, _) = full.with_background(BackgroundChoice::None)?;
    out.extend(run(&no_background, "background ignored")?);
    Ok((background, out))
}

/// The results as a Markdown table, one row per scene, model and method.
pub fn instrument_markdown(
    setup: &Setup,
    background: &[(String, f64)],
    rows: &[InstrumentCost],
) -> String {
    let mut s = format!(
        "## What ignoring the instrument costs\n\nMeasured with: {}; background per scene (counts per pixel and bin): {}.\n\n| scene | model assumed | method | PSNR (dB) | time (s) |\n|---|---|---|---|---|\n",
        setup.model_summary(),
        background
            .iter()
            .map(|(n, b)| format!("{n} {b:.3e}"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    for r in rows {
        s.push_str(&format!(
            "| {} | {} | {} | {:.2} | {:.2} |\n",
            r.scene, r.model, r.method, r.psnr, r.wall_s
        ));
    }
    s
}
