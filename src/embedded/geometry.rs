//! The object inside the medium, lit through it: a pulsed beam enters the
//! front slab, the light that crosses it lights a thin mask (the object),
//! and what the mask passes crosses the back slab to the imaged face.
//!
//! Both slabs are the diffusion model's finite slab with extrapolated
//! boundaries ([`scatterscope_physics::slab`]); the light reaching the
//! object plane at lateral position `x` and time `t` is the front slab's
//! transmitted flux `f1(t)` times a Gaussian of variance `2 D1 c t` per
//! axis, convolved with the beam's profile. The forward model is the back
//! slab's kernels applied to the object times that light, with `f1` (and
//! the instrument's response, when one is given) as the arrival-time
//! density of the light entering the back slab: exact in time (on a grid
//! of at most 5 ps). The light's lateral profile is taken as its
//! time-weighted mean `b(x)` (the beam's map); how far the true
//! time-varying profile departs from `b(x) f1(t)` is reported
//! ([`BeamMap::separation_error`]).

use ndarray::Array2;
use scatterscope_physics::{
    Diffusion, InstrumentResponse, IrfTable, Medium, MediumModel, ParamError, Sensor, Setup,
    TimeBins,
};
use serde::Serialize;

/// The finest grid (ps) the front slab's time profile is tabulated on.
pub const PROFILE_STEP_PS: f64 = 5.0;
/// Share of the front slab's light the tabulated profile may leave out
/// at its late end.
pub const PROFILE_TAIL: f64 = 1e-6;

/// The beam entering the front slab.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum Beam {
    /// A plane wave: the same light at every lateral position.
    Plane,
    /// A Gaussian beam of `fwhm_cm` centred at `centre_cm` (x, y) from the
    /// imaged field's centre.
    Gaussian {
        /// Full width at half maximum (cm).
        fwhm_cm: f64,
        /// Centre (x right, y down) from the field's centre (cm).
        centre_cm: (f64, f64),
    },
}

/// Front slab, back slab, beam and instrument response.
#[derive(Debug, Clone, PartialEq)]
pub struct Geometry {
    /// The slab between the beam and the object.
    pub front: Medium,
    /// The slab between the object and the imaged face.
    pub back: Medium,
    /// The beam entering the front slab.
    pub beam: Beam,
    /// The instrument's timing response, where one is known.
    pub irf: Option<IrfTable>,
}

/// A slab medium from its reduced scattering coefficient (g taken as 0,
/// which the diffusion model sees only through `(1 - g) mu_s`).
pub fn slab(mu_s_reduced_per_cm: f64, mu_a_per_cm: f64, n: f64, thickness_cm: f64) -> Medium {
    Medium {
        mu_a_per_cm,
        mu_s_per_cm: mu_s_reduced_per_cm,
        g: 0.0,
        refractive_index: n,
        thickness_cm,
        model: MediumModel::Slab,
    }
}

/// The light's lateral profile at the object plane and how separable it is.
#[derive(Debug, Clone)]
pub struct BeamMap {
    /// Time-weighted light at each object-grid pixel, 1 at its largest.
    pub map: Array2<f64>,
    /// `|| I(x, t) - b(x) f1(t) || / || I ||` over the grid and time: how far
    /// the light's time-varying profile is from the separable model's
    /// (0 for a plane wave).
    pub separation_error: f64,
}

impl Geometry {
    /// Checks both media (as slabs) and the beam; the error names the field.
    pub fn validate(&self) -> Result<(), ParamError> {
        self.front.validate().map_err(|e| prefixed("front_", e))?;
        self.back.validate().map_err(|e| prefixed("back_", e))?;
        if let Beam::Gaussian { fwhm_cm, centre_cm } = self.beam {
            if !(fwhm_cm.is_finite() && fwhm_cm > 0.0) {
                return Err(ParamError::new(
                    "beam_fwhm_cm",
                    fwhm_cm,
                    "a beam's width must be positive and finite",
                ));
            }
            if !(centre_cm.0.is_finite() && centre_cm.1.is_finite()) {
                return Err(ParamError::new(
                    "beam_centre_cm",
                    format!("{centre_cm:?}"),
                    "a beam's centre must be finite",
                ));
            }
        }
        Ok(())
    }

