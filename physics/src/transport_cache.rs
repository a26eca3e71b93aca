//! Monte Carlo transport runs kept on disk, keyed by their physics: the
//! slab, the source, the grid of times and rings, the packets and the
//! seed, and the scheme's version. A run is deterministic given these,
//! so a kept run is the run. The folder is set by the front end
//! ([`set_dir`]); without one nothing is kept.
//!
//! A file holds a header line, the key as text (so that a file is only
//! taken for the key it was written for, whatever its name), then the
//! run's numbers as little-endian bytes. It is written under a temporary
//! name and renamed: a reader sees a whole file or none. A file that does
//! not read back whole is run again and replaced, and that is said.

use std::fmt;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::RwLock;

use crate::transport::{Estimate, Grid, Run, Slab, Source, Transport, TransportError, transport};

/// The first line of every cache file.
const MAGIC: &str = "scatterscope transport cache";

/// The transport scheme's version: changed whenever a change to
/// `transport` changes what a run gives, so older files are not taken.
pub const SCHEME_VERSION: u32 = 1;

static DIR: RwLock<Option<PathBuf>> = RwLock::new(None);

/// Sets the folder runs are kept in (`None`: keep nothing).
pub fn set_dir(dir: Option<PathBuf>) {
    *DIR.write().unwrap_or_else(|e| e.into_inner()) = dir;
}

/// The folder runs are kept in, if any.
pub fn dir() -> Option<PathBuf> {
    DIR.read().unwrap_or_else(|e| e.into_inner()).clone()
}

/// What the cache did for one run.
#[derive(Debug, Clone, PartialEq)]
pub enum CacheUse {
    /// No folder set: the run was made and not kept.
    Off,
    /// The run was read from this file.
    Read(PathBuf),
    /// The run was made and kept in this file.
    Written(PathBuf),
    /// The run was made; this file could not be written (the reason).
    NotWritten(PathBuf, String),
    /// This file did not read back whole (the reason): the run was made
    /// again and the file replaced.
    Replaced(PathBuf, String),
}

impl fmt::Display for CacheUse {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CacheUse::Off => write!(f, "made now, not kept (no cache folder)"),
            CacheUse::Read(p) => write!(f, "read from the cache {}", p.display()),
            CacheUse::Written(p) => write!(f, "made now and kept in {}", p.display()),
            CacheUse::NotWritten(p, why) => {
                write!(f, "made now; not kept: {} ({why})", p.display())
            }
            CacheUse::Replaced(p, why) => write!(
                f,
                "made again: the cache file {} did not read back ({why}) and was replaced",
                p.display()
            ),
        }
    }
}

/// The run's key: every input, floats by their bits.
fn key(slab: &Slab, source: Source, grid: &Grid, run: &Run) -> String {
    let b = |v: f64| format!("{:016x}", v.to_bits());
    format!(
        "scheme {SCHEME_VERSION}; slab mu_a {} mu_s {} g {} n {} outside {} d {}; source {source:?}; grid t {} dt {} bins {} dr {} rings {}; run {} packets seed {} cap {}",
        b(slab.mu_a_per_cm),
        b(slab.mu_s_per_cm),
        b(slab.g),
        b(slab.n),
        b(slab.n_outside),
        b(slab.thickness_cm),
        b(grid.t_start_ps),
        b(grid.bin_width_ps),
        grid.bins,
        b(grid.ring_width_cm),
        grid.rings,
        run.photons,
        run.seed,
        b(run.max_path_cm)
    )
}

/// FNV-1a, 64 bits: the file's name from its key (the key inside the
/// file decides; the name only spreads files).
fn name_of(key: &str) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for byte in key.bytes() {
        h ^= u64::from(byte);
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    format!("transport-{h:016x}.bin")
}

/// [`transport`], kept in and taken from the cache folder when one is
/// set; says what the cache did.
pub fn transport_cached(
    slab: &Slab,
    source: Source,
    grid: &Grid,
    run: &Run,
) -> Result<(Transport, CacheUse), TransportError> {
    let Some(dir) = dir() else {
        return Ok((transport(slab, source, grid, run)?, CacheUse::Off));
    };
    transport_in(&dir, slab, source, grid, run)
}

