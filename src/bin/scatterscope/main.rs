//! The `scatterscope` command-line tool.

mod acquire;
mod batch;
mod bench_hidden;
mod bench_recon;
mod calibrate_cmd;
mod calibrate_slab;
mod denoise;
mod denoise_bench;
mod embedded;
mod fit;
mod hidden;
mod hints;
mod lifetime;
mod psf;
mod recon_args;
mod reconstruct;
mod renames;
mod report;
mod shared_args;
mod signals;
mod simulate;
mod tags_cmd;
mod weights_cmd;

use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};
use scatterscope::units::parse_size;

/// The allocator: the reconstructions free and allocate images of 0.5-1 MB
/// per bin and iteration on several threads, and the system allocator
/// handed them back to the kernel and faulted them in again each time
/// (measured: 40 % of `rl-stack`'s run time in the kernel); mimalloc keeps
/// them for reuse.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// Time-resolved imaging through scattering media.
///
/// Models the blur of a scattering slab with the diffusion approximation
/// (the ST-PSF), acquires or simulates photon-count stacks, and
/// reconstructs the object behind it.
#[derive(Debug, Parser)]
#[command(name = "scatterscope", version, about, long_about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Memory any input may ask for (e.g. 8GiB) [default:
    /// $SCATTERSCOPE_MEMORY_LIMIT, else half the machine's memory].
    #[arg(long, global = true, value_name = "SIZE", value_parser = parse_size)]
    memory_limit: Option<u64>,
}

#[derive(Debug, Subcommand)]
enum Command {
    Psf(psf::PsfArgs),
    Simulate(simulate::SimulateArgs),
    Reconstruct(reconstruct::ReconstructArgs),
    Calibrate(calibrate_cmd::CalibrateArgs),
    CalibrateSlab(calibrate_slab::CalibrateSlabArgs),
    Hidden(hidden::HiddenArgs),
    Embedded(embedded::EmbeddedArgs),
    SimulateEmbedded(embedded::SimulateEmbeddedArgs),
    Report(report::ReportArgs),
    BenchRecon(Box<bench_recon::BenchReconArgs>),
    BenchHidden(bench_hidden::BenchHiddenArgs),
    Info(tags_cmd::InfoArgs),
    Bin(tags_cmd::BinArgs),
    Convert(tags_cmd::ConvertArgs),
    Lifetime(lifetime::LifetimeArgs),
    Fit(fit::FitArgs),
    Acquire(Box<acquire::AcquireArgs>),
    Devices(acquire::DevicesArgs),
    Batch(batch::BatchArgs),
    Denoise(denoise::DenoiseArgs),
    DenoiseBench(denoise_bench::DenoiseBenchArgs),
    Weights(weights_cmd::WeightsArgs),
    Demo(DemoArgs),
}

/// End-to-end demo on the mock device, no hardware needed.
///
/// `acquire --device mock --out OUT/acquire`, then `reconstruct` of its
/// stack against its truth into OUT/reconstruct.
#[derive(Debug, clap::Args)]
struct DemoArgs {
    /// Output directory.
    #[arg(long, default_value = "out/demo")]
    out: std::path::PathBuf,
}

fn demo(args: &DemoArgs) -> anyhow::Result<()> {
    let (acq, rec) = (args.out.join("acquire"), args.out.join("reconstruct"));
    let (stack, truth) = (acq.join("stack.exr"), acq.join("truth.exr"));
    let steps = [
        vec!["acquire", "--device", "mock", "--out", s(&acq)?],
        vec![
            "reconstruct",
            s(&stack)?,
            "--truth",
            s(&truth)?,
            "--out",
            s(&rec)?,
        ],
    ];
    for step in steps {
        println!("== scatterscope {}", step.join(" "));
        dispatch(Cli::try_parse_from(std::iter::once("scatterscope").chain(step))?.command)?;
    }
    Ok(())
}

