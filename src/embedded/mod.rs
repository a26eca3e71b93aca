//! The object inside the medium, lit through it, recorded by a SPAD camera
//! as labs record it: source -> front slab -> object (a thin mask) ->
//! back slab -> imaged face (the geometry of time-of-flight diffuse
//! optical tomography with a SPAD camera).
//!
//! One call, [`reconstruct`], takes a recorded [`cube::Cube`] and the
//! [`Settings`] and returns the object's transmission map with every
//! choice it made in its notes:
//!
//! - [`cube`]: the cube and its pixel positions from the files labs keep
//!   (MATLAB level 5 or v7.3, `.npy`; any axis order, sign and type);
//! - [`pixels`]: the pixels left out of the likelihood (a given mask;
//!   filtered, dead and hot pixels found in the data);
//! - [`noise`]: the noise measured from the cube and the likelihood that
//!   matches it;
//! - [`calibrate`]: the time zero (and the scattering) fitted to the cube's
//!   own time profile where not stated;
//! - [`geometry`]: both slabs and the beam: the back slab's kernels with the
//!   front slab's light as their arrival-time density, and the beam's map;
//! - [`solve`]: Richardson-Lucy with per-pixel backgrounds over the used
//!   pixels, stopped by cross-validation over the pixels' parity;
//! - [`request`]: the same from files and flags with units (the command
//!   line's `embedded` and `simulate-embedded`);
//! - [`simulate`]: cubes of this geometry with a known truth, written as a
//!   lab would (the tests' stand-ins).

pub mod calibrate;
pub mod cube;
pub mod geometry;
pub mod noise;
pub mod pixels;
pub mod request;
pub mod simulate;
pub mod solve;

use std::path::{Path, PathBuf};

use ndarray::{Array2, Array3, s};
use scatterscope_physics::{KernelStack, Sampling, Sensor, TimeBins};
use serde::Serialize;

use crate::forward::ForwardModel;
use cube::Cube;
use geometry::Geometry;
use noise::{NoiseModel, Subtracted};
use pixels::BadPixels;
use solve::Fit;

/// The deviance's z above which the notes warn that no transmission
/// explains the counts under the chosen noise model.
pub const MISFIT_Z: f64 = 10.0;
/// Time groups of equal light the bins after the onset are summed into,
/// unless set.
pub const DEFAULT_TIME_GROUPS: usize = 8;
/// The most iterations the parity split searches, unless set.
pub const DEFAULT_MAX_ITERS: usize = 5000;

/// How to reconstruct a cube.
#[derive(Debug, Clone)]
pub struct Settings {
    /// Both slabs, the beam, the instrument's response.
    pub geometry: Geometry,
    /// Width of the cube's bins (ps).
    pub bin_width_ps: f64,
    /// The pulse's entry into the front slab on the cube's clock (ps after
    /// bin 0's start); fitted to the cube's time profile when `None`.
    pub time_zero_ps: Option<f64>,
    /// The media factors fitted with the time zero (scattering,
    /// absorption: one factor each on both slabs).
    pub fit_media: calibrate::Free,
    /// Time groups of equal light (1: the time-summed cube).
    pub time_groups: usize,
    /// The most iterations searched.
    pub max_iters: usize,
    /// Iterations to run instead of searching (a fixed stop).
    pub iterations: Option<usize>,
    /// The background the lab subtracted, where stated.
    pub subtracted: Option<Subtracted>,
    /// Pixels to use (true) from a mask file.
    pub mask: Option<Array2<bool>>,
}

/// Everything a reconstruction found.
#[derive(Debug, Clone)]
pub struct Outcome {
    /// Relative transmission on the camera's pixels (1 at the 99th
    /// percentile of the used pixels' values).
    pub transmission: Array2<f64>,
    /// The beam's light at the object plane on the same pixels.
    pub beam: Array2<f64>,
    /// The pixels used.
    pub used: Array2<bool>,
    /// The report written beside the images.
    pub report: Report,
}

