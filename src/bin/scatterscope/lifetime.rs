//! `scatterscope lifetime`: what every pixel's decay says, from a recorded file.

use std::path::PathBuf;

use scatterscope::decay::recording::{LifetimeRequest, ReferenceFile, lifetime_file};
use scatterscope::decay::{DecayOptions, Onset};
use scatterscope::tags::bin_file::BinSpec;

/// Per-pixel decay maps of a recorded file (PTU, .spc, .sdt, .sstags):
/// photons, mean arrival time and its variance after the decay's onset,
/// fast lifetime, phasors (g, s) at harmonics of the laser frequency and,
/// against a reference, apparent phase and modulation lifetimes.
///
/// Writes maps.ome.tif (float32, one named channel per map), maps.npy
/// with maps.json (channel names, notes, metadata), lifetime.png and
/// phasor.png. Pixels with fewer photons than --min-photons are masked
/// (NaN in the maps, 1 in the mask channel).
#[derive(Debug, clap::Args)]
pub struct LifetimeArgs {
    /// The recorded file.
    file: PathBuf,
    #[command(flatten)]
    spec: BinSpec,
    /// Laser repetition rate (Hz), when the file does not state its sync
    /// rate or it is to be overridden.
    #[arg(long, value_name = "HZ")]
    frequency: Option<f64>,
    /// Harmonics of the laser frequency for the phasors (comma-separated).
    #[arg(long, value_delimiter = ',', default_value = "1,2")]
    harmonics: Vec<u32>,
    /// Pixels with fewer photons are masked.
    #[arg(long, default_value_t = 20.0)]
    min_photons: f64,
    /// The decay's onset (ps after the sync) instead of the half-maximum
    /// crossing of the image's summed decay.
    #[arg(long, value_parser = scatterscope::units::parse_ps)]
    onset: Option<f64>,
    /// A recording of a reference of known lifetime (a dye) to calibrate
    /// the phasors against (with --reference-lifetime).
    #[arg(long, requires = "reference_lifetime", conflicts_with = "irf")]
    reference: Option<PathBuf>,
    /// The reference's lifetime (default unit ps).
    #[arg(long, requires = "reference", value_parser = scatterscope::units::parse_ps)]
    reference_lifetime: Option<f64>,
    /// A recording of the instrument response: calibrates the phasors
    /// (lifetime 0) and its barycentre is the onset.
    #[arg(long, conflicts_with = "onset")]
    irf: Option<PathBuf>,
    /// Keep every bin, also those the instrument did not record whole
    /// (outside an .sdt's TAC limits, a sync period's cut last bin).
    #[arg(long)]
    all_bins: bool,
    /// Write the maps only, without lifetime.png and phasor.png.
    #[arg(long)]
    no_figures: bool,
    /// Output directory (created if missing).
    #[arg(long, default_value = "out/lifetime")]
    out: PathBuf,
}

pub fn run(args: &LifetimeArgs) -> anyhow::Result<()> {
    let reference = match (&args.reference, args.reference_lifetime, &args.irf) {
        (Some(path), Some(lifetime_ps), _) => Some(ReferenceFile::Dye {
            path: path.clone(),
            lifetime_ps,
        }),
        (_, _, Some(irf)) => Some(ReferenceFile::Irf(irf.clone())),
        _ => None,
    };
    let request = LifetimeRequest {
        options: DecayOptions {
            harmonics: args.harmonics.clone(),
            min_photons: args.min_photons,
            onset: args.onset.map_or(Onset::HalfMaximum, Onset::At),
            reference: None,
        },
        frequency_hz: args.frequency,
        reference,
        out: args.out.clone(),
        figures: !args.no_figures,
        all_bins: args.all_bins,
    };
    let done = lifetime_file(&args.file, &args.spec, &request)?;
    let mut summary = done.summary();
    summary.pop();
    for line in summary {
        println!("{line}");
    }
    for m in &done.stacks {
        for n in &m.notes {
            println!("note: {n}");
        }
        println!(
            "{} of {} pixels mapped ({} masked), {:.0} photons; median {} {:.1} ps: wrote {}",
            m.pixels - m.masked,
            m.pixels,
            m.masked,
            m.photons,
            m.median_lifetime.1,
            m.median_lifetime.0,
            m.files
                .iter()
                .map(|f| f.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    crate::signals::warned(done.warnings().len())
}
