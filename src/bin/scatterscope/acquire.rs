//! `scatterscope acquire` and `scatterscope devices`.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use crate::shared_args::{PhysicsArgs, progress};
use anyhow::Context;
use scatterscope::acquire::session::StopReason;
use scatterscope::acquire::{DeviceSpec, Job, MockJob, TimeZero, device};
use scatterscope::config::{parse_duration, parse_ps};
use scatterscope::scene::Scene;
use scatterscope::tags::binning::Region;
use scatterscope_mocks::{EmitterOptions, Faults, MockOptions};

/// Acquire a transient stack from a time tagger (or the mock device).
///
/// Streams photons into --bins bins of --bin-width from --t-start after
/// time zero and writes stack.{exr,png} and acquisition.json (the device,
/// its configuration, where every photon went). Ctrl-C stops cleanly. The
/// physics flags describe the sample (the stack's metadata; the mock's
/// ST-PSF).
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
    /// Mock: probability of an afterpulse (mean delay 50 ns) per detection.
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
    /// hardware rates). 0: draw every photon.
    #[arg(long, default_value_t = 0)]
    replay: usize,
    /// Mock: faults every n-th batch, e.g. corrupt=10,duplicate=7,reorder=5,
    /// drop-bytes=9,overflow=4:1000,disconnect=50 (random=SEED: at random).
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
    let bar = progress(job.duration.map(|d| d.as_millis()));
    let done = job.run(&stop, |p| {
        bar.set_position(p.elapsed.as_millis() as u64);
        bar.set_message(p.describe());
    })?;
    bar.finish_and_clear();
    for note in &done.notes {
        println!("{note}");
    }
    for line in done.summary() {
        println!("{line}");
    }
    let names: Vec<String> = done.files.iter().map(|f| f.display().to_string()).collect();
    println!("wrote {}", names.join(", "));
    done.verdict().map_err(anyhow::Error::msg)?;
    match done.outcome.stop {
        StopReason::Interrupted => Err(Interrupted.into()),
        _ => Ok(()),
    }
}

/// An acquisition ended by a signal: its outputs are complete (exit
/// status 3, so that a script can tell it from the planned end).
#[derive(Debug)]
pub struct Interrupted;

impl std::fmt::Display for Interrupted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "interrupted (Ctrl-C or SIGTERM): every output is complete and holds what was received"
        )
    }
}

impl std::error::Error for Interrupted {}

/// List the devices `acquire --device` can open.
///
/// Serial ports, USB time taggers with known ids, and the two mocks.
#[derive(Debug, clap::Args)]
pub struct DevicesArgs {
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
}

pub fn devices(args: &DevicesArgs) -> anyhow::Result<()> {
    let (all, hardware) = device::list_devices();
    match args.json {
        true => println!("{}", serde_json::to_string_pretty(&all)?),
        false => println!("{}", device::devices_table(&all, hardware).join("\n")),
    }
    Ok(())
}
