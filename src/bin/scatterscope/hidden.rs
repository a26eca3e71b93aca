//! `scatterscope hidden`: a hidden object's volume from a confocal scan of
//! a scattering slab's near face.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use scatterscope::confocal::scan::DEFAULT_MAT_DATASET;
use scatterscope::confocal::{
    ConfocalScan, HiddenMethod, HiddenResult, PoissonOptions, PublishedOptions, SlabOptics,
    hidden_warnings,
};
use scatterscope::report::hidden::write_hidden;
use scatterscope::units::parse_positive_m;

use crate::shared_args::{FileBinWidthArgs, choice};

/// Reconstruct what hides behind a slab from a confocal scan of its face.
///
/// The scan: a MATLAB v7.3 file of counts (column, row, time; the
/// confocal diffuse tomography scans) or a project stack whose pixels are
/// scan points (e.g. a galvo-scanned PTU binned with `bin`). The methods:
/// `auto` (the default), the published method followed by a 3-D Gaussian
/// blur whose width two thinned halves of the scan choose without the
/// truth; `published`, Wiener deconvolution of the slab's in-and-out
/// diffusion kernel then f-k migration (Lindell and Wetzstein 2020),
/// sharpest at full counts and noisy at low light; `poisson`, the
/// slab's blur undone by maximum likelihood of the counts (with a
/// background per bin, stopped by cross-validation on thinned halves),
/// then f-k migration. Writes OUT/volume.{npy,json,exr}, OUT/depth.{npy,png},
/// OUT/mip_{front,top,side}.png and, for `poisson`, OUT/trace.csv.
#[derive(Debug, clap::Args)]
pub struct HiddenArgs {
    /// The scan (.mat, .exr or .npy).
    scan: PathBuf,
    /// Side of the scanned square on the slab's face, first to last
    /// point, with its unit (e.g. 0.7m, 63.6cm).
    #[arg(long, value_name = "LENGTH")]
    scan_side: String,
    /// Slab thickness with its unit (e.g. 1in, 2.54cm).
    #[arg(long, value_name = "LENGTH")]
    slab_thickness: String,
    /// The slab's material: a material file (e.g. calibrate-slab's
    /// OUT/material.toml: mu_a, mu_s, g, n). Without it the published foam
    /// fit is assumed (n 1.12, mu_a 0.53 /m, mu_s' 262 /m, z_e 3.6 mm).
    #[arg(long, value_name = "FILE")]
    material: Option<PathBuf>,
    #[command(flatten)]
    bin_width: FileBinWidthArgs,
    /// Dataset holding the counts in MATLAB files.
    #[arg(long, default_value = DEFAULT_MAT_DATASET)]
    dataset: String,
    /// Reconstruction method: auto (published, smoothed as the scan's own
    /// noise asks), published, or poisson (slower, and on the shared scans
    /// below auto at every light level; see the guide).
    #[arg(long, value_parser = choice::<HiddenMethod>(), default_value = "auto")]
    method: HiddenMethod,
    /// Wiener constant of the published method (the authors used 2.5e3
    /// to 2e4 per scene).
    #[arg(long, default_value_t = PublishedOptions::default().snr)]
    snr: f64,
    /// Keep only this fraction of the photons (binomial thinning, seeded
    /// by --thin-seed): what a shorter exposure of the same scene gives.
    #[arg(long, value_name = "FRACTION")]
    thin: Option<f64>,
    /// Seed of --thin.
    #[arg(long, default_value_t = 1, requires = "thin")]
    thin_seed: u64,
    /// Depth behind the slab to reconstruct, with its unit.
    #[arg(long, value_name = "LENGTH", default_value = "1m")]
    depth: String,
    /// Output directory (created if missing).
    #[arg(long, default_value = "out/hidden")]
    out: PathBuf,
}

pub fn run(args: &HiddenArgs) -> anyhow::Result<()> {
    let side_m = parse_positive_m(&args.scan_side)
        .map_err(anyhow::Error::msg)
        .context("--scan-side")?;
    let thickness_m = parse_positive_m(&args.slab_thickness)
        .map_err(anyhow::Error::msg)
        .context("--slab-thickness")?;
    let depth_m = parse_positive_m(&args.depth)
        .map_err(anyhow::Error::msg)
        .context("--depth")?;
    let bin_width = args.bin_width.bin_width;
    let mut scan = ConfocalScan::open(&args.scan, &args.dataset, bin_width, side_m)?;
    if let Some(fraction) = args.thin.filter(|&f| f != 1.0) {
        scan = scan.thinned(fraction, args.thin_seed).context("--thin")?;
    }
    let material = args.material.as_deref();
    let optics = SlabOptics::for_slab(material, thickness_m)?;
    let published = PublishedOptions {
        snr: args.snr,
        depth_m,
        ..PublishedOptions::default()
    };
    let poisson = PoissonOptions {
        depth_m,
        ..PoissonOptions::default()
    };
    println!("scan: {}", scan.describe());
    match material {
        Some(path) => println!("material: {} ({})", path.display(), optics.describe()),
        None => println!(
            "material: the published foam fit ({}); assumed, not measured here (--material)",
            optics.describe()
        ),
    }
    let started = Instant::now();
    let method = args.method.reconstructor(&published, &poisson);
    let HiddenResult { volume, trace, .. } = method.reconstruct(&scan, &optics)?;
    let wall_s = started.elapsed().as_secs_f64();
    for note in &volume.notes {
        println!("{note}");
    }
    if let Some(line) = volume.describe_object_depth() {
        println!("{line}");
    }
    println!("reconstructed in {wall_s:.3} s");
    let warnings = hidden_warnings(&scan, &volume, depth_m);
    for w in &warnings {
        println!("warning: {w}");
    }
    let written = write_hidden(&volume, trace.as_deref(), &args.out)?;
    println!(
        "wrote {}",
        written
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
    crate::signals::warned(warnings.len())
}
