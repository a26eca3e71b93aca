//! `scatterscope denoise`: one denoiser on one image, to try a prior alone.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use ndarray::Array2;
use ndarray_npy::{ReadNpyExt, WriteNpyExt};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use scatterscope::formats::exr;
use scatterscope::formats::image::read_image;
use scatterscope::formats::png::write_png;
use scatterscope::metrics::{psnr, ssim};

use crate::recon_args::PriorArgs;

/// Denoise one image with a Plug-and-Play prior.
///
/// INPUT and --out are PNG/JPEG (gray levels on a [0, 1] scale), EXR
/// (luminance, values as stored) or 2-D .npy (float32/float64). The image
/// is handed to the denoiser as it is, taken to be on a [0, 1] scale, and
/// --sigma is the noise standard deviation on that scale (e.g. 25/255 for
/// sigma 25 of an 8-bit image). Sigma above the prior's trained range is
/// clamped, and the output says so. With --add-noise the input is taken as
/// clean, white Gaussian noise of --sigma is added first (seeded), and the
/// PSNR/SSIM of the noisy and the denoised image against it are printed.
#[derive(Debug, clap::Args)]
pub struct DenoiseArgs {
    /// Image to denoise.
    input: PathBuf,
    /// Noise standard deviation on the image's scale (a number or a
    /// fraction such as 25/255).
    #[arg(long, value_parser = parse_sigma)]
    sigma: f64,
    #[command(flatten)]
    prior: PriorArgs,
    /// Treat INPUT as clean: add noise of --sigma with this seed first and
    /// report PSNR/SSIM against INPUT (data range 1).
    #[arg(long, value_name = "SEED")]
    add_noise: Option<u64>,
    /// Output image (.png, .exr or .npy).
    #[arg(long)]
    out: PathBuf,
}

fn parse_sigma(s: &str) -> Result<f64, String> {
    let v = match s.split_once('/') {
        Some((a, b)) => {
            let a: f64 = a
                .trim()
                .parse()
                .map_err(|_| format!("`{s}`: `{a}` is not a number"))?;
            let b: f64 = b
                .trim()
                .parse()
                .map_err(|_| format!("`{s}`: `{b}` is not a number"))?;
            a / b
        }
        None => s
            .trim()
            .parse()
            .map_err(|_| format!("`{s}` is not a number or a fraction"))?,
    };
    if v >= 0.0 && v.is_finite() {
        Ok(v)
    } else {
        Err(format!("`{s}`: sigma must be finite and not negative"))
    }
}

fn extension(path: &Path) -> String {
    path.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default()
}

fn load(path: &Path) -> anyhow::Result<Array2<f64>> {
    if extension(path) != "npy" {
        return Ok(read_image(path)?);
    }
    let open = || std::fs::File::open(path).with_context(|| format!("opening {}", path.display()));
    let img = match Array2::<f32>::read_npy(open()?) {
        Ok(a) => a.mapv(f64::from),
        Err(_) => Array2::<f64>::read_npy(open()?).with_context(|| {
            format!(
                "{}: expected a 2-D float32 or float64 .npy array",
                path.display()
            )
        })?,
    };
    if let Some(((r, c), v)) = img.indexed_iter().find(|(_, v)| !v.is_finite()) {
        anyhow::bail!(
            "{}: pixel (row {r}, column {c}) is {v}; images must be finite",
            path.display()
        );
    }
    Ok(img)
}

fn save(img: &Array2<f64>, path: &Path) -> anyhow::Result<()> {
    match extension(path).as_str() {
        "png" => write_png(img.mapv(|v| v.clamp(0.0, 1.0)).view(), Some(1.0), path)?,
        "exr" => exr::write_image(img.mapv(|v| v as f32).view(), path)?,
        "npy" => img
            .mapv(|v| v as f32)
            .write_npy(
                std::fs::File::create(path)
                    .with_context(|| format!("creating {}", path.display()))?,
            )
            .with_context(|| format!("writing {}", path.display()))?,
        other => anyhow::bail!(
            "--out {}: unknown extension `{other}` (use .png, .exr or .npy)",
            path.display()
        ),
    }
    Ok(())
}

pub fn run(args: &DenoiseArgs) -> anyhow::Result<()> {
    let denoiser = args.prior.denoiser()?;
    let clean = load(&args.input)?;
    anyhow::ensure!(
        !clean.is_empty(),
        "{}: the image is empty",
        args.input.display()
    );
    let noisy = match args.add_noise {
        Some(seed) => {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
            let noise = Normal::new(0.0, args.sigma).context("--sigma")?;
            clean.mapv(|v| v + noise.sample(&mut rng))
        }
        None => clean.clone(),
    };
    let t = Instant::now();
    let out = denoiser.denoise_unit(noisy.view(), args.sigma);
    let secs = t.elapsed().as_secs_f64();
    if args.sigma > denoiser.sigma_max() {
        println!(
            "note: sigma {:.5} is above the prior's trained range; clamped to {:.5}",
            args.sigma,
            denoiser.sigma_max()
        );
    }
    let (h, w) = out.dim();
    println!(
        "{} on {w}x{h} at sigma {:.5}: {:.1} ms",
        denoiser.name(),
        args.sigma,
        secs * 1e3
    );
    if args.add_noise.is_some() {
        println!(
            "noisy:    PSNR {:.2} dB, SSIM {:.4}",
            psnr(noisy.view(), clean.view()),
            ssim(noisy.view(), clean.view())
        );
        println!(
            "denoised: PSNR {:.2} dB, SSIM {:.4}",
            psnr(out.view(), clean.view()),
            ssim(out.view(), clean.view())
        );
    }
    save(&out, &args.out)?;
    println!("wrote {}", args.out.display());
    Ok(())
}
