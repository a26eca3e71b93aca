//! `scatterscope hidden`: a hidden object's volume from a confocal scan of
//! a scattering slab's near face.

use std::path::PathBuf;

use scatterscope::report::hidden::HiddenRequest;

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
    #[command(flatten)]
    request: HiddenRequest,
    /// Output directory (created if missing).
    #[arg(long, default_value = "out/hidden")]
    out: PathBuf,
}

pub fn run(args: &HiddenArgs) -> anyhow::Result<()> {
    let done = args.request.run(&args.out, |line| println!("{line}"))?;
    for w in &done.warnings {
        println!("warning: {w}");
    }
    let names: Vec<String> = done.files.iter().map(|p| p.display().to_string()).collect();
    println!("wrote {}", names.join(", "));
    crate::signals::warned(done.warnings.len())
}
