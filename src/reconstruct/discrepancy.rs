//! The Poisson discrepancy principle: a stopping rule that needs no truth.
//!
//! An estimate that explains the counts as well as Poisson noise allows has a
//! deviance `D = 2 sum [m log(m/y) - (m - y)]` close to the deviance that pure
//! Poisson noise produces around the same means `y`,
//! `E[D] = sum f(y)` with `f(mu) = 2 (E[m log m] - mu log mu)` for
//! `m ~ Poisson(mu)`. For large means `f -> 1`; for the low means of early
//! bins it is much smaller, which is why the classical "D = number of data"
//! rule fails on photon-starved data and we use the exact `f`.

use ndarray::parallel::prelude::*;
use ndarray::{Array3, ArrayView2, Axis};

use crate::forward::ForwardModel;

/// Lookup of the expected deviance per data point, `f(mu)`.
pub struct ExpectedDeviance {
    log_lo: f64,
    step: f64,
    table: Vec<f64>,
}

const TABLE_LO: f64 = 1e-8;
const TABLE_HI: f64 = 400.0;
const TABLE_N: usize = 4000;

impl ExpectedDeviance {
    /// The table, built once per process (about 4000 Poisson sums) and
    /// shared by every reconstruction.
    pub fn shared() -> &'static Self {
        static TABLE: std::sync::LazyLock<ExpectedDeviance> =
            std::sync::LazyLock::new(ExpectedDeviance::build);
        &TABLE
    }

    fn build() -> Self {
        let (log_lo, log_hi) = (TABLE_LO.ln(), TABLE_HI.ln());
        let step = (log_hi - log_lo) / (TABLE_N - 1) as f64;
        let table = (0..TABLE_N)
            .map(|i| exact(((log_lo + i as f64 * step).exp()).min(TABLE_HI)))
            .collect();
        Self {
            log_lo,
            step,
            table,
        }
    }
}

/// `f(mu)` by direct summation over the Poisson probabilities.
fn exact(mu: f64) -> f64 {
    let spread = 15.0 * mu.sqrt() + 15.0;
    let hi = (mu + spread).ceil() as u64;
    let lo = (mu - spread).floor().max(1.0) as u64;
    let e_mlogm: f64 = (lo..=hi)
        .map(|m| {
            let mf = m as f64;
            let log_p = mf * mu.ln() - mu - libm::lgamma(mf + 1.0);
            log_p.exp() * mf * mf.ln()
        })
        .sum();
    (2.0 * (e_mlogm - mu * mu.ln())).max(0.0)
}

impl ExpectedDeviance {
    /// `f(mu)`, interpolated (relative error below 1e-5 on the table range).
    pub fn per_point(&self, mu: f64) -> f64 {
        if mu.is_nan() || mu <= 0.0 {
            0.0
        } else if mu < TABLE_LO {
            // f(mu) ~ -2 mu log mu + O(mu^2) as mu -> 0.
            -2.0 * mu * mu.ln()
        } else if mu >= TABLE_HI {
            1.0 + 1.0 / (6.0 * mu)
        } else {
            let x = (mu.ln() - self.log_lo) / self.step;
            let i = (x.floor() as usize).min(TABLE_N - 2);
            let t = x - i as f64;
            self.table[i] * (1.0 - t) + self.table[i + 1] * t
        }
    }

    /// Deviance of `estimate` against `counts` (bins `bins` of `model`) and
    /// the deviance Poisson noise alone would give: `(D, E[D])`.
    pub fn check(
        &self,
        model: &ForwardModel,
        counts: &Array3<f64>,
        bins: &[usize],
        estimate: ArrayView2<f64>,
    ) -> (f64, f64) {
        let x: Vec<f64> = estimate.iter().copied().collect();
        let spec = model.fft().forward(&x);
        counts
            .axis_iter(Axis(0))
            .into_par_iter()
            .zip(bins.par_iter())
            .map(|(m, &k)| {
                let prod = spec
                    .iter()
                    .zip(model.spectrum(k))
                    .map(|(a, b)| a * b)
                    .collect();
                let y = model.fft().inverse(prod);
                let mut d = 0.0;
                let mut e = 0.0;
                for (&mj, &yj) in m.iter().zip(&y) {
                    let yj = yj.max(1e-300);
                    d += if mj > 0.0 { mj * (mj / yj).ln() } else { 0.0 } - (mj - yj);
                    e += self.per_point(yj);
                }
                (2.0 * d, e)
            })
            .reduce(|| (0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn expected_deviance_limits_and_monte_carlo() {
        let f = ExpectedDeviance::shared();
        assert!((f.per_point(1000.0) - 1.0).abs() < 1e-3);
        assert!((f.per_point(100.0) - exact(100.0)).abs() < 1e-5);
        assert!(f.per_point(0.01) < 0.2 && f.per_point(0.0) == 0.0);
        // Monte Carlo check at mu = 0.7 with a simple inversion sampler.
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mu: f64 = 0.7;
        let n = 200_000;
        let mut acc = 0.0;
        for _ in 0..n {
            let (mut m, mut p, u) = (0u32, (-mu).exp(), rng.random::<f64>());
            let mut cdf = p;
            while u > cdf {
                m += 1;
                p *= mu / m as f64;
                cdf += p;
            }
            let mf = m as f64;
            acc += 2.0 * (if m > 0 { mf * (mf / mu).ln() } else { 0.0 } - (mf - mu));
        }
        let mc = acc / n as f64;
        assert!(
            (mc - f.per_point(mu)).abs() < 0.01,
            "{mc} vs {}",
            f.per_point(mu)
        );
    }
}
