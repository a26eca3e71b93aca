//! A capture summed from parts (e.g. one histogram per second of
//! acquisition), checked for parts that belong to another capture.
//!
//! A part that occurs bit for bit in two captures of one run cannot be a
//! measurement of both: an acquisition buffer that was not cleared between
//! captures leaves one capture's seconds in the next one's file. (In the
//! shared confocal-diffuse-tomography captures, seconds 120-239 of the
//! 3.0, 3.5 and 4.0 inch files are the same 120 histograms; BENCHMARKS.md.)
//! Such shared parts are kept only in the captures whose own parts they
//! agree with in shape ([`two_sample_chi2`] at most [`SHARED_PART_CHI2`]),
//! and dropped from the others; a capture with no parts of its own keeps
//! them, and the note says that nothing could be checked.

use std::collections::HashMap;
use std::hash::{Hash, Hasher};

/// Largest two-sample chi-square per degree of freedom between a
/// capture's shared parts and its own parts at which the shared parts are
/// taken as the capture's. Set from the shared captures before any fit:
/// halves and quarters of one capture differ by at most 12.5 (timing
/// drift over a minute), parts of another slab by 900 and more.
pub const SHARED_PART_CHI2: f64 = 50.0;

/// Fewest counts of a bin, in the two sums together, for the bin to enter
/// [`two_sample_chi2`] (so that its normal approximation holds).
pub const MIN_BIN_COUNTS: f64 = 50.0;

/// What the check decided for one capture.
#[derive(Debug, Clone, PartialEq)]
pub struct PartsCheck {
    /// Indices of the parts whose sum is the capture's histogram.
    pub kept: Vec<usize>,
    /// Indices of the parts that also occur in another capture.
    pub shared: Vec<usize>,
    /// The other captures (indices into the checked list) holding them.
    pub shared_with: Vec<usize>,
    /// Two-sample chi-square per degree of freedom of the shared parts'
    /// sum against the own parts' sum, with its degrees of freedom; `None`
    /// when either is empty or no bin holds enough counts.
    pub chi2_per_dof: Option<(f64, usize)>,
    /// Two-sample chi-square per degree of freedom of the first half of
    /// the kept parts against the second half: above [`SHARED_PART_CHI2`]
    /// the capture mixes measurements even where no other capture shows
    /// it (say, when it is checked alone). `None` for fewer than two parts.
    pub halves_chi2: Option<(f64, usize)>,
}

impl PartsCheck {
    /// Whether the shared parts were dropped.
    pub fn dropped_shared(&self) -> bool {
        !self.shared.is_empty() && self.shared.iter().all(|i| !self.kept.contains(i))
    }

    /// One line for the output, naming the capture by `label` and the
    /// others by `labels`.
    pub fn describe(&self, label: &str, parts: usize, labels: &[&str]) -> String {
        let halves = match self.halves_chi2 {
            Some((c, _)) if c > SHARED_PART_CHI2 => format!(
                "; WARNING: the first and second half of the kept parts differ in shape (chi2/dof {c:.1}, limit {SHARED_PART_CHI2}): parts of different measurements?"
            ),
            _ => String::new(),
        };
        if self.shared.is_empty() {
            return format!(
                "{label}: {parts} parts, none shared with another capture; all kept{halves}"
            );
        }
        let with: Vec<&str> = self.shared_with.iter().map(|&j| labels[j]).collect();
        let test = match self.chi2_per_dof {
            Some((c, dof)) => format!(
                "their shape against the capture's own parts: chi2/dof {c:.2} over {dof} degrees of freedom (limit {SHARED_PART_CHI2})"
            ),
            None => "no own parts to compare them with".into(),
        };
        let verdict = if self.dropped_shared() {
            "dropped: they belong to another capture"
        } else {
            "kept"
        };
        format!(
            "{label}: {parts} parts, {} ({}) also in {}; {test}; {verdict}; the histogram sums {} parts{halves}",
            self.shared.len(),
            ranges(&self.shared),
            with.join(", "),
            self.kept.len()
        )
    }
}

/// `1, 2, 3, 7` as `1-3, 7`.
fn ranges(ix: &[usize]) -> String {
    let mut out: Vec<String> = Vec::new();
    let mut i = 0;
    while i < ix.len() {
        let mut j = i;
        while j + 1 < ix.len() && ix[j + 1] == ix[j] + 1 {
            j += 1;
        }
        out.push(if j > i {
            format!("{}-{}", ix[i], ix[j])
        } else {
            ix[i].to_string()
        });
        i = j + 1;
    }
    out.join(", ")
}

