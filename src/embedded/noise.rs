//! The noise of a recorded cube, measured from the cube itself, and the
//! likelihood that matches it.
//!
//! A camera's counts are Poisson at heart, but what a lab keeps has often
//! been processed: a background subtracted (the counts go negative where
//! the light is faint), a gain applied, pixels averaged. The model here is
//! the shifted, scaled Poisson one: at pixel `p` and bin `k`,
//! `Var(y) = gain * net_mean + dark_variance_p`, `E(y) = net_mean +
//! dark_level_p`. Then `z = (y - dark_level_p + dark_variance_p / gain) /
//! gain` has equal mean and variance, `(net_mean / gain) + offset_p` with
//! `offset_p = dark_variance_p / gain^2`: the Poisson likelihood of `z`
//! against that mean is the likelihood the solver uses. It reduces to
//! plain Poisson for raw counts (gain 1, dark variance = dark level).
//!
//! The dark level and variance come from the bins before the light
//! arrives (or from the stated subtracted background); the gain from the
//! light's bins: the variance of each bin about the line through its two
//! neighbours (`y_k - (y_{k-1} + y_{k+1}) / 2`, variance `1.5 sigma^2`
//! for independent noise on a signal smooth over three bins) against the
//! net mean there.

use ndarray::{Array2, Array3, s};
use serde::Serialize;

/// Bins before the light that the dark level and variance need.
pub const MIN_DARK_BINS: usize = 8;
/// The light starts at the first bin whose summed counts pass this share of
/// the summed profile's rise above its dark level.
pub const ONSET_SHARE: f64 = 0.02;
/// Bins left between the dark bins and the light's onset.
pub const ONSET_GUARD: usize = 2;
/// A measured gain within this much of 1 (or three standard errors, if
/// more) is taken as 1: the counts are Poisson.
pub const GAIN_TOLERANCE: f64 = 0.1;
/// Lag-one correlation of the second differences of white noise.
pub const WHITE_LAG1: f64 = -2.0 / 3.0;

/// The likelihood chosen for a cube.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum NoiseKind {
    /// Raw photon counts.
    Poisson,
    /// Photon counts with a background subtracted: Poisson shifted by the
    /// background's variance.
    PoissonLessBackground,
    /// Counts scaled by a gain other than 1 (and shifted by the dark
    /// variance): camera gain or processing.
    ScaledPoisson,
}

impl NoiseKind {
    /// The name in notes and files.
    pub fn name(self) -> &'static str {
        match self {
            NoiseKind::Poisson => "Poisson",
            NoiseKind::PoissonLessBackground => "Poisson less a subtracted background",
            NoiseKind::ScaledPoisson => "scaled Poisson (gain and dark variance measured)",
        }
    }
}

/// Variance against mean over one band of net means.
#[derive(Debug, Clone, Serialize)]
pub struct Band {
    /// The band's mean net count per bin.
    pub mean: f64,
    /// Its measured variance less the dark variance, over its mean: the
    /// gain there.
    pub variance_over_mean: f64,
    /// Bins in the band.
    pub samples: usize,
}

/// The measured noise and the model chosen.
#[derive(Debug, Clone, Serialize)]
pub struct NoiseModel {
    /// The model.
    pub kind: NoiseKind,
    /// Variance per unit net mean (1 for photon counts).
    pub gain: f64,
    /// The gain as measured, before it was taken as 1 or kept.
    pub measured_gain: f64,
    /// Its standard error (over pixels).
    pub gain_se: f64,
    /// Bins before the light's onset used for the dark statistics (0 when
    /// the background was stated instead).
    pub dark_bins: usize,
    /// Mean of each pixel's dark bins (rows, columns).
    #[serde(skip)]
    pub dark_level: Array2<f64>,
    /// Variance of each pixel's dark bins.
    #[serde(skip)]
    pub dark_variance: Array2<f64>,
    /// Median dark level and variance over the used pixels.
    pub median_dark: (f64, f64),
    /// Lag-one correlation of the second differences in the light's bins
    /// ([`WHITE_LAG1`] for noise independent from bin to bin).
    pub lag_one: f64,
    /// Variance against mean, by quartile of the net mean.
    pub bands: Vec<Band>,
    /// Share of the cube's values below 0.
    pub negative_share: f64,
    /// Why this model.
    pub reason: String,
}

