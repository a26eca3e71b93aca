//! Richardson-Lucy on the time-summed stack, stopped by cross-validation,
//! continued over the growing snapshots of one acquisition: the live
//! view's reconstruction.
//!
//! The cross-validated stop ([`super::rl_sum`]) runs RL on two thinned
//! halves of the counts, each scored on the other's. A snapshot continues
//! the last one's two searches instead of starting from the flat object:
//! each half is the last snapshot's half plus a thinned half of the photons
//! that arrived since, and starts from its own estimate there, scaled to
//! its light. Each half's estimate has then only ever seen its own half's
//! photons, so the score on the other half stays a score on counts it never
//! saw, and the search needs the steps the new photons call for rather than
//! all of them again.

use std::cell::RefCell;

use ndarray::{Array2, ArrayView2, Axis};

use super::data::Data;
use super::em::{Acceleration, CvBest};
use super::error::ReconstructError;
use super::problem::Problem;
use super::rl_sum::{RlOperator, search_halves, thinned_halves};
use super::run::{Estimate, Reconstruction, Reconstructor, Run, WorkShape};
use super::trace::TraceRow;
use crate::poisson::thinning::{THINNING_SEED, thin_halves};

/// The searches of the snapshots of one acquisition so far.
#[derive(Debug, Default)]
pub struct Series {
    last: Option<Last>,
}

/// What a snapshot's search leaves for the next one.
#[derive(Debug)]
struct Last {
    /// The summed counts its halves were made from.
    summed: Array2<f64>,
    /// Its two halves of them.
    halves: [Array2<f64>; 2],
    /// Each half's estimate at the best iteration, on the model's grid.
    points: Vec<Vec<f64>>,
    /// The model's grid.
    grid: (usize, usize),
    /// Snapshots reconstructed in the series (each thins its new photons
    /// with a seed of its own).
    snapshots: u64,
    /// Iterations the search scored (its start included).
    searched: usize,
    /// The most iterations it could take.
    max_iters: usize,
}

impl Series {
    /// A series with no snapshot yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Iterations the last snapshot's search ran (scored iterations, the
    /// start included) when it stopped by itself, before its cap: about
    /// what the next one needs.
    pub fn stopped_after(&self) -> Option<usize> {
        self.last
            .as_ref()
            .filter(|l| l.searched <= l.max_iters)
            .map(|l| l.searched)
    }

    /// Reconstructs `problem` (a snapshot of the acquisition the series
    /// follows: its counts only ever grow) by RL on its summed bins,
    /// stopped by cross-validation within `max_iters` iterations, continuing
    /// the last snapshot's searches where the grid is the same and no
    /// count went down (else afresh, and the trace says why). Scored
    /// against `truth` when given; each trace row goes to `on_iter`.
    pub fn reconstruct(
        &mut self,
        problem: &Problem,
        max_iters: usize,
        truth: Option<ArrayView2<f64>>,
        mut on_iter: impl FnMut(&TraceRow),
    ) -> Result<Reconstruction, ReconstructError> {
        let all = problem.all_bins();
        let data = Data::new(&problem.model, &problem.counts, &all)?;
        let step = Continued {
            last: RefCell::new(&mut self.last),
            max_iters,
        };
        step.run(&data, truth, &mut on_iter)
    }
}

/// One snapshot's search, as a method.
struct Continued<'s> {
    last: RefCell<&'s mut Option<Last>>,
    max_iters: usize,
}

