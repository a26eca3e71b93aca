//! Numerical Hessians and small matrix inverses for the fits' standard
//! errors (the inverse of the negative log-likelihood's Hessian).

/// Hessian of `f` at `x` by central differences with per-coordinate
/// steps `steps`: `2 k^2 + 1` evaluations for `k` coordinates.
pub fn numerical_hessian(f: &dyn Fn(&[f64]) -> f64, x: &[f64], steps: &[f64]) -> Vec<Vec<f64>> {
    let k = x.len();
    let at = |d: &[(usize, f64)]| {
        let mut q = x.to_vec();
        for &(i, h) in d {
            q[i] += h;
        }
        f(&q)
    };
    let centre = at(&[]);
    let mut hess = vec![vec![0.0; k]; k];
    for a in 0..k {
        for b in a..k {
            let (ha, hb) = (steps[a], steps[b]);
            let v = if a == b {
                (at(&[(a, ha)]) - 2.0 * centre + at(&[(a, -ha)])) / (ha * ha)
            } else {
                (at(&[(a, ha), (b, hb)]) - at(&[(a, ha), (b, -hb)]) - at(&[(a, -ha), (b, hb)])
                    + at(&[(a, -ha), (b, -hb)]))
                    / (4.0 * ha * hb)
            };
            hess[a][b] = v;
            hess[b][a] = v;
        }
    }
    hess
}

/// Inverse of a small square matrix by Gauss-Jordan elimination with
/// partial pivoting; `None` when it is singular or not finite.
pub fn invert(m: &[Vec<f64>]) -> Option<Vec<Vec<f64>>> {
    let n = m.len();
    let mut a: Vec<Vec<f64>> = m
        .iter()
        .enumerate()
        .map(|(i, row)| {
            let mut r = row.clone();
            r.extend((0..n).map(|j| if i == j { 1.0 } else { 0.0 }));
            r
        })
        .collect();
    for c in 0..n {
        let piv = (c..n).max_by(|&x, &y| a[x][c].abs().total_cmp(&a[y][c].abs()))?;
        let p = a[piv][c].abs();
        if p.is_nan() || p < 1e-300 {
            return None;
        }
        a.swap(c, piv);
        let d = a[c][c];
        a[c].iter_mut().for_each(|v| *v /= d);
        let row = a[c].clone();
        for (r, other) in a.iter_mut().enumerate() {
            if r != c {
                let f = other[c];
                other.iter_mut().zip(&row).for_each(|(v, w)| *v -= f * w);
            }
        }
    }
    Some(a.into_iter().map(|r| r[n..].to_vec()).collect())
}

/// Standard error of coordinate `i` from the inverse Hessian `inverse`:
/// `None` when there is no inverse, the variance is not positive and
/// finite, or the error exceeds `bound` (the data do not determine it).
pub fn standard_error(inverse: Option<&Vec<Vec<f64>>>, i: usize, bound: f64) -> Option<f64> {
    let var = inverse?[i][i];
    (var.is_finite() && var > 0.0 && var.sqrt() <= bound).then(|| var.sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quadratic_hessian_and_inverse_are_exact() {
        // f = x^T M x / 2 with M = [[4, 1], [1, 3]].
        let f = |v: &[f64]| 0.5 * (4.0 * v[0] * v[0] + 2.0 * v[0] * v[1] + 3.0 * v[1] * v[1]);
        let h = numerical_hessian(&f, &[0.3, -0.7], &[1e-3, 1e-3]);
        for (row, want) in h.iter().zip([[4.0, 1.0], [1.0, 3.0]]) {
            for (a, b) in row.iter().zip(want) {
                assert!((a - b).abs() < 1e-6, "{a} vs {b}");
            }
        }
        let inv = invert(&h).unwrap();
        // M^-1 = [[3, -1], [-1, 4]] / 11.
        assert!((inv[0][0] - 3.0 / 11.0).abs() < 1e-6);
        assert!((inv[0][1] + 1.0 / 11.0).abs() < 1e-6);
        assert!(invert(&[vec![1.0, 2.0], vec![2.0, 4.0]]).is_none());
    }
}
