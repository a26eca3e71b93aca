//! The cases a bad-input campaign found where the output did not say what
//! happened: each now says it, or refuses.

#[path = "common/command.rs"]
mod command;
use command::{SMALL_SENSOR, run_isolated, simulate_disks, streams};

/// A simulated 32 x 32 stack in `dir/sim`; returns its counts file.
fn small_stack(dir: &std::path::Path) -> String {
    let sim = dir.join("sim");
    let o = simulate_disks(&sim, 32, &[]);
    assert!(o.status.success(), "{}", streams(&o).1);
    sim.join("counts.exr").to_str().unwrap().to_string()
}

#[test]
fn an_acquisition_that_receives_nothing_fails() {
    let dir = tempfile::tempdir().unwrap();
    // Every batch's frame corrupted: the host accepts none.
    let out = dir.path().join("acq");
    let run = [
        "--unpaced",
        "--max-photons",
        "50000",
        "--faults",
        "corrupt=1",
        "--out",
        out.to_str().unwrap(),
    ];
    let o = run_isolated(&[&["acquire"][..], &SMALL_SENSOR, &run].concat());
    let (stdout, stderr) = streams(&o);
    assert_eq!(o.status.code(), Some(1), "{stdout}\n{stderr}");
    assert!(
        stderr.contains("no photon was received from the device"),
        "{stderr}"
    );
    // What was (not) received is still written and said.
    assert!(dir.path().join("acq/acquisition.json").is_file());
}

#[test]
fn a_calibration_the_data_cannot_determine_writes_nothing_and_fails() {
    let dir = tempfile::tempdir().unwrap();
    let stack = small_stack(dir.path());
    // One photon in the whole stack.
    let mut s = scatterscope::Stack::load(std::path::Path::new(&stack)).unwrap();
    s.data.fill(0.0);
    s.data[[3, 16, 16]] = 1.0;
    let one = dir.path().join("one.exr");
    s.save(&one).unwrap();
    let out = dir.path().join("cal");
    let o = run_isolated(&[
        "calibrate",
        one.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let (stdout, stderr) = streams(&o);
    assert_eq!(o.status.code(), Some(1), "{stdout}\n{stderr}");
    assert!(
        stderr.contains("determine none of the fitted parameters"),
        "{stderr}"
    );
    assert!(!out.join("physics.toml").exists());
}

#[test]
fn settings_that_are_not_numbers_or_absurd_are_refused_with_their_flag() {
    let dir = tempfile::tempdir().unwrap();
    let stack = small_stack(dir.path());
    let out = dir.path().join("rec");
    for (flag, value, want) in [
        (
            "--residual-tol",
            "NaN",
            "residual_tol = NaN must be a number >= 0",
        ),
        (
            "--warm-start",
            "1000000000",
            "warm_start = 1000000000 must be at most 100000",
        ),
        ("--rho", "inf", "rho = inf must be a positive number"),
        // A flag spelled otherwise than its setting: found by its id.
        (
            "--lbfgs-tol",
            "NaN",
            "lbfgs_grad_tol = NaN must be a number >= 0",
        ),
    ] {
        let o = run_isolated(&[
            "reconstruct",
            &stack,
            flag,
            value,
            "--out",
            out.to_str().unwrap(),
        ]);
        let (_, stderr) = streams(&o);
        assert_eq!(o.status.code(), Some(1), "{flag} {value}: {stderr}");
        assert!(stderr.contains(want), "{stderr}");
        assert!(
            stderr.contains(&format!("hint: set it with {flag}")),
            "{stderr}"
        );
    }
}

#[test]
fn a_truth_of_another_size_is_said_to_be_resampled() {
    let dir = tempfile::tempdir().unwrap();
    let stack = small_stack(dir.path());
    let truth = dir.path().join("big_truth.png");
    let img = ndarray::Array2::from_shape_fn((48, 48), |(r, c)| ((r + c) % 7) as f64 / 7.0);
    scatterscope::formats::image::write_image(img.view(), &truth).unwrap();
    let o = run_isolated(&[
        "reconstruct",
        &stack,
        "--method",
        "rl-sum",
        "--truth",
        truth.to_str().unwrap(),
        "--out",
        dir.path().join("rec").to_str().unwrap(),
    ]);
    let (stdout, stderr) = streams(&o);
    assert!(o.status.success(), "{stderr}");
    assert!(
        stderr.contains("big_truth.png is 48 x 48 pixels; resampled to the 32 x 32 sensor"),
        "{stderr}"
    );
    assert!(stdout.contains("output PSNR"), "{stdout}");
}

#[test]
fn a_memory_limit_that_is_not_a_size_is_refused() {
    let o = run_isolated(&["psf", "--memory-limit", "lots", "--out", "/tmp/none"]);
    assert_eq!(o.status.code(), Some(2), "{}", streams(&o).1);
    let o = command::scatterscope()
        .args(["psf", "--out", "/tmp/scatterscope-psf-limit"])
        .env("SCATTERSCOPE_MEMORY_LIMIT", "1MB")
        .output()
        .unwrap();
    let (_, stderr) = streams(&o);
    assert_eq!(o.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("more than the budget of 976.6 KiB (SCATTERSCOPE_MEMORY_LIMIT)")
            && stderr.contains("hint: --memory-limit"),
        "{stderr}"
    );
}
