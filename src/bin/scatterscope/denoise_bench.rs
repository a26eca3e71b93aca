//! `scatterscope denoise-bench`: every prior on clean images with added
//! noise, PSNR/SSIM and time per call.

use std::path::PathBuf;

use anyhow::Context;
use scatterscope::denoise::benchmark::{self, StandardPriors};

/// Denoising benchmark: PSNR and time of each prior at several noise levels.
///
/// Seeded white noise of each --sigmas level (8-bit units) on every clean
/// image; FFDNet (embedded, imported, --weights), TV and TV's oracle gain.
/// Writes results.csv and summary.md to --out.
#[derive(Debug, clap::Args)]
pub struct DenoiseBenchArgs {
    /// Clean images (PNG/JPEG, gray or colour, read as luminance in [0, 1])
    /// or directories of them.
    #[arg(required = true)]
    images: Vec<PathBuf>,
    /// Noise levels in 8-bit units.
    #[arg(long, value_delimiter = ',', default_value = "10,25,50")]
    sigmas: Vec<f64>,
    /// Additional FFDNet weights to compare.
    #[arg(long, value_name = "PATH")]
    weights: Option<PathBuf>,
    /// Noise seed.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Also write each noisy input as OUT/noisy/IMAGE_sigmaS.npy (float32),
    /// so another implementation can be scored on identical noise.
    #[arg(long)]
    save_noisy: bool,
    /// Output directory.
    #[arg(long, default_value = "out/denoise-bench")]
    out: PathBuf,
}

pub fn run(args: &DenoiseBenchArgs) -> anyhow::Result<()> {
    for &s in &args.sigmas {
        anyhow::ensure!(s > 0.0 && s <= 255.0, "--sigmas: {s} is not in (0, 255]");
    }
    let images = benchmark::collect_images(&args.images)?;
    let standard = StandardPriors::with_weights(args.weights.as_deref())?;
    let priors = standard.priors();
    println!(
        "{} image(s) x {} sigma(s) x {} prior(s)",
        images.len(),
        args.sigmas.len(),
        priors.len()
    );
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    if args.save_noisy {
        benchmark::write_noisy(&args.out.join("noisy"), &images, &args.sigmas, args.seed)?;
    }
    let results = benchmark::run(&images, &args.sigmas, &priors, args.seed, |r| {
        println!(
            "  {:<10} sigma {:>4}: {:<28} {:6.2} dB (noisy {:5.2}), {:7.1} ms",
            r.image,
            r.sigma_8bit,
            r.prior,
            r.psnr,
            r.psnr_noisy,
            r.seconds * 1e3
        );
    });
    scatterscope::files::write_atomic(
        args.out.join("results.csv"),
        benchmark::results_csv(&results),
    )?;
    let md = benchmark::summary_markdown(&images, &results);
    scatterscope::files::write_atomic(args.out.join("summary.md"), &md)?;
    println!("\n{md}");
    println!("wrote {}", args.out.display());
    Ok(())
}
