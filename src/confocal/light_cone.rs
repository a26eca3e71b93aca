//! Confocal free-space propagation as a linear operator with its adjoint,
//! evaluated fast with the light-cone transform (O'Toole, Lindell and
//! Wetzstein, Nature 555, 338 (2018)).
//!
//! A hidden point at lateral offset `d` from a scan point and depth `z`
//! behind the slab's far face returns light to it after the round trip
//! `2 r / c`, `r = sqrt(d^2 + z^2)`, weakened as `r^-4` (a diffuse point
//! lit and seen from the same spot). With `u = z^2` and `v = r^2` the sum
//! over hidden points becomes a convolution in (`u`, x, y): `v = u + d^2`.
//! The operator here is the composition of three linear maps, each with an
//! exact transpose:
//!
//! 1. depth samples to bins of `u` (each sample's weight split linearly
//!    between the two nearest bin centres; mass kept);
//! 2. a three-dimensional convolution with the light cone `h(m, a, b)`,
//!    the weight of lateral offset `(a, b)` landing `m` bins of `v` later
//!    (split linearly, mass kept), by FFT on a grid padded to twice each
//!    axis (a linear, not circular, convolution);
//! 3. bins of `v` to time bins of the round trip, weighted by `v^-2`
//!    (split linearly between the two nearest bins in `r`).
//!
//! [`direct`] evaluates the same model point by point (the slow
//! reference the tests compare against).

use ndarray::{Array3, Zip, s};
use ndrustfft::Complex;

use super::fft3::{Fft3, complex};

/// The grid the operator maps between: `depths` depth samples at
/// `(k + 1/2) step` and as many time bins `[i step, (i + 1) step)` of
/// one-way path (`step = c dt / 2`), on `rows` x `cols` scan points
/// `spacing` apart (all lengths in metres).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConeGrid {
    /// Depth samples and time bins.
    pub depths: usize,
    /// Scan points per column.
    pub rows: usize,
    /// Scan points per row.
    pub cols: usize,
    /// Distance between neighbouring scan points (m).
    pub spacing_m: f64,
    /// Depth per sample and one-way path per time bin (m).
    pub step_m: f64,
}

/// The light-cone operator on one grid.
pub struct LightCone {
    grid: ConeGrid,
    /// Per depth sample: (u bin, weight).
    depth_to_u: Vec<[(usize, f64); 2]>,
    /// Per v bin: (time bin, weight including `v^-2`).
    v_to_time: Vec<[(usize, f64); 2]>,
    /// Spectrum of the light cone on the padded grid.
    cone: Array3<Complex<f64>>,
    fft: Fft3,
}

/// Splits position `p` (in bin-centre units: bin `j`'s centre is `j`)
/// between its two neighbouring bins below `n`; weights of bins outside are
/// dropped.
fn tent(p: f64, n: usize) -> [(usize, f64); 2] {
    let lo = p.floor();
    let frac = p - lo;
    let at = |j: f64, w: f64| {
        if j >= 0.0 && (j as usize) < n {
            (j as usize, w)
        } else {
            (0, 0.0)
        }
    };
    [at(lo, 1.0 - frac), at(lo + 1.0, frac)]
}

impl LightCone {
    /// Plans the operator on `grid` with `oversample` bins of `u` and `v`
    /// per depth sample (1 matches the bins at half the depth range).
    pub fn new(grid: ConeGrid, oversample: usize) -> Self {
        let n = grid.depths;
        let u_bins = n * oversample.max(1);
        let range = n as f64 * grid.step_m;
        let du = range * range / u_bins as f64;
        let depth_to_u = (0..n)
            .map(|k| {
                let z = (k as f64 + 0.5) * grid.step_m;
                tent(z * z / du - 0.5, u_bins)
            })
            .collect();
        let v_to_time = (0..u_bins)
            .map(|j| {
                let v = (j as f64 + 0.5) * du;
                let r = v.sqrt();
                let mut split = tent(r / grid.step_m - 0.5, n);
                for part in &mut split {
                    part.1 /= v * v;
                }
                split
            })
            .collect();
        let dim = (2 * u_bins, 2 * grid.rows, 2 * grid.cols);
        let mut cone = Array3::<f64>::zeros(dim);
        for a in -(grid.rows as i64 - 1)..grid.rows as i64 {
            for b in -(grid.cols as i64 - 1)..grid.cols as i64 {
                let d2 = ((a * a + b * b) as f64) * grid.spacing_m * grid.spacing_m;
                let q = d2 / du;
                let lo = q.floor();
                let frac = q - lo;
                let ra = a.rem_euclid(dim.1 as i64) as usize;
                let cb = b.rem_euclid(dim.2 as i64) as usize;
                for (m, w) in [(lo as usize, 1.0 - frac), (lo as usize + 1, frac)] {
                    if m < u_bins {
                        cone[[m, ra, cb]] += w;
                    }
                }
            }
        }
        let fft = Fft3::new(dim);
        let mut spectrum = complex(&cone);
        fft.forward(&mut spectrum);
        Self {
            grid,
            depth_to_u,
            v_to_time,
            cone: spectrum,
            fft,
        }
    }

    /// Expected transient (time, row, column) of `volume` (depth, row,
    /// column).
    pub fn forward(&self, volume: &Array3<f64>) -> Array3<f64> {
        self.apply(
            volume,
            links(&self.depth_to_u, false),
            links(&self.v_to_time, true),
            false,
        )
    }

