//! The slab's diffusion kernel for confocal light: the laterally resolved
//! time-resolved transmittance of a finite slab (extrapolated boundaries,
//! image sources; Patterson, Chance and Wilson 1989), sampled on a grid of
//! lateral offsets and times, and convolved with itself for the way in and
//! the way out.

use ndarray::Array3;
use ndrustfft::Complex;
use scatterscope_physics::diffusion::diffusion_coefficient_cm;
use scatterscope_physics::{Diffusion, Medium};

use super::ConfocalError;
use super::fft3::{Fft3, complex};

/// Image-source pairs on each side of the slab (the published code's 20;
/// at the published foam's 1 inch the 20th pair's term is below 1e-300).
pub const IMAGE_PAIRS: i32 = 20;

/// The slab's optics in the physics crate's units (cm, 1/cm), so that
/// the optics the physics crate derives for a medium and the
/// transmittance it evaluates for these optics take no conversion; the
/// scan's own lengths (m) become cm where the kernel is sampled.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SlabOptics {
    /// Thickness (cm).
    pub thickness_cm: f64,
    /// Refractive index.
    pub refractive_index: f64,
    /// Absorption coefficient (1/cm).
    pub mu_a_per_cm: f64,
    /// Reduced scattering coefficient (1/cm).
    pub mu_s_reduced_per_cm: f64,
    /// Distance of each extrapolated boundary outside its face (cm).
    pub extrapolation_cm: f64,
    /// Depth of the equivalent isotropic source below the lit face (cm).
    pub source_depth_cm: f64,
}

impl SlabOptics {
    /// The 1-inch foam of the confocal diffuse tomography scans, with the
    /// authors' fit (n 1.12, mu_a 0.53 /m, mu_s' 262 /m, z_e 3.6 mm) and
    /// their source depth `1 / mu_s'`, written in cm.
    pub const PUBLISHED_FOAM: Self = Self {
        thickness_cm: 2.54,
        refractive_index: 1.12,
        mu_a_per_cm: 0.0053,
        mu_s_reduced_per_cm: 2.62,
        extrapolation_cm: 0.36,
        source_depth_cm: 1.0 / 2.62,
    };

    /// The optics of a slab medium as the physics crate models it (source
    /// one transport mean free path deep, `z_e = 2 A D` from the effective
    /// reflection of the index mismatch): its `Diffusion`'s slab.
    pub fn from_medium(medium: &Medium) -> Result<Self, ConfocalError> {
        let slab_medium = Medium {
            model: scatterscope_physics::MediumModel::Slab,
            ..*medium
        };
        let diffusion = Diffusion::new(&slab_medium)
            .map_err(|e| ConfocalError::input("medium", e.to_string()))?;
        let slab = diffusion
            .slab
            .expect("a slab medium's diffusion has its slab geometry");
        Ok(Self {
            thickness_cm: medium.thickness_cm,
            refractive_index: medium.refractive_index,
            mu_a_per_cm: diffusion.mu_a_per_cm,
            mu_s_reduced_per_cm: diffusion.mu_s_reduced_per_cm,
            extrapolation_cm: slab.extrapolation_cm,
            source_depth_cm: slab.source_depth_cm,
        })
    }

    /// The optics of the material file at `path` (e.g. the
    /// `material.toml` that `calibrate-slab` writes) for a slab
    /// `thickness_cm` thick. A file that names another thickness is refused
    /// with both.
    pub fn from_material_file(
        path: &std::path::Path,
        thickness_cm: f64,
    ) -> Result<Self, ConfocalError> {
        let name = path.display().to_string();
        let file = crate::config::read_material(path)
            .map_err(|e| ConfocalError::input(&name, e.to_string()))?;
        if let Some(cm) = file.thickness_cm
            && (cm - thickness_cm).abs() > 1e-6 * thickness_cm.max(1e-7)
        {
            return Err(ConfocalError::setting(
                "thickness_cm",
                format!(
                    "{name}: the material file is for a slab {cm} cm thick, the scan's slab is {thickness_cm} cm: remove its `thickness` key to use the material at another thickness"
                ),
            ));
        }
        Self::from_medium(&Medium {
            mu_a_per_cm: file.mu_a_per_cm,
            mu_s_per_cm: file.mu_s_per_cm,
            g: file.g,
            refractive_index: file.refractive_index,
            thickness_cm,
            model: scatterscope_physics::MediumModel::Slab,
        })
        .map_err(|e| match e {
            ConfocalError::Input { message, .. } => ConfocalError::input(&name, message),
            other => other,
        })
    }

