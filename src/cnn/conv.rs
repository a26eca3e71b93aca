//! The 3x3 convolution engine: zero-padded NHWC feature maps, im2col over
//! bands of rows, and a GEMM per band.
//!
//! A band is a few rows of the output; its im2col matrix (pixels x 9*cin)
//! plus the weight matrix fit in a core's L2 (1 MiB here), so the GEMM reads
//! its operands from cache. Bands run in parallel under rayon, each GEMM on
//! one thread (the `gemm` crate's own threading would split work that is
//! already split). The GEMM is the `gemm` crate (pure Rust, AVX2/FMA
//! kernels): measured in `benches/denoise.rs`, see BENCHMARKS.md.

use rayon::prelude::*;

use super::FoldedConv;

/// A feature map: `h x w` pixels of `c` channels, stored NHWC with a
/// one-pixel zero border, so the 3x3 "same" convolution reads the border
/// instead of branching.
#[derive(Debug, Clone)]
pub struct FeatureMap {
    /// Height without the border.
    pub h: usize,
    /// Width without the border.
    pub w: usize,
    /// Channels.
    pub c: usize,
    /// `(h + 2) * (w + 2) * c` values; the border stays zero.
    pub data: Vec<f32>,
}

impl FeatureMap {
    /// An all-zero map.
    pub fn zeros(h: usize, w: usize, c: usize) -> Self {
        FeatureMap {
            h,
            w,
            c,
            data: vec![0.0; (h + 2) * (w + 2) * c],
        }
    }

    /// Offset of pixel `(y, x)` (unpadded coordinates) in `data`.
    #[inline]
    pub fn at(&self, y: usize, x: usize) -> usize {
        ((y + 1) * (self.w + 2) + x + 1) * self.c
    }
}

/// Output pixels per band: the band's im2col matrix of a 64-channel layer
/// (256 x 576 f32 = 576 KiB) plus the 144 KiB weight matrix fit in L2.
const BAND_PIXELS: usize = 256;

/// The bytes one thread's band of [`conv3x3`] holds on a map `width`
/// pixels wide, for a layer of `cin` -> `cout` channels: its im2col matrix
/// and product (the GEMM's packing buffers are kept by each thread from
/// its first call, not counted).
pub fn band_bytes(cin: usize, cout: usize, width: usize) -> u64 {
    let pixels = BAND_PIXELS.max(width) as u64;
    pixels * (9 * cin + cout) as u64 * 4
}

/// Applies `layer` to `input`, writing `output` (whose border stays zero).
pub fn conv3x3(layer: &FoldedConv, input: &FeatureMap, output: &mut FeatureMap) {
    assert_eq!(input.c, layer.cin);
    assert_eq!(
        (output.h, output.w, output.c),
        (input.h, input.w, layer.cout)
    );
    let (h, w) = (input.h, input.w);
    let rows_per_band = (BAND_PIXELS / w).max(1);
    let cout = layer.cout;
    let row_len = (w + 2) * cout;
    // Each band owns whole output rows (interior and border columns).
    let interior = &mut output.data[row_len..(h + 1) * row_len];
    interior
        .par_chunks_mut(rows_per_band * row_len)
        .enumerate()
        .for_each_init(
            || (Vec::new(), Vec::new()),
            |(cols, prod), (band, out_rows)| {
                let y0 = band * rows_per_band;
                let rows = out_rows.len() / row_len;
                band_conv(layer, input, y0, rows, cols, prod, out_rows);
            },
        );
}

/// One band: im2col of rows `y0..y0+rows`, GEMM, bias, ReLU, store.
fn band_conv(
    layer: &FoldedConv,
    input: &FeatureMap,
    y0: usize,
    rows: usize,
    cols: &mut Vec<f32>,
    prod: &mut Vec<f32>,
    out_rows: &mut [f32],
) {
    let (w, cin, cout) = (input.w, layer.cin, layer.cout);
    let k = 9 * cin;
    let m = rows * w;
    cols.resize(m * k, 0.0);
    prod.resize(m * cout, 0.0);
    for r in 0..rows {
        let y = y0 + r;
        for x in 0..w {
            let dst = &mut cols[(r * w + x) * k..][..k];
            for ky in 0..3 {
                // Pixels (y + ky - 1, x - 1 ..= x + 1) are contiguous in the
                // padded map: one copy of 3 * cin values per kernel row.
                let src = ((y + ky) * (w + 2) + x) * cin;
                dst[ky * 3 * cin..(ky + 1) * 3 * cin]
                    .copy_from_slice(&input.data[src..src + 3 * cin]);
            }
        }
    }
    matmul(prod, cols, &layer.matrix, (m, cout, k));
    let row_len = (w + 2) * cout;
    for r in 0..rows {
        let out = &mut out_rows[r * row_len + cout..][..w * cout];
        store_activated(layer, out, &prod[r * w * cout..][..w * cout]);
    }
}

