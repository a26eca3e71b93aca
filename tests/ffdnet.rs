//! FFDNet: the Rust engine against PyTorch reference outputs, weight-file
//! validation, the legacy .pth importer, and the prior's behaviour on odd
//! sizes and out-of-range sigma.

#[path = "common/shared_data.rs"]
mod shared_data;

use std::collections::BTreeMap;
use std::path::Path;

use ndarray::{Array2, s};
use ndarray_npy::ReadNpyExt;
use scatterscope::denoise::Denoiser;
use scatterscope::denoise::ffdnet::weights::{Architecture, FfdnetWeights, to_safetensors};
use scatterscope::denoise::ffdnet::{Ffdnet, pth, source};

fn fixture(name: &str) -> Array2<f32> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/ffdnet")
        .join(name);
    Array2::<f32>::read_npy(std::fs::File::open(&p).unwrap()).unwrap()
}

fn max_abs_diff(a: &Array2<f32>, b: &Array2<f32>) -> f32 {
    assert_eq!(a.dim(), b.dim());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

#[test]
fn embedded_weights_match_pytorch_on_an_odd_sized_image() {
    let input = fixture("input.npy");
    assert_eq!(
        input.dim(),
        (37, 30),
        "odd height exercises the reflection padding"
    );
    let net = Ffdnet::new(source::embedded(), "embedded");
    let out = net.run(input.view(), 25.0 / 255.0);
    let d = max_abs_diff(&out, &fixture("embedded_sigma25.npy"));
    assert!(d < 1e-4, "max |Rust - PyTorch| = {d}");
    // And it denoises: the output differs from the input by about sigma.
    let rms = ((&out - &input).mapv(|v| v * v).mean().unwrap()).sqrt();
    assert!(
        rms > 0.5 * 25.0 / 255.0 && rms < 1.5 * 25.0 / 255.0,
        "removed rms {rms}"
    );
}

#[test]
#[ignore = "needs the original FFDNet weights (scripts/fetch_ffdnet_weights.sh)"]
fn imported_original_weights_match_pytorch() {
    let pth_path = shared_data::original_ffdnet_pth();
    let bytes = std::fs::read(&pth_path).unwrap();
    let converted = pth::import_ffdnet_gray(&bytes, &pth_path).unwrap();
    let w = FfdnetWeights::from_bytes(&converted, "imported").unwrap();
    assert_eq!(w.arch, Architecture::original());
    let net = Ffdnet::new(w, "imported");
    let out = net.run(fixture("input.npy").view(), 25.0 / 255.0);
    let d = max_abs_diff(&out, &fixture("original_sigma25.npy"));
    assert!(d < 1e-4, "max |Rust - PyTorch| = {d}");
}

#[test]
fn importer_refuses_damaged_and_foreign_files_with_the_path() {
    let path = Path::new("/data/weights.pth");
    let cases: Vec<(Vec<u8>, &str)> = vec![
        (b"PK\x03\x04rest of a zip".to_vec(), "zip-format"),
        (b"hello".to_vec(), "pickle at byte"),
        (Vec::new(), "file ends inside a pickle"),
    ];
    // Found by the `pth` fuzz target: values nested until the stack
    // overflowed (here 200 000 TUPLE1 opcodes), and memo copies doubling a
    // value 40 times (200 bytes that would build 2^40 values).
    let mut deep = b"\x80\x02N".to_vec();
    deep.extend(std::iter::repeat_n(0x85u8, 200_000));
    deep.push(b'.');
    let mut wide = b"\x80\x02N".to_vec();
    for _ in 0..40 {
        wide.extend_from_slice(b"q\x00h\x00h\x00\x86");
    }
    wide.push(b'.');
    // And a storage whose element count (2^62 - 1) overflowed the end
    // offset: a panic with overflow checks, a wrapped bound without.
    let huge = std::fs::read(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/fuzz/pth_storage_size_overflow.pth"),
    )
    .unwrap();
    let cases: Vec<(Vec<u8>, &str)> = cases
        .into_iter()
        .chain([
            (deep, "values nested 65 deep"),
            (wide, "memo copies would build over"),
            (huge, "4611686018427387903 elements run past the end"),
        ])
        .collect();
    for (bytes, want) in cases {
        let e = pth::import_ffdnet_gray(&bytes, path)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("/data/weights.pth: "), "{e}");
        assert!(e.contains(want), "{e}");
    }
}

