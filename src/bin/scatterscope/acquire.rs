//! `scatterscope acquire` and `scatterscope devices`.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use crate::shared_args::PhysicsArgs;
use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use scatterscope::acquire::session::StopReason;
use scatterscope::acquire::{DeviceSpec, Job, MockJob, TimeZero};
use scatterscope::config::{parse_duration, parse_ps};
use scatterscope::scene::Scene;
use scatterscope::tags::binning::Region;
use scatterscope_mocks::{EmitterOptions, Faults, MockOptions};

/// Acquire a transient stack from a time tagger (or the mock device).
///
/// Identifies and configures the device, streams photon events, bins them
/// by arrival time into --bins bins of --bin-width from --t-start after
/// time zero (--t0), and writes stack.{exr,png} and acquisition.json with
/// the device, its configuration and where every photon went (received,
/// binned, outside the window or ROI, lost in the device or in transit).
/// Ctrl-C stops cleanly: the device's last batches are binned and every
/// file is closed and valid. The physics flags describe the sample; they go
/// into the stack's metadata for `reconstruct` and drive the mock's ST-PSF.
#[derive(Debug, clap::Args)]
pub struct AcquireArgs {
    /// mock (in-process USB), mock-serial (pseudo-terminal),
    /// serial:PATH or usb:VID:PID[:SERIAL]; see `scatterscope devices`.
    #[arg(long, default_value = "mock")]
    device: DeviceSpec,
    /// How long to acquire (e.g. 10s, 500ms, 2m); 0 runs until the device
    /// stops or Ctrl-C.
    #[arg(long, default_value = "2s", value_parser = parse_duration)]
    duration: Duration,
    #[command(flatten)]
    physics: PhysicsArgs,
    /// Time zero of the instrument: micro time at which the pulse reaches
    /// the object (default unit ps).
    #[arg(long, default_value = "0", value_parser = parse_ps, conflicts_with = "t0_from")]
    t0: f64,
    /// Take time zero from a tag file of a reference measurement (the
    /// centre of its most populated micro-time step).
    #[arg(long, value_name = "TAGS")]
    t0_from: Option<PathBuf>,
    /// Bin only this region of the sensor: X,Y,WIDTH,HEIGHT in pixels.
    #[arg(long)]
    roi: Option<Region>,
    /// Micro-time unit to configure (default: the device's TDC resolution).
    #[arg(long, value_name = "TIME", value_parser = parse_ps)]
    resolution: Option<f64>,
    /// Also record every event batch losslessly to this tag file
    /// (.sstags; `--raw` is the old name of this flag).
    #[arg(long, value_name = "FILE", alias = "raw")]
    tags: Option<PathBuf>,
    /// Mock: the scene behind the medium (usaf, star, text, disks or an image).
    #[arg(long, default_value = "usaf", value_name = "SCENE|FILE")]
    scene: String,
    /// Mock: detected signal photons per second.
    #[arg(long, default_value_t = 2e6)]
    rate: f64,
    /// Mock: dark counts per second over the sensor.
    #[arg(long, default_value_t = 0.0)]
    dark_rate: f64,
    /// Mock: probability that a detection is followed by an afterpulse
    /// (mean delay 50 ns) in the same pixel; 0 turns after-pulsing off.
    #[arg(long, default_value_t = 0.0)]
    afterpulse: f64,
    /// Mock: random seed (same seed, same photons).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Mock: delay of the pulse after the laser sync (default unit ps).
    #[arg(long, default_value = "0", value_parser = parse_ps)]
    mock_delay: f64,
    /// Mock: stop by itself after this many detected photons (0 = never).
    #[arg(long, default_value_t = 0)]
    max_photons: u64,
    /// Mock: emit as fast as the link takes photons instead of in real time.
    #[arg(long)]
    unpaced: bool,
    /// Mock: draw this many batches once and replay them (load tests at
    /// hardware rates; with --rate above what the host takes, the device
    /// FIFO overflows and says how much). 0: draw every photon.
    #[arg(long, default_value_t = 0)]
    replay: usize,
    /// Mock: inject faults, e.g. corrupt=10,duplicate=7,reorder=5,drop-bytes=9,
    /// overflow=4:1000,disconnect=50 (every n-th batch; with random=SEED,
    /// each with probability 1/n per batch at seeded random times).
    #[arg(long, default_value = "")]
    faults: Faults,
    /// Output directory (created if missing).
    #[arg(long, default_value = "out/acquire")]
    out: PathBuf,
}

