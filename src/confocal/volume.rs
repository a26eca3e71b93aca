//! A reconstructed hidden volume and what a person reads from it:
//! maximum-intensity projections, a depth map and the depth of the object.

use ndarray::{Array, Array2, Array3, Axis, Dimension};

/// Values over (depth behind the slab, row, column).
#[derive(Debug, Clone)]
pub struct HiddenVolume {
    /// Values, indexed (depth, row, column); non-negative.
    pub data: Array3<f64>,
    /// Depth between samples (m).
    pub depth_step_m: f64,
    /// Depth of sample 0 behind the slab's far face (m); sample `k` lies
    /// `k` steps farther.
    pub first_depth_m: f64,
    /// Side of the scanned area (m), first to last row and column.
    pub side_m: f64,
    /// What was done and assumed, for the printed notes.
    pub notes: Vec<String>,
}

/// Which maximum-intensity projection.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Projection {
    /// Over depth: rows by columns (the view through the slab).
    Front,
    /// Over rows: depth by columns (seen from above).
    Top,
    /// Over columns: depth by rows (seen from the side).
    Side,
}

/// Fraction of the front projection's maximum above which a scan point
/// belongs to the object (fixed before any scan was looked at; see
/// docs/journal/2026-11-25-nineteenth-session.md).
pub const OBJECT_LEVEL: f64 = 0.5;

impl HiddenVolume {
    /// The maximum of the volume along one axis.
    pub fn projection(&self, which: Projection) -> Array2<f64> {
        let axis = match which {
            Projection::Front => 0,
            Projection::Top => 1,
            Projection::Side => 2,
        };
        self.data
            .fold_axis(Axis(axis), f64::NEG_INFINITY, |m, &v| m.max(v))
    }

    /// Depth (m) of every scan point's brightest sample, refined to a
    /// fraction of a sample by the parabola through it and its two
    /// neighbours; the brightness at that depth beside it.
    pub fn depth_map(&self) -> (Array2<f64>, Array2<f64>) {
        let (nz, rows, cols) = self.data.dim();
        let mut depth = Array2::zeros((rows, cols));
        let mut peak = Array2::zeros((rows, cols));
        for r in 0..rows {
            for c in 0..cols {
                let lane = self.data.slice(ndarray::s![.., r, c]);
                let (k, &v) = lane
                    .iter()
                    .enumerate()
                    .fold(
                        (0, &f64::NEG_INFINITY),
                        |b, x| if x.1 > b.1 { x } else { b },
                    );
                depth[[r, c]] =
                    (k as f64 + parabola_offset(&lane.to_vec(), k, nz)) * self.depth_step_m;
                peak[[r, c]] = v;
            }
        }
        (depth, peak)
    }

    /// [`Self::object_depth`] in words (in cm), `None` for an empty
    /// volume.
    pub fn describe_object_depth(&self) -> Option<String> {
        self.object_depth().map(|d| {
            format!(
                "object depth (median over points at half the brightest or more): {:.1} cm behind the slab",
                d * crate::units::CM_PER_M
            )
        })
    }

    /// Depth of the object (m): the median refined depth over the scan
    /// points whose front projection reaches [`OBJECT_LEVEL`] of its
    /// maximum; `None` for an empty volume.
    pub fn object_depth(&self) -> Option<f64> {
        let (depth, peak) = self.depth_map();
        let top = peak.iter().fold(0.0f64, |m, &v| m.max(v));
        if top.is_nan() || top <= 0.0 {
            return None;
        }
        let mut chosen: Vec<f64> = depth
            .iter()
            .zip(peak.iter())
            .filter(|(_, p)| **p >= OBJECT_LEVEL * top)
            .map(|(d, _)| *d)
            .collect();
        chosen.sort_by(f64::total_cmp);
        let n = chosen.len();
        Some(if n % 2 == 1 {
            chosen[n / 2]
        } else {
            0.5 * (chosen[n / 2 - 1] + chosen[n / 2])
        })
    }

