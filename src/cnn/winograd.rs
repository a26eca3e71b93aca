//! Winograd F(4x4, 3x3) for the wide inner layers (Lavin and Gray, 2016):
//! each 4x4 output tile costs 36 multiplies per channel pair instead of 144.
//!
//! Per block of tiles: the input transform `B^T d B` turns each 6x6 input
//! patch into 36 values per channel, 36 GEMMs (tiles x cin times cin x cout)
//! multiply them by the transformed weights `G g G^T`, and the output
//! transform `A^T m A` gives the 4x4 outputs, with bias and ReLU. The
//! transforms run over whole channel vectors (NHWC), which the compiler
//! vectorises. Interpolation points 0, +-1, +-2: in f32 the result agrees
//! with direct convolution to about 1e-6 relative (tested).

use rayon::prelude::*;

use super::FoldedConv;
use super::conv::{FeatureMap, matmul, store_activated};

/// G (6x3): weight transform.
const G: [[f64; 3]; 6] = [
    [1.0 / 4.0, 0.0, 0.0],
    [-1.0 / 6.0, -1.0 / 6.0, -1.0 / 6.0],
    [-1.0 / 6.0, 1.0 / 6.0, -1.0 / 6.0],
    [1.0 / 24.0, 1.0 / 12.0, 1.0 / 6.0],
    [1.0 / 24.0, -1.0 / 12.0, 1.0 / 6.0],
    [0.0, 0.0, 1.0],
];

/// Tile budget per block. A block is as many whole rows of tiles as fit
/// in it, at least one (one row of 40 for a 160-wide map, the 320 x 320
/// grid unshuffled), so that it owns whole output rows and writes them in
/// place. Within the budget the block's transformed input and products
/// (36 x 64 x 64 f32 each, 576 KiB) stay in L2/L3 between the three steps;
/// a map wider than 256 pixels makes a one-row block larger.
const BLOCK_TILES: usize = 64;

/// Transformed weights of one layer: 36 row-major `cin x cout` matrices.
#[derive(Debug, Clone)]
pub struct WinogradWeights {
    /// `u[e * cin * cout + ci * cout + co]`, `e = 6 * xi + nu`.
    pub u: Vec<f32>,
}

/// `G g G^T` for every channel pair of `layer` (computed in f64).
pub fn transform_weights(layer: &FoldedConv) -> WinogradWeights {
    let (cin, cout) = (layer.cin, layer.cout);
    let mut u = vec![0f32; 36 * cin * cout];
    for ci in 0..cin {
        for co in 0..cout {
            let g = |ky: usize, kx: usize| {
                f64::from(layer.matrix[((ky * 3 + kx) * cin + ci) * cout + co])
            };
            for xi in 0..6 {
                for nu in 0..6 {
                    let mut acc = 0.0;
                    for (ky, gy) in G[xi].iter().enumerate() {
                        for (kx, gx) in G[nu].iter().enumerate() {
                            acc += gy * g(ky, kx) * gx;
                        }
                    }
                    u[(xi * 6 + nu) * cin * cout + ci * cout + co] = acc as f32;
                }
            }
        }
    }
    WinogradWeights { u }
}

/// `B^T x` for six vectors (one column of the 6x6 patch), in place per lane.
#[inline(always)]
fn bt6(x: [&[f32]; 6], out: [&mut [f32]; 6]) {
    let [o0, o1, o2, o3, o4, o5] = out;
    for i in 0..x[0].len() {
        let (d0, d1, d2, d3, d4, d5) = (x[0][i], x[1][i], x[2][i], x[3][i], x[4][i], x[5][i]);
        o0[i] = 4.0 * d0 - 5.0 * d2 + d4;
        o1[i] = -4.0 * (d1 + d2) + d3 + d4;
        o2[i] = 4.0 * (d1 - d2) - d3 + d4;
        o3[i] = -2.0 * (d1 - d3) - d2 + d4;
        o4[i] = 2.0 * (d1 - d3) - d2 + d4;
        o5[i] = 4.0 * d1 - 5.0 * d3 + d5;
    }
}

/// `A^T x` for six vectors into four.
#[inline(always)]
fn at4(x: [&[f32]; 6], out: [&mut [f32]; 4]) {
    let [o0, o1, o2, o3] = out;
    for i in 0..x[0].len() {
        let (m0, m1, m2, m3, m4, m5) = (x[0][i], x[1][i], x[2][i], x[3][i], x[4][i], x[5][i]);
        let (s12, d12, s34, d34) = (m1 + m2, m1 - m2, m3 + m4, m3 - m4);
        o0[i] = m0 + s12 + s34;
        o1[i] = d12 + 2.0 * d34;
        o2[i] = s12 + 4.0 * s34;
        o3[i] = d12 + 8.0 * d34 + m5;
    }
}