#[test]
#[ignore = "needs the original FFDNet weights (scripts/fetch_ffdnet_weights.sh)"]
fn the_original_weights_cut_anywhere_are_an_error() {
    let path = Path::new("/data/weights.pth");
    let bytes = std::fs::read(shared_data::original_ffdnet_pth()).unwrap();
    // Cut anywhere: an error, never a panic or a partial network.
    for cut in [
        10,
        200,
        5_000,
        11_000,
        11_400,
        bytes.len() / 2,
        bytes.len() - 1,
    ] {
        let e = pth::import_ffdnet_gray(&bytes[..cut], path)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("/data/weights.pth: "), "cut {cut}: {e}");
    }
}

#[test]
fn weight_files_round_trip_and_mismatches_are_named() {
    let arch = Architecture {
        layers: 4,
        channels: 6,
        sigma_max: 0.3,
        batchnorm_eps: 1e-5,
    };
    let good = arch.stand_in_tensors();
    let none = BTreeMap::new();
    let bytes = to_safetensors(&arch, &good, &none, "test").unwrap();
    let w = FfdnetWeights::from_bytes(&bytes, "test").unwrap();
    assert_eq!(w.arch, arch);
    assert_eq!(w.layers.len(), 4);
    assert!(w.layers[0].bias.is_none() && w.layers[1].bias.is_some() && !w.layers[3].relu);

    let mut missing = good.clone();
    missing.remove("bn.2.running_var");
    let e = to_safetensors(&arch, &missing, &none, "w.safetensors")
        .unwrap_err()
        .to_string();
    assert_eq!(e, "w.safetensors: tensor `bn.2.running_var` is missing");

    let mut extra = good.clone();
    extra.insert("conv.9.weight".into(), vec![0.0; 4]);
    let e = to_safetensors(&arch, &extra, &none, "w")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("`conv.9.weight` is not part of a 4-layer, 6-channel FFDNet"),
        "{e}"
    );

    let mut nan = good.clone();
    nan.get_mut("conv.1.weight").unwrap()[5] = f32::NAN;
    let e = to_safetensors(&arch, &nan, &none, "w")
        .unwrap_err()
        .to_string();
    assert!(e.contains("`conv.1.weight` element 5 is NaN"), "{e}");

    // A file of another architecture: the metadata says 6 channels but the
    // tensors are for 8.
    let wider = Architecture {
        channels: 8,
        ..arch.clone()
    };
    let mut bytes8 = to_safetensors(&wider, &wider.stand_in_tensors(), &none, "w").unwrap();
    let header_len = u64::from_le_bytes(bytes8[..8].try_into().unwrap()) as usize;
    let header = String::from_utf8(bytes8[8..8 + header_len].to_vec()).unwrap();
    let lied = header.replace("\"channels\":\"8\"", "\"channels\":\"6\"");
    assert_ne!(lied, header);
    bytes8.splice(8..8 + header_len, lied.into_bytes());
    let e = FfdnetWeights::from_bytes(&bytes8, "w8")
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("w8: tensor `conv.0.weight` has shape [8, 5, 3, 3], expected [6, 5, 3, 3]"),
        "{e}"
    );

    let bad_meta = BTreeMap::from([("padding".to_string(), "zeros".to_string())]);
    let e = to_safetensors(&arch, &good, &bad_meta, "w")
        .unwrap_err()
        .to_string();
    assert_eq!(
        e,
        "w: metadata field `padding` is `zeros`, expected `reflect`"
    );

    let e = FfdnetWeights::from_bytes(b"not a weight file", "junk.bin")
        .unwrap_err()
        .to_string();
    assert!(e.starts_with("junk.bin: not a safetensors file"), "{e}");
}

#[test]
fn batchnorm_folding_matches_an_unfolded_reference_layer() {
    // One inner layer checked by hand at one pixel: conv, then BatchNorm.
    let arch = Architecture {
        layers: 3,
        channels: 2,
        sigma_max: 0.3,
        batchnorm_eps: 1e-5,
    };
    let t = arch.stand_in_tensors();
    let w = FfdnetWeights::from_bytes(
        &to_safetensors(&arch, &t, &BTreeMap::new(), "t").unwrap(),
        "t",
    )
    .unwrap();
    let l = &w.layers[1];
    let (cin, cout) = (2, 2);
    for co in 0..cout {
        let g = f64::from(t["bn.1.weight"][co]);
        let b = f64::from(t["bn.1.bias"][co]);
        let m = f64::from(t["bn.1.running_mean"][co]);
        let v = f64::from(t["bn.1.running_var"][co]);
        // Input: all ones in every tap and channel.
        let conv: f64 = t["conv.1.weight"][co * cin * 9..(co + 1) * cin * 9]
            .iter()
            .map(|&x| f64::from(x))
            .sum();
        let want = g * (conv - m) / (v + 1e-5).sqrt() + b;
        let folded: f64 = (0..9 * cin)
            .map(|k| f64::from(l.matrix[k * cout + co]))
            .sum::<f64>()
            + f64::from(l.bias.as_ref().unwrap()[co]);
        assert!(
            (want - folded).abs() < 1e-5,
            "channel {co}: {want} vs {folded}"
        );
    }
}

