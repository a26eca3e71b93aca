//! What every pixel's decay says: photon count, mean arrival time and its
//! variance after the decay's onset, PicoQuant's fast lifetime, and phasor
//! coordinates at harmonics of the laser frequency, calibrated against a
//! reference of known lifetime into apparent phase and modulation
//! lifetimes: the first picture of a FLIM recording, and time-domain
//! diffuse optics' moments of the time of flight.
//!
//! Definitions (bin `k` of width `w` starting at `t_k - w/2`, its centre
//! `t_k`, holding `n_k` photons of a pixel):
//! - **onset** `t_0`: where the decay of the whole image (every pixel
//!   summed) first reaches half its maximum on its rising edge, linearly
//!   interpolated between bin centres: the "entrance of the FWHM interval"
//!   that PicoQuant's Time-Resolved Fluorescence Wiki (tcspc.com, "Fast
//!   lifetime") names as a time zero when no IRF is at hand; or the
//!   barycentre of a measured IRF when one is given.
//! - **mean arrival time** `m = sum n_k (t_k - t_0) / sum n_k` and its
//!   **variance** `sum n_k (t_k - t_0 - m)^2 / sum n_k`, over the bins at
//!   or after the onset (photons before it are background and IRF, left
//!   out, and counted).
//! - **fast lifetime** as PicoQuant's wiki defines SymPhoTime's FastLT: the
//!   barycentre of the pixel's whole decay minus the time zero (the IRF's
//!   barycentre, else the entrance of the FWHM interval), in SymPhoTime's
//!   conventions: a photon of bin `k` arrives at the bin's start
//!   (TCSPC channel times resolution), and without an IRF the time zero is
//!   the start of the first bin of the image's summed decay at or above
//!   half its maximum (no interpolation). The **centred fast lifetime**
//!   keeps this module's own conventions (bins' centres, the interpolated
//!   onset): the two differ by a constant per image, less than a bin.
//! - **phasor** at harmonic `h` of the laser frequency `f`:
//!   `g = sum n_k cos(2 pi h f t_k) / N`, `s = sum n_k sin(2 pi h f t_k) / N`,
//!   `N = sum n_k` over every bin: PhasorPy's `phasor_from_signal` with the
//!   bins' phases given (`sample_phase`).
//! - **calibration** as PhasorPy's `phasor_calibrate`: the reference's
//!   phasor (that of its whole decay, every pixel summed) is rotated and
//!   scaled onto the phasor of a single exponential of its known lifetime
//!   (`g = 1/(1+(w tau)^2)`, `s = w tau/(1+(w tau)^2)`; an IRF is lifetime
//!   0), and every pixel's phasor by the same phase and modulation; the
//!   apparent lifetimes are `tau_phi = s / (w g)` and
//!   `tau_m = sqrt(1/(g^2 + s^2) - 1) / w` (0 past the semicircle's
//!   modulation 1, as PhasorPy).
//!
//! Pixels with fewer photons than the threshold are masked: their times,
//! lifetimes and phasors are NaN in the maps, the mask says which, and the
//! notes count them.

pub mod fit;
mod map_files;
pub mod recording;

use ndarray::{Array2, ArrayView3, Axis};

use crate::stack::CountsView;

/// Why maps cannot be made.
#[derive(Debug, thiserror::Error)]
pub enum DecayError {
    /// The stack or the settings cannot give maps; says which and why.
    #[error("{0}")]
    Input(String),
}

/// Where the decay starts, the time zero of the arrival times.
#[derive(Debug, Clone, PartialEq)]
pub enum Onset {
    /// The half-maximum crossing on the rising edge of the image's summed
    /// decay.
    HalfMaximum,
    /// A given time (ps after the sync).
    At(f64),
    /// The barycentre of a measured IRF (ps after the sync): the fast
    /// lifetime's time zero, and the onset.
    IrfBarycentre(f64),
}

/// A reference of known lifetime, as its phasors (harmonic by harmonic,
/// of its whole decay) and that lifetime.
#[derive(Debug, Clone, PartialEq)]
pub struct Reference {
    /// Its phasor `(g, s)` per harmonic of [`DecayOptions::harmonics`].
    pub phasors: Vec<(f64, f64)>,
    /// Its lifetime (ps; 0 for an IRF).
    pub lifetime_ps: f64,
    /// What it is, in words (a file's name).
    pub what: String,
}

/// How the maps are made.
#[derive(Debug, Clone, PartialEq)]
pub struct DecayOptions {
    /// Harmonics of the laser frequency.
    pub harmonics: Vec<u32>,
    /// Pixels with fewer photons are masked.
    pub min_photons: f64,
    /// The onset rule.
    pub onset: Onset,
    /// The reference the phasors are calibrated against, if any.
    pub reference: Option<Reference>,
}

impl Default for DecayOptions {
    /// The first two harmonics, pixels of fewer than 20 photons masked
    /// (the phasor of 20 photons of a 2 ns decay at 80 MHz scatters by
    /// about 0.1 in g and s), the half-maximum onset, no reference.
    fn default() -> Self {
        Self {
            harmonics: vec![1, 2],
            min_photons: 20.0,
            onset: Onset::HalfMaximum,
            reference: None,
        }
    }
}

/// One harmonic's phasor maps.
#[derive(Debug, Clone)]
pub struct PhasorMaps {
    /// The harmonic.
    pub harmonic: u32,
    /// `g` (NaN where masked).
    pub g: Array2<f64>,
    /// `s` (NaN where masked).
    pub s: Array2<f64>,
    /// Calibrated `g`, `s`, apparent phase and modulation lifetimes (ps),
    /// with a reference.
    pub calibrated: Option<Calibrated>,
}

