//! The kept bins' kernels as combinations of a few orthonormal kernels.
//!
//! The ST-PSF changes smoothly from bin to bin, so the K kernels of a stack
//! span far fewer than K dimensions: on the paper preset the 20 kept bins'
//! kernels are matched to 1e-9 of their norm by 11 orthonormal kernels
//! (BENCHMARKS.md). A whole-stack operator then needs one transform per
//! basis kernel instead of one per bin: `H_k o = sum_j A_kj (Q_j * o)`
//! takes r inverse FFTs and a K x r combination per pixel, and
//! `sum_k H_k^T r_k = sum_j Q_j^T (sum_k A_kj r_k)` r forward FFTs. The
//! dropped part of every bin's kernel is below [`BASIS_TOLERANCE`] of that
//! kernel's norm, far below the counts' noise and the double-precision
//! guard of the Richardson-Lucy ratio; where the basis would need as many
//! kernels as bins it is not used.
//!
//! The basis comes from Gram-Schmidt with pivoting on the kernels' spectra
//! (Parseval's inner product): each step takes the bin worst matched so
//! far, so the worst bin's error, not an average, decides the rank.

use rayon::prelude::*;
use rustfft::num_complex::Complex64;

use crate::forward::ForwardModel;

/// Largest relative L2 error allowed for any bin's kernel.
pub const BASIS_TOLERANCE: f64 = 1e-9;

/// The kept bins' kernels of a [`ForwardModel`] spanned by `rank`
/// orthonormal kernels, or the kernels themselves where that saves nothing.
pub struct TimeBasis<'a> {
    model: &'a ForwardModel,
    /// Model kernel index of each bin.
    bins: Vec<usize>,
    /// The orthonormal kernels' spectra; empty when the bins' own kernels
    /// are used.
    spectra: Vec<Vec<Complex64>>,
    /// `coefficients[b][j]`: bin `b`'s kernel is `sum_j c_bj Q_j`.
    coefficients: Vec<Vec<f64>>,
    /// Largest relative L2 error of a bin's kernel.
    worst_error: f64,
}

impl<'a> TimeBasis<'a> {
    /// The basis of `model`'s kernels `bins` to relative error `tolerance`
    /// per bin (use [`BASIS_TOLERANCE`]); the bins' own kernels if the basis
    /// needs as many kernels as there are bins.
    pub fn new(model: &'a ForwardModel, bins: &[usize], tolerance: f64) -> Self {
        let weights = model.fft().parseval_weights();
        let dot = |a: &[Complex64], b: &[Complex64]| -> f64 {
            a.iter()
                .zip(b)
                .zip(&weights)
                .map(|((x, y), w)| w * (x.re * y.re + x.im * y.im))
                .sum()
        };
        let norms: Vec<f64> = bins
            .iter()
            .map(|&k| dot(model.spectrum(k), model.spectrum(k)).sqrt())
            .collect();
        let mut residuals: Vec<Vec<Complex64>> =
            bins.iter().map(|&k| model.spectrum(k).to_vec()).collect();
        let mut spectra: Vec<Vec<Complex64>> = Vec::new();
        let relative = |r: &[Complex64], n: f64| if n > 0.0 { dot(r, r).sqrt() / n } else { 0.0 };
        let mut worst_error = 0.0;
        while spectra.len() < bins.len() {
            let (pivot, error) = residuals
                .iter()
                .zip(&norms)
                .map(|(r, &n)| relative(r, n))
                .enumerate()
                .fold(
                    (0, 0.0),
                    |best, (b, e)| if e > best.1 { (b, e) } else { best },
                );
            worst_error = error;
            if error <= tolerance {
                break;
            }
            // Orthogonalise the pivot's residual once more against the
            // basis (round-off), normalise it, and remove it from every
            // bin's residual.
            let mut q = residuals[pivot].clone();
            for p in &spectra {
                let c = dot(p, &q);
                q.iter_mut().zip(p).for_each(|(x, y)| *x -= y * c);
            }
            let n = dot(&q, &q).sqrt();
            if !n.is_normal() {
                // Nothing left to add (round-off): the error stays as it is.
                break;
            }
            q.iter_mut().for_each(|x| *x /= n);
            residuals.par_iter_mut().for_each(|r| {
                let c = dot(&q, r);
                r.iter_mut().zip(&q).for_each(|(x, y)| *x -= y * c);
            });
            spectra.push(q);
        }
        if spectra.len() >= bins.len() {
            return Self {
                model,
                bins: bins.to_vec(),
                spectra: Vec::new(),
                coefficients: Vec::new(),
                worst_error: 0.0,
            };
        }
        let coefficients = bins
            .iter()
            .map(|&k| spectra.iter().map(|q| dot(q, model.spectrum(k))).collect())
            .collect();
        Self {
            model,
            bins: bins.to_vec(),
            spectra,
            coefficients,
            worst_error,
        }
    }

    /// Kernels transformed per direction: the basis's rank, or the number
    /// of bins where the bins' own kernels are used.
    pub fn rank(&self) -> usize {
        if self.spectra.is_empty() {
            self.bins.len()
        } else {
            self.spectra.len()
        }
    }

