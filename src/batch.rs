//! Many jobs at once (`scatterscope batch`): a TOML manifest of commands,
//! run on this machine by a bounded pool of workers or as a Slurm job
//! array, resumable, with one summary.
//!
//! ```toml
//! [[job]]
//! name = "v20"                     # optional; default job-000, job-001, ...
//! command = "bin"                  # any scatterscope command
//! input = "data/v20_t3.ptu"        # optional first argument
//! args = ["--bin-width", "64ps"]   # optional further arguments
//! ```
//!
//! Each job runs as `scatterscope COMMAND [INPUT] ARGS... --out
//! OUT/NAME` (a child process of the same binary, so a crash or a bad
//! input fails that job alone) with its output in `OUT/NAME/job.log`. A
//! finished job leaves `OUT/NAME/batch.json` (status, seconds, its key
//! result); a run skips the jobs whose record says they succeeded and runs
//! the failed and missing ones again. Each job's threads are limited
//! (`RAYON_NUM_THREADS`) so that the workers together use the cores once.
//! A job may have a time limit (`timeout = "30m"` in its table, or one for
//! every job from the command line); each runs in its own process group,
//! so that a timeout, or Ctrl-C / SIGTERM to the batch, reaches the job and
//! everything it started: SIGTERM first (an acquisition then saves what it
//! received), SIGKILL after a grace period, and the record says which.
//! On Slurm each array task runs one job by `SLURM_ARRAY_TASK_ID`; Slurm
//! schedules, retries and accounts, and [`collect`] reads the records into
//! the same summary.

use std::ffi::OsString;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

/// The file a finished job leaves in its folder.
pub const RECORD: &str = "batch.json";
/// The job's output log.
pub const LOG: &str = "job.log";

/// One job of a manifest.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct JobSpec {
    /// Name, and the folder under the batch's output.
    #[serde(default)]
    pub name: String,
    /// The scatterscope command.
    pub command: String,
    /// The first argument (a file), if any.
    #[serde(default)]
    pub input: Option<String>,
    /// Further arguments.
    #[serde(default)]
    pub args: Vec<String>,
    /// Time limit (`90s`, `30m`, `2h`); none when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub timeout: Option<String>,
}

/// Commands whose `--out` names a file, not a folder, and the file a
/// batch job of theirs writes in its folder.
const FILE_OUTPUTS: [(&str, &str); 2] = [("convert", "converted.ptu"), ("denoise", "denoised.exr")];

impl JobSpec {
    /// The job's command line after the program's name: its command, its
    /// input, its arguments and `--out` with its folder under `out` (a
    /// file in that folder for the commands that write one file).
    pub fn command_line(&self, out: &Path) -> Vec<OsString> {
        let mut line = vec![OsString::from(&self.command)];
        line.extend(self.input.iter().map(OsString::from));
        line.extend(self.args.iter().map(OsString::from));
        line.push("--out".into());
        let folder = out.join(&self.name);
        line.push(
            match FILE_OUTPUTS.iter().find(|(c, _)| *c == self.command) {
                Some((_, file)) => folder.join(file).into_os_string(),
                None => folder.into_os_string(),
            },
        );
        line
    }
}

/// Checks every job's command line with `check` (the front end's parser,
/// and for an acquisition its request) before any job runs; the first
/// refused is named with the manifest and why.
pub fn check_jobs(
    manifest: &Path,
    jobs: &[JobSpec],
    out: &Path,
    check: impl Fn(&[OsString]) -> Result<(), String>,
) -> Result<(), BatchError> {
    for job in jobs {
        check(&job.command_line(out)).map_err(|reason| BatchError::Manifest {
            path: manifest.to_owned(),
            reason: format!("job `{}` ({}): {reason}", job.name, job.command),
        })?;
    }
    Ok(())
}

/// Largest manifest read (a manifest of ten thousand jobs is far smaller).
pub const MAX_MANIFEST: u64 = 16 << 20;

