//! f-k (Stolt) migration of confocal free-space propagation (Lindell,
//! Wetzstein and O'Toole, ACM Trans. Graph. 38, 116 (2019)).
//!
//! A confocal measurement behaves as a wave field recorded at the wall
//! whose sources sit at the hidden points, travelling at half the speed of
//! light. In the Fourier domain of (time, row, column) each temporal
//! frequency `k_z` of the volume is read off the measurement's spectrum at
//! `sqrt(a^2 (k_r^2 + k_c^2) + k_z^2)`, linearly interpolated along the
//! time axis and weighted by `k_z / sqrt(...)`; the inverse transform's
//! squared magnitude is the volume.

use ndarray::{Array3, Zip};
use ndrustfft::Complex;

use super::fft3::{Fft3, complex};

/// Migrates `padded` (time, row, column; each axis twice the measurement's,
/// the measurement in the first half) whose time axis spans `range_m` of
/// the published unit (`2 z_max`, four times the depth) and whose first
/// half of each lateral axis spans `side_m`. Returns `|field|^2` on the
/// same grid. The measurement's square root is migrated (amplitudes).
pub fn migrate(padded: &Array3<f64>, side_m: f64, range_m: f64) -> Array3<f64> {
    let dim = padded.dim();
    let (nt, nr, nc) = dim;
    let (half_t, half_r, half_c) = (nt / 2, nr / 2, nc / 2);
    let fft = Fft3::new(dim);
    let mut spectrum = complex(&padded.mapv(|v| v.max(0.0).sqrt()));
    fft.forward(&mut spectrum);
    // The published scale: (N range) / (M width 4), N and M the halves.
    let scale = (half_r as f64 * range_m) / (half_t as f64 * side_m * 4.0);
    let mut moved = Array3::<Complex<f64>>::zeros(dim);
    // Frequencies in fftshift order: shifted index i is frequency i - half,
    // found at unshifted index (i + half) mod n.
    let unshift = |i: usize, half: usize, n: usize| (i + half) % n;
    let last = (nt - 1) as f64;
    Zip::indexed(moved.lanes_mut(ndarray::Axis(0))).par_for_each(|(r, c), mut column| {
        let kr = (r as f64 - half_r as f64) / half_r as f64;
        let kc = (c as f64 - half_c as f64) / half_c as f64;
        let lateral = scale * scale * (kr * kr + kc * kc);
        let (ur, uc) = (unshift(r, half_r, nr), unshift(c, half_c, nc));
        for i in half_t + 1..nt {
            let kz = (i as f64 - half_t as f64) / half_t as f64;
            let source = (lateral + kz * kz).sqrt();
            let at = (source + 1.0) * half_t as f64;
            if at > last {
                continue;
            }
            let lo = at.floor() as usize;
            let hi = (lo + 1).min(nt - 1);
            let frac = at - lo as f64;
            let value = spectrum[[unshift(lo, half_t, nt), ur, uc]] * (1.0 - frac)
                + spectrum[[unshift(hi, half_t, nt), ur, uc]] * frac;
            column[unshift(i, half_t, nt)] = value * (kz / source.max(1e-8));
        }
    });
    // `moved` is already in unshifted order: only the inverse remains.
    fft.inverse(&mut moved);
    moved.mapv(|z| z.norm_sqr())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A point behind the wall migrates to a volume whose brightest voxel
    /// sits at the point's lateral position and depth: the migration's
    /// geometry against the hyperbola `t = 2 sqrt(d^2 + z^2) / c`,
    /// evaluated directly.
    #[test]
    fn focuses_a_point_to_its_position() {
        let (m, n) = (64usize, 16usize);
        let side = 0.6;
        let range = 4.0; // time axis: M samples over range / 2 of path
        let (pr, pc, pz) = (9usize, 6usize, 20usize);
        let dx = side / (n - 1) as f64;
        // Time sample k is k range / (2 M) of round-trip path, depth
        // k range / (4 M).
        let dz = range / 4.0 / m as f64;
        let depth = pz as f64 * dz;
        let mut padded = Array3::<f64>::zeros((2 * m, 2 * n, 2 * n));
        for r in 0..n {
            for c in 0..n {
                let d2 =
                    ((r as f64 - pr as f64) * dx).powi(2) + ((c as f64 - pc as f64) * dx).powi(2);
                let dist = (d2 + depth * depth).sqrt();
                let k = (dist / dz).round() as usize;
                if k < m {
                    padded[[k, r, c]] = 1.0 / (dist.powi(4)).max(1e-12);
                }
            }
        }
        let vol = migrate(&padded, side, range);
        let (mut best, mut at) = (f64::MIN, (0, 0, 0));
        for ((k, r, c), &v) in vol.indexed_iter() {
            if k < m && r < n && c < n && v > best {
                (best, at) = (v, (k, r, c));
            }
        }
        assert_eq!((at.1, at.2), (pr, pc), "lateral position of the focus");
        assert!(
            (at.0 as i64 - pz as i64).abs() <= 1,
            "depth {} vs {pz}",
            at.0
        );
    }
}
