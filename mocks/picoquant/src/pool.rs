//! The records the stand-in device replays: photons sampled from the
//! ST-PSF of a built-in scene (a point detector, or a galvo scan with line
//! and frame markers), encoded as T3 records with overflow records, spanning
//! a whole number of overflow periods so that replaying them continues the
//! time base exactly.

use scatterscope_mocks::{Emitter, EmitterOptions};
use scatterscope_physics::kernel::{KernelStack, Sampling};
use scatterscope_physics::params::Preset;

use crate::config::MockConfig;

/// The T3 record layout a family's FIFO delivers, as PicoQuant's
/// file-reading demos decode each record type (the PTU demos' `ProcessHHT3`
/// and `ProcessPHT3`): the stand-in encodes photons on input 0, markers and
/// overflows in the family's own bits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Records {
    /// HydraHarp v2, TimeHarp 260, MultiHarp and PicoHarp 330 T3: special
    /// 1 bit, channel 6, dtime 15, nsync 10; special channel 63 counts
    /// overflows of 1024 syncs in its nsync field, special 1-15 markers.
    Wide,
    /// PicoHarp 300 T3 (0x00010303): channel 4 bits, dtime 12, nsync 16;
    /// routing channel 1 the input, channel 15 special (dtime 0 one
    /// overflow of 65,536 syncs, else the marker bits).
    PicoHarp,
}

impl Records {
    /// Syncs per overflow.
    pub fn wrap(self) -> u64 {
        match self {
            Records::Wide => 1024,
            Records::PicoHarp => 65_536,
        }
    }

    /// The largest micro time (dtime) a record holds.
    fn max_micro(self) -> u32 {
        match self {
            Records::Wide => 0x7FFF,
            Records::PicoHarp => 0xFFF,
        }
    }

    /// Overflows one record can count.
    fn overflows_per_record(self) -> u64 {
        match self {
            Records::Wide => 1023,
            Records::PicoHarp => 1,
        }
    }

    fn photon(self, micro: u32, nsync: u32) -> u32 {
        match self {
            Records::Wide => (micro << 10) | nsync,
            Records::PicoHarp => (1 << 28) | (micro << 16) | nsync,
        }
    }

    fn marker(self, bits: u32, nsync: u32) -> u32 {
        match self {
            Records::Wide => (1 << 31) | (bits << 25) | nsync,
            Records::PicoHarp => (15 << 28) | (bits << 16) | nsync,
        }
    }

    fn overflow(self, n: u64) -> u32 {
        match self {
            Records::Wide => (1 << 31) | (63 << 25) | n as u32,
            Records::PicoHarp => 15 << 28,
        }
    }

    /// Whether `rec` is a photon record.
    pub fn is_photon(self, rec: u32) -> bool {
        match self {
            Records::Wide => rec >> 31 == 0,
            Records::PicoHarp => rec >> 28 != 15,
        }
    }

    /// Whether `rec` is a marker record.
    pub fn is_marker(self, rec: u32) -> bool {
        match self {
            Records::Wide => rec >> 31 == 1 && (rec >> 25) & 63 != 63 && (rec >> 25) & 63 != 0,
            Records::PicoHarp => rec >> 28 == 15 && (rec >> 16) & 0xF != 0,
        }
    }
}
/// Marker bits of the scanner's clocks (line start, line stop, frame).
pub const LINE_START: u32 = 1;
/// Line stop marker bit.
pub const LINE_STOP: u32 = 2;
/// Frame marker bit.
pub const FRAME: u32 = 4;
/// Syncs a scanned point is dwelt on.
pub const DWELL_SYNCS: u64 = 800;
/// Syncs of the scanner's return between lines.
const RETRACE_SYNCS: u64 = 1600;
/// Delay of the pulse's arrival after the sync, ps (cables).
pub const PULSE_DELAY_PS: f64 = 1000.0;
/// Photons in the point detector's pool.
const POINT_POOL_PHOTONS: usize = 1 << 21;
/// Frames in a scan's pool, each drawn on its own (Poisson), so that
/// frames differ as a real scanner's do; a run longer than these frames
/// replays them.
pub const SCAN_FRAMES: u64 = 8;

/// One replay unit.
pub struct Pool {
    /// The records.
    pub records: Vec<u32>,
    /// Sync count at each record (its time), from the pool's start.
    pub sync_at: Vec<u64>,
    /// Syncs the pool spans (a multiple of the layout's wrap).
    pub span: u64,
    /// Syncs of one frame of a scan (a multiple of the wrap; frame `f`
    /// starts at `f * frame_span`); the whole span for a point detector.
    pub frame_span: u64,
    /// Scan pixel of each photon record (`u32::MAX` for other records);
    /// empty for a point detector.
    pub pixel_of: Vec<u32>,
    /// The records' layout.
    pub layout: Records,
}