impl Reconstructor for Continued<'_> {
    fn name(&self, _bins: usize) -> &'static str {
        "rl-sum"
    }

    fn reconstruct(
        &self,
        data: &Data<'_>,
        run: &mut Run<'_>,
    ) -> Result<Estimate, ReconstructError> {
        let model = data.model;
        let rl = RlOperator::new(model, data.bins);
        let summed = data.counts.sum_axis(Axis(0));
        let mut last = self.last.borrow_mut();
        let previous = last.take();
        if summed.sum() == 0.0 || rl.mass <= 0.0 {
            return Ok(run.no_photons(model.sensor_shape()));
        }
        let grid = model.grid_shape();
        let (halves, start, how, snapshots) = match previous {
            Some(p)
                if p.grid == grid
                    && p.summed.dim() == summed.dim()
                    && summed.iter().zip(&p.summed).all(|(n, o)| n >= o) =>
            {
                let since = &summed - &p.summed;
                let seed = THINNING_SEED.wrapping_add(p.snapshots);
                let (a, b) = thin_halves(&since, seed, "the counts since the last snapshot")?;
                let halves = [&p.halves[0] + &a, &p.halves[1] + &b];
                // Each estimate scaled by its half's light (less its
                // background) then and now.
                let (h, w) = model.sensor_shape();
                let bg = model.background() * data.bins.len() as f64 / 2.0 * (h * w) as f64;
                let start = p
                    .points
                    .into_iter()
                    .zip(p.halves.iter().zip(&halves))
                    .map(|(mut point, (then, now))| {
                        let gain = (now.sum() - bg) / (then.sum() - bg);
                        let gain = if gain.is_finite() && gain > 0.0 {
                            gain
                        } else {
                            now.sum() / then.sum()
                        };
                        point.iter_mut().for_each(|v| *v *= gain);
                        point
                    })
                    .collect();
                let how = format!(
                    "continued from the last snapshot's two searches: each half is its half there plus a thinned half of the {} photons since (seed {seed:#x}), {} and {} photons in all, and starts from its own estimate there scaled to its light (each is still scored on counts it never saw)",
                    since.sum(),
                    halves[0].sum(),
                    halves[1].sum()
                );
                (halves, Some(start), how, p.snapshots + 1)
            }
            previous => {
                if previous.is_some() {
                    run.note(
                        "started afresh: the grid changed or some count went down since the last snapshot (not the same acquisition)",
                    );
                }
                let (halves, how) = thinned_halves(&summed)?;
                (halves, None, how, 1)
            }
        };
        let CvBest {
            iteration,
            image,
            points,
        } = search_halves(
            data,
            &rl,
            [&halves[0], &halves[1]],
            start,
            &how,
            (self.max_iters, Acceleration::None),
            true,
            run,
        );
        **last = Some(Last {
            summed,
            halves,
            points,
            grid,
            snapshots,
            searched: run.rows().len(),
            max_iters: self.max_iters,
        });
        Ok(Estimate { image, iteration })
    }

    /// Plain rl-sum's working memory, and what the series keeps: the
    /// summed counts, their two halves (sensor) and each half's estimate
    /// (grid).
    fn working_bytes(&self, shape: &WorkShape) -> u64 {
        shape.bytes([0; 3], [64 + 24, 80 + 16, 64])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::forward::{ForwardModel, poisson_counts};
    use crate::metrics::psnr_fitted;
    use crate::physics::Preset;
    use crate::reconstruct::em::tests::paper_disks;
    use crate::reconstruct::method::{Method, MethodOptions, run_method};

    /// The problem of `counts` on `model`.
    fn problem(model: &ForwardModel, counts: &ndarray::Array3<f64>) -> Problem {
        Problem {
            model: model.clone(),
            counts: counts.clone(),
            bin_starts_ps: Vec::new(),
            setup: Preset::Paper.setup(),
            left_out: Vec::new(),
        }
    }

    /// Snapshots of one acquisition: the counts of a run at growing
    /// exposures, each the last plus new Poisson counts.
    fn snapshots(model: &ForwardModel, truth: &Array2<f64>, n: usize) -> Vec<ndarray::Array3<f64>> {
        let mut sum = None::<ndarray::Array3<f64>>;
        (0..n)
            .map(|i| {
                let part =
                    poisson_counts(&model.expected((truth * 2.0).view()).counts, 11 + i as u64);
                let s = match sum.take() {
                    Some(s) => s + part,
                    None => part,
                };
                sum = Some(s.clone());
                s
            })
            .collect()
    }

    /// Continued over growing snapshots, the search needs fewer
    /// iterations than afresh on the last one, and its output is as good
    /// (within 0.3 dB, after the gain that fits the truth).
    #[test]
    fn a_continued_search_needs_fewer_iterations_and_is_as_good() {
        let (model, truth) = paper_disks(32);
        let stacks = snapshots(&model, &truth, 4);
        let mut series = Series::new();
        let mut continued = None;
        for counts in &stacks {
            let p = problem(&model, counts);
            continued = Some(series.reconstruct(&p, 1000, None, |_| {}).unwrap());
        }
        let continued = continued.unwrap();
        let last = problem(&model, &stacks[3]);
        let afresh = Series::new()
            .reconstruct(&last, 1000, None, |_| {})
            .unwrap();
        let rows = |r: &Reconstruction| r.trace.rows.len();
        assert!(
            rows(&continued) * 2 < rows(&afresh),
            "iterations: {} continued, {} afresh",
            rows(&continued),
            rows(&afresh)
        );
        assert!(
            continued
                .trace
                .notes
                .iter()
                .any(|n| n.contains("continued from")),
            "{:?}",
            continued.trace.notes
        );
        let psnr = |image: &Array2<f64>| psnr_fitted(image.view(), truth.view()).unwrap();
        let (c, a) = (psnr(&continued.image), psnr(&afresh.image));
        assert!(c > a - 0.3, "PSNR {c:.2} continued, {a:.2} afresh");
        // Afresh, the series is rl-sum with its cross-validated stop.
        let rl_sum = run_method(
            &last,
            Method::RlSum,
            None,
            &crate::denoise::NoPrior,
            &MethodOptions::default(),
            None,
            |_| {},
        )
        .unwrap();
        assert_eq!(rl_sum.image, afresh.image);
    }

    /// A snapshot whose counts went down (another acquisition) starts
    /// afresh, and says so.
    #[test]
    fn counts_that_go_down_start_afresh() {
        let (model, truth) = paper_disks(16);
        let stacks = snapshots(&model, &truth, 2);
        let (more, fewer) = (problem(&model, &stacks[1]), problem(&model, &stacks[0]));
        let afresh = Series::new()
            .reconstruct(&fewer, 200, None, |_| {})
            .unwrap();
        let mut series = Series::new();
        series.reconstruct(&more, 200, None, |_| {}).unwrap();
        let restarted = series.reconstruct(&fewer, 200, None, |_| {}).unwrap();
        assert!(
            restarted
                .trace
                .notes
                .iter()
                .any(|n| n.contains("started afresh")),
            "{:?}",
            restarted.trace.notes
        );
        assert_eq!(restarted.image, afresh.image);
    }
}
