//! What the live page shows, updated by the acquisition's watching stage
//! and by the reconstruction thread, read by the server. The watching
//! stage keeps its own copy and only tries the shared one's lock: the
//! server and the reconstruction run below the acquisition's priority, and
//! one preempted while holding the lock would otherwise stall the
//! acquisition.

use serde::Serialize;

use crate::acquire::{Ledger, Snapshot};
use crate::tags::counts::Counts;

/// Rates kept for the page: the last minute.
pub const RATE_HISTORY_S: f64 = 60.0;

/// How often a FLIM scan's mean-arrival-time image is remade: a pass over
/// the stack on the rayon pool (about 50 ms for 256 x 256 x 133 bins on 2
/// vCPUs), off the 250 ms cadence of the rest.
pub const MEAN_TIME_EVERY: std::time::Duration = std::time::Duration::from_secs(1);

/// One point of the rate plot.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct RatePoint {
    /// Seconds since the start.
    pub t_s: f64,
    /// Photons received per second.
    pub photons_per_s: f64,
    /// Count rate of each input the device reports (counts/s); empty when
    /// it reports none.
    pub inputs: Vec<f64>,
}

/// The decay histogram: photons per bin over every pixel.
#[derive(Debug, Clone, Default, Serialize, PartialEq)]
pub struct Decay {
    /// Start of the first bin after time zero, ps.
    pub start_ps: f64,
    /// Bin width, ps.
    pub width_ps: f64,
    /// Photons per bin.
    pub counts: Vec<u64>,
    /// The bins the last reconstruction kept (enough light to use).
    pub kept: Vec<usize>,
}

/// An image: row-major values.
#[derive(Debug, Clone, Default, Serialize, PartialEq)]
pub struct Image {
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Values, row-major.
    pub values: Vec<f32>,
}

/// The mean photon arrival time of every pixel of a FLIM scan, after the
/// decay's onset, as `lifetime` maps it ([`crate::decay::decay_maps`]).
#[derive(Debug, Clone, Default, Serialize, PartialEq)]
pub struct MeanTime {
    /// Mean arrival time after the onset, ps; `null` (NaN) where masked.
    pub image: Image,
    /// Seconds of acquisition it holds.
    pub acquired_s: f64,
    /// Pixels with fewer photons are masked.
    pub min_photons: f64,
    /// What was assumed and left out, in words (the onset, the mask).
    pub notes: Vec<String>,
}

/// The counters so far.
#[derive(Debug, Clone, Default, Serialize, PartialEq)]
pub struct Counters {
    /// Where the records and photons read went.
    #[serde(flatten)]
    pub counts: Counts,
    /// Frames that failed their checks.
    pub damaged_frames: u64,
}

/// One reconstruction of a snapshot.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct LiveReconstruction {
    /// Seconds of acquisition the snapshot holds.
    pub acquired_s: f64,
    /// Photons in it.
    pub photons: u64,
    /// The method that ran (the default, `auto`, says which it chose).
    pub method: String,
    /// Seconds the reconstruction took.
    pub run_s: f64,
    /// The image, on the sensor's grid.
    pub image: Image,
    /// Its notes (what it assumed, chose and left out).
    pub notes: Vec<String>,
    /// PSNR against the known truth (mock scenes), dB, after the gain that
    /// best fits the truth (a snapshot's light budget is not yet known).
    pub psnr_db: Option<f64>,
}

/// One point of the error-against-run-time trace.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct TracePoint {
    /// Seconds of acquisition.
    pub acquired_s: f64,
    /// Photons.
    pub photons: u64,
    /// PSNR against the truth, dB.
    pub psnr_db: Option<f64>,
    /// Seconds the reconstruction took.
    pub run_s: f64,
}

/// Everything the page shows.
#[derive(Debug, Clone, Default, Serialize)]
pub struct LiveState {
    /// The device, in words.
    pub device: String,
    /// Seconds since the start.
    pub elapsed_s: f64,
    /// Whether the acquisition has ended (then `ledger` is final).
    pub done: bool,
    /// Why it ended, once it has.
    pub ended: Option<String>,
    /// Rates over the last minute.
    pub rates: Vec<RatePoint>,
    /// The decay histogram.
    pub decay: Decay,
    /// The accumulated intensity image (photons per pixel).
    pub image: Image,
    /// A FLIM scan's mean-arrival-time image, updated every
    /// [`MEAN_TIME_EVERY`]; `None` for other devices.
    pub mean_time: Option<MeanTime>,
    /// Why a FLIM scan shows no mean-arrival-time image, when it cannot.
    pub mean_time_error: Option<String>,
    /// The counters so far.
    pub counters: Counters,
    /// The final ledger, once the acquisition ended.
    pub ledger: Option<Ledger>,
    /// The final ledger as the summary prints it.
    pub ledger_table: Vec<String>,
    /// The latest reconstruction.
    pub reconstruction: Option<LiveReconstruction>,
    /// Error against run time: one point per reconstruction.
    pub trace: Vec<TracePoint>,
    /// What the reconstruction of a snapshot could not do, if it failed.
    pub reconstruction_error: Option<String>,
    /// Why snapshots are being skipped (the acquisition keeps every core
    /// busy), while they are.
    pub reconstruction_paused: Option<String>,
    /// What the reconstruction is doing now, in words, when no result
    /// shows it: a snapshot at work, starved of CPU (and by what), the
    /// whole run's reconstruction, or that it was skipped.
    pub reconstruction_status: Option<String>,
    /// Increments on every change.
    pub version: u64,
}