    /// The optics of a slab `thickness_cm` thick: the material of
    /// `material_file` ([`Self::from_material_file`]), or the published foam's
    /// when there is none.
    pub fn for_slab(
        material_file: Option<&std::path::Path>,
        thickness_cm: f64,
    ) -> Result<Self, ConfocalError> {
        match material_file {
            Some(path) => Self::from_material_file(path, thickness_cm),
            None => Ok(Self {
                thickness_cm,
                ..Self::PUBLISHED_FOAM
            }),
        }
    }

    /// The slab in words: thickness, index, mu_a, mu_s', z_e (the
    /// coefficients per metre and z_e in mm, as the published fit states
    /// them).
    pub fn describe(&self) -> String {
        use crate::units::CM_PER_M;
        format!(
            "{:.2} cm, n {}, mu_a {:.3} /m, mu_s' {:.1} /m, z_e {:.2} mm",
            self.thickness_cm,
            self.refractive_index,
            self.mu_a_per_cm * CM_PER_M,
            self.mu_s_reduced_per_cm * CM_PER_M,
            self.extrapolation_cm * 10.0
        )
    }

    /// Diffusion coefficient `D = 1 / (3 (mu_a + mu_s'))` (cm).
    pub fn diffusion_cm(&self) -> f64 {
        diffusion_coefficient_cm(self.mu_a_per_cm, self.mu_s_reduced_per_cm)
    }

    /// Photon flux density leaving the far face at lateral offset `rho`
    /// (cm) from the source, `t` ps after it entered, for light speed
    /// `v` (cm/ps) in the slab (unnormalised: the published form,
    /// `(4 pi D v)^(-3/2) t^(-5/2) exp(-mu_a v t - rho^2 / (4 D v t))`
    /// times the image sum).
    pub fn transmittance(&self, rho2_cm2: f64, t_ps: f64, v: f64) -> f64 {
        self.temporal_factor(t_ps, v) * self.lateral_factor(rho2_cm2, t_ps, v)
    }

    /// The factor of [`Self::transmittance`] that depends on time only.
    pub fn temporal_factor(&self, t_ps: f64, v: f64) -> f64 {
        if t_ps.is_nan() || t_ps <= 0.0 {
            return 0.0;
        }
        let d = self.diffusion_cm();
        let four_dvt = 4.0 * d * v * t_ps;
        let (s, ze, z0) = (
            self.thickness_cm,
            self.extrapolation_cm,
            self.source_depth_cm,
        );
        let mut images = 0.0;
        for m in -IMAGE_PAIRS..=IMAGE_PAIRS {
            let m = f64::from(m);
            let z_pos = s * (1.0 - 2.0 * m) - 4.0 * m * ze - z0;
            let z_neg = s * (1.0 - 2.0 * m) - (4.0 * m - 2.0) * ze + z0;
            images += z_pos * (-z_pos * z_pos / four_dvt).exp()
                - z_neg * (-z_neg * z_neg / four_dvt).exp();
        }
        (4.0 * std::f64::consts::PI * d * v).powf(-1.5)
            * t_ps.powf(-2.5)
            * (-self.mu_a_per_cm * v * t_ps).exp()
            * images
    }

    /// The lateral Gaussian of [`Self::transmittance`],
    /// `exp(-rho^2 / (4 D v t))` (1 at `t <= 0`, where the temporal factor
    /// is 0).
    pub fn lateral_factor(&self, rho2_cm2: f64, t_ps: f64, v: f64) -> f64 {
        if t_ps.is_nan() || t_ps <= 0.0 {
            return 1.0;
        }
        (-rho2_cm2 / (4.0 * self.diffusion_cm() * v * t_ps)).exp()
    }
}

/// The grid a kernel is sampled on: `times_ps[k]` by lateral offsets
/// `rows_cm[r]`, `cols_cm[c]`, origin at index (0, 0, 0) after a circular
/// shift, as the padded volumes it convolves.
pub struct KernelGrid {
    /// Sample times (ps).
    pub times_ps: Vec<f64>,
    /// Lateral offsets along rows (cm), before the shift.
    pub rows_cm: Vec<f64>,
    /// Lateral offsets along columns (cm), before the shift.
    pub cols_cm: Vec<f64>,
    /// Light speed in the slab (cm/ps).
    pub speed_cm_per_ps: f64,
}

