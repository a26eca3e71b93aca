//! The memory budget. Every allocation whose size comes from input (a
//! file's header, a sensor size, a bin count) is estimated and checked
//! against it first, so that input asks for at most the budget and a
//! larger request is a clear error, not an aborted process. Whole-file
//! reads go through [`crate::files::read_bounded`], which refuses special
//! files and caps the size.
//!
//! The budget is, first found: a limit set by the program
//! ([`set_limit`], e.g. from a command-line flag), the environment
//! variable [`LIMIT_ENV`] (`4GiB`, `500MB`, a number of bytes), or
//! [`DEFAULT_SHARE`] of the smallest of the machine's memory, the
//! process's address-space limit (`ulimit -v`) and its cgroup's memory
//! limit, as the operating system reports them (Linux; elsewhere
//! [`FALLBACK_BYTES`]).

use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};

/// Environment variable that sets the budget.
pub const LIMIT_ENV: &str = "SCATTERSCOPE_MEMORY_LIMIT";

/// Share of the machine's (or the process's) memory the budget takes by
/// default: the rest is for the program itself, its threads and the
/// allocations no header sizes.
pub const DEFAULT_SHARE: f64 = 0.5;

/// The budget where the system reports no memory size.
pub const FALLBACK_BYTES: u64 = 4 << 30;

/// A limit set by the program (0: none).
static LIMIT: AtomicU64 = AtomicU64::new(0);

/// How much memory input may ask for, and where that figure came from.
#[derive(Debug, Clone, PartialEq)]
pub struct Budget {
    /// Bytes.
    pub bytes: u64,
    /// Where the figure came from, in words.
    pub source: String,
}

/// A request larger than the budget, or a budget that cannot be read.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MemoryError {
    /// The estimate exceeds the budget.
    #[error(
        "{what} needs about {} of memory, more than the budget of {} ({}); set {LIMIT_ENV} to allow more",
        size(*needed),
        size(budget.bytes),
        budget.source
    )]
    OverBudget {
        /// What needed it.
        what: String,
        /// The estimate, bytes.
        needed: u64,
        /// The budget.
        budget: Budget,
    },
    /// The environment variable does not hold a size.
    #[error("{LIMIT_ENV} = `{value}`: {reason}")]
    BadLimit {
        /// Its value.
        value: String,
        /// What is wrong.
        reason: String,
    },
}

/// A byte count in words (binary units).
pub fn size(bytes: u64) -> String {
    let b = bytes as f64;
    let (value, unit) = [
        (1u64 << 40, "TiB"),
        (1 << 30, "GiB"),
        (1 << 20, "MiB"),
        (1 << 10, "KiB"),
    ]
    .into_iter()
    .find(|(u, _)| bytes >= *u)
    .map_or((b, "bytes"), |(u, n)| (b / u as f64, n));
    if unit == "bytes" {
        format!("{bytes} bytes")
    } else {
        format!("{value:.1} {unit}")
    }
}

/// Sets the budget for this process (`None`: back to the environment
/// variable or the system's figure).
pub fn set_limit(bytes: Option<u64>) {
    LIMIT.store(bytes.unwrap_or(0), Ordering::Relaxed);
}

/// The budget in effect.
pub fn budget() -> Result<Budget, MemoryError> {
    let set = LIMIT.load(Ordering::Relaxed);
    if set > 0 {
        return Ok(Budget {
            bytes: set,
            source: "set by the program".into(),
        });
    }
    if let Some(value) = std::env::var_os(LIMIT_ENV).filter(|v| !v.is_empty()) {
        let value = value.to_string_lossy().into_owned();
        let bytes = crate::units::parse_size(&value).map_err(|reason| MemoryError::BadLimit {
            value: value.clone(),
            reason,
        })?;
        return Ok(Budget {
            bytes,
            source: LIMIT_ENV.to_string(),
        });
    }
    let limits = [
        (meminfo_total(), "the machine's memory"),
        (address_space_limit(), "the process's address-space limit"),
        (cgroup_limit(), "the cgroup's memory limit"),
    ];
    Ok(
        match limits
            .iter()
            .filter_map(|(l, name)| l.map(|l| (l, *name)))
            .min_by_key(|(l, _)| *l)
        {
            Some((limit, name)) => Budget {
                bytes: (limit as f64 * DEFAULT_SHARE) as u64,
                source: format!("{:.0} % of {name}, {}", DEFAULT_SHARE * 100.0, size(limit)),
            },
            None => Budget {
                bytes: FALLBACK_BYTES,
                source: "the system reports no memory size".into(),
            },
        },
    )
}