pub fn run(args: &AcquireArgs) -> anyhow::Result<()> {
    let job = Job {
        device: args.device.clone(),
        setup: args.physics.resolve()?,
        t0: match &args.t0_from {
            Some(reference) => TimeZero::FromReference(reference.clone()),
            None => TimeZero::At(args.t0),
        },
        region: args.roi,
        duration: (!args.duration.is_zero()).then_some(args.duration),
        resolution_ps: args.resolution,
        tag_file: args.tags.clone(),
        software: format!("scatterscope {}", env!("CARGO_PKG_VERSION")),
        mock: MockJob {
            scene: Scene::parse(&args.scene),
            emitter: EmitterOptions {
                rate_hz: args.rate,
                dark_rate_hz: args.dark_rate,
                afterpulse_probability: args.afterpulse,
                t0_delay_ps: args.mock_delay,
                seed: args.seed,
                ..EmitterOptions::default()
            },
            device: MockOptions {
                real_time: !args.unpaced,
                max_photons: args.max_photons,
                faults: args.faults.clone(),
                replay_batches: args.replay,
                ..MockOptions::default()
            },
        },
        out: args.out.clone(),
    };
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        // A second Ctrl-C while stopping is ignored: the files must close.
        ctrlc::set_handler(move || stop.store(true, Ordering::Relaxed))
            .context("installing the Ctrl-C handler")?;
    }
    let bar = match job.duration {
        Some(d) => ProgressBar::new(d.as_millis() as u64).with_style(
            ProgressStyle::with_template("{bar:30} {elapsed}/{duration} {msg}").expect("template"),
        ),
        None => ProgressBar::new_spinner().with_style(
            ProgressStyle::with_template("{spinner} {elapsed} {msg}").expect("template"),
        ),
    };
    let mut last = (Duration::ZERO, 0u64);
    let done = job.run(&stop, |p| {
        let dt = (p.elapsed - last.0).as_secs_f64();
        let rate = if dt > 0.0 {
            (p.received - last.1) as f64 / dt
        } else {
            0.0
        };
        last = (p.elapsed, p.received);
        bar.set_position(p.elapsed.as_millis() as u64);
        bar.set_message(format!(
            "{} photons, {:.2} Mcps, lost in device {}, damaged frames {}",
            p.received,
            rate / 1e6,
            p.lost_in_device,
            p.damaged_frames
        ));
    })?;
    bar.finish_and_clear();
    for note in &done.notes {
        println!("{note}");
    }
    let summary = done.summary();
    println!("{}", summary[..2].join("\n"));
    if args.device.is_mock()
        && args.max_photons > 0
        && done.outcome.stop == StopReason::Duration
        && done.outcome.accounting.received < args.max_photons
    {
        println!(
            "  note: --duration {:?} ended the acquisition before the mock's --max-photons {} was reached; --duration 0 runs until the device stops",
            args.duration, args.max_photons
        );
    }
    for line in &summary[2..] {
        println!("{line}");
    }
    for file in done.files.iter().filter(|f| {
        f.extension().is_some_and(|e| e == "exr" || e == "sstags") && !f.ends_with("truth.exr")
    }) {
        println!("wrote {}", file.display());
    }
    done.verdict().map_err(anyhow::Error::msg)
}

/// List the devices `acquire --device` can open.
///
/// Serial ports, USB time taggers with known ids, and the two mock devices.
/// A machine with no hardware lists only the mocks.
#[derive(Debug, clap::Args)]
pub struct DevicesArgs {
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
}

pub fn devices(args: &DevicesArgs) -> anyhow::Result<()> {
    let (all, hardware) = scatterscope::acquire::device::list_devices();
    if args.json {
        println!("{}", serde_json::to_string_pretty(&all)?);
    } else {
        println!("{hardware} hardware device(s)");
        for d in &all {
            println!("  {:<28} {}", d.address, d.description);
        }
    }
    Ok(())
}