/// Phasors calibrated against a reference, and their apparent lifetimes.
#[derive(Debug, Clone)]
pub struct Calibrated {
    /// Calibrated `g`.
    pub g: Array2<f64>,
    /// Calibrated `s`.
    pub s: Array2<f64>,
    /// Apparent phase lifetime (ps).
    pub tau_phase_ps: Array2<f64>,
    /// Apparent modulation lifetime (ps).
    pub tau_modulation_ps: Array2<f64>,
    /// The rotation (rad) and scale the reference gave.
    pub phase_rad: f64,
    /// See `phase_rad`.
    pub modulation: f64,
}

/// Every map of one stack.
#[derive(Debug, Clone)]
pub struct DecayMaps {
    /// Photons per pixel, every bin.
    pub intensity: Array2<f64>,
    /// Mean arrival time after the onset (ps; NaN where masked).
    pub mean_time_ps: Array2<f64>,
    /// Variance of the arrival times after the onset (ps^2; NaN where
    /// masked).
    pub variance_ps2: Array2<f64>,
    /// PicoQuant's fast lifetime in SymPhoTime's conventions (ps; NaN
    /// where masked).
    pub fast_lifetime_ps: Array2<f64>,
    /// The fast lifetime from the bins' centres and the interpolated
    /// onset (ps; NaN where masked).
    pub fast_lifetime_centred_ps: Array2<f64>,
    /// The phasors, harmonic by harmonic.
    pub phasors: Vec<PhasorMaps>,
    /// True where a pixel is masked.
    pub mask: Array2<bool>,
    /// The onset used (ps after the sync).
    pub onset_ps: f64,
    /// The laser frequency (Hz).
    pub frequency_hz: f64,
    /// What was assumed and left out, in words.
    pub notes: Vec<String>,
}

/// The phasor `(g, s)` of a single exponential decay of `lifetime_ps` at
/// angular frequency `omega` (rad/ps).
pub fn single_exponential_phasor(lifetime_ps: f64, omega: f64) -> (f64, f64) {
    let wt = omega * lifetime_ps;
    let d = 1.0 + wt * wt;
    (1.0 / d, wt / d)
}

/// The onset of `decay` (counts per bin, centres `centres_ps`): the
/// half-maximum crossing of its rising edge, interpolated; `None` for an
/// empty decay.
pub fn half_maximum_onset(decay: &[f64], centres_ps: &[f64]) -> Option<f64> {
    let (peak, top) = decay.iter().enumerate().fold(
        (0, 0.0),
        |(i, m), (j, &v)| if v > m { (j, v) } else { (i, m) },
    );
    if top <= 0.0 {
        return None;
    }
    let half = top / 2.0;
    // The last bin before the peak below half the maximum, then the
    // crossing between it and the next.
    match (0..=peak).rev().find(|&k| decay[k] < half) {
        None => Some(centres_ps[0]),
        Some(k) => {
            let (a, b) = (decay[k], decay[k + 1]);
            let t = (half - a) / (b - a);
            Some(centres_ps[k] + t * (centres_ps[k + 1] - centres_ps[k]))
        }
    }
}

/// SymPhoTime's time zero of `decay` (counts per bin; bins start at
/// `starts_ps`, `width_ps` wide) for its fast lifetime, photons at their
/// bins' starts: the rising flank's line, through the steepest-rising
/// pair of bins before the peak (each at its start), extended to the
/// peak's count, less half a bin. PicoQuant's glossary names "the rising
/// flank of the decay" as the time zero where no IRF is measured without
/// giving the construction; this one reproduces SymPhoTime 64's export of
/// PicoQuant's example within 0.1 ps (`tests/symphotime.rs`). `None` for
/// an empty decay or one that does not rise before its peak.
pub fn rising_flank_zero(decay: &[f64], starts_ps: &[f64], width_ps: f64) -> Option<f64> {
    let (peak, top) = decay.iter().enumerate().fold(
        (0, 0.0),
        |(i, m), (j, &v)| if v > m { (j, v) } else { (i, m) },
    );
    let (k, rise) =
        (0..peak)
            .map(|j| (j, decay[j + 1] - decay[j]))
            .fold(
                (0, 0.0),
                |(i, m), (j, r)| if r > m { (j, r) } else { (i, m) },
            );
    (top > 0.0 && rise > 0.0)
        .then(|| starts_ps[k] + (top - decay[k]) / rise * width_ps - width_ps / 2.0)
}

/// The phasor of a whole decay (`counts` per bin at `centres_ps`) at each
/// harmonic of `frequency_hz`: a reference's.
pub fn decay_phasors(
    counts: &[f64],
    centres_ps: &[f64],
    frequency_hz: f64,
    harmonics: &[u32],
) -> Vec<(f64, f64)> {
    let total: f64 = counts.iter().sum();
    harmonics
        .iter()
        .map(|&h| {
            let omega = 2.0 * std::f64::consts::PI * f64::from(h) * frequency_hz * 1e-12;
            let (g, s) = counts
                .iter()
                .zip(centres_ps)
                .fold((0.0, 0.0), |(g, s), (&n, &t)| {
                    (g + n * (omega * t).cos(), s + n * (omega * t).sin())
                });
            (g / total, s / total)
        })
        .collect()
}

/// The maps of `counts` (bins, rows, columns) whose bins start at
/// `starts_ps` and are `width_ps` wide, at the laser frequency
/// `frequency_hz`.
pub fn decay_maps(
    counts: CountsView<'_>,
    starts_ps: &[f64],
    width_ps: f64,
    frequency_hz: f64,
    options: &DecayOptions,
) -> Result<DecayMaps, DecayError> {
    match counts {
        CountsView::U16(c) => maps_of(c, starts_ps, width_ps, frequency_hz, options),
        CountsView::U32(c) => maps_of(c, starts_ps, width_ps, frequency_hz, options),
    }
}

