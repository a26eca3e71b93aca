//! Decay maps of a recorded file (PTU, `.spc`, `.sdt`, tag file), written
//! as a lab opens them: what `scatterscope lifetime` runs.
//!
//! Each stack the file gives (one per kept frame, one per `.sdt` block) is
//! binned ([`bin_file_each`], one block in memory at a time), mapped
//! ([`decay_maps`]) and written before the next is read:
//! - `maps.ome.tif`: float32, one named channel per map (the name says the
//!   quantity and unit), the pixel size when the file states it;
//! - `maps.npy` (float32, channels x rows x columns) with `maps.json`
//!   (the channels' names, the notes, onset, frequency, the stack's
//!   metadata);
//! - `lifetime.png` (the lifetime coloured, weighted by intensity, with its
//!   colour bar) and `phasor.png` (the first harmonic's phasor histogram on
//!   the universal semicircle), unless left out.
//!
//! Several stacks are written `maps_f000.*`, `lifetime_f000.png`, ...

use std::path::{Path, PathBuf};

use ndarray::Array2;
use serde::Serialize;

use super::map_files::{
    LifetimeImage, draw_lifetime, refuse_inputs, stack_tail, stale_note, stated_meta,
    unmasked_finite, write_channels,
};
use super::{DecayMaps, DecayOptions, Onset, Reference, decay_maps, decay_phasors};
use crate::files::input::same_file;
use crate::plot::quantile;
use crate::stack::{StackError, StackMeta, Unstated};
use crate::tags::bin_file::bin_file_each;
use crate::tags::binned::{BinSpec, BinnedFile, RecordedFileError, StackCounts, spec_error};

/// A file whose decay calibrates the phasors.
#[derive(Debug, Clone, PartialEq)]
pub enum ReferenceFile {
    /// A dye (or any sample) of known single-exponential lifetime (ps).
    Dye {
        /// The recording.
        path: PathBuf,
        /// Its lifetime (ps).
        lifetime_ps: f64,
    },
    /// A measured instrument response (lifetime 0): it also gives the
    /// onset (its barycentre), the fast lifetime's time zero.
    Irf(PathBuf),
}

impl ReferenceFile {
    fn path(&self) -> &Path {
        match self {
            ReferenceFile::Dye { path, .. } | ReferenceFile::Irf(path) => path,
        }
    }
}

/// What `lifetime` is asked beyond the binning.
#[derive(Debug, Clone, PartialEq)]
pub struct LifetimeRequest {
    /// Harmonics, mask threshold and onset (an IRF reference sets the
    /// onset to its barycentre).
    pub options: DecayOptions,
    /// The laser frequency (Hz), when the file does not state it or is to
    /// be overridden.
    pub frequency_hz: Option<f64>,
    /// The reference the phasors are calibrated against.
    pub reference: Option<ReferenceFile>,
    /// The folder written.
    pub out: PathBuf,
    /// Whether to draw `lifetime.png` and `phasor.png`.
    pub figures: bool,
    /// Keep every bin, also those the instrument did not record whole.
    pub all_bins: bool,
}