    /// The arrival-time density of the light entering the back slab: the
    /// front slab's transmitted flux (from the pulse's entry at 0 ps),
    /// convolved with the instrument's response, on a grid of at most
    /// [`PROFILE_STEP_PS`] (`bin_ps / 10` when finer), up to where all but
    /// [`PROFILE_TAIL`] of it has arrived.
    pub fn arrival_profile(&self, bin_ps: f64) -> Result<IrfTable, ParamError> {
        self.validate()?;
        let step = PROFILE_STEP_PS.min(bin_ps / 10.0);
        let d = Diffusion::new(&self.front)?;
        let front = flux_on(&d, step)?;
        let weights = match &self.irf {
            None => front,
            Some(irf) => convolve(&front, &resample(irf, step)),
        };
        let start = self
            .irf
            .as_ref()
            .map_or(0.0, |irf| snap(irf.start_ps(), step));
        IrfTable::new(step, start, weights)
    }

    /// The back slab's setup for a cube of `bins` (times from the pulse's
    /// entry into the front slab) on `sensor`, with the light entering it
    /// timed by [`Self::arrival_profile`]; the kernels carry one photon in
    /// all.
    pub fn back_setup(&self, bins: TimeBins, sensor: Sensor) -> Result<Setup, ParamError> {
        let profile = self.arrival_profile(bins.width_ps)?;
        Ok(Setup {
            medium: self.back,
            sensor,
            bins,
            total_photons: 1.0,
            min_bin_photons: 0.0,
            irf: Some(InstrumentResponse::Measured(profile)),
        })
    }

    /// The beam's light at the object plane on a grid of `shape` pixels of
    /// `pitch_cm` whose pixel `centre` (row, column) sits at the field's
    /// centre: the time-weighted mean of the front slab's lateral spread
    /// convolved with the beam, 1 at its largest.
    pub fn beam_map(
        &self,
        shape: (usize, usize),
        centre: (f64, f64),
        pitch_cm: f64,
    ) -> Result<BeamMap, ParamError> {
        let (fwhm, (cx, cy)) = match self.beam {
            Beam::Plane => {
                return Ok(BeamMap {
                    map: Array2::ones(shape),
                    separation_error: 0.0,
                });
            }
            Beam::Gaussian { fwhm_cm, centre_cm } => (fwhm_cm, centre_cm),
        };
        let d = Diffusion::new(&self.front)?;
        // The front slab's flux on a coarse grid: the profile's shape in
        // time enters only through the spread's variance.
        let step = 25.0;
        let flux = flux_on(&d, step)?;
        let beam_var = (fwhm / (8.0 * std::f64::consts::LN_2).sqrt()).powi(2);
        let (h, w) = shape;
        let r2: Array2<f64> = Array2::from_shape_fn(shape, |(i, j)| {
            let x = (j as f64 - centre.1) * pitch_cm - cx;
            let y = (i as f64 - centre.0) * pitch_cm - cy;
            x * x + y * y
        });
        let frame = |t: f64| {
            let var = beam_var + 2.0 * d.dc_cm2_per_ps() * t;
            r2.mapv(|r| (-r / (2.0 * var)).exp() / (2.0 * std::f64::consts::PI * var))
        };
        let mut mean = Array2::<f64>::zeros((h, w));
        let frames: Vec<(f64, Array2<f64>)> = flux
            .iter()
            .enumerate()
            .filter(|(_, f)| **f > 1e-9)
            .map(|(k, &f)| (f, frame((k as f64 + 0.5) * step)))
            .collect();
        for (f, fr) in &frames {
            mean.scaled_add(*f, fr);
        }
        let total: f64 = frames.iter().map(|(f, _)| f).sum();
        mean /= total;
        let (mut off, mut all) = (0.0, 0.0);
        for (f, fr) in &frames {
            off += f * f * (fr - &mean).mapv(|v| v * v).sum();
            all += f * f * fr.mapv(|v| v * v).sum();
        }
        let top = mean.fold(0.0f64, |m, &v| m.max(v));
        Ok(BeamMap {
            map: mean / top,
            separation_error: (off / all).sqrt(),
        })
    }
}

