//! What the stand-in emulates, from the environment variable
//! `SCATTERSCOPE_PQ_MOCK` (a C library has no other way in): comma-separated
//! `key=value` items, e.g. `rate=5e6,scan=32x32,fault=overrun@1000000`.
//!
//! - `devices=N`: devices attached (default 1; 0 for none).
//! - `rate=HZ`: detected photons per second (default 2e6); `rate=max`
//!   delivers full FIFO reads as fast as they are asked for (load tests).
//! - `dark=HZ`: dark counts per second (default 0).
//! - `sync=HZ`: laser sync rate (default 80e6).
//! - `scan=WxH`: a galvo scan of W x H points with line and frame markers
//!   (default: a point detector); each frame is drawn anew (Poisson).
//! - `drift=N`: a scan's scene moves N points to the right each frame
//!   (default 0).
//! - `fault=overrun@N`, `fault=error@N`, `fault=vanish@N`, `fault=drop@N`:
//!   after N records the FIFO overruns, a read fails, the device
//!   disappears, or (MultiHarp) the device drops counts and says so in its
//!   flags (`FLAG_CNTS_DROPPED`) while the run goes on.
//! - `seed=S`: photon sampling seed (default 0).
//! - `truth=PATH`: on StopMeas, write what was delivered (records, photons,
//!   markers, overflows, per-pixel photons of a scan) to PATH as JSON.
//! - `lifetimes=BAR/DISC/BACKGROUND`: a FLIM scan whose objects (the
//!   scene's bar, disc and background) decay with known lifetimes instead
//!   of the slab's time profile: each `T` (ps, one exponential) or
//!   `T1+T2@F` (two, the first holding the share F of the photons); each
//!   photon arrives at the pulse plus a Gaussian IRF of `irf=FWHM` ps
//!   (default 150) plus its exponential delay, wrapped into the sync
//!   period (so earlier pulses' light arrives too). The truth a test
//!   checks a fit against.
//! - `ph330_input_modes=no`: a PicoHarp 330 whose `PH330_GetFeatures` lacks
//!   `FEATURE_INPT_MODE` (its inputs' trigger mode cannot be set).

use std::path::PathBuf;

/// The variable the stand-in reads.
pub const ENV: &str = "SCATTERSCOPE_PQ_MOCK";

/// A fault injected after a number of delivered records.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fault {
    /// The FIFO overruns: the device stops and sets the FIFO-full flag.
    Overrun(u64),
    /// A FIFO read returns an error (the device stays).
    ReadError(u64),
    /// The device disappears: every later call fails.
    Vanish(u64),
    /// The device drops counts (its `FLAG_CNTS_DROPPED` set from then on)
    /// and goes on.
    DropCounts(u64),
}

/// The stand-in's configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct MockConfig {
    /// Devices attached.
    pub devices: usize,
    /// Detected photons per second.
    pub rate_hz: f64,
    /// Deliver as fast as asked.
    pub unpaced: bool,
    /// Dark counts per second.
    pub dark_hz: f64,
    /// Sync rate, Hz.
    pub sync_hz: f64,
    /// Scan points (width, height).
    pub scan: Option<(usize, usize)>,
    /// Points a scan's scene moves to the right each frame.
    pub drift: usize,
    /// The fault, if any.
    pub fault: Option<Fault>,
    /// Sampling seed.
    pub seed: u64,
    /// Where to write the delivered totals.
    pub truth: Option<PathBuf>,
    /// The TimeHarp 260 board: a Nano (edge triggers) rather than a Pico
    /// (CFDs).
    pub th260_nano: bool,
    /// Whether a PicoHarp 330 has `FEATURE_INPT_MODE`.
    pub ph330_input_modes: bool,
    /// The decays of the bar, disc and background, when told.
    pub lifetimes: Option<[Decay; 3]>,
    /// The IRF's FWHM (ps) with `lifetimes`.
    pub irf_fwhm_ps: f64,
}

/// A decay an object is told to have: components (lifetime ps, share of
/// the photons).
#[derive(Debug, Clone, PartialEq)]
pub struct Decay(pub Vec<(f64, f64)>);

impl Decay {
    /// `T` or `T1+T2@F`.
    fn parse(s: &str) -> Option<Self> {
        let positive = |v: &str| v.parse::<f64>().ok().filter(|x| x.is_finite() && *x > 0.0);
        match s.split_once('+') {
            None => Some(Self(vec![(positive(s)?, 1.0)])),
            Some((a, rest)) => {
                let (b, f) = rest.split_once('@')?;
                let f = f.parse::<f64>().ok().filter(|f| (0.0..=1.0).contains(f))?;
                Some(Self(vec![(positive(a)?, f), (positive(b)?, 1.0 - f)]))
            }
        }
    }
}