/// What was written of one stack.
#[derive(Debug, Clone)]
pub struct MapsWritten {
    /// The files, the OME-TIFF first.
    pub files: Vec<PathBuf>,
    /// Pixels, masked pixels, photons, and the median lifetime shown.
    pub pixels: usize,
    /// See `pixels`.
    pub masked: usize,
    /// See `pixels`.
    pub photons: f64,
    /// The median over unmasked pixels of the lifetime the figure shows
    /// (ps), and its name.
    pub median_lifetime: (f64, &'static str),
    /// What was assumed and left out.
    pub notes: Vec<String>,
}

/// The channels of a map file, in order, each with its name (quantity and
/// unit) and values.
fn channels(maps: &DecayMaps) -> Vec<(String, std::borrow::Cow<'_, Array2<f64>>)> {
    use std::borrow::Cow::{Borrowed, Owned};
    let mut c = vec![
        ("photons".to_string(), Borrowed(&maps.intensity)),
        (
            "mean arrival time after onset (ps)".into(),
            Borrowed(&maps.mean_time_ps),
        ),
        (
            "arrival time variance after onset (ps^2)".into(),
            Borrowed(&maps.variance_ps2),
        ),
        (
            "fast lifetime (ps)".into(),
            Borrowed(&maps.fast_lifetime_ps),
        ),
        (
            "fast lifetime centred (ps)".into(),
            Borrowed(&maps.fast_lifetime_centred_ps),
        ),
    ];
    for p in &maps.phasors {
        let h = p.harmonic;
        c.push((format!("g harmonic {h}"), Borrowed(&p.g)));
        c.push((format!("s harmonic {h}"), Borrowed(&p.s)));
        if let Some(k) = &p.calibrated {
            c.push((format!("g calibrated harmonic {h}"), Borrowed(&k.g)));
            c.push((format!("s calibrated harmonic {h}"), Borrowed(&k.s)));
            c.push((
                format!("phase lifetime harmonic {h} (ps)"),
                Borrowed(&k.tau_phase_ps),
            ));
            c.push((
                format!("modulation lifetime harmonic {h} (ps)"),
                Borrowed(&k.tau_modulation_ps),
            ));
        }
    }
    c.push((
        "mask (1: fewer photons than the threshold)".into(),
        Owned(maps.mask.mapv(|m| f64::from(u8::from(m)))),
    ));
    c
}

/// The `maps.json` sidecar.
#[derive(Serialize)]
struct Sidecar<'a> {
    channels: Vec<&'a str>,
    onset_ps: f64,
    laser_frequency_hz: f64,
    harmonics: &'a [u32],
    min_photons: f64,
    notes: &'a [String],
    stack: serde_json::Value,
}

/// A reference's decay: photons per bin, the bins' centres (ps), and the
/// laser frequency (Hz) when the recording states it.
pub(crate) type Decay = (Vec<f64>, Vec<f64>, Option<f64>);

/// The summed decay of every stack of `reference`.
pub(crate) fn reference_decay(
    reference: &Path,
    spec: &BinSpec,
) -> Result<Decay, RecordedFileError> {
    let mut decay: Option<Decay> = None;
    bin_file_each(reference, spec, |s| {
        if s.meta.is_unstated(Unstated::TimeUnit) {
            return Err(spec_error(
                reference,
                "its time unit is unknown (bins are micro-time channels): a reference needs times in ps".into(),
            ));
        }
        let summed = s.counts.bin_totals();
        let centres: Vec<f64> = s
            .meta
            .bin_starts_ps
            .iter()
            .map(|t| t + s.meta.bin_width_ps / 2.0)
            .collect();
        match &mut decay {
            None => decay = Some((summed, centres, s.meta.laser_frequency_hz)),
            Some((d, c, _)) if *c == centres => {
                d.iter_mut().zip(&summed).for_each(|(a, b)| *a += b);
            }
            Some(_) => {
                return Err(spec_error(
                    reference,
                    "its stacks have different time bins: give a reference of one decay".into(),
                ));
            }
        }
        Ok(())
    })?;
    let (d, c, f) = decay.ok_or_else(|| spec_error(reference, "it gives no stack".into()))?;
    let photons = d.iter().sum::<f64>();
    if photons < REFERENCE_PHOTONS {
        return Err(spec_error(
            reference,
            format!(
                "it holds {photons} photons in the time window: a reference needs at least {REFERENCE_PHOTONS} (its phasor and barycentre scatter too much with fewer)"
            ),
        ));
    }
    Ok((d, c, f))
}

/// The fewest photons a reference decay may hold: its phasor scatters by
/// about `1 / sqrt(2 N)`, 0.07 at 100.
pub const REFERENCE_PHOTONS: f64 = 100.0;

/// The laser frequency of a stack: the request's, else the recording's,
/// each checked ([`crate::tags::laser`]).
pub(crate) fn frequency_of(
    path: &Path,
    meta: &StackMeta,
    asked: Option<f64>,
) -> Result<f64, RecordedFileError> {
    match (asked, meta.laser_frequency_hz) {
        (Some(f), _) => {
            crate::tags::laser::given(f).map_err(|e| spec_error(path, format!("--frequency: {e}")))
        }
        (None, Some(f)) => Ok(f),
        (None, None) => Err(spec_error(
            path,
            format!(
                "the recording states no laser frequency that can be used{}: give it with --frequency (Hz), or the phasors have no fundamental",
                if meta.laser_notes.is_empty() {
                    String::new()
                } else {
                    format!(" ({})", meta.laser_notes.join("; "))
                }
            ),
        )),
    }
}

