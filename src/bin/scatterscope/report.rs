//! `scatterscope report`: every method on simulated scenes, against the truth.

use std::path::PathBuf;

use crate::shared_args::{PhysicsArgs, choice};
use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use scatterscope::forward::Boundary;
use scatterscope::report::instrument::{instrument_costs, instrument_markdown, realistic};
use scatterscope::report::{run_scene, summary_csv, summary_markdown};
use scatterscope::scene::Scene;

use crate::recon_args::ReconArgs;

/// Simulate scenes, run every method, and compare them with the truth.
///
/// Per scene (in OUT/SCENE/): output images, traces, per_bin.csv, the
/// paper's Fig. 4 analogue (fig4_psnr_per_bin.png) and PSNR against wall
/// time (error_vs_time.png). OUT/summary.md and summary.csv hold the table
/// of PSNR, SSIM and wall time per method and the margins of full-stack PnP
/// over the best baseline.
#[derive(Debug, clap::Args)]
pub struct ReportArgs {
    /// Scene(s): usaf, star, text, disks or image files (default: all built-in).
    #[arg(long = "scene", value_name = "SCENE|FILE")]
    scenes: Vec<String>,
    #[command(flatten)]
    physics: PhysicsArgs,
    #[command(flatten)]
    recon: ReconArgs,
    /// How the sensor's edges are simulated and modelled (sensor: the scene
    /// fills the field, dark outside; periodic: wrap-around).
    #[arg(long, value_parser = choice::<Boundary>(), default_value = "sensor")]
    boundary: Boundary,
    /// Seed of the Poisson sampler.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Instrument: ideal (the physics as given) or realistic (also measure
    /// each scene with an IRF, the physics' own or 50 ps FWHM with a 20 ps
    /// tail, and a background, and report what ignoring either costs).
    #[arg(long, value_parser = ["ideal", "realistic"], default_value = "ideal")]
    instrument: String,
    /// Realistic instrument: background as a share of the mean expected
    /// count per pixel and bin.
    #[arg(long, default_value_t = 0.05)]
    background_share: f64,
    /// Run the single-bin methods on every n-th bin only.
    #[arg(long, default_value_t = 1)]
    slice_step: usize,
    /// Output directory (created if missing).
    #[arg(long, default_value = "out/report")]
    out: PathBuf,
}

pub fn run(args: &ReportArgs) -> anyhow::Result<()> {
    let setup = args.physics.resolve()?;
    let opts = args.recon.options()?;
    let denoiser = args.recon.prior.denoiser()?;
    // The learned prior is compared with TV on the same data.
    let comparison = args.recon.prior.tv_comparison()?;
    let names: Vec<String> = if args.scenes.is_empty() {
        Scene::BUILT_IN.iter().map(|s| s.to_string()).collect()
    } else {
        args.scenes.clone()
    };
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating output directory {}", args.out.display()))?;
    let bar = ProgressBar::new_spinner();
    bar.set_style(ProgressStyle::with_template("{spinner} {elapsed} {msg}").expect("template"));
    bar.enable_steady_tick(std::time::Duration::from_millis(200));
    let mut reports = Vec::new();
    for name in &names {
        let scene = Scene::parse(name);
        let dir = args.out.join(scene_dir(&scene));
        bar.set_message(format!("{name}: simulating"));
        let report = run_scene(
            &scene,
            &setup,
            args.boundary,
            args.seed,
            denoiser.as_ref(),
            comparison.as_ref().map(|(n, d)| (n.as_str(), d.as_ref())),
            &opts,
            args.slice_step,
            &dir,
            |msg| bar.set_message(msg.to_string()),
        )?;
        bar.println(format!("{name}: done, files in {}", dir.display()));
        reports.push(report);
    }
    let mut md = summary_markdown(&reports);
    if args.instrument == "realistic" {
        let (mut backgrounds, mut rows) = (Vec::new(), Vec::new());
        for name in &names {
            let scene = Scene::parse(name);
            bar.set_message(format!("{name}: realistic instrument"));
            let (b, r) = instrument_costs(
                &scene,
                &setup,
                args.background_share,
                args.boundary,
                args.seed,
                denoiser.as_ref(),
                &opts,
            )
            .with_context(|| {
                format!(
                    "{name}: realistic instrument (--background-share {})",
                    args.background_share
                )
            })?;
            backgrounds.push((scene.name(), b));
            rows.extend(r);
        }
        md.push('\n');
        md.push_str(&instrument_markdown(
            &realistic(&setup),
            &backgrounds,
            &rows,
        ));
    }
    bar.finish_and_clear();
    std::fs::write(args.out.join("summary.md"), &md)?;
    std::fs::write(args.out.join("summary.csv"), summary_csv(&reports))?;
    println!("{md}");
    println!(
        "wrote {}/summary.{{md,csv}} and one folder per scene",
        args.out.display()
    );
    Ok(())
}

fn scene_dir(scene: &Scene) -> String {
    match scene {
        Scene::File(p) => p
            .file_stem()
            .map_or("file".into(), |s| s.to_string_lossy().into_owned()),
        other => other.name(),
    }
}
