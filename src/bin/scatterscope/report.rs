//! `scatterscope report`: every method on simulated scenes, against the truth.

use std::path::PathBuf;

use scatterscope::Named;
use scatterscope::denoise::prior::PriorKind;
use scatterscope::report::{ReportConfig, ReportSettings, run_report};
use scatterscope::scene::Scene;

use crate::recon_args::ReconArgs;
use crate::shared_args::{progress, resolve};
use scatterscope::config::PhysicsOverrides;

/// Simulate scenes, run every method, and compare them with the truth.
///
/// Per scene OUT/SCENE/ holds images, traces, per_bin.csv and the plots;
/// OUT/summary.{md,csv} the table of PSNR, SSIM and time per method.
#[derive(Debug, clap::Args)]
pub struct ReportArgs {
    /// Scene(s): usaf, star, text, disks or image files (default: all built-in).
    #[arg(long = "scene", value_name = "SCENE|FILE")]
    scenes: Vec<String>,
    #[command(flatten)]
    settings: ReportSettings,
    /// Output directory (created if missing).
    #[arg(long, default_value = "out/report")]
    out: PathBuf,
    #[command(flatten)]
    physics: PhysicsOverrides,
    #[command(flatten)]
    recon: ReconArgs,
}

pub fn run(args: &ReportArgs) -> anyhow::Result<()> {
    let denoiser = args.recon.prior.build()?;
    // The learned prior is compared with TV on the same data.
    let comparison = args.recon.prior.tv_beside()?;
    let cfg = ReportConfig {
        scenes: match args.scenes.is_empty() {
            true => Scene::BUILT_IN.iter().map(|s| Scene::parse(s)).collect(),
            false => args.scenes.iter().map(|s| Scene::parse(s)).collect(),
        },
        setup: resolve(&args.physics)?,
        settings: args.settings.clone(),
        denoiser: denoiser.as_ref(),
        comparison: comparison
            .as_ref()
            .map(|d| (PriorKind::Tv.name(), d.as_ref())),
        opts: args.recon.options()?,
        rl_iters: args.recon.rl_iters,
        out: args.out.clone(),
    };
    let bar = progress(None);
    bar.enable_steady_tick(std::time::Duration::from_millis(200));
    let md = run_report(&cfg, |msg| bar.set_message(msg.to_string()))?;
    bar.finish_and_clear();
    println!("{md}");
    println!(
        "wrote {}/summary.{{md,csv}} and one folder per scene",
        args.out.display()
    );
    Ok(())
}
