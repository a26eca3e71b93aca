//! `scatterscope embedded` and `scatterscope simulate-embedded`: an object
//! inside the medium, lit through it and imaged by a SPAD camera.

use std::path::PathBuf;

use scatterscope::embedded::request::{EmbeddedRequest, SimulateEmbeddedRequest};

/// Reconstruct an object inside a scattering medium from a SPAD camera's
/// cube: the beam crosses the front slab, lights the object (a thin mask),
/// and its light crosses the back slab to the imaged face.
///
/// Reads the cube as labs keep it (MATLAB level 5 or v7.3, .npy; any axis
/// order, type and sign), measures its noise and picks the likelihood that
/// fits it, leaves filtered, hot and dead pixels out, fits the time zero
/// (and with --fit-scattering the scattering) to the cube's own time
/// profile, and reconstructs the object's transmission with the beam
/// divided out. Writes OUT/transmission.{npy,png}, OUT/beam.npy,
/// OUT/used_pixels.npy, OUT/held_out.csv and OUT/report.json; prints every
/// choice with its figures.
#[derive(Debug, clap::Args)]
pub struct EmbeddedArgs {
    #[command(flatten)]
    request: EmbeddedRequest,
    /// Output directory (created if missing).
    #[arg(long, default_value = "out/embedded")]
    out: PathBuf,
}

pub fn run(args: &EmbeddedArgs) -> anyhow::Result<()> {
    let done = args.request.run(&args.out).map_err(anyhow::Error::msg)?;
    let notes = &done.outcome.report.notes;
    for note in notes {
        println!("{note}");
    }
    let names: Vec<String> = done.files.iter().map(|p| p.display().to_string()).collect();
    println!("wrote {}", names.join(", "));
    crate::signals::warned(done.outcome.report.warnings())
}

/// Simulate a SPAD camera's cube of an object inside the medium, written
/// as a lab publishes one: OUT/cube.mat (MATLAB level 5, rows x columns x
/// bins, background subtracted), OUT/positions.mat (pixel centres in mm)
/// and OUT/truth.npy.
#[derive(Debug, clap::Args)]
pub struct SimulateEmbeddedArgs {
    #[command(flatten)]
    request: SimulateEmbeddedRequest,
    /// Output directory (created if missing).
    #[arg(long, default_value = "out/simulate-embedded")]
    out: PathBuf,
}

pub fn simulate(args: &SimulateEmbeddedArgs) -> anyhow::Result<()> {
    let files = args.request.run(&args.out).map_err(anyhow::Error::msg)?;
    let names: Vec<String> = files.iter().map(|p| p.display().to_string()).collect();
    println!("wrote {}", names.join(", "));
    Ok(())
}