/// The kernel `optics` gives on `grid`, normalised to sum 1, rolled so that
/// offset index `len / 2` sits at 0, then convolved with itself circularly
/// (in and out); returns its 3-D spectrum.
pub fn in_and_out_spectrum(optics: &SlabOptics, grid: &KernelGrid) -> Array3<Complex<f64>> {
    let (nt, nr, nc) = (grid.times_ps.len(), grid.rows_cm.len(), grid.cols_cm.len());
    // Separable: a factor per time, and per time a Gaussian per row and
    // per column (the image sum is evaluated once per time, not per voxel).
    let v = grid.speed_cm_per_ps;
    let mut once = Array3::<f64>::zeros((nt, nr, nc));
    ndarray::Zip::indexed(once.outer_iter_mut()).par_for_each(|k, mut plane| {
        let t = grid.times_ps[k];
        let temporal = optics.temporal_factor(t, v);
        let along = |offsets: &[f64], n: usize| -> Vec<f64> {
            (0..n)
                .map(|i| {
                    let x = offsets[(i + n / 2) % n];
                    optics.lateral_factor(x * x, t, v)
                })
                .collect()
        };
        let (gr, gc) = (along(&grid.rows_cm, nr), along(&grid.cols_cm, nc));
        for ((r, c), value) in plane.indexed_iter_mut() {
            *value = temporal * gr[r] * gc[c];
        }
    });
    let total = once.sum();
    if total > 0.0 {
        once /= total;
    }
    let fft = Fft3::new((nt, nr, nc));
    let mut spectrum = complex(&once);
    fft.forward(&mut spectrum);
    // |ifft(F^2)|, as published: the self-convolution is real and
    // non-negative up to rounding, the magnitude removes the rounding.
    spectrum.mapv_inplace(|z| z * z);
    fft.inverse(&mut spectrum);
    spectrum.mapv_inplace(|z| Complex::new(z.norm(), 0.0));
    fft.forward(&mut spectrum);
    spectrum
}

#[cfg(test)]
mod tests {
    use super::*;

    fn material_file(text: &str) -> std::path::PathBuf {
        use std::sync::atomic::{AtomicUsize, Ordering};
        static N: AtomicUsize = AtomicUsize::new(0);
        let path = std::env::temp_dir().join(format!(
            "scatterscope-medium-{}-{}.toml",
            std::process::id(),
            N.fetch_add(1, Ordering::Relaxed)
        ));
        std::fs::write(&path, text).unwrap();
        path
    }

    /// A medium file without a thickness gives the physics crate's optics
    /// at the scan's thickness; one for another thickness, or without
    /// `n`, is refused with the reason.
    #[test]
    fn medium_files_are_read_and_checked() {
        let ok =
            material_file("mu_a = 0.0048\nmu_s = 2.72\ng = 0.0\nn = 1.12\nmedium = \"slab\"\n");
        let optics = SlabOptics::from_material_file(&ok, 2.54).unwrap();
        assert!((optics.mu_s_reduced_per_cm - 2.72).abs() < 1e-12);
        assert_eq!(optics.thickness_cm, 2.54);
        let other = material_file("mu_a = 0.0048\nmu_s = 2.72\nn = 1.12\nthickness = 3.0\n");
        let e = SlabOptics::from_material_file(&other, 2.54)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("3 cm thick") && e.contains("2.54 cm") && e.contains(".toml:"),
            "{e}"
        );
        let missing = material_file("mu_a = 0.0048\nmu_s = 2.72\n");
        let e = SlabOptics::from_material_file(&missing, 2.54)
            .unwrap_err()
            .to_string();
        assert!(e.contains("key `n` is missing"), "{e}");
        for p in [ok, other, missing] {
            std::fs::remove_file(p).ok();
        }
    }

    /// The published kernel's time profile (integrated over the far face)
    /// is the physics crate's slab transmittance at the same constants.
    #[test]
    fn equals_physics_slab_transmittance() {
        let o = SlabOptics::PUBLISHED_FOAM;
        let v = scatterscope_physics::diffusion::light_speed_cm_per_ps(o.refractive_index);
        let slab = crate::confocal::forward::slab_transmittance(&o);
        // Integrated over the plane the lateral Gaussian gives 4 pi D v t.
        let d = o.diffusion_cm();
        let ratio = |t_ps: f64| {
            let plane = o.transmittance(0.0, t_ps, v) * 4.0 * std::f64::consts::PI * d * v * t_ps;
            plane / slab.log_density(t_ps).exp()
        };
        // To 5 ns, where the flux has fallen to about 2e-7 of its peak;
        // later the published image sum loses digits to cancellation (its
        // terms are of order one, their sum far smaller), where the physics
        // crate has switched to its sine series.
        let reference = ratio(1000.0);
        for t_ps in [100.0, 300.0, 1000.0, 3000.0, 5000.0] {
            let r = ratio(t_ps) / reference;
            assert!((r - 1.0).abs() < 1e-9, "t = {t_ps} ps: ratio {r}");
        }
    }
}
