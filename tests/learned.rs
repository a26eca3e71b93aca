//! The learned reconstruction: the unrolled network on the project's engine
//! against PyTorch's output on fixtures (`training/learned_reference.py`:
//! a small random network and the embedded weights, on one small simulated
//! case, the data steps included), its weight file's checks, and the
//! method through the command line.

#[path = "common/command.rs"]
mod command;

use std::path::Path;

use ndarray::Array2;
use ndarray_npy::ReadNpyExt;
use scatterscope::reconstruct::learned::inputs::learned_inputs;
use scatterscope::reconstruct::learned::net::LearnedNet;
use scatterscope::reconstruct::learned::network_estimate;

fn fixture(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/learned")
        .join(name)
}

/// The fixtures' case: a 32-pixel sensor at the paper's pitch over the
/// committed object, simulated as the trainer simulates (seed 5).
fn fixture_case() -> scatterscope::report::bench::BenchCase {
    let object =
        Array2::<f64>::read_npy(std::fs::File::open(fixture("object.npy")).unwrap()).unwrap();
    let mut setup = scatterscope::Preset::Paper.setup();
    setup.sensor.width_px = 32;
    setup.sensor.height_px = 32;
    setup.sensor.fov_cm = 50.0 * 32.0 / 256.0;
    scatterscope::report::bench::simulate_object(object, &setup, 5, &Default::default()).unwrap()
}

/// The network's output on the fixture case, on the sensor.
fn network_output(net: &LearnedNet) -> Array2<f64> {
    let case = fixture_case();
    let bins = case.problem.all_bins();
    let model = &case.problem.model;
    let data = scatterscope::reconstruct::Data::new(model, &case.problem.counts, &bins).unwrap();
    let inputs = learned_inputs(&data).unwrap();
    let grid = network_estimate(net, &data, &inputs);
    Array2::from_shape_vec(model.sensor_shape(), model.crop_vec(&grid)).unwrap()
}

fn relative_error(a: &Array2<f64>, b: &Array2<f64>) -> f64 {
    let top = b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    a.iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
        / top
}

#[test]
fn the_network_matches_pytorch_on_fixtures() {
    let small = LearnedNet::from_bytes(
        &std::fs::read(fixture("small.safetensors")).unwrap(),
        "small.safetensors",
    )
    .unwrap();
    assert_eq!(small.channels, [4, 6, 8]);
    assert_eq!((small.stages, small.em_steps), (2, 2));
    let want =
        Array2::<f64>::read_npy(std::fs::File::open(fixture("small_output.npy")).unwrap()).unwrap();
    let got = network_output(&small);
    assert_eq!(got.dim(), (32, 32));
    let e = relative_error(&got, &want);
    assert!(e < 1e-4, "{e}");
    let want =
        Array2::<f64>::read_npy(std::fs::File::open(fixture("embedded_output.npy")).unwrap())
            .unwrap();
    let got = network_output(scatterscope::reconstruct::learned::embedded());
    let e = relative_error(&got, &want);
    assert!(e < 1e-4, "{e}");
}

#[test]
fn a_weight_file_of_another_kind_is_refused_by_name() {
    let bytes = std::fs::read(fixture("small.safetensors")).unwrap();
    // The FFDNet prior's weights are safetensors too, of another format.
    let ffdnet = std::fs::read(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("weights/ffdnet-gray-small.safetensors"),
    )
    .unwrap();
    let e = LearnedNet::from_bytes(&ffdnet, "ffdnet.safetensors").unwrap_err();
    assert!(
        e.to_string()
            .contains("ffdnet.safetensors: metadata field `format`"),
        "{e}"
    );
    let e = LearnedNet::from_bytes(&bytes[..bytes.len() - 10], "cut.safetensors").unwrap_err();
    assert!(e.to_string().contains("cut.safetensors"), "{e}");
    // Outside the trained ranges, by name.
    let small = LearnedNet::from_bytes(&bytes, "small").unwrap();
    assert_eq!(small.outside(5.0, 5.0, 0.0), None);
    let why = small.outside(100.0, 5.0, 0.0).unwrap();
    assert!(why.contains("100.000 photons per pixel"), "{why}");
    let why = small.outside(5.0, 30.0, 0.0).unwrap();
    assert!(why.contains("blur of 30.00 px"), "{why}");
}

/// Weights a user trained are read from a file (`--learned-weights`): a
/// copy of the embedded weights reconstructs exactly as the embedded
/// network does, another network's file differently, `weights show` prints what the file says it was trained
/// on, and a cut file is refused naming it, with nothing written.
#[test]
fn weights_a_user_trained_are_read_from_a_file() {
    let dir = tempfile::tempdir().unwrap();
    // The paper's pixel pitch (50 cm over 256 pixels), inside the
    // network's trained blur widths.
    let sim = dir.path().join("sim");
    let o = command::run_isolated(&[
        "simulate",
        "--scene",
        "disks",
        "--size",
        "32",
        "--fov",
        "6.25",
        "--seed",
        "4",
        "--out",
        sim.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", command::streams(&o).1);
    let stack = sim.join("counts.exr");
    let embedded =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("weights/learned-unrolled.safetensors");
    let copy = dir.path().join("mine.safetensors");
    std::fs::copy(&embedded, &copy).unwrap();
    let reconstruct = |out: &str, weights: Option<&Path>| {
        let out = dir.path().join(out);
        let mut args = vec![
            "reconstruct".to_string(),
            stack.to_str().unwrap().into(),
            "--method".into(),
            "learned".into(),
            "--out".into(),
            out.to_str().unwrap().into(),
        ];
        if let Some(w) = weights {
            args.extend(["--learned-weights".into(), w.to_str().unwrap().into()]);
        }
        (command::run_isolated(&args), out)
    };
    let (o, by_embedded) = reconstruct("embedded", None);
    assert!(o.status.success(), "{}", command::streams(&o).1);
    let (o, by_file) = reconstruct("file", Some(&copy));
    let (stdout, stderr) = command::streams(&o);
    assert!(o.status.success(), "{stderr}");
    assert!(stdout.contains("learned: Richardson-Lucy"), "{stdout}");
    let read = |d: &Path| std::fs::read(d.join("reconstruction.exr")).unwrap();
    assert_eq!(read(&by_embedded), read(&by_file));
    // Another network's file is the one used: the fixtures' small network
    // was trained on other ranges, which this stack lies outside.
    let (o, by_small) = reconstruct("small", Some(&fixture("small.safetensors")));
    let (stdout, stderr) = command::streams(&o);
    assert!(o.status.success(), "{stderr}");
    assert!(
        stdout.contains("the stack lies outside what the network was trained on"),
        "{stdout}"
    );
    assert_ne!(read(&by_embedded), read(&by_small));

    let o = command::run_isolated(&["weights", "show", copy.to_str().unwrap()]);
    let (stdout, stderr) = command::streams(&o);
    assert!(o.status.success(), "{stderr}");
    assert!(
        stdout.starts_with("learned network: unrolled-em"),
        "{stdout}"
    );
    assert!(stdout.contains("  trained: trained here"), "{stdout}");

    let bytes = std::fs::read(&copy).unwrap();
    let cut = dir.path().join("cut.safetensors");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let (o, out) = reconstruct("cut", Some(&cut));
    assert!(!o.status.success());
    let stderr = command::streams(&o).1;
    assert!(stderr.contains(cut.to_str().unwrap()), "{stderr}");
    assert!(!out.exists(), "nothing is written for weights refused");
}
