//! `scatterscope denoise`: one denoiser on one image, to try a prior alone.

use std::path::PathBuf;
use std::time::Instant;

use scatterscope::config::parse_noise_sigma;
use scatterscope::denoise::benchmark::add_noise;
use scatterscope::denoise::denoise_image;
use scatterscope::formats::image::{read_image, write_image};
use scatterscope::metrics::{psnr, ssim};

use scatterscope::denoise::prior::PriorSpec;

/// Denoise one image with a Plug-and-Play prior.
///
/// INPUT and --out are PNG/JPEG (gray levels in [0, 1]), EXR or 2-D .npy;
/// --sigma is on the [0, 1] scale (e.g. 25/255). With --add-noise the input
/// is clean, noise is added (seeded) and PSNR/SSIM are printed.
#[derive(Debug, clap::Args)]
pub struct DenoiseArgs {
    /// Image to denoise.
    input: PathBuf,
    /// Noise standard deviation on the image's scale (a number or a
    /// fraction such as 25/255).
    #[arg(long, value_parser = parse_noise_sigma)]
    sigma: f64,
    #[command(flatten)]
    prior: PriorSpec,
    /// Treat INPUT as clean: add noise of --sigma with this seed first and
    /// report PSNR/SSIM against INPUT (data range 1).
    #[arg(long, value_name = "SEED")]
    add_noise: Option<u64>,
    /// Output image (.png, .exr or .npy).
    #[arg(long)]
    out: PathBuf,
}

pub fn run(args: &DenoiseArgs) -> anyhow::Result<()> {
    let denoiser = args.prior.build()?;
    let clean = read_image(&args.input)?;
    let noisy = match args.add_noise {
        Some(seed) => add_noise(&clean, args.sigma, seed),
        None => clean.clone(),
    };
    let t = Instant::now();
    let (out, note) = denoise_image(denoiser.as_ref(), noisy.view(), args.sigma)?;
    let secs = t.elapsed().as_secs_f64();
    if let Some(note) = note {
        println!("note: {note}");
    }
    let (h, w) = out.dim();
    println!(
        "{} on {w}x{h} at sigma {:.5}: {:.1} ms",
        denoiser.name(),
        args.sigma,
        secs * 1e3
    );
    if args.add_noise.is_some() {
        for (name, img) in [("noisy:   ", &noisy), ("denoised:", &out)] {
            println!(
                "{name} PSNR {:.2} dB, SSIM {:.4}",
                psnr(img.view(), clean.view()),
                ssim(img.view(), clean.view())
            );
        }
    }
    write_image(out.view(), &args.out)?;
    println!("wrote {}", args.out.display());
    Ok(())
}