/// Applies `layer` (with its transformed weights `wino`) to `input`,
/// writing `output`'s interior.
pub fn conv3x3_winograd(
    layer: &FoldedConv,
    wino: &WinogradWeights,
    input: &FeatureMap,
    output: &mut FeatureMap,
) {
    let (h, w, cin, cout) = (input.h, input.w, layer.cin, layer.cout);
    assert_eq!(input.c, cin);
    assert_eq!((output.h, output.w, output.c), (h, w, cout));
    let tx = w.div_ceil(4);
    // A block is `tile_rows` rows of tiles and owns the 4 * tile_rows output
    // rows they cover (the last block fewer), so it writes them in place:
    // no per-block output buffer and no serial scatter afterwards (they
    // were a memset and a memmove of the whole map per layer).
    let tile_rows = (BLOCK_TILES / tx).max(1);
    let row_len = (w + 2) * cout;
    let interior = &mut output.data[row_len..(h + 1) * row_len];
    interior
        .par_chunks_mut(4 * tile_rows * row_len)
        .enumerate()
        .for_each_init(
            || (Vec::new(), Vec::new(), Vec::new()),
            |(v, m, scratch), (b, out_rows)| {
                let t0 = b * tile_rows * tx;
                let nt = (out_rows.len() / row_len).div_ceil(4) * tx;
                block(layer, wino, input, t0, nt, tx, v, m, scratch, out_rows);
            },
        );
}

#[allow(clippy::too_many_arguments)]
fn block(
    layer: &FoldedConv,
    wino: &WinogradWeights,
    input: &FeatureMap,
    t0: usize,
    nt: usize,
    tx: usize,
    v: &mut Vec<f32>,
    m: &mut Vec<f32>,
    scratch: &mut Vec<f32>,
    out_rows: &mut [f32],
) {
    let (h, w, cin, cout) = (input.h, input.w, layer.cin, layer.cout);
    let c = cin.max(cout);
    v.resize(36 * nt * cin, 0.0);
    m.resize(36 * nt * cout, 0.0);
    // scratch: the 6x6 patch, then the column-transformed patch (36 c each).
    scratch.resize(2 * 36 * c, 0.0);
    let (patch, tmp) = scratch.split_at_mut(36 * c);
    let zero = vec![0f32; cin];
    let pw = w + 2;
    for k in 0..nt {
        let t = t0 + k;
        // Top-left of the 6x6 patch in padded coordinates.
        let (py, px) = (4 * (t / tx), 4 * (t % tx));
        // A patch inside the padded map is read in place (its rows are
        // contiguous there); only edge patches are copied, with zeros
        // beyond the map. The copies were 36 small memmove calls per tile.
        let inside = py + 6 <= h + 2 && px + 6 <= pw;
        let (src, row_stride) = if inside {
            (&input.data[(py * pw + px) * cin..], pw * cin)
        } else {
            for i in 0..6 {
                for j in 0..6 {
                    let (y, x) = (py + i, px + j);
                    let src = if y < h + 2 && x < pw {
                        &input.data[(y * pw + x) * cin..][..cin]
                    } else {
                        &zero[..]
                    };
                    patch[(i * 6 + j) * cin..][..cin].copy_from_slice(src);
                }
            }
            (&patch[..], 6 * cin)
        };
        // Columns: tmp[i][j] = sum_r B^T[i][r] patch[r][j].
        for j in 0..6 {
            let col: [&[f32]; 6] = std::array::from_fn(|r| &src[r * row_stride + j * cin..][..cin]);
            let mut outs = split6(tmp, j, cin);
            bt6(col, outs.each_mut().map(|o| &mut **o));
        }
        // Rows: v[i][j] = sum_r tmp[i][r] B[r][j], stored at e = 6 i + j.
        for i in 0..6 {
            let row: [&[f32]; 6] = std::array::from_fn(|r| &tmp[(i * 6 + r) * cin..][..cin]);
            let mut outs: [&mut [f32]; 6] = split_row(v, i, k, nt, cin);
            bt6(row, outs.each_mut().map(|o| &mut **o));
        }
    }
    for e in 0..36 {
        matmul(
            &mut m[e * nt * cout..],
            &v[e * nt * cin..],
            &wino.u[e * cin * cout..],
            (nt, cout, cin),
        );
    }
    // scratch, reused: the 4x6 column-transformed products, then the 4x4
    // output tile.
    let (tmp4, rest) = scratch.split_at_mut(24 * c);
    let tile = &mut rest[..16 * cout];
    let row_len = (w + 2) * cout;
    let rows = out_rows.len() / row_len;
    for k in 0..nt {
        // Columns: tmp4[a][j] = sum_r A^T[a][r] m[r][j]  (4 x 6).
        for j in 0..6 {
            let col: [&[f32]; 6] =
                std::array::from_fn(|r| &m[((r * 6 + j) * nt + k) * cout..][..cout]);
            let mut outs: [&mut [f32]; 4] = split4(tmp4, j, cout);
            at4(col, outs.each_mut().map(|o| &mut **o));
        }
        // Rows: y[a][b] = sum_r tmp4[a][r] A[r][b].
        for a in 0..4 {
            let row: [&[f32]; 6] = std::array::from_fn(|r| &tmp4[(a * 6 + r) * cout..][..cout]);
            let mut outs: [&mut [f32]; 4] = {
                let (r0, rest) = tile[a * 4 * cout..(a + 1) * 4 * cout].split_at_mut(cout);
                let (r1, rest) = rest.split_at_mut(cout);
                let (r2, r3) = rest.split_at_mut(cout);
                [r0, r1, r2, r3]
            };
            at4(row, outs.each_mut().map(|o| &mut **o));
        }
        // Bias, ReLU and the store into this block's output rows (tile
        // pixels past the map's edge are dropped).
        let (y0, x0) = (4 * (k / tx), 4 * (k % tx));
        let nx = 4.min(w - x0);
        for dy in 0..4.min(rows - y0) {
            store_activated(
                layer,
                &mut out_rows[(y0 + dy) * row_len + (x0 + 1) * cout..][..nx * cout],
                &tile[dy * 4 * cout..][..nx * cout],
            );
        }
    }
}