/// Writes the layer's raw outputs `src` (whole pixels of `cout` channels)
/// into `dst` with the bias added and, for a ReLU layer, clamped at zero:
/// the last step of both convolution engines.
#[inline]
pub(crate) fn store_activated(layer: &FoldedConv, dst: &mut [f32], src: &[f32]) {
    let cout = layer.cout;
    for (o, s) in dst.chunks_exact_mut(cout).zip(src.chunks_exact(cout)) {
        match &layer.bias {
            Some(b) => o
                .iter_mut()
                .zip(s)
                .zip(b)
                .for_each(|((o, &s), &b)| *o = s + b),
            None => o.copy_from_slice(s),
        }
        if layer.relu {
            o.iter_mut().for_each(|v| *v = v.max(0.0));
        }
    }
}

/// `dst = lhs rhs` for row-major `lhs` (m x k), `rhs` (k x n) and `dst`
/// (m x n) at the slices' starts, on the calling thread (the layers run
/// their tiles on rayon's threads themselves).
pub(crate) fn matmul(dst: &mut [f32], lhs: &[f32], rhs: &[f32], (m, n, k): (usize, usize, usize)) {
    assert!(dst.len() >= m * n && lhs.len() >= m * k && rhs.len() >= k * n);
    // SAFETY: the assert: the pointers cover the three row-major matrices.
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            dst.as_mut_ptr(),
            1,
            n as isize,
            false,
            lhs.as_ptr(),
            1,
            k as isize,
            rhs.as_ptr(),
            1,
            n as isize,
            0.0,
            1.0,
            false,
            false,
            false,
            gemm::Parallelism::None,
        );
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A map of `h x w x cin` pseudo-random values in [-0.5, 0.5) and a
    /// layer `cin -> cout` from the same stream (seeded by `seed`): weights
    /// scaled by `weight_scale` and a bias when one is given, else a bias
    /// only when `relu`.
    pub(crate) fn random_case(
        seed: u32,
        h: usize,
        w: usize,
        cin: usize,
        cout: usize,
        weight_scale: Option<f32>,
        relu: bool,
    ) -> (FeatureMap, FoldedConv) {
        let mut s = seed;
        let mut next = || {
            s = s.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (s >> 8) as f32 / (1u32 << 24) as f32 - 0.5
        };
        let mut input = FeatureMap::zeros(h, w, cin);
        for y in 0..h {
            for x in 0..w {
                let at = input.at(y, x);
                for c in 0..cin {
                    input.data[at + c] = next();
                }
            }
        }
        let scale = weight_scale.unwrap_or(1.0);
        let matrix = (0..9 * cin * cout).map(|_| next() * scale).collect();
        let bias = (weight_scale.is_some() || relu).then(|| (0..cout).map(|_| next()).collect());
        let layer = FoldedConv {
            cin,
            cout,
            matrix,
            bias,
            relu,
        };
        (input, layer)
    }

    /// Direct 3x3 convolution with zero padding, the textbook loop.
    fn direct(layer: &FoldedConv, input: &FeatureMap) -> FeatureMap {
        let mut out = FeatureMap::zeros(input.h, input.w, layer.cout);
        for y in 0..input.h {
            for x in 0..input.w {
                for co in 0..layer.cout {
                    let mut acc = layer.bias.as_ref().map_or(0.0, |b| f64::from(b[co]));
                    for ky in 0..3 {
                        for kx in 0..3 {
                            let (yy, xx) = (y + ky, x + kx); // padded coordinates
                            for ci in 0..layer.cin {
                                let v = input.data[(yy * (input.w + 2) + xx) * input.c + ci];
                                let wgt = layer.matrix
                                    [((ky * 3 + kx) * layer.cin + ci) * layer.cout + co];
                                acc += f64::from(v) * f64::from(wgt);
                            }
                        }
                    }
                    let v = if layer.relu { acc.max(0.0) } else { acc };
                    let at = out.at(y, x) + co;
                    out.data[at] = v as f32;
                }
            }
        }
        out
    }

    #[test]
    fn banded_gemm_matches_direct_convolution_and_keeps_the_border_zero() {
        // Sizes that leave a partial last band and odd widths.
        for &(h, w, cin, cout, relu) in &[
            (7, 5, 5, 6, true),
            (37, 9, 8, 4, false),
            (3, 300, 3, 2, true),
        ] {
            let (input, layer) = random_case(1, h, w, cin, cout, None, relu);
            let want = direct(&layer, &input);
            let mut got = FeatureMap::zeros(h, w, cout);
            conv3x3(&layer, &input, &mut got);
            let worst = want
                .data
                .iter()
                .zip(&got.data)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0f32, f32::max);
            assert!(
                worst < 1e-5,
                "{h}x{w} {cin}->{cout}: max difference {worst}"
            );
        }
    }
}
