//! The denoising benchmark: priors on clean images with added white
//! Gaussian noise of known sigma, scored by PSNR/SSIM (data range 1) and
//! timed per call.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use ndarray::Array2;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

use super::Denoiser;
use super::ffdnet::weights::WeightsError;
use super::ffdnet::{Ffdnet, source};
use super::tv::TotalVariation;
use crate::formats::detect::Format;
use crate::formats::image::{ImageError, read_image, write_image};
use crate::metrics::{psnr, ssim};

/// One clean test image on the [0, 1] scale.
#[derive(Debug, Clone)]
pub struct BenchImage {
    /// Name for the tables (file stem).
    pub name: String,
    /// The clean image.
    pub clean: Array2<f64>,
}

/// A prior under test. `oracle` priors pick among several settings with
/// the clean image (an upper bound, labelled as such).
pub struct BenchPrior<'a> {
    /// Row label.
    pub label: String,
    /// Candidate settings; more than one makes this an oracle choice.
    pub candidates: Vec<&'a dyn Denoiser>,
}

/// One (prior, image, sigma) measurement.
#[derive(Debug, Clone)]
pub struct BenchResult {
    /// Prior label.
    pub prior: String,
    /// Image name.
    pub image: String,
    /// Noise sigma in 8-bit units.
    pub sigma_8bit: f64,
    /// PSNR of the noisy input (dB).
    pub psnr_noisy: f64,
    /// PSNR of the denoised image (dB).
    pub psnr: f64,
    /// SSIM of the denoised image.
    pub ssim: f64,
    /// Wall time of the chosen setting's call (s).
    pub seconds: f64,
}

impl BenchResult {
    /// The measurement as one printed line.
    pub fn line(&self) -> String {
        format!(
            "  {:<10} sigma {:>4}: {:<28} {:6.2} dB (noisy {:5.2}), {:7.1} ms",
            self.image,
            self.sigma_8bit,
            self.prior,
            self.psnr,
            self.psnr_noisy,
            self.seconds * 1e3
        )
    }
}

/// A noise level in 8-bit units, in (0, 255].
pub fn parse_sigma_8bit(text: &str) -> Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(s) if s > 0.0 && s <= 255.0 => Ok(s),
        _ => Err(format!(
            "{text:?} is not a noise level in (0, 255] (8-bit units)"
        )),
    }
}

/// The noise seed of image `index` at `sigma_8bit`: every prior sees the
/// same noise.
pub fn noise_seed(seed: u64, index: usize, sigma_8bit: f64) -> u64 {
    seed ^ ((index as u64) << 32) ^ sigma_8bit.to_bits()
}

/// `clean` plus white Gaussian noise of `sigma` (on the [0, 1] scale).
pub fn add_noise(clean: &Array2<f64>, sigma: f64, seed: u64) -> Array2<f64> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let noise = Normal::new(0.0, sigma).expect("sigma is finite and not negative");
    clean.mapv(|v| v + noise.sample(&mut rng))
}

