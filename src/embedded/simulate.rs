//! Cubes of the object inside the medium with a known truth, recorded as a
//! SPAD camera and a lab's processing leave them: dark counts that differ
//! from pixel to pixel, a background subtracted that leaves some behind, a
//! gain, filtered pixels (neighbour means), hot and dead pixels; written as
//! a lab publishes them (a MATLAB level 5 cube of rows x columns x bins and
//! a file of pixel centres).

use std::path::Path;

use ndarray::{Array2, Array3, s};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Poisson};
use scatterscope_physics::TimeBins;

use super::geometry::Geometry;
use crate::forward::ForwardModel;

/// A transmissive target cut in an opaque card.
#[derive(Debug, Clone, PartialEq)]
pub enum Target {
    /// One capital letter filling most of the field.
    Letter(char),
    /// Two vertical slits `separation_cm` apart (centre to centre), each
    /// half that wide and 2 cm long.
    DoubleSlit {
        /// Centre-to-centre separation (cm).
        separation_cm: f64,
    },
}

impl Target {
    /// Parses `letter:A` or `slits:0.5` (cm).
    pub fn parse(s: &str) -> Result<Self, String> {
        if let Some(l) = s.strip_prefix("letter:") {
            let mut c = l.chars();
            return match (c.next(), c.next()) {
                (Some(ch), None) if ch.is_ascii_alphanumeric() => {
                    Ok(Target::Letter(ch.to_ascii_uppercase()))
                }
                _ => Err(format!("target `{s}`: one letter or digit after letter:")),
            };
        }
        if let Some(v) = s.strip_prefix("slits:") {
            let sep: f64 = v
                .parse()
                .map_err(|_| format!("target `{s}`: a separation in cm after slits:"))?;
            if !(sep.is_finite() && sep > 0.0) {
                return Err(format!("target `{s}`: the separation must be positive"));
            }
            return Ok(Target::DoubleSlit { separation_cm: sep });
        }
        Err(format!("target `{s}`: letter:X or slits:CM"))
    }

    /// The transmission (0 or 1) on `shape` pixels of `pitch_cm`.
    pub fn render(&self, shape: (usize, usize), pitch_cm: f64) -> Array2<f64> {
        let (h, w) = shape;
        match *self {
            Target::Letter(ch) => {
                let text = ch.to_string();
                crate::scene::text(h, w, &[text.as_str()]).mapv(|v| if v > 0.5 { 1.0 } else { 0.0 })
            }
            Target::DoubleSlit { separation_cm } => {
                let (cy, cx) = ((h as f64 - 1.0) / 2.0, (w as f64 - 1.0) / 2.0);
                // Each pixel's covered share of a slit, on a 4 x 4 subgrid.
                Array2::from_shape_fn(shape, |(i, j)| {
                    let mut covered = 0.0;
                    for a in 0..4 {
                        for b in 0..4 {
                            let y = (i as f64 - cy + (a as f64 - 1.5) / 4.0) * pitch_cm;
                            let x = (j as f64 - cx + (b as f64 - 1.5) / 4.0) * pitch_cm;
                            let in_slit = y.abs() <= 1.0
                                && ((x.abs() - 0.5 * separation_cm).abs() <= 0.25 * separation_cm);
                            covered += f64::from(u8::from(in_slit));
                        }
                    }
                    covered / 16.0
                })
            }
        }
    }
}

/// How the camera and the lab's processing record the light.
#[derive(Debug, Clone)]
pub struct Recording {
    /// Net photons the whole cube holds on average.
    pub photons: f64,
    /// Each pixel's dark counts per bin, drawn uniformly from this range.
    pub dark: (f64, f64),
    /// What the lab's subtraction leaves per pixel and bin, drawn uniformly.
    pub residual: (f64, f64),
    /// Variance per unit mean (1: photon counting).
    pub gain: f64,
    /// Pixels replaced by the mean of 2-4 of their neighbours.
    pub filtered: usize,
    /// Hot pixels (50x the dark counts).
    pub hot: usize,
    /// Dead pixels (no counts).
    pub dead: usize,
    /// Seed of every draw.
    pub seed: u64,
}

/// A simulated cube and what made it.
#[derive(Debug, Clone)]
pub struct Simulated {
    /// The recorded values (bins, rows, columns), background subtracted.
    pub cube: Array3<f64>,
    /// The expected net counts (bins, rows, columns).
    pub expected: Array3<f64>,
    /// The target's transmission on the camera's pixels.
    pub truth: Array2<f64>,
    /// The pixels made bad, (row, column).
    pub bad: Vec<(usize, usize)>,
}

