//! Which pixels of a recorded cube enter the likelihood: a mask given as a
//! file, and the pixels found bad in the data itself: filtered (a camera's
//! software replaced them by the mean of some of their neighbours), dead
//! (no change in time) and hot (a dark level far above the camera's).

use ndarray::{Array2, Array3};
use serde::Serialize;

/// A pixel's dark variance above this many times the camera's median marks
/// it hot.
pub const HOT_FACTOR: f64 = 10.0;
/// Relative tolerance within which a pixel's trace equals a neighbour mean.
pub const FILTERED_TOLERANCE: f64 = 1e-9;

/// Pixels left out, by cause.
#[derive(Debug, Clone, Default, Serialize)]
pub struct BadPixels {
    /// Pixels the given mask left out.
    pub masked: usize,
    /// Pixels whose every bin is the mean of 2-4 of their 8 neighbours.
    pub filtered: usize,
    /// Pixels whose trace never changes.
    pub dead: usize,
    /// Pixels whose dark variance is over [`HOT_FACTOR`] times the median.
    pub hot: usize,
}

impl BadPixels {
    /// Every pixel left out.
    pub fn total(&self) -> usize {
        self.masked + self.filtered + self.dead + self.hot
    }

    /// One line for the notes.
    pub fn describe(&self, pixels: usize) -> String {
        format!(
            "pixels left out of the likelihood: {} of {pixels} ({} by the given mask, {} filtered (each bin the mean of 2-4 neighbours), {} dead (no change in time), {} hot (dark variance over {HOT_FACTOR}x the median))",
            self.total(),
            self.masked,
            self.filtered,
            self.dead,
            self.hot
        )
    }
}

/// The pixels of `cube` (bins, rows, columns) to use: `given` (true = use)
/// less the filtered and dead pixels found; the counts by cause (hot
/// pixels need the dark variance: [`mark_hot`]).
pub fn find(cube: &Array3<f64>, given: Option<&Array2<bool>>) -> (Array2<bool>, BadPixels) {
    let (_, h, w) = cube.dim();
    let mut used = given
        .cloned()
        .unwrap_or_else(|| Array2::from_elem((h, w), true));
    let mut bad = BadPixels {
        masked: used.iter().filter(|&&u| !u).count(),
        ..BadPixels::default()
    };
    let scale = cube.fold(0.0f64, |m, &v| m.max(v.abs())) + 1.0;
    for i in 0..h {
        for j in 0..w {
            if !used[[i, j]] {
                continue;
            }
            let trace = cube.slice(ndarray::s![.., i, j]);
            let first = trace[0];
            if trace.iter().all(|&v| v == first) {
                used[[i, j]] = false;
                bad.dead += 1;
            } else if is_neighbour_mean(cube, i, j, FILTERED_TOLERANCE * scale) {
                used[[i, j]] = false;
                bad.filtered += 1;
            }
        }
    }
    (used, bad)
}

/// Leaves out of `used` the pixels whose `dark_variance` is over
/// [`HOT_FACTOR`] times the used pixels' median, counting them in `bad`.
pub fn mark_hot(used: &mut Array2<bool>, bad: &mut BadPixels, dark_variance: &Array2<f64>) {
    let median = super::percentile(super::used_values(dark_variance.view(), used), 0.5);
    for (u, v) in used.iter_mut().zip(dark_variance.iter()) {
        if *u && median > 0.0 && *v > HOT_FACTOR * median {
            *u = false;
            bad.hot += 1;
        }
    }
}

