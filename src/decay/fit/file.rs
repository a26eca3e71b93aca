//! Lifetime fits of a recorded file (PTU, `.spc`, `.sdt`, tag file),
//! written as the decay maps are: what `scatterscope fit` runs.
//!
//! Each stack the file gives is binned (one block in memory at a time),
//! fitted ([`super::fit_maps`]) and written before the next is read:
//! - `fit.ome.tif`: float32, one named channel per map (quantity and
//!   unit), the pixel size when the file states it;
//! - `fit.npy` (float32, channels x rows x columns) with `fit.json` (the
//!   channels, the notes, the summed decay's fit, the stack's metadata);
//! - `fit_lifetime.png` (the intensity-weighted mean lifetime coloured,
//!   brightness the photons, with its colour bar) and `fit_decay.png` (the
//!   summed decay, its fit, the IRF and the weighted residuals), unless
//!   left out.
//!
//! Several stacks are written `fit_f000.*`, ...

use std::path::{Path, PathBuf};

use ndarray::Array2;
use serde::Serialize;

use super::{FitMaps, FitOptions, IrfSource, fit_maps};
use crate::decay::map_files::{
    LifetimeImage, draw_lifetime, recorded_note, refuse_inputs, stack_tail, stale_note,
    stated_meta, unmasked_finite, write_channels,
};
use crate::decay::recording::reference_decay;
use crate::files::input::same_file;
use crate::plot::quantile;
use crate::stack::{StackError, Unstated};
use crate::tags::bin_file::bin_file_each;
use crate::tags::binned::{BinSpec, BinnedFile, RecordedFileError, StackCounts, spec_error};

/// Where a fit's IRF comes from, as asked.
#[derive(Debug, Clone, PartialEq)]
pub enum IrfRequest {
    /// A recorded file (its decay, every pixel summed, on the same bins).
    File(PathBuf),
    /// A Gaussian, its centre and width fitted.
    Gaussian,
    /// Estimated from the rising edge of the summed decay.
    RisingEdge,
    /// None: a tail fit.
    Tail,
}

/// What `fit` is asked beyond the binning.
#[derive(Debug, Clone, PartialEq)]
pub struct FitRequest {
    /// The fit's settings (its IRF taken from `irf`).
    pub options: FitOptions,
    /// The IRF.
    pub irf: IrfRequest,
    /// The laser frequency (Hz), overriding the file's.
    pub frequency_hz: Option<f64>,
    /// The folder written.
    pub out: PathBuf,
    /// Whether to draw the figures.
    pub figures: bool,
    /// Keep every bin in the default window, also those the instrument
    /// did not record whole.
    pub all_bins: bool,
}

/// What was written of one stack.
#[derive(Debug, Clone)]
pub struct FitWritten {
    /// The files, the OME-TIFF first.
    pub files: Vec<PathBuf>,
    /// Pixels, masked pixels, photons in the window (each once, binning
    /// or not).
    pub pixels: usize,
    /// See `pixels`.
    pub masked: usize,
    /// See `pixels`.
    pub photons: f64,
    /// Median intensity-weighted mean lifetime over the fitted pixels, ps.
    pub median_lifetime_ps: f64,
    /// What was assumed, left out and masked.
    pub notes: Vec<String>,
}

#[derive(Serialize)]
struct Sidecar<'a> {
    channels: Vec<&'a str>,
    window_bins: (usize, usize),
    summed_decay: &'a [f64],
    summed_fit: &'a [f64],
    summed_params: &'a [f64],
    summed_values: &'a [String],
    summed_reduced_chi2: f64,
    laser_frequency_hz: Option<f64>,
    notes: &'a [String],
    stack: serde_json::Value,
}

/// The channels of a fit's map file, in order, each with its name.
fn channels(m: &FitMaps) -> Vec<(String, Array2<f64>)> {
    let mut c = vec![("photons".to_string(), m.photons.clone())];
    for (k, t) in m.lifetimes_ps.iter().enumerate() {
        c.push((format!("tau{} (ps)", k + 1), t.clone()));
        c.push((
            format!("tau{} standard error (ps)", k + 1),
            m.lifetime_errors_ps[k].clone(),
        ));
        c.push((
            format!("a{} (photons per bin at time zero)", k + 1),
            m.amplitudes[k].clone(),
        ));
        c.push((
            format!("a{} fraction", k + 1),
            m.amplitude_fractions[k].clone(),
        ));
        c.push((
            format!("intensity fraction {}", k + 1),
            m.intensity_fractions[k].clone(),
        ));
    }
    c.extend([
        (
            "amplitude-weighted mean lifetime (ps)".into(),
            m.tau_amplitude_ps.clone(),
        ),
        (
            "intensity-weighted mean lifetime (ps)".into(),
            m.tau_intensity_ps.clone(),
        ),
        ("background (photons per bin)".into(), m.background.clone()),
        ("reduced chi-squared".into(), m.reduced_chi2.clone()),
        ("Poisson deviance".into(), m.deviance.clone()),
        ("mask".into(), m.mask.mapv(|v| f64::from(u8::from(v)))),
    ]);
    c
}