/// Simulates `target` in `geometry` for a camera of `shape` pixels of
/// `pitch_cm` and `bins` on its clock (time zero `time_zero_ps` after bin
/// 0's start), recorded as `rec` says.
pub fn simulate(
    geometry: &Geometry,
    truth: &Array2<f64>,
    pitch_cm: f64,
    bins: (usize, f64),
    time_zero_ps: f64,
    rec: &Recording,
) -> Result<Simulated, String> {
    let (h, w) = truth.dim();
    let bins_on_clock = TimeBins {
        start_ps: -time_zero_ps,
        width_ps: bins.1,
        count: bins.0,
    };
    let kernels = super::back_kernels(geometry, bins_on_clock, (h, w), pitch_cm)
        .map_err(|e| e.to_string())?;
    let model = ForwardModel::with_sensor(&kernels, (h, w));
    let beam = super::beam_on(geometry, &model, pitch_cm).map_err(|e| e.to_string())?;
    // The card is opaque outside the field.
    let lit = model.embed(truth.view(), 0.0) * &beam.map;
    // Every bin of the camera, those before any light can arrive (which
    // the kernel stack leaves out) at 0.
    let kept = model.expected(lit.view()).counts;
    let mut expected = Array3::<f64>::zeros((bins.0, h, w));
    for (at, info) in kernels.kept_bins().enumerate() {
        expected
            .slice_mut(s![info.index, .., ..])
            .assign(&kept.slice(s![at, .., ..]));
    }
    let total = expected.sum();
    if total <= 0.0 {
        return Err("the target passes no light to the camera".into());
    }
    expected *= rec.photons / total;
    let mut rng = ChaCha8Rng::seed_from_u64(rec.seed);
    let mut dark = Array2::from_shape_fn((h, w), |_| rng.random_range(rec.dark.0..=rec.dark.1));
    let residual = Array2::from_shape_fn((h, w), |_| {
        rng.random_range(rec.residual.0..=rec.residual.1)
    });
    // Bad pixels away from the edges, none twice.
    let mut bad: Vec<(usize, usize)> = Vec::new();
    let wanted = rec.filtered + rec.hot + rec.dead;
    if wanted > (h.saturating_sub(2)) * (w.saturating_sub(2)) / 2 {
        return Err(format!(
            "{wanted} bad pixels on a {h} x {w} camera: at most half its inner pixels"
        ));
    }
    while bad.len() < wanted {
        let p = (rng.random_range(1..h - 1), rng.random_range(1..w - 1));
        if !bad
            .iter()
            .any(|q| q.0.abs_diff(p.0) <= 1 && q.1.abs_diff(p.1) <= 1)
        {
            bad.push(p);
        }
    }
    let (filtered, rest) = bad.split_at(rec.filtered);
    let (hot, dead) = rest.split_at(rec.hot);
    for &p in hot {
        dark[p] *= 50.0;
    }
    let g = rec.gain;
    let mut cube = Array3::from_shape_fn(expected.dim(), |(k, i, j)| {
        let lam = (expected[[k, i, j]] + dark[[i, j]]) / g;
        let raw = if lam > 0.0 {
            g * Poisson::new(lam).expect("finite mean").sample(&mut rng)
        } else {
            0.0
        };
        raw - (dark[[i, j]] - residual[[i, j]])
    });
    for &(i, j) in dead {
        let level = -(dark[[i, j]] - residual[[i, j]]);
        cube.slice_mut(s![.., i, j]).fill(level);
    }
    for &(i, j) in filtered {
        // The mean of 2-4 neighbours, as a camera's software fills a pixel.
        let near = [(i - 1, j), (i + 1, j), (i, j - 1), (i, j + 1)];
        let n = rng.random_range(2..=4usize);
        let chosen = &near[..n];
        for k in 0..cube.dim().0 {
            let m = chosen.iter().map(|&q| cube[[k, q.0, q.1]]).sum::<f64>() / n as f64;
            cube[[k, i, j]] = m;
        }
    }
    Ok(Simulated {
        cube,
        expected,
        truth: truth.clone(),
        bad,
    })
}

/// Writes `cube` (bins, rows, columns) as a lab publishes it: `cube.mat`
/// (MATLAB level 5, variable `cube`, rows x columns x bins, doubles) and
/// `positions.mat` (variables `x` and `y`, rows x columns, pixel centres in
/// mm for pixels of `pitch_cm`).
pub fn write_as_lab(cube: &Array3<f64>, pitch_cm: (f64, f64), dir: &Path) -> std::io::Result<()> {
    let (bins, h, w) = cube.dim();
    // Column-major over (rows, columns, bins): rows fastest, which is the
    // standard order over (bins, columns, rows).
    let values: Vec<f64> = cube
        .view()
        .permuted_axes([0, 2, 1])
        .iter()
        .copied()
        .collect();
    crate::formats::mat5::write(&dir.join("cube.mat"), &[("cube", &[h, w, bins], &values)])?;
    let column_major = |f: &dyn Fn(usize, usize) -> f64| -> Vec<f64> {
        ndarray::Array2::from_shape_fn((h, w), |(i, j)| f(i, j))
            .t()
            .iter()
            .copied()
            .collect()
    };
    let x = column_major(&|_, j| 10.0 * pitch_cm.0 * j as f64);
    let y = column_major(&|i, _| 10.0 * pitch_cm.1 * i as f64);
    crate::formats::mat5::write(
        &dir.join("positions.mat"),
        &[("x", &[h, w], &x), ("y", &[h, w], &y)],
    )
}
