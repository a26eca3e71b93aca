//! What photon counts can be, for every reader of counts (stacks, confocal
//! scans, calibration histograms): finite, non-negative, no larger than
//! any measurement gives, and together at least one photon.

/// The largest count a measurement can hold: 2^53, where whole numbers
/// stop being exact in 64-bit floats. A detector counting a billion
/// photons a second takes over a hundred days to reach it in one element.
pub const MAX_COUNT: f64 = 9_007_199_254_740_992.0;

/// Why values are not photon counts. `at` names the element in the
/// reader's words ("bin 3, row 2, column 7").
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CountsError {
    /// Not a finite non-negative number.
    #[error("{at} holds {value}: counts must be finite and non-negative")]
    Invalid {
        /// Where.
        at: String,
        /// The value.
        value: f64,
    },
    /// More than any measurement counts.
    #[error(
        "{at} holds {value:e}, more than any measurement counts (2^53, where whole counts stop being exact): not photon counts"
    )]
    TooLarge {
        /// Where.
        at: String,
        /// The value.
        value: f64,
    },
    /// Less than one photon in all.
    #[error("{}", no_light(*elements, *total))]
    NoLight {
        /// Values read.
        elements: usize,
        /// Their sum.
        total: f64,
    },
}

fn no_light(elements: usize, total: f64) -> String {
    if total == 0.0 {
        format!("all {elements} values are 0: no photon was recorded, so there is nothing to use")
    } else {
        format!(
            "the {elements} values add up to {total:e}, less than one photon: no light was recorded, so there is nothing to use"
        )
    }
}

/// Checks one value as a photon count (finite, non-negative, at most
/// [`MAX_COUNT`]); `at` names its place when it is not.
pub fn check_count(v: f64, at: impl FnOnce() -> String) -> Result<(), CountsError> {
    if !(v.is_finite() && v >= 0.0) {
        return Err(CountsError::Invalid { at: at(), value: v });
    }
    if v > MAX_COUNT {
        return Err(CountsError::TooLarge { at: at(), value: v });
    }
    Ok(())
}

/// Checks `values` as photon counts and returns their sum: the first
/// value that is not finite and non-negative, or above [`MAX_COUNT`], is
/// refused by its place (`at` names the index in the reader's words), and
/// so are values that add up to less than one photon.
pub fn check_counts(
    values: impl IntoIterator<Item = f64>,
    at: impl Fn(usize) -> String,
) -> Result<f64, CountsError> {
    let (mut total, mut elements) = (0.0, 0);
    for (i, v) in values.into_iter().enumerate() {
        check_count(v, || at(i))?;
        total += v;
        elements += 1;
    }
    check_light(total, elements)
}

/// `total`, the sum of `elements` counts already checked one by one, when
/// it is at least one photon; else [`CountsError::NoLight`].
pub fn check_light(total: f64, elements: usize) -> Result<f64, CountsError> {
    if total < 1.0 {
        return Err(CountsError::NoLight { elements, total });
    }
    Ok(total)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(i: usize) -> String {
        format!("element {i}")
    }

    #[test]
    fn counts_are_refused_by_place_and_value() {
        assert_eq!(check_counts([0.0, 2.0, 3.0], at), Ok(5.0));
        let e = check_counts([1.0, f64::NAN], at).unwrap_err();
        assert!(e.to_string().starts_with("element 1 holds NaN"), "{e}");
        let e = check_counts([1.0, -1.0], at).unwrap_err();
        assert!(matches!(e, CountsError::Invalid { .. }), "{e}");
        for big in [3.4e38, 1e30, 2f64.powi(63), MAX_COUNT * 2.0] {
            let e = check_counts([1.0, 1.0, big], at).unwrap_err();
            assert!(e.to_string().contains("element 2 holds"), "{e}");
            assert!(matches!(e, CountsError::TooLarge { .. }), "{e}");
        }
        assert_eq!(check_counts([MAX_COUNT], at), Ok(MAX_COUNT));
    }

    #[test]
    fn less_than_one_photon_in_all_is_no_light() {
        let e = check_counts([0.0; 6], at).unwrap_err().to_string();
        assert!(e.contains("all 6 values are 0"), "{e}");
        let e = check_counts([1e-45; 6], at).unwrap_err().to_string();
        assert!(e.contains("less than one photon"), "{e}");
        assert!(check_counts([0.5, 0.5], at).is_ok());
    }
}
