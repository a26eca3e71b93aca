//! `scatterscope reconstruct`: recover the object from a stack.

use scatterscope::Named;
use std::path::PathBuf;

use crate::shared_args::{PhysicsArgs, choice};
use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use scatterscope::formats::exr;
use scatterscope::formats::png::write_png;
use scatterscope::forward::Boundary;
use scatterscope::physics::{Preset, Sampling};
use scatterscope::reconstruct::method::{Method, run_method};
use scatterscope::reconstruct::problem::{BackgroundChoice, Problem};
use scatterscope::scene::Scene;
use scatterscope::stack::{Stack, StackMeta, ValueKind, missing_meta};

use crate::calibrate_cmd::calibration_lines;
use crate::recon_args::ReconArgs;
use scatterscope::calibrate::{Free, fit_stack_physics};

/// Reconstruct the object from a transient stack (.exr or .npy).
///
/// Physics comes from the stack's metadata; flags or --config override it
/// (stacks without physics, e.g. from `bin`, need them). Writes
/// reconstruction.{exr,png} and the per-iteration trace as trace.{csv,json}.
#[derive(Debug, clap::Args)]
pub struct ReconstructArgs {
    /// The stack file.
    stack: PathBuf,
    /// Method: pnp (whole stack), pnp-sum (time-summed), pnp-slice (one
    /// bin), rl (one bin), rl-sum (time-summed), rl-stack (whole stack),
    /// scaled-counts.
    #[arg(long, value_parser = choice::<Method>(), default_value = "pnp")]
    method: Method,
    /// Bin (0-based, in stack order) for single-bin methods and raw.
    #[arg(long)]
    bin: Option<usize>,
    /// How the sensor's edges are modelled: sensor (light off the sensor is
    /// lost, light from outside its field reaches its edges; real sensors)
    /// or periodic (wrap-around) [default: the stack's record, else sensor].
    #[arg(long, value_parser = choice::<Boundary>())]
    boundary: Option<Boundary>,
    /// Truth image (PNG/JPEG/EXR) to report PSNR and SSIM against.
    #[arg(long)]
    truth: Option<PathBuf>,
    /// Background counts per pixel and bin (dark counts, ambient light) in
    /// the likelihood of every method: auto (estimated from the stack's bins
    /// before the first light, none if it has none), none, or a number.
    #[arg(long, value_parser = BackgroundChoice::parse, default_value = "auto")]
    background: BackgroundChoice,
    /// Fit these to the stack's time profile first and reconstruct with the
    /// fitted physics, comma-separated: mu_a, mu_s, t0, irf (as
    /// `calibrate --fit`); the fit is printed and kept in trace.json.
    #[arg(long, value_delimiter = ',')]
    fit_physics: Vec<String>,
    #[command(flatten)]
    recon: ReconArgs,
    #[command(flatten)]
    physics: PhysicsArgs,
    /// Output directory (created if missing).
    #[arg(long, default_value = "out/reconstruct")]
    out: PathBuf,
}