#[test]
fn odd_and_tiny_images_keep_their_shape_and_sigma_is_clamped() {
    let net = Ffdnet::new(source::embedded(), "embedded");
    for (h, w) in [(1, 1), (1, 7), (2, 3), (5, 1), (9, 11)] {
        let img = Array2::from_shape_fn((h, w), |(y, x)| ((y * 3 + x) % 5) as f32 / 4.0);
        let out = net.run(img.view(), 0.1);
        assert_eq!(out.dim(), (h, w));
        assert!(out.iter().all(|v| v.is_finite()), "{h}x{w}");
    }
    // An odd-sized image equals the crop of its reflection-padded version.
    let img = fixture("input.npy");
    let padded = Array2::from_shape_fn((38, 30), |(y, x)| img[[if y < 37 { y } else { 35 }, x]]);
    let a = net.run(img.view(), 0.1);
    let b = net.run(padded.view(), 0.1);
    assert!(max_abs_diff(&a, &b.slice(s![..37, ..]).to_owned()) < 1e-6);
    // Above the trained range the network sees sigma_max.
    let max = net.sigma_max() as f32;
    assert!((max - 75.0 / 255.0).abs() < 1e-6);
    let at_max = net.run(img.view(), max);
    let above = net.run(img.view(), 5.0);
    assert_eq!(max_abs_diff(&at_max, &above), 0.0);
    assert!(net.name().starts_with("ffdnet(embedded"), "{}", net.name());
}

/// FFDNet's 2x2 unshuffle grid makes its output depend on where the grid
/// starts; averaged over the grid's four positions it does not: denoising
/// an image shifted by one pixel gives the shifted denoised image (away
/// from the borders), where the single grid does not.
#[test]
fn grid_average_makes_the_prior_shift_equivariant() {
    use scatterscope::denoise::{denoise_scaled, denoise_scaled_at, denoise_scaled_grid_average};
    let d = Ffdnet::new(source::embedded(), "embedded");
    assert!(d.unshuffles());
    // A smooth field with a little texture, 128 x 128, values in [0.2,
    // 0.9], its minimum and maximum pinned at the centre so that a shift
    // keeps the denoiser's scaling.
    let n = 128;
    let mut img = Array2::from_shape_fn((n, n), |(i, j)| {
        let (y, x) = (i as f64 / n as f64, j as f64 / n as f64);
        0.55 + 0.25 * (5.0 * x + 2.0 * y).sin() * (3.0 * y).cos()
            + 0.05 * ((i * 7 + j * 13) % 11) as f64 / 11.0
    });
    img[(n / 2, n / 2)] = 0.0;
    img[(n / 2, n / 2 + 5)] = 1.0;
    let sigma = 0.2;
    // Shift by one pixel down and right: shifted[i+1, j+1] = img[i, j].
    let shifted = Array2::from_shape_fn((n, n), |(i, j)| img[(i.max(1) - 1, j.max(1) - 1)]);
    // The network sees about 30 pixels around each output pixel.
    let inner = s![34..n - 34, 34..n - 34];
    let inner_shifted = s![35..n - 33, 35..n - 33];
    let gap = |a: &Array2<f64>, b: &Array2<f64>| {
        a.slice(inner)
            .iter()
            .zip(b.slice(inner_shifted))
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max)
    };
    let single = denoise_scaled(&d, img.view(), sigma).image;
    let single_shifted = denoise_scaled(&d, shifted.view(), sigma).image;
    let averaged = denoise_scaled_grid_average(&d, img.view(), sigma);
    let averaged_shifted = denoise_scaled_grid_average(&d, shifted.view(), sigma);
    let (g_single, g_avg) = (
        gap(&single, &single_shifted),
        gap(&averaged, &averaged_shifted),
    );
    assert!(
        g_avg < 1e-4,
        "averaged prior moved by {g_avg} under a shift"
    );
    assert!(
        g_single > 20.0 * g_avg.max(1e-6),
        "single grid {g_single} against {g_avg}"
    );
    // Moving the grid by (1, 1) is the same as denoising the shifted image.
    let at = denoise_scaled_at(&d, img.view(), sigma, (1, 1)).image;
    let at_gap = at
        .slice(inner)
        .iter()
        .zip(single_shifted.slice(inner_shifted))
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max);
    assert!(at_gap < 1e-4, "grid moved by (1, 1) differs by {at_gap}");
}