/// What the solver fits: the transformed counts and their offsets.
#[derive(Debug, Clone)]
pub struct Transformed {
    /// `z` per bin (bins, rows, columns), clamped at 0.
    pub counts: Array3<f64>,
    /// `offset_p` per bin (rows, columns): the starting background.
    pub offset: Array2<f64>,
    /// Values of `z` below 0 set to 0.
    pub clamped: usize,
}

/// The background a lab subtracted, as it stated it.
#[derive(Debug, Clone)]
pub enum Subtracted {
    /// Counts per pixel and bin, the same everywhere.
    Level(f64),
    /// Counts per bin for each pixel (rows, columns).
    Map(Array2<f64>),
}

/// Measures the noise of `cube` (bins, rows, columns) over the `used`
/// pixels. `subtracted` stands in for the dark bins where there are too
/// few. The error names what is missing.
pub fn measure(
    cube: &Array3<f64>,
    used: &Array2<bool>,
    subtracted: Option<&Subtracted>,
) -> Result<NoiseModel, String> {
    let (bins, h, w) = cube.dim();
    if bins < 5 {
        return Err(format!(
            "{bins} time bins: the variance is measured from each bin against its neighbours, which needs at least 5"
        ));
    }
    let profile: Vec<f64> = (0..bins)
        .map(|k| {
            cube.slice(s![k, .., ..])
                .iter()
                .zip(used.iter())
                .filter(|(_, u)| **u)
                .map(|(v, _)| v)
                .sum()
        })
        .collect();
    let onset = light_onset(&profile);
    let dark_end = onset.saturating_sub(ONSET_GUARD);
    let (dark_level, dark_variance, dark_bins) = if dark_end >= MIN_DARK_BINS {
        let dark = cube.slice(s![..dark_end, .., ..]);
        let level = dark.mean_axis(ndarray::Axis(0)).expect("bins");
        let var = dark.var_axis(ndarray::Axis(0), 1.0);
        (level, var, dark_end)
    } else {
        match subtracted {
            Some(Subtracted::Level(b)) => (Array2::zeros((h, w)), Array2::from_elem((h, w), *b), 0),
            Some(Subtracted::Map(m)) => (Array2::zeros((h, w)), m.clone(), 0),
            None => {
                return Err(format!(
                    "only {dark_end} bins before the light arrives (bin {onset}): the dark level and variance need {MIN_DARK_BINS}; state the background the lab subtracted (--subtracted-background)"
                ));
            }
        }
    };
    // Second differences and local means in the light's bins.
    let mut samples: Vec<(f64, f64)> = Vec::new();
    let mut per_pixel: Vec<(f64, f64)> = Vec::new();
    let (mut lag_num, mut lag_den) = (0.0, 0.0);
    let start = onset.max(1);
    for i in 0..h {
        for j in 0..w {
            if !used[[i, j]] {
                continue;
            }
            let y = cube.slice(s![.., i, j]);
            let (mut excess, mut mean_sum) = (0.0, 0.0);
            let mut last: Option<f64> = None;
            for k in start..bins - 1 {
                let e = y[k] - 0.5 * (y[k - 1] + y[k + 1]);
                let net = (y[k - 1] + y[k] + y[k + 1]) / 3.0 - dark_level[[i, j]];
                if let Some(prev) = last {
                    lag_num += prev * e;
                }
                lag_den += e * e;
                last = Some(e);
                if net > 0.0 {
                    let v = e * e / 1.5 - dark_variance[[i, j]];
                    samples.push((net, v));
                    excess += v;
                    mean_sum += net;
                }
            }
            if mean_sum > 0.0 {
                per_pixel.push((excess, mean_sum));
            }
        }
    }
    if samples.len() < 10 || per_pixel.len() < 2 {
        return Err(format!(
            "too few bins with light ({} over {} pixels) to measure the variance against the mean",
            samples.len(),
            per_pixel.len()
        ));
    }
    let (ex, ms) = per_pixel
        .iter()
        .fold((0.0, 0.0), |(a, b), (e, m)| (a + e, b + m));
    let measured_gain = ex / ms;
    // Standard error of the ratio over pixels (their ratios weighted by
    // their light).
    let n = per_pixel.len() as f64;
    let mean_m = ms / n;
    let se2 = per_pixel
        .iter()
        .map(|(e, m)| (e - measured_gain * m).powi(2))
        .sum::<f64>()
        / (n * (n - 1.0) * mean_m * mean_m);
    let gain_se = se2.sqrt();
    samples.sort_by(|a, b| a.0.total_cmp(&b.0));
    let bands: Vec<Band> = samples
        .chunks(samples.len().div_ceil(4))
        .map(|c| {
            let m: f64 = c.iter().map(|s| s.0).sum();
            let v: f64 = c.iter().map(|s| s.1).sum();
            Band {
                mean: m / c.len() as f64,
                variance_over_mean: v / m,
                samples: c.len(),
            }
        })
        .collect();
    let median = |a: &Array2<f64>| super::percentile(super::used_values(a.view(), used), 0.5);
    let median_dark = (median(&dark_level), median(&dark_variance));
    let negative_share =
        cube.iter().filter(|&&v| v < 0.0).count() as f64 / cube.len().max(1) as f64;
    let integer = cube.iter().all(|&v| v >= 0.0 && v.fract() == 0.0);
    let poisson_gain = (measured_gain - 1.0).abs() <= GAIN_TOLERANCE.max(3.0 * gain_se);
    let (kind, gain) = if !poisson_gain {
        (NoiseKind::ScaledPoisson, measured_gain.max(1e-3))
    } else if integer && (median_dark.1 - median_dark.0).abs() <= 0.3 * median_dark.0.max(1.0) {
        (NoiseKind::Poisson, 1.0)
    } else {
        (NoiseKind::PoissonLessBackground, 1.0)
    };
    let lag_one = if lag_den > 0.0 {
        lag_num / lag_den
    } else {
        0.0
    };
    let dark_source = if dark_bins > 0 {
        format!("the {dark_bins} bins before the light (onset at bin {onset})")
    } else {
        "the stated subtracted background".to_string()
    };
    let reason = format!(
        "variance against net mean measured from each bin's departure from its neighbours: gain {measured_gain:.3} +- {gain_se:.3} ({} bins; by quartile of the mean {}); dark level {:.3} and variance {:.3} per bin (medians) from {dark_source}; {:.1} % of values negative{}; lag-one correlation of the second differences {lag_one:.2} ({:.2} for noise independent in time{})",
        samples.len(),
        bands_text(&bands),
        median_dark.0,
        median_dark.1,
        100.0 * negative_share,
        if integer { ", all whole numbers" } else { "" },
        WHITE_LAG1,
        if (lag_one - WHITE_LAG1).abs() > 0.15 {
            ": the noise is correlated in time (filtered?), so the measured variance is that of the filtered noise"
        } else {
            ""
        }
    );
    Ok(NoiseModel {
        kind,
        gain,
        measured_gain,
        gain_se,
        dark_bins,
        dark_level,
        dark_variance,
        median_dark,
        lag_one,
        bands,
        negative_share,
        reason,
    })
}