/// Maps every stack of the recorded file `path` as `request` says and
/// writes them: what `scatterscope lifetime` runs. The result's stacks are
/// what was written of each.
pub fn lifetime_file(
    path: &Path,
    spec: &BinSpec,
    request: &LifetimeRequest,
) -> Result<BinnedFile<MapsWritten>, RecordedFileError> {
    let mut options = request.options.clone();
    let reference = match &request.reference {
        None => None,
        Some(r) => {
            if same_file(r.path(), path) {
                return Err(spec_error(
                    r.path(),
                    "is the sample itself: a reference is another recording".into(),
                ));
            }
            Some((r, reference_decay(r.path(), spec)?))
        }
    };
    std::fs::create_dir_all(&request.out)
        .map_err(|e| RecordedFileError::Output(StackError::io(&request.out, e)))?;
    bin_file_each(path, spec, |s| {
        let meta = s.meta;
        if meta.is_unstated(Unstated::TimeUnit) {
            return Err(spec_error(
                path,
                "its time unit is unknown (the bins are micro-time channels): the maps need times in ps (for a .spc file give --micro-unit)".into(),
            ));
        }
        let frequency = frequency_of(path, meta, request.frequency_hz)?;
        // The bins the instrument recorded whole: a partial bin's photons
        // (the sync period's last) would count at a time they were not
        // recorded over, as SymPhoTime leaves them out. A reference on
        // the same bins is cut alike.
        let (first, end) = meta
            .recorded_window(request.all_bins)
            .unwrap_or((0, meta.bin_starts_ps.len()));
        if let Some((r, (decay, centres, f_ref))) = &reference {
            let (decay, centres) = if decay.len() == meta.bin_starts_ps.len() {
                (&decay[first..end], &centres[first..end])
            } else {
                (&decay[..], &centres[..])
            };
            if let Some(f) = f_ref.filter(|f| (f - frequency).abs() > 1e-3 * frequency) {
                return Err(spec_error(
                    r.path(),
                    format!(
                        "its laser frequency {:.6} MHz is not the sample's {:.6} MHz: a reference is measured at the sample's",
                        f * 1e-6,
                        frequency * 1e-6
                    ),
                ));
            }
            let (lifetime_ps, what) = match r {
                ReferenceFile::Dye { lifetime_ps, .. } => (*lifetime_ps, "reference"),
                ReferenceFile::Irf(_) => {
                    let n: f64 = decay.iter().sum();
                    let bary = decay.iter().zip(centres).map(|(d, t)| d * t).sum::<f64>() / n;
                    options.onset = Onset::IrfBarycentre(bary);
                    (0.0, "IRF")
                }
            };
            options.reference = Some(Reference {
                phasors: decay_phasors(decay, centres, frequency, &options.harmonics),
                lifetime_ps,
                what: format!("the {what} {}", r.path().display()),
            });
        }
        let mut maps = decay_maps(
            s.counts.bins(first, end),
            &meta.bin_starts_ps[first..end],
            meta.bin_width_ps,
            frequency,
            &options,
        )
        .map_err(|e| spec_error(path, e.to_string()))?;
        if request.frequency_hz.is_none() {
            maps.notes.splice(0..0, meta.laser_notes.iter().cloned());
        }
        maps.notes
            .extend(super::map_files::recorded_note(meta, request.all_bins));
        write_maps(&maps, &s, &options, path, request).map_err(RecordedFileError::Output)
    })
}

