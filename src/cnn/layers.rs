//! The layers besides 3x3 convolutions that the learned reconstruction's
//! network uses, each as PyTorch computes it: `nn.AvgPool2d(2)` (floor
//! of odd sizes), `nn.Upsample(scale_factor=2, mode="nearest")` and
//! `torch.cat` along channels. Maps keep the engine's zero border.

use super::conv::FeatureMap;

/// The mean of each 2 x 2 block (`AvgPool2d(2)`): `h / 2 x w / 2`, a last
/// odd row or column dropped as PyTorch drops it.
pub fn avg_pool2(input: &FeatureMap) -> FeatureMap {
    let (h, w, c) = (input.h / 2, input.w / 2, input.c);
    let mut out = FeatureMap::zeros(h, w, c);
    for y in 0..h {
        for x in 0..w {
            let o = out.at(y, x);
            let corners = [
                input.at(2 * y, 2 * x),
                input.at(2 * y, 2 * x + 1),
                input.at(2 * y + 1, 2 * x),
                input.at(2 * y + 1, 2 * x + 1),
            ];
            for ch in 0..c {
                let s: f32 = corners.iter().map(|&i| input.data[i + ch]).sum();
                out.data[o + ch] = 0.25 * s;
            }
        }
    }
    out
}

/// Each pixel repeated over a 2 x 2 block, to `h x w` (the size of the
/// map a pooled one came from: an odd size repeats the last pixel once
/// more, where PyTorch's caller pads to even sizes first).
pub fn upsample2(input: &FeatureMap, h: usize, w: usize) -> FeatureMap {
    let c = input.c;
    let mut out = FeatureMap::zeros(h, w, c);
    for y in 0..h {
        for x in 0..w {
            let src = input.at((y / 2).min(input.h - 1), (x / 2).min(input.w - 1));
            let dst = out.at(y, x);
            out.data[dst..dst + c].copy_from_slice(&input.data[src..src + c]);
        }
    }
    out
}

/// `a`'s channels, then `b`'s, per pixel (`torch.cat([a, b], dim=1)`).
pub fn concat(a: &FeatureMap, b: &FeatureMap) -> FeatureMap {
    assert_eq!((a.h, a.w), (b.h, b.w), "maps of one size");
    let c = a.c + b.c;
    let mut out = FeatureMap::zeros(a.h, a.w, c);
    for y in 0..a.h {
        for x in 0..a.w {
            let (o, ia, ib) = (out.at(y, x), a.at(y, x), b.at(y, x));
            out.data[o..o + a.c].copy_from_slice(&a.data[ia..ia + a.c]);
            out.data[o + a.c..o + c].copy_from_slice(&b.data[ib..ib + b.c]);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map(h: usize, w: usize, c: usize, f: impl Fn(usize, usize, usize) -> f32) -> FeatureMap {
        let mut m = FeatureMap::zeros(h, w, c);
        for y in 0..h {
            for x in 0..w {
                let at = m.at(y, x);
                for ch in 0..c {
                    m.data[at + ch] = f(y, x, ch);
                }
            }
        }
        m
    }

    #[test]
    fn pooling_averages_blocks_and_upsampling_repeats_them() {
        let m = map(5, 4, 2, |y, x, c| (y * 10 + x) as f32 + 100.0 * c as f32);
        let p = avg_pool2(&m);
        assert_eq!((p.h, p.w, p.c), (2, 2, 2));
        // Block (1, 0): rows 2-3, columns 0-1: (20 + 21 + 30 + 31) / 4.
        assert_eq!(p.data[p.at(1, 0)], 25.5);
        assert_eq!(p.data[p.at(1, 0) + 1], 125.5);
        let u = upsample2(&p, 4, 4);
        assert_eq!(u.data[u.at(3, 1)], 25.5);
        assert_eq!(u.data[u.at(0, 3) + 1], p.data[p.at(0, 1) + 1]);
        // The border stays zero.
        assert!(u.data[..(u.w + 2) * u.c].iter().all(|&v| v == 0.0));
        let cat = concat(&m, &map(5, 4, 1, |_, _, _| -1.0));
        assert_eq!(cat.c, 3);
        let at = cat.at(4, 3);
        assert_eq!(&cat.data[at..at + 3], &[43.0, 143.0, -1.0]);
    }
}
