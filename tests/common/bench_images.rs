//! A small image set for `bench-recon`: the built-in disks (tuning) and a
//! 160-pixel disks image (held out), with the flags of a run that takes
//! seconds.

use std::path::{Path, PathBuf};

/// Flags of a seconds-long `bench-recon` on [`small_image_set`]: both
/// sets, 32 x 32 pixels at the paper's pitch, one light level, TV prior,
/// few iterations.
pub const QUICK_BENCH_FLAGS: [&str; 20] = [
    "--split",
    "all",
    "--size",
    "32",
    "--fov",
    "6.25",
    "--object-px",
    "160",
    "--levels",
    "1",
    "--solvers",
    "split",
    "--priors",
    "tv",
    "--max-iters",
    "10",
    "--rl-iters",
    "5",
    "--rl-best-iters",
    "20",
];

/// Writes the image set with its manifest into `dir/images`; returns that
/// folder.
pub fn small_image_set(dir: &Path) -> PathBuf {
    let images = dir.join("images");
    std::fs::create_dir_all(&images).unwrap();
    let wide = scatterscope::scene::Scene::parse("disks")
        .render(160, 160)
        .unwrap();
    scatterscope::formats::png::write_png(wide.view(), Some(1.0), &images.join("wide.png"))
        .unwrap();
    std::fs::write(
        images.join("manifest.csv"),
        "name,file,source,category,split,licence\n\
         disks,,scatterscope,sparse,tuning,built-in\n\
         wide,wide.png,test,line art,held-out,test\n",
    )
    .unwrap();
    images
}