    /// The volume blurred by a 3-D Gaussian of standard deviation
    /// `sigma_across` voxels along rows and columns and `sigma_depth` along
    /// depth (0: not along that axis); taps past an edge are left out and
    /// the rest renormalised, so an edge is not darkened. The baseline a
    /// method must beat: projection correlation rewards smoothing.
    pub fn blurred(&self, sigma_across: f64, sigma_depth: f64) -> HiddenVolume {
        let mut data = self.data.clone();
        for (axis, sigma) in [(0, sigma_depth), (1, sigma_across), (2, sigma_across)] {
            data = blur_axis(&data, Axis(axis), sigma);
        }
        let mut notes = self.notes.clone();
        notes.push(format!(
            "then a 3-D Gaussian blur: sigma {sigma_across:.2} voxels across, {sigma_depth:.2} in depth"
        ));
        HiddenVolume {
            data,
            notes,
            ..*self
        }
    }

    /// Depth of the single brightest voxel (m), unrefined.
    pub fn brightest_depth(&self) -> f64 {
        let (mut best, mut at) = (f64::NEG_INFINITY, 0);
        for ((k, _, _), &v) in self.data.indexed_iter() {
            if v > best {
                (best, at) = (v, k);
            }
        }
        self.first_depth_m + at as f64 * self.depth_step_m
    }
}

/// `data` convolved along `axis` with a Gaussian of `sigma` samples
/// (truncated at 3 sigma, renormalised at the edges); unchanged for a
/// sigma that is not positive.
fn blur_axis(data: &Array3<f64>, axis: Axis, sigma: f64) -> Array3<f64> {
    if sigma.is_nan() || sigma <= 0.0 {
        return data.clone();
    }
    let radius = (3.0 * sigma).ceil() as isize;
    let taps: Vec<f64> = (-radius..=radius)
        .map(|d| (-0.5 * (d as f64 / sigma).powi(2)).exp())
        .collect();
    let mut out = Array3::zeros(data.dim());
    for (lane, mut dst) in data.lanes(axis).into_iter().zip(out.lanes_mut(axis)) {
        let n = lane.len() as isize;
        for i in 0..n {
            let (mut sum, mut weight) = (0.0, 0.0);
            for (t, &w) in taps.iter().enumerate() {
                let j = i + t as isize - radius;
                if (0..n).contains(&j) {
                    sum += w * lane[j as usize];
                    weight += w;
                }
            }
            dst[i as usize] = sum / weight;
        }
    }
    out
}

/// Offset (in samples, within ±0.5) of the vertex of the parabola through
/// samples `k - 1`, `k`, `k + 1` of `lane`; 0 at the ends or when flat.
fn parabola_offset(lane: &[f64], k: usize, n: usize) -> f64 {
    if k == 0 || k + 1 >= n {
        return 0.0;
    }
    let (a, b, c) = (lane[k - 1], lane[k], lane[k + 1]);
    let curvature = a - 2.0 * b + c;
    if curvature.is_nan() || curvature >= 0.0 {
        return 0.0;
    }
    (0.5 * (a - c) / curvature).clamp(-0.5, 0.5)
}

/// Pearson correlation of two equally shaped arrays of any dimension;
/// `None` when either is constant or not finite.
pub fn pearson<D: Dimension>(a: &Array<f64, D>, b: &Array<f64, D>) -> Option<f64> {
    let n = a.len() as f64;
    let (ma, mb) = (a.sum() / n, b.sum() / n);
    let (mut ab, mut aa, mut bb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b.iter()) {
        let (dx, dy) = (x - ma, y - mb);
        ab += dx * dy;
        aa += dx * dx;
        bb += dy * dy;
    }
    (aa > 0.0 && bb > 0.0).then(|| ab / (aa * bb).sqrt())
}