/// [`decay_maps`] of float values (a stack read from a file); every value
/// must be a finite count `>= 0`.
pub fn decay_maps_f32(
    values: ArrayView3<'_, f32>,
    starts_ps: &[f64],
    width_ps: f64,
    frequency_hz: f64,
    options: &DecayOptions,
) -> Result<DecayMaps, DecayError> {
    if let Some(((k, r, c), v)) = values
        .indexed_iter()
        .find(|(_, v)| !(v.is_finite() && **v >= 0.0))
    {
        return Err(DecayError::Input(format!(
            "bin {k}, row {r}, column {c} holds {v}: a count must be a finite number >= 0"
        )));
    }
    maps_of(values, starts_ps, width_ps, frequency_hz, options)
}

/// Harmonics phasors can be made at from `bins` samples of a period:
/// each from 1 to half the samples (past it a harmonic aliases onto a
/// lower one, as PhasorPy refuses), none twice.
fn check_harmonics(harmonics: &[u32], bins: usize) -> Result<(), DecayError> {
    let most = bins / 2;
    if harmonics.is_empty() {
        return Err(DecayError::Input(
            "no harmonics: give at least one, from 1".into(),
        ));
    }
    if let Some(h) = harmonics.iter().find(|&&h| h == 0 || h as usize > most) {
        return Err(DecayError::Input(format!(
            "harmonic {h}: give harmonics from 1 to {most} (half the {bins} bins; a higher one aliases onto a lower)"
        )));
    }
    if let Some((i, h)) = harmonics
        .iter()
        .enumerate()
        .find(|(i, h)| harmonics[..*i].contains(h))
    {
        return Err(DecayError::Input(format!(
            "harmonic {h} given twice (at places {} and {}): give each once",
            harmonics.iter().position(|x| x == h).expect("found") + 1,
            i + 1
        )));
    }
    Ok(())
}

/// A reference phasors can be calibrated against: one finite phasor per
/// harmonic, each of modulation at least [`REFERENCE_MODULATION`] (a flat
/// decay's phasor sits at the origin and would scale every pixel's by a
/// huge factor), a finite lifetime from 0 up to a hundred laser periods.
fn check_reference(r: &Reference, harmonics: &[u32], frequency_hz: f64) -> Result<(), DecayError> {
    let bad = |s: String| Err(DecayError::Input(format!("{}: {s}", r.what)));
    if r.phasors.len() != harmonics.len() {
        return bad(format!(
            "{} phasors for {} harmonics: give one (g, s) per harmonic",
            r.phasors.len(),
            harmonics.len()
        ));
    }
    let period_ps = 1e12 / frequency_hz;
    if !(r.lifetime_ps.is_finite() && r.lifetime_ps >= 0.0 && r.lifetime_ps <= 100.0 * period_ps) {
        return bad(format!(
            "lifetime {} ps: give a finite lifetime from 0 (an IRF) to a hundred laser periods ({:.0} ps)",
            number_text(r.lifetime_ps),
            100.0 * period_ps
        ));
    }
    for (&(g, s), h) in r.phasors.iter().zip(harmonics) {
        let m = g.hypot(s);
        if !(m.is_finite() && m >= REFERENCE_MODULATION) {
            return bad(format!(
                "its phasor at harmonic {h} is ({g}, {s}), of modulation {m:.2e}: a reference needs a decay (at least {REFERENCE_MODULATION}; a flat one sits at the origin)"
            ));
        }
    }
    Ok(())
}

/// A number as a user wrote it: plain when short, in exponent form when
/// huge or tiny.
fn number_text(v: f64) -> String {
    if v == 0.0 || (1e-6..1e9).contains(&v.abs()) {
        v.to_string()
    } else {
        format!("{v:e}")
    }
}

/// The least modulation a reference's phasor may have.
pub const REFERENCE_MODULATION: f64 = 1e-2;