/// What the notes file holds.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    /// How the cube was read.
    pub cube: cube::Provenance,
    /// Pixels, bins, pitch.
    pub shape: (usize, usize, usize),
    /// Pixel pitch x, y (cm).
    pub pitch_cm: (f64, f64),
    /// The noise model and its figures.
    pub noise: NoiseModel,
    /// Pixels left out.
    pub bad_pixels: BadPixels,
    /// The time zero (ps on the cube's clock) and where it came from.
    pub time_zero_ps: f64,
    /// The self-calibration, where one ran.
    pub calibration: Option<calibrate::Calibration>,
    /// Front and back reduced scattering used (1/cm).
    pub mu_s_reduced_per_cm: (f64, f64),
    /// Full width at half maximum of the back slab's blur summed over the
    /// cube's bins, along a row (cm).
    pub blur_fwhm_cm: f64,
    /// The beam and how separable its light is in space and time.
    pub beam: geometry::Beam,
    /// `|| I - b f1 || / || I ||` of the beam's light at the object plane.
    pub beam_separation_error: f64,
    /// First bin and bins of each time group.
    pub time_groups: Vec<(usize, usize)>,
    /// The fit.
    pub fit: Fit,
    /// Values of the transformed counts below 0 set to 0.
    pub clamped: usize,
    /// Every note, in order; warnings start with `warning:`.
    pub notes: Vec<String>,
}

impl Report {
    /// The notes that are warnings (`warning:` in them): the outputs are
    /// written, but doubtful.
    pub fn warnings(&self) -> usize {
        self.notes.iter().filter(|n| n.contains("warning:")).count()
    }
}

