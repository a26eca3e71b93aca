//! `scatterscope info`, `bin` and `convert`: recorded time-tag files.

use std::path::PathBuf;

use scatterscope::formats::becker_hickl::spc::{SpcModule, SpcOptions};
use scatterscope::tags::bin_file::{BinSpec, Pixels, bin_file};
use scatterscope::tags::binning::FrameSelect;
use scatterscope::tags::convert::{ConvertError, convert_to_ptu};
use scatterscope::tags::survey::survey;

use crate::shared_args::choice;

/// What a Becker & Hickl `.spc` file does not record.
#[derive(Debug, Clone, Copy, clap::Args)]
pub struct SpcArgs {
    /// Layout of a Becker & Hickl .spc file's records (the file does not
    /// record its module): spc-130 (SPC-130/140/150/160/180/830, the
    /// default), spc-600-256 or spc-600-4096 (SPC-600/630).
    #[arg(long, value_name = "MODULE", value_parser = choice::<SpcModule>())]
    spc_module: Option<SpcModule>,
    /// Micro-time unit of a .spc file (default unit ps: TAC range / TAC
    /// gain / ADC channels); default: from the SPCM setup file beside it
    /// (NAME.set).
    #[arg(long, value_name = "TIME", value_parser = scatterscope::units::parse_ps)]
    micro_unit: Option<f64>,
}

impl SpcArgs {
    fn options(&self) -> SpcOptions {
        SpcOptions {
            module: self.spc_module,
            micro_unit_ps: self.micro_unit,
        }
    }
}

/// Show what a recorded file (PTU, HT3, PT3, .sstags, B&H .spc and .sdt) holds.
///
/// The header, then events counted by kind in one pass.
#[derive(Debug, clap::Args)]
pub struct InfoArgs {
    /// The file.
    file: PathBuf,
    #[command(flatten)]
    spc: SpcArgs,
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
    /// Bin width (default unit ps; default: the file's TCSPC resolution).
    #[arg(long, value_parser = scatterscope::units::parse_ps)]
    bin_width: Option<f64>,
    /// Start of the first bin after the sync (default unit ps).
    #[arg(long, default_value = "0", value_parser = scatterscope::units::parse_ps)]
    t_start: f64,
    /// Number of bins (default: enough to cover one sync period).
    #[arg(long)]
    bins: Option<usize>,
    /// Keep only photons of this input channel (as numbered in the records).
    #[arg(long)]
    channel: Option<u16>,
    /// Pixel mapping: auto (image for imaging files, else single), single, channel.
    #[arg(long, value_parser = choice::<Pixels>(), default_value = "auto")]
    pixels: Pixels,
    /// Frames of imaging files: sum, all (one stack per frame) or a frame number.
    #[arg(long, default_value = "sum")]
    frames: FrameSelect,
    /// Bin the complete records of a cut file instead of failing.
    #[arg(long)]
    allow_truncated: bool,
    #[command(flatten)]
    spc: SpcArgs,
    /// Write the stacks only, without their PNG contact sheets (on a
    /// small file the sheet takes about a third of the command's time).
    #[arg(long)]
    no_preview: bool,
    /// Also write each stack as OME-TIFF (stack.ome.tif: one page per bin,
    /// the bins as the lifetime axis, counts as integers) for Fiji,
    /// napari or FLIMfit.
    #[arg(long)]
    ome_tiff: bool,
    /// Output directory (created if missing).
    #[arg(long, default_value = "out/bin")]
    out: PathBuf,
}

pub fn info(args: &InfoArgs) -> anyhow::Result<()> {
    let lines = survey(&args.file, &args.spc.options())?.lines();
    for line in &lines {
        println!("{line}");
    }
    crate::signals::warned(lines.iter().filter(|l| l.starts_with("warning:")).count())
}

pub fn bin(args: &BinArgs) -> anyhow::Result<()> {
    let spec = BinSpec {
        bin_width_ps: args.bin_width,
        t_start_ps: args.t_start,
        bins: args.bins,
        channel: args.channel,
        pixels: args.pixels,
        frames: args.frames,
        allow_truncated: args.allow_truncated,
        spc: args.spc.options(),
    };
    let binned = bin_file(&args.file, &spec)?;
    binned.write(&args.out, !args.no_preview, args.ome_tiff)?;
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
    spc: SpcArgs,
}

pub fn convert(args: &ConvertArgs) -> anyhow::Result<()> {
    let stop = crate::signals::stop_flag();
    let done = match convert_to_ptu(
        &args.input,
        &args.out,
        args.allow_truncated,
        &args.spc.options(),
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