/// How long a job has to end after SIGTERM before it is killed.
pub const GRACE: Duration = Duration::from_secs(10);

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ManifestFile {
    job: Vec<JobSpec>,
}

/// Why a batch cannot run.
#[derive(Debug, thiserror::Error)]
pub enum BatchError {
    /// The manifest cannot be read or is invalid.
    #[error("{path}: {reason}")]
    Manifest {
        /// The manifest.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// A file or process could not be used.
    #[error("{0}")]
    Io(String),
}

/// Reads a manifest; names default to `job-NNN`, relative inputs are
/// taken from the manifest's folder, and names must be unique folder names.
pub fn read_manifest(path: &Path) -> Result<Vec<JobSpec>, BatchError> {
    let bad = |reason: String| BatchError::Manifest {
        path: path.to_owned(),
        reason,
    };
    let bytes = crate::files::read_bounded(path, MAX_MANIFEST, "batch manifest")
        .map_err(|e| BatchError::Io(e.to_string()))?;
    let text = String::from_utf8(bytes).map_err(|e| {
        bad(format!(
            "not UTF-8 text (byte {}): a manifest is TOML",
            e.utf8_error().valid_up_to()
        ))
    })?;
    parse_manifest(path, &text)
}

/// [`read_manifest`] on the manifest's text (`path` names it and is the
/// base of relative inputs).
pub fn parse_manifest(path: &Path, text: &str) -> Result<Vec<JobSpec>, BatchError> {
    let bad = |reason: String| BatchError::Manifest {
        path: path.to_owned(),
        reason,
    };
    let file: ManifestFile = toml::from_str(text).map_err(|e| bad(e.to_string()))?;
    let base = path.parent().unwrap_or(Path::new("."));
    let mut jobs = file.job;
    if jobs.is_empty() {
        return Err(bad("no [[job]] entries".into()));
    }
    let mut seen = std::collections::HashSet::new();
    for (i, job) in jobs.iter_mut().enumerate() {
        if job.name.is_empty() {
            job.name = format!("job-{i:03}");
        }
        if job.name.contains(['/', '\\']) || job.name.starts_with('.') {
            return Err(bad(format!(
                "job {i}: name `{}` must be a plain folder name",
                job.name
            )));
        }
        if !seen.insert(job.name.clone()) {
            return Err(bad(format!("job {i}: name `{}` is used twice", job.name)));
        }
        if job.command.is_empty() || job.command.starts_with('-') || job.command == "batch" {
            return Err(bad(format!(
                "job `{}`: command `{}` is not a scatterscope command a batch can run",
                job.name, job.command
            )));
        }
        if job.args.iter().any(|a| a == "--out") {
            return Err(bad(format!(
                "job `{}`: --out is set by the batch (OUT/{})",
                job.name, job.name
            )));
        }
        if let Some(t) = &job.timeout {
            crate::units::parse_duration(t)
                .map_err(|e| bad(format!("job `{}`: timeout {e}", job.name)))?;
        }
        if let Some(input) = &job.input {
            // Absolute, so that the jobs read the same file wherever they
            // run (a Slurm task starts in another folder).
            let p = base.join(input);
            job.input = Some(std::path::absolute(&p).unwrap_or(p).display().to_string());
        }
        // A relative path among the arguments (a reference, an IRF, a
        // truth) is the manifest's, as its input is: made absolute when
        // the manifest's folder holds it.
        for arg in &mut job.args {
            let (flag, value) = match arg.split_once('=') {
                Some((f, v)) if f.starts_with("--") => (Some(f.to_string()), v.to_string()),
                _ => (None, arg.clone()),
            };
            if value.starts_with('-') || Path::new(&value).is_absolute() {
                continue;
            }
            let p = base.join(&value);
            if !value.is_empty() && p.exists() {
                let p = std::path::absolute(&p).unwrap_or(p).display().to_string();
                *arg = flag.map_or(p.clone(), |f| format!("{f}={p}"));
            }
        }
    }
    Ok(jobs)
}

/// Writes `jobs` as a manifest [`read_manifest`] reads back.
pub fn write_manifest(path: &Path, jobs: &[JobSpec]) -> Result<(), BatchError> {
    #[derive(Serialize)]
    struct File<'a> {
        job: &'a [JobSpec],
    }
    let text = toml::to_string(&File { job: jobs })
        .map_err(|e| BatchError::Io(format!("{}: {e}", path.display())))?;
    crate::files::write_atomic(path, text)
        .map_err(|e| BatchError::Io(format!("{}: {e}", path.display())))
}