/// The error of one slab with its field named for the slab.
fn prefixed(prefix: &'static str, e: ParamError) -> ParamError {
    let field: &'static str = match (prefix, e.field) {
        ("front_", "mu_a_per_cm") => "front_mu_a_per_cm",
        ("front_", "mu_s_per_cm") => "front_mu_s_reduced_per_cm",
        ("front_", "refractive_index") => "front_refractive_index",
        ("front_", "thickness_cm") => "front_thickness_cm",
        ("back_", "mu_a_per_cm") => "back_mu_a_per_cm",
        ("back_", "mu_s_per_cm") => "back_mu_s_reduced_per_cm",
        ("back_", "refractive_index") => "back_refractive_index",
        ("back_", "thickness_cm") => "back_thickness_cm",
        (_, other) => other,
    };
    ParamError::new(field, e.value, e.reason)
}

/// The slab's transmitted flux integrated over bins of `step` ps from 0,
/// until all but [`PROFILE_TAIL`] of it has arrived (unnormalised).
pub(super) fn flux_on(d: &Diffusion, step: f64) -> Result<Vec<f64>, ParamError> {
    // Four-point Gauss-Legendre in every bin: the flux is smooth on 5 ps
    // wherever it carries light (its rise takes hundreds of ps here).
    const NODES: [(f64, f64); 4] = [
        (-0.861_136_311_594_053, 0.347_854_845_137_454),
        (-0.339_981_043_584_856, 0.652_145_154_862_546),
        (0.339_981_043_584_856, 0.652_145_154_862_546),
        (0.861_136_311_594_053, 0.347_854_845_137_454),
    ];
    let peak = d.peak_time_ps().max(step);
    let log_peak = d.log_temporal_density(peak);
    let most = (scatterscope_physics::irf::MAX_TABLE_BINS / 2).max(1);
    let mut weights = Vec::new();
    let mut total = 0.0;
    for k in 0..most {
        let mid = (k as f64 + 0.5) * step;
        let w: f64 = NODES
            .iter()
            .map(|(x, wt)| {
                let t = mid + 0.5 * step * x;
                wt * 0.5 * step * (d.log_temporal_density(t) - log_peak).exp()
            })
            .sum();
        let last = weights.last().copied().unwrap_or(0.0);
        weights.push(w);
        total += w;
        // Past the peak the flux falls at least geometrically from bin to
        // bin: stop where the rest at the current ratio, w r / (1 - r), is
        // below the tail.
        let r = if last > 0.0 { w / last } else { 1.0 };
        if mid > 2.0 * peak && r < 1.0 && w * r / (1.0 - r) < PROFILE_TAIL * total {
            break;
        }
    }
    if !(total > 0.0 && total.is_finite()) {
        return Err(ParamError::new(
            "front_thickness_cm",
            d.z0_cm,
            "the front slab transmits no light in the modelled time",
        ));
    }
    Ok(weights)
}

/// A table's density on bins of `step` from its start snapped to `step`.
fn resample(irf: &IrfTable, step: f64) -> Vec<f64> {
    let (lo, hi) = irf.support_ps();
    let start = snap(lo, step);
    let n = ((hi - start) / step).ceil().max(1.0) as usize;
    (0..n)
        .map(|k| {
            let a = start + k as f64 * step;
            irf.cdf(a + step) - irf.cdf(a)
        })
        .collect()
}

/// `t` rounded down to a multiple of `step`.
fn snap(t: f64, step: f64) -> f64 {
    (t / step).floor() * step
}

