//! The Poisson deviance `D = 2 sum [m log(m/y) - (m - y)]` of counts `m`
//! under means `y`: how far an estimate's prediction is from counts, in the
//! units of Poisson noise (each point adds about 1 at large means).

use ndarray::{Array3, Zip, s};

/// One point's deviance for count `m` and mean `y > 0`, with `m log m`
/// ([`m_log_m`]) and `log y` given (a solver computes them once).
#[inline]
pub fn point_deviance(m: f64, m_log_m: f64, y: f64, log_y: f64) -> f64 {
    2.0 * (m_log_m - m * log_y - (m - y))
}

/// `m log m`, 0 for `m = 0`: the part of a point's deviance that depends on
/// the count alone.
#[inline]
pub fn m_log_m(m: f64) -> f64 {
    if m > 0.0 { m * m.ln() } else { 0.0 }
}

/// Two predictions `a` and `b` (plus `bg`, guarded below by `guard`) of
/// the same `counts`: their Poisson deviances and the sum of `n (ln a -
/// ln b)^2`, the variance of their log-likelihood difference under
/// Poisson noise (twice its root is the noise sd of the deviances'
/// difference). What a paired check of two estimates on held-back counts
/// sums.
pub fn paired_deviances(counts: &[f64], a: &[f64], b: &[f64], bg: f64, guard: f64) -> [f64; 3] {
    let mut sums = [0.0; 3];
    for ((&n, &ya), &yb) in counts.iter().zip(a).zip(b) {
        let (ma, mb) = ((ya + bg).max(guard), (yb + bg).max(guard));
        let (la, lb) = (ma.ln(), mb.ln());
        let nl = m_log_m(n);
        sums[0] += point_deviance(n, nl, ma, la);
        sums[1] += point_deviance(n, nl, mb, lb);
        sums[2] += n * (la - lb) * (la - lb);
    }
    sums
}

/// The deviance of a volume of `counts` (bins first) under `means` over
/// the bins from `onset`, each point as `m log(m/y)` in one logarithm;
/// means below 1e-300 count as 1e-300.
pub fn volume_deviance(counts: &Array3<f64>, means: &Array3<f64>, onset: usize) -> f64 {
    let mut total = 0.0;
    Zip::from(counts.slice(s![onset.., .., ..]))
        .and(means.slice(s![onset.., .., ..]))
        .for_each(|&m, &y| {
            let y = y.max(1e-300);
            total += 2.0 * (if m > 0.0 { m * (m / y).ln() } else { 0.0 } - (m - y));
        });
    total
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_forms_agree_with_the_definition() {
        for (m, y) in [(0.0f64, 0.3f64), (1.0, 0.3), (7.0, 7.0), (12.0, 3.5)] {
            let by_definition = 2.0 * (if m > 0.0 { m * (m / y).ln() } else { 0.0 } - (m - y));
            let point = point_deviance(m, m_log_m(m), y, f64::ln(y));
            assert!((point - by_definition).abs() < 1e-12, "{m} {y}");
            let counts = Array3::from_elem((2, 1, 1), m);
            let means = Array3::from_elem((2, 1, 1), y);
            // The bin before the onset is left out.
            let volume = volume_deviance(&counts, &means, 1);
            assert!((volume - by_definition).abs() < 1e-12, "{m} {y}");
        }
        // A perfect prediction has deviance 0; any other more.
        assert_eq!(point_deviance(5.0, m_log_m(5.0), 5.0, f64::ln(5.0)), 0.0);
        assert!(point_deviance(5.0, m_log_m(5.0), 4.0, f64::ln(4.0)) > 0.0);
    }
}
