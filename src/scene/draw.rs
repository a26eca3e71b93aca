//! Anti-aliased rasterisation helpers: every pixel gets the area-weighted
//! value of the continuous pattern, so fine structure is not aliased.

use ndarray::Array2;

/// Adds `value` times the exact overlap area of each pixel with the
/// rectangle `[x0, x1) x [y0, y1)` (pixel units, pixel (r, c) spans
/// `[c, c+1) x [r, r+1)`).
pub fn fill_rect(img: &mut Array2<f64>, x0: f64, y0: f64, x1: f64, y1: f64, value: f64) {
    let (h, w) = img.dim();
    let cols = x0.floor().max(0.0) as usize..(x1.ceil().max(0.0) as usize).min(w);
    let rows = y0.floor().max(0.0) as usize..(y1.ceil().max(0.0) as usize).min(h);
    for r in rows {
        let oy = (y1.min(r as f64 + 1.0) - y0.max(r as f64)).max(0.0);
        for c in cols.clone() {
            let ox = (x1.min(c as f64 + 1.0) - x0.max(c as f64)).max(0.0);
            img[[r, c]] += value * ox * oy;
        }
    }
}

/// Averages `f(x, y)` (pixel units) over an `n x n` grid inside each pixel.
pub fn supersample(h: usize, w: usize, n: usize, f: impl Fn(f64, f64) -> f64) -> Array2<f64> {
    let inv = 1.0 / n as f64;
    Array2::from_shape_fn((h, w), |(r, c)| {
        let mut acc = 0.0;
        for i in 0..n {
            for j in 0..n {
                acc += f(
                    c as f64 + (j as f64 + 0.5) * inv,
                    r as f64 + (i as f64 + 0.5) * inv,
                );
            }
        }
        acc * inv * inv
    })
}
