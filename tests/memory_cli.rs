//! The command line asked for more memory than it may have, in every way
//! a bad-input campaign found: a huge `.npy` stack, a forged EXR header, a
//! huge sensor, whole-file reads of special files. Each ends in under
//! 10 s with exit status 1 and an error naming the problem, with and
//! without an address-space limit of 4 GB (`ulimit -v`), and no run's
//! peak memory reaches 1 GB.

#[path = "common/command.rs"]
mod command;
#[path = "common/forged.rs"]
mod forged;

use std::process::{Command, Output};
use std::time::{Duration, Instant};

use forged::{forged_exr, forged_npy};

/// Runs the binary, under `ulimit -v 4 GB` when `limited`.
fn run(args: &[&str], limited: bool) -> (Output, Duration) {
    let mut cmd = if limited {
        let mut c = Command::new("bash");
        c.args([
            "-c",
            "ulimit -v 4194304 && exec \"$0\" \"$@\"",
            command::PROGRAM,
        ]);
        c
    } else {
        command::scatterscope()
    };
    let start = Instant::now();
    let out = cmd
        .args(args)
        .env_remove("SCATTERSCOPE_MEMORY_LIMIT")
        .output()
        .unwrap();
    (out, start.elapsed())
}

#[test]
fn every_way_to_ask_for_too_much_memory_ends_quickly_with_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let d = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    forged_npy(&dir.path().join("big.npy"), "<f4", &[20, 32768, 32768]);
    forged_exr(&dir.path().join("forged.exr"), 131_072, 131_072, 17 << 20);
    // A small stack and image for the reads that need one.
    let o = command::simulate_disks(&dir.path().join("sim"), 32, &[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stack = d("sim/counts.exr");
    let png = d("sim/truth.png");
    let out = d("out");
    let (big, forged, denoised) = (d("big.npy"), d("forged.exr"), d("d.png"));
    let cases: Vec<(Vec<&str>, Vec<&str>)> = vec![
        (
            vec!["reconstruct", &big, "--out", &out],
            vec!["big.npy", "budget"],
        ),
        (
            vec!["reconstruct", &forged, "--out", &out],
            vec!["forged.exr"],
        ),
        (
            vec!["psf", "--size", "20000", "--out", &out],
            vec!["20000 x 20000", "budget"],
        ),
        (
            vec!["simulate", "--size", "32768", "--out", &out],
            vec!["32768 x 32768", "budget"],
        ),
        (
            vec!["simulate", "--config", "/dev/zero", "--out", &out],
            vec!["/dev/zero", "character device"],
        ),
        (
            vec![
                "simulate",
                "--scene",
                "/dev/zero",
                "--size",
                "32",
                "--out",
                &out,
            ],
            vec!["/dev/zero", "character device"],
        ),
        (
            vec!["reconstruct", &stack, "--truth", "/dev/zero", "--out", &out],
            vec!["/dev/zero", "character device"],
        ),
        (
            vec![
                "denoise",
                &png,
                "--sigma",
                "0.1",
                "--weights",
                "/dev/zero",
                "--out",
                &denoised,
            ],
            vec!["/dev/zero", "character device"],
        ),
        (
            vec!["denoise", "/dev/zero", "--sigma", "0.1", "--out", &denoised],
            vec!["/dev/zero", "character device"],
        ),
    ];
    for limited in [false, true] {
        for (args, want) in &cases {
            let (o, took) = run(args, limited);
            let stderr = String::from_utf8_lossy(&o.stderr);
            assert_eq!(
                o.status.code(),
                Some(1),
                "{args:?} (ulimit {limited}): {stderr}"
            );
            assert!(
                want.iter().all(|w| stderr.contains(w)),
                "{args:?} (ulimit {limited}): {stderr}"
            );
            assert!(took < Duration::from_secs(10), "{args:?} took {took:?}");
        }
    }
    // The largest resident set of any of them (kilobytes on Linux).
    let usage =
        nix::sys::resource::getrusage(nix::sys::resource::UsageWho::RUSAGE_CHILDREN).unwrap();
    assert!(
        usage.max_rss() < 1 << 20,
        "a run's peak resident memory was {} KiB",
        usage.max_rss()
    );
}