/// Why a reconstruction could not run.
#[derive(Debug, thiserror::Error)]
pub enum EmbeddedError {
    /// A setting or the data, named.
    #[error("{0}")]
    Invalid(String),
    /// The physics refused a parameter.
    #[error("{0}")]
    Physics(#[from] scatterscope_physics::ParamError),
}

/// Reconstructs the transmission of the object inside the medium from
/// `cube`.
pub fn reconstruct(cube: &Cube, settings: &Settings) -> Result<Outcome, EmbeddedError> {
    let invalid = |e: String| EmbeddedError::Invalid(format!("{}: {e}", cube.provenance.file));
    settings.geometry.validate()?;
    if !(settings.bin_width_ps.is_finite() && settings.bin_width_ps > 0.0) {
        return Err(EmbeddedError::Invalid(format!(
            "bin width {} ps: must be positive",
            settings.bin_width_ps
        )));
    }
    if settings.fit_media.scattering && settings.fit_media.absorption {
        return Err(EmbeddedError::Invalid(format!(
            "fitting the scattering and the absorption together: {}",
            calibrate::JOINT_REFUSED
        )));
    }
    if settings.time_groups == 0 || settings.max_iters == 0 || settings.iterations == Some(0) {
        return Err(EmbeddedError::Invalid(
            "time groups and iterations must be at least 1".into(),
        ));
    }
    let y = &cube.values;
    let (bins, h, w) = y.dim();
    crate::memory::check(crate::memory::bytes_of([bins, h, w], CUBE_BYTES), || {
        format!("reconstructing a cube of {bins} bins x {h} x {w} pixels")
    })
    .map_err(|e| invalid(e.to_string()))?;
    let mut notes = Vec::new();

    // Pixels and noise: filtered and dead pixels first (a neighbour mean
    // has less variance), then hot ones from the dark variance.
    let (mut used, mut bad) = pixels::find(y, settings.mask.as_ref());
    if !used.iter().any(|&u| u) {
        return Err(invalid(
            "no pixel is left to use (the mask and the pixels found bad leave none)".into(),
        ));
    }
    let first = noise::measure(y, &used, settings.subtracted.as_ref()).map_err(invalid)?;
    pixels::mark_hot(&mut used, &mut bad, &first.dark_variance);
    let noise = noise::measure(y, &used, settings.subtracted.as_ref()).map_err(invalid)?;
    notes.push(bad.describe(h * w));
    notes.push(format!(
        "noise model: {}; {}",
        noise.kind.name(),
        noise.reason
    ));

    // Time zero and scattering.
    let profile: Vec<f64> = (0..bins)
        .map(|k| used_values(y.slice(s![k, .., ..]), &used).sum())
        .collect();
    let variance: Vec<f64> = (0..bins)
        .map(|k| {
            y.slice(s![k, .., ..])
                .indexed_iter()
                .filter(|(p, _)| used[*p])
                .map(|(p, &v)| {
                    noise.gain * (v - noise.dark_level[p]).max(0.0)
                        + noise.dark_variance[p].max(0.0)
                })
                .sum()
        })
        .collect();
    let fit_media = settings.fit_media != calibrate::Free::default();
    let (time_zero_ps, calibration, geometry) = match settings.time_zero_ps {
        Some(t0) if !fit_media => {
            notes.push(format!("time zero {t0} ps on the cube's clock, as stated"));
            (t0, None, settings.geometry.clone())
        }
        _ => {
            let cal = calibrate::fit(
                &settings.geometry,
                (w as f64 * cube.pitch_cm.0, h as f64 * cube.pitch_cm.1),
                &profile,
                &variance,
                settings.bin_width_ps,
                settings.fit_media,
            )
            .map_err(invalid)?;
            let geometry = calibrate::scaled(&settings.geometry, cal.factors);
            let t0 = settings.time_zero_ps.unwrap_or(cal.time_zero_ps.0);
            let medium = |name: &str, (front, back, se): (f64, f64, f64), fitted: bool| {
                if fitted {
                    format!(
                        ", {name} {front:.3} /cm front and {back:.3} /cm back (+- {:.1} %)",
                        100.0 * se
                    )
                } else {
                    String::new()
                }
            };
            notes.push(format!(
                "self-calibration on the summed time profile (reduced chi-square {:.2}): time zero {:.1} +- {:.1} ps{}{}{}; {} as stated",
                cal.reduced_chi2,
                cal.time_zero_ps.0,
                cal.time_zero_ps.1,
                if settings.time_zero_ps.is_some() { " (the stated time zero is used)" } else { " (used)" },
                medium("reduced scattering", cal.mu_s_reduced_per_cm, cal.scattering_fitted),
                medium("absorption", cal.mu_a_per_cm, cal.absorption_fitted),
                match (cal.scattering_fitted, cal.absorption_fitted) {
                    (false, false) => "the media",
                    (true, false) => "absorption, index and thicknesses",
                    (false, true) => "scattering, index and thicknesses",
                    (true, true) => "index and thicknesses",
                }
            ));
            (t0, Some(cal), geometry)
        }
    };

    // Time groups: the dark bins alone, then bins of equal light.
    let onset = noise::light_onset(&profile);
    let groups = time_groups(&profile, onset, settings.time_groups);
    notes.push(format!(
        "time axis: {bins} bins summed into {} groups ({}); the bins' own kernels are summed within each group: the time information finer than a group is left out",
        groups.len(),
        groups
            .iter()
            .map(|(a, n)| format!("{a}-{}", a + n - 1))
            .collect::<Vec<_>>()
            .join(", ")
    ));

    // The physics on the camera's pixels.
    let pitch = (cube.pitch_cm.0 * cube.pitch_cm.1).sqrt();
    let aspect = cube.pitch_cm.1 / cube.pitch_cm.0;
    if (aspect - 1.0).abs() > 1e-3 {
        notes.push(format!(
            "pixels of {:.4} x {:.4} cm ({:+.1} % in y): modelled as squares of their geometric mean, {pitch:.4} cm; at the blur's width this places a kernel's edge {:.2} pixels off at most",
            cube.pitch_cm.0,
            cube.pitch_cm.1,
            100.0 * (aspect - 1.0),
            0.5 * (aspect - 1.0).abs() * 3.0 * geometry_sigma_px(&geometry, bins, settings.bin_width_ps, time_zero_ps, pitch)
        ));
    }
    let kernels = back_kernels(
        &geometry,
        TimeBins {
            start_ps: -time_zero_ps,
            width_ps: settings.bin_width_ps,
            count: bins,
        },
        (h, w),
        pitch,
    )?;
    let grouped = group_kernels(&kernels, &groups);
    let model = ForwardModel::with_sensor(&grouped, (h, w));
    let beam = beam_on(&geometry, &model, pitch)?;
    let (oy, ox) = model.sensor_offset();

    // The likelihood's counts.
    let transformed = noise.transform(y);
    let counts: Vec<Vec<f64>> = groups
        .iter()
        .map(|&(a, n)| {
            transformed
                .counts
                .slice(s![a..a + n, .., ..])
                .sum_axis(ndarray::Axis(0))
                .iter()
                .copied()
                .collect()
        })
        .collect();
    let problem = solve::Problem {
        model: &model,
        counts,
        group_bins: groups.iter().map(|&(_, n)| n as f64).collect(),
        offset: transformed.offset.iter().copied().collect(),
        used: used.iter().copied().collect(),
        beam: beam.map.iter().copied().collect(),
        gain: noise.gain,
    };
    let fit = problem.solve(settings.max_iters, settings.iterations);
    notes.push(format!(
        "stop: {} iterations, {}{}",
        fit.iterations,
        if settings.iterations.is_some() {
            "as set"
        } else {
            "chosen by two-fold cross-validation over the pixels' parity"
        },
        if fit.stopped_at_cap {
            format!(
                " (warning: the search reached its cap of {} before its best was clear; the held-out likelihood was still improving)",
                settings.max_iters
            )
        } else {
            String::new()
        }
    ));
    let z = fit.misfit_z();
    notes.push(format!(
        "misfit under the {} model: deviance {:.0} against {:.0} +- {:.0} from noise alone (z = {z:.1})",
        noise.kind.name(),
        fit.deviance,
        fit.expected_deviance.0,
        fit.expected_deviance.1
    ));
    if z > MISFIT_Z {
        notes.push(format!(
            "warning: no transmission explains the counts under this noise model (z = {z:.1} > {MISFIT_Z}): the media, time zero, beam or noise differ from what was assumed; {}",
            departure(&problem, &fit)
        ));
    }
    notes.push(format!(
        "blur: the back slab's kernel summed over the bins is {:.2} cm wide at half maximum ({:.1} pixels)",
        summed_fwhm_px(&grouped) * pitch,
        summed_fwhm_px(&grouped)
    ));
    notes.push(format!(
        "the beam ({}) divided out: its light at the object plane is modelled as a fixed map times the front slab's time profile, {:.1} % from the true time-varying profile",
        match geometry.beam {
            geometry::Beam::Plane => "a plane wave".to_string(),
            geometry::Beam::Gaussian { fwhm_cm, centre_cm } => format!(
                "Gaussian, FWHM {fwhm_cm} cm at ({}, {}) cm",
                centre_cm.0, centre_cm.1
            ),
        },
        100.0 * beam.separation_error
    ));
    notes.push(
        "assumed: the object is a thin mask inside a continuous medium (no light reflected back into the front slab), both slabs homogeneous diffusion slabs with extrapolated boundaries".into(),
    );
    if transformed.clamped > 0 {
        notes.push(format!(
            "{} transformed values below 0 set to 0 ({:.2} % of the cube)",
            transformed.clamped,
            100.0 * transformed.clamped as f64 / y.len() as f64
        ));
    }

    let object = solve::on_sensor(&model, &fit.object);
    let scale = percentile(used_values(object.view(), &used), 0.99);
    let transmission = object.mapv(|v| if scale > 0.0 { v / scale } else { 0.0 });
    notes.push(
        "transmission is relative: 1 at the 99th percentile of the used pixels (the beam's power is not known)".into(),
    );
    let beam_on_sensor = beam.map.slice(s![oy..oy + h, ox..ox + w]).to_owned();
    let report = Report {
        cube: cube.provenance.clone(),
        shape: (bins, h, w),
        pitch_cm: cube.pitch_cm,
        noise,
        bad_pixels: bad,
        time_zero_ps,
        calibration,
        mu_s_reduced_per_cm: (
            geometry.front.mu_s_per_cm * (1.0 - geometry.front.g),
            geometry.back.mu_s_per_cm * (1.0 - geometry.back.g),
        ),
        blur_fwhm_cm: summed_fwhm_px(&grouped) * pitch,
        beam: geometry.beam,
        beam_separation_error: beam.separation_error,
        time_groups: groups.clone(),
        fit,
        clamped: transformed.clamped,
        notes,
    };
    Ok(Outcome {
        transmission,
        beam: beam_on_sensor,
        used,
        report,
    })
}

/// Bytes per pixel and bin a reconstruction holds besides its kernels:
/// the cube, its transform, the dark statistics' and pixel checks' views.
pub const CUBE_BYTES: u64 = 32;

/// Standard deviations of the back slab's lateral spread that its kernels
/// reach.
pub const KERNEL_SIGMAS: f64 = 4.0;
/// The widest kernel array (pixels a side).
pub const MAX_KERNEL_PX: usize = 513;

/// The back slab's kernels for a camera of `sensor` pixels of `pitch_cm`
/// and `bins` (times from the pulse's entry into the front slab), on
/// arrays wide enough for [`KERNEL_SIGMAS`] of the spread at the last bin's
/// end (wider than the camera where the blur is: an object point's light
/// reaches across it), every bin of the setup described, those before any
/// light left out of the stack.
pub fn back_kernels(
    geometry: &Geometry,
    bins: TimeBins,
    sensor: (usize, usize),
    pitch_cm: f64,
) -> Result<KernelStack, scatterscope_physics::ParamError> {
    let d = scatterscope_physics::Diffusion::new(&geometry.back)?;
    let reach = (KERNEL_SIGMAS * d.lateral_sigma_cm(bins.end_ps()) / pitch_cm).ceil();
    let side = (2 * reach.min(MAX_KERNEL_PX as f64) as usize + 1)
        .max(sensor.0)
        .max(sensor.1)
        .min(MAX_KERNEL_PX);
    // The kernels of every bin, and their local arrays as they are built.
    crate::memory::check(
        crate::memory::bytes_of([bins.count, side, side], 16),
        || {
            format!(
                "the back slab's kernels: {} bins of {side} x {side} pixels",
                bins.count
            )
        },
    )
    .map_err(|e| scatterscope_physics::ParamError::new("bins", bins.count as f64, e.to_string()))?;
    let setup = geometry.back_setup(
        bins,
        Sensor {
            fov_cm: pitch_cm * side as f64,
            width_px: side,
            height_px: side,
        },
    )?;
    KernelStack::build(&setup, Sampling::Integrated)
}

/// The beam's light on `model`'s object grid of pixels of `pitch_cm`, the
/// camera's centre at the field's.
pub fn beam_on(
    geometry: &Geometry,
    model: &ForwardModel,
    pitch_cm: f64,
) -> Result<geometry::BeamMap, scatterscope_physics::ParamError> {
    let (h, w) = model.sensor_shape();
    let (oy, ox) = model.sensor_offset();
    geometry.beam_map(
        model.grid_shape(),
        (
            oy as f64 + (h as f64 - 1.0) / 2.0,
            ox as f64 + (w as f64 - 1.0) / 2.0,
        ),
        pitch_cm,
    )
}

/// The lateral blur's width (pixels) at the profile's mean arrival.
fn geometry_sigma_px(g: &Geometry, bins: usize, bin_ps: f64, t0: f64, pitch: f64) -> f64 {
    let d = scatterscope_physics::Diffusion::new(&g.back).expect("validated");
    let mid = 0.5 * bins as f64 * bin_ps - t0;
    d.lateral_sigma_cm(mid.max(0.0)) / pitch
}

/// Where the counts depart from the fit, by time group: measured over
/// predicted light in each.
fn departure(problem: &solve::Problem, fit: &Fit) -> String {
    let pred = problem.model_counts(fit);
    let ratios: Vec<String> = problem
        .counts
        .iter()
        .zip(&pred)
        .map(|(z, m)| {
            let (a, b) = z
                .iter()
                .zip(m)
                .zip(&problem.used)
                .filter(|(_, u)| **u)
                .fold((0.0, 0.0), |(a, b), ((z, m), _)| (a + z, b + m));
            format!("{:.3}", a / b.max(1e-300))
        })
        .collect();
    format!(
        "counts over prediction by time group: {}",
        ratios.join(", ")
    )
}

/// The values of `a` at the used pixels.
pub(crate) fn used_values<'a>(
    a: ndarray::ArrayView2<'a, f64>,
    used: &'a Array2<bool>,
) -> impl Iterator<Item = f64> + 'a {
    a.into_iter()
        .zip(used.iter())
        .filter(|(_, u)| **u)
        .map(|(v, _)| *v)
}

