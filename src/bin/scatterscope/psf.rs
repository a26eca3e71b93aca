//! `scatterscope psf`: the ST-PSF kernel stack and its per-bin table.

use std::path::PathBuf;

use scatterscope::formats::png::SheetScale;
use scatterscope::physics::Sampling;
use scatterscope::physics::validity::describe_setup;
use scatterscope::psf::PsfReport;

use crate::shared_args::{choice, resolve};
use scatterscope::config::PhysicsOverrides;

/// Compute the ST-PSF for each time bin and write it with a per-bin table.
///
/// Writes psf.exr (centred kernels of the kept bins), psf_bins.csv and
/// psf_sheet.png, and compares the integrated and point-sampled kernels.
#[derive(Debug, clap::Args)]
pub struct PsfArgs {
    #[command(flatten)]
    physics: PhysicsOverrides,
    /// Discretisation written to psf.exr: integrated (over pixel area and
    /// bin duration) or point (samples at pixel and bin centres).
    #[arg(long, default_value = Sampling::default().name(), value_parser = choice::<Sampling>())]
    sampling: Sampling,
    /// Contact-sheet scaling.
    #[arg(long, value_parser = choice::<SheetScale>(), default_value = "per-bin")]
    sheet_scale: SheetScale,
    /// Output directory (created if missing).
    #[arg(long, default_value = "out/psf")]
    out: PathBuf,
}

pub fn run(args: &PsfArgs) -> anyhow::Result<()> {
    let setup = resolve(&args.physics)?;
    let report = PsfReport::build(&setup, args.sampling)?;
    for line in describe_setup(&setup, report.chosen()) {
        eprintln!("{line}");
    }
    for line in report.table().0.iter().chain(&report.comparison()) {
        println!("{line}");
    }
    report.write(&args.out, args.sheet_scale)?;
    println!(
        "wrote {}/{{psf.exr, psf_bins.csv, psf_sheet.png}}",
        args.out.display()
    );
    Ok(())
}
