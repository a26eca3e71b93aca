//! The library calls each command is built on, called directly as a user
//! of the library would: a plain array made ready to reconstruct, an
//! acquisition on the mock, a recorded file surveyed and binned, single
//! images in and out, the ST-PSF report, and errors that name settings
//! rather than flags.

use std::sync::atomic::AtomicBool;

use ndarray::{Array2, Array3};
use ndarray_npy::WriteNpyExt;
use scatterscope::acquire::{DeviceSpec, Job, MockSpec, StreamPlan, TimeZero};
use scatterscope::config::PhysicsOverrides;
use scatterscope::formats::image::{read_image, write_image};
use scatterscope::formats::picoquant::writer::write_synthetic_t3;
use scatterscope::physics::{Preset, Sampling, Setup};
use scatterscope::psf::PsfReport;
use scatterscope::reconstruct::ReconstructError;
use scatterscope::reconstruct::input::{InputSpec, load};
use scatterscope::reconstruct::method::{Method, MethodOptions, run_method};
use scatterscope::scene::Scene;
use scatterscope::tags::bin_file::{BinOutputs, BinSpec, bin_file, bin_file_to};
use scatterscope::tags::recorded::survey;
use scatterscope::tags::survey::Survey;
use scatterscope::{Named, Stack};

/// The paper's physics on a small sensor.
fn small(size: usize) -> Setup {
    let mut s = Preset::Paper.setup();
    (s.sensor.width_px, s.sensor.height_px) = (size, size);
    s.sensor.fov_cm = 50.0 * size as f64 / 256.0;
    s
}

#[test]
fn a_plain_array_takes_its_physics_from_the_overrides_and_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("plain.npy");
    let counts = Array3::<f32>::from_shape_fn((8, 16, 16), |(k, r, c)| ((k + r + c) % 3) as f32);
    counts
        .write_npy(std::fs::File::create(&path).unwrap())
        .unwrap();
    let spec = InputSpec {
        physics: PhysicsOverrides {
            size: Some(16),
            fov: Some(50.0 * 16.0 / 256.0),
            bins: Some(8),
            t_start: Some(40.0),
            ..Default::default()
        },
        ..Default::default()
    };
    let input = load(&path, &spec).unwrap();
    assert_eq!(input.problem.counts.dim(), (8, 16, 16));
    assert_eq!(input.stack.meta.bin_starts_ps[0], 40.0);
    assert!(
        input.warnings[0].contains("plain.npy has no sidecar")
            && input.warnings[0].contains("8 consecutive bins of 4 ps from 40 ps"),
        "{:?}",
        input.warnings
    );
    assert!(input.assumed.iter().any(|a| a.starts_with("model: ")));
    // Without the sensor's size the array cannot match the physics.
    let err = load(&path, &InputSpec::default())
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("16 x 16 pixels"), "{err}");
}

