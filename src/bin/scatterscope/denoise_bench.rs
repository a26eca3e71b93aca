//! `scatterscope denoise-bench`: every prior on clean images with added
//! noise, PSNR/SSIM and time per call.

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::Context;
use ndarray_npy::WriteNpyExt;
use scatterscope::denoise::Denoiser;
use scatterscope::denoise::benchmark::{self, BenchImage, BenchPrior};
use scatterscope::denoise::ffdnet::{Ffdnet, source};
use scatterscope::denoise::tv::TotalVariation;
use scatterscope::formats::image::read_image;

/// Denoising benchmark: PSNR and time of each prior at several noise levels.
///
/// Adds seeded white Gaussian noise of each --sigmas level (8-bit units) to
/// every clean image and runs: FFDNet with the embedded weights, FFDNet
/// with imported weights (data directory) and with --weights if given, TV
/// at the gain PnP uses, and TV with the best of several gains chosen with
/// the clean image (an oracle, labelled so). Writes results.csv (every
/// measurement) and summary.md (mean PSNR/SSIM, median time) to --out.
/// `python3 training/export_eval_images.py DIR` writes the five natural
/// test images used in BENCHMARKS.md.
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

fn collect_images(paths: &[PathBuf]) -> anyhow::Result<Vec<BenchImage>> {
    let mut files = Vec::new();
    for p in paths {
        if p.is_dir() {
            let mut inner: Vec<PathBuf> = std::fs::read_dir(p)
                .with_context(|| format!("reading {}", p.display()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|f| {
                    let ext = f
                        .extension()
                        .map(|e| e.to_string_lossy().to_ascii_lowercase());
                    matches!(ext.as_deref(), Some("png" | "jpg" | "jpeg"))
                })
                .collect();
            inner.sort();
            anyhow::ensure!(!inner.is_empty(), "{}: no PNG/JPEG images", p.display());
            files.extend(inner);
        } else {
            files.push(p.clone());
        }
    }
    files
        .iter()
        .map(|f| {
            Ok(BenchImage {
                name: f
                    .file_stem()
                    .map_or_else(String::new, |s| s.to_string_lossy().into_owned()),
                clean: read_image(f)?,
            })
        })
        .collect()
}

pub fn run(args: &DenoiseBenchArgs) -> anyhow::Result<()> {
    for &s in &args.sigmas {
        anyhow::ensure!(s > 0.0 && s <= 255.0, "--sigmas: {s} is not in (0, 255]");
    }
    let images = collect_images(&args.images)?;
    let mut nets: Vec<(String, Ffdnet)> = vec![(
        "ffdnet embedded".into(),
        Ffdnet::new(source::embedded(), "embedded"),
    )];
    if let Some(p) = source::imported_path().filter(|p| p.is_file()) {
        nets.push(("ffdnet imported".into(), Ffdnet::from_file(&p, "imported")?));
    }
    if let Some(p) = &args.weights {
        nets.push((
            format!("ffdnet {}", p.display()),
            Ffdnet::from_file(p, p.display().to_string())?,
        ));
    }
    let tv = TotalVariation::default();
    let tv_gains: Vec<TotalVariation> = [0.2, 0.3, 0.4, 0.5, 0.7, 1.0, 1.4]
        .into_iter()
        .map(|gain| TotalVariation {
            gain,
            ..Default::default()
        })
        .collect();
    let mut priors: Vec<BenchPrior<'_>> = nets
        .iter()
        .map(|(label, n)| BenchPrior {
            label: label.clone(),
            candidates: vec![n as &dyn Denoiser],
        })
        .collect();
    priors.push(BenchPrior {
        label: format!("tv gain {}", tv.gain),
        candidates: vec![&tv],
    });
    priors.push(BenchPrior {
        label: "tv oracle gain".into(),
        candidates: tv_gains.iter().map(|t| t as &dyn Denoiser).collect(),
    });
    println!(
        "{} image(s) x {} sigma(s) x {} prior(s)",
        images.len(),
        args.sigmas.len(),
        priors.len()
    );
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    if args.save_noisy {
        let dir = args.out.join("noisy");
        std::fs::create_dir_all(&dir)?;
        for (i, img) in images.iter().enumerate() {
            for &s in &args.sigmas {
                let noisy = benchmark::add_noise(
                    &img.clean,
                    s / 255.0,
                    benchmark::noise_seed(args.seed, i, s),
                );
                let f = dir.join(format!("{}_sigma{s}.npy", img.name));
                noisy.mapv(|v| v as f32).write_npy(
                    std::fs::File::create(&f)
                        .with_context(|| format!("creating {}", f.display()))?,
                )?;
            }
        }
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
    let mut csv = String::from("prior,image,sigma_8bit,psnr_noisy_db,psnr_db,ssim,seconds\n");
    for r in &results {
        writeln!(
            csv,
            "{},{},{},{:.4},{:.4},{:.5},{:.6}",
            r.prior, r.image, r.sigma_8bit, r.psnr_noisy, r.psnr, r.ssim, r.seconds
        )?;
    }
    std::fs::write(args.out.join("results.csv"), csv)?;
    let mut md = format!(
        "Images: {}. Mean PSNR (data range 1) / mean SSIM, median time per call.\n\n| prior | sigma | PSNR (dB) | SSIM | time (ms) |\n|---|---|---|---|---|\n",
        images
            .iter()
            .map(|i| i.name.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    );
    for (prior, s, p, ss, t) in benchmark::summarise(&results) {
        writeln!(md, "| {prior} | {s} | {p:.2} | {ss:.4} | {:.1} |", t * 1e3)?;
    }
    std::fs::write(args.out.join("summary.md"), &md)?;
    println!("\n{md}");
    println!("wrote {}", args.out.display());
    Ok(())
}