/// The `q` quantile of `values` (0 when there are none).
pub(crate) fn percentile(values: impl Iterator<Item = f64>, q: f64) -> f64 {
    let mut v: Vec<f64> = values.collect();
    if v.is_empty() {
        return 0.0;
    }
    let at = ((v.len() - 1) as f64 * q).round() as usize;
    *v.select_nth_unstable_by(at, f64::total_cmp).1
}

/// Where `values` is largest and its value (the first where it ties).
pub(crate) fn peak<'a>(values: impl IntoIterator<Item = &'a f64>) -> (usize, f64) {
    values.into_iter().enumerate().fold(
        (0, f64::NEG_INFINITY),
        |b, (k, &v)| if v > b.1 { (k, v) } else { b },
    )
}

/// `(first bin, bins)` of each group: bins before `onset` as one group
/// (where there are any), the rest split into `n` runs of equal summed
/// light (fewer where bins run out).
pub fn time_groups(profile: &[f64], onset: usize, n: usize) -> Vec<(usize, usize)> {
    let mut groups = Vec::new();
    if onset > 0 {
        groups.push((0, onset));
    }
    let rest = &profile[onset..];
    let total: f64 = rest.iter().map(|v| v.max(0.0)).sum();
    let mut start = onset;
    let mut acc = 0.0;
    for (i, v) in rest.iter().enumerate() {
        acc += v.max(0.0);
        let k = onset + i;
        let done = groups.len() - usize::from(onset > 0);
        if done + 1 < n && acc >= total * (done + 1) as f64 / n as f64 && k + 1 < profile.len() {
            groups.push((start, k + 1 - start));
            start = k + 1;
        }
    }
    groups.push((start, profile.len() - start));
    groups
}

