//! `scatterscope acquire` and `scatterscope devices`.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use crate::shared_args::PhysicsArgs;
use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use scatterscope::acquire::{
    DeviceSpec, MockReference, MockSetup, Plan, StopReason, acquire, open_device,
};
use scatterscope::config::parse_ps;
use scatterscope::formats::exr;
use scatterscope::formats::png::{SheetScale, write_contact_sheet, write_image};
use scatterscope::physics::{KernelStack, Sampling};
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
    /// Take time zero from a raw tag file of a reference measurement (the
    /// centre of its most populated micro-time step).
    #[arg(long, value_name = "RAW")]
    t0_from: Option<PathBuf>,
    /// Bin only this region of the sensor: X,Y,WIDTH,HEIGHT in pixels.
    #[arg(long, value_parser = parse_roi)]
    roi: Option<Region>,
    /// Micro-time unit to configure (default: the device's TDC resolution).
    #[arg(long, value_name = "TIME", value_parser = parse_ps)]
    resolution: Option<f64>,
    /// Also record every event batch losslessly to this raw tag file.
    #[arg(long, value_name = "FILE")]
    raw: Option<PathBuf>,
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
    #[arg(long, value_parser = parse_faults, default_value = "")]
    faults: Faults,
    /// Output directory (created if missing).
    #[arg(long, default_value = "out/acquire")]
    out: PathBuf,
}

fn parse_duration(s: &str) -> Result<Duration, String> {
    let t = s.trim();
    let (num, scale) = if let Some(n) = t.strip_suffix("ms") {
        (n, 1e-3)
    } else if let Some(n) = t.strip_suffix('s') {
        (n, 1.0)
    } else if let Some(n) = t.strip_suffix('m') {
        (n, 60.0)
    } else if let Some(n) = t.strip_suffix('h') {
        (n, 3600.0)
    } else {
        (t, 1.0)
    };
    let v: f64 = num
        .trim()
        .parse()
        .map_err(|_| format!("`{s}` is not a duration (e.g. 10s, 500ms, 2m)"))?;
    if !(v >= 0.0 && v.is_finite()) {
        return Err(format!("`{s}`: a duration must be finite and not negative"));
    }
    Ok(Duration::from_secs_f64(v * scale))
}

fn parse_roi(s: &str) -> Result<Region, String> {
    let v: Vec<usize> = s
        .split(',')
        .map(|p| p.trim().parse::<usize>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("`{s}`: expected X,Y,WIDTH,HEIGHT as whole pixels"))?;
    match v[..] {
        [x, y, width, height] if width > 0 && height > 0 => Ok(Region {
            x,
            y,
            width,
            height,
        }),
        _ => Err(format!(
            "`{s}`: expected X,Y,WIDTH,HEIGHT with a non-empty size"
        )),
    }
}

fn parse_faults(s: &str) -> Result<Faults, String> {
    let mut f = Faults::default();
    for item in s.split(',').map(str::trim).filter(|i| !i.is_empty()) {
        let (name, value) = item
            .split_once('=')
            .ok_or_else(|| format!("fault `{item}`: expected NAME=N"))?;
        let n = |v: &str| {
            v.parse::<u32>()
                .map_err(|_| format!("fault `{item}`: `{v}` is not a count"))
        };
        match name {
            "corrupt" => f.corrupt_every = n(value)?,
            "drop-bytes" => f.drop_bytes_every = n(value)?,
            "duplicate" => f.duplicate_every = n(value)?,
            "reorder" => f.reorder_every = n(value)?,
            "disconnect" => f.disconnect_after = n(value)?,
            "random" => {
                f.random_seed = value
                    .parse()
                    .map_err(|_| format!("fault `{item}`: `{value}` is not a seed"))?
            }
            "overflow" => {
                let (every, photons) = value
                    .split_once(':')
                    .ok_or_else(|| format!("fault `{item}`: expected overflow=EVERY:PHOTONS"))?;
                f.overflow_every = n(every)?;
                f.overflow_photons = u64::from(n(photons)?);
            }
            other => {
                return Err(format!(
                    "unknown fault `{other}` (corrupt, drop-bytes, duplicate, reorder, overflow, disconnect, random)"
                ));
            }
        }
    }
    Ok(f)
}