// split6, split4 and split_row are kept apart on purpose: one generic
// helper taking the offsets as a closure measured 8 % slower on
// `conv3x3_64x64_128x128_winograd` (2.7 -> 3.0 ms).

/// Mutable views of `tmp[i][j]` for i in 0..6 at column `j` (6x6 of `c`).
fn split6(tmp: &mut [f32], j: usize, c: usize) -> [&mut [f32]; 6] {
    let mut rest = &mut tmp[..36 * c];
    let mut out: Vec<&mut [f32]> = Vec::with_capacity(6);
    let mut offset = 0;
    for i in 0..6 {
        let start = (i * 6 + j) * c - offset;
        let (_, tail) = rest.split_at_mut(start);
        let (cur, tail) = tail.split_at_mut(c);
        out.push(cur);
        rest = tail;
        offset = (i * 6 + j + 1) * c;
    }
    out.try_into().map_err(|_| ()).expect("six views")
}

/// Mutable views of `tmp[a][j]` for a in 0..4 at column `j` (4x6 of `c`).
fn split4(tmp: &mut [f32], j: usize, c: usize) -> [&mut [f32]; 4] {
    let mut rest = &mut tmp[..24 * c];
    let mut out: Vec<&mut [f32]> = Vec::with_capacity(4);
    let mut offset = 0;
    for a in 0..4 {
        let start = (a * 6 + j) * c - offset;
        let (_, tail) = rest.split_at_mut(start);
        let (cur, tail) = tail.split_at_mut(c);
        out.push(cur);
        rest = tail;
        offset = (a * 6 + j + 1) * c;
    }
    out.try_into().map_err(|_| ()).expect("four views")
}

/// Mutable views of `v[e = 6 i + j][tile k]` for j in 0..6.
fn split_row(v: &mut [f32], i: usize, k: usize, nt: usize, c: usize) -> [&mut [f32]; 6] {
    let mut rest = &mut v[..];
    let mut out: Vec<&mut [f32]> = Vec::with_capacity(6);
    let mut offset = 0;
    for j in 0..6 {
        let start = ((i * 6 + j) * nt + k) * c - offset;
        let (_, tail) = rest.split_at_mut(start);
        let (cur, tail) = tail.split_at_mut(c);
        out.push(cur);
        rest = tail;
        offset = ((i * 6 + j) * nt + k + 1) * c;
    }
    out.try_into().map_err(|_| ()).expect("six views")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cnn::conv::conv3x3;
    use crate::cnn::conv::tests::random_case;

    #[test]
    fn winograd_matches_im2col_on_sizes_that_leave_partial_tiles() {
        for &(h, w, cin, cout, relu) in &[
            (9, 7, 16, 8, true),
            (128, 128, 64, 64, true),
            (13, 30, 8, 16, false),
        ] {
            let (input, layer) = random_case(7, h, w, cin, cout, Some(0.2), relu);
            let mut want = FeatureMap::zeros(h, w, cout);
            conv3x3(&layer, &input, &mut want);
            let mut got = FeatureMap::zeros(h, w, cout);
            conv3x3_winograd(&layer, &transform_weights(&layer), &input, &mut got);
            let worst = want
                .data
                .iter()
                .zip(&got.data)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0f32, f32::max);
            let scale = want.data.iter().fold(0.0f32, |m, v| m.max(v.abs()));
            assert!(
                worst < 2e-6 * scale.max(1.0) * 4.0,
                "{h}x{w} {cin}->{cout}: {worst} (scale {scale})"
            );
        }
    }
}
