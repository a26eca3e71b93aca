//! Photons sampled from the ST-PSF of a scene.
//!
//! A photon's source pixel is drawn with probability proportional to the
//! scene's intensity, its time bin and lateral offset jointly from the
//! ST-PSF kernels (their relative masses are the physics), its arrival time
//! uniformly within that bin. Every bin with light is sampled, also those
//! the given kernels leave out for carrying under `min_bin_photons` of the
//! setup's light budget: that threshold is a reconstruction's choice, and a
//! device records every photon that arrives. The detected pixel is the source pixel plus
//! the offset; photons that land off the sensor are not detected. Arrival
//! times form a Poisson process at the configured rate; dark counts add
//! uniformly distributed pixels and times.
//!
//! With an instrument response in the kernels' setup, arrivals are sampled
//! from the ideal (IRF-free) kernels over every bin the IRF can move light
//! from, and each recorded time is the arrival plus a delay drawn from the
//! IRF (a Gaussian plus an exponential, or a measured table: uniform within
//! the drawn table bin), as a detector's jitter does. A
//! delay that would fall before its own sync is recorded at 0: give
//! `t0_delay_ps` more than the IRF's early support.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Exp, Normal, weighted::WeightedAliasIndex};
use scatterscope_physics::{InstrumentResponse, IrfTable, KernelStack, Sampling, Setup};

/// Bins of the ideal arrival kernels carrying fewer expected photons than
/// this are not sampled (a millionth of a photon per bin).
pub const NEGLIGIBLE_ARRIVAL_PHOTONS: f64 = 1e-6;

/// What to emit, besides the scene and its kernels.
#[derive(Debug, Clone, PartialEq)]
pub struct EmitterOptions {
    /// Detected signal photons per second (before losses at the sensor edge).
    pub rate_hz: f64,
    /// Dark counts per second over the whole sensor.
    pub dark_rate_hz: f64,
    /// Probability that a detection is followed by an afterpulse in the
    /// same pixel (0: off, the default).
    pub afterpulse_probability: f64,
    /// Mean delay of an afterpulse after its detection (exponential), ps.
    pub afterpulse_delay_ps: f64,
    /// Laser sync period, picoseconds.
    pub sync_period_ps: f64,
    /// Delay of time zero of the ST-PSF after the sync (cables,
    /// electronics), picoseconds; the host calibrates it away with t0.
    pub t0_delay_ps: f64,
    /// RNG seed.
    pub seed: u64,
}

impl Default for EmitterOptions {
    fn default() -> Self {
        Self {
            rate_hz: 2e6,
            dark_rate_hz: 0.0,
            afterpulse_probability: 0.0,
            afterpulse_delay_ps: 50_000.0,
            sync_period_ps: 12_500.0,
            t0_delay_ps: 0.0,
            seed: 0,
        }
    }
}

/// A photon as the sensor sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Detection {
    /// Row-major pixel index.
    pub pixel: u32,
    /// Arrival after the sync, picoseconds.
    pub delay_ps: f64,
    /// Laser-sync count.
    pub sync: u64,
    /// What produced it.
    pub origin: Origin,
}

/// What produced a detection.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Origin {
    /// A photon from the scene through the medium.
    Signal,
    /// A dark count.
    Dark,
    /// An afterpulse of an earlier detection in the same pixel.
    Afterpulse,
}

/// Samples detections; deterministic for a seed.
pub struct Emitter {
    width: usize,
    height: usize,
    source: WeightedAliasIndex<f64>,
    kernel: WeightedAliasIndex<f64>,
    /// (start, width) in ps of each kept kernel.
    bins: Vec<(f64, f64)>,
    options: EmitterOptions,
    gap: Exp<f64>,
    dark_fraction: f64,
    rng: ChaCha8Rng,
    time_s: f64,
    /// Afterpulses due later: (time s, pixel), earliest last.
    afterpulses: Vec<(f64, u32)>,
    off_sensor: u64,
    /// The IRF's delays, if any.
    jitter: Option<Jitter>,
}

/// How the recorded delay after an arrival is drawn.
#[derive(Debug, Clone)]
enum Jitter {
    /// The Gaussian part and the exponential tail, if any.
    Parametric(Normal<f64>, Option<Exp<f64>>),
    /// A measured table, by its inverse distribution.
    Measured(IrfTable),
}

