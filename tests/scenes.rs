//! Built-in scenes and image loading.

use image::{GrayImage, Luma};
use scatterscope::scene::Scene;

#[test]
fn built_in_scenes_are_in_range_and_have_contrast() {
    for name in Scene::BUILT_IN {
        for (h, w) in [(256, 256), (64, 96)] {
            let img = Scene::parse(name).render(h, w).unwrap();
            assert_eq!(img.dim(), (h, w));
            let (lo, hi) = img
                .iter()
                .fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
            assert!(lo >= 0.0 && hi <= 1.0 + 1e-12, "{name}: [{lo}, {hi}]");
            assert!(hi - lo > 0.5, "{name} has no contrast");
        }
    }
}

#[test]
fn usaf_bars_have_exact_area_coverage() {
    // Anti-aliasing by exact area: the bright area is the sum of bar areas,
    // which a 512 render resolves at twice the scale of a 256 render.
    let a = Scene::Usaf.render(256, 256).unwrap();
    let b = Scene::Usaf.render(512, 512).unwrap();
    let bright = |img: &ndarray::Array2<f64>| {
        img.iter().map(|v| (v - 0.05) / 0.95).sum::<f64>() / img.len() as f64
    };
    assert!(
        (bright(&a) - bright(&b)).abs() < 0.02,
        "{} {}",
        bright(&a),
        bright(&b)
    );
}

#[test]
fn siemens_star_is_symmetric() {
    let img = Scene::Star.render(128, 128).unwrap();
    // 36 sectors: rotation by 180 degrees maps the star onto itself
    // (about the image centre, the corner shared by pixels 63 and 64).
    for r in 0..128 {
        for c in 0..128 {
            assert!((img[[r, c]] - img[[127 - r, 127 - c]]).abs() < 1e-9);
        }
    }
}

#[test]
fn image_files_load_as_grayscale_and_resize() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ramp.png");
    let mut png = GrayImage::new(40, 20);
    for (x, _, p) in png.enumerate_pixels_mut() {
        *p = Luma([if x < 20 { 0 } else { 255 }]);
    }
    png.save(&path).unwrap();
    let img = Scene::File(path.clone()).render(10, 20).unwrap();
    assert_eq!(img.dim(), (10, 20));
    assert!(img[[5, 2]] < 0.01 && img[[5, 17]] > 0.99);

    // EXR with values above 1 is scaled by its maximum.
    let exr = dir.path().join("hdr.exr");
    let data = ndarray::Array2::from_shape_fn((8, 8), |(r, _)| r as f32 * 2.0);
    scatterscope::formats::exr::write_image(data.view(), &exr).unwrap();
    let img = Scene::File(exr).render(8, 8).unwrap();
    assert!((img[[7, 0]] - 1.0).abs() < 1e-6 && (img[[1, 3]] - 2.0 / 14.0).abs() < 1e-6);

    let missing = dir.path().join("nope.png");
    let e = Scene::File(missing).render(8, 8).unwrap_err().to_string();
    assert!(e.contains("nope.png"), "{e}");
}
