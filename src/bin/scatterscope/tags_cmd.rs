//! `scatterscope info` and `scatterscope bin`: recorded time-tag files.

use std::path::PathBuf;

use anyhow::Context;
use scatterscope::formats::picoquant::{Container, FileError, FileInfo, TtrError};
use scatterscope::formats::png::{SheetScale, write_contact_sheet};
use scatterscope::formats::sstags::is_tag_file;
use scatterscope::tags::bin_file::{BinFileError, BinSpec, Pixels, Recording, bin_file};
use scatterscope::tags::binning::FrameSelect;
use scatterscope::tags::survey::{survey_picoquant, survey_raw};

/// Show what a PicoQuant file (PTU, HT3, HT2) holds.
///
/// Prints the header (device, record type, resolutions, sync rate, record
/// counts, imaging tags) and, from one pass over the records, photons per
/// channel, markers, overflows and the measured duration.
#[derive(Debug, clap::Args)]
pub struct InfoArgs {
    /// The file.
    file: PathBuf,
}

/// Bin a T3 file into a transient stack (counts per micro-time bin and pixel).
///
/// Single-pixel files give a 1 x 1 stack; --pixels channel makes each input
/// channel a pixel (SPAD arrays); imaging files (Measurement_SubMode 3) are
/// binned into their scanned image from the line and frame markers.
#[derive(Debug, clap::Args)]
pub struct BinArgs {
    /// The file.
    file: PathBuf,
    /// Bin width (default unit ps; default: the file's TCSPC resolution).
    #[arg(long, value_parser = scatterscope::config::parse_ps)]
    bin_width: Option<f64>,
    /// Start of the first bin after the sync (default unit ps).
    #[arg(long, default_value = "0", value_parser = scatterscope::config::parse_ps)]
    t_start: f64,
    /// Number of bins (default: enough to cover one sync period).
    #[arg(long)]
    bins: Option<usize>,
    /// Keep only photons of this input channel (as numbered in the records).
    #[arg(long)]
    channel: Option<u16>,
    /// Pixel mapping: auto (image for imaging files, else single), single, channel.
    #[arg(long, default_value = "auto")]
    pixels: String,
    /// Frames of imaging files: sum, all (one stack per frame) or a frame number.
    #[arg(long, default_value = "sum")]
    frames: String,
    /// Bin the complete records of a cut file instead of failing.
    #[arg(long)]
    allow_truncated: bool,
    /// Output directory (created if missing).
    #[arg(long, default_value = "out/bin")]
    out: PathBuf,
}

pub fn info(args: &InfoArgs) -> anyhow::Result<()> {
    if is_tag_file(&args.file) {
        return info_raw(args);
    }
    let (info, survey) = survey_picoquant(&args.file)?;
    print_header(&info);
    println!("photons per channel: {:?}", survey.photons_per_channel);
    println!(
        "markers: {}, syncs: {}, overflow records: {}",
        survey.markers, survey.syncs, survey.overflows
    );
    println!(
        "measured duration: {:.6} s (last event)",
        survey.last_event_s
    );
    if let Some(e) = survey.cut {
        println!("warning: {e}");
    }
    Ok(())
}

fn print_header(info: &FileInfo) {
    let container = match &info.container {
        Container::Ptu(v) => format!("PTU {v}"),
        Container::HydraHarpLegacy(v) => format!("HydraHarp HT3/HT2 {v}"),
        Container::PicoHarpLegacy(v) => format!("PicoHarp PT3/PT2 {v}"),
    };
    println!("file: {}", info.path.display());
    println!("container: {container}; device: {}", info.device);
    println!(
        "record type: {} (0x{:08X})",
        info.record_type.name(),
        info.record_type.code()
    );
    println!(
        "resolution: {:.3} ps; macro unit: {:.6e} s{}",
        info.resolution_s * 1e12,
        info.macro_unit_s,
        info.sync_rate_hz
            .map_or(String::new(), |r| format!("; sync rate {r} Hz"))
    );
    println!(
        "records: {} announced, {} present{}",
        info.records_announced,
        info.records_present,
        if info.trailing_bytes > 0 {
            format!(", {} trailing bytes", info.trailing_bytes)
        } else {
            String::new()
        }
    );
    if let Some(d) = info.acquisition_time_s() {
        println!("acquisition time set: {d} s");
    }
    if let Some(d) = info.stopped_after_s() {
        println!("stopped after: {d} s");
    }
    println!("measurement sub mode: {}", info.sub_mode);
    if let Some(img) = &info.imaging {
        println!(
            "image: {} x {} pixels, line start mask {}, line stop mask {}, frame mask {}, bidirectional {}",
            img.pixels_x, img.pixels_y, img.line_start, img.line_stop, img.frame, img.bidirectional
        );
    }
}