/// Writes `maps` of stack `s` into the request's folder.
fn write_maps(
    maps: &DecayMaps,
    s: &StackCounts<'_>,
    options: &DecayOptions,
    input: &Path,
    request: &LifetimeRequest,
) -> Result<MapsWritten, StackError> {
    let tail = stack_tail(s);
    let dir = &request.out;
    let tif = dir.join(format!("maps{tail}.ome.tif"));
    let npy = dir.join(format!("maps{tail}.npy"));
    let json = crate::formats::npy::sidecar_path(&npy);
    let lifetime_png = dir.join(format!("lifetime{tail}.png"));
    let phasor_png = dir.join(format!("phasor{tail}.png"));
    let mut files = vec![tif.clone(), npy.clone(), json.clone()];
    if request.figures {
        files.extend([lifetime_png.clone(), phasor_png.clone()]);
    }
    let mut reads = vec![input.to_owned(), input.with_extension("set")];
    reads.extend(request.reference.as_ref().map(|r| r.path().to_owned()));
    refuse_inputs(&files, &reads)?;
    let chans = channels(maps);
    let (h, w) = maps.intensity.dim();
    let views: Vec<(String, ndarray::ArrayView2<f64>)> =
        chans.iter().map(|(n, m)| (n.clone(), m.view())).collect();
    write_channels(&views, s.meta, &tif, &npy)?;
    let sidecar = Sidecar {
        channels: chans.iter().map(|(n, _)| n.as_str()).collect(),
        onset_ps: maps.onset_ps,
        laser_frequency_hz: maps.frequency_hz,
        harmonics: &options.harmonics,
        min_photons: options.min_photons,
        notes: &maps.notes,
        stack: stated_meta(s.meta),
    };
    let text = serde_json::to_string_pretty(&sidecar).expect("the sidecar serialises");
    crate::files::write_atomic(&json, text).map_err(|e| StackError::io(&json, e))?;
    let shown = shown_lifetime(maps);
    // The shown lifetime's unmasked, finite values: the figure's colour
    // range and the printed median.
    let unmasked = unmasked_finite(shown.1, &maps.mask);
    if request.figures {
        figures(maps, &shown, &unmasked, &lifetime_png, &phasor_png)?;
    }
    let median = quantile(unmasked, 0.5).unwrap_or(f64::NAN);
    let mut notes = maps.notes.clone();
    if !request.figures {
        notes.push("figures left out (asked)".into());
    }
    notes.extend(stale_note(dir, "maps", s));
    Ok(MapsWritten {
        files,
        pixels: h * w,
        masked: maps.mask.iter().filter(|&&m| m).count(),
        photons: maps.intensity.sum(),
        median_lifetime: (median, shown.0),
        notes,
    })
}

/// The lifetime the figure shows: the first harmonic's calibrated phase
/// lifetime with a reference, else the fast lifetime.
fn shown_lifetime(maps: &DecayMaps) -> (&'static str, &Array2<f64>) {
    match maps.phasors.first().and_then(|p| p.calibrated.as_ref()) {
        Some(c) => ("phase lifetime", &c.tau_phase_ps),
        None => ("fast lifetime", &maps.fast_lifetime_ps),
    }
}

/// Draws the lifetime image (`unmasked`: its unmasked, finite values)
/// and the first harmonic's phasor plot.
fn figures(
    maps: &DecayMaps,
    (name, lifetime): &(&'static str, &Array2<f64>),
    unmasked: &[f64],
    lifetime_png: &Path,
    phasor_png: &Path,
) -> Result<(), StackError> {
    let shown = ndarray::Zip::from(*lifetime)
        .and(&maps.mask)
        .map_collect(|&v, &m| if m { f64::NAN } else { v });
    let title = format!(
        "{name}, weighted by photons (masked black; {:.0} MHz)",
        maps.frequency_hz * 1e-6
    );
    let bar = format!("{name} (ps)");
    draw_lifetime(
        lifetime_png,
        &LifetimeImage {
            values: shown.view(),
            unmasked,
            photons: &maps.intensity,
            title: &title,
            bar_label: &bar,
        },
    )?;
    let first = maps.phasors.first().expect("at least one harmonic");
    let (g, s, calibrated) = match &first.calibrated {
        Some(c) => (&c.g, &c.s, true),
        None => (&first.g, &first.s, false),
    };
    let points: Vec<(f64, f64)> = g
        .iter()
        .zip(s)
        .zip(&maps.mask)
        .filter(|(_, m)| !**m)
        .map(|((&g, &s), _)| (g, s))
        .collect();
    let omega = 2.0 * std::f64::consts::PI * f64::from(first.harmonic) * maps.frequency_hz * 1e-12;
    let marks = [500.0, 1000.0, 2000.0, 4000.0, 8000.0];
    let title = format!(
        "phasors, harmonic {} of {:.3} MHz ({})",
        first.harmonic,
        maps.frequency_hz * 1e-6,
        if calibrated {
            "calibrated"
        } else {
            "not calibrated: the semicircle's marks are left out"
        }
    );
    crate::plot::phasor_histogram(
        phasor_png,
        &crate::plot::PhasorHistogram {
            points: &points,
            title: &title,
            marks: calibrated.then_some((&marks[..], omega)),
        },
    )
    .map_err(|e| StackError::format(phasor_png, format!("drawing: {e}")))
}
