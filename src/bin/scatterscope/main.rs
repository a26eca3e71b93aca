//! The `scatterscope` command-line tool.

mod physics_summary;
mod psf;
mod simulate;

use clap::{Parser, Subcommand};

/// Time-resolved imaging through scattering media.
///
/// Light from an object behind a scattering slab (tissue, fog) reaches a
/// time-resolving sensor spread in space and time. scatterscope models that
/// blur with the diffusion approximation (the ST-PSF), simulates photon-count
/// stacks, and writes them as OpenEXR/.npy with PNG previews.
#[derive(Debug, Parser)]
#[command(name = "scatterscope", version, about, long_about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    Psf(psf::PsfArgs),
    Simulate(simulate::SimulateArgs),
}

fn main() -> anyhow::Result<()> {
    match Cli::parse().command {
        Command::Psf(args) => psf::run(&args),
        Command::Simulate(args) => simulate::run(&args),
    }
}