fn parse_frames(s: &str) -> anyhow::Result<FrameSelect> {
    Ok(match s {
        "sum" => FrameSelect::Sum,
        "all" => FrameSelect::All,
        n => FrameSelect::One(
            n.parse()
                .with_context(|| format!("--frames {n}: use sum, all or a frame number"))?,
        ),
    })
}

pub fn bin(args: &BinArgs) -> anyhow::Result<()> {
    let spec = BinSpec {
        bin_width_ps: args.bin_width,
        t_start_ps: args.t_start,
        bins: args.bins,
        channel: args.channel,
        pixels: match args.pixels.as_str() {
            "auto" => Pixels::Auto,
            "single" => Pixels::Single,
            "channel" => Pixels::Channel,
            other => anyhow::bail!("--pixels {other}: use auto, single or channel"),
        },
        frames: parse_frames(&args.frames)?,
        allow_truncated: args.allow_truncated,
    };
    let binned = bin_file(&args.file, &spec).map_err(|e| match e {
        BinFileError::File(FileError {
            error: TtrError::Truncated { .. },
            ..
        }) => anyhow::anyhow!("{e} (pass --allow-truncated to bin the complete records)"),
        e => e.into(),
    })?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating output directory {}", args.out.display()))?;
    let many = binned.stacks.len() > 1;
    for (f, stack) in binned.stacks.iter().enumerate() {
        let stem = if many {
            format!("stack_f{f:03}")
        } else {
            "stack".into()
        };
        stack.save(&args.out.join(format!("{stem}.exr")))?;
        write_contact_sheet(
            stack,
            SheetScale::Shared,
            &args.out.join(format!("{stem}.png")),
        )?;
    }
    let acc = binned.accounting;
    match &binned.recording {
        Recording::PicoQuant(_) => println!(
            "{} records ({:.0} M records/s): {} photons, {} binned, {} outside the time window, {} on other channels, {} outside the image; {} markers, {} frames",
            acc.records,
            binned.records_per_s / 1e6,
            acc.received,
            acc.binned,
            acc.outside_window,
            acc.other_channel,
            acc.outside_region,
            acc.markers,
            acc.frames
        ),
        Recording::Raw { counts, .. } => println!(
            "{} records ({:.0} M records/s): {} photons, {} binned, {} outside the window, {} lost in the device, {} invalid",
            acc.records,
            binned.records_per_s / 1e6,
            acc.received,
            acc.binned,
            acc.outside_window,
            counts.lost_in_device,
            counts.invalid_records
        ),
    }
    for note in &binned.notes {
        println!("note: {note}");
    }
    if let Some(t) = &binned.truncated {
        println!("warning: {t}");
    }
    let (k, h, w) = binned.stacks[0].data.dim();
    println!(
        "wrote {} stack(s) of {k} x {h} x {w} ({} ps bins from {} ps) to {}",
        binned.stacks.len(),
        binned.window.width_ps(binned.resolution_ps),
        binned.window.start_ps(binned.resolution_ps),
        args.out.display()
    );
    Ok(())
}

/// `info` of the project's raw tag files.
fn info_raw(args: &InfoArgs) -> anyhow::Result<()> {
    let (summary, survey) = survey_raw(&args.file)?;
    let h = &summary.header;
    println!("file: {}", args.file.display());
    println!(
        "container: scatterscope raw tags v{}; written by {}",
        h.format_version, h.software
    );
    println!("device: {} {} via {}", h.model, h.serial, h.link);
    println!(
        "sensor: {} x {} pixels; micro-time unit {} fs; sync period {} fs (divider {})",
        h.pixels_x, h.pixels_y, h.resolution_fs, h.sync_period_fs, h.sync_divider
    );
    println!(
        "batches: {}; photons: {}; markers: {}; lost in the device: {}; invalid records: {}",
        summary.batches,
        survey.photons,
        survey.markers,
        survey.lost_in_device,
        survey.invalid_records
    );
    println!(
        "measured duration: {:.6} s (last event)",
        survey.last_event_s
    );
    match summary.totals {
        Some(t) => println!(
            "device totals: {} batches, {} photons sent, {} lost in the device{}",
            t.batches,
            t.photons_sent,
            t.photons_lost,
            if t.photons_sent == survey.photons {
                ""
            } else {
                " (the file misses some: lost in transit)"
            }
        ),
        None => println!("warning: no end frame: the recording was cut (crash or disconnect)"),
    }
    if summary.bytes_skipped > 0 {
        println!(
            "warning: {} bytes did not form valid frames (damage or a cut last batch)",
            summary.bytes_skipped
        );
    }
    Ok(())
}