/// The exit status of a command that wrote its outputs with warnings.
pub const WARNED_EXIT: i32 = 4;
/// The status of a job that exited with [`WARNED_EXIT`].
const WARNED: &str = "ok with warnings";

/// How a job ended.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JobRecord {
    /// The job's name.
    pub name: String,
    /// `ok`, `ok with warnings` (exit 4: its outputs written, with
    /// warnings), `failed`, `timeout` (ended at its time limit) or
    /// `interrupted` (ended by Ctrl-C or SIGTERM to the batch).
    pub status: String,
    /// The exit status (None: killed by a signal).
    pub exit_code: Option<i32>,
    /// Start, seconds since the Unix epoch.
    pub started_unix_s: f64,
    /// Wall time, seconds.
    pub seconds: f64,
    /// The key result (a reconstruction's method and deviance, else the
    /// job's last line of output), or why it failed.
    pub result: String,
}

impl JobRecord {
    /// Whether the job succeeded (its outputs written, with or without
    /// warnings).
    pub fn ok(&self) -> bool {
        self.status == "ok" || self.status == WARNED
    }
}

/// How to run a batch on this machine.
#[derive(Debug, Clone)]
pub struct LocalRun {
    /// The scatterscope binary the jobs run.
    pub exe: PathBuf,
    /// The batch's output folder.
    pub out: PathBuf,
    /// Jobs at once.
    pub workers: usize,
    /// Threads of each job.
    pub threads_per_job: usize,
    /// Time limit of the jobs whose table sets none.
    pub job_timeout: Option<Duration>,
}

impl LocalRun {
    /// Workers and threads on this machine: `workers` jobs at once
    /// (default: its cores divided by `threads_per_job`), each with
    /// `threads_per_job` threads (at least one).
    pub fn on_this_machine(
        exe: PathBuf,
        out: PathBuf,
        workers: Option<usize>,
        threads_per_job: usize,
    ) -> Self {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let threads = threads_per_job.max(1);
        Self {
            exe,
            out,
            workers: workers.unwrap_or(cores / threads).max(1),
            threads_per_job: threads,
            job_timeout: None,
        }
    }
}

/// The record of `job` in `out`, if it finished.
pub fn record_of(out: &Path, job: &JobSpec) -> Option<JobRecord> {
    let bytes =
        crate::files::read_bounded(&out.join(&job.name).join(RECORD), 1 << 20, "job record");
    serde_json::from_slice(&bytes.ok()?).ok()
}

/// The key result of a finished job: a reconstruction's method, its last
/// deviance (else objective) and its iterations from its trace, else the
/// last line of its output that is not the list of files written.
fn key_result(dir: &Path, stdout: &str) -> String {
    if let Ok(bytes) = crate::files::read_bounded(&dir.join("trace.json"), 64 << 20, "trace")
        && let Ok(trace) = serde_json::from_slice::<serde_json::Value>(&bytes)
    {
        let last = |key: &str| {
            trace["rows"]
                .as_array()
                .and_then(|r| r.iter().rev().find_map(|row| row[key].as_f64()))
                .map(|v| format!(", {key} {v:.6e}"))
        };
        return format!(
            "method {}{}, {} iterations",
            trace["method"].as_str().unwrap_or("?"),
            last("deviance")
                .or_else(|| last("objective"))
                .unwrap_or_default(),
            trace["rows"].as_array().map_or(0, Vec::len)
        );
    }
    stdout
        .lines()
        .rev()
        .map(str::trim)
        .find(|l| !l.is_empty() && !l.starts_with("wrote "))
        .unwrap_or("")
        .to_string()
}