/// Kernels of the arrival times that reach `setup`'s bins: the same
/// physics without the IRF, every bin down to
/// [`NEGLIGIBLE_ARRIVAL_PHOTONS`] kept (the setup's `min_bin_photons` is a
/// reconstruction's choice about its light budget; a device records every
/// photon that arrives), and with an IRF the binning extended on both
/// sides by its support.
fn arrival_kernels(
    setup: &Setup,
    irf: Option<&InstrumentResponse>,
) -> Result<KernelStack, EmitterError> {
    let mut s = setup.clone();
    s.irf = None;
    s.min_bin_photons = NEGLIGIBLE_ARRIVAL_PHOTONS;
    if let Some(irf) = irf {
        let (early, late) = irf.support_ps();
        let w = s.bins.width_ps;
        let before = ((late / w).ceil() as usize).min((s.bins.start_ps / w).floor() as usize);
        let after = (-early / w).ceil() as usize;
        s.bins.start_ps -= before as f64 * w;
        s.bins.count += before + after;
    }
    KernelStack::build(&s, Sampling::Integrated)
        .map_err(|e| EmitterError::Invalid(format!("arrival kernels: {e}")))
}

/// Why an emitter cannot be built.
#[derive(Debug, thiserror::Error)]
pub enum EmitterError {
    /// Scene and kernels disagree, or a value is out of range.
    #[error("mock emitter: {0}")]
    Invalid(String),
}

impl Emitter {
    /// An emitter for `scene` (row-major, `kernels`' sensor size, non-negative).
    pub fn new(
        scene: &[f64],
        kernels: &KernelStack,
        options: EmitterOptions,
    ) -> Result<Self, EmitterError> {
        let (k, h, w) = kernels.kernels.dim();
        if scene.len() != h * w {
            return Err(EmitterError::Invalid(format!(
                "scene has {} pixels, the sensor {}x{} = {}",
                scene.len(),
                w,
                h,
                h * w
            )));
        }
        if k == 0 {
            return Err(EmitterError::Invalid(
                "the ST-PSF has no kept time bin".into(),
            ));
        }
        let bad =
            |what: &str, v: f64| EmitterError::Invalid(format!("{what} = {v} is out of range"));
        let total_rate = options.rate_hz + options.dark_rate_hz;
        if !(options.rate_hz >= 0.0
            && options.dark_rate_hz >= 0.0
            && total_rate > 0.0
            && total_rate.is_finite())
        {
            return Err(bad("rate_hz + dark_rate_hz", total_rate));
        }
        if !(options.sync_period_ps > 0.0 && options.sync_period_ps.is_finite()) {
            return Err(bad("sync_period_ps", options.sync_period_ps));
        }
        if !(0.0..1.0).contains(&options.afterpulse_probability) {
            return Err(bad(
                "afterpulse_probability",
                options.afterpulse_probability,
            ));
        }
        if !(options.afterpulse_delay_ps > 0.0 && options.afterpulse_delay_ps.is_finite()) {
            return Err(bad("afterpulse_delay_ps", options.afterpulse_delay_ps));
        }
        let source = WeightedAliasIndex::new(
            scene
                .iter()
                .map(|&v| if v.is_finite() { v.max(0.0) } else { 0.0 })
                .collect(),
        )
        .map_err(|e| EmitterError::Invalid(format!("scene weights: {e}")))?;
        // Arrivals from the IRF-free kernels of every bin with light; with
        // an IRF, then the jitter.
        let arrivals = arrival_kernels(&kernels.setup, kernels.setup.irf.as_ref())?;
        let jitter = match &kernels.setup.irf {
            Some(InstrumentResponse::Parametric(irf)) => Some(Jitter::Parametric(
                Normal::new(0.0, irf.sigma_ps())
                    .map_err(|e| EmitterError::Invalid(format!("IRF: {e}")))?,
                (irf.tail_ps > 0.0)
                    .then(|| Exp::new(1.0 / irf.tail_ps))
                    .transpose()
                    .map_err(|e| EmitterError::Invalid(format!("IRF tail: {e}")))?,
            )),
            Some(InstrumentResponse::Measured(table)) => Some(Jitter::Measured(table.clone())),
            None => None,
        };
        let sampled = &arrivals;
        let kernel = WeightedAliasIndex::new(sampled.kernels.iter().map(|&v| v.max(0.0)).collect())
            .map_err(|e| EmitterError::Invalid(format!("kernel weights: {e}")))?;
        let bins = sampled
            .kept_bins()
            .map(|b| (b.start_ps, b.end_ps - b.start_ps))
            .collect();
        Ok(Self {
            width: w,
            height: h,
            source,
            kernel,
            bins,
            gap: Exp::new(total_rate).map_err(|e| EmitterError::Invalid(e.to_string()))?,
            dark_fraction: options.dark_rate_hz / total_rate,
            rng: ChaCha8Rng::seed_from_u64(options.seed),
            options,
            time_s: 0.0,
            afterpulses: Vec::new(),
            off_sensor: 0,
            jitter,
        })
    }

