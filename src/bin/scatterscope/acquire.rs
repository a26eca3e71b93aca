//! `scatterscope acquire` and `scatterscope devices`.

use std::path::PathBuf;
use std::time::Duration;

use crate::shared_args::progress;
use crate::signals::Interrupted;
use scatterscope::acquire::Acquisition;
use scatterscope::acquire::request::{PicoQuantRequest, Request};
use scatterscope::acquire::{DeviceSpec, MockSpec, StopReason, TimeZero, device};
use scatterscope::config::PhysicsOverrides;
use scatterscope::live::LiveView;
use scatterscope::live::recon::FinalRun;
use scatterscope::live::server::LiveStage;
use scatterscope::scene::Scene;
use scatterscope::tags::binning::Region;
use scatterscope::units::{parse_duration, parse_ps};
use scatterscope_mocks::{EmitterOptions, Faults, MockOptions};
use std::sync::atomic::AtomicBool;

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
    /// serial:PATH, usb:VID:PID[:SERIAL], picoquant[:FAMILY][:SERIAL]
    /// (FAMILY multiharp, hydraharp, timeharp260, picoharp330 or picoharp
    /// for the PicoHarp 300, through
    /// the vendor's library), or
    /// replay:FILE (a PTU or tag file played back at its recorded pace,
    /// e.g. with --live to review a run); see `scatterscope devices`.
    #[arg(long, default_value = "mock")]
    device: DeviceSpec,
    /// How long to acquire (e.g. 10s, 500ms, 2m); 0 runs until the device
    /// stops or Ctrl-C.
    /// [default: 2s; a replay: the whole recording]
    #[arg(long, value_parser = parse_duration)]
    duration: Option<Duration>,
    #[command(flatten)]
    physics: PhysicsOverrides,
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
    /// Micro-time unit of our own devices to configure (default: the
    /// device's TDC resolution; --binning sets a PicoQuant device's).
    #[arg(long, value_name = "TIME", value_parser = parse_ps)]
    micro_time_unit: Option<f64>,
    /// Also record every event batch losslessly to this tag file (.sstags).
    #[arg(long, value_name = "FILE")]
    tags: Option<PathBuf>,
    /// Mock: the scene behind the medium (usaf, star, text, disks or an image).
    #[arg(long, default_value = "usaf", value_name = "SCENE|FILE")]
    scene: String,
    /// Mock: detected signal photons per second.
    #[arg(long, default_value_t = EmitterOptions::default().rate_hz)]
    rate: f64,
    /// Mock: dark counts per second over the sensor.
    #[arg(long, default_value_t = EmitterOptions::default().dark_rate_hz)]
    dark_rate: f64,
    /// Mock: probability of an afterpulse (mean delay 50 ns) per detection.
    #[arg(long, default_value_t = EmitterOptions::default().afterpulse_probability)]
    afterpulse: f64,
    /// Mock: random seed (same seed, same photons).
    #[arg(long, default_value_t = EmitterOptions::default().seed)]
    seed: u64,
    /// Mock: delay of the pulse after the laser sync (default unit ps).
    #[arg(long, default_value_t = EmitterOptions::default().t0_delay_ps, value_parser = parse_ps)]
    mock_delay: f64,
    /// Mock: stop by itself after this many detected photons (0 = never).
    #[arg(long, default_value_t = MockOptions::default().max_photons)]
    max_photons: u64,
    /// Mock: emit as fast as the link takes photons instead of in real time.
    #[arg(long)]
    unpaced: bool,
    /// Mock: draw this many batches once and replay them (load tests at
    /// hardware rates). 0: draw every photon.
    #[arg(long, value_name = "N", default_value_t = MockOptions::default().replay_batches)]
    mock_replay: usize,
    /// Mock: faults every n-th batch, e.g. corrupt=10,duplicate=7,reorder=5,
    /// drop-bytes=9,overflow=4:1000,disconnect=50 (random=SEED: at random).
    #[arg(long, default_value = "")]
    faults: Faults,
    #[command(flatten)]
    picoquant: PicoQuantRequest,
    /// Serve a live view of the run (rates, decay, image, ledger, the
    /// reconstruction as it forms) on 127.0.0.1 at a free port, or on
    /// ADDRESS:PORT (any other address than loopback gets an access token,
    /// printed with the address).
    #[arg(long, value_name = "ADDRESS:PORT", num_args = 0..=1, default_missing_value = "127.0.0.1:0")]
    live: Option<String>,
    /// With --device replay:FILE: play the recording this many times faster
    /// than it was recorded.
    #[arg(long, value_name = "FACTOR", default_value_t = 1.0)]
    speed: f64,
    /// With --live: keep serving the final page this long after the run
    /// (Ctrl-C ends it sooner).
    #[arg(long, value_name = "TIME", value_parser = parse_duration, default_value = "0s", requires = "live")]
    linger: Duration,
    /// Also write the stack as OME-TIFF (stack.ome.tif: one page per bin,
    /// the bins as the lifetime axis, counts as integers) for Fiji,
    /// napari or FLIMfit.
    #[arg(long)]
    ome_tiff: bool,
    /// Output directory (created if missing).
    #[arg(long, default_value = "out/acquire")]
    out: PathBuf,
}