fn maps_of<T: Copy + Into<f64> + Sync>(
    counts: ArrayView3<'_, T>,
    starts_ps: &[f64],
    width_ps: f64,
    frequency_hz: f64,
    options: &DecayOptions,
) -> Result<DecayMaps, DecayError> {
    let (bins, h, w) = counts.dim();
    let bad = |s: String| Err(DecayError::Input(s));
    if bins < 2 {
        return bad(format!(
            "a stack of {bins} bin: a decay needs at least two time bins (bin the recording with its micro-time bins, not summed)"
        ));
    }
    if starts_ps.len() != bins || !(width_ps.is_finite() && width_ps > 0.0) {
        return bad(format!(
            "{} bin starts and a bin width of {width_ps} ps for {bins} bins",
            starts_ps.len()
        ));
    }
    crate::tags::laser::given(frequency_hz).map_err(DecayError::Input)?;
    check_harmonics(&options.harmonics, bins)?;
    if !(options.min_photons.is_finite() && options.min_photons >= 1.0) {
        return bad(format!(
            "a threshold of {} photons: give at least 1",
            options.min_photons
        ));
    }
    let span = (starts_ps[0], starts_ps[bins - 1] + width_ps);
    match options.onset {
        Onset::At(t) | Onset::IrfBarycentre(t)
            if !(t.is_finite() && t >= span.0 - (span.1 - span.0) && t < span.1) =>
        {
            return bad(format!(
                "onset {} ps: it must lie in the stack's time window ({:.1} to {:.1} ps) or at most one window before it",
                number_text(t),
                span.0,
                span.1
            ));
        }
        _ => {}
    }
    if let Some(r) = &options.reference {
        check_reference(r, &options.harmonics, frequency_hz)?;
    }
    // The maps' memory: the per-pixel sums and each band's copy of them,
    // four time maps and the mask, two phasor maps per harmonic and four
    // more calibrated.
    let planes = 5 + 2 * options.harmonics.len();
    let per_harmonic = if options.reference.is_some() { 6 } else { 2 };
    let per_pixel = 8 * (2 * planes + 5 + per_harmonic * options.harmonics.len()) as u64;
    crate::memory::check(crate::memory::bytes_of([h, w], per_pixel), || {
        format!(
            "the decay maps of {h} x {w} pixels at {} harmonics",
            options.harmonics.len()
        )
    })
    .map_err(|e| DecayError::Input(e.to_string()))?;
    let centres: Vec<f64> = starts_ps.iter().map(|s| s + width_ps / 2.0).collect();
    let summed: Vec<f64> = counts
        .axis_iter(Axis(0))
        .map(|p| p.iter().map(|&v| v.into()).sum())
        .collect();
    let mut notes = Vec::new();
    // The onset (the centred conventions' time zero) and SymPhoTime's
    // time zero (photons at their bins' starts).
    let (onset, zero_start) = match options.onset {
        Onset::HalfMaximum => {
            let t = half_maximum_onset(&summed, &centres).ok_or_else(|| {
                DecayError::Input("the stack holds no photon: no decay to find an onset in".into())
            })?;
            let zero =
                rising_flank_zero(&summed, starts_ps, width_ps).unwrap_or(t - width_ps / 2.0);
            notes.push(format!(
                "onset {t:.1} ps: where the image's summed decay first reaches half its maximum on its rising edge, between bins' centres (PicoQuant's 'entrance of the FWHM interval'); the fast lifetime's time zero {zero:.1} ps: the rising flank's line through the steepest-rising pair of bins, at their starts, extended to the peak's count, less half a bin, photons at their bins' starts (SymPhoTime 64's export reproduced); the centred fast lifetime's: the onset, photons at their bins' centres"
            ));
            (t, zero)
        }
        Onset::At(t) => {
            notes.push(format!(
                "onset {t:.1} ps, as given; the fast lifetime's time zero (photons at their bins' starts; the centred fast lifetime's, photons at their centres)"
            ));
            (t, t)
        }
        Onset::IrfBarycentre(t) => {
            notes.push(format!(
                "onset and fast lifetime's time zero {t:.1} ps: the IRF's barycentre (its photons and the decay's at their bins' centres; {:.1} ps with both at their bins' starts)",
                t - width_ps / 2.0
            ));
            (t, t - width_ps / 2.0)
        }
    };
    let first = centres.iter().position(|&t| t >= onset).unwrap_or(bins);
    notes.push(format!(
        "mean arrival time and variance from the {} bins at or after the onset; {} bins before it left out of them ({:.0} photons in all)",
        bins - first,
        first,
        summed[..first].iter().sum::<f64>()
    ));
    let omegas: Vec<f64> = options
        .harmonics
        .iter()
        .map(|&h| 2.0 * std::f64::consts::PI * f64::from(h) * frequency_hz * 1e-12)
        .collect();
    let trig: Vec<Vec<(f64, f64)>> = omegas
        .iter()
        .map(|&o| {
            centres
                .iter()
                .map(|&t| ((o * t).cos(), (o * t).sin()))
                .collect()
        })
        .collect();
    let sums = accumulate(counts, &centres, onset, first, &trig);
    let nan = || Array2::from_elem((h, w), f64::NAN);
    let intensity = Array2::from_shape_vec((h, w), sums.plane(Sum::Photons).to_vec())
        .expect("one sum per pixel");
    let mut mask = intensity.mapv(|n| n < options.min_photons);
    let dim = mask.iter().filter(|&&m| m).count();
    // A pixel with photons, none of them at or after the onset, has no
    // mean arrival time: masked, and counted.
    let mut before_onset = 0;
    for (p, m) in mask.iter_mut().enumerate() {
        if !*m && sums.at(Sum::After, p) <= 0.0 {
            *m = true;
            before_onset += 1;
        }
    }
    let (mut mean, mut var, mut fast, mut fast_centred) = (nan(), nan(), nan(), nan());
    let mut gs: Vec<(Array2<f64>, Array2<f64>)> = omegas.iter().map(|_| (nan(), nan())).collect();
    for (p, (&m, &n)) in mask.iter().zip(&intensity).enumerate() {
        if m {
            continue;
        }
        let (r, c) = (p / w, p % w);
        let barycentre = sums.at(Sum::Timed, p) / n;
        fast[[r, c]] = barycentre - width_ps / 2.0 - zero_start;
        fast_centred[[r, c]] = barycentre - onset;
        let after = sums.at(Sum::After, p);
        let m1 = sums.at(Sum::AfterDelay, p) / after;
        mean[[r, c]] = m1;
        // Non-negative however the sums round.
        var[[r, c]] = (sums.at(Sum::AfterDelaySquared, p) / after - m1 * m1).max(0.0);
        for (i, (g, s)) in gs.iter_mut().enumerate() {
            g[[r, c]] = sums.at(Sum::Cos(i), p) / n;
            s[[r, c]] = sums.at(Sum::Sin(i), p) / n;
        }
    }
    let empty = intensity.iter().filter(|&&n| n == 0.0).count();
    notes.push(format!(
        "{dim} of {} pixels masked (fewer than {} photons; {empty} of them empty): NaN in the time, lifetime and phasor maps, true in the mask",
        h * w,
        options.min_photons
    ));
    if before_onset > 0 {
        notes.push(format!(
            "{before_onset} more pixels masked: enough photons, none at or after the onset (no mean arrival time)"
        ));
    }
    notes.push(format!(
        "phasors at harmonics {:?} of {}, from the bins' centres",
        options.harmonics,
        crate::tags::laser::hz_text(frequency_hz)
    ));
    let mut phasors: Vec<PhasorMaps> = options
        .harmonics
        .iter()
        .zip(gs)
        .zip(&omegas)
        .enumerate()
        .map(|(i, ((&harmonic, (g, s)), &omega))| {
            let calibrated = options
                .reference
                .as_ref()
                .map(|r| calibrate(&g, &s, r.phasors[i], r.lifetime_ps, omega));
            PhasorMaps {
                harmonic,
                g,
                s,
                calibrated,
            }
        })
        .collect();
    if let Some(r) = &options.reference {
        notes.push(format!(
            "phasors calibrated against {} of lifetime {:.1} ps (PhasorPy's phasor_calibrate: its whole decay's phasor rotated and scaled onto a single exponential's)",
            r.what, r.lifetime_ps
        ));
        // A calibrated phasor at or past 90 degrees, or at the origin, has
        // no finite apparent lifetime: its pixel is masked, and counted.
        let mut beyond = 0;
        for p in 0..h * w {
            let at = [p / w, p % w];
            let finite = phasors.iter().all(|m| {
                m.calibrated.as_ref().is_none_or(|c| {
                    c.tau_phase_ps[at].is_finite() && c.tau_modulation_ps[at].is_finite()
                })
            });
            if !mask[at] && !finite {
                mask[at] = true;
                beyond += 1;
            }
        }
        if beyond > 0 {
            notes.push(format!(
                "{beyond} more pixels masked: a calibrated phasor with no finite apparent lifetime (at or past 90 degrees, or at the origin)"
            ));
            let mut maps = vec![&mut mean, &mut var, &mut fast, &mut fast_centred];
            for pm in &mut phasors {
                maps.extend([&mut pm.g, &mut pm.s]);
                if let Some(c) = pm.calibrated.as_mut() {
                    maps.extend([
                        &mut c.g,
                        &mut c.s,
                        &mut c.tau_phase_ps,
                        &mut c.tau_modulation_ps,
                    ]);
                }
            }
            for m in maps {
                m.zip_mut_with(&mask, |v, &masked| {
                    if masked {
                        *v = f64::NAN;
                    }
                });
            }
        }
    } else {
        notes.push(
            "phasors not calibrated (no reference given): apparent lifetimes left out".into(),
        );
    }
    Ok(DecayMaps {
        intensity,
        mean_time_ps: mean,
        variance_ps2: var,
        fast_lifetime_ps: fast,
        fast_lifetime_centred_ps: fast_centred,
        phasors,
        mask,
        onset_ps: onset,
        frequency_hz,
        notes,
    })
}