/// An IRF's decay: a recorded file's, every pixel summed (on its bins'
/// centres), or a `.npy` array of photons per bin (on the sample's bins:
/// no centres to check).
fn irf_decay(
    path: &Path,
    spec: &BinSpec,
) -> Result<crate::decay::recording::Decay, RecordedFileError> {
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("npy"))
    {
        use ndarray_npy::ReadNpyExt;
        // The input gate: a FIFO or device is refused at once, not waited
        // on.
        let (file, _) = crate::files::input::open_regular(path, "IRF array")
            .map_err(|e| RecordedFileError::Output(StackError::io(path, e)))?;
        let v = ndarray::Array1::<f64>::read_npy(std::io::BufReader::new(file)).map_err(|e| {
            spec_error(
                path,
                format!("is not a 1-D float64 .npy array of photons per bin: {e}"),
            )
        })?;
        return Ok((v.to_vec(), Vec::new(), None));
    }
    reference_decay(path, spec)
}

/// Fits every stack of the recorded file `path` as `request` says and
/// writes them: what `scatterscope fit` runs.
pub fn fit_file(
    path: &Path,
    spec: &BinSpec,
    request: &FitRequest,
) -> Result<BinnedFile<FitWritten>, RecordedFileError> {
    let irf_decay = match &request.irf {
        IrfRequest::File(irf) => {
            if same_file(irf, path) {
                return Err(spec_error(
                    irf,
                    "is the sample itself: an IRF is another recording".into(),
                ));
            }
            Some((irf.clone(), irf_decay(irf, spec)?))
        }
        _ => None,
    };
    if let Some(f) = request.frequency_hz {
        crate::tags::laser::given(f).map_err(|e| spec_error(path, format!("--frequency: {e}")))?;
    }
    std::fs::create_dir_all(&request.out)
        .map_err(|e| RecordedFileError::Output(StackError::io(&request.out, e)))?;
    bin_file_each(path, spec, |s| {
        let meta = s.meta;
        if meta.is_unstated(Unstated::TimeUnit) {
            return Err(spec_error(
                path,
                "its time unit is unknown (the bins are micro-time channels): a fit needs times in ps (for a .spc file give --micro-unit)".into(),
            ));
        }
        let mut options = request.options.clone();
        options.irf = match (&request.irf, &irf_decay) {
            (IrfRequest::File(_), Some((irf, (decay, centres, _)))) => {
                let own: Vec<f64> = meta
                    .bin_starts_ps
                    .iter()
                    .map(|t| t + meta.bin_width_ps / 2.0)
                    .collect();
                let checked = !centres.is_empty();
                if decay.len() != own.len()
                    || checked
                        && centres
                            .iter()
                            .zip(&own)
                            .any(|(a, b)| (a - b).abs() > 1e-3 * meta.bin_width_ps)
                {
                    return Err(spec_error(
                        irf,
                        format!(
                            "its {} bins of {:.3} ps are not the sample's {} bins of {:.3} ps: record the IRF with the sample's time bins",
                            decay.len(),
                            centres
                                .get(1)
                                .zip(centres.first())
                                .map_or(0.0, |(b, a)| b - a),
                            own.len(),
                            meta.bin_width_ps
                        ),
                    ));
                }
                IrfSource::Measured {
                    decay: decay.clone(),
                    what: irf.display().to_string(),
                }
            }
            (IrfRequest::Gaussian, _) => IrfSource::Gaussian,
            (IrfRequest::Tail, _) => IrfSource::Tail,
            _ => IrfSource::RisingEdge,
        };
        options.recorded = meta.recorded_window(request.all_bins);
        let frequency = request.frequency_hz.or(meta.laser_frequency_hz);
        let mut maps = fit_maps(
            s.counts,
            &meta.bin_starts_ps,
            meta.bin_width_ps,
            frequency,
            &options,
        )
        .map_err(|e| spec_error(path, e.to_string()))?;
        if let Some(note) = recorded_note(meta, request.all_bins) {
            maps.notes.insert(0, note);
        }
        write_fit(&maps, &s, frequency, path, request).map_err(RecordedFileError::Output)
    })
}

