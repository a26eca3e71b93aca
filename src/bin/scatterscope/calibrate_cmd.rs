//! `scatterscope calibrate`: the medium's and the instrument's parameters
//! from a measured stack's time profile.

use std::path::PathBuf;

use anyhow::Context;
use scatterscope::calibrate::Free;
use scatterscope::report::calibration::calibrate_file;

use scatterscope::config::PhysicsOverrides;

/// Fit mu_a, mu_s' and, optionally, time zero and the IRF width to a stack.
///
/// Poisson maximum likelihood on the stack's time profile, signal and
/// background always fitted; writes OUT/profile.{csv,png} and
/// OUT/physics.toml (the fitted medium and IRF, for --config).
#[derive(Debug, clap::Args)]
pub struct CalibrateArgs {
    /// The stack (.exr or .npy with metadata; its physics is the start).
    stack: PathBuf,
    /// What to fit, comma-separated: mu_a, mu_s_reduced (the reduced
    /// scattering coefficient mu_s'; `mu_s`, its old name, still works), t0
    /// (time zero) and irf (the IRF's FWHM).
    #[arg(long, value_delimiter = ',', default_value = "mu_a,mu_s_reduced")]
    fit: Vec<String>,
    #[command(flatten)]
    physics: PhysicsOverrides,
    /// Output directory (created if missing).
    #[arg(long, default_value = "out/calibrate")]
    out: PathBuf,
}

pub fn run(args: &CalibrateArgs) -> anyhow::Result<()> {
    crate::shared_args::note_renamed_parameters("--fit", &args.fit);
    let free = Free::from_names(&args.fit).context("--fit")?;
    let done = calibrate_file(&args.stack, &args.physics, free)?;
    println!("model: {}", done.start.model_summary());
    for line in done.fit.lines() {
        println!("{line}");
    }
    done.write(&args.out, &args.stack)?;
    println!(
        "wrote {}/{{profile.csv, profile.png, physics.toml}}",
        args.out.display()
    );
    Ok(())
}