/// How a job's process ended.
enum Ending {
    /// It exited, or was killed by a signal not of ours.
    Exited(std::process::ExitStatus),
    /// Its time limit passed.
    Timeout(std::process::ExitStatus),
    /// The batch was stopped.
    Interrupted(std::process::ExitStatus),
}

/// Sends `signal` to the process group `pgid` (the job and its children).
#[cfg(unix)]
fn signal_group(pgid: u32, signal: i32) {
    // SAFETY: kill(2) with a negative pid signals a process group; it has
    // no memory effects.
    unsafe {
        libc::kill(-(pgid as i32), signal);
    }
}

/// Waits for `child`, ending its process group at `deadline` or when
/// `stop` is set: SIGTERM, then SIGKILL after [`GRACE`].
fn supervise(
    child: &mut std::process::Child,
    deadline: Option<Instant>,
    stop: &AtomicBool,
) -> std::io::Result<Ending> {
    let mut asked: Option<(Instant, bool)> = None; // (when, was it the timeout)
    loop {
        if let Some(status) = child.try_wait()? {
            return Ok(match asked {
                None => Ending::Exited(status),
                Some((_, true)) => Ending::Timeout(status),
                Some((_, false)) => Ending::Interrupted(status),
            });
        }
        let now = Instant::now();
        match asked {
            None => {
                let timed_out = deadline.is_some_and(|d| now >= d);
                if timed_out || stop.load(Ordering::Relaxed) {
                    #[cfg(unix)]
                    signal_group(child.id(), libc::SIGTERM);
                    #[cfg(not(unix))]
                    let _ = child.kill();
                    asked = Some((now, timed_out));
                }
            }
            Some((when, _)) if now.duration_since(when) > GRACE => {
                #[cfg(unix)]
                signal_group(child.id(), libc::SIGKILL);
                let _ = child.kill();
            }
            Some(_) => {}
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Runs one job now (whatever its record says) and writes its record;
/// `timeout` applies when the job's table sets none, and `stop` (the
/// batch's Ctrl-C) ends it early.
pub fn run_job(
    exe: &Path,
    out: &Path,
    job: &JobSpec,
    threads: usize,
    timeout: Option<Duration>,
    stop: &AtomicBool,
) -> Result<JobRecord, BatchError> {
    let dir = out.join(&job.name);
    std::fs::create_dir_all(&dir).map_err(|e| BatchError::Io(format!("{}: {e}", dir.display())))?;
    let _ = std::fs::remove_file(dir.join(RECORD));
    let timeout = match &job.timeout {
        Some(t) => Some(
            crate::units::parse_duration(t)
                .map_err(|e| BatchError::Io(format!("job `{}`: timeout {e}", job.name)))?,
        ),
        None => timeout,
    };
    let started = Instant::now();
    let started_unix_s = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64());
    let mut cmd = std::process::Command::new(exe);
    cmd.args(job.command_line(out))
        .env("RAYON_NUM_THREADS", threads.to_string())
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped());
    #[cfg(unix)]
    {
        use std::os::unix::process::CommandExt;
        // Its own process group: a terminal's Ctrl-C reaches the batch
        // alone, which then ends each job in order.
        cmd.process_group(0);
        #[cfg(target_os = "linux")]
        // SAFETY: prctl is async-signal-safe; between fork and exec it
        // only asks the kernel to send SIGTERM when the parent dies, so
        // that a batch killed outright leaves no job running.
        unsafe {
            cmd.pre_exec(|| {
                libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM);
                Ok(())
            });
        }
    }
    let start_err = |e: std::io::Error| BatchError::Io(format!("starting {}: {e}", exe.display()));
    let mut child = cmd.spawn().map_err(start_err)?;
    let drain = |pipe: Option<Box<dyn Read + Send>>| {
        std::thread::spawn(move || {
            let mut bytes = Vec::new();
            if let Some(mut p) = pipe {
                let _ = p.read_to_end(&mut bytes);
            }
            bytes
        })
    };
    let out_reader = drain(
        child
            .stdout
            .take()
            .map(|p| Box::new(p) as Box<dyn Read + Send>),
    );
    let err_reader = drain(
        child
            .stderr
            .take()
            .map(|p| Box::new(p) as Box<dyn Read + Send>),
    );
    let ending = supervise(&mut child, timeout.map(|t| started + t), stop)
        .map_err(|e| BatchError::Io(format!("waiting for job `{}`: {e}", job.name)))?;
    let stdout = out_reader.join().unwrap_or_default();
    let stderr = err_reader.join().unwrap_or_default();
    let seconds = started.elapsed().as_secs_f64();
    let stdout = String::from_utf8_lossy(&stdout);
    let stderr = String::from_utf8_lossy(&stderr);
    let log = format!("$ {cmd:?}\n{stdout}{stderr}");
    crate::files::write_atomic(dir.join(LOG), log)
        .map_err(|e| BatchError::Io(format!("{}: {e}", dir.display())))?;
    let last_error = || {
        stderr
            .lines()
            .map(str::trim)
            .rfind(|l| !l.is_empty())
            .unwrap_or("no error message")
            .to_string()
    };
    let (status, exit, result) = match ending {
        Ending::Exited(s) if s.success() => ("ok", s, key_result(&dir, &stdout)),
        Ending::Exited(s) if s.code() == Some(WARNED_EXIT) => (
            WARNED,
            s,
            format!("{}; warned: {}", key_result(&dir, &stdout), last_error()),
        ),
        Ending::Exited(s) => ("failed", s, last_error()),
        Ending::Timeout(s) => (
            "timeout",
            s,
            format!(
                "ended at its time limit of {:.1} s",
                timeout.map_or(0.0, |t| t.as_secs_f64())
            ),
        ),
        Ending::Interrupted(s) => (
            "interrupted",
            s,
            "ended by Ctrl-C or SIGTERM to the batch".to_string(),
        ),
    };
    let record = JobRecord {
        name: job.name.clone(),
        status: status.into(),
        exit_code: exit.code(),
        started_unix_s,
        seconds,
        result,
    };
    let text = serde_json::to_string_pretty(&record).expect("records serialise");
    crate::files::write_atomic(dir.join(RECORD), text)
        .map_err(|e| BatchError::Io(format!("{}: {e}", dir.display())))?;
    Ok(record)
}