/// Whether every bin of pixel (i, j) equals the mean of the same 2, 3 or 4
/// of its (up to 8) neighbours within `tol`.
fn is_neighbour_mean(cube: &Array3<f64>, i: usize, j: usize, tol: f64) -> bool {
    let (_, h, w) = cube.dim();
    let mut near = Vec::with_capacity(8);
    for di in -1i64..=1 {
        for dj in -1i64..=1 {
            let (a, b) = (i as i64 + di, j as i64 + dj);
            if (di, dj) != (0, 0) && a >= 0 && b >= 0 && (a as usize) < h && (b as usize) < w {
                near.push((a as usize, b as usize));
            }
        }
    }
    let n = near.len();
    let traces: Vec<_> = near
        .iter()
        .map(|&(a, b)| cube.slice(ndarray::s![.., a, b]))
        .collect();
    let own = cube.slice(ndarray::s![.., i, j]);
    // Every subset of 2-4 neighbours, as a bit set.
    (1u32..(1 << n))
        .filter(|s| (2..=4).contains(&s.count_ones()))
        .any(|s| {
            let members: Vec<usize> = (0..n).filter(|k| s & (1 << k) != 0).collect();
            let m = members.len() as f64;
            own.iter().enumerate().all(|(t, &v)| {
                let mean = members.iter().map(|&k| traces[k][t]).sum::<f64>() / m;
                (v - mean).abs() <= tol
            })
        })
}

/// A mask file's array as pixels to use: non-zero entries mark bad pixels
/// (the usual bad-pixel map); `shape` is the cube's (rows, columns).
pub fn mask_from(
    values: &ndarray::ArrayD<f64>,
    shape: (usize, usize),
) -> Result<Array2<bool>, String> {
    let got = values.shape();
    if got != [shape.0, shape.1] {
        return Err(format!(
            "a bad-pixel mask of shape {got:?} for a cube of {} x {} pixels",
            shape.0, shape.1
        ));
    }
    if let Some(v) = values.iter().find(|v| !v.is_finite()) {
        return Err(format!(
            "a bad-pixel mask holds {v}: entries are 0 (use) or 1 (bad)"
        ));
    }
    Ok(values
        .view()
        .into_dimensionality::<ndarray::Ix2>()
        .expect("2-D")
        .mapv(|v| v == 0.0))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    #[test]
    fn filtered_dead_and_hot_pixels_are_found_and_counted() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut cube =
            Array3::from_shape_fn((40, 6, 7), |_| rng.random_range(0.0..50.0f64).round());
        // (2, 3) the mean of its left and right neighbours; (4, 1) of three.
        for t in 0..40 {
            cube[[t, 2, 3]] = (cube[[t, 2, 2]] + cube[[t, 2, 4]]) / 2.0;
            cube[[t, 4, 1]] = (cube[[t, 3, 0]] + cube[[t, 5, 2]] + cube[[t, 4, 2]]) / 3.0;
            cube[[t, 0, 6]] = 7.0;
        }
        let mut dark = Array2::from_elem((6, 7), 4.0);
        dark[[5, 5]] = 60.0;
        let (mut used, mut bad) = find(&cube, None);
        mark_hot(&mut used, &mut bad, &dark);
        assert_eq!((bad.filtered, bad.dead, bad.hot), (2, 1, 1), "{bad:?}");
        assert!(!used[[2, 3]] && !used[[4, 1]] && !used[[0, 6]] && !used[[5, 5]]);
        assert_eq!(used.iter().filter(|&&u| u).count(), 42 - 4);
        // Noise alone is never a neighbour mean.
        let (_, clean) = find(
            &Array3::from_shape_fn((40, 6, 7), |_| rng.random_range(0.0..50.0f64).round()),
            None,
        );
        assert_eq!(clean.total(), 0);
    }

    #[test]
    fn a_mask_of_the_wrong_shape_is_refused() {
        let m = ndarray::ArrayD::<f64>::zeros(ndarray::IxDyn(&[3, 4]));
        assert!(mask_from(&m, (4, 3)).unwrap_err().contains("[3, 4]"));
        assert_eq!(
            mask_from(&m, (3, 4))
                .unwrap()
                .iter()
                .filter(|&&u| u)
                .count(),
            12
        );
    }
}
