//! `scatterscope batch`: a 20-job manifest (simulations, reconstructions,
//! binning PTU files, one bad input) run by the local pool with jobs
//! overlapping, a killed run resumed with only the missing jobs run, the
//! bad job failing alone with its error in the summary; and the same
//! manifest as a Slurm job array on the cluster this machine runs
//! (`scripts/slurm_local.sh`), its outputs equal to the local run's bit for
//! bit. Where no cluster answers, that test says why and skips.

#[path = "common/bench_images.rs"]
mod bench_images;
#[path = "common/command.rs"]
mod command;
use bench_images::{QUICK_BENCH_FLAGS, small_image_set};
use command::{run, text};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use scatterscope::events::Tag;
use scatterscope::formats::picoquant::records::RecordType;
use scatterscope::formats::picoquant::writer::{PtuWriter, WriterHeader};

/// A small T3 file: `n` photons on two channels.
fn write_ptu(path: &Path, n: u64, seed: u64) {
    let h = WriterHeader {
        resolution_s: 16e-12,
        sync_rate_hz: 20e6,
        device: "TestHarp".into(),
        imaging: None,
        extra: Vec::new(),
    };
    let mut w = PtuWriter::create(path, RecordType::GenericT3, &h).unwrap();
    let mut state = seed | 1;
    for i in 0..n {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        w.write_tag(Tag::Photon {
            channel: (state % 2) as u16,
            macro_time: i * 3,
            micro_time: (state >> 8) as u32 % 3000,
        })
        .unwrap();
    }
    w.finish().unwrap();
}

/// The manifest: 8 simulations, 8 reconstructions of pre-made stacks, 3
/// binned PTUs, 1 bin of a missing file.
fn manifest(dir: &Path) -> PathBuf {
    let data = dir.join("data");
    std::fs::create_dir_all(&data).unwrap();
    let mut m = String::new();
    for i in 0..8 {
        m.push_str(&format!(
            "[[job]]\nname = \"sim-{i}\"\ncommand = \"simulate\"\nargs = [\"--scene\", \"disks\", \"--size\", \"48\", \"--seed\", \"{i}\"]\n\n"
        ));
    }
    for i in 0..8 {
        let stack = data.join(format!("counts-{i}"));
        let o = run(&[
            "simulate",
            "--scene",
            "text",
            "--size",
            "48",
            "--seed",
            &i.to_string(),
            "--out",
            stack.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", text(&o));
        m.push_str(&format!(
            "[[job]]\nname = \"rec-{i}\"\ncommand = \"reconstruct\"\ninput = \"data/counts-{i}/counts.exr\"\nargs = [\"--method\", \"rl-stack\"]\n\n"
        ));
    }
    for i in 0..3 {
        write_ptu(&data.join(format!("tags-{i}.ptu")), 200_000, i + 1);
        m.push_str(&format!(
            "[[job]]\nname = \"bin-{i}\"\ncommand = \"bin\"\ninput = \"data/tags-{i}.ptu\"\nargs = [\"--pixels\", \"channel\"]\n\n"
        ));
    }
    m.push_str("[[job]]\nname = \"bad\"\ncommand = \"bin\"\ninput = \"data/missing.ptu\"\n");
    let path = dir.join("manifest.toml");
    std::fs::write(&path, m).unwrap();
    path
}

fn record(out: &Path, name: &str) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(out.join(name).join("batch.json")).unwrap())
        .unwrap()
}

/// The files each kind of job writes that must agree bit for bit.
fn outputs(name: &str) -> &'static [&'static str] {
    match name.split('-').next().unwrap() {
        "sim" => &["counts.exr", "expected.exr", "truth.exr"],
        "rec" => &["reconstruction.exr"],
        "bin" => &["stack.exr"],
        _ => &[],
    }
}

fn names() -> Vec<String> {
    (0..8)
        .map(|i| format!("sim-{i}"))
        .chain((0..8).map(|i| format!("rec-{i}")))
        .chain((0..3).map(|i| format!("bin-{i}")))
        .collect()
}

