//! `scatterscope batch`: many jobs from a manifest, on this machine or as a
//! Slurm job array.

use std::path::PathBuf;

use scatterscope::batch::{
    LocalRun, Outcome, SlurmOptions, check_jobs, collect, read_manifest, run_job, run_local,
    submit_slurm, write_summary,
};

use crate::shared_args::progress;

/// Run the jobs of a manifest: locally with a pool of workers (a re-run
/// skips the jobs that succeeded), or as a Slurm job array (--slurm), then
/// gather the records into one summary (--collect).
///
/// The manifest is TOML, one `[[job]]` table per job: `command` (any
/// scatterscope command), optional `name` (its folder under --out),
/// `input` (first argument; relative to the manifest) and `args`. Each job
/// writes into OUT/NAME with its log (job.log) and record (batch.json).
/// Every job's command line is checked first (its flags; an
/// acquisition's settings for its device), and a manifest with a refused
/// one runs nothing.
#[derive(Debug, clap::Args)]
pub struct BatchArgs {
    /// The manifest (TOML).
    manifest: PathBuf,
    /// Jobs at once (default: the cores divided by --threads-per-job).
    #[arg(long)]
    workers: Option<usize>,
    /// Threads of each job.
    #[arg(long, default_value_t = 1)]
    threads_per_job: usize,
    /// Time limit of every job whose table sets no `timeout` (e.g. 30m);
    /// a job past it is ended (SIGTERM, then SIGKILL) and recorded as such.
    #[arg(long, value_parser = scatterscope::units::parse_duration)]
    job_timeout: Option<std::time::Duration>,
    /// Submit as a Slurm job array with sbatch (one task per job).
    #[arg(long, conflicts_with = "collect")]
    slurm: bool,
    /// Slurm: partition.
    #[arg(long, requires = "slurm")]
    partition: Option<String>,
    /// Slurm: time limit per task (e.g. 00:30:00).
    #[arg(long, requires = "slurm")]
    time: Option<String>,
    /// Slurm: memory per task (e.g. 4G).
    #[arg(long, requires = "slurm")]
    mem: Option<String>,
    /// Slurm: wait for the array to end, then print the summary.
    #[arg(long, requires = "slurm")]
    wait: bool,
    /// Gather the jobs' records into the summary (after a Slurm array).
    #[arg(long)]
    collect: bool,
    /// Run only the job with this index (what each Slurm task runs).
    #[arg(long, hide = true)]
    task: Option<usize>,
    /// Output directory (created if missing).
    #[arg(long, default_value = "out/batch")]
    out: PathBuf,
}

fn print_summary(outcomes: &[Outcome], out: &std::path::Path) -> anyhow::Result<()> {
    let (table, path, all_ok) = write_summary(outcomes, out)?;
    print!("{table}");
    println!("wrote {}", path.display());
    anyhow::ensure!(
        all_ok,
        "not every job succeeded (see the table; logs in OUT/JOB/job.log)"
    );
    Ok(())
}

pub fn run(args: &BatchArgs) -> anyhow::Result<()> {
    let jobs = read_manifest(&args.manifest)?;
    let exe = std::env::current_exe()?;
    if let Some(k) = args.task {
        let job = jobs.get(k).ok_or_else(|| {
            anyhow::anyhow!("task {k}: the manifest has jobs 0 to {}", jobs.len() - 1)
        })?;
        let r = run_job(
            &exe,
            &args.out,
            job,
            args.threads_per_job,
            args.job_timeout,
            crate::signals::stop_flag(),
        )?;
        println!(
            "{}: {} in {:.2} s: {}",
            r.name, r.status, r.seconds, r.result
        );
        anyhow::ensure!(r.ok(), "job {} failed", r.name);
        return Ok(());
    }
    if args.collect {
        return print_summary(&collect(&jobs, &args.out), &args.out);
    }
    // Every job's command line, checked before any job runs.
    check_jobs(&args.manifest, &jobs, &args.out, crate::check_line)?;
    if args.slurm {
        let opts = SlurmOptions {
            partition: args.partition.clone(),
            time: args.time.clone(),
            cpus_per_task: args.threads_per_job,
            mem: args.mem.clone(),
            wait: args.wait,
        };
        let (script, id) = submit_slurm(&exe, &args.manifest, &args.out, jobs.len(), &opts)?;
        println!(
            "submitted {} as Slurm job {id}: {} array tasks",
            script.display(),
            jobs.len()
        );
        if args.wait {
            return print_summary(&collect(&jobs, &args.out), &args.out);
        }
        println!(
            "when it ends: scatterscope batch {} --collect --out {}",
            args.manifest.display(),
            args.out.display()
        );
        return Ok(());
    }
    let (out, workers) = (args.out.clone(), args.workers);
    let mut local = LocalRun::on_this_machine(exe, out, workers, args.threads_per_job);
    local.job_timeout = args.job_timeout;
    let stop = crate::signals::stop_flag();
    println!(
        "{} jobs, {} at once with {} thread(s) each",
        jobs.len(),
        local.workers,
        local.threads_per_job
    );
    let bar = progress(None);
    bar.set_length(jobs.len() as u64);
    let outcomes = run_local(&jobs, &local, stop, |o| {
        bar.inc(1);
        if let Outcome::Ran(r) = o {
            bar.set_message(format!("{} {}", r.name, r.status));
        }
    })?;
    bar.finish_and_clear();
    let printed = print_summary(&outcomes, &args.out);
    if stop.load(std::sync::atomic::Ordering::Relaxed) {
        return Err(crate::signals::Interrupted(
            "interrupted (Ctrl-C or SIGTERM): running jobs were ended and recorded as interrupted; a re-run does the rest",
        )
        .into());
    }
    printed
}
