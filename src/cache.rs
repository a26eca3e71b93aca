//! Where results derived from the physics alone are kept between runs:
//! Monte Carlo transport runs (`physics::transport_cache`), which take
//! seconds to make and are the same every time for the same physics.
//!
//! The folder is `SCATTERSCOPE_CACHE_DIR` when set (empty: keep nothing),
//! else the user's cache folder's `scatterscope` (`~/.cache/scatterscope`
//! on Linux). Front ends call [`use_default`] once at start; library
//! users keep nothing unless they call it or set a folder themselves.

use std::path::PathBuf;

/// The variable naming the cache folder (empty: keep nothing).
pub const CACHE_DIR_ENV: &str = "SCATTERSCOPE_CACHE_DIR";

/// The cache folder from the environment, if any.
pub fn default_dir() -> Option<PathBuf> {
    match std::env::var_os(CACHE_DIR_ENV) {
        Some(d) if d.is_empty() => None,
        Some(d) => Some(PathBuf::from(d)),
        None => dirs::cache_dir().map(|d| d.join("scatterscope")),
    }
}

/// Keeps transport runs in [`default_dir`]'s `transport` folder.
pub fn use_default() {
    crate::physics::transport_cache::set_dir(default_dir().map(|d| d.join("transport")));
}