#[test]
fn a_mock_acquisition_writes_its_stack_and_record_and_balances() {
    let dir = tempfile::tempdir().unwrap();
    let mock = MockSpec {
        scene: Scene::parse("disks"),
        real_time: false,
        max_photons: 200_000,
        ..MockSpec::default()
    };
    let setup = small(32);
    let mut plan = StreamPlan {
        tag_file: Some(dir.path().join("tags.sstags")),
        software: "entry-point test".into(),
        ..StreamPlan::default()
    };
    plan.set_window(&setup.bins);
    let job = Job {
        device: DeviceSpec::Mock(mock),
        setup: Some(setup),
        t0: TimeZero::At(0.0),
        plan,
        out: dir.path().join("acq"),
        ome_tiff: false,
    };
    let done = job.run(&AtomicBool::new(false), |_| {}).unwrap();
    done.verdict().unwrap();
    let acc = &done.outcome.ledger;
    assert_eq!(acc.counts.photons, 200_000);
    // Every file it lists exists, and the stack holds what was binned.
    for f in &done.files {
        assert!(f.is_file(), "{}", f.display());
    }
    let stack = Stack::load(&dir.path().join("acq/stack.exr")).unwrap();
    assert_eq!(stack.total() as u64, acc.counts.binned);
    assert!(done.summary().iter().any(|l| l.contains("200000 photons")));
    // The tag file reads back to the same stack.
    let binned = bin_file(
        &dir.path().join("tags.sstags"),
        &BinSpec {
            bin_width_ps: Some(stack.meta.bin_width_ps),
            t_start_ps: stack.meta.bin_starts_ps[0],
            bins: Some(stack.bins()),
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(binned.stacks[0].data, stack.data);
    // A sensor the protocol cannot address is refused before anything runs.
    let mut big = job.clone();
    big.setup = Some(small(300));
    let err = big.run(&AtomicBool::new(false), |_| {}).unwrap_err();
    assert!(err.to_string().contains("300 x 300 pixels"), "{err}");
}

#[test]
fn a_recorded_file_is_surveyed_binned_and_written() {
    let dir = tempfile::tempdir().unwrap();
    let ptu = dir.path().join("t3.ptu");
    write_synthetic_t3(&ptu, 5_000).unwrap();
    let Survey::PicoQuant(info, s) = survey(&ptu, &Default::default()).unwrap() else {
        panic!("a PTU file is PicoQuant's")
    };
    let photons: u64 = s.photons_per_channel.values().sum();
    assert_eq!(photons, 5_000);
    assert_eq!(info.records_present, info.records_announced);
    let binned = bin_file(&ptu, &BinSpec::default()).unwrap();
    assert_eq!(binned.counts.photons, photons);
    let written = bin_file_to(
        &ptu,
        &BinSpec::default(),
        &BinOutputs::new(dir.path().join("bin")),
    )
    .unwrap();
    let files = &written.stacks[0];
    let back = Stack::load(&files[0]).unwrap();
    assert_eq!(back.data, binned.stacks[0].data);
    assert_eq!(back.meta, binned.stacks[0].meta);
    assert_eq!(written.counts, binned.counts);
    assert!(dir.path().join("bin/stack.png").is_file());
}

#[test]
fn single_images_round_trip_in_every_format_and_bad_ones_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let img = Array2::from_shape_fn((5, 7), |(r, c)| (r * 7 + c) as f64 / 40.0);
    for ext in ["exr", "npy"] {
        let path = dir.path().join(format!("i.{ext}"));
        write_image(img.view(), &path).unwrap();
        let back = read_image(&path).unwrap();
        let err = back
            .iter()
            .zip(&img)
            .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        assert!(err < 1e-6, "{ext}: {err}");
    }
    // PNG keeps 8 bits.
    let png = dir.path().join("i.png");
    write_image(img.view(), &png).unwrap();
    let back = read_image(&png).unwrap();
    assert!(
        back.iter()
            .zip(&img)
            .all(|(a, b)| (a - b).abs() <= 0.5 / 255.0 + 1e-6)
    );
    let err = write_image(img.view(), &dir.path().join("i.tif"))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("i.tif") && err.contains("unknown extension `tif`"),
        "{err}"
    );
}

#[test]
fn the_psf_report_compares_both_discretisations_bin_by_bin() {
    let report = PsfReport::build(&small(32), Sampling::Integrated).unwrap();
    let point = report.point.as_ref().unwrap();
    let (lines, csv) = report.table();
    assert_eq!(lines.len(), 1 + report.integrated.bins.len());
    assert_eq!(csv.lines().count(), 1 + report.integrated.bins.len());
    // The difference, by hand, for the first kept bin.
    let index = report.integrated.kept_bins().next().unwrap().index;
    let (i, p) = (
        report.integrated.position_of_bin(index).unwrap(),
        point.position_of_bin(index).unwrap(),
    );
    let (a, b) = (report.integrated.kernel(i), point.kernel(p));
    let by_hand: f64 = a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum::<f64>() / a.sum();
    assert!((report.difference(index).unwrap() - by_hand).abs() < 1e-15);
}

