//! Time-resolved transmittance of a finite slab in the diffusion
//! approximation, with extrapolated boundaries (Patterson, Chance and
//! Wilson, Appl. Opt. 28, 2331 (1989); Contini, Martelli and Zaccanti, Appl.
//! Opt. 36, 4587 (1997)).
//!
//! The object's light enters at one face and is modelled as an isotropic
//! point source one transport mean free path `z_s = 1 / (mu_a + mu_s')`
//! deep (equal to the usual `1 / mu_s'` where diffusion holds,
//! `mu_a << mu_s'`). The fluence vanishes on extrapolated boundaries a
//! distance `z_e = 2 A D` outside each face, where `A` follows from the
//! effective reflection of the refractive-index mismatch to air. The flux
//! through the far face, integrated over that face (`L = s + 2 z_e`):
//!
//! ```text
//! T(t) = exp(-mu_a c t) / (2 sqrt(4 pi D c) t^(3/2))
//!        sum_m [ z1_m exp(-z1_m^2 / (4 D c t)) - z2_m exp(-z2_m^2 / (4 D c t)) ]
//! z1_m = s - z_s - 2 m L,   z2_m = s + 2 z_e + z_s - 2 m L
//! ```
//!
//! The image sum converges fast at early times; at late times the same
//! function is the eigenfunction (sine) series
//!
//! ```text
//! T(t) = (2 pi D c / L^2) exp(-mu_a c t)
//!        sum_n n (-1)^(n+1) sin(n pi (z_s + z_e) / L) cos(n pi z_e / L) exp(-D c n^2 pi^2 t / L^2)
//! ```
//!
//! (the two are Poisson-summation duals). [`SlabTransmittance`] uses the
//! image sum for `D c t / L^2 < 0.3` and the sine series beyond, each summed
//! until the next terms change the sum by less than `SERIES_TOL`; the laterally
//! resolved transmittance is `T(t)` times the same lateral Gaussian as the
//! infinite medium's.

use std::f64::consts::PI;

/// Relative size below which further series terms are left out.
pub const SERIES_TOL: f64 = 1e-16;

/// At most this many terms (image pairs or sine modes) are summed; the
/// switch between the two series keeps the count near ten.
pub const MAX_TERMS: usize = 10_000;

/// `D c t / L^2` below which the image sum is used.
const IMAGE_SUM_LIMIT: f64 = 0.3;

/// Effective reflection coefficient `R_eff` of a diffusing medium of
/// relative refractive index `n` against air (Haskell et al., J. Opt. Soc.
/// Am. A 11, 2727 (1994)): `R_eff = (R_phi + R_j) / (2 - R_phi + R_j)`,
/// with the Fresnel reflectance integrated over the hemisphere,
/// `R_phi = int 2 sin cos R_F`, `R_j = int 3 sin cos^2 R_F`.
pub fn effective_reflection(n: f64) -> f64 {
    if n == 1.0 {
        return 0.0;
    }
    // Composite Simpson over the incidence angle. R_F has a kink at the
    // critical angle, so the two sides are integrated apart.
    let critical = if n > 1.0 { (1.0 / n).asin() } else { PI / 2.0 };
    let simpson = |a: f64, b: f64, f: &dyn Fn(f64) -> f64| {
        let panels = 2000;
        let h = (b - a) / panels as f64;
        let mut acc = f(a) + f(b);
        for i in 1..panels {
            acc += f(a + i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 };
        }
        acc * h / 3.0
    };
    let phi = |th: f64| 2.0 * th.sin() * th.cos() * fresnel_unpolarised(n, th);
    let j = |th: f64| 3.0 * th.sin() * th.cos().powi(2) * fresnel_unpolarised(n, th);
    let r_phi = simpson(0.0, critical, &phi) + simpson(critical, PI / 2.0, &phi);
    let r_j = simpson(0.0, critical, &j) + simpson(critical, PI / 2.0, &j);
    (r_phi + r_j) / (2.0 - r_phi + r_j)
}

/// Unpolarised Fresnel reflectance from inside a medium of index `n` into
/// air at incidence angle `theta` (1 beyond the critical angle).
pub fn fresnel_unpolarised(n: f64, theta: f64) -> f64 {
    fresnel_unpolarised_sin_cos(n, theta.sin(), theta.cos())
}

/// [`fresnel_unpolarised`] for `n` the ratio of the index the light comes
/// from to the one it meets, given the incidence angle's sine and cosine
/// (transport meets faces with a direction cosine, not an angle); 0 for
/// `n` 1.
pub fn fresnel_unpolarised_sin_cos(n: f64, sin_i: f64, cos_i: f64) -> f64 {
    if n == 1.0 {
        return 0.0;
    }
    let sin_t = n * sin_i;
    if sin_t >= 1.0 {
        return 1.0;
    }
    let (ci, ct) = (cos_i, (1.0 - sin_t * sin_t).sqrt());
    let rs = (n * ci - ct) / (n * ci + ct);
    let rp = (n * ct - ci) / (n * ct + ci);
    0.5 * (rs * rs + rp * rp)
}

/// The slab's image-source geometry for one medium.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SlabTransmittance {
    /// Slab thickness `s` (cm).
    pub thickness_cm: f64,
    /// Depth of the equivalent isotropic source `z_s` (cm).
    pub source_depth_cm: f64,
    /// Distance of each extrapolated boundary outside its face `z_e` (cm).
    pub extrapolation_cm: f64,
    /// `D c` (cm^2/ps).
    pub dc_cm2_per_ps: f64,
    /// `mu_a c` (1/ps).
    pub absorption_per_ps: f64,
}