    /// Detections per second (signal and dark counts).
    pub fn rate_hz(&self) -> f64 {
        self.options.rate_hz + self.options.dark_rate_hz
    }

    /// Emission time of the last detection, seconds since start.
    pub fn time_s(&self) -> f64 {
        self.time_s
    }

    /// Signal photons so far that landed off the sensor (never detected).
    pub fn off_sensor(&self) -> u64 {
        self.off_sensor
    }

    /// Sensor size (width, height).
    pub fn sensor(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// The next detection (photons landing off the sensor are skipped; they
    /// are never detected).
    pub fn next_detection(&mut self) -> Detection {
        let d = self.next_primary();
        if self.options.afterpulse_probability > 0.0
            && self.rng.random::<f64>() < self.options.afterpulse_probability
        {
            let delay = -self.rng.random::<f64>().max(f64::MIN_POSITIVE).ln()
                * self.options.afterpulse_delay_ps;
            let at = self.time_s + (d.delay_ps + delay) * 1e-12;
            let i = self.afterpulses.partition_point(|&(t, _)| t > at);
            self.afterpulses.insert(i, (at, d.pixel));
        }
        d
    }

    /// A detection at `time` seconds in `pixel`.
    /// The sync period a time falls in. Every detection's sync comes from
    /// here: two roundings of the same time (`t / P` against `t 1e12 / P'`)
    /// can differ by one period at a boundary, and sync counts must never
    /// go back (found by the soak test after 2.4e9 photons).
    fn sync_of(&self, time_s: f64) -> u64 {
        (time_s * 1e12 / self.options.sync_period_ps) as u64
    }

    fn at(&self, time: f64, pixel: u32, origin: Origin) -> Detection {
        let sync = self.sync_of(time);
        Detection {
            pixel,
            delay_ps: (time * 1e12 - sync as f64 * self.options.sync_period_ps).max(0.0),
            sync,
            origin,
        }
    }

    fn next_primary(&mut self) -> Detection {
        loop {
            let next = self.time_s + self.gap.sample(&mut self.rng);
            if let Some(&(t, pixel)) = self.afterpulses.last()
                && t <= next
            {
                self.afterpulses.pop();
                // Never before what was already emitted: sync counts only
                // grow. The clock moves to the afterpulse (arrivals are
                // memoryless, so the next gap may start there); left behind,
                // the next primary could come before it.
                self.time_s = t.max(self.time_s);
                return self.at(self.time_s, pixel, Origin::Afterpulse);
            }
            self.time_s = next;
            let sync = self.sync_of(self.time_s);
            if self.rng.random::<f64>() < self.dark_fraction {
                let pixel = self.rng.random_range(0..self.width * self.height) as u32;
                let delay_ps = self.rng.random::<f64>() * self.options.sync_period_ps;
                return Detection {
                    pixel,
                    delay_ps,
                    sync,
                    origin: Origin::Dark,
                };
            }
            let src = self.source.sample(&mut self.rng);
            let entry = self.kernel.sample(&mut self.rng);
            let plane = self.width * self.height;
            let (bin, offset) = (entry / plane, entry % plane);
            let dy = (offset / self.width) as isize - (self.height / 2) as isize;
            let dx = (offset % self.width) as isize - (self.width / 2) as isize;
            let y = (src / self.width) as isize + dy;
            let x = (src % self.width) as isize + dx;
            if y < 0 || x < 0 || y >= self.height as isize || x >= self.width as isize {
                self.off_sensor += 1;
                continue;
            }
            let (start, width) = self.bins[bin];
            let mut delay_ps = self.options.t0_delay_ps + start + self.rng.random::<f64>() * width;
            match &self.jitter {
                Some(Jitter::Parametric(gauss, tail)) => {
                    delay_ps += gauss.sample(&mut self.rng);
                    if let Some(tail) = tail {
                        delay_ps += tail.sample(&mut self.rng);
                    }
                }
                Some(Jitter::Measured(table)) => {
                    delay_ps += table.delay_for(self.rng.random::<f64>());
                }
                None => {}
            }
            delay_ps = delay_ps.max(0.0);
            return Detection {
                pixel: (y as usize * self.width + x as usize) as u32,
                delay_ps,
                sync,
                origin: Origin::Signal,
            };
        }
    }
}
