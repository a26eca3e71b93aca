//! Binomial thinning: photon counts split into two halves that are
//! independent Poisson images of half the light each (each photon lands in
//! either half with probability 1/2). One half scores an estimate made from
//! the other, which is cross-validation without a truth.
//!
//! Two draws, each fixed by the outputs it made: the images of the 2-D
//! methods ([`thin_halves`], checked, one draw per element, empty ones
//! included) and the volumes of the confocal scans ([`keep_photons`],
//! [`halves`], empty elements draw nothing). A seed gives the same halves
//! release after release, so neither changes its sequence.

use ndarray::{Array2, Array3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Binomial, Distribution};

use super::counts::MAX_COUNT;

/// Seed of the 2-D methods' thinning, so that a reconstruction is
/// reproducible.
pub const THINNING_SEED: u64 = 0x7417_2026;

/// Why counts cannot be thinned.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CountError {
    /// A whole count larger than any measurement gives (2^53 and more,
    /// where counts are no longer exact even in 64-bit floats).
    #[error(
        "row {row}, column {col} of {what} is {value:e} photons, more than any measurement counts (whole counts stop being exact at 2^53): check the stack's values"
    )]
    ImplausibleCount {
        /// The image (e.g. "the time-summed counts").
        what: String,
        /// Row.
        row: usize,
        /// Column.
        col: usize,
        /// The offending value.
        value: f64,
    },
    /// A count that is not a whole number of photons.
    #[error(
        "cross-validation by thinning needs whole photon counts: row {row}, column {col} of {what} is {value} (expected counts, or a scaled or background-subtracted stack: stop Richardson-Lucy after a fixed count instead)"
    )]
    NotWholeCounts {
        /// The image (e.g. "the time-summed counts").
        what: String,
        /// Row.
        row: usize,
        /// Column.
        col: usize,
        /// The offending value.
        value: f64,
    },
}

/// Splits `counts` (whole photon counts) into two halves whose sum is
/// `counts`, each photon going to the first half with probability 1/2.
/// A count that is not a whole number (a stack that was scaled or had its
/// background subtracted) is refused by position and value; `what` names
/// the image in that message (e.g. "the time-summed counts").
pub fn thin_halves(
    counts: &Array2<f64>,
    seed: u64,
    what: &str,
) -> Result<(Array2<f64>, Array2<f64>), CountError> {
    if let Some(((row, col), &value)) = counts
        .indexed_iter()
        .find(|(_, v)| !(v.is_finite() && **v >= 0.0 && v.fract() == 0.0 && **v < MAX_COUNT))
    {
        let (what, row, col) = (what.into(), row, col);
        return Err(
            if value.is_finite() && value.fract() == 0.0 && value > 0.0 {
                CountError::ImplausibleCount {
                    what,
                    row,
                    col,
                    value,
                }
            } else {
                CountError::NotWholeCounts {
                    what,
                    row,
                    col,
                    value,
                }
            },
        );
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let first = counts.mapv(|m| {
        Binomial::new(m as u64, 0.5)
            .expect("p = 1/2 is a valid probability")
            .sample(&mut rng) as f64
    });
    let second = counts - &first;
    Ok((first, second))
}

/// Each photon of `counts` (whole numbers, `fraction` in (0, 1]) kept with
/// probability `fraction`, seeded; empty elements draw nothing.
pub fn keep_photons(counts: &Array3<f64>, fraction: f64, seed: u64) -> Array3<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    counts.mapv(|v| {
        if v <= 0.0 {
            0.0
        } else {
            Binomial::new(v as u64, fraction)
                .expect("fraction lies in (0, 1]")
                .sample(&mut rng) as f64
        }
    })
}

/// Splits whole counts into two halves, each photon to the first with
/// probability 1/2, seeded ([`keep_photons`] at one half).
pub fn halves(counts: &Array3<f64>, seed: u64) -> (Array3<f64>, Array3<f64>) {
    let first = keep_photons(counts, 0.5, seed);
    let second = counts - &first;
    (first, second)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn halves_sum_to_the_counts_and_share_them_evenly() {
        let counts = Array2::from_shape_fn((64, 64), |(r, c)| ((r * 7 + c * 3) % 50) as f64);
        let (a, b) = thin_halves(&counts, 1, "test").unwrap();
        assert_eq!(&a + &b, counts);
        assert!(
            a.iter()
                .chain(b.iter())
                .all(|&x| x >= 0.0 && x.fract() == 0.0)
        );
        // Binomial(N, 1/2): the first half holds N/2 +- sqrt(N)/2.
        let total = counts.sum();
        let z = (a.sum() - total / 2.0) / (total.sqrt() / 2.0);
        assert!(z.abs() < 5.0, "first half {} of {total}: z = {z}", a.sum());
        // The same seed gives the same split, another seed another.
        assert_eq!(thin_halves(&counts, 1, "test").unwrap().0, a);
        assert_ne!(thin_halves(&counts, 2, "test").unwrap().0, a);
    }

    #[test]
    fn fractional_negative_and_nan_counts_are_refused_by_position() {
        for bad in [2.5, -1.0, f64::NAN] {
            let mut counts = Array2::from_elem((3, 4), 2.0);
            counts[(1, 2)] = bad;
            let err = thin_halves(&counts, 0, "test").unwrap_err().to_string();
            assert!(
                err.contains("row 1, column 2") && err.contains(&format!("{bad}")),
                "{err}"
            );
        }
    }
}
