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
    #[arg(long, value_delimiter = ',', default_value = "10,25,50", value_parser = benchmark::parse_sigma_8bit)]
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
        println!("{}", r.line())
    });
    let md = benchmark::write_results(&args.out, &images, &results)
        .with_context(|| format!("writing into {}", args.out.display()))?;
    println!("\n{md}");
    println!("wrote {}", args.out.display());
    Ok(())
}