/// Writes `maps` of stack `s` into the request's folder.
fn write_fit(
    maps: &FitMaps,
    s: &StackCounts<'_>,
    frequency_hz: Option<f64>,
    input: &Path,
    request: &FitRequest,
) -> Result<FitWritten, StackError> {
    let tail = stack_tail(s);
    let dir = &request.out;
    let tif = dir.join(format!("fit{tail}.ome.tif"));
    let npy = dir.join(format!("fit{tail}.npy"));
    let json = crate::formats::npy::sidecar_path(&npy);
    let lifetime_png = dir.join(format!("fit_lifetime{tail}.png"));
    let decay_png = dir.join(format!("fit_decay{tail}.png"));
    let irf_npy = dir.join(format!("fit_irf{tail}.npy"));
    let mut files = vec![tif.clone(), npy.clone(), json.clone()];
    if !maps.summed.irf.is_empty() {
        files.push(irf_npy.clone());
    }
    if request.figures {
        files.extend([lifetime_png.clone(), decay_png.clone()]);
    }
    let mut reads = vec![input.to_owned(), input.with_extension("set")];
    if let IrfRequest::File(irf) = &request.irf {
        reads.push(irf.clone());
    }
    refuse_inputs(&files, &reads)?;
    let chans = channels(maps);
    let (h, w) = maps.photons.dim();
    let views: Vec<(String, ndarray::ArrayView2<f64>)> =
        chans.iter().map(|(n, m)| (n.clone(), m.view())).collect();
    write_channels(&views, s.meta, &tif, &npy)?;
    let mut notes = maps.notes.clone();
    if !maps.summed.irf.is_empty() {
        // The IRF the fit used, on the stack's bins and of unit sum: what
        // `--irf` takes back.
        let mut irf = ndarray::Array1::<f64>::zeros(s.meta.bin_starts_ps.len());
        let (first, end) = maps.summed.window;
        irf.slice_mut(ndarray::s![first..end])
            .assign(&ndarray::ArrayView1::from(&maps.summed.irf));
        crate::formats::npy::write_array(&irf, &irf_npy)?;
        notes.push(format!(
            "the IRF used written to {} (unit sum on the stack's bins; --irf takes it back)",
            irf_npy.display()
        ));
    }
    if !request.figures {
        notes.push("figures left out (asked)".into());
    }
    notes.extend(stale_note(dir, "fit", s));
    let sidecar = Sidecar {
        channels: chans.iter().map(|(n, _)| n.as_str()).collect(),
        window_bins: maps.summed.window,
        summed_decay: &maps.summed.decay,
        summed_fit: &maps.summed.fit,
        summed_params: &maps.summed.params,
        summed_values: &maps.summed.values,
        summed_reduced_chi2: maps.summed.reduced_chi2,
        laser_frequency_hz: frequency_hz,
        notes: &notes,
        stack: stated_meta(s.meta),
    };
    let text = serde_json::to_string_pretty(&sidecar).expect("the sidecar serialises");
    crate::files::write_atomic(&json, text).map_err(|e| StackError::io(&json, e))?;
    let unmasked = unmasked_finite(&maps.tau_intensity_ps, &maps.mask);
    if request.figures {
        figures(maps, &unmasked, &lifetime_png, &decay_png)?;
    }
    Ok(FitWritten {
        files,
        pixels: h * w,
        masked: maps.mask.iter().filter(|&&m| m).count(),
        // Each photon once: the window's photons of the stack, not of the
        // binned decays (which count a photon in every square holding it).
        photons: maps.summed.window_photons,
        median_lifetime_ps: quantile(unmasked, 0.5).unwrap_or(f64::NAN),
        notes,
    })
}

/// Draws the mean lifetime image and the summed decay's fit.
fn figures(
    maps: &FitMaps,
    unmasked: &[f64],
    lifetime_png: &Path,
    decay_png: &Path,
) -> Result<(), StackError> {
    draw_lifetime(
        lifetime_png,
        &LifetimeImage {
            values: maps.tau_intensity_ps.view(),
            unmasked,
            photons: &maps.photons,
            title: "intensity-weighted mean lifetime, weighted by photons (masked black)",
            bar_label: "lifetime (ps)",
        },
    )?;
    let times: Vec<f64> = maps.summed.starts_ps.iter().map(|t| t * 1e-3).collect();
    // The IRF scaled to the summed decay's peak.
    let irf_shown: Vec<f64> = {
        let top = maps.summed.irf.iter().cloned().fold(0.0, f64::max);
        let peak = maps.summed.decay.iter().cloned().fold(0.0, f64::max);
        if top > 0.0 {
            maps.summed.irf.iter().map(|v| v / top * peak).collect()
        } else {
            Vec::new()
        }
    };
    crate::plot::decay_fit(
        decay_png,
        &crate::plot::DecayFitPlot {
            title: &format!(
                "summed decay and its fit (reduced chi-squared {:.3})",
                maps.summed.reduced_chi2
            ),
            times_ns: &times,
            decay: &maps.summed.decay,
            fit: &maps.summed.fit,
            irf: &irf_shown,
            values: &maps.summed.values,
        },
    )
    .map_err(|e| StackError::format(decay_png, format!("drawing: {e}")))
}