/// [`transport_cached`] with the folder `dir`.
pub fn transport_in(
    dir: &Path,
    slab: &Slab,
    source: Source,
    grid: &Grid,
    run: &Run,
) -> Result<(Transport, CacheUse), TransportError> {
    let key = key(slab, source, grid, run);
    let path = dir.join(name_of(&key));
    let unreadable = match std::fs::read(&path) {
        Ok(bytes) => match decode(&bytes, &key, grid) {
            Ok(Some(t)) => return Ok((t, CacheUse::Read(path))),
            // Another key under the same name: made and kept anew.
            Ok(None) => None,
            Err(why) => Some(why),
        },
        Err(_) => None,
    };
    let t = transport(slab, source, grid, run)?;
    let written = write_whole(&path, &encode(&t, &key));
    let used = match (written, unreadable) {
        (Err(why), _) => CacheUse::NotWritten(path, why),
        (Ok(()), Some(why)) => CacheUse::Replaced(path, why),
        (Ok(()), None) => CacheUse::Written(path),
    };
    Ok((t, used))
}

/// Writes `bytes` to a temporary name beside `path`, then renames it.
fn write_whole(path: &Path, bytes: &[u8]) -> Result<(), String> {
    let dir = path.parent().unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).map_err(|e| e.to_string())?;
    // Unique to the process and the call: two writers never share one.
    static CALLS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let call = CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let temp = path.with_extension(format!("tmp-{}-{call}", std::process::id()));
    let result = std::fs::File::create(&temp)
        .and_then(|mut f| f.write_all(bytes).and_then(|()| f.sync_all()))
        .and_then(|()| std::fs::rename(&temp, path));
    if result.is_err() {
        let _ = std::fs::remove_file(&temp);
    }
    result.map_err(|e| e.to_string())
}

fn encode(t: &Transport, key: &str) -> Vec<u8> {
    let mut out = format!("{MAGIC}\n{key}\n").into_bytes();
    out.extend_from_slice(&t.photons.to_le_bytes());
    out.extend_from_slice(&t.specular.to_le_bytes());
    let estimates = [
        t.reflected,
        t.transmitted,
        t.absorbed,
        t.cut,
        t.outside_grid,
    ];
    for e in estimates.iter().chain(&t.cells).chain(&t.face) {
        out.extend_from_slice(&e.mean.to_le_bytes());
        out.extend_from_slice(&e.error.to_le_bytes());
    }
    out
}

/// The run kept in `bytes` for `key` (`None`: a file of another key);
/// an error when the file is not whole.
fn decode(bytes: &[u8], key: &str, grid: &Grid) -> Result<Option<Transport>, String> {
    let header = format!("{MAGIC}\n");
    let rest = bytes
        .strip_prefix(header.as_bytes())
        .ok_or("no cache header")?;
    let line_end = rest.iter().position(|&b| b == b'\n').ok_or("no key line")?;
    if &rest[..line_end] != key.as_bytes() {
        return Ok(None);
    }
    let body = &rest[line_end + 1..];
    let estimates = 5 + grid.bins * grid.rings + grid.bins;
    let want = 16 + 16 * estimates;
    if body.len() != want {
        return Err(format!("{} bytes of numbers, {want} expected", body.len()));
    }
    let word = |i: usize| -> [u8; 8] { body[8 * i..8 * i + 8].try_into().expect("8 bytes") };
    let photons = u64::from_le_bytes(word(0));
    let specular = f64::from_le_bytes(word(1));
    let e: Vec<Estimate> = (0..estimates)
        .map(|i| Estimate {
            mean: f64::from_le_bytes(word(2 + 2 * i)),
            error: f64::from_le_bytes(word(3 + 2 * i)),
        })
        .collect();
    if !e.iter().all(|e| e.mean.is_finite() && e.error.is_finite()) || !specular.is_finite() {
        return Err("a number that is not finite".into());
    }
    let cells_end = 5 + grid.bins * grid.rings;
    Ok(Some(Transport {
        photons,
        specular,
        reflected: e[0],
        transmitted: e[1],
        absorbed: e[2],
        cut: e[3],
        outside_grid: e[4],
        grid: *grid,
        cells: e[5..cells_end].to_vec(),
        face: e[cells_end..].to_vec(),
    }))
}