/// One per-pixel sum of [`accumulate`].
#[derive(Debug, Clone, Copy)]
enum Sum {
    /// `sum n_k`.
    Photons,
    /// `sum n_k t_k`.
    Timed,
    /// `sum n_k` over the bins at or after the onset.
    After,
    /// `sum n_k (t_k - t0)` over them.
    AfterDelay,
    /// `sum n_k (t_k - t0)^2` over them.
    AfterDelaySquared,
    /// `sum n_k cos(w_h t_k)` for harmonic index `h`.
    Cos(usize),
    /// `sum n_k sin(w_h t_k)`.
    Sin(usize),
}

/// Every pixel's sums, one plane of `pixels` values per [`Sum`].
struct Sums {
    values: Vec<f64>,
    pixels: usize,
}

impl Sum {
    fn index(self) -> usize {
        match self {
            Sum::Photons => 0,
            Sum::Timed => 1,
            Sum::After => 2,
            Sum::AfterDelay => 3,
            Sum::AfterDelaySquared => 4,
            Sum::Cos(h) => 5 + 2 * h,
            Sum::Sin(h) => 6 + 2 * h,
        }
    }
}

impl Sums {
    fn plane(&self, s: Sum) -> &[f64] {
        &self.values[s.index() * self.pixels..(s.index() + 1) * self.pixels]
    }

    fn at(&self, s: Sum, pixel: usize) -> f64 {
        self.values[s.index() * self.pixels + pixel]
    }
}

/// Rows per band of [`accumulate`]: the band's sums (11 planes of 8
/// rows of 512 pixels, 360 kB) stay in the core's cache while every bin
/// passes over them.
const BAND_ROWS: usize = 8;

/// Every pixel's [`Sum`]s over the bins of `counts` (centres `centres`,
/// onset `onset`, the first bin at or after it `first`; `trig` the cosine
/// and sine of each harmonic at each centre). Bins outer and pixels
/// inner, band by band of rows on every core: a pixel's decay is strided
/// in a bins-first stack, so walking it pixel by pixel read a cache line
/// per count (measured: 2.5 s for the shared 2 x 512 x 512 x 256 `.sdt`
/// image, against phasorpy's 2.4 s whole process).
fn accumulate<T: Copy + Into<f64> + Sync>(
    counts: ArrayView3<'_, T>,
    centres: &[f64],
    onset: f64,
    first: usize,
    trig: &[Vec<(f64, f64)>],
) -> Sums {
    use rayon::prelude::*;
    let (bins, h, w) = counts.dim();
    let hw = h * w;
    let planes = 5 + 2 * trig.len();
    let standard = counts.as_standard_layout();
    let flat = standard
        .as_slice()
        .expect("a standard-layout array is one slice");
    let bands: Vec<Vec<f64>> = (0..h.div_ceil(BAND_ROWS))
        .into_par_iter()
        .map(|b| {
            let (p0, p1) = (b * BAND_ROWS * w, ((b + 1) * BAND_ROWS).min(h) * w);
            let n = p1 - p0;
            let mut acc = vec![0.0; planes * n];
            for k in 0..bins {
                let src = &flat[k * hw + p0..k * hw + p1];
                let (t, after) = (centres[k], k >= first);
                // A bin of mostly counted pixels (bright, dense decays)
                // sums plane by plane, loops the compiler vectorises; a
                // mostly empty one (most FLIM bins) visits its counts
                // only. Dense 256 x 256 x 256 blocks took 0.30 s each
                // visiting every count, against PhasorPy's 0.08 s.
                let counted = src.iter().filter(|&&v| v.into() != 0.0).count();
                if counted * 4 >= n {
                    dense_bin(&mut acc, src, t, t - onset, after, trig, k);
                } else {
                    sparse_bin(&mut acc, src, t, t - onset, after, trig, k);
                }
            }
            acc
        })
        .collect();
    let mut values = vec![0.0; planes * hw];
    for (b, acc) in bands.iter().enumerate() {
        let p0 = b * BAND_ROWS * w;
        let n = acc.len() / planes;
        for q in 0..planes {
            values[q * hw + p0..q * hw + p0 + n].copy_from_slice(&acc[q * n..(q + 1) * n]);
        }
    }
    Sums { values, pixels: hw }
}

