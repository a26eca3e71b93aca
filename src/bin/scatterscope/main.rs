//! The `scatterscope` command-line tool.

mod acquire;
mod physics_summary;
mod psf;
mod recon_args;
mod reconstruct;
mod report;
mod simulate;
mod tags_cmd;

use clap::{Parser, Subcommand};

/// Time-resolved imaging through scattering media.
///
/// Light from an object behind a scattering slab (tissue, fog) reaches a
/// time-resolving sensor spread in space and time. scatterscope models that
/// blur with the diffusion approximation (the ST-PSF), simulates photon-count
/// stacks, writes them as OpenEXR/.npy with PNG previews, and reconstructs the
/// object with Poisson Plug-and-Play ADMM or Richardson-Lucy.
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
    Reconstruct(reconstruct::ReconstructArgs),
    Report(report::ReportArgs),
    Info(tags_cmd::InfoArgs),
    Bin(tags_cmd::BinArgs),
    Acquire(acquire::AcquireArgs),
    Devices(acquire::DevicesArgs),
}

fn main() -> anyhow::Result<()> {
    match Cli::parse().command {
        Command::Psf(args) => psf::run(&args),
        Command::Simulate(args) => simulate::run(&args),
        Command::Reconstruct(args) => reconstruct::run(&args),
        Command::Report(args) => report::run(&args),
        Command::Info(args) => tags_cmd::info(&args),
        Command::Bin(args) => tags_cmd::bin(&args),
        Command::Acquire(args) => acquire::run(&args),
        Command::Devices(args) => acquire::devices(&args),
    }
}