/// One line of the summary.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// Ran in this run.
    Ran(JobRecord),
    /// Skipped: its record from an earlier run says it succeeded.
    Done(JobRecord),
    /// Not run (a Slurm task that has not finished, or never ran).
    Missing(String),
}

/// Runs the jobs not already done with `run.workers` at once; `on_done`
/// sees each job as it ends. A failing job never stops the others.
/// Once `stop` is set, no further job starts and the running ones are
/// ended ([`run_job`]); the jobs not started are missing from the summary.
pub fn run_local(
    jobs: &[JobSpec],
    run: &LocalRun,
    stop: &AtomicBool,
    on_done: impl Fn(&Outcome) + Sync,
) -> Result<Vec<Outcome>, BatchError> {
    std::fs::create_dir_all(&run.out)
        .map_err(|e| BatchError::Io(format!("{}: {e}", run.out.display())))?;
    let outcomes: Vec<Mutex<Option<Outcome>>> = jobs.iter().map(|_| Mutex::new(None)).collect();
    let todo: Vec<usize> = jobs
        .iter()
        .enumerate()
        .filter_map(|(i, job)| match record_of(&run.out, job) {
            Some(r) if r.ok() => {
                let o = Outcome::Done(r);
                on_done(&o);
                *outcomes[i].lock().expect("not poisoned") = Some(o);
                None
            }
            _ => Some(i),
        })
        .collect();
    let next = AtomicUsize::new(0);
    let failure: Mutex<Option<BatchError>> = Mutex::new(None);
    std::thread::scope(|scope| {
        for _ in 0..run.workers.min(todo.len()).max(1) {
            scope.spawn(|| {
                loop {
                    let k = next.fetch_add(1, Ordering::Relaxed);
                    let Some(&i) = todo.get(k) else { break };
                    if stop.load(Ordering::Relaxed) {
                        break;
                    }
                    let job = &jobs[i];
                    match run_job(
                        &run.exe,
                        &run.out,
                        job,
                        run.threads_per_job,
                        run.job_timeout,
                        stop,
                    ) {
                        Ok(r) => {
                            let o = Outcome::Ran(r);
                            on_done(&o);
                            *outcomes[i].lock().expect("not poisoned") = Some(o);
                        }
                        Err(e) => {
                            failure.lock().expect("not poisoned").get_or_insert(e);
                        }
                    }
                }
            });
        }
    });
    if let Some(e) = failure.into_inner().expect("not poisoned") {
        return Err(e);
    }
    Ok(outcomes
        .into_iter()
        .zip(jobs)
        .map(|(o, job)| {
            o.into_inner()
                .expect("not poisoned")
                .unwrap_or_else(|| Outcome::Missing(job.name.clone()))
        })
        .collect())
}

