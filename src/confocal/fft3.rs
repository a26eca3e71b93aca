//! Three-dimensional complex FFTs of `ndarray` volumes, one axis at a
//! time with `ndrustfft` (rustfft underneath, lanes in parallel with
//! rayon). The inverse is normalised by the volume's size, as numpy's.

use ndarray::Array3;
use ndrustfft::{Complex, FftHandler, ndfft_inplace_par, ndifft_inplace_par};

/// Planned transforms for one volume shape.
pub struct Fft3 {
    handlers: [FftHandler<f64>; 3],
}

impl Fft3 {
    /// Plans the transforms of a volume of shape `dim`.
    pub fn new(dim: (usize, usize, usize)) -> Self {
        Self {
            handlers: [
                FftHandler::new(dim.0),
                FftHandler::new(dim.1),
                FftHandler::new(dim.2),
            ],
        }
    }

    /// Forward transform in place.
    pub fn forward(&self, volume: &mut Array3<Complex<f64>>) {
        for (axis, handler) in self.handlers.iter().enumerate().rev() {
            ndfft_inplace_par(volume, handler, axis);
        }
    }

    /// Inverse transform in place, divided by the number of elements.
    pub fn inverse(&self, volume: &mut Array3<Complex<f64>>) {
        for (axis, handler) in self.handlers.iter().enumerate().rev() {
            ndifft_inplace_par(volume, handler, axis);
        }
    }
}

/// A real volume as complex numbers.
pub fn complex(volume: &Array3<f64>) -> Array3<Complex<f64>> {
    volume.mapv(|v| Complex::new(v, 0.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The transform agrees with the 3-D DFT summed directly.
    #[test]
    fn matches_direct_dft() {
        let dim = (4, 3, 5);
        let x = Array3::from_shape_fn(dim, |(a, b, c)| {
            Complex::new(
                (a * 7 + b * 3 + c) as f64 % 5.0 - 2.0,
                (a + 2 * c) as f64 * 0.1,
            )
        });
        let mut y = x.clone();
        let fft = Fft3::new(dim);
        fft.forward(&mut y);
        let tau = std::f64::consts::TAU;
        for ((ka, kb, kc), &got) in y.indexed_iter() {
            let mut want = Complex::new(0.0, 0.0);
            for ((a, b, c), &v) in x.indexed_iter() {
                let phase = -tau
                    * ((ka * a) as f64 / dim.0 as f64
                        + (kb * b) as f64 / dim.1 as f64
                        + (kc * c) as f64 / dim.2 as f64);
                want += v * Complex::from_polar(1.0, phase);
            }
            assert!(
                (got - want).norm() < 1e-10,
                "bin ({ka},{kb},{kc}): {got} vs {want}"
            );
        }
        fft.inverse(&mut y);
        for (a, b) in y.iter().zip(x.iter()) {
            assert!((a - b).norm() < 1e-12);
        }
    }
}