/// Two-sample chi-square per degree of freedom of the shapes of `a` and
/// `b` (counts per bin, compared after normalising each to its total),
/// over the bins holding at least [`MIN_BIN_COUNTS`] in the two together;
/// about 1 when both are Poisson samples of one shape. `None` when a total
/// is zero or fewer than two bins qualify.
pub fn two_sample_chi2(a: &[f64], b: &[f64]) -> Option<(f64, usize)> {
    let (ta, tb): (f64, f64) = (a.iter().sum(), b.iter().sum());
    if ta <= 0.0 || tb <= 0.0 {
        return None;
    }
    let (mut chi2, mut bins) = (0.0, 0usize);
    for (&x, &y) in a.iter().zip(b) {
        if x + y < MIN_BIN_COUNTS {
            continue;
        }
        let d = x / ta - y / tb;
        chi2 += d * d / (x / (ta * ta) + y / (tb * tb));
        bins += 1;
    }
    (bins >= 2).then(|| (chi2 / (bins - 1) as f64, bins - 1))
}

fn sum(parts: &[Vec<f64>], ix: &[usize]) -> Vec<f64> {
    let mut out = vec![0.0; parts.first().map_or(0, Vec::len)];
    for &i in ix {
        out.iter_mut().zip(&parts[i]).for_each(|(o, &v)| *o += v);
    }
    out
}

/// Checks the parts of several captures of one run (`captures[c][p]`: part
/// `p` of capture `c`, counts per bin) against each other; see the
/// module's documentation.
pub fn check_parts(captures: &[Vec<Vec<f64>>]) -> Vec<PartsCheck> {
    // Parts by content: a hash of their bits, then exact comparison.
    let mut by_hash: HashMap<u64, Vec<(usize, usize)>> = HashMap::new();
    for (c, parts) in captures.iter().enumerate() {
        for (p, part) in parts.iter().enumerate() {
            let mut h = std::collections::hash_map::DefaultHasher::new();
            part.len().hash(&mut h);
            part.iter().for_each(|v| v.to_bits().hash(&mut h));
            by_hash.entry(h.finish()).or_default().push((c, p));
        }
    }
    let mut shared: Vec<Vec<usize>> = vec![Vec::new(); captures.len()];
    let mut with: Vec<Vec<usize>> = vec![Vec::new(); captures.len()];
    for holders in by_hash.values() {
        for &(c, p) in holders {
            let others: Vec<usize> = holders
                .iter()
                .filter(|&&(d, q)| d != c && captures[d][q] == captures[c][p])
                .map(|&(d, _)| d)
                .collect();
            if !others.is_empty() {
                shared[c].push(p);
                with[c].extend(others);
            }
        }
    }
    captures
        .iter()
        .enumerate()
        .map(|(c, parts)| {
            let mut shared_c = std::mem::take(&mut shared[c]);
            shared_c.sort_unstable();
            shared_c.dedup();
            let mut shared_with = std::mem::take(&mut with[c]);
            shared_with.sort_unstable();
            shared_with.dedup();
            let own: Vec<usize> = (0..parts.len())
                .filter(|p| shared_c.binary_search(p).is_err())
                .collect();
            let chi2 = if shared_c.is_empty() || own.is_empty() {
                None
            } else {
                two_sample_chi2(&sum(parts, &shared_c), &sum(parts, &own))
            };
            let keep_shared = match chi2 {
                Some((c2, _)) => c2 <= SHARED_PART_CHI2,
                None => true,
            };
            let kept = if keep_shared {
                (0..parts.len()).collect()
            } else {
                own
            };
            let (first, second) = kept.split_at(kept.len() / 2);
            let halves_chi2 = if first.is_empty() {
                None
            } else {
                two_sample_chi2(&sum(parts, first), &sum(parts, second))
            };
            PartsCheck {
                halves_chi2,
                kept,
                shared: shared_c,
                shared_with,
                chi2_per_dof: chi2,
            }
        })
        .collect()
}