/// The records of every job in `out` (after a Slurm array, or any run).
pub fn collect(jobs: &[JobSpec], out: &Path) -> Vec<Outcome> {
    jobs.iter()
        .map(|job| match record_of(out, job) {
            Some(r) => Outcome::Ran(r),
            None => Outcome::Missing(job.name.clone()),
        })
        .collect()
}

/// [`summary`] written to `out/summary.md` (whole or not at all): the
/// table, the file and whether every job succeeded.
pub fn write_summary(
    outcomes: &[Outcome],
    out: &Path,
) -> Result<(String, PathBuf, bool), BatchError> {
    let (table, all_ok) = summary(outcomes);
    let path = out.join("summary.md");
    let io = |e: std::io::Error| BatchError::Io(format!("{}: {e}", path.display()));
    std::fs::create_dir_all(out).map_err(io)?;
    crate::files::write_atomic(&path, &table).map_err(io)?;
    Ok((table, path, all_ok))
}

/// The summary table (Markdown) and whether every job succeeded.
pub fn summary(outcomes: &[Outcome]) -> (String, bool) {
    let mut s = String::from("| job | status | time (s) | result |\n| --- | --- | --- | --- |\n");
    let mut all_ok = true;
    for o in outcomes {
        let (name, status, secs, result) = match o {
            Outcome::Ran(r) => (
                r.name.as_str(),
                r.status.clone(),
                r.seconds,
                r.result.as_str(),
            ),
            Outcome::Done(r) => (
                r.name.as_str(),
                format!("{} (earlier run)", r.status),
                r.seconds,
                r.result.as_str(),
            ),
            Outcome::Missing(n) => (
                n.as_str(),
                "missing".into(),
                f64::NAN,
                "not run or not finished",
            ),
        };
        all_ok &= status.starts_with("ok");
        let secs = if secs.is_nan() {
            "-".to_string()
        } else {
            format!("{secs:.2}")
        };
        s.push_str(&format!(
            "| {name} | {status} | {secs} | {} |\n",
            result.replace('|', "/")
        ));
    }
    (s, all_ok)
}

