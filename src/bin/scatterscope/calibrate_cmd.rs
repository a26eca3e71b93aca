//! `scatterscope calibrate`: the medium's and the instrument's parameters
//! from a measured stack's time profile.

use std::path::PathBuf;

use anyhow::Context;
use scatterscope::calibrate::{Free, calibrate, time_profile};
use scatterscope::stack::Stack;

use crate::shared_args::PhysicsArgs;

/// Fit mu_a, mu_s' and, optionally, time zero and the IRF width to a stack.
///
/// Poisson maximum likelihood on the stack's time profile (counts summed
/// over the sensor per bin), with the signal and a constant background per
/// bin always fitted. Prints each parameter with its standard error, the
/// chi-square per degree of freedom and the parameters the data cannot pin
/// down; writes OUT/profile.csv and OUT/profile.png (measured and fitted)
/// and OUT/physics.toml, the fitted medium and IRF for `--config`.
#[derive(Debug, clap::Args)]
pub struct CalibrateArgs {
    /// The stack (.exr or .npy with metadata; its physics is the start).
    stack: PathBuf,
    /// What to fit, comma-separated: mu_a, mu_s (the reduced scattering
    /// coefficient), t0 (time zero) and irf (the IRF's FWHM).
    #[arg(long, value_delimiter = ',', default_value = "mu_a,mu_s")]
    fit: Vec<String>,
    #[command(flatten)]
    physics: PhysicsArgs,
    /// Output directory (created if missing).
    #[arg(long, default_value = "out/calibrate")]
    out: PathBuf,
}

pub fn run(args: &CalibrateArgs) -> anyhow::Result<()> {
    let (data, meta) = Stack::read(&args.stack)?;
    let meta = meta.with_context(|| {
        format!(
            "{} records no time bins; calibration needs a stack with metadata",
            args.stack.display()
        )
    })?;
    let stack = Stack::from_parts(data, meta, &args.stack)?;
    let setup = args.physics.resolve_over(stack.meta.setup.clone())?;
    let free = Free::from_names(&args.fit).context("--fit")?;
    let (start, counts) = time_profile(&stack)?;
    let c = calibrate(&counts, start, &setup, free)
        .with_context(|| format!("calibrating {}", args.stack.display()))?;
    println!("model: {}", setup.model_summary());
    for line in c.lines() {
        println!("{line}");
    }
    c.write(&args.out, start, stack.meta.bin_width_ps, &args.stack)?;
    println!(
        "wrote {}/{{profile.csv, profile.png, physics.toml}}",
        args.out.display()
    );
    Ok(())
}