/// An event before encoding: sync count, and a photon's (channel, micro
/// time) or a marker's bits.
#[derive(Clone, Copy)]
enum Event {
    Photon { sync: u64, micro: u32, pixel: u32 },
    Marker { sync: u64, bits: u32 },
}

impl Event {
    fn sync(&self) -> u64 {
        match *self {
            Event::Photon { sync, .. } | Event::Marker { sync, .. } => sync,
        }
    }
}

/// The built-in scene on a `w` x `h` grid: a bright bar, a dimmer disc
/// and a faint background, so that scanned images have structure.
pub fn scene(w: usize, h: usize) -> Vec<f64> {
    (0..w * h)
        .map(|p| 0.02 + [1.0, 0.5, 0.0][object(w, h, p % w, p / w)])
        .collect()
}

/// Which object of the built-in scene point `(x, y)` of a `w` x `h` grid
/// shows: 0 the bar, 1 the disc, 2 the background.
pub fn object(w: usize, h: usize, x: usize, y: usize) -> usize {
    let (fx, fy) = (x as f64 / w as f64, y as f64 / h as f64);
    if (0.2..0.35).contains(&fx) && (0.15..0.85).contains(&fy) {
        0
    } else if (fx - 0.65).powi(2) + (fy - 0.5).powi(2) < 0.04 {
        1
    } else {
        2
    }
}

/// Delays of a FLIM scan told its objects' lifetimes: the pulse, a
/// Gaussian IRF and the object's exponential, wrapped into the period.
struct Lifetimes {
    rng: rand_chacha::ChaCha8Rng,
    irf: rand_distr::Normal<f64>,
    decays: [crate::config::Decay; 3],
    period_ps: f64,
}

impl Lifetimes {
    fn new(cfg: &MockConfig, period_ps: f64) -> Option<Self> {
        use rand::SeedableRng;
        let decays = cfg.lifetimes.clone()?;
        Some(Self {
            rng: rand_chacha::ChaCha8Rng::seed_from_u64(cfg.seed ^ 0x11fe_7173),
            irf: rand_distr::Normal::new(PULSE_DELAY_PS, cfg.irf_fwhm_ps / 2.354_820_045)
                .expect("a positive width"),
            decays,
            period_ps,
        })
    }

    /// A photon's delay after the sync from object `o`.
    fn delay(&mut self, o: usize) -> f64 {
        use rand::RngExt;
        use rand_distr::Distribution;
        let mut u: f64 = self.rng.random();
        let comps = &self.decays[o].0;
        let mut tau = comps[comps.len() - 1].0;
        for &(t, share) in comps {
            if u < share {
                tau = t;
                break;
            }
            u -= share;
        }
        let e: f64 = rand_distr::Exp::new(1.0 / tau)
            .expect("a positive lifetime")
            .sample(&mut self.rng);
        (self.irf.sample(&mut self.rng) + e).rem_euclid(self.period_ps)
    }
}

fn emitter(cfg: &MockConfig, w: usize, h: usize, period_ps: f64) -> Result<Emitter, String> {
    let mut setup = Preset::Paper.setup();
    setup.sensor.width_px = w;
    setup.sensor.height_px = h;
    let kernels = KernelStack::build(&setup, Sampling::Integrated).map_err(|e| e.to_string())?;
    Emitter::new(
        &scene(w, h),
        &kernels,
        EmitterOptions {
            rate_hz: cfg.rate_hz,
            dark_rate_hz: cfg.dark_hz,
            sync_period_ps: period_ps,
            t0_delay_ps: PULSE_DELAY_PS,
            seed: cfg.seed,
            ..EmitterOptions::default()
        },
    )
    .map_err(|e| e.to_string())
}