/// Full width at half maximum (pixels) along the centre row of the sum of
/// `kernels`' kernels, by linear interpolation between pixels.
fn summed_fwhm_px(kernels: &KernelStack) -> f64 {
    let sum = kernels.kernels.sum_axis(ndarray::Axis(0));
    let (h, w) = sum.dim();
    let row = sum.row(h / 2);
    let (cx, top) = peak(row);
    let half = 0.5 * top;
    let side = |dir: i64| {
        let mut j = cx as i64;
        while (0..w as i64).contains(&(j + dir)) && row[(j + dir) as usize] > half {
            j += dir;
        }
        let (a, b) = (
            row[j as usize],
            row.get((j + dir) as usize).copied().unwrap_or(0.0),
        );
        (j - cx as i64).abs() as f64 + if a > b { (a - half) / (a - b) } else { 0.0 }
    };
    side(-1) + side(1)
}

/// A kernel stack whose kernels are the sums of `kernels`' over each
/// group's bins (of the setup, kept or not).
fn group_kernels(kernels: &KernelStack, groups: &[(usize, usize)]) -> KernelStack {
    let (_, h, w) = kernels.kernels.dim();
    let mut summed = Array3::<f64>::zeros((groups.len(), h, w));
    let mut bins = Vec::with_capacity(groups.len());
    for (g, &(a, n)) in groups.iter().enumerate() {
        let mut slot = summed.slice_mut(s![g, .., ..]);
        let mut info = kernels.bins[a].clone();
        info.index = g;
        info.photons = 0.0;
        for k in a..a + n {
            // Bins before any light can arrive carry no kernel.
            if let Some(at) = kernels.position_of_bin(k) {
                slot += &kernels.kernel(at);
            }
            info.photons += kernels.bins[k].photons;
            info.end_ps = kernels.bins[k].end_ps;
        }
        info.kept = true;
        bins.push(info);
    }
    KernelStack {
        setup: kernels.setup.clone(),
        sampling: kernels.sampling,
        diffusion: kernels.diffusion,
        kernels: summed,
        bins,
        transport_cache: kernels.transport_cache.clone(),
    }
}