    /// The transpose of [`Self::forward`]: a volume from a transient.
    pub fn adjoint(&self, transient: &Array3<f64>) -> Array3<f64> {
        self.apply(
            transient,
            links(&self.v_to_time, true),
            links(&self.depth_to_u, false),
            true,
        )
    }

    /// Resamples `input` onto the padded grid along `into` (padded slice,
    /// input slice, weight), convolves with the cone (its transpose when
    /// `transpose`), and resamples back along `from` (padded slice, output
    /// slice, weight).
    fn apply(
        &self,
        input: &Array3<f64>,
        into: impl Iterator<Item = (usize, usize, f64)>,
        from: impl Iterator<Item = (usize, usize, f64)>,
        transpose: bool,
    ) -> Array3<f64> {
        let g = self.grid;
        let mut padded = Array3::<Complex<f64>>::zeros(self.cone.dim());
        for (j, k, w) in into {
            let mut dst = padded.slice_mut(s![j, ..g.rows, ..g.cols]);
            Zip::from(&mut dst)
                .and(input.slice(s![k, .., ..]))
                .for_each(|d, &v| d.re += w * v);
        }
        self.fft.forward(&mut padded);
        Zip::from(&mut padded)
            .and(&self.cone)
            .par_for_each(|x, &h| *x *= if transpose { h.conj() } else { h });
        self.fft.inverse(&mut padded);
        let mut out = Array3::<f64>::zeros((g.depths, g.rows, g.cols));
        for (j, i, w) in from {
            let mut dst = out.slice_mut(s![i, .., ..]);
            Zip::from(&mut dst)
                .and(padded.slice(s![j, ..g.rows, ..g.cols]))
                .for_each(|d, v| *d += w * v.re);
        }
        out
    }
}

/// The non-zero links of a resampling map as (padded slice, other slice,
/// weight), in the map's order; `outer_is_padded` says which index the
/// map's outer one is.
fn links(
    map: &[[(usize, f64); 2]],
    outer_is_padded: bool,
) -> impl Iterator<Item = (usize, usize, f64)> + '_ {
    map.iter().enumerate().flat_map(move |(outer, split)| {
        split
            .iter()
            .filter(|(_, w)| *w != 0.0)
            .map(move |&(inner, w)| {
                if outer_is_padded {
                    (outer, inner, w)
                } else {
                    (inner, outer, w)
                }
            })
    })
}

/// The same model evaluated point by point: every hidden sample's `r^-4`
/// split linearly between the two time bins nearest its round trip (the
/// slow reference, `rows^2 cols^2 depths` steps).
pub fn direct(grid: ConeGrid, volume: &Array3<f64>) -> Array3<f64> {
    let n = grid.depths;
    let mut out = Array3::<f64>::zeros((n, grid.rows, grid.cols));
    for ((k, r, c), &rho) in volume.indexed_iter() {
        if rho == 0.0 {
            continue;
        }
        let z = (k as f64 + 0.5) * grid.step_m;
        for r2 in 0..grid.rows {
            for c2 in 0..grid.cols {
                let dr = (r2 as f64 - r as f64) * grid.spacing_m;
                let dc = (c2 as f64 - c as f64) * grid.spacing_m;
                let v = dr * dr + dc * dc + z * z;
                for (i, w) in tent(v.sqrt() / grid.step_m - 0.5, n) {
                    out[[i, r2, c2]] += rho * w / (v * v);
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn grid() -> ConeGrid {
        ConeGrid {
            depths: 24,
            rows: 6,
            cols: 5,
            spacing_m: 0.05,
            step_m: 0.02,
        }
    }

    fn random(dim: (usize, usize, usize), seed: u64) -> Array3<f64> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        Array3::from_shape_fn(dim, |_| rng.random::<f64>())
    }

    /// <A x, y> = <x, A^T y> for random x and y.
    #[test]
    fn adjoint_identity() {
        let g = grid();
        let cone = LightCone::new(g, 2);
        let x = random((g.depths, g.rows, g.cols), 1);
        let y = random((g.depths, g.rows, g.cols), 2);
        let lhs = (&cone.forward(&x) * &y).sum();
        let rhs = (&x * &cone.adjoint(&y)).sum();
        assert!((lhs - rhs).abs() <= 1e-10 * lhs.abs(), "{lhs} vs {rhs}");
    }

    /// The fast operator agrees with the point-by-point model on a tiny
    /// grid: within 5 % (relative L2) for a volume far enough behind the
    /// slab that the bins of u are finer than the depth samples there,
    /// and each time bin's total within 5 % of the direct one's total.
    #[test]
    fn fast_matches_direct_evaluation() {
        let g = grid();
        let cone = LightCone::new(g, 4);
        let mut x = Array3::<f64>::zeros((g.depths, g.rows, g.cols));
        x.slice_mut(s![10..16, 1..5, 1..4])
            .assign(&random((6, 4, 3), 3));
        let fast = cone.forward(&x);
        let slow = direct(g, &x);
        let err = (&fast - &slow).mapv(|v| v * v).sum().sqrt() / slow.mapv(|v| v * v).sum().sqrt();
        assert!(err < 0.05, "relative L2 error {err}");
        let mass = |a: &Array3<f64>| a.sum();
        assert!((mass(&fast) / mass(&slow) - 1.0).abs() < 0.05);
    }

    /// Every entry is non-negative (the EM update needs it).
    #[test]
    fn operator_is_non_negative() {
        let g = grid();
        let cone = LightCone::new(g, 1);
        let x = random((g.depths, g.rows, g.cols), 4);
        assert!(cone.forward(&x).iter().all(|&v| v >= -1e-9 * x.sum()));
    }
}