/// Builds the pool for `cfg` at a micro-time unit of `resolution_ps` and a
/// sync period of `period_ps`, in `layout`'s records.
pub fn build(
    cfg: &MockConfig,
    resolution_ps: f64,
    period_ps: f64,
    layout: Records,
) -> Result<Pool, String> {
    let wrap = layout.wrap();
    let micro = |delay_ps: f64| ((delay_ps / resolution_ps) as u32).min(layout.max_micro());
    let mut events = Vec::new();
    match cfg.scan {
        None => {
            // A point detector: every photon on input 0.
            let mut e = emitter(cfg, 16, 16, period_ps)?;
            for _ in 0..POINT_POOL_PHOTONS {
                let d = e.next_detection();
                events.push(Event::Photon {
                    sync: d.sync,
                    micro: micro(d.delay_ps),
                    pixel: u32::MAX,
                });
            }
        }
        Some((w, h)) => {
            let mut e = emitter(cfg, w, h, period_ps)?;
            let mut told = Lifetimes::new(cfg, period_ps);
            let line = w as u64 * DWELL_SYNCS + RETRACE_SYNCS;
            let frame_syncs = h as u64 * line;
            let frame_span = frame_syncs.div_ceil(wrap) * wrap;
            // The clocks first: a photon at the same sync as a line's start
            // follows it (the sort below is stable).
            for frame in 0..SCAN_FRAMES {
                let base = frame * frame_span;
                events.push(Event::Marker {
                    sync: base,
                    bits: FRAME,
                });
                for y in 0..h as u64 {
                    let start = base + y * line + 1;
                    events.push(Event::Marker {
                        sync: start,
                        bits: LINE_START,
                    });
                    events.push(Event::Marker {
                        sync: start + w as u64 * DWELL_SYNCS,
                        bits: LINE_STOP,
                    });
                }
            }
            // Photons drawn over each frame's time in turn, each placed in
            // its pixel's dwell (a point is seen only while the scan is on
            // it); with a drift the scene moves `drift` points to the right
            // a frame (wrapping around).
            loop {
                let d = e.next_detection();
                let frame = d.sync / frame_syncs;
                if frame >= SCAN_FRAMES {
                    break;
                }
                let shift = (frame * cfg.drift as u64) % w as u64;
                let (x, y) = (
                    (u64::from(d.pixel) % w as u64 + shift) % w as u64,
                    u64::from(d.pixel) / w as u64,
                );
                events.push(Event::Photon {
                    sync: frame * frame_span
                        + y * line
                        + 1
                        + x * DWELL_SYNCS
                        + d.sync % DWELL_SYNCS,
                    micro: micro(match told.as_mut() {
                        Some(t) => {
                            let p = d.pixel as usize;
                            t.delay(object(w, h, p % w, p / w))
                        }
                        None => d.delay_ps,
                    }),
                    pixel: (y * w as u64 + x) as u32,
                });
            }
            events.sort_by_key(Event::sync);
            return Ok(encode(
                &events,
                Some(SCAN_FRAMES * frame_span),
                frame_span,
                layout,
            ));
        }
    }
    Ok(encode(&events, None, 0, layout))
}