#[test]
fn a_killed_batch_resumes_with_only_the_missing_jobs_and_a_bad_job_fails_alone() {
    let dir = tempfile::tempdir().unwrap();
    let manifest = manifest(dir.path());
    let out = dir.path().join("out");
    let args = [
        "batch",
        manifest.to_str().unwrap(),
        "--workers",
        "2",
        "--out",
        out.to_str().unwrap(),
    ];
    // Start, and kill the batch once a few jobs have finished.
    let mut child = command::scatterscope()
        .args(args)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    let finished = |out: &Path| {
        names()
            .iter()
            .filter(|n| out.join(n).join("batch.json").exists())
            .count()
    };
    while finished(&out) < 3 && t0.elapsed() < Duration::from_secs(120) {
        std::thread::sleep(Duration::from_millis(20));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    let before: Vec<String> = names()
        .into_iter()
        .filter(|n| out.join(n).join("batch.json").exists())
        .collect();
    assert!(
        !before.is_empty() && before.len() < 19,
        "killed with {} jobs done",
        before.len()
    );
    let stamps: Vec<f64> = before
        .iter()
        .map(|n| record(&out, n)["started_unix_s"].as_f64().unwrap())
        .collect();
    // Resume.
    let o = run(&args);
    let all = text(&o);
    assert!(!o.status.success(), "the bad job fails the batch: {all}");
    for (n, s) in before.iter().zip(&stamps) {
        assert_eq!(
            record(&out, n)["started_unix_s"].as_f64().unwrap(),
            *s,
            "{n} was done before the kill and must not run again"
        );
        assert!(
            all.contains(&format!("| {n} | ok (earlier run) |")),
            "{all}"
        );
    }
    for n in names() {
        let r = record(&out, &n);
        assert_eq!(r["status"], "ok", "{n}: {r}");
        for f in outputs(&n) {
            assert!(out.join(&n).join(f).exists(), "{n}/{f}");
        }
    }
    let bad = record(&out, "bad");
    assert_eq!(bad["status"], "failed");
    assert!(
        bad["result"].as_str().unwrap().contains("missing.ptu"),
        "{bad}"
    );
    assert!(all.contains("| bad | failed |"), "{all}");
    assert!(
        record(&out, "rec-0")["result"]
            .as_str()
            .unwrap()
            .starts_with("method rl-stack, objective"),
        "the summary's key result of a reconstruction"
    );
    // Both workers busy: some jobs of the resumed run overlap in time.
    let spans: Vec<(f64, f64)> = names()
        .iter()
        .filter(|n| !before.contains(n))
        .map(|n| {
            let r = record(&out, n);
            let s = r["started_unix_s"].as_f64().unwrap();
            (s, s + r["seconds"].as_f64().unwrap())
        })
        .collect();
    let overlapping = spans
        .iter()
        .enumerate()
        .any(|(i, a)| spans[i + 1..].iter().any(|b| a.0 < b.1 && b.0 < a.1));
    assert!(
        overlapping,
        "two workers run jobs at the same time: {spans:?}"
    );
    assert!(out.join("summary.md").exists());
}

/// `batch` on a manifest of `body` (dir/m.toml) into dir/out.
fn run_manifest(dir: &Path, body: &str) -> (std::process::Output, PathBuf) {
    let path = dir.join("m.toml");
    std::fs::write(&path, body).unwrap();
    let out = dir.join("out");
    let o = run(&[
        "batch",
        path.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    (o, out)
}

#[test]
fn a_manifest_with_mistakes_is_refused_naming_them() {
    let dir = tempfile::tempdir().unwrap();
    for (body, words) in [
        ("", "missing field `job`"),
        (
            "[[job]]\ncommand = \"bin\"\nflags = 1\n",
            "unknown field `flags`",
        ),
        (
            "[[job]]\nname = \"a\"\ncommand = \"psf\"\n[[job]]\nname = \"a\"\ncommand = \"psf\"\n",
            "used twice",
        ),
        (
            "[[job]]\ncommand = \"batch\"\n",
            "not a scatterscope command",
        ),
        (
            "[[job]]\ncommand = \"psf\"\nargs = [\"--out\", \"x\"]\n",
            "--out is set by the batch",
        ),
        (
            "[[job]]\nname = \"../up\"\ncommand = \"psf\"\n",
            "plain folder name",
        ),
        // Checked as the command line checks them, before any job runs.
        (
            "[[job]]\nname = \"ok\"\ncommand = \"psf\"\n[[job]]\nname = \"typo\"\ncommand = \"psf\"\nargs = [\"--mu-z\", \"1\"]\n",
            "job `typo` (psf): unexpected argument '--mu-z'",
        ),
        (
            "[[job]]\nname = \"ok\"\ncommand = \"psf\"\n[[job]]\nname = \"lab\"\ncommand = \"acquire\"\nargs = [\"--device\", \"mock\", \"--sync-level\", \"-50\"]\n",
            "job `lab` (acquire): --sync-level set a PicoQuant device",
        ),
    ] {
        let (o, out) = run_manifest(dir.path(), body);
        assert!(!o.status.success());
        assert!(!out.exists(), "{words}: a job ran");
        assert!(
            text(&o).contains(words) && text(&o).contains("m.toml"),
            "{words}: {}",
            text(&o)
        );
    }
}

#[test]
fn a_file_an_earlier_job_writes_is_not_looked_for_before_the_jobs_run() {
    let dir = tempfile::tempdir().unwrap();
    let (o, out) = run_manifest(
        dir.path(),
        "[[job]]\nname = \"scan\"\ncommand = \"acquire\"\nargs = [\"--irf-from\", \"written-by-an-earlier-job.sstags\"]\n",
    );
    // The job ran (and failed alone: no earlier job wrote the file).
    assert!(!o.status.success());
    let log = std::fs::read_to_string(out.join("scan").join("job.log")).unwrap();
    assert!(log.contains("written-by-an-earlier-job.sstags"), "{log}");
    // A job asking for its command's help is not a refused command line.
    let (o, out) = run_manifest(
        dir.path(),
        "[[job]]\nname = \"help\"\ncommand = \"psf\"\nargs = [\"--help\"]\n",
    );
    let log = std::fs::read_to_string(out.join("help").join("job.log")).unwrap();
    assert!(
        o.status.success() && log.contains("Usage:"),
        "{}\n{log}",
        text(&o)
    );
}

/// Whether a Slurm cluster answers here; else why not.
fn slurm_ready() -> Result<(), String> {
    let sinfo = Command::new("sinfo").args(["-h", "-o", "%T"]).output();
    match sinfo {
        Err(e) => Err(format!("sinfo not found ({e}): no Slurm on this machine")),
        Ok(o) if !o.status.success() => Err(format!(
            "sinfo failed: {}",
            String::from_utf8_lossy(&o.stderr).trim()
        )),
        Ok(o) => {
            let states = String::from_utf8_lossy(&o.stdout).to_string();
            if states.contains("idle") || states.contains("mix") || states.contains("alloc") {
                Ok(())
            } else {
                Err(format!("no node is up (sinfo: {})", states.trim()))
            }
        }
    }
}

#[test]
fn the_same_manifest_as_a_slurm_array_gives_the_local_runs_outputs() {
    if let Err(why) = slurm_ready() {
        // CI starts a cluster before the tests: there a missing one is a
        // failure, not a skip; on a user's machine it is a skip.
        assert!(
            std::env::var("CI").as_deref() != Ok("true"),
            "CI=true but no Slurm cluster answers: {why}"
        );
        eprintln!("skipped: {why} (start one with `bash scripts/slurm_local.sh`)");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let manifest = manifest(dir.path());
    let local = dir.path().join("local");
    let slurm = dir.path().join("slurm");
    let m = manifest.to_str().unwrap();
    let o = run(&["batch", m, "--out", local.to_str().unwrap()]);
    assert!(!o.status.success(), "the bad job fails: {}", text(&o));
    let o = run(&[
        "batch",
        m,
        "--slurm",
        "--wait",
        "--out",
        slurm.to_str().unwrap(),
    ]);
    let all = text(&o);
    assert!(
        all.contains("submitted") && all.contains("20 array tasks"),
        "{all}"
    );
    let c = run(&["batch", m, "--collect", "--out", slurm.to_str().unwrap()]);
    let collected = text(&c);
    for n in names() {
        assert!(collected.contains(&format!("| {n} | ok |")), "{collected}");
        if n.starts_with("rec") {
            // The key result of the others holds their run times.
            assert_eq!(
                record(&slurm, &n)["result"],
                record(&local, &n)["result"],
                "{n}"
            );
        }
        for f in outputs(&n) {
            let a = std::fs::read(local.join(&n).join(f)).unwrap();
            let b = std::fs::read(slurm.join(&n).join(f)).unwrap();
            assert!(
                a == b,
                "{n}/{f} differs between the local and the Slurm run"
            );
        }
    }
    assert!(collected.contains("| bad | failed |"), "{collected}");
    assert_eq!(
        record(&slurm, "bad")["result"],
        record(&local, "bad")["result"]
    );
    assert!(slurm.join("batch.sbatch").exists());
}

#[test]
fn bench_recon_as_a_batch_gives_the_single_runs_rows() {
    let dir = tempfile::tempdir().unwrap();
    let images = small_image_set(dir.path());
    let flags = QUICK_BENCH_FLAGS;
    let bench = |extra: &[&str]| {
        let mut args = vec!["bench-recon", images.to_str().unwrap()];
        args.extend_from_slice(&flags);
        args.extend_from_slice(extra);
        let o = run(&args);
        assert!(o.status.success(), "{extra:?}: {}", text(&o));
    };
    let single = dir.path().join("single");
    bench(&["--out", single.to_str().unwrap()]);
    let manifest = dir.path().join("bench.toml");
    let batched = dir.path().join("batched");
    bench(&["--write-batch", manifest.to_str().unwrap()]);
    let o = run(&[
        "batch",
        manifest.to_str().unwrap(),
        "--out",
        batched.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    bench(&["--merge", "--out", batched.to_str().unwrap()]);
    // Every column but the wall time (the 8th) agrees.
    let strip = |path: &Path| -> Vec<String> {
        std::fs::read_to_string(path)
            .unwrap()
            .lines()
            .map(|l| {
                let mut f: Vec<&str> = l.split(',').collect();
                f.remove(7);
                f.join(",")
            })
            .collect()
    };
    let a = strip(&single.join("rows.csv"));
    let b = strip(&batched.join("rows.csv"));
    assert!(a.len() > 10, "{a:?}");
    assert_eq!(a, b);
    assert!(batched.join("summary.md").exists());
}

/// Processes whose command line mentions `needle` (Linux's /proc).
fn processes_mentioning(needle: &str) -> Vec<String> {
    let mut found = Vec::new();
    for entry in std::fs::read_dir("/proc").unwrap().flatten() {
        if let Ok(cmd) = std::fs::read(entry.path().join("cmdline")) {
            let cmd = String::from_utf8_lossy(&cmd).replace('\0', " ");
            if cmd.contains(needle) && cmd.contains("acquire") {
                found.push(cmd);
            }
        }
    }
    found
}

#[cfg(target_os = "linux")]
#[test]
fn a_job_past_its_time_limit_and_a_stopped_batch_end_their_jobs_and_say_so() {
    let dir = tempfile::tempdir().unwrap();
    let acquire = "command = \"acquire\"\nargs = [\"--device\", \"mock\", \"--duration\", \"60s\", \"--size\", \"16\"]\n";
    let m = dir.path().join("slow.toml");
    std::fs::write(
        &m,
        format!("[[job]]\nname = \"slow\"\ntimeout = \"1s\"\n{acquire}"),
    )
    .unwrap();
    let out = dir.path().join("timed");
    let t = Instant::now();
    let o = run(&["batch", m.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert!(t.elapsed() < Duration::from_secs(30), "{:?}", t.elapsed());
    assert!(!o.status.success(), "{}", text(&o));
    let r = record(&out, "slow");
    assert_eq!(r["status"], "timeout", "{r}");
    // The job was asked to stop (SIGTERM): an acquisition saves what it
    // received and exits 3.
    assert_eq!(r["exit_code"], 3, "{r}");
    assert!(out.join("slow").join("stack.exr").exists());
    assert!(text(&o).contains("| slow | timeout |"), "{}", text(&o));

    // SIGTERM to the batch reaches the running job; nothing is left running.
    let m = dir.path().join("long.toml");
    std::fs::write(&m, format!("[[job]]\nname = \"long\"\n{acquire}")).unwrap();
    let out = dir.path().join("stopped");
    let mut child = command::scatterscope()
        .args(["batch", m.to_str().unwrap(), "--out", out.to_str().unwrap()])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let needle = out.to_str().unwrap().to_string();
    let t = Instant::now();
    while processes_mentioning(&needle).is_empty() && t.elapsed() < Duration::from_secs(20) {
        std::thread::sleep(Duration::from_millis(50));
    }
    std::thread::sleep(Duration::from_millis(500));
    // SAFETY: kill(2) on our own child.
    unsafe { libc::kill(child.id() as i32, libc::SIGTERM) };
    let status = child.wait().unwrap();
    assert_eq!(
        status.code(),
        Some(3),
        "the batch itself ends as interrupted"
    );
    assert!(t.elapsed() < Duration::from_secs(30));
    let r = record(&out, "long");
    assert_eq!(r["status"], "interrupted", "{r}");
    assert_eq!(r["exit_code"], 3, "{r}");
    assert!(
        processes_mentioning(&needle).is_empty(),
        "orphans: {:?}",
        processes_mentioning(&needle)
    );
}
