//! `scatterscope acquire` and `scatterscope devices`.

use std::path::PathBuf;
use std::time::Duration;

use crate::shared_args::progress;
use crate::signals::Interrupted;
use scatterscope::acquire::Acquisition;
use scatterscope::acquire::request::Request;
use scatterscope::acquire::{StopReason, TimeZero, device};
use scatterscope::live::LiveView;
use scatterscope::live::recon::FinalRun;
use scatterscope::live::server::LiveStage;
use scatterscope::units::{parse_duration, parse_ps};
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
    /// Time zero of the instrument: micro time at which the pulse reaches
    /// the object (default unit ps).
    #[arg(long, default_value = "0", value_parser = parse_ps, conflicts_with = "t0_from")]
    t0: f64,
    /// Take time zero from a tag file of a reference measurement (the
    /// centre of its most populated micro-time step).
    #[arg(long, value_name = "TAGS")]
    t0_from: Option<PathBuf>,
    /// Serve a live view of the run (rates, decay, image, ledger, the
    /// reconstruction as it forms) on 127.0.0.1 at a free port, or on
    /// ADDRESS:PORT (any other address than loopback gets an access token,
    /// printed with the address).
    #[arg(long, value_name = "ADDRESS:PORT", num_args = 0..=1, default_missing_value = "127.0.0.1:0")]
    live: Option<String>,
    /// With --live: keep serving the final page this long after the run
    /// (Ctrl-C ends it sooner).
    #[arg(long, value_name = "TIME", value_parser = parse_duration, default_value = "0s", requires = "live")]
    linger: Duration,
    #[command(flatten)]
    request: Request,
}

impl AcquireArgs {
    /// The request the flags make.
    pub fn request(&self) -> Request {
        let t0 = match &self.t0_from {
            Some(reference) => TimeZero::FromReference(reference.clone()),
            None => TimeZero::At(self.t0),
        };
        Request {
            t0,
            ..self.request.clone()
        }
    }
}

pub fn run(args: &AcquireArgs) -> anyhow::Result<()> {
    let stop = crate::signals::stop_flag();
    let (job, notes) = args.request().job()?;
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
    if let Some(end) = &end {
        eprintln!("live view: {}", end.describe());
    }
    end == Some(FinalRun::Skipped)
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
    if args.picoquant && list.no_picoquant_library() {
        anyhow::bail!("no PicoQuant library loaded:\n{}", list.notes.join("\n"));
    }
    Ok(())
}
