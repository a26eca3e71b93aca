//! `scatterscope calibrate`: the medium's and the instrument's parameters
//! from a measured stack's time profile.

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::Context;
use scatterscope::calibrate::{Calibration, Free, calibrate, time_profile};
use scatterscope::config::medium_toml;
use scatterscope::report::plot::{Series, chart};
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

/// The fit's parameters, quality and notes, one printable line each.
pub fn calibration_lines(c: &Calibration) -> Vec<String> {
    let mut lines = vec![format!(
        "fit of {} bins ({} counts), {} likelihood evaluations:",
        c.measured.len(),
        c.measured.iter().sum::<f64>(),
        c.evaluations
    )];
    for p in &c.parameters {
        let value = match (p.fitted, p.standard_error) {
            (true, Some(se)) => format!("{:.6} +- {:.2e}", p.value, se),
            (true, None) => format!("{:.6} (not determined by the data)", p.value),
            (false, _) => format!("{:.6} (fixed)", p.value),
        };
        lines.push(format!("  {:<11} {value} {}", p.name, p.unit));
    }
    lines.push(format!(
        "  chi-square per degree of freedom {:.3} ({} degrees of freedom)",
        c.chi2_per_dof, c.dof
    ));
    lines.extend(c.undetermined.iter().map(|u| format!("  note: {u}")));
    lines
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
    for line in calibration_lines(&c) {
        println!("{line}");
    }
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating output directory {}", args.out.display()))?;
    let width = stack.meta.bin_width_ps;
    let mut csv = String::from("bin_start_ps,measured,fitted\n");
    for (i, (m, f)) in c.measured.iter().zip(&c.fitted).enumerate() {
        writeln!(csv, "{},{m},{f}", start + i as f64 * width).expect("writing to a String");
    }
    let csv_path = args.out.join("profile.csv");
    std::fs::write(&csv_path, csv).with_context(|| format!("writing {}", csv_path.display()))?;
    let centre = |i: usize| start + (i as f64 + 0.5) * width;
    let measured = Series {
        label: "measured".into(),
        points: c
            .measured
            .iter()
            .enumerate()
            .map(|(i, &m)| (centre(i), m))
            .collect(),
    };
    let fitted = Series {
        label: "fitted".into(),
        points: c
            .fitted
            .iter()
            .enumerate()
            .map(|(i, &f)| (centre(i), f))
            .collect(),
    };
    let png = args.out.join("profile.png");
    chart(
        &png,
        "time profile",
        "time (ps)",
        "counts per bin",
        &[measured],
        &[fitted],
        false,
    )
    .map_err(|e| anyhow::anyhow!("writing {}: {e}", png.display()))?;
    let toml_path = args.out.join("physics.toml");
    let shift = &c.parameters[2];
    let mut header = format!(
        "Medium and instrument fitted by `scatterscope calibrate {}` (chi-square per degree of freedom {:.3}).\nUse: scatterscope reconstruct STACK --config {}",
        args.stack.display(),
        c.chi2_per_dof,
        toml_path.display()
    );
    if shift.fitted {
        header.push_str(&format!(
            "\nNot in this file: the fitted time-zero shift of {:.3} ps (reconstruct --fit-physics t0 applies it).",
            shift.value
        ));
    }
    std::fs::write(&toml_path, medium_toml(&c.setup, &header))
        .with_context(|| format!("writing {}", toml_path.display()))?;
    println!(
        "wrote {}/{{profile.csv, profile.png, physics.toml}}",
        args.out.display()
    );
    Ok(())
}