pub fn run(args: &AcquireArgs) -> anyhow::Result<()> {
    let setup = args.physics.resolve()?;
    let (h, w) = (setup.sensor.height_px, setup.sensor.width_px);
    anyhow::ensure!(
        h * w <= 1 << 16,
        "--size {w}: the protocol addresses at most 65536 pixels (256 x 256)"
    );
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating output directory {}", args.out.display()))?;
    let mock = if args.device.is_mock() {
        let scene = Scene::parse(&args.scene);
        let truth = scene.render(h, w)?;
        exr::write_image(truth.mapv(|v| v as f32).view(), &args.out.join("truth.exr"))?;
        write_image(truth.view(), Some(1.0), &args.out.join("truth.png"))?;
        let kernels = KernelStack::build(&setup, Sampling::Integrated)?;
        Some(MockSetup {
            scene: truth,
            kernels,
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
        })
    } else {
        None
    };
    let t0_ps = match &args.t0_from {
        Some(reference) => {
            let t0 = scatterscope::acquire::calibration::t0_from_reference(reference)?;
            println!("t0 = {t0:.3} ps from reference {}", reference.display());
            t0
        }
        None => args.t0,
    };
    let plan = Plan {
        t_start_ps: setup.bins.start_ps,
        bin_width_ps: setup.bins.width_ps,
        bins: setup.bins.count,
        t0_ps,
        region: args.roi,
        duration: (!args.duration.is_zero()).then_some(args.duration),
        resolution_fs: args.resolution.map(|ps| (ps * 1000.0).round() as u32),
        tag_file: args.raw.clone(),
        software: format!("scatterscope {}", env!("CARGO_PKG_VERSION")),
    };
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        // A second Ctrl-C while stopping is ignored: the files must close.
        ctrlc::set_handler(move || stop.store(true, Ordering::Relaxed))
            .context("installing the Ctrl-C handler")?;
    }
    // For a mock the scene is known, so the stack's light budget can be set
    // such that reconstructions come out in the scene's units (comparable
    // with its truth image).
    let mock_reference = mock.as_ref().map(MockReference::new);
    let opened = open_device(&args.device, mock)?;
    let bar = match plan.duration {
        Some(d) => ProgressBar::new(d.as_millis() as u64).with_style(
            ProgressStyle::with_template("{bar:30} {elapsed}/{duration} {msg}").expect("template"),
        ),
        None => ProgressBar::new_spinner().with_style(
            ProgressStyle::with_template("{spinner} {elapsed} {msg}").expect("template"),
        ),
    };
    let mut last = (Duration::ZERO, 0u64);
    let outcome = acquire(opened.link, &plan, &stop, |p| {
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
    })
    .with_context(|| format!("acquiring from {}", args.device))?;
    bar.finish_and_clear();
    let truth = opened.mock.map(|m| m.truth());

    let acc = &outcome.accounting;
    let mut stack_setup = setup.clone();
    if let (Some(reference), Some(t)) = (&mock_reference, &truth)
        && let Some(budget) =
            reference.light_budget(setup.total_photons, outcome.region, acc.binned, t)
    {
        stack_setup.total_photons = budget;
        println!(
            "light budget {budget:.4e} photons (mock: scaled so the object comes out in the scene's units)"
        );
    }
    // The reconstruction's physics: the flags' (for the mock, the light
    // budget of the known scene).
    let mut stack = outcome.stack(
        &plan,
        &stack_setup,
        format!("scatterscope acquire --device {}", args.device),
    );
    stack.meta.seed = args.device.is_mock().then_some(args.seed);
    let record = outcome.record(&plan);
    stack.save(&args.out.join("stack.exr"))?;
    write_contact_sheet(&stack, SheetScale::Shared, &args.out.join("stack.png"))?;
    let json_path = args.out.join("acquisition.json");
    std::fs::write(&json_path, serde_json::to_string_pretty(&record)? + "\n")
        .with_context(|| format!("writing {}", json_path.display()))?;

    let secs = outcome.elapsed.as_secs_f64().max(1e-9);
    println!(
        "{} ({} {}): {} photons in {:.2} s ({:.2} Mcps), {} bins of {} ps from {} ps after t0 = {} ps",
        outcome.link,
        outcome.identity.model,
        outcome.identity.serial,
        acc.received,
        secs,
        acc.received as f64 / secs / 1e6,
        plan.bins,
        plan.bin_width_ps,
        plan.t_start_ps,
        plan.t0_ps
    );
    println!("  ended: {}", outcome.stop.describe());
    if args.device.is_mock()
        && args.max_photons > 0
        && outcome.stop == StopReason::Duration
        && acc.received < args.max_photons
    {
        println!(
            "  note: --duration {:?} ended the acquisition before the mock's --max-photons {} was reached; --duration 0 runs until the device stops",
            args.duration, args.max_photons
        );
    }
    print!("{}", acc.table());
    if let Some(t) = truth {
        println!(
            "  mock truth: detected {} ({} dark, {} afterpulses), lost in FIFO {}, damaged in transit {}, never sent {}",
            t.photons_detected,
            t.dark_counts,
            t.afterpulses,
            t.photons_lost_fifo,
            t.photons_damaged,
            t.photons_unsent
        );
    }
    let empty: Vec<usize> = (0..stack.bins())
        .filter(|&k| stack.bin(k).iter().all(|&v| v == 0.0))
        .collect();
    if !empty.is_empty() {
        println!(
            "  {} of {} bins are empty (bins {:?})",
            empty.len(),
            stack.bins(),
            empty
        );
    }
    println!("wrote {}", args.out.join("stack.exr").display());
    if let Some(raw) = &outcome.tag_file {
        println!("wrote {}", raw.display());
    }
    match &outcome.stop {
        StopReason::Disconnected(e) => anyhow::bail!(
            "the device disconnected ({e}); the {} photons received before are in {}",
            acc.received,
            args.out.display()
        ),
        StopReason::NoStopAnswer => {
            anyhow::bail!("the device did not confirm Stop; its totals are unknown")
        }
        _ => {}
    }
    anyhow::ensure!(
        acc.balances(),
        "photon accounting does not balance:\n{}",
        acc.table()
    );
    Ok(())
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
