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