/// The sum of the kept parts of one capture.
pub fn kept_sum(parts: &[Vec<f64>], check: &PartsCheck) -> Vec<f64> {
    sum(parts, &check.kept)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A peaked shape of `total` expected counts with its peak at `at`,
    /// rounded (deterministic, so that equal arguments give equal parts).
    fn part(total: f64, at: f64, wobble: f64) -> Vec<f64> {
        let shape: Vec<f64> = (0..200)
            .map(|i| (-((i as f64 - at) / 12.0).powi(2)).exp())
            .collect();
        let s: f64 = shape.iter().sum();
        shape
            .iter()
            .enumerate()
            .map(|(i, v)| {
                (total * v / s + wobble * ((i * 7 % 5) as f64 - 2.0))
                    .round()
                    .max(0.0)
            })
            .collect()
    }

    #[test]
    fn chi2_is_small_for_one_shape_and_large_for_another() {
        let a = part(1e6, 80.0, 0.0);
        let b = part(5e5, 80.0, 0.0);
        let (same, dof) = two_sample_chi2(&a, &b).unwrap();
        assert!(same < 0.1 && dof > 10, "{same} {dof}");
        let c = part(5e5, 90.0, 0.0);
        assert!(two_sample_chi2(&a, &c).unwrap().0 > 1000.0);
        assert_eq!(two_sample_chi2(&a, &[0.0; 200]), None);
    }

    #[test]
    fn stale_parts_are_dropped_where_they_do_not_fit_and_kept_where_they_do() {
        // Capture 0 (the stale parts' own) has 3 parts of its shape and the
        // 2 shared ones; capture 1 (another slab: later, wider) has 2 of its
        // own and the same 2 shared parts; capture 2 shares nothing.
        let stale = [part(1e5, 80.0, 1.0), part(1e5, 80.0, 2.0)];
        let c0 = vec![
            part(1e5, 80.0, 3.0),
            part(1e5, 80.0, 4.0),
            part(1e5, 80.0, 5.0),
            stale[0].clone(),
            stale[1].clone(),
        ];
        let c1 = vec![
            part(2e5, 100.0, 1.0),
            part(2e5, 100.0, 2.0),
            stale[0].clone(),
            stale[1].clone(),
        ];
        let c2 = vec![part(1e5, 60.0, 0.0)];
        let checks = check_parts(&[c0.clone(), c1.clone(), c2]);
        assert_eq!(checks[0].shared, vec![3, 4]);
        assert_eq!(checks[0].shared_with, vec![1]);
        assert_eq!(checks[0].kept, vec![0, 1, 2, 3, 4]);
        assert!(!checks[0].dropped_shared());
        assert_eq!(checks[1].shared, vec![2, 3]);
        assert_eq!(checks[1].kept, vec![0, 1]);
        assert!(checks[1].dropped_shared());
        assert!(checks[1].chi2_per_dof.unwrap().0 > SHARED_PART_CHI2);
        assert_eq!(checks[2].kept, vec![0]);
        assert!(checks[2].shared.is_empty());
        // The kept sum is the own parts' sum.
        let s = kept_sum(&c1, &checks[1]);
        let own: f64 = c1[0].iter().chain(&c1[1]).sum();
        assert_eq!(s.iter().sum::<f64>(), own);
        let line = checks[1].describe("b", 4, &["a", "b", "c"]);
        assert!(
            line.contains("2 (2-3) also in a") && line.contains("dropped"),
            "{line}"
        );
    }

    #[test]
    fn a_capture_mixing_measurements_is_flagged_when_checked_alone() {
        let mixed = vec![
            part(1e5, 80.0, 1.0),
            part(1e5, 80.0, 2.0),
            part(1e5, 100.0, 1.0),
            part(1e5, 100.0, 2.0),
        ];
        let check = &check_parts(&[mixed])[0];
        assert_eq!(check.kept, vec![0, 1, 2, 3]);
        assert!(check.halves_chi2.unwrap().0 > SHARED_PART_CHI2);
        assert!(check.describe("m", 4, &["m"]).contains("WARNING"));
        let even = vec![part(1e5, 80.0, 1.0), part(1e5, 80.0, 2.0)];
        let check = &check_parts(&[even])[0];
        assert!(check.halves_chi2.unwrap().0 < 1.0);
        assert!(!check.describe("e", 2, &["e"]).contains("WARNING"));
    }

    #[test]
    fn a_capture_made_only_of_shared_parts_keeps_them() {
        let p = part(1e5, 80.0, 0.0);
        let checks = check_parts(&[vec![p.clone()], vec![p.clone(), part(1e5, 120.0, 0.0)]]);
        assert_eq!(checks[0].kept, vec![0]);
        assert_eq!(checks[0].chi2_per_dof, None);
        assert!(
            checks[0]
                .describe("a", 1, &["a", "b"])
                .contains("no own parts")
        );
        assert_eq!(checks[1].kept, vec![1]);
    }
}
