//! `scatterscope info`, `bin` and `convert`: recorded time-tag files.

use std::path::PathBuf;

use scatterscope::formats::becker_hickl::spc::SpcOptions;
use scatterscope::tags::bin_file::{BinOutputs, BinSpec, bin_file_to};
use scatterscope::tags::convert::ConvertError;
use scatterscope::tags::recorded::convert_to_ptu;
use scatterscope::tags::recorded::survey;

/// Show what a recorded file (PTU, HT3, PT3, .sstags, B&H .spc and .sdt) holds.
///
/// The header, then events counted by kind in one pass.
#[derive(Debug, clap::Args)]
pub struct InfoArgs {
    /// The file.
    file: PathBuf,
    #[command(flatten)]
    spc: SpcOptions,
}

/// Bin a T3 file into a transient stack (counts per micro-time bin and pixel).
///
/// Single-pixel files give a 1 x 1 stack, --pixels channel a pixel per
/// channel; imaging files bin into their scanned image. Becker & Hickl
/// .spc photon files bin like T3 files (routing channels as channels);
/// .sdt histogram files give one stack per block of decay curves.
#[derive(Debug, clap::Args)]
pub struct BinArgs {
    /// The file.
    file: PathBuf,
    #[command(flatten)]
    spec: BinSpec,
    /// Write the stacks only, without their PNG contact sheets (on a
    /// small file the sheet takes about a third of the command's time).
    #[arg(long)]
    no_preview: bool,
    /// Also write each stack as OME-TIFF (stack.ome.tif: one page per bin,
    /// the bins as the lifetime axis, counts as integers) for Fiji,
    /// napari or FLIMfit.
    #[arg(long)]
    ome_tiff: bool,
    /// Write each stack as .npy (16- or 32-bit counts, uncompressed) with
    /// its JSON sidecar instead of EXR: the fastest to write and to load
    /// with numpy.
    #[arg(long)]
    npy: bool,
    /// Output directory (created if missing).
    #[arg(long, default_value = "out/bin")]
    out: PathBuf,
}

pub fn info(args: &InfoArgs) -> anyhow::Result<()> {
    let lines = survey(&args.file, &args.spc)?.lines();
    for line in &lines {
        println!("{line}");
    }
    crate::signals::warned(lines.iter().filter(|l| l.starts_with("warning:")).count())
}

pub fn bin(args: &BinArgs) -> anyhow::Result<()> {
    let outputs = BinOutputs {
        npy: args.npy,
        previews: !args.no_preview,
        ome_tiff: args.ome_tiff,
        ..BinOutputs::new(&args.out)
    };
    let binned = bin_file_to(&args.file, &args.spec, &outputs)?;
    let mut summary = binned.summary();
    let last = summary.pop().expect("the summary ends with the stacks");
    for line in summary {
        println!("{line}");
    }
    println!("wrote {last} to {}", args.out.display());
    crate::signals::warned(binned.warnings().len())
}

/// Convert a recorded file (PTU, HT3, PT3, .sstags, B&H .spc) to PTU, photon for photon.
///
/// PicoQuant files keep their record type; a tag file becomes Generic T3
/// with each photon's sensor pixel as its input channel (sensors of at
/// most 63 pixels); a .spc file becomes Generic T3 with its routing
/// channel as the input channel and its macro-time clock as the sync.
#[derive(Debug, clap::Args)]
pub struct ConvertArgs {
    /// The recorded file.
    input: PathBuf,
    /// The PTU file to write.
    #[arg(long)]
    out: PathBuf,
    /// Convert the complete records of a cut file instead of failing.
    #[arg(long)]
    allow_truncated: bool,
    #[command(flatten)]
    spc: SpcOptions,
}

pub fn convert(args: &ConvertArgs) -> anyhow::Result<()> {
    let stop = crate::signals::stop_flag();
    let done = match convert_to_ptu(
        &args.input,
        &args.out,
        args.allow_truncated,
        &args.spc,
        stop,
    ) {
        Err(ConvertError::Interrupted { .. }) => {
            return Err(crate::signals::Interrupted(
                "interrupted (Ctrl-C or SIGTERM): the conversion stopped and nothing was written",
            )
            .into());
        }
        other => other?,
    };
    println!("{}", done.summary(&args.out));
    crate::signals::warned(done.warnings.len())
}
