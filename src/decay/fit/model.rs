//! The decay model a fit adjusts: `K` exponential components and a
//! constant background, reconvolved with the instrument response (or, for
//! a tail fit, without it), with every derivative the optimiser needs.
//!
//! Time is counted in bins of the fitted window. Component `k` holds
//! `N_k` photons of lifetime `tau_k`; a photon of the IRF sample in bin `m`
//! leaves anywhere in that bin, uniformly, so its exponential puts the
//! fraction `1 - a (1 - r)` (`a = tau / w`, `w` the bin width, `r =
//! exp(-w / tau)`) into bin `m` and `a (1 - r)^2 r^(j-1)` into bin `m + j`:
//! the exact integrals over the bins, summing to 1 (a photon placed at the
//! bin's centre instead biased a 400 ps lifetime 1 % low in 49 ps bins). With the laser period
//! known, the light of earlier pulses still decaying (the incomplete
//! decay, as SPCImage models it) is added: the tail past the window,
//! carried over whole periods. A tail fit has no IRF: its first bin is
//! the decay's time zero and `N_k` counts the photons from there on.
//!
//! The IRF is a measured decay (normalised, shifted by a fitted fraction of
//! bins with linear interpolation), or a Gaussian of fitted centre and
//! width integrated over the bins.

/// The instrument response a model convolves with.
#[derive(Debug, Clone, PartialEq)]
pub enum IrfShape {
    /// None: a tail fit from the window's first bin.
    Tail,
    /// A measured response, one value per bin of the window (normalised
    /// to sum 1 when the model is made); its shift is fitted.
    Measured(Vec<f64>),
    /// A Gaussian whose centre and standard deviation (bins) are fitted.
    Gaussian,
}

/// How an exponential after an IRF sample is put into bins.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Kernel {
    /// The exact integral over each bin of a photon leaving anywhere in
    /// its IRF bin (what a TCSPC histogram holds).
    #[default]
    Integrated,
    /// The exponential sampled at the bins' starts from the IRF sample's
    /// (flimlib's discrete convolution): about half a bin later.
    Sampled,
}

/// The fixed part of a model: the window's bins, the components, the IRF
/// and the laser period.
#[derive(Debug, Clone)]
pub struct DecayModel {
    /// Bins in the fitted window.
    pub bins: usize,
    /// Bin width, ps.
    pub width_ps: f64,
    /// Exponential components, 1 to 3.
    pub components: usize,
    /// The IRF.
    pub irf: IrfShape,
    /// The laser period in bins, when the incomplete decay is modelled.
    pub period_bins: Option<f64>,
    /// How the IRF's exponentials are binned.
    pub kernel: Kernel,
}

/// Where each parameter sits in a parameter vector: `N_1, tau_1, ...,
/// N_K, tau_K, background`, then the IRF's (its shift for a measured IRF;
/// its centre and width for a Gaussian). Lifetimes are in ps, the IRF's in
/// bins, photons per component, background per bin.
impl DecayModel {
    /// Parameters in all.
    pub fn parameters(&self) -> usize {
        2 * self.components + 1 + self.irf_parameters()
    }

    /// The IRF's parameters.
    pub fn irf_parameters(&self) -> usize {
        match self.irf {
            IrfShape::Tail => 0,
            IrfShape::Measured(_) => 1,
            IrfShape::Gaussian => 2,
        }
    }

    /// Index of the background.
    pub fn background(&self) -> usize {
        2 * self.components
    }

    /// The IRF on the window's bins at parameters `p` (the model's layout);
    /// empty for a tail fit.
    pub fn irf(&self, p: &[f64]) -> Vec<f64> {
        self.irf_on_bins(&p[self.background() + 1..]).0
    }

