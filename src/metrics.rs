//! Image quality against a known truth.
//!
//! Data-range convention: truth images are transmittances in [0, 1], so PSNR
//! and SSIM use a data range of 1 (peak = 1, SSIM's L = 1). Estimates are
//! compared as they are (reconstructions are already clamped to >= 0), not
//! rescaled to the truth, so a wrong overall brightness costs PSNR.

use ndarray::{Array2, ArrayView2, Zip};

/// Peak signal-to-noise ratio in dB with peak 1.
pub fn psnr(estimate: ArrayView2<f64>, truth: ArrayView2<f64>) -> f64 {
    let mse = Zip::from(estimate)
        .and(truth)
        .fold(0.0, |acc, &e, &t| acc + (e - t) * (e - t))
        / truth.len() as f64;
    -10.0 * mse.log10()
}

/// Structural similarity (Wang et al. 2004): 11 x 11 Gaussian window with
/// sigma 1.5, K1 = 0.01, K2 = 0.03, L = 1, mean over the valid region.
pub fn ssim(estimate: ArrayView2<f64>, truth: ArrayView2<f64>) -> f64 {
    const C1: f64 = 0.01 * 0.01;
    const C2: f64 = 0.03 * 0.03;
    let mu_x = gaussian_filter(estimate);
    let mu_y = gaussian_filter(truth);
    let xx = gaussian_filter((&estimate * &estimate).view());
    let yy = gaussian_filter((&truth * &truth).view());
    let xy = gaussian_filter((&estimate * &truth).view());
    let mut sum = 0.0;
    let mut n = 0usize;
    Zip::from(&mu_x)
        .and(&mu_y)
        .and(&xx)
        .and(&yy)
        .and(&xy)
        .for_each(|&mx, &my, &sxx, &syy, &sxy| {
            let (vx, vy, cov) = (sxx - mx * mx, syy - my * my, sxy - mx * my);
            sum += ((2.0 * mx * my + C1) * (2.0 * cov + C2))
                / ((mx * mx + my * my + C1) * (vx + vy + C2));
            n += 1;
        });
    sum / n as f64
}

/// Separable 11-tap Gaussian (sigma 1.5) over the valid region only.
fn gaussian_filter(img: ArrayView2<f64>) -> Array2<f64> {
    const R: usize = 5;
    let weights: Vec<f64> = (0..=2 * R)
        .map(|i| (-((i as f64 - R as f64).powi(2)) / (2.0 * 1.5 * 1.5)).exp())
        .collect();
    let total: f64 = weights.iter().sum();
    let weights: Vec<f64> = weights.iter().map(|w| w / total).collect();
    let (h, w) = img.dim();
    if h <= 2 * R || w <= 2 * R {
        return Array2::from_elem((1, 1), img.mean().unwrap_or(0.0));
    }
    let rows = Array2::from_shape_fn((h, w - 2 * R), |(r, c)| {
        (0..=2 * R)
            .map(|i| weights[i] * img[[r, c + i]])
            .sum::<f64>()
    });
    Array2::from_shape_fn((h - 2 * R, w - 2 * R), |(r, c)| {
        (0..=2 * R)
            .map(|i| weights[i] * rows[[r + i, c]])
            .sum::<f64>()
    })
}

/// PSNR of `image` against `truth` after the gain that best fits the truth
/// (least squares); `None` when the shapes differ or the image is dark.
pub fn psnr_fitted(image: ArrayView2<f64>, truth: ArrayView2<f64>) -> Option<f64> {
    if image.dim() != truth.dim() {
        return None;
    }
    let (xy, xx) = image
        .iter()
        .zip(truth.iter())
        .fold((0.0, 0.0), |(xy, xx), (&x, &y)| (xy + x * y, xx + x * x));
    if xx <= 0.0 {
        return None;
    }
    let scaled = image.mapv(|v| v * xy / xx);
    Some(psnr(scaled.view(), truth))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_fitted_psnr_ignores_the_gain_and_sees_the_error() {
        let truth = Array2::from_shape_fn((8, 8), |(y, x)| ((x + y) % 3) as f64);
        let scaled = truth.mapv(|v| 7.0 * v);
        assert!(psnr_fitted(scaled.view(), truth.view()).unwrap() > 100.0);
        let mut off = scaled.clone();
        off[(2, 2)] += 5.0;
        let p = psnr_fitted(off.view(), truth.view()).unwrap();
        assert!(p.is_finite() && p < 60.0, "{p}");
        assert!(psnr_fitted(Array2::zeros((8, 8)).view(), truth.view()).is_none());
        assert!(psnr_fitted(Array2::ones((4, 8)).view(), truth.view()).is_none());
    }

    #[test]
    fn psnr_of_a_known_error() {
        let t = Array2::from_elem((10, 10), 0.5);
        let e = t.mapv(|v| v + 0.1);
        assert!((psnr(e.view(), t.view()) - 20.0).abs() < 1e-9);
    }

    #[test]
    fn ssim_is_one_for_identity_and_lower_for_noise() {
        let t = Array2::from_shape_fn((32, 32), |(r, c)| ((r / 4 + c / 4) % 2) as f64);
        assert!((ssim(t.view(), t.view()) - 1.0).abs() < 1e-12);
        let noisy = Array2::from_shape_fn((32, 32), |(r, c)| {
            t[[r, c]] + 0.6 * (((r * 7 + c * 13) % 5) as f64 - 2.0) / 2.0
        });
        let s = ssim(noisy.view(), t.view());
        assert!(s < 0.9 && s > 0.0, "{s}");
        // Symmetric in its arguments.
        assert!((s - ssim(t.view(), noisy.view())).abs() < 1e-12);
    }
}