pub fn run(args: &ReconstructArgs) -> anyhow::Result<()> {
    let (data, meta) = Stack::read(&args.stack)?;
    let (mut stack, mut setup) = match meta {
        Some(meta) => {
            let stack = Stack::from_parts(data, meta, &args.stack)?;
            let setup = args.physics.resolve_over(stack.meta.setup.clone())?;
            if stack.meta.setup.is_none()
                && args.physics.preset.is_none()
                && args.physics.config.is_none()
            {
                eprintln!(
                    "note: {} records no physics; using the {} preset with your flags",
                    args.stack.display(),
                    Preset::Paper.name()
                );
            }
            (stack, setup)
        }
        None => {
            // A plain array (np.save, another tool's EXR): physics and
            // time window from the flags, the bins one after another.
            let meta = StackMeta::consecutive(
                &args.physics.resolve()?,
                data.dim().0,
                ValueKind::Counts,
                format!("{} (no metadata)", args.stack.display()),
            )
            .with_context(|| format!("the physics for {}", args.stack.display()))?;
            let setup = meta
                .setup
                .clone()
                .expect("consecutive metadata holds its physics");
            eprintln!(
                "note: {} has {}; assumed: photon counts in {} consecutive bins of {} ps from {} ps (the physics' time window and photon budget), {} x {} pixels of {} cm, physics from {}",
                args.stack.display(),
                missing_meta(&args.stack),
                setup.bins.count,
                setup.bins.width_ps,
                setup.bins.start_ps,
                setup.sensor.height_px,
                setup.sensor.width_px,
                meta.pixel_pitch_cm,
                match (&args.physics.preset, &args.physics.config) {
                    (Some(p), _) => format!("the {} preset and your flags", p.name()),
                    (None, Some(c)) => format!("{} and your flags", c.display()),
                    (None, None) => format!(
                        "the {} preset (default) and your flags",
                        Preset::Paper.name()
                    ),
                }
            );
            (Stack::from_parts(data, meta, &args.stack)?, setup)
        }
    };
    let mut assumed = Vec::new();
    if !args.fit_physics.is_empty() {
        let free = Free::from_names(&args.fit_physics).context("--fit-physics")?;
        let cal = fit_stack_physics(&mut stack, &setup, free)
            .with_context(|| format!("fitting the physics of {}", args.stack.display()))?;
        assumed.push(format!(
            "physics fitted to the stack's time profile ({})",
            args.fit_physics.join(", ")
        ));
        assumed.extend(calibration_lines(&cal));
        setup = cal.setup;
    }
    let sampling = stack.meta.sampling.unwrap_or(Sampling::Integrated);
    let boundary = args.boundary.or(stack.meta.boundary).unwrap_or_default();
    anyhow::ensure!(
        !args.method.needs_bin() || args.bin.is_some(),
        "method {} needs --bin K",
        args.method.name()
    );
    let problem = Problem::new(&stack, &setup, sampling, boundary)
        .with_context(|| format!("matching {} with its physics", args.stack.display()))?;
    let (problem, background) = problem
        .with_background(args.background)
        .with_context(|| format!("the background of {}", args.stack.display()))?;
    assumed.push(format!("model: {}", setup.model_summary()));
    assumed.push(format!("background: {background}"));
    for line in &assumed {
        println!("{line}");
    }
    if !problem.left_out.is_empty() {
        let counts: f64 = problem.left_out.iter().map(|(_, c)| c).sum();
        println!(
            "left out {} bins ({} ps to {} ps) where the ST-PSF puts no light; they held {counts} counts",
            problem.left_out.len(),
            problem.left_out[0].0,
            problem.left_out[problem.left_out.len() - 1].0 + stack.meta.bin_width_ps
        );
    }
    let (_, h, w) = stack.data.dim();
    let truth = match &args.truth {
        Some(p) => Some(Scene::File(p.clone()).render(h, w)?),
        None => None,
    };
    let opts = args.recon.options()?;
    let denoiser = args.recon.prior.denoiser()?;
    let bar = ProgressBar::new_spinner();
    bar.set_style(ProgressStyle::with_template("{spinner} {elapsed} {msg}").expect("template"));
    let mut result = run_method(
        &problem,
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
    let printed = assumed.len();
    result.trace.notes.splice(0..0, assumed);
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating output directory {}", args.out.display()))?;
    let image = &result.image;
    exr::write_image(
        image.mapv(|v| v as f32).view(),
        &args.out.join("reconstruction.exr"),
    )?;
    let top = image.iter().fold(1.0f64, |m, &v| m.max(v));
    write_png(
        image.view(),
        Some(top),
        &args.out.join("reconstruction.png"),
    )?;
    result
        .trace
        .write(&args.out, "trace")
        .with_context(|| format!("writing the trace to {}", args.out.display()))?;
    let last = result.trace.rows.last();
    println!(
        "{}{}: {} iterations in {:.2} s",
        args.method.name(),
        result
            .trace
            .prior
            .as_ref()
            .map_or(String::new(), |p| format!(" with prior {p}")),
        last.map_or(0, |r| r.iteration),
        last.map_or(0.0, |r| r.wall_s)
    );
    for note in result.trace.notes.iter().skip(printed) {
        println!("  {note}");
    }
    if let (Some(t), Some(best)) = (&truth, result.trace.best_psnr()) {
        println!(
            "  output PSNR {:.2} dB, SSIM {:.4}; best iteration by truth: {} ({:.2} dB)",
            scatterscope::metrics::psnr(image.view(), t.view()),
            scatterscope::metrics::ssim(image.view(), t.view()),
            best.iteration,
            best.psnr.unwrap_or(f64::NAN)
        );
    }
    println!(
        "wrote {}/{{reconstruction.exr, reconstruction.png, trace.csv, trace.json}}",
        args.out.display()
    );
    Ok(())
}