/// Checks that `needed` bytes (an estimate) fit the budget; `what` names
/// the request in the error.
pub fn check(needed: u64, what: impl FnOnce() -> String) -> Result<(), MemoryError> {
    let budget = budget()?;
    if needed > budget.bytes {
        return Err(MemoryError::OverBudget {
            what: what(),
            needed,
            budget,
        });
    }
    Ok(())
}

/// `count` elements of `item` bytes, saturating (an absurd header must
/// not overflow the estimate into a small number).
pub fn bytes_of(count: impl IntoIterator<Item = usize>, item: u64) -> u64 {
    count
        .into_iter()
        .fold(item, |acc, d| acc.saturating_mul(d as u64))
}

/// Bytes per pixel and bin a simulation holds at once: the kernels, their
/// spectra on a grid up to twice the sensor's side, the expected counts,
/// the draw and their single-precision stacks.
pub const SIMULATE_BYTES: u64 = 64;
/// Bytes per pixel and bin of the ST-PSF report: both discretisations'
/// kernels and the single-precision stack.
pub const PSF_BYTES: u64 = 24;
/// Bytes per pixel and bin a reconstruction's problem holds: the counts,
/// the kernels and their spectra on a grid up to twice the sensor's side
/// (57 measured on a 32 x 32 sensor, whose grid is that large). Each
/// method's own memory is its plan's
/// ([`crate::reconstruct::method::MethodPlan::working_bytes`]).
pub const PROBLEM_BYTES: u64 = 80;

/// Checks a job on `setup`'s sensor and bins against the budget at
/// `per_pixel_bin` bytes per pixel and bin; `what` names the job.
pub fn check_setup(
    setup: &crate::physics::Setup,
    per_pixel_bin: u64,
    what: &str,
) -> Result<(), MemoryError> {
    let (h, w, k) = (
        setup.sensor.height_px,
        setup.sensor.width_px,
        setup.bins.count,
    );
    check(bytes_of([k, h, w], per_pixel_bin), || {
        format!("{what} of {k} bins on a {w} x {h} sensor")
    })
}

/// `MemTotal` of `/proc/meminfo`, bytes.
fn meminfo_total() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// The soft `Max address space` of `/proc/self/limits`, bytes.
fn address_space_limit() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/self/limits").ok()?;
    let line = text.lines().find(|l| l.starts_with("Max address space"))?;
    line.split_whitespace().nth(3)?.parse().ok()
}

/// `memory.max` of the process's cgroup (v2), bytes.
fn cgroup_limit() -> Option<u64> {
    let cgroup = std::fs::read_to_string("/proc/self/cgroup").ok()?;
    let path = cgroup.lines().find_map(|l| l.strip_prefix("0::"))?;
    let file = Path::new("/sys/fs/cgroup")
        .join(path.trim_start_matches('/'))
        .join("memory.max");
    std::fs::read_to_string(file).ok()?.trim().parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_are_written_in_their_largest_unit() {
        assert_eq!(size(3 << 30), "3.0 GiB");
        assert_eq!(size(12), "12 bytes");
    }

    #[test]
    fn saturating_estimates_never_wrap() {
        assert_eq!(bytes_of([1 << 40, 1 << 40, 1 << 40], 4), u64::MAX);
        assert_eq!(bytes_of([2, 3], 4), 24);
    }
}