/// Slurm resources of an array.
#[derive(Debug, Clone, Default)]
pub struct SlurmOptions {
    /// Partition (`None`: the cluster's default).
    pub partition: Option<String>,
    /// Time limit per task (Slurm's format, e.g. `00:30:00`).
    pub time: Option<String>,
    /// CPUs per task (and the job's threads).
    pub cpus_per_task: usize,
    /// Memory per task (Slurm's format, e.g. `4G`).
    pub mem: Option<String>,
    /// Wait for the array to end (`sbatch --wait`).
    pub wait: bool,
}

/// The sbatch script of a batch: one array task per job, each running
/// `scatterscope batch MANIFEST --task $SLURM_ARRAY_TASK_ID`.
pub fn slurm_script(
    exe: &Path,
    manifest: &Path,
    out: &Path,
    jobs: usize,
    opts: &SlurmOptions,
) -> String {
    let mut s = String::from("#!/bin/bash\n#SBATCH --job-name=scatterscope-batch\n");
    s.push_str(&format!("#SBATCH --array=0-{}\n", jobs.saturating_sub(1)));
    s.push_str(&format!(
        "#SBATCH --output={}/slurm-%A_%a.log\n",
        out.display()
    ));
    s.push_str(&format!(
        "#SBATCH --cpus-per-task={}\n",
        opts.cpus_per_task.max(1)
    ));
    if let Some(p) = &opts.partition {
        s.push_str(&format!("#SBATCH --partition={p}\n"));
    }
    if let Some(t) = &opts.time {
        s.push_str(&format!("#SBATCH --time={t}\n"));
    }
    if let Some(m) = &opts.mem {
        s.push_str(&format!("#SBATCH --mem={m}\n"));
    }
    s.push_str(&format!(
        "exec '{}' batch '{}' --out '{}' --threads-per-job {} --task \"$SLURM_ARRAY_TASK_ID\"\n",
        exe.display(),
        manifest.display(),
        out.display(),
        opts.cpus_per_task.max(1)
    ));
    s
}

