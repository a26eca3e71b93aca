//! The learned reconstruction: the network on the project's engine against
//! PyTorch's output on fixtures (`training/learned_reference.py`: a small
//! random network and the embedded weights, on an input of an odd size),
//! its weight file's checks, and the method through the command line.

#[path = "common/command.rs"]
mod command;

use std::path::Path;

use ndarray::{Array2, Array3};
use ndarray_npy::ReadNpyExt;
use scatterscope::reconstruct::learned::net::LearnedNet;

fn fixture(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/learned")
        .join(name)
}

fn max_error(a: &Array2<f32>, b: &Array2<f32>) -> f32 {
    a.iter().zip(b).fold(0.0, |m, (x, y)| m.max((x - y).abs()))
}

#[test]
fn the_network_matches_pytorch_on_fixtures() {
    let input =
        Array3::<f32>::read_npy(std::fs::File::open(fixture("input.npy")).unwrap()).unwrap();
    let small = LearnedNet::from_bytes(
        &std::fs::read(fixture("small.safetensors")).unwrap(),
        "small.safetensors",
    )
    .unwrap();
    assert_eq!(small.channels, [4, 6, 8]);
    let want =
        Array2::<f32>::read_npy(std::fs::File::open(fixture("small_output.npy")).unwrap()).unwrap();
    let got = small.forward(&input);
    assert_eq!(got.dim(), (21, 14));
    assert!(max_error(&got, &want) < 1e-4, "{}", max_error(&got, &want));
    let want =
        Array2::<f32>::read_npy(std::fs::File::open(fixture("embedded_output.npy")).unwrap())
            .unwrap();
    let got = scatterscope::reconstruct::learned::embedded().forward(&input);
    assert!(max_error(&got, &want) < 1e-4, "{}", max_error(&got, &want));
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