impl LiveState {
    /// Takes in a snapshot of the running acquisition: counters, rates,
    /// decay histogram and image (summed over bins), copied.
    pub fn update(&mut self, s: &Snapshot<'_>) {
        let p = s.progress;
        self.device = format!(
            "{} ({} {})",
            s.facts.device.link, s.facts.device.model, s.facts.device.serial
        );
        self.elapsed_s = p.elapsed.as_secs_f64();
        self.counters = Counters {
            counts: p.counts,
            damaged_frames: p.damaged_frames,
        };
        self.rates.push(RatePoint {
            t_s: self.elapsed_s,
            photons_per_s: p.rate_hz,
            inputs: p.rates.as_ref().map_or(Vec::new(), |r| r.inputs.clone()),
        });
        let keep_from = self.elapsed_s - RATE_HISTORY_S;
        self.rates.retain(|r| r.t_s >= keep_from);
        let (k, h, w) = s.counts.dim();
        let mut decay = vec![0u64; k];
        let mut image = vec![0f32; h * w];
        for (b, plane) in s.counts.outer_iter().enumerate() {
            for (i, &c) in plane.iter().enumerate() {
                decay[b] += u64::from(c);
                image[i] += c as f32;
            }
        }
        self.decay.start_ps = s.window_ps.0 - s.t0_ps;
        self.decay.width_ps = s.window_ps.1;
        self.decay.counts = decay;
        self.image = Image {
            width: w,
            height: h,
            values: image,
        };
        self.version += 1;
    }

    /// Remakes the mean-arrival-time image from the whole run's stack of
    /// a FLIM scan (at `sync_period_ps`), `acquired_s` long.
    pub fn final_mean_time(&mut self, stack: &crate::Stack, sync_period_ps: f64, acquired_s: f64) {
        let options = mean_time_options();
        let maps = crate::decay::decay_maps_f32(
            stack.data.view(),
            &stack.meta.bin_starts_ps,
            stack.meta.bin_width_ps,
            1e12 / sync_period_ps,
            &options,
        );
        self.show_mean_time(mean_time_of(maps, acquired_s, &options));
    }

    /// Shows a mean-arrival-time image, or why there is none.
    pub fn show_mean_time(&mut self, mean_time: Result<MeanTime, String>) {
        match mean_time {
            Ok(m) => {
                self.mean_time = Some(m);
                self.mean_time_error = None;
            }
            Err(e) => self.mean_time_error = Some(e),
        }
        self.version += 1;
    }

    /// Shows what `acquired` holds of the acquisition (device, counters,
    /// rates, decay, image), leaving the reconstruction's part as it is.
    pub fn show_acquisition(&mut self, acquired: &LiveState) {
        self.device.clone_from(&acquired.device);
        self.elapsed_s = acquired.elapsed_s;
        self.counters = acquired.counters.clone();
        self.rates.clone_from(&acquired.rates);
        self.decay.start_ps = acquired.decay.start_ps;
        self.decay.width_ps = acquired.decay.width_ps;
        self.decay.counts.clone_from(&acquired.decay.counts);
        self.image.clone_from(&acquired.image);
        self.version += 1;
    }
}

/// The mean-arrival-time image of a FLIM scan's counts so far (`counts`,
/// bins starting at `starts_ps`, `width_ps` wide, a laser of
/// `frequency_hz`), `acquired_s` into the run, or why there is none.
pub fn counts_mean_time(
    counts: ndarray::ArrayView3<'_, u32>,
    (starts_ps, width_ps): (&[f64], f64),
    frequency_hz: f64,
    acquired_s: f64,
) -> Result<MeanTime, String> {
    let options = mean_time_options();
    let maps = crate::decay::decay_maps(
        crate::stack::CountsView::U32(counts),
        starts_ps,
        width_ps,
        frequency_hz,
        &options,
    );
    mean_time_of(maps, acquired_s, &options)
}

/// The image of `maps`' mean arrival times, made with `options`,
/// `acquired_s` into the run; their error in words.
fn mean_time_of(
    maps: Result<crate::decay::DecayMaps, crate::decay::DecayError>,
    acquired_s: f64,
    options: &crate::decay::DecayOptions,
) -> Result<MeanTime, String> {
    let maps = maps.map_err(|e| e.to_string())?;
    let (h, w) = maps.mean_time_ps.dim();
    Ok(MeanTime {
        image: Image {
            width: w,
            height: h,
            values: maps.mean_time_ps.iter().map(|&v| v as f32).collect(),
        },
        acquired_s,
        min_photons: options.min_photons,
        notes: maps
            .notes
            .into_iter()
            .filter(|n| !n.starts_with("phasors"))
            .collect(),
    })
}

/// The live view's mean-time maps: `lifetime`'s defaults (the half-maximum
/// onset, pixels of fewer than 20 photons masked), one harmonic.
fn mean_time_options() -> crate::decay::DecayOptions {
    crate::decay::DecayOptions {
        harmonics: vec![1],
        ..crate::decay::DecayOptions::default()
    }
}
