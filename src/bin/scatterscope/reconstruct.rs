//! `scatterscope reconstruct`: recover the object from a stack.

use std::path::PathBuf;

use anyhow::Context;
use scatterscope::Named;
use scatterscope::calibrate::Free;
use scatterscope::forward::Boundary;
use scatterscope::reconstruct::input::{self, InputSpec};
use scatterscope::reconstruct::method::{Method, run_method};
use scatterscope::reconstruct::problem::BackgroundChoice;

use crate::recon_args::ReconArgs;
use crate::shared_args::{choice, progress};
use scatterscope::config::PhysicsOverrides;

/// Reconstruct the object from a transient stack (.exr or .npy).
///
/// Physics from the stack's metadata, overridden by flags or --config.
/// Writes reconstruction.{exr,png} and trace.{csv,json}.
#[derive(Debug, clap::Args)]
pub struct ReconstructArgs {
    /// The stack file.
    stack: PathBuf,
    /// Method: on the whole stack, the time-summed stack or one bin.
    #[arg(long, value_parser = choice::<Method>(), default_value = "auto")]
    method: Method,
    /// Bin (0-based) for single-bin methods and scaled-counts.
    #[arg(long)]
    bin: Option<usize>,
    /// The sensor's edges: sensor (real sensors) or periodic (wrap-around)
    /// [default: the stack's record, else sensor].
    #[arg(long, value_parser = choice::<Boundary>())]
    boundary: Option<Boundary>,
    /// Truth image (PNG/JPEG/EXR) to report PSNR and SSIM against.
    #[arg(long)]
    truth: Option<PathBuf>,
    /// Background counts per pixel and bin: auto (from the bins before the
    /// first light), none, or a number.
    #[arg(long, value_parser = BackgroundChoice::parse, default_value = "auto")]
    background: BackgroundChoice,
    /// Fit these to the stack's time profile first (as `calibrate --fit`).
    #[arg(long, value_delimiter = ',')]
    fit_physics: Vec<String>,
    #[command(flatten)]
    physics: PhysicsOverrides,
    /// Output directory (created if missing).
    #[arg(long, default_value = "out/reconstruct")]
    out: PathBuf,
    /// Also write the image as OME-TIFF (reconstruction.ome.tif, floats,
    /// the sensor's pixel size) for Fiji or napari.
    #[arg(long)]
    ome_tiff: bool,
    #[command(flatten)]
    recon: ReconArgs,
}

pub fn run(args: &ReconstructArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        !args.method.needs_bin() || args.bin.is_some(),
        "method {} needs --bin K",
        args.method.name()
    );
    crate::shared_args::note_renamed_parameters("--fit-physics", &args.fit_physics);
    let fit_physics = (!args.fit_physics.is_empty())
        .then(|| Free::from_names(&args.fit_physics))
        .transpose()
        .context("--fit-physics")?;
    let input = input::load(
        &args.stack,
        &InputSpec {
            physics: args.physics.clone(),
            fit_physics,
            boundary: args.boundary,
            background: args.background,
        },
    )?;
    for warning in &input.warnings {
        eprintln!("note: {warning}");
    }
    for line in &input.assumed {
        println!("{line}");
    }
    let truth = match &args.truth {
        Some(p) => {
            let (truth, note) = input.truth(p)?;
            note.iter().for_each(|n| eprintln!("note: {n}"));
            Some(truth)
        }
        None => None,
    };
    let opts = args.recon.options()?;
    let denoiser = args.recon.prior.build()?;
    let bar = progress(None);
    let mut result = run_method(
        &input.problem,
        args.method,
        args.bin,
        denoiser.as_ref(),
        &opts,
        truth.as_ref().map(|t| t.view()),
        |row| {
            let score = row
                .psnr
                .map_or(String::new(), |p| format!(", PSNR {p:.2} dB"));
            bar.set_message(format!(
                "{} iteration {}{score}",
                args.method.name(),
                row.iteration
            ));
            bar.tick();
        },
    )?;
    bar.finish_and_clear();
    // The record says what the reconstruction assumed (printed above).
    let printed = input.assumed.len();
    result.trace.notes.splice(0..0, input.assumed);
    result.write(&args.out)?;
    let mut tiff = "";
    if args.ome_tiff {
        result.write_ome_tiff(&args.out, &input.stack)?;
        tiff = ", reconstruction.ome.tif";
    }
    for line in result.summary(printed, truth.as_ref().map(|t| t.view())) {
        println!("{line}");
    }
    let out = args.out.display();
    println!("wrote {out}/{{reconstruction.exr, reconstruction.png{tiff}, trace.csv, trace.json}}");
    crate::signals::warned(result.warnings())
}