#[test]
fn library_errors_name_settings_not_flags() {
    let mut opts = MethodOptions::default();
    opts.admm_lbfgs.primal_tol = f64::NAN;
    opts.admm_lbfgs.dual_tol = f64::NAN;
    let err = opts.validate().unwrap_err();
    assert!(
        matches!(
            err,
            ReconstructError::Setting {
                name: "residual_tol",
                ..
            }
        ),
        "{err}"
    );
    assert!(!err.to_string().contains("--"), "{err}");
    // The same check guards every run.
    let mut setup = small(16);
    setup.bins.count = 24;
    let sim = scatterscope::simulate::simulate(
        &setup,
        &Scene::parse("disks"),
        Sampling::Integrated,
        Default::default(),
        1,
    )
    .unwrap();
    let problem = scatterscope::Problem::new(
        &sim.counts,
        &setup,
        Sampling::Integrated,
        Default::default(),
    )
    .unwrap();
    let tv = scatterscope::denoise::tv::TotalVariation::default();
    for method in Method::ALL {
        let e = run_method(&problem, *method, Some(3), &tv, &opts, None, |_| {});
        assert!(e.is_err(), "{} ran with a NaN tolerance", method.name());
    }
}

/// The command line's flags are the library's settings types: given no
/// flag, each parses to the type's own default, the one a library user and
/// the Python package start from.
#[test]
fn each_settings_type_parsed_from_no_flag_is_its_default() {
    use clap::Parser;
    use scatterscope::acquire::request::Request;
    use scatterscope::denoise::prior::PriorSpec;
    use scatterscope::formats::becker_hickl::spc::SpcOptions;
    use scatterscope::reconstruct::admm_lbfgs::AdmmLbfgsOptions;
    use scatterscope::reconstruct::split::SplitOptions;
    use scatterscope::report::ReportSettings;
    use scatterscope::report::hidden::HiddenRequest;

    #[derive(clap::Parser)]
    struct Flags {
        #[command(flatten)]
        request: Request,
        #[command(flatten)]
        split: SplitOptions,
        #[command(flatten)]
        admm_lbfgs: AdmmLbfgsOptions,
        #[command(flatten)]
        spc: SpcOptions,
        #[command(flatten)]
        prior: PriorSpec,
    }
    #[derive(clap::Parser)]
    struct Report {
        #[command(flatten)]
        settings: ReportSettings,
    }
    #[derive(clap::Parser)]
    struct Hidden {
        #[command(flatten)]
        request: HiddenRequest,
    }
    let flags = Flags::try_parse_from(["scatterscope"]).unwrap();
    let mock = DeviceSpec::Mock(MockSpec::default());
    let request = Request::new(mock, "out/acquire".into());
    assert_eq!(format!("{:?}", flags.request), format!("{request:?}"));
    let split = format!("{:?}", SplitOptions::default());
    assert_eq!(format!("{:?}", flags.split), split);
    let admm_lbfgs = format!("{:?}", AdmmLbfgsOptions::default());
    assert_eq!(format!("{:?}", flags.admm_lbfgs), admm_lbfgs);
    assert_eq!(flags.spc, SpcOptions::default());
    assert_eq!(flags.prior, PriorSpec::default());
    let report = Report::try_parse_from(["x"]).unwrap().settings;
    assert_eq!(report, ReportSettings::default());
    let args = [
        "x",
        "s.mat",
        "--scan-side",
        "63.6cm",
        "--slab-thickness",
        "2.54cm",
    ];
    let hidden = Hidden::try_parse_from(args).unwrap().request;
    let request = HiddenRequest::new("s.mat".into(), 0.636, 2.54);
    assert_eq!(format!("{hidden:?}"), format!("{request:?}"));
    // A flag reaches its field.
    let flags = Flags::try_parse_from(["scatterscope", "--unpaced", "--prior-grid", "average"]);
    let flags = flags.unwrap();
    assert!(!flags.request.mock.real_time && flags.split.average_prior_grid);
    let report = Report::try_parse_from(["x", "--instrument", "realistic"]).unwrap();
    assert_eq!(report.settings.realistic_background(), Some(0.05));
}