/// The files [`write`] makes in a folder.
pub const OUTPUTS: [&str; 6] = [
    "transmission.npy",
    "transmission.png",
    "beam.npy",
    "used_pixels.npy",
    "held_out.csv",
    "report.json",
];

/// Writes the outcome's files into `dir`, each whole or not at all, after
/// checking that none of them is one of `inputs`.
pub fn write(outcome: &Outcome, dir: &Path, inputs: &[&Path]) -> Result<Vec<PathBuf>, String> {
    let mut plan = crate::files::plan::FilePlan::new();
    for input in inputs {
        plan.input("input", input);
    }
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let paths: Vec<PathBuf> = OUTPUTS.iter().map(|n| dir.join(n)).collect();
    for p in &paths {
        plan.output("output", p);
    }
    plan.check().map_err(|e| e.to_string())?;
    let err = |e: String| e;
    crate::formats::image::write_image(outcome.transmission.view(), &paths[0])
        .map_err(|e| err(e.to_string()))?;
    let big = upscaled(&outcome.transmission, 8);
    crate::formats::image::write_image(big.view(), &paths[1]).map_err(|e| e.to_string())?;
    crate::formats::image::write_image(outcome.beam.view(), &paths[2])
        .map_err(|e| e.to_string())?;
    crate::formats::image::write_image(
        outcome.used.mapv(|u| f64::from(u8::from(u))).view(),
        &paths[3],
    )
    .map_err(|e| e.to_string())?;
    let csv: String = std::iter::once("iteration,held_out_deviance\n".to_string())
        .chain(
            outcome
                .report
                .fit
                .held_out
                .iter()
                .enumerate()
                .map(|(i, d)| format!("{},{d}\n", i + 1)),
        )
        .collect();
    crate::files::write_atomic(&paths[4], csv)
        .map_err(|e| format!("{}: {e}", paths[4].display()))?;
    let json = serde_json::to_string_pretty(&outcome.report).expect("report serialises");
    crate::files::write_atomic(&paths[5], json)
        .map_err(|e| format!("{}: {e}", paths[5].display()))?;
    Ok(paths)
}

/// `img` with each pixel repeated `k` times on both axes, scaled to [0, 1].
fn upscaled(img: &Array2<f64>, k: usize) -> Array2<f64> {
    let (h, w) = img.dim();
    Array2::from_shape_fn((h * k, w * k), |(i, j)| img[[i / k, j / k]].clamp(0.0, 1.0))
}
