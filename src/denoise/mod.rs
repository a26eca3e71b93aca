//! Gaussian denoisers used as Plug-and-Play priors.
//!
//! A [`Denoiser`] works on images in [0, 1] with a noise standard deviation
//! on that scale. [`denoise_scaled`] maps an arbitrary image into that range
//! and the noise level with it, and maps the result back.

pub mod benchmark;
pub mod ffdnet;
pub mod prior;
pub mod tv;

use ndarray::{Array2, ArrayView2};

/// A Gaussian denoiser: image in [0, 1] and noise sigma -> denoised image.
pub trait Denoiser: Sync {
    /// Short name for traces and reports (e.g. `tv(gain=1)`).
    fn name(&self) -> String;

    /// Denoises `img` (values nominally in [0, 1]) corrupted by white
    /// Gaussian noise of standard deviation `sigma` on the same scale.
    fn denoise_unit(&self, img: ArrayView2<f64>, sigma: f64) -> Array2<f64>;

    /// Largest sigma (on the [0, 1] scale) the denoiser honours; larger
    /// requests are clamped to it (learned denoisers know only the noise
    /// levels they were trained on).
    fn sigma_max(&self) -> f64 {
        f64::INFINITY
    }

    /// Whether the denoiser tends to the identity as sigma -> 0 (TV, whose
    /// weight is proportional to sigma, and the identity itself). PnP-ADMM's
    /// primal residual `||o - v||` then falls to zero with sigma and carries
    /// no stopping signal, so [`crate::reconstruct::admm_lbfgs::PnpStop::Auto`]
    /// stops such priors on the deviance instead.
    fn fades_to_identity(&self) -> bool {
        true
    }

    /// Whether the denoiser works on a 2x2 pixel-unshuffled grid, so that
    /// its output depends on where that grid starts (FFDNet); see
    /// [`denoise_scaled_at`].
    fn unshuffles(&self) -> bool {
        false
    }

    /// Bytes one call on an `h` x `w` image holds at once (an estimate for
    /// the memory budget): by default a few copies of the image.
    fn working_bytes(&self, h: usize, w: usize) -> u64 {
        crate::memory::bytes_of([h, w], 64)
    }
}

/// No prior: the denoiser that returns its input (ADMM then reduces to a
/// damped likelihood ascent). Named "identity" on the command line.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoPrior;

impl Denoiser for NoPrior {
    fn name(&self) -> String {
        "identity".into()
    }

    fn denoise_unit(&self, img: ArrayView2<f64>, _sigma: f64) -> Array2<f64> {
        img.to_owned()
    }
}

/// Result of [`denoise_scaled`].
#[derive(Debug, Clone)]
pub struct Scaled {
    /// The denoised image, on the input's scale.
    pub image: Array2<f64>,
    /// The sigma the denoiser was asked for on its [0, 1] scale (before any
    /// clamping to [`Denoiser::sigma_max`]); `None` for a constant image,
    /// which is returned unchanged.
    pub unit_sigma: Option<f64>,
}

/// `d` on `img` (values on the [0, 1] scale) at noise level `sigma`, once
/// its working memory is checked against the budget: the call a front end
/// makes on an image of any size. The note says when `sigma` lies above
/// the prior's trained range and was clamped.
pub fn denoise_image(
    d: &dyn Denoiser,
    img: ArrayView2<f64>,
    sigma: f64,
) -> Result<(Array2<f64>, Option<String>), crate::memory::MemoryError> {
    let (h, w) = img.dim();
    crate::memory::check(d.working_bytes(h, w), || {
        format!("{} on a {w} x {h} image", d.name())
    })?;
    let note = (sigma > d.sigma_max()).then(|| {
        format!(
            "sigma {sigma:.5} is above the prior's trained range; clamped to {:.5}",
            d.sigma_max()
        )
    });
    Ok((d.denoise_unit(img, sigma), note))
}

/// Denoises `img` of any range: it is shifted and scaled to [0, 1] by its
/// minimum and maximum, `sigma` is scaled by the same factor, and the result
/// is mapped back. A constant image is returned unchanged.
pub fn denoise_scaled(d: &dyn Denoiser, img: ArrayView2<f64>, sigma: f64) -> Scaled {
    let (lo, hi) = img
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    let range = hi - lo;
    if range.is_nan() || range <= f64::EPSILON * hi.abs().max(1.0) {
        return Scaled {
            image: img.to_owned(),
            unit_sigma: None,
        };
    }
    let unit = img.mapv(|v| (v - lo) / range);
    let unit_sigma = sigma / range;
    Scaled {
        image: d
            .denoise_unit(unit.view(), unit_sigma)
            .mapv(|v| v * range + lo),
        unit_sigma: Some(unit_sigma),
    }
}

/// [`denoise_scaled`] with the image shifted by `phase = (rows, cols)`
/// (each 0 or 1) before denoising: that many rows and columns are repeated
/// at the top and left, and cropped off again. For a denoiser that
/// [`Denoiser::unshuffles`], this moves its 2x2 grid by one pixel.
pub fn denoise_scaled_at(
    d: &dyn Denoiser,
    img: ArrayView2<f64>,
    sigma: f64,
    phase: (usize, usize),
) -> Scaled {
    if phase == (0, 0) {
        return denoise_scaled(d, img, sigma);
    }
    let (h, w) = img.dim();
    let (dy, dx) = phase;
    let padded = Array2::from_shape_fn((h + dy, w + dx), |(i, j)| {
        img[(i.saturating_sub(dy), j.saturating_sub(dx))]
    });
    let out = denoise_scaled(d, padded.view(), sigma);
    Scaled {
        image: out.image.slice(ndarray::s![dy.., dx..]).to_owned(),
        unit_sigma: out.unit_sigma,
    }
}

/// The four positions of a 2x2 unshuffle grid, as `(rows, cols)` shifts.
const GRID_POSITIONS: [(usize, usize); 4] = [(0, 0), (1, 1), (0, 1), (1, 0)];

/// [`denoise_scaled`] averaged over the four positions of the denoiser's
/// 2x2 grid ([`denoise_scaled_at`]) when it [`Denoiser::unshuffles`]; a
/// single call otherwise. The average does not depend on where the grid
/// starts, so it adds no fixed 2x2 pattern: in PnP such a pattern sits in
/// the blur's null space, where the data cannot remove it.
pub fn denoise_scaled_grid_average(
    d: &dyn Denoiser,
    img: ArrayView2<f64>,
    sigma: f64,
) -> Array2<f64> {
    if !d.unshuffles() {
        return denoise_scaled(d, img, sigma).image;
    }
    let mut sum = Array2::zeros(img.dim());
    for &p in &GRID_POSITIONS {
        sum += &denoise_scaled_at(d, img, sigma, p).image;
    }
    sum / GRID_POSITIONS.len() as f64
}