/// Adds bin `k`'s counts `src` (one band, `n` pixels) at centre `t`,
/// `d` after the onset, to the band's planes `acc` (`n` each: photons,
/// timed, after, after delay, after delay squared, then cos and sin per
/// harmonic), plane by plane.
fn dense_bin<T: Copy + Into<f64>>(
    acc: &mut [f64],
    src: &[T],
    t: f64,
    d: f64,
    after: bool,
    trig: &[Vec<(f64, f64)>],
    k: usize,
) {
    let n = src.len();
    let fixed = [
        Some(1.0),
        Some(t),
        after.then_some(1.0),
        after.then_some(d),
        after.then_some(d * d),
    ];
    let harmonics = trig.iter().flat_map(|tr| {
        let (co, si) = tr[k];
        [Some(co), Some(si)]
    });
    for (plane, weight) in acc
        .chunks_exact_mut(n)
        .zip(fixed.into_iter().chain(harmonics))
    {
        if let Some(weight) = weight {
            for (a, &v) in plane.iter_mut().zip(src) {
                *a += v.into() * weight;
            }
        }
    }
}

/// [`dense_bin`] visiting only the counted pixels.
fn sparse_bin<T: Copy + Into<f64>>(
    acc: &mut [f64],
    src: &[T],
    t: f64,
    d: f64,
    after: bool,
    trig: &[Vec<(f64, f64)>],
    k: usize,
) {
    let n = src.len();
    for (i, &v) in src.iter().enumerate() {
        let v: f64 = v.into();
        if v == 0.0 {
            continue;
        }
        acc[i] += v;
        acc[n + i] += v * t;
        if after {
            acc[2 * n + i] += v;
            acc[3 * n + i] += v * d;
            acc[4 * n + i] += v * d * d;
        }
        for (j, tr) in trig.iter().enumerate() {
            let (co, si) = tr[k];
            acc[(5 + 2 * j) * n + i] += v * co;
            acc[(6 + 2 * j) * n + i] += v * si;
        }
    }
}

