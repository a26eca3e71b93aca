//! Paths into the read-only material beside the repository
//! (`../shared/data`) and into files fetched by scripts (the original
//! FFDNet weights). The tests that use them are `#[ignore = "needs ..."]`,
//! so a clone without them reports them skipped; run with
//! `cargo nextest run --run-ignored all` (as CI does), a missing file is a
//! failure that names it, never a silent pass.

use std::path::{Path, PathBuf};

/// `../shared/data/REL`, which must exist.
#[allow(dead_code)]
pub fn shared_data(rel: &str) -> PathBuf {
    required(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../shared/data")
            .join(rel),
        "the shared data ship beside the project repository",
    )
}

/// The original FFDNet weights, which must have been fetched.
#[allow(dead_code)]
pub fn original_ffdnet_pth() -> PathBuf {
    required(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("target/ffdnet/ffdnet_weights_gray.pth"),
        "run scripts/fetch_ffdnet_weights.sh; the GPL weights are not part of the repository",
    )
}

fn required(path: PathBuf, how: &str) -> PathBuf {
    assert!(
        path.exists(),
        "{} is absent ({how}); this test needs it",
        path.display()
    );
    path
}