    /// The IRF on the window's bins for the IRF's parameters `p`, and its
    /// derivative by each of them.
    fn irf_on_bins(&self, p: &[f64]) -> (Vec<f64>, Vec<Vec<f64>>) {
        let n = self.bins;
        match &self.irf {
            IrfShape::Tail => (Vec::new(), Vec::new()),
            IrfShape::Measured(values) => {
                // Shifted by `s` bins: value at `i - s`, linearly
                // interpolated (zero outside the window).
                let s = p[0];
                let at = |k: isize| -> f64 {
                    if k < 0 || k as usize >= values.len() {
                        0.0
                    } else {
                        values[k as usize]
                    }
                };
                let mut v = vec![0.0; n];
                let mut dv = vec![0.0; n];
                for i in 0..n {
                    let x = i as f64 - s;
                    let k = x.floor();
                    let f = x - k;
                    let (a, b) = (at(k as isize), at(k as isize + 1));
                    v[i] = a + f * (b - a);
                    dv[i] = -(b - a);
                }
                (v, vec![dv])
            }
            IrfShape::Gaussian => {
                let (c, sd) = (p[0], p[1].max(1e-3));
                let mut v = vec![0.0; n];
                let mut dc = vec![0.0; n];
                let mut ds = vec![0.0; n];
                for i in 0..n {
                    // Mass of bin i: [i - 1/2, i + 1/2) in bin units.
                    let (za, zb) = ((i as f64 - 0.5 - c) / sd, (i as f64 + 0.5 - c) / sd);
                    let (pa, pb) = (normal_pdf(za), normal_pdf(zb));
                    v[i] = normal_cdf(zb) - normal_cdf(za);
                    dc[i] = -(pb - pa) / sd;
                    ds[i] = -(pb * zb - pa * za) / sd;
                }
                (v, vec![dc, ds])
            }
        }
    }

    /// The model `mu` on the window's bins for parameters `p`, and, when
    /// `jacobian` is given (bins x parameters, row-major), its derivatives.
    pub fn evaluate(&self, p: &[f64], mu: &mut [f64], jacobian: Option<&mut [f64]>) {
        let n = self.bins;
        let np = self.parameters();
        let bg = self.background();
        let k_irf = bg + 1;
        let (irf, dirf) = self.irf_on_bins(&p[k_irf..]);
        mu.iter_mut().for_each(|m| *m = p[bg]);
        let mut jac = jacobian;
        if let Some(j) = jac.as_deref_mut() {
            j.iter_mut().for_each(|v| *v = 0.0);
            for i in 0..n {
                j[i * np + bg] = 1.0;
            }
        }
        let mut e = vec![0.0; n];
        let mut de = vec![0.0; n];
        let mut di: Vec<Vec<f64>> = vec![vec![0.0; n]; dirf.len()];
        for c in 0..self.components {
            let (photons, tau) = (p[2 * c], p[2 * c + 1]);
            let tau_bins = tau / self.width_ps;
            match self.irf {
                IrfShape::Tail => self.tail_kernel(tau_bins, &mut e, &mut de),
                _ => {
                    self.convolved(tau_bins, &irf, &mut e, &mut de);
                    for (d, dirf) in di.iter_mut().zip(&dirf) {
                        let mut unused = vec![0.0; n];
                        self.convolved(tau_bins, dirf, d, &mut unused);
                    }
                }
            }
            for i in 0..n {
                mu[i] += photons * e[i];
            }
            if let Some(j) = jac.as_deref_mut() {
                for i in 0..n {
                    let row = &mut j[i * np..(i + 1) * np];
                    row[2 * c] = e[i];
                    // d/dtau (ps) = d/dtau_bins / width.
                    row[2 * c + 1] = photons * de[i] / self.width_ps;
                    for (q, d) in di.iter().enumerate() {
                        row[k_irf + q] += photons * d[i];
                    }
                }
            }
        }
    }

    /// The tail kernel: bin `j` of the window holds `(1 - r) r^j` of a
    /// component's photons, `r = exp(-1 / tau)` (tau in bins); with the
    /// period, the light of earlier pulses too. `de`: its derivative by
    /// tau (bins).
    fn tail_kernel(&self, tau: f64, e: &mut [f64], de: &mut [f64]) {
        let r = (-1.0 / tau).exp();
        let dr = r / (tau * tau);
        let (wrap, dwrap) = self.wrap_factor(r, dr);
        for j in 0..self.bins {
            let rj = r.powi(j as i32);
            let drj = if j == 0 {
                0.0
            } else {
                j as f64 * r.powi(j as i32 - 1) * dr
            };
            // (1 - r) r^j (1 + wrap): wrap is the earlier pulses' share.
            let base = (1.0 - r) * rj;
            let dbase = -dr * rj + (1.0 - r) * drj;
            e[j] = base * (1.0 + wrap);
            de[j] = dbase * (1.0 + wrap) + base * dwrap;
        }
    }