impl SlabTransmittance {
    /// Distance between the two extrapolated boundaries, `L = s + 2 z_e`.
    pub fn extrapolated_thickness_cm(&self) -> f64 {
        self.thickness_cm + 2.0 * self.extrapolation_cm
    }

    /// Fraction of the source's photons that leave through the far face
    /// without absorption (`mu_a = 0`), the steady-state
    /// `(z_s + z_e) / (s + 2 z_e)`.
    pub fn transmitted_fraction_without_absorption(&self) -> f64 {
        (self.source_depth_cm + self.extrapolation_cm) / self.extrapolated_thickness_cm()
    }

    /// ln `T(t)` (1/ps), by whichever series converges faster at `t`;
    /// `-inf` for `t <= 0` and non-finite `t`.
    pub fn log_density(&self, t_ps: f64) -> f64 {
        if t_ps.is_nan() || t_ps <= 0.0 || t_ps.is_infinite() {
            return f64::NEG_INFINITY;
        }
        let l = self.extrapolated_thickness_cm();
        if self.dc_cm2_per_ps * t_ps / (l * l) < IMAGE_SUM_LIMIT {
            self.log_density_images(t_ps)
        } else {
            self.log_density_modes(t_ps)
        }
    }

    /// ln `T(t)` by the image sum, the largest exponential factored out so
    /// that early times (a nearly delta-like pulse) do not underflow.
    pub fn log_density_images(&self, t_ps: f64) -> f64 {
        if t_ps.is_nan() || t_ps <= 0.0 || t_ps.is_infinite() {
            return f64::NEG_INFINITY;
        }
        let (s, zs, ze) = (
            self.thickness_cm,
            self.source_depth_cm,
            self.extrapolation_cm,
        );
        let l = self.extrapolated_thickness_cm();
        let u = 1.0 / (4.0 * self.dc_cm2_per_ps * t_ps);
        let nearest = s - zs;
        let term = |z: f64| z * (-(z * z - nearest * nearest) * u).exp();
        let pair = |m: f64| term(s - zs - 2.0 * m * l) - term(s + 2.0 * ze + zs - 2.0 * m * l);
        // z e^(-z^2 u) grows up to |z| = 1/sqrt(2u): terms are only left
        // out beyond that.
        let rising = (0.5 / u).sqrt();
        let mut sum = pair(0.0);
        for m in 1..MAX_TERMS {
            let m = m as f64;
            let next = pair(m) + pair(-m);
            sum += next;
            let closest = 2.0 * m * l - s - 2.0 * ze - zs;
            if closest > rising && next.abs() <= SERIES_TOL * sum.abs() {
                break;
            }
        }
        if sum <= 0.0 {
            return f64::NEG_INFINITY;
        }
        sum.ln()
            - nearest * nearest * u
            - (2.0 * (4.0 * PI * self.dc_cm2_per_ps).sqrt()).ln()
            - 1.5 * t_ps.ln()
            - self.absorption_per_ps * t_ps
    }

    /// ln `T(t)` by the sine series, the first mode's decay factored out.
    pub fn log_density_modes(&self, t_ps: f64) -> f64 {
        if t_ps.is_nan() || t_ps <= 0.0 || t_ps.is_infinite() {
            return f64::NEG_INFINITY;
        }
        let l = self.extrapolated_thickness_cm();
        let k = PI / l;
        let rate = self.dc_cm2_per_ps * k * k * t_ps;
        let w0 = self.source_depth_cm + self.extrapolation_cm;
        let mut sum = 0.0;
        for n in 1..=MAX_TERMS {
            let nf = n as f64;
            let sign = if n % 2 == 1 { 1.0 } else { -1.0 };
            let next = sign
                * nf
                * (nf * k * w0).sin()
                * (nf * k * self.extrapolation_cm).cos()
                * (-(nf * nf - 1.0) * rate).exp();
            sum += next;
            if (nf * nf - 1.0) * rate > 40.0 && next.abs() <= SERIES_TOL * sum.abs() {
                break;
            }
        }
        if sum <= 0.0 {
            return f64::NEG_INFINITY;
        }
        sum.ln() + (2.0 * PI * self.dc_cm2_per_ps / (l * l)).ln()
            - rate
            - self.absorption_per_ps * t_ps
    }

    /// Time of maximal transmitted flux (ps), by golden-section search on
    /// `ln T` over `ln t` (T is unimodal).
    pub fn peak_time_ps(&self) -> f64 {
        // Leading-order guess: the nearest image alone gives
        // b t^2 + 3t/2 - a = 0.
        let nearest = self.thickness_cm - self.source_depth_cm;
        let a = nearest * nearest / (4.0 * self.dc_cm2_per_ps);
        let b = self.absorption_per_ps;
        let guess = 2.0 * a / (1.5 + (2.25 + 4.0 * a * b).sqrt());
        let f = |x: f64| self.log_density(x.exp());
        let (mut lo, mut hi) = ((guess * 1e-3).ln(), (guess * 1e3).ln());
        let ratio = 0.5 * (5f64.sqrt() - 1.0);
        let (mut x1, mut x2) = (hi - ratio * (hi - lo), lo + ratio * (hi - lo));
        let (mut f1, mut f2) = (f(x1), f(x2));
        for _ in 0..100 {
            if f1 < f2 {
                lo = x1;
                x1 = x2;
                f1 = f2;
                x2 = lo + ratio * (hi - lo);
                f2 = f(x2);
            } else {
                hi = x2;
                x2 = x1;
                f2 = f1;
                x1 = hi - ratio * (hi - lo);
                f1 = f(x1);
            }
        }
        (0.5 * (lo + hi)).exp()
    }
}