/// Encodes `events` in `layout`'s records; a scan's pool (`span` given)
/// ends at that span, its frames `frame_span` apart; a point detector's on
/// the wrap after its last event.
fn encode(events: &[Event], span: Option<u64>, frame_span: u64, layout: Records) -> Pool {
    let scanned = span.is_some();
    let wrap = layout.wrap();
    let mut pool = Pool {
        records: Vec::with_capacity(events.len() * 21 / 20),
        sync_at: Vec::with_capacity(events.len() * 21 / 20),
        span: 0,
        frame_span,
        pixel_of: Vec::new(),
        layout,
    };
    let mut base = 0u64;
    let push = |pool: &mut Pool, rec: u32, sync: u64, pixel: u32| {
        pool.records.push(rec);
        pool.sync_at.push(sync);
        if scanned {
            pool.pixel_of.push(pixel);
        }
    };
    let per_record = layout.overflows_per_record();
    for ev in events {
        let s = ev.sync();
        while s - base >= wrap {
            let n = ((s - base) / wrap).min(per_record);
            base += n * wrap;
            push(&mut pool, layout.overflow(n), base, u32::MAX);
        }
        let nsync = (s - base) as u32;
        match *ev {
            Event::Photon { micro, pixel, .. } => {
                push(&mut pool, layout.photon(micro, nsync), s, pixel);
            }
            Event::Marker { bits, .. } => push(&mut pool, layout.marker(bits, nsync), s, u32::MAX),
        }
    }
    match span {
        // Close the pool on its span, so that frames replay in step.
        Some(span) => {
            while base < span {
                let n = ((span - base) / wrap).min(per_record);
                base += n * wrap;
                push(&mut pool, layout.overflow(n), base, u32::MAX);
            }
        }
        // Close the pool on an overflow boundary past its last event.
        None => {
            base += wrap;
            push(&mut pool, layout.overflow(1), base, u32::MAX);
            pool.frame_span = base;
        }
    }
    pool.span = base;
    pool
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Decodes a pool's records back to (sync, record) for photons and
    /// markers, with each layout's overflow rule.
    fn decode(records: &[u32], layout: Records) -> Vec<(u64, u32)> {
        let mut base = 0u64;
        let mut out = Vec::new();
        for &r in records {
            let overflow = match layout {
                Records::Wide if r >> 31 == 1 && (r >> 25) & 63 == 63 => {
                    Some(u64::from(r & 1023).max(1))
                }
                Records::PicoHarp if r >> 28 == 15 && (r >> 16) & 0xFFF == 0 => Some(1),
                _ => None,
            };
            match overflow {
                Some(n) => base += layout.wrap() * n,
                None => {
                    let nsync = match layout {
                        Records::Wide => r & 1023,
                        Records::PicoHarp => r & 0xFFFF,
                    };
                    out.push((base + u64::from(nsync), r))
                }
            }
        }
        out
    }

    #[test]
    fn records_decode_to_their_times_and_the_pool_ends_on_a_wrap() {
        let cfg = MockConfig {
            scan: Some((4, 3)),
            ..MockConfig::default()
        };
        for layout in [Records::Wide, Records::PicoHarp] {
            let pool = build(&cfg, 5.0, 12_500.0, layout).unwrap();
            assert_eq!(pool.span % layout.wrap(), 0);
            let decoded = decode(&pool.records, layout);
            let times: Vec<u64> = pool
                .records
                .iter()
                .zip(&pool.sync_at)
                .filter(|(r, _)| layout.is_photon(**r) || layout.is_marker(**r))
                .map(|(_, &s)| s)
                .collect();
            assert_eq!(decoded.iter().map(|d| d.0).collect::<Vec<_>>(), times);
            assert!(times.windows(2).all(|w| w[0] <= w[1]));
            assert!(*times.last().unwrap() < pool.span);
            let markers = pool.records.iter().filter(|&&r| layout.is_marker(r));
            assert_eq!(
                markers.count() as u64,
                SCAN_FRAMES * (1 + 2 * 3),
                "a frame marker and two per line ({layout:?})"
            );
            assert_eq!(pool.span, SCAN_FRAMES * pool.frame_span);
            // Every photon lies in its pixel's dwell, on the layout's first
            // input (PicoHarp routing channel 1).
            let line = 4 * DWELL_SYNCS + RETRACE_SYNCS;
            for ((&r, &s), &p) in pool.records.iter().zip(&pool.sync_at).zip(&pool.pixel_of) {
                if layout.is_photon(r) {
                    let (x, y) = (u64::from(p) % 4, u64::from(p) / 4);
                    let start =
                        s / pool.frame_span * pool.frame_span + y * line + 1 + x * DWELL_SYNCS;
                    assert!(
                        (start..start + DWELL_SYNCS).contains(&s),
                        "pixel {p} at {s}"
                    );
                    let channel = match layout {
                        Records::Wide => (r >> 25) & 63,
                        Records::PicoHarp => r >> 28,
                    };
                    assert_eq!(channel, u32::from(layout == Records::PicoHarp));
                }
            }
        }
    }

    /// Per-pixel photons of each frame of a scan's pool.
    fn frame_images(pool: &Pool, pixels: usize) -> Vec<Vec<u64>> {
        let frames = (pool.span / pool.frame_span) as usize;
        let mut images = vec![vec![0u64; pixels]; frames];
        for ((&r, &s), &p) in pool.records.iter().zip(&pool.sync_at).zip(&pool.pixel_of) {
            if pool.layout.is_photon(r) {
                images[(s / pool.frame_span) as usize][p as usize] += 1;
            }
        }
        images
    }

    #[test]
    fn frames_vary_as_poisson_draws_and_drift_moves_the_scene() {
        let still = MockConfig {
            scan: Some((16, 8)),
            rate_hz: 2e7,
            ..MockConfig::default()
        };
        let images = frame_images(&build(&still, 5.0, 12_500.0, Records::Wide).unwrap(), 128);
        assert_eq!(images.len() as u64, SCAN_FRAMES);
        for pair in images.windows(2) {
            assert_ne!(pair[0], pair[1], "two frames identical count for count");
        }
        // Frame totals scatter about their mean as Poisson counts do.
        let totals: Vec<f64> = images
            .iter()
            .map(|i| i.iter().sum::<u64>() as f64)
            .collect();
        let mean = totals.iter().sum::<f64>() / totals.len() as f64;
        let var =
            totals.iter().map(|t| (t - mean).powi(2)).sum::<f64>() / (totals.len() - 1) as f64;
        assert!(mean > 1000.0, "{mean}");
        assert!(var / mean < 4.0, "variance {var} for a mean {mean}");
        // A drift of 2 points a frame moves the image's centroid right
        // (the bright bar sits at a fifth of the width).
        let drifting = MockConfig { drift: 2, ..still };
        let images = frame_images(
            &build(&drifting, 5.0, 12_500.0, Records::Wide).unwrap(),
            128,
        );
        let centroid = |img: &Vec<u64>| {
            let (mut sx, mut n) = (0.0, 0.0);
            for (p, &c) in img.iter().enumerate() {
                sx += (p % 16) as f64 * c as f64;
                n += c as f64;
            }
            sx / n
        };
        assert!(
            centroid(&images[2]) > centroid(&images[0]) + 1.5,
            "{} then {}",
            centroid(&images[0]),
            centroid(&images[2])
        );
    }
}