/// The mock's scene and behaviour from the mock flags.
fn mock_spec(args: &AcquireArgs) -> MockSpec {
    MockSpec {
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
            replay_batches: args.mock_replay,
            ..MockOptions::default()
        },
    }
}

/// The request the flags make.
pub fn request(args: &AcquireArgs) -> Request {
    Request {
        duration: args.duration,
        physics: args.physics.clone(),
        t0: match &args.t0_from {
            Some(reference) => TimeZero::FromReference(reference.clone()),
            None => TimeZero::At(args.t0),
        },
        region: args.roi,
        micro_time_unit_ps: args.micro_time_unit,
        tags: args.tags.clone(),
        mock: mock_spec(args),
        picoquant: args.picoquant.clone(),
        speed: args.speed,
        ome_tiff: args.ome_tiff,
        ..Request::new(args.device.clone(), args.out.clone())
    }
}

pub fn run(args: &AcquireArgs) -> anyhow::Result<()> {
    let stop = crate::signals::stop_flag();
    let (job, notes) = request(args).job()?;
    for note in notes {
        println!("{note}");
    }
    let live = args
        .live
        .as_deref()
        .map(|addr| LiveView::start(Some(addr)))
        .transpose()?;
    let mut stage = live.as_ref().map(|view| {
        println!("live view: {}", view.url());
        let truth = job.setup.as_ref().and_then(|s| job.device.known_scene(s));
        view.stage(job.setup.clone(), truth)
    });
    let bar = progress(job.plan.duration.map(|d| d.as_millis()));
    let done = job.run_watched(
        stop,
        |p| {
            bar.set_position(p.elapsed.as_millis() as u64);
            bar.set_message(p.describe());
        },
        &mut |s| {
            if let Some(stage) = stage.as_mut() {
                stage.watch(s);
            }
        },
    )?;
    bar.finish_and_clear();
    for note in &done.notes {
        println!("{note}");
    }
    for line in done.summary() {
        println!("{line}");
    }
    let names: Vec<String> = done.files.iter().map(|f| f.display().to_string()).collect();
    println!("wrote {}", names.join(", "));
    if let (Some(view), Some(stage)) = (&live, stage) {
        view.finish(&done);
        if !args.linger.is_zero() {
            // Ctrl-C while it works ends the page's part as it ends the
            // lingering: the acquisition's outputs are all written.
            if !reconstruct_whole_run(stage, &done, stop) {
                println!(
                    "live view: the final page stays up for {:?} (Ctrl-C ends it)",
                    args.linger
                );
                view.linger(args.linger, stop);
            }
        }
    }
    done.verdict().map_err(anyhow::Error::msg)?;
    match done.outcome.end.stop {
        StopReason::Interrupted => Err(Interrupted(INTERRUPTED).into()),
        _ => Ok(()),
    }
}

/// The live view's reconstruction of the whole run, with a progress line
/// every few seconds on stderr (the command is not silent while it works);
/// `true` when Ctrl-C skipped it.
fn reconstruct_whole_run(stage: LiveStage, done: &Acquisition, stop: &AtomicBool) -> bool {
    const EVERY_S: f64 = 5.0;
    let mut next_line = EVERY_S;
    eprintln!(
        "live view: reconstructing the whole run ({} photons) for the page; Ctrl-C skips it (the outputs are written)",
        done.outcome.ledger.counts.photons
    );
    let end = stage.finish(done, stop, |p| {
        if p.elapsed_s >= next_line {
            eprintln!("live view: reconstructing the whole run: {}", p.describe());
            next_line += EVERY_S;
        }
    });
    match end {
        Some(FinalRun::Shown { run_s, method }) => {
            eprintln!("live view: the whole run reconstructed in {run_s:.1} s ({method})");
            false
        }
        Some(FinalRun::Failed(e)) => {
            eprintln!("live view: the whole run's reconstruction failed: {e}");
            false
        }
        Some(FinalRun::Skipped) => {
            eprintln!(
                "live view: the whole run's reconstruction skipped (Ctrl-C); every output is written"
            );
            true
        }
        None => false,
    }
}

/// What an acquisition ended by a signal says.
const INTERRUPTED: &str =
    "interrupted (Ctrl-C or SIGTERM): every output is complete and holds what was received";

/// List the devices `acquire --device` can open.
///
/// Serial ports, USB time taggers with known ids, PicoQuant devices the
/// vendor's libraries find (with where each library was looked for), and
/// the two mocks.
#[derive(Debug, clap::Args)]
pub struct DevicesArgs {
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
    /// The PicoQuant library file to ask (default: the installer's places).
    #[arg(long, value_name = "FILE")]
    vendor_lib: Option<PathBuf>,
    /// Fail (exit non-zero) when no PicoQuant vendor library loads.
    #[arg(long)]
    picoquant: bool,
}

pub fn devices(args: &DevicesArgs) -> anyhow::Result<()> {
    let list = device::list_devices(args.vendor_lib.as_deref());
    match args.json {
        true => println!("{}", serde_json::to_string_pretty(&list.all)?),
        false => println!("{}", list.table().join("\n")),
    }
    if args.picoquant && list.notes.len() == scatterscope_drivers::picoquant::Family::ALL.len() {
        anyhow::bail!("no PicoQuant library loaded:\n{}", list.notes.join("\n"));
    }
    Ok(())
}