/// Pearson correlation of two equally sized images; 0 when either is
/// constant.
pub fn correlation(a: &Array2<f64>, b: &Array2<f64>) -> f64 {
    pearson(a, b).unwrap_or(0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pearson_is_one_for_scaled_copies_and_none_for_constants() {
        let a = Array3::from_shape_fn((4, 5, 6), |(k, r, c)| (k * 31 + r * 7 + c) as f64);
        assert!((pearson(&a, &(a.clone() * 3.0 + 1.0)).unwrap() - 1.0).abs() < 1e-12);
        assert_eq!(pearson(&a, &Array3::from_elem((4, 5, 6), 2.0)), None);
    }

    /// The parabola's vertex is exact for samples of a parabola.
    #[test]
    fn parabola_vertex_is_exact_on_a_parabola() {
        let vertex = 5.3;
        let lane: Vec<f64> = (0..10)
            .map(|k| 10.0 - (k as f64 - vertex).powi(2))
            .collect();
        let off = parabola_offset(&lane, 5, 10);
        assert!((5.0 + off - vertex).abs() < 1e-12, "{off}");
    }

    /// A bright slab of voxels at one depth gives that depth everywhere
    /// on the object, and the object's depth.
    #[test]
    fn object_depth_of_a_flat_object() {
        let mut data = Array3::zeros((20, 4, 4));
        for r in 1..3 {
            for c in 1..3 {
                data[[7, r, c]] = 2.0;
                data[[6, r, c]] = 1.0;
                data[[8, r, c]] = 1.0;
            }
        }
        let vol = HiddenVolume {
            data,
            depth_step_m: 0.01,
            first_depth_m: 0.0,
            side_m: 0.5,
            notes: vec![],
        };
        assert!((vol.object_depth().unwrap() - 0.07).abs() < 1e-12);
        assert_eq!(vol.projection(Projection::Front)[[1, 1]], 2.0);
        assert_eq!(vol.projection(Projection::Top).dim(), (20, 4));
    }

    /// An interior point spreads with the asked variance along each axis
    /// and keeps its mass; an edge point keeps its peak at the edge.
    #[test]
    fn the_blur_has_the_asked_widths_and_keeps_mass() {
        let mut data = Array3::zeros((41, 31, 31));
        data[[20, 15, 15]] = 1.0;
        let mut vol = HiddenVolume {
            data,
            depth_step_m: 0.01,
            first_depth_m: 0.0,
            side_m: 0.5,
            notes: vec![],
        };
        let b = vol.blurred(1.5, 3.0).data;
        let centre = b.slice(ndarray::s![5..36, 5..26, 5..26]);
        assert!((centre.sum() - 1.0).abs() < 1e-6, "{}", centre.sum());
        let moment = |axis: usize, mid: f64| -> f64 {
            centre
                .indexed_iter()
                .map(|(i, &v)| {
                    let x = [i.0 as f64 + 5.0, i.1 as f64 + 5.0, i.2 as f64 + 5.0][axis];
                    v * (x - mid).powi(2)
                })
                .sum()
        };
        // The variance of the Gaussian sampled at whole offsets and cut at
        // 3 sigma (a little under sigma squared).
        let variance = |sigma: f64| {
            let r = (3.0 * sigma).ceil() as i32;
            let w = |d: i32| (-0.5 * (d as f64 / sigma).powi(2)).exp();
            let total: f64 = (-r..=r).map(w).sum();
            (-r..=r).map(|d| w(d) * (d * d) as f64).sum::<f64>() / total
        };
        assert!((variance(3.0) - 9.0).abs() < 0.3);
        assert!(
            (moment(0, 20.0) - variance(3.0)).abs() < 1e-9,
            "{}",
            moment(0, 20.0)
        );
        assert!(
            (moment(1, 15.0) - variance(1.5)).abs() < 1e-9,
            "{}",
            moment(1, 15.0)
        );
        assert!(
            (moment(2, 15.0) - variance(1.5)).abs() < 1e-9,
            "{}",
            moment(2, 15.0)
        );
        assert_eq!(vol.blurred(0.0, 0.0).data, vol.data);
        vol.data.fill(0.0);
        vol.data[[0, 0, 0]] = 1.0;
        let b = vol.blurred(1.5, 3.0).data;
        assert!(b[[0, 0, 0]] > b[[1, 0, 0]] && b[[0, 0, 0]] > b[[0, 1, 1]]);
        assert!(b.iter().all(|v| v.is_finite() && *v >= 0.0));
    }

    #[test]
    fn correlation_of_affine_copies_is_one() {
        let a = Array2::from_shape_fn((3, 4), |(i, j)| (i * 4 + j) as f64);
        let b = a.mapv(|v| 3.0 * v + 1.0);
        assert!((correlation(&a, &b) - 1.0).abs() < 1e-12);
        assert_eq!(correlation(&a, &Array2::zeros((3, 4))), 0.0);
    }
}