/// Refuses a command line (a command and its arguments) this tool would
/// refuse, without running it: parsed as `main` parses (old spellings
/// rewritten) and, for an acquisition, its request built and its device
/// rules checked.
fn check_line(line: &[std::ffi::OsString]) -> Result<(), String> {
    let program = std::iter::once("scatterscope".into());
    let (args, _) = renames::new_spellings(program.chain(line.iter().cloned()));
    let cli = match Cli::try_parse_from(args) {
        Ok(cli) => cli,
        // `--help` or `--version`: the job prints them.
        Err(e) if !e.use_stderr() => return Ok(()),
        Err(e) => {
            let text = e.to_string();
            let first = text.lines().next().unwrap_or_default();
            return Err(first.trim_start_matches("error: ").to_string());
        }
    };
    if let Command::Acquire(args) = &cli.command {
        args.request().check().map_err(|e| e.to_string())?;
    }
    Ok(())
}

/// A path as a demo's argument.
fn s(p: &std::path::Path) -> anyhow::Result<&str> {
    p.to_str()
        .ok_or_else(|| anyhow::anyhow!("{}: not a UTF-8 path", p.display()))
}

/// Exit status: 0 success; 1 the command failed (bad input, I/O, a device
/// error), with one `error:` line naming the file, field and value and the
/// causes after it, then a `hint:` line per flag that changes it; 2 the
/// command line itself is wrong (clap's usage errors); 3 an acquisition
/// ended by Ctrl-C or SIGTERM, its outputs complete with what was received
/// (a conversion or a batch ended so writes nothing partial); 4 the command
/// finished and wrote its outputs, but printed `warning:` lines (an empty or
/// implausible result, an incomplete input); 130 any other command ended by
/// a signal, the outputs it was writing removed. A panic (101) is a bug.
fn main() -> std::process::ExitCode {
    let (args, notes) = renames::new_spellings(std::env::args_os());
    for note in notes {
        eprintln!("{note}");
    }
    let matches = Cli::command().get_matches_from(args);
    let mut cli = Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    if let (Command::BenchRecon(args), Some((_, m))) = (&mut cli.command, matches.subcommand()) {
        args.forwarded = bench_recon::forwarded(m);
    }
    scatterscope::memory::set_limit(cli.memory_limit);
    scatterscope::cache::use_default();
    // One command per process: no output may replace a file it read.
    scatterscope::files::input::remember_inputs();
    let run = signals::install().and_then(|()| dispatch(cli.command));
    match run {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) if e.is::<signals::Interrupted>() => {
            eprintln!("{e}");
            std::process::ExitCode::from(3)
        }
        Err(e) if e.is::<signals::Warned>() => {
            eprintln!("{e}");
            std::process::ExitCode::from(4)
        }
        Err(e) => {
            eprintln!("error: {}", scatterscope::error_text(e.as_ref()));
            let name = matches.subcommand_name().unwrap_or_default();
            let command = Cli::command().find_subcommand(name).cloned();
            let command = command.unwrap_or_else(Cli::command);
            for hint in hints::flag_hints(&e, &command) {
                eprintln!("hint: {hint}");
            }
            std::process::ExitCode::from(1)
        }
    }
}

fn dispatch(command: Command) -> anyhow::Result<()> {
    match command {
        Command::Psf(args) => psf::run(&args),
        Command::Simulate(args) => simulate::run(&args),
        Command::Reconstruct(args) => reconstruct::run(&args),
        Command::Calibrate(args) => calibrate_cmd::run(&args),
        Command::CalibrateSlab(args) => calibrate_slab::run(&args),
        Command::Hidden(args) => hidden::run(&args),
        Command::Embedded(args) => embedded::run(&args),
        Command::SimulateEmbedded(args) => embedded::simulate(&args),
        Command::Report(args) => report::run(&args),
        Command::BenchRecon(args) => bench_recon::run(&args),
        Command::BenchHidden(args) => bench_hidden::run(&args),
        Command::Info(args) => tags_cmd::info(&args),
        Command::Bin(args) => tags_cmd::bin(&args),
        Command::Batch(args) => batch::run(&args),
        Command::Convert(args) => tags_cmd::convert(&args),
        Command::Lifetime(args) => lifetime::run(&args),
        Command::Fit(args) => fit::run(&args),
        Command::Acquire(args) => acquire::run(&args),
        Command::Devices(args) => acquire::devices(&args),
        Command::Denoise(args) => denoise::run(&args),
        Command::DenoiseBench(args) => denoise_bench::run(&args),
        Command::Weights(args) => weights_cmd::run(&args),
        Command::Demo(args) => demo(&args),
    }
}