/// Runs every prior on every image at every sigma (8-bit units); calls
/// `progress` after each measurement.
pub fn run(
    images: &[BenchImage],
    sigmas_8bit: &[f64],
    priors: &[BenchPrior<'_>],
    seed: u64,
    mut progress: impl FnMut(&BenchResult),
) -> Vec<BenchResult> {
    let mut out = Vec::new();
    for (i, img) in images.iter().enumerate() {
        for &s8 in sigmas_8bit {
            let sigma = s8 / 255.0;
            let noisy = add_noise(&img.clean, sigma, noise_seed(seed, i, s8));
            let psnr_noisy = psnr(noisy.view(), img.clean.view());
            for prior in priors {
                let mut best: Option<BenchResult> = None;
                for d in &prior.candidates {
                    let t = Instant::now();
                    let den = d.denoise_unit(noisy.view(), sigma);
                    let seconds = t.elapsed().as_secs_f64();
                    let p = psnr(den.view(), img.clean.view());
                    if best.as_ref().is_none_or(|b| p > b.psnr) {
                        best = Some(BenchResult {
                            prior: prior.label.clone(),
                            image: img.name.clone(),
                            sigma_8bit: s8,
                            psnr_noisy,
                            psnr: p,
                            ssim: ssim(den.view(), img.clean.view()),
                            seconds,
                        });
                    }
                }
                if let Some(b) = best {
                    progress(&b);
                    out.push(b);
                }
            }
        }
    }
    out
}

/// Mean PSNR, mean SSIM and median seconds per (prior, sigma), in the order
/// the priors and sigmas first appear.
pub fn summarise(results: &[BenchResult]) -> Vec<(String, f64, f64, f64, f64)> {
    let mut keys: Vec<(String, u64)> = Vec::new();
    for r in results {
        let k = (r.prior.clone(), r.sigma_8bit.to_bits());
        if !keys.contains(&k) {
            keys.push(k);
        }
    }
    keys.into_iter()
        .map(|(prior, s)| {
            let rows: Vec<&BenchResult> = results
                .iter()
                .filter(|r| r.prior == prior && r.sigma_8bit.to_bits() == s)
                .collect();
            let n = rows.len() as f64;
            let mut secs: Vec<f64> = rows.iter().map(|r| r.seconds).collect();
            secs.sort_by(f64::total_cmp);
            (
                prior,
                f64::from_bits(s),
                rows.iter().map(|r| r.psnr).sum::<f64>() / n,
                rows.iter().map(|r| r.ssim).sum::<f64>() / n,
                secs[secs.len() / 2],
            )
        })
        .collect()
}

/// The clean images at `paths`: files, or directories whose PNG and JPEG
/// files are taken in name order.
pub fn collect_images(paths: &[PathBuf]) -> Result<Vec<BenchImage>, ImageError> {
    let mut files = Vec::new();
    for p in paths {
        if !p.is_dir() {
            files.push(p.clone());
            continue;
        }
        let listing = std::fs::read_dir(p).map_err(|e| ImageError::Decode {
            path: p.clone(),
            reason: e.to_string(),
        })?;
        let mut inner: Vec<PathBuf> = listing
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|f| matches!(Format::of_file(f), Format::Png | Format::Jpeg))
            .collect();
        if inner.is_empty() {
            return Err(ImageError::Content {
                path: p.clone(),
                reason: "no PNG/JPEG images".into(),
            });
        }
        inner.sort();
        files.extend(inner);
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

/// The priors the benchmark compares: FFDNet with each of `nets`, TV at
/// the gain PnP uses, and TV with the best of several gains chosen with
/// the clean image (an oracle, labelled so).
pub struct StandardPriors {
    nets: Vec<(String, Ffdnet)>,
    tv: TotalVariation,
    tv_gains: Vec<TotalVariation>,
}

impl StandardPriors {
    /// The standard set with the embedded FFDNet weights, the imported ones
    /// if there are any, and `extra` if given.
    pub fn with_weights(extra: Option<&Path>) -> Result<Self, WeightsError> {
        let mut nets = vec![(
            "ffdnet embedded".to_string(),
            Ffdnet::new(source::embedded(), "embedded"),
        )];
        if let Some(p) = source::imported_path().filter(|p| p.is_file()) {
            nets.push(("ffdnet imported".into(), Ffdnet::from_file(&p, "imported")?));
        }
        if let Some(p) = extra {
            let label = p.display().to_string();
            nets.push((format!("ffdnet {label}"), Ffdnet::from_file(p, label)?));
        }
        Ok(Self::new(nets))
    }

    /// The standard set with these FFDNet weights, each with its label.
    pub fn new(nets: Vec<(String, Ffdnet)>) -> Self {
        Self {
            nets,
            tv: TotalVariation::default(),
            tv_gains: [0.2, 0.3, 0.4, 0.5, 0.7, 1.0, 1.4]
                .into_iter()
                .map(|gain| TotalVariation {
                    gain,
                    ..Default::default()
                })
                .collect(),
        }
    }

    /// The priors, in table order.
    pub fn priors(&self) -> Vec<BenchPrior<'_>> {
        let mut priors: Vec<BenchPrior<'_>> = self
            .nets
            .iter()
            .map(|(label, n)| BenchPrior {
                label: label.clone(),
                candidates: vec![n as &dyn Denoiser],
            })
            .collect();
        priors.push(BenchPrior {
            label: format!("tv gain {}", self.tv.gain),
            candidates: vec![&self.tv],
        });
        priors.push(BenchPrior {
            label: "tv oracle gain".into(),
            candidates: self.tv_gains.iter().map(|t| t as &dyn Denoiser).collect(),
        });
        priors
    }
}

/// Writes each image's noisy input at each sigma (8-bit units) as
/// `dir/IMAGE_sigmaS.npy` (float32), the noise every prior sees, so that
/// another implementation can be scored on identical noise.
pub fn write_noisy(
    dir: &Path,
    images: &[BenchImage],
    sigmas_8bit: &[f64],
    seed: u64,
) -> Result<(), ImageError> {
    std::fs::create_dir_all(dir).map_err(|e| ImageError::Write {
        path: dir.to_path_buf(),
        reason: e.to_string(),
    })?;
    for (i, img) in images.iter().enumerate() {
        for &s in sigmas_8bit {
            let noisy = add_noise(&img.clean, s / 255.0, noise_seed(seed, i, s));
            write_image(
                noisy.view(),
                &dir.join(format!("{}_sigma{s}.npy", img.name)),
            )?;
        }
    }
    Ok(())
}

/// Writes `out/results.csv` and `out/summary.md` (each whole or not at
/// all); returns the summary.
pub fn write_results(
    out: &Path,
    images: &[BenchImage],
    results: &[BenchResult],
) -> std::io::Result<String> {
    crate::files::write_atomic(out.join("results.csv"), results_csv(results))?;
    let md = summary_markdown(images, results);
    crate::files::write_atomic(out.join("summary.md"), &md)?;
    Ok(md)
}

/// Every measurement as CSV.
pub fn results_csv(results: &[BenchResult]) -> String {
    let mut csv = String::from("prior,image,sigma_8bit,psnr_noisy_db,psnr_db,ssim,seconds\n");
    for r in results {
        writeln!(
            csv,
            "{},{},{},{:.4},{:.4},{:.5},{:.6}",
            r.prior, r.image, r.sigma_8bit, r.psnr_noisy, r.psnr, r.ssim, r.seconds
        )
        .expect("writing to a String");
    }
    csv
}

/// The summary table (mean PSNR and SSIM, median time per call) as
/// Markdown.
pub fn summary_markdown(images: &[BenchImage], results: &[BenchResult]) -> String {
    let mut md = format!(
        "Images: {}. Mean PSNR (data range 1) / mean SSIM, median time per call.\n\n| prior | sigma | PSNR (dB) | SSIM | time (ms) |\n|---|---|---|---|---|\n",
        images
            .iter()
            .map(|i| i.name.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    );
    for (prior, s, p, ss, t) in summarise(results) {
        writeln!(md, "| {prior} | {s} | {p:.2} | {ss:.4} | {:.1} |", t * 1e3)
            .expect("writing to a String");
    }
    md
}