impl Default for MockConfig {
    fn default() -> Self {
        Self {
            devices: 1,
            rate_hz: 2e6,
            unpaced: false,
            dark_hz: 0.0,
            sync_hz: 80e6,
            scan: None,
            drift: 0,
            fault: None,
            seed: 0,
            truth: None,
            th260_nano: false,
            ph330_input_modes: true,
            lifetimes: None,
            irf_fwhm_ps: 150.0,
        }
    }
}

impl MockConfig {
    /// Reads [`ENV`]; the default when unset.
    pub fn from_env() -> Result<Self, String> {
        match std::env::var(ENV) {
            Ok(v) => Self::parse(&v),
            Err(_) => Ok(Self::default()),
        }
    }

    /// Parses the `key=value,...` list.
    pub fn parse(text: &str) -> Result<Self, String> {
        let mut c = Self::default();
        for item in text.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let (key, value) = item
                .split_once('=')
                .ok_or_else(|| format!("{ENV}: `{item}` is not key=value"))?;
            let bad = || format!("{ENV}: {key}={value} is not valid");
            let number = |v: &str| v.parse::<f64>().ok().filter(|x| x.is_finite() && *x >= 0.0);
            match key {
                "devices" => c.devices = value.parse().map_err(|_| bad())?,
                "rate" if value == "max" => c.unpaced = true,
                "rate" => c.rate_hz = number(value).filter(|r| *r > 0.0).ok_or_else(bad)?,
                "dark" => c.dark_hz = number(value).ok_or_else(bad)?,
                "sync" => c.sync_hz = number(value).filter(|r| *r >= 1e3).ok_or_else(bad)?,
                "seed" => c.seed = value.parse().map_err(|_| bad())?,
                "drift" => c.drift = value.parse().map_err(|_| bad())?,
                "truth" => c.truth = Some(PathBuf::from(value)),
                "lifetimes" => {
                    let parts: Vec<Decay> = value
                        .split('/')
                        .map(Decay::parse)
                        .collect::<Option<_>>()
                        .ok_or_else(bad)?;
                    c.lifetimes = Some(<[Decay; 3]>::try_from(parts).map_err(|_| bad())?);
                }
                "irf" => c.irf_fwhm_ps = number(value).filter(|v| *v > 0.0).ok_or_else(bad)?,
                "ph330_input_modes" => {
                    c.ph330_input_modes = match value {
                        "yes" => true,
                        "no" => false,
                        _ => return Err(bad()),
                    }
                }
                "th260" => {
                    c.th260_nano = match value {
                        "pico" => false,
                        "nano" => true,
                        _ => return Err(bad()),
                    }
                }
                "scan" => {
                    let (w, h) = value.split_once('x').ok_or_else(bad)?;
                    let (w, h): (usize, usize) =
                        (w.parse().map_err(|_| bad())?, h.parse().map_err(|_| bad())?);
                    if !(1..=1024).contains(&w) || !(1..=1024).contains(&h) {
                        return Err(bad());
                    }
                    c.scan = Some((w, h));
                }
                "fault" => {
                    let (kind, at) = value.split_once('@').ok_or_else(bad)?;
                    let at: u64 = at.parse().map_err(|_| bad())?;
                    c.fault = Some(match kind {
                        "overrun" => Fault::Overrun(at),
                        "error" => Fault::ReadError(at),
                        "vanish" => Fault::Vanish(at),
                        "drop" => Fault::DropCounts(at),
                        _ => return Err(bad()),
                    });
                }
                _ => return Err(format!("{ENV}: unknown key `{key}`")),
            }
        }
        Ok(c)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn items_parse_and_bad_ones_name_themselves() {
        let c = MockConfig::parse("rate=max, scan=32x16,fault=vanish@10,devices=2,seed=3").unwrap();
        assert!(c.unpaced);
        assert_eq!(c.scan, Some((32, 16)));
        assert_eq!(c.fault, Some(Fault::Vanish(10)));
        assert_eq!(c.devices, 2);
        assert_eq!(c.seed, 3);
        assert_eq!(MockConfig::parse("").unwrap(), MockConfig::default());
        for bad in ["rate=-1", "scan=0x4", "fault=melt@3", "colour=blue", "rate"] {
            let e = MockConfig::parse(bad).unwrap_err();
            assert!(e.contains(ENV), "{bad}: {e}");
        }
    }
}