/// Writes the script into `out` and submits it with `sbatch` (found on
/// PATH); returns the script's path and sbatch's answer (the job id).
pub fn submit_slurm(
    exe: &Path,
    manifest: &Path,
    out: &Path,
    jobs: usize,
    opts: &SlurmOptions,
) -> Result<(PathBuf, String), BatchError> {
    std::fs::create_dir_all(out).map_err(|e| BatchError::Io(format!("{}: {e}", out.display())))?;
    let abs = |p: &Path| std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
    let script_path = out.join("batch.sbatch");
    let script = slurm_script(&abs(exe), &abs(manifest), &abs(out), jobs, opts);
    crate::files::write_atomic(&script_path, script)
        .map_err(|e| BatchError::Io(format!("{}: {e}", script_path.display())))?;
    let mut cmd = std::process::Command::new("sbatch");
    cmd.arg("--parsable");
    if opts.wait {
        cmd.arg("--wait");
    }
    let output = cmd.arg(&script_path).output().map_err(|e| {
        BatchError::Io(format!(
            "running sbatch (is Slurm installed and on PATH?): {e}"
        ))
    })?;
    let id = String::from_utf8_lossy(&output.stdout).trim().to_string();
    // With --wait, sbatch fails when a task failed; the array still ran
    // and its records say which.
    let array_ran = opts.wait && !id.is_empty();
    if !output.status.success() && !array_ran {
        return Err(BatchError::Io(format!(
            "sbatch {} failed: {}",
            script_path.display(),
            String::from_utf8_lossy(&output.stderr).trim()
        )));
    }
    Ok((script_path, id))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_sbatch_script_runs_one_job_per_array_task_with_its_resources() {
        let s = slurm_script(
            Path::new("/opt/scatterscope"),
            Path::new("/data/jobs.toml"),
            Path::new("/data/out"),
            20,
            &SlurmOptions {
                partition: Some("gpu".into()),
                time: Some("00:30:00".into()),
                cpus_per_task: 4,
                mem: Some("4G".into()),
                wait: false,
            },
        );
        for line in [
            "#SBATCH --array=0-19",
            "#SBATCH --cpus-per-task=4",
            "#SBATCH --partition=gpu",
            "#SBATCH --time=00:30:00",
            "#SBATCH --mem=4G",
            "#SBATCH --output=/data/out/slurm-%A_%a.log",
            "--threads-per-job 4 --task \"$SLURM_ARRAY_TASK_ID\"",
        ] {
            assert!(s.contains(line), "{line}: {s}");
        }
        assert!(s.starts_with("#!/bin/bash\n"));
    }

    /// A path among a job's arguments is the manifest's, as its input is,
    /// wherever the batch is started from; other arguments are left.
    #[test]
    fn argument_paths_are_the_manifests() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("study");
        std::fs::create_dir(&dir).unwrap();
        std::fs::write(dir.join("irf.ptu"), b"x").unwrap();
        let manifest = dir.join("jobs.toml");
        let jobs = parse_manifest(
            &manifest,
            "[[job]]\ncommand = \"lifetime\"\ninput = \"a.ptu\"\nargs = [\"--irf\", \"irf.ptu\", \"--harmonics\", \"1,2\", \"--reference=irf.ptu\", \"--truth\", \"missing.png\"]\n",
        )
        .unwrap();
        let irf = std::path::absolute(dir.join("irf.ptu"))
            .unwrap()
            .display()
            .to_string();
        assert_eq!(
            jobs[0].args,
            [
                "--irf",
                irf.as_str(),
                "--harmonics",
                "1,2",
                &format!("--reference={irf}"),
                "--truth",
                "missing.png"
            ]
        );
    }

    /// Exit 4 (outputs written, with warnings) is a job done: the next run
    /// skips it.
    #[test]
    fn a_job_that_warned_counts_as_done() {
        let record = JobRecord {
            name: "j".into(),
            status: WARNED.into(),
            exit_code: Some(WARNED_EXIT),
            started_unix_s: 0.0,
            seconds: 1.0,
            result: "warned".into(),
        };
        assert!(record.ok());
        assert!(
            !JobRecord {
                status: "failed".into(),
                ..record
            }
            .ok()
        );
    }

    #[test]
    fn manifests_round_trip_and_inputs_become_absolute() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path();
        let jobs = vec![JobSpec {
            name: "a".into(),
            command: "bin".into(),
            input: Some("x.ptu".into()),
            args: vec!["--bins".into(), "10".into()],
            timeout: Some("90s".into()),
        }];
        let path = dir.join("m.toml");
        write_manifest(&path, &jobs).unwrap();
        let back = read_manifest(&path).unwrap();
        assert_eq!(back[0].args, jobs[0].args);
        let input = PathBuf::from(back[0].input.as_ref().unwrap());
        assert!(input.is_absolute() && input.ends_with("x.ptu"), "{input:?}");
        assert_eq!(back[0].timeout.as_deref(), Some("90s"));
    }

    #[test]
    fn a_manifest_that_is_not_a_small_text_file_is_refused_at_once() {
        let t = Instant::now();
        let err = read_manifest(Path::new("/dev/zero"))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("not a regular file") && err.contains("/dev/zero"),
            "{err}"
        );
        let tmp = tempfile::tempdir().unwrap();
        let big = tmp.path().join("big.toml");
        let f = std::fs::File::create(&big).unwrap();
        f.set_len(10 << 30).unwrap(); // sparse: 10 GiB that take no disk
        let err = read_manifest(&big).unwrap_err().to_string();
        assert!(
            err.contains("batch manifest") && err.contains("big.toml"),
            "{err}"
        );
        let bad = tmp.path().join("bad.toml");
        std::fs::write(&bad, b"[[job]]\ncommand = \"bin\"\ntimeout = \"soon\"\n").unwrap();
        let err = read_manifest(&bad).unwrap_err().to_string();
        assert!(err.contains("timeout") && err.contains("soon"), "{err}");
        assert!(t.elapsed() < Duration::from_secs(1));
    }
}