    /// The share `q = r^P / (1 - r^P)` of earlier pulses (`P` the period
    /// in bins) beside a pulse's own decay at the same time after it, with
    /// its derivative; 0 without a period.
    fn wrap_factor(&self, r: f64, dr: f64) -> (f64, f64) {
        let Some(period) = self.period_bins else {
            return (0.0, 0.0);
        };
        // Relative to a pulse's own decay at the same phase: earlier
        // pulses add r^P + r^2P + ... = r^P / (1 - r^P).
        let rp = r.powf(period);
        if rp >= 1.0 {
            return (0.0, 0.0);
        }
        let drp = period * r.powf(period - 1.0) * dr;
        let q = rp / (1.0 - rp);
        let dq = drp / ((1.0 - rp) * (1.0 - rp));
        (q, dq)
    }

    /// The IRF `irf` convolved with the exponential of lifetime `tau`
    /// (bins) as the module says, with earlier pulses when the period is
    /// known; `de` its derivative by tau.
    fn convolved(&self, tau: f64, irf: &[f64], e: &mut [f64], de: &mut [f64]) {
        let n = self.bins;
        let r = (-1.0 / tau).exp();
        let dr = r / (tau * tau);
        let ((e0, de0), (c1, dc1)) = match self.kernel {
            // A photon leaves anywhere in its IRF bin, uniformly: it stays
            // in that bin with probability e0 = 1 - tau (1 - r), and
            // reaches bin m + j (j >= 1) with c1 r^(j-1), c1 = tau (1 -
            // r)^2.
            Kernel::Integrated => (
                (1.0 - tau * (1.0 - r), -(1.0 - r) + tau * dr),
                (
                    tau * (1.0 - r) * (1.0 - r),
                    (1.0 - r) * (1.0 - r) - 2.0 * tau * (1.0 - r) * dr,
                ),
            ),
            // Sampled at the bins' starts, normalised: (1 - r) r^j.
            Kernel::Sampled => ((1.0 - r, -dr), (r * (1.0 - r), dr * (1.0 - 2.0 * r))),
        };
        // G[i] = sum_{m < i} irf[m] c1 r^(i-1-m): the recursion
        // G[i] = r G[i-1] + c1 irf[i-1].
        let (mut g, mut dg) = (0.0, 0.0);
        for i in 0..n {
            if i > 0 {
                dg = dr * g + r * dg + dc1 * irf[i - 1];
                g = r * g + c1 * irf[i - 1];
            }
            e[i] = irf[i] * e0 + g;
            de[i] = irf[i] * de0 + dg;
        }
        if let Some(period) = self.period_bins {
            // The tail at the window's end (G continued to bin n), carried
            // to the next pulse's bin 0 (period bins after this one's)
            // and through every earlier period: at bin i it adds
            // G[n] r^(P - n) r^i / (1 - r^P).
            let gn = r * g + c1 * irf[n - 1];
            let dgn = dr * g + r * dg + dc1 * irf[n - 1];
            let gap = (period - n as f64).max(0.0);
            let rp = r.powf(period);
            if rp < 1.0 {
                let rg = r.powf(gap);
                let drg = if gap > 0.0 {
                    gap * r.powf(gap - 1.0) * dr
                } else {
                    0.0
                };
                let drp = period * r.powf(period - 1.0) * dr;
                let q = rg / (1.0 - rp);
                let dq = drg / (1.0 - rp) + rg * drp / ((1.0 - rp) * (1.0 - rp));
                let (mut ri, mut dri) = (1.0, 0.0);
                for i in 0..n {
                    e[i] += gn * q * ri;
                    de[i] += dgn * q * ri + gn * dq * ri + gn * q * dri;
                    dri = dri * r + ri * dr;
                    ri *= r;
                }
            }
        }
    }
}

/// The standard normal density.
fn normal_pdf(z: f64) -> f64 {
    (-0.5 * z * z).exp() / (2.0 * std::f64::consts::PI).sqrt()
}