fn bands_text(bands: &[Band]) -> String {
    bands
        .iter()
        .map(|b| format!("{:.3} at {:.2}", b.variance_over_mean, b.mean))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The first bin of the light: the first bin from which three bins of
/// the summed `profile` stay above its dark level (the median of the bins
/// before a quarter of the way to its peak) by [`ONSET_SHARE`] of its
/// rise to the peak, and by four times the dark bins' spread (their median
/// absolute deviation as a standard deviation), so that noise alone does
/// not start it.
pub fn light_onset(profile: &[f64]) -> usize {
    let peak_at = super::peak(profile).0;
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let head = &profile[..(peak_at / 4).max(1)];
    let base = median(&mut head.to_vec());
    let spread = 1.4826 * median(&mut head.iter().map(|v| (v - base).abs()).collect());
    let threshold = (ONSET_SHARE * (profile[peak_at] - base)).max(4.0 * spread);
    (0..profile.len())
        .find(|&k| {
            profile[k..(k + 3).min(profile.len())]
                .iter()
                .all(|&v| v - base > threshold)
        })
        .unwrap_or(0)
}

impl NoiseModel {
    /// The cube as the solver's Poisson-like counts and their offsets.
    pub fn transform(&self, cube: &Array3<f64>) -> Transformed {
        let g = self.gain;
        let (bins, h, w) = cube.dim();
        let mut clamped = 0;
        let shift = Array2::from_shape_fn((h, w), |(i, j)| {
            self.dark_variance[[i, j]].max(0.0) / g - self.dark_level[[i, j]]
        });
        let counts = Array3::from_shape_fn((bins, h, w), |(k, i, j)| {
            let z = (cube[[k, i, j]] + shift[[i, j]]) / g;
            if z < 0.0 {
                clamped += 1;
                0.0
            } else {
                z
            }
        });
        let offset = self.dark_variance.mapv(|v| v.max(0.0) / (g * g));
        Transformed {
            counts,
            offset,
            clamped,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Poisson};

    /// 60 bins: 20 dark, then a pulse; raw counts Poisson(signal + dark).
    fn raw(gain: f64, dark: f64, seed: u64) -> (Array3<f64>, Array3<f64>) {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mean = Array3::from_shape_fn((60, 12, 12), |(k, i, j)| {
            let t = k as f64 - 20.0;
            let pulse = if t > 0.0 {
                40.0 * (t / 8.0) * (-t / 8.0).exp() * 2.7
            } else {
                0.0
            };
            pulse * (1.0 + 0.03 * (i + j) as f64)
        });
        let y = mean.mapv(|m| {
            let lam = (m + dark) / gain;
            gain * Poisson::new(lam).unwrap().sample(&mut rng)
        });
        (y, mean)
    }

    #[test]
    fn raw_counts_are_poisson_and_scaled_counts_have_their_gain_measured() {
        let used = Array2::from_elem((12, 12), true);
        let (y, _) = raw(1.0, 5.0, 1);
        let m = measure(&y, &used, None).unwrap();
        assert_eq!(m.kind, NoiseKind::Poisson, "{}", m.reason);
        assert!((m.median_dark.0 - 5.0).abs() < 0.5);
        for (gain, seed) in [(3.8, 2), (0.35, 3)] {
            let (y, _) = raw(gain, 5.0, seed);
            let m = measure(&y, &used, None).unwrap();
            assert_eq!(m.kind, NoiseKind::ScaledPoisson, "{}", m.reason);
            assert!(
                (m.measured_gain / gain - 1.0).abs() < 0.1,
                "{} for {gain}",
                m.measured_gain
            );
            assert!((m.lag_one - WHITE_LAG1).abs() < 0.1, "{}", m.lag_one);
        }
    }

    #[test]
    fn a_subtracted_background_is_poisson_less_it_and_the_transform_equalises_mean_and_variance() {
        let used = Array2::from_elem((12, 12), true);
        let (y, mean) = raw(1.0, 6.0, 4);
        let y = y - 6.0;
        let m = measure(&y, &used, None).unwrap();
        assert_eq!(m.kind, NoiseKind::PoissonLessBackground, "{}", m.reason);
        assert!(m.negative_share > 0.05);
        let t = m.transform(&y);
        // Dark bins: within each pixel z's variance equals its mean (the
        // pixel's estimated shift is constant in time), on average over
        // the pixels; both near the dark rate (6).
        let dark = t.counts.slice(s![..18, .., ..]);
        let mu = dark.mean_axis(ndarray::Axis(0)).unwrap();
        let var = dark.var_axis(ndarray::Axis(0), 1.0);
        let (mu, var) = (mu.mean().unwrap(), var.mean().unwrap());
        assert!(
            (var / mu - 1.0).abs() < 0.1 && (mu - 6.0).abs() < 0.5,
            "{mu} {var}"
        );
        assert!((t.offset.mean().unwrap() - 6.0).abs() < 0.6);
        // Light bins: mean z = net mean + offset.
        let k = 28;
        let z_mean = t.counts.slice(s![k, .., ..]).mean().unwrap();
        let want = mean.slice(s![k, .., ..]).mean().unwrap() + 6.0;
        assert!((z_mean / want - 1.0).abs() < 0.05, "{z_mean} {want}");
    }

    #[test]
    fn too_few_bins_or_dark_bins_are_refused_by_name() {
        let used = Array2::from_elem((3, 3), true);
        let e = measure(&Array3::zeros((4, 3, 3)), &used, None).unwrap_err();
        assert!(e.contains("at least 5"), "{e}");
        // The light 5 bins after the cube's start.
        let (y, _) = raw(1.0, 5.0, 6);
        let y = y.slice(s![15.., ..3, ..3]).to_owned();
        let e = measure(&y, &used, None).unwrap_err();
        assert!(e.contains("--subtracted-background"), "{e}");
    }
}
