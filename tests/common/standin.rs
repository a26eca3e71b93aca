//! The stand-in PicoQuant library (`mocks/picoquant`, built as a cdylib
//! beside the test binaries because the main crate names it as a
//! dev-dependency) and the tests' way to run `acquire` against it.

use std::path::{Path, PathBuf};
use std::process::Output;

/// The stand-in's shared library file.
pub fn standin_library() -> PathBuf {
    let exe = std::env::current_exe().expect("the test binary's path");
    let deps = exe.parent().expect("target/PROFILE/deps");
    let name = format!(
        "{}scatterscope_mock_picoquant{}",
        std::env::consts::DLL_PREFIX,
        std::env::consts::DLL_SUFFIX
    );
    [deps.to_path_buf(), deps.join("..")]
        .iter()
        .map(|d| d.join(&name))
        .find(|p| p.exists())
        .unwrap_or_else(|| {
            panic!(
                "{name} not found beside {}: build the workspace",
                deps.display()
            )
        })
}

/// Runs the CLI with the stand-in configured by `mock` (its
/// `SCATTERSCOPE_PQ_MOCK`).
#[allow(dead_code)]
pub fn scatterscope_pq(args: &[&str], mock: &str) -> Output {
    super::command::scatterscope()
        .args(args)
        .env("SCATTERSCOPE_PQ_MOCK", mock)
        .env_remove("SCATTERSCOPE_MHLIB")
        .env_remove("SCATTERSCOPE_HHLIB")
        .output()
        .expect("binary runs")
}

/// The stand-in's truth file as JSON.
#[allow(dead_code)]
pub fn truth(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path).expect("the stand-in wrote its truth");
    serde_json::from_str(&text).expect("truth is JSON")
}