/// The density of the sum of two delays, each uniform within the bins of
/// its table (same step): the product of bins `i` and `j` spans bins `i +
/// j` and `i + j + 1` as a triangle, split half and half (so the mean is
/// exact).
pub(super) fn convolve(a: &[f64], b: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; a.len() + b.len()];
    for (i, &x) in a.iter().enumerate() {
        if x == 0.0 {
            continue;
        }
        for (j, &y) in b.iter().enumerate() {
            let half = 0.5 * x * y;
            out[i + j] += half;
            out[i + j + 1] += half;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn published() -> Geometry {
        Geometry {
            front: slab(71.0, 0.14, 1.0, 2.5),
            back: slab(71.0, 0.14, 1.0, 2.5),
            beam: Beam::Gaussian {
                fwhm_cm: 3.0,
                centre_cm: (0.0, 0.0),
            },
            irf: None,
        }
    }

    #[test]
    fn the_arrival_profile_is_the_front_slabs_flux_normalised_and_peaks_where_the_slab_does() {
        let g = published();
        let p = g.arrival_profile(50.0).unwrap();
        let d = Diffusion::new(&g.front).unwrap();
        let w = p.weights();
        let (k, _) = w
            .iter()
            .enumerate()
            .fold((0, 0.0), |b, (k, &v)| if v > b.1 { (k, v) } else { b });
        let at = (k as f64 + 0.5) * p.bin_ps();
        assert!(
            (at - d.peak_time_ps()).abs() <= p.bin_ps(),
            "{at} vs {}",
            d.peak_time_ps()
        );
        // The table's sum against the slab's flux integrated independently
        // (trapezoid on 1 ps up to the table's end, relative to the same
        // integral to 10x further): what the table leaves out.
        let end = w.len() as f64 * p.bin_ps();
        let dens = |t: f64| d.log_temporal_density(t).exp();
        let trap = |a: f64, b: f64| {
            let n = ((b - a) / 1.0) as usize;
            (0..n)
                .map(|i| 0.5 * (dens(a + i as f64) + dens(a + i as f64 + 1.0)))
                .sum::<f64>()
        };
        let left_out = trap(end, 10.0 * end) / trap(0.0, 10.0 * end);
        assert!(left_out < 1e-5, "{left_out}");
    }

    #[test]
    fn an_instrument_response_delays_the_profile_by_its_mean() {
        let mut g = published();
        let plain = g.arrival_profile(50.0).unwrap();
        g.irf = Some(IrfTable::new(10.0, 200.0, vec![1.0, 2.0, 1.0]).unwrap());
        let delayed = g.arrival_profile(50.0).unwrap();
        let shift = delayed.mean_ps() - plain.mean_ps();
        assert!((shift - 215.0).abs() < 1.0, "{shift}");
    }

    #[test]
    fn a_plane_wave_lights_every_pixel_alike_and_a_wide_beam_nearly_so() {
        let mut g = published();
        g.beam = Beam::Plane;
        let m = g.beam_map((8, 8), (3.5, 3.5), 0.14).unwrap();
        assert!(m.map.iter().all(|&v| v == 1.0));
        assert_eq!(m.separation_error, 0.0);
        g.beam = Beam::Gaussian {
            fwhm_cm: 6.0,
            centre_cm: (0.0, 0.0),
        };
        let m = g.beam_map((32, 32), (15.5, 15.5), 0.14).unwrap();
        // Centre 1, corner (2.2 cm out on both axes) lower but lit.
        assert!((m.map[[15, 15]] - 1.0).abs() < 1e-3);
        assert!(
            m.map[[0, 0]] < 0.9 && m.map[[0, 0]] > 0.3,
            "{}",
            m.map[[0, 0]]
        );
        assert!(m.separation_error > 0.0 && m.separation_error < 0.5);
    }

    #[test]
    fn a_bad_slab_is_named_by_its_side() {
        let mut g = published();
        g.back.thickness_cm = 0.0;
        let e = g.validate().unwrap_err();
        assert_eq!(e.field, "back_thickness_cm");
        g.back.thickness_cm = 2.5;
        g.front.refractive_index = 0.9;
        assert_eq!(g.validate().unwrap_err().field, "front_refractive_index");
    }
}