/// `g`, `s` calibrated with the reference phasor `(gr, sr)` of lifetime
/// `tau_ps` at `omega` (rad/ps), and the apparent lifetimes.
fn calibrate(
    g: &Array2<f64>,
    s: &Array2<f64>,
    (gr, sr): (f64, f64),
    tau_ps: f64,
    omega: f64,
) -> Calibrated {
    let (gk, sk) = single_exponential_phasor(tau_ps, omega);
    let phase = sk.atan2(gk) - sr.atan2(gr);
    let modulation = gk.hypot(sk) / gr.hypot(sr);
    let (c, sn) = (phase.cos(), phase.sin());
    let gc = ndarray::Zip::from(g)
        .and(s)
        .map_collect(|&g, &s| modulation * (g * c - s * sn));
    let sc = ndarray::Zip::from(g)
        .and(s)
        .map_collect(|&g, &s| modulation * (g * sn + s * c));
    let tau_phase = ndarray::Zip::from(&gc).and(&sc).map_collect(|&g, &s| {
        if g.is_nan() || s.is_nan() {
            f64::NAN
        } else if (g * omega).abs() > 0.0 {
            s / (g * omega)
        } else {
            f64::INFINITY
        }
    });
    let tau_mod = ndarray::Zip::from(&gc).and(&sc).map_collect(|&g, &s| {
        let t = g * g + s * s;
        if t.is_nan() {
            f64::NAN
        } else if t <= 0.0 {
            f64::INFINITY
        } else if t <= 1.0 {
            (1.0 / t - 1.0).sqrt() / omega
        } else {
            0.0
        }
    });
    Calibrated {
        g: gc,
        s: sc,
        tau_phase_ps: tau_phase,
        tau_modulation_ps: tau_mod,
        phase_rad: phase,
        modulation,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array3;

    /// A single exponential of 2 ns at 80 MHz, sampled finely over one
    /// period: its calibrated phasor against itself is the theory's, the
    /// apparent lifetimes 2 ns, the mean arrival time after its onset
    /// about 2 ns.
    #[test]
    fn a_single_exponential_gives_its_lifetime() {
        let (bins, width) = (500, 25.0);
        let tau = 2000.0;
        let starts: Vec<f64> = (0..bins).map(|k| k as f64 * width).collect();
        let counts = Array3::from_shape_fn((bins, 2, 3), |(k, r, _)| {
            let t = starts[k] + width / 2.0;
            let decay = if t < 1000.0 {
                0.0
            } else {
                1e4 * (-(t - 1000.0) / tau).exp()
            };
            // Every pixel the same decay, scaled: each its reference's phasor.
            decay.round() as u32 * (1 + r as u32)
        });
        let f = 80e6;
        let reference = decay_phasors(
            &counts
                .sum_axis(Axis(1))
                .sum_axis(Axis(1))
                .mapv(f64::from)
                .to_vec(),
            &starts.iter().map(|s| s + width / 2.0).collect::<Vec<_>>(),
            f,
            &[1],
        );
        let opts = DecayOptions {
            harmonics: vec![1],
            reference: Some(Reference {
                phasors: reference,
                lifetime_ps: tau,
                what: "itself".into(),
            }),
            ..DecayOptions::default()
        };
        let maps = decay_maps(CountsView::U32(counts.view()), &starts, width, f, &opts).unwrap();
        let cal = maps.phasors[0].calibrated.as_ref().unwrap();
        assert!((cal.tau_phase_ps[[1, 2]] - tau).abs() < 1e-6 * tau);
        assert!((cal.tau_modulation_ps[[0, 0]] - tau).abs() < 1e-6 * tau);
        // The decay rises in one bin at 1000 ps: the onset is half a bin
        // before the first full bin's centre, the mean about tau plus it.
        assert!((maps.onset_ps - 1000.0).abs() < width, "{}", maps.onset_ps);
        let m = maps.mean_time_ps[[0, 1]];
        assert!((m - tau).abs() < 0.05 * tau, "{m}");
        assert!(maps.mask.iter().all(|&m| !m));
    }

    /// Bins of every density (all pixels counted, a few, none) sum to
    /// what the definitions give pixel by pixel, whichever way a bin is
    /// visited.
    #[test]
    fn dense_and_sparse_bins_give_the_definitions() {
        let (bins, h, w, width) = (40, 9, 11, 50.0);
        let starts: Vec<f64> = (0..bins).map(|k| 100.0 + k as f64 * width).collect();
        let mut seed = 7u64;
        let counts = Array3::from_shape_fn((bins, h, w), |(k, _, _)| {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let r = (seed >> 33) % 100;
            // Bins 0-9 sparse (1 in 10 counted), 10-29 dense, 30- empty.
            match k {
                0..10 if r < 10 => 1 + (r % 3) as u16,
                10..30 => (r % 7) as u16,
                _ => 0,
            }
        });
        let f = 80e6;
        let onset = 720.0;
        let opts = DecayOptions {
            harmonics: vec![1, 3],
            min_photons: 1.0,
            onset: Onset::At(onset),
            reference: None,
        };
        let maps = decay_maps(CountsView::U16(counts.view()), &starts, width, f, &opts).unwrap();
        let centres: Vec<f64> = starts.iter().map(|s| s + width / 2.0).collect();
        for r in 0..h {
            for c in 0..w {
                let n: Vec<f64> = (0..bins).map(|k| f64::from(counts[[k, r, c]])).collect();
                let total: f64 = n.iter().sum();
                if total == 0.0 {
                    assert!(maps.mask[[r, c]]);
                    continue;
                }
                let after: Vec<(f64, f64)> = centres
                    .iter()
                    .zip(&n)
                    .filter(|(t, _)| **t >= onset)
                    .map(|(t, v)| (t - onset, *v))
                    .collect();
                let na: f64 = after.iter().map(|a| a.1).sum();
                if na == 0.0 {
                    // Photons, none at or after the onset: no mean time.
                    assert!(maps.mask[[r, c]], "{r},{c}");
                    assert!(maps.fast_lifetime_ps[[r, c]].is_nan());
                    continue;
                }
                let mean = after.iter().map(|(d, v)| d * v).sum::<f64>() / na;
                let var = after
                    .iter()
                    .map(|(d, v)| (d - mean).powi(2) * v)
                    .sum::<f64>()
                    / na;
                let centred =
                    centres.iter().zip(&n).map(|(t, v)| t * v).sum::<f64>() / total - onset;
                // SymPhoTime's: photons at their bins' starts, the given
                // onset the time zero.
                let fast = starts.iter().zip(&n).map(|(t, v)| t * v).sum::<f64>() / total - onset;
                let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * b.abs().max(1.0);
                assert!(close(maps.mean_time_ps[[r, c]], mean), "mean at {r},{c}");
                assert!(close(maps.variance_ps2[[r, c]], var), "variance at {r},{c}");
                assert!(
                    close(maps.fast_lifetime_centred_ps[[r, c]], centred),
                    "centred fast lifetime at {r},{c}"
                );
                assert!(
                    close(maps.fast_lifetime_ps[[r, c]], fast),
                    "fast lifetime at {r},{c}"
                );
                for (i, &hm) in [1.0, 3.0].iter().enumerate() {
                    let o = 2.0 * std::f64::consts::PI * hm * f * 1e-12;
                    let g = centres
                        .iter()
                        .zip(&n)
                        .map(|(t, v)| v * (o * t).cos())
                        .sum::<f64>()
                        / total;
                    let s = centres
                        .iter()
                        .zip(&n)
                        .map(|(t, v)| v * (o * t).sin())
                        .sum::<f64>()
                        / total;
                    assert!(close(maps.phasors[i].g[[r, c]], g), "g at {r},{c}");
                    assert!(close(maps.phasors[i].s[[r, c]], s), "s at {r},{c}");
                }
            }
        }
    }

    #[test]
    fn bad_stacks_are_refused_and_empty_pixels_masked() {
        let one = Array3::<u32>::ones((1, 2, 2));
        let e = decay_maps(
            CountsView::U32(one.view()),
            &[0.0],
            10.0,
            80e6,
            &DecayOptions::default(),
        )
        .unwrap_err();
        assert!(e.to_string().contains("at least two time bins"), "{e}");
        let mut counts = Array3::<f32>::zeros((4, 2, 2));
        counts[[1, 0, 0]] = 50.0;
        counts[[2, 0, 0]] = 30.0;
        let starts = [0.0, 10.0, 20.0, 30.0];
        let maps =
            decay_maps_f32(counts.view(), &starts, 10.0, 80e6, &DecayOptions::default()).unwrap();
        assert_eq!(maps.mask.iter().filter(|&&m| m).count(), 3);
        assert!(maps.mean_time_ps[[1, 1]].is_nan() && !maps.mean_time_ps[[0, 0]].is_nan());
        assert!(
            maps.notes
                .iter()
                .any(|n| n.contains("3 of 4 pixels masked") && n.contains("3 of them empty"))
        );
        counts[[0, 1, 1]] = f32::NAN;
        let e = decay_maps_f32(counts.view(), &starts, 10.0, 80e6, &DecayOptions::default())
            .unwrap_err();
        assert!(
            e.to_string().contains("bin 0, row 1, column 1 holds NaN"),
            "{e}"
        );
        counts[[0, 1, 1]] = 0.0;
        let e = decay_maps_f32(counts.view(), &starts, 10.0, 0.0, &DecayOptions::default())
            .unwrap_err();
        assert!(
            e.to_string().contains("outside the repetition rates"),
            "{e}"
        );
    }

    /// The rising flank's line through the steepest pair (30 to 90 at
    /// bins 2 and 3) reaches the peak (100) 70/60 of a bin after bin 2's
    /// start; less half a bin. A decay that does not rise has none.
    #[test]
    fn the_rising_flanks_time_zero_follows_the_steepest_pair() {
        let starts = [0.0, 10.0, 20.0, 30.0, 40.0, 50.0];
        let zero = rising_flank_zero(&[0.0, 10.0, 30.0, 90.0, 100.0, 60.0], &starts, 10.0);
        assert!((zero.unwrap() - (20.0 + 70.0 / 60.0 * 10.0 - 5.0)).abs() < 1e-12);
        assert_eq!(
            rising_flank_zero(&[9.0, 5.0, 2.0, 1.0, 0.0, 0.0], &starts, 10.0),
            None
        );
        assert_eq!(rising_flank_zero(&[0.0; 6], &starts, 10.0), None);
    }

    /// Without an IRF the fast lifetime's time zero is where the line
    /// through the steepest-rising pair of bins (at their starts) reaches
    /// the peak, less half a bin, photons at their bins' starts
    /// (SymPhoTime); the centred one's the interpolated onset, photons at
    /// their centres.
    #[test]
    fn the_fast_lifetime_takes_symphotimes_conventions() {
        let decay = [2.0, 3.0, 40.0, 100.0, 70.0, 50.0, 30.0, 20.0];
        let starts: Vec<f64> = (0..8).map(|k| 100.0 + 97.0 * k as f64).collect();
        let counts = Array3::from_shape_fn((8, 1, 1), |(k, _, _)| decay[k] as u32);
        let maps = decay_maps(
            CountsView::U32(counts.view()),
            &starts,
            97.0,
            80e6,
            &DecayOptions::default(),
        )
        .unwrap();
        let n: f64 = decay.iter().sum();
        let bary_start = starts.iter().zip(&decay).map(|(t, v)| t * v).sum::<f64>() / n;
        // The steepest rise is bins 2 to 3 (40 to 100, against 3 to 40
        // before): that line reaches the peak, 100, at bin 3's start.
        let zero = starts[2] + (100.0 - 40.0) / (100.0 - 40.0) * 97.0 - 48.5;
        let want = bary_start - zero;
        assert!(
            (maps.fast_lifetime_ps[[0, 0]] - want).abs() < 1e-9,
            "{}",
            maps.fast_lifetime_ps[[0, 0]]
        );
        // The interpolated onset: between the centres of bins 2 and 3.
        let onset = starts[2] + 48.5 + (50.0 - 40.0) / (100.0 - 40.0) * 97.0;
        assert!((maps.onset_ps - onset).abs() < 1e-9);
        let centred = bary_start + 48.5 - onset;
        assert!((maps.fast_lifetime_centred_ps[[0, 0]] - centred).abs() < 1e-9);
    }

    /// A pixel with photons none of which arrive at or after the onset is
    /// masked and counted; a flat reference, a reference lifetime out of
    /// range, aliased or repeated harmonics and an onset outside the
    /// window are refused by value.
    #[test]
    fn maps_never_hold_a_nan_the_mask_does_not_say() {
        let mut counts = Array3::<u32>::zeros((8, 1, 2));
        for k in 0..8 {
            counts[[k, 0, 0]] = [0, 0, 50, 100, 70, 50, 30, 20][k];
        }
        counts[[0, 0, 1]] = 40;
        let starts: Vec<f64> = (0..8).map(|k| 100.0 * k as f64).collect();
        let maps = decay_maps(
            CountsView::U32(counts.view()),
            &starts,
            100.0,
            80e6,
            &DecayOptions::default(),
        )
        .unwrap();
        assert!(maps.mask[[0, 1]] && !maps.mask[[0, 0]]);
        assert!(
            maps.notes
                .iter()
                .any(|n| n
                    .contains("1 more pixels masked: enough photons, none at or after the onset")),
            "{:?}",
            maps.notes
        );
        let refused = |options: DecayOptions| {
            decay_maps(
                CountsView::U32(counts.view()),
                &starts,
                100.0,
                80e6,
                &options,
            )
            .unwrap_err()
            .to_string()
        };
        let reference = |phasor: (f64, f64), lifetime_ps: f64| DecayOptions {
            harmonics: vec![1],
            reference: Some(Reference {
                phasors: vec![phasor],
                lifetime_ps,
                what: "the reference".into(),
            }),
            ..DecayOptions::default()
        };
        assert!(refused(reference((1e-4, 0.0), 1000.0)).contains("modulation 1.00e-4"));
        assert!(refused(reference((f64::NAN, 0.0), 1000.0)).contains("modulation NaN"));
        assert!(refused(reference((0.5, 0.3), f64::NAN)).contains("lifetime NaN ps"));
        assert!(refused(reference((0.5, 0.3), -1.0)).contains("lifetime -1 ps"));
        let harmonics = |h: Vec<u32>| DecayOptions {
            harmonics: h,
            ..DecayOptions::default()
        };
        assert!(refused(harmonics(vec![5])).contains("harmonic 5: give harmonics from 1 to 4"));
        assert!(refused(harmonics(vec![1, 2, 1])).contains("harmonic 1 given twice"));
        let onset = |t: f64| DecayOptions {
            onset: Onset::At(t),
            ..DecayOptions::default()
        };
        assert!(refused(onset(f64::NAN)).contains("onset NaN ps"));
        assert!(refused(onset(800.0)).contains("onset 800 ps"));
        assert!(refused(onset(-1e300)).contains("onset -1e300 ps"));
    }
}