/// The standard normal distribution function.
fn normal_cdf(z: f64) -> f64 {
    0.5 * libm::erfc(-z / std::f64::consts::SQRT_2)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model(irf: IrfShape, period: Option<f64>) -> DecayModel {
        DecayModel {
            bins: 64,
            width_ps: 50.0,
            components: 2,
            irf,
            period_bins: period,
            kernel: Kernel::Integrated,
        }
    }

    fn gaussian_irf(n: usize, c: f64, sd: f64) -> Vec<f64> {
        (0..n)
            .map(|i| (-0.5 * ((i as f64 - c) / sd).powi(2)).exp())
            .collect()
    }

    /// Every analytic derivative equals the central difference.
    #[test]
    fn the_jacobian_is_the_models_derivative() {
        for (irf, p) in [
            (IrfShape::Tail, vec![1000.0, 300.0, 500.0, 1800.0, 2.0]),
            (
                IrfShape::Measured(gaussian_irf(64, 8.0, 2.0)),
                vec![1000.0, 300.0, 500.0, 1800.0, 2.0, 0.3],
            ),
            (
                IrfShape::Gaussian,
                vec![1000.0, 300.0, 500.0, 1800.0, 2.0, 9.2, 1.7],
            ),
        ] {
            for (period, kernel) in [
                (None, Kernel::Integrated),
                (Some(80.0), Kernel::Integrated),
                (Some(80.0), Kernel::Sampled),
            ] {
                let m = DecayModel {
                    kernel,
                    ..model(irf.clone(), period)
                };
                let np = m.parameters();
                let mut mu = vec![0.0; 64];
                let mut jac = vec![0.0; 64 * np];
                m.evaluate(&p, &mut mu, Some(&mut jac));
                for q in 0..np {
                    let h = 1e-5 * p[q].abs().max(1.0);
                    let (mut up, mut down) = (p.clone(), p.clone());
                    up[q] += h;
                    down[q] -= h;
                    let (mut mu_up, mut mu_down) = (vec![0.0; 64], vec![0.0; 64]);
                    m.evaluate(&up, &mut mu_up, None);
                    m.evaluate(&down, &mut mu_down, None);
                    for i in 0..64 {
                        let numeric = (mu_up[i] - mu_down[i]) / (2.0 * h);
                        let analytic = jac[i * np + q];
                        // The measured IRF's interpolation has kinks at
                        // whole bins; 0.3 is inside one.
                        assert!(
                            (numeric - analytic).abs() <= 1e-5 * (1.0 + numeric.abs()),
                            "{irf:?} period {period:?} parameter {q} bin {i}: {numeric} vs {analytic}"
                        );
                    }
                }
            }
        }
    }

    /// Photons are conserved: a component's kernel sums to 1 over every
    /// bin it reaches (a long window, no period), and the periodic model
    /// holds all of each period's light (the window spans the period).
    #[test]
    fn each_component_carries_its_photons() {
        let irf = gaussian_irf(400, 10.0, 2.0);
        let long = DecayModel {
            bins: 400,
            width_ps: 50.0,
            components: 1,
            irf: IrfShape::Measured(irf.iter().map(|v| v / irf.iter().sum::<f64>()).collect()),
            period_bins: None,
            kernel: Kernel::Integrated,
        };
        let mut mu = vec![0.0; 400];
        long.evaluate(&[1000.0, 1000.0, 0.0, 0.0], &mut mu, None);
        // exp(-390 / 20) of the light lies past the window: 3.4e-6.
        assert!(
            (mu.iter().sum::<f64>() - 1000.0 * (1.0 - (-19.5f64).exp())).abs() < 1e-6,
            "{}",
            mu.iter().sum::<f64>()
        );
        // 64 bins spanning the period, lifetime 3x the window: the
        // periodic model keeps every photon.
        let short = DecayModel {
            bins: 64,
            width_ps: 50.0,
            components: 1,
            irf: IrfShape::Measured({
                let g = gaussian_irf(64, 10.0, 2.0);
                let s: f64 = g.iter().sum();
                g.iter().map(|v| v / s).collect()
            }),
            period_bins: Some(64.0),
            kernel: Kernel::Integrated,
        };
        let mut mu = vec![0.0; 64];
        short.evaluate(&[1000.0, 9600.0, 0.0, 0.0], &mut mu, None);
        assert!(
            (mu.iter().sum::<f64>() - 1000.0).abs() < 1e-6,
            "{}",
            mu.iter().sum::<f64>()
        );
        let tail = DecayModel {
            irf: IrfShape::Tail,
            ..short
        };
        tail.evaluate(&[1000.0, 9600.0, 0.0], &mut mu, None);
        assert!(
            (mu.iter().sum::<f64>() - 1000.0).abs() < 1e-6,
            "{}",
            mu.iter().sum::<f64>()
        );
    }
}
