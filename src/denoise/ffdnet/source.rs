//! Where FFDNet weights come from, in order of priority: an explicit path
//! (`--weights`, else the environment variable [`WEIGHTS_ENV`]), weights
//! imported into the user's data directory (`scatterscope weights import`),
//! and the project's own weights embedded in the binary. The explicit
//! choice may also be the word [`EMBEDDED_NAME`], which picks the embedded
//! weights even when imported ones exist.

use std::path::{Path, PathBuf};

use super::Ffdnet;
use super::weights::{FfdnetWeights, WeightsError};

/// Environment variable naming a weight file (used when no `--weights`).
pub const WEIGHTS_ENV: &str = "SCATTERSCOPE_FFDNET_WEIGHTS";
/// Environment variable overriding the data directory (default: the
/// platform's, e.g. `~/.local/share/scatterscope`).
pub const DATA_DIR_ENV: &str = "SCATTERSCOPE_DATA_DIR";
/// File name of imported weights inside the data directory.
pub const IMPORTED_FILE: &str = "ffdnet-gray.safetensors";
/// The explicit choice (`--weights`, [`WEIGHTS_ENV`]) that names the
/// embedded weights; a file of that name is reached as `./embedded`.
pub const EMBEDDED_NAME: &str = "embedded";

/// The project's own weights, trained by `training/train_ffdnet.py` on
/// dead-leaves and scikit-image images (see `training/README.md`).
const EMBEDDED: &[u8] = include_bytes!("../../../weights/ffdnet-gray-small.safetensors");

/// The data directory of the project (may not exist yet).
pub fn data_dir() -> Option<PathBuf> {
    match std::env::var_os(DATA_DIR_ENV) {
        Some(d) if !d.is_empty() => Some(PathBuf::from(d)),
        _ => dirs::data_dir().map(|d| d.join("scatterscope")),
    }
}

/// Where `weights import` writes and where imported weights are looked for.
pub fn imported_path() -> Option<PathBuf> {
    data_dir().map(|d| d.join(IMPORTED_FILE))
}

/// The embedded weights (validated like any file).
pub fn embedded() -> FfdnetWeights {
    FfdnetWeights::from_bytes(EMBEDDED, "embedded weights")
        .expect("the embedded weights are validated by a test")
}

/// Loads FFDNet by priority: `explicit`, then [`WEIGHTS_ENV`], then the
/// imported file, then the embedded weights. An explicit choice of
/// [`EMBEDDED_NAME`] is the embedded weights. An explicit or imported file
/// that fails validation is an error, never a silent fallback.
pub fn load(explicit: Option<&Path>) -> Result<Ffdnet, WeightsError> {
    let env = std::env::var_os(WEIGHTS_ENV)
        .filter(|v| !v.is_empty())
        .map(PathBuf::from);
    if let Some(p) = explicit {
        return load_explicit(p, p.display().to_string());
    }
    if let Some(p) = env {
        let label = format!("{} from {WEIGHTS_ENV}", p.display());
        return load_explicit(&p, label);
    }
    if let Some(p) = imported_path().filter(|p| p.is_file()) {
        let label = format!("imported {}", p.display());
        return Ffdnet::from_file(&p, label);
    }
    Ok(Ffdnet::new(embedded(), "embedded"))
}

/// An explicit choice: the embedded weights by name, else a file.
fn load_explicit(p: &Path, label: String) -> Result<Ffdnet, WeightsError> {
    if p.as_os_str() == EMBEDDED_NAME {
        return Ok(Ffdnet::new(embedded(), "embedded"));
    }
    Ffdnet::from_file(p, label)
}

/// Why weights could not be imported.
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    /// The legacy file cannot be converted.
    #[error(transparent)]
    Pth(#[from] super::pth::PthError),
    /// The converted weights do not validate, or a file cannot be read.
    #[error(transparent)]
    Weights(#[from] WeightsError),
    /// No output was given and this system has no data directory.
    #[error("no data directory on this system: give an output file")]
    NoDataDir,
    /// The output cannot be written.
    #[error("{path}: {source}")]
    Write {
        /// The file or directory.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
}

/// Converts the original FFDNet gray weights at `pth` (a legacy PyTorch
/// `.pth`) into the project's format at `out`, or where imported weights
/// are looked for ([`imported_path`]); returns the file and the weights,
/// validated as the prior loads them.
pub fn import(pth: &Path, out: Option<&Path>) -> Result<(PathBuf, FfdnetWeights), ImportError> {
    let bytes = crate::files::read_bounded(pth, super::weights::MAX_WEIGHT_FILE, "weight file")
        .map_err(|e| WeightsError::Read(e.to_string()))?;
    let converted = super::pth::import_ffdnet_gray(&bytes, pth)?;
    let out = match out {
        Some(o) => o.to_path_buf(),
        None => imported_path().ok_or(ImportError::NoDataDir)?,
    };
    let write = |path: &Path| {
        let path = path.to_path_buf();
        move |source| ImportError::Write { path, source }
    };
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(write(dir))?;
    }
    crate::files::write_atomic(&out, &converted).map_err(write(&out))?;
    let weights = FfdnetWeights::from_file(&out)?;
    Ok((out, weights))
}