    /// Largest relative L2 error of a bin's kernel (0 for the bins' own).
    pub fn worst_error(&self) -> f64 {
        self.worst_error
    }

    /// What the basis left out, for traces.
    pub fn note(&self) -> String {
        if self.spectra.is_empty() {
            return format!(
                "{} bins, each transformed with its own kernel (a basis would need as many kernels)",
                self.bins.len()
            );
        }
        format!(
            "the {} bins' kernels spanned by {} orthonormal kernels (every bin's kernel within {:.1e} of its norm, tolerance {BASIS_TOLERANCE:e}): {} transforms per direction left out",
            self.bins.len(),
            self.spectra.len(),
            self.worst_error,
            self.bins.len() - self.spectra.len()
        )
    }

    /// `H_k o` on the sensor window for every bin, from one forward
    /// transform of `o` (on the grid) and [`Self::rank`] inverse ones.
    pub fn forward(&self, o: &[f64]) -> Vec<Vec<f64>> {
        let model = self.model;
        let spec = model.fft().forward(o);
        if self.spectra.is_empty() {
            return self
                .bins
                .par_iter()
                .map(|&k| model.apply_spectrum(k, &spec))
                .collect();
        }
        let parts: Vec<Vec<f64>> = self
            .spectra
            .par_iter()
            .map(|q| model.apply_spectrum_with(q, &spec))
            .collect();
        let parts: Vec<&[f64]> = parts.iter().map(Vec::as_slice).collect();
        mix(&parts, &self.coefficients)
    }

    /// `sum_k H_k^T r_k` on the grid for sensor-window images `r` (one per
    /// bin; `None` for a bin that back-projects zero): [`Self::rank`]
    /// forward transforms and one inverse.
    pub fn adjoint_sum(&self, r: &[Option<Vec<f64>>]) -> Vec<f64> {
        let model = self.model;
        let fft = model.fft();
        let spectra: Vec<Vec<Complex64>> = if self.spectra.is_empty() {
            self.bins
                .par_iter()
                .zip(r)
                .filter_map(|(&k, rk)| rk.as_ref().map(|rk| model.adjoint_spectrum(k, rk)))
                .collect()
        } else {
            let lit: Vec<&[f64]> = r.iter().flatten().map(Vec::as_slice).collect();
            // weights[j][i]: the coefficient of basis kernel j in the i-th
            // bin with counts.
            let weights: Vec<Vec<f64>> = (0..self.spectra.len())
                .map(|j| {
                    r.iter()
                        .zip(&self.coefficients)
                        .filter(|(rk, _)| rk.is_some())
                        .map(|(_, c)| c[j])
                        .collect()
                })
                .collect();
            let mixed = mix(&lit, &weights);
            self.spectra
                .par_iter()
                .zip(&mixed)
                .map(|(q, x)| model.adjoint_spectrum_with(q, x))
                .collect()
        };
        let mut acc = vec![Complex64::default(); fft.spectrum_len()];
        for spec in spectra {
            acc.iter_mut().zip(&spec).for_each(|(a, s)| *a += s);
        }
        fft.inverse(acc)
    }
}

/// Pixels per block of [`mix`]: a block of every input fits the second-
/// level cache, so each input and output streams through memory once.
const MIX_BLOCK: usize = 1024;

/// Pixels [`mix`] sums in registers at once.
const LANES: usize = 8;

/// `out_i = sum_j weights[i][j] inputs[j]`, pixel by pixel, for images of
/// equal length. Blocked over pixels and spread over threads: done output
/// by output, the images would stream through memory once per output and
/// cost more than the transforms the basis saves (measured).
fn mix(inputs: &[&[f64]], weights: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let len = inputs.first().map_or(0, |x| x.len());
    let mut outputs = vec![vec![0.0; len]; weights.len()];
    let mut blocks: Vec<Vec<&mut [f64]>> =
        (0..len.div_ceil(MIX_BLOCK)).map(|_| Vec::new()).collect();
    for out in &mut outputs {
        for (block, part) in blocks.iter_mut().zip(out.chunks_mut(MIX_BLOCK)) {
            block.push(part);
        }
    }
    blocks
        .into_par_iter()
        .enumerate()
        .for_each(|(b, mut outs)| {
            let base = b * MIX_BLOCK;
            for (out, w) in outs.iter_mut().zip(weights) {
                // Eight pixels at a time, summed over the inputs in registers
                // (one store per pixel instead of one per pixel and input).
                let n = out.len();
                let mut lanes = out.chunks_exact_mut(LANES);
                for (g, group) in lanes.by_ref().enumerate() {
                    let at = base + g * LANES;
                    let mut acc = [0.0; LANES];
                    for (x, &c) in inputs.iter().zip(w) {
                        let x: &[f64; LANES] = x[at..at + LANES].try_into().expect("LANES values");
                        acc.iter_mut().zip(x).for_each(|(a, v)| *a += c * v);
                    }
                    group.copy_from_slice(&acc);
                }
                let rest = lanes.into_remainder();
                let at = base + n - rest.len();
                for (i, o) in rest.iter_mut().enumerate() {
                    *o = inputs.iter().zip(w).map(|(x, &c)| c * x[at + i]).sum();
                }
            }
        });
    outputs
}
