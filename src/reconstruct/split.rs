//! Exact-splitting Poisson Plug-and-Play ADMM (P4IP: Rond, Giryes and Elad,
//! "Poisson inverse problems by the Plug-and-Play scheme", 2016), adapted to
//! the stack and to a sensor with edges.
//!
//! Variables: the object `o` on the model's grid, one `z_k = H_k o` per kept
//! bin and `v = o`, with scaled duals `a_k` and `b`:
//!
//! ```text
//! o <- (sum_k rho_k H_k^T H_k + gamma)^-1 (sum_k rho_k H_k^T (z_k - a_k) + gamma (v - b))
//! z_k <- prox of the Poisson term at H_k o + a_k     (per pixel and bin, closed form)
//! v <- D_sigma(o + b) projected onto v >= 0
//! a_k <- a_k + H_k o - z_k,   b <- b + o - v
//! ```
//!
//! The output is `v`. A prior that works on a 2x2 pixel-unshuffled grid
//! (FFDNet) leaves a faint 2x2 pattern there, at the Nyquist frequency,
//! which the blur does not pass, so the data never correct it; with
//! `average_prior_grid` the prior is averaged over the grid's four
//! positions (4 denoiser calls per iteration; an option, BENCHMARKS.md).
//!
//! - The o-update is exact: every operator is a convolution on the grid, so
//!   it is a division in the Fourier domain by `sum_k rho_k |K_k|^2 + gamma`
//!   (the kernel part computed once).
//! - The z-update minimises `z - m log z + rho/2 (z - t)^2`, whose minimiser
//!   is the positive root of `rho z^2 + (1 - rho t) z - m = 0`; it is exact
//!   for zero counts (`max(t - 1/rho, 0)`) and for the stiff early bins, and
//!   needs no surrogate logarithm.
//! - Sensor edges (Almeida and Figueiredo, "Deconvolving images with unknown
//!   boundaries using the alternating direction method of multipliers",
//!   2013): `z_k` outside the sensor window is unobserved and left free, so
//!   there it equals `H_k o` and its dual stays 0.
//!
//! Scales, so that one set of defaults serves every scene and light level:
//! with the flat object `o_flat` that explains the total count, bin masses
//! `mass_k` and their total `M`,
//! - `rho_k = rho / (mass_k o_flat)`: the Poisson curvature `1/z` at the
//!   flat object's counts (`rho` = 1; 0.3 and 3 converged slower);
//! - `gamma = g M / o_flat`: `g = rho` would give prior and data equal
//!   weight at zero frequency; `g` = 0.03, fixed;
//! - sigma (the denoiser's noise level, object units) starts at
//!   `sigma0 o_flat` (0.5) and shrinks by `sigma_decay` (0.85) per iteration
//!   down to `sigma_floor o_flat n^-sigma_power` with `n = o_flat M` the
//!   photons per pixel of the flat object (3.2 and 0.25), never above its
//!   start: the prior weakens as the light grows. Up to `(3.2 / 0.5)^4`,
//!   about 1680 photons per pixel of the flat object, the floor is the
//!   start and sigma stays at `sigma0 o_flat` (on the benchmark's images:
//!   at the paper's light and below); it falls with brighter light. (The
//!   power 0.5, sigma following the relative Poisson noise, and floors of
//!   0.8 and 1.6 did worse on the tuning images, most at 10x the light;
//!   3.2 was chosen on the 16 tuning images of the second round, six of
//!   which the prior has never seen.)
//!
//! Start: `o`, `v` and `z_k = H_k o` start from the flat object, or with
//! `warm_start` > 0 from that many Richardson-Lucy iterations on the
//! time-summed stack, on the sensor window, with the flat level beyond it.
//! The split's own path fits a sparse scene's counts slowly and leaves
//! light on its dark background, where RL's multiplicative steps keep it
//! dark: 50 iterations (about a third of a second at the paper's size)
//! gained 2.3-5.0 dB on the held-out point and star fields, but cost
//! 0.3-1.8 dB on sharp edges on black, the mock acquisitions included, so
//! the default stays the flat start (BENCHMARKS.md, "eighth session").
//!
//! Stopping, without the truth: at the floor, the run stops once the
//! deviance of `H o` has been within `target_z` (1) noise standard
//! deviations of what Poisson noise alone gives for `patience` (15)
//! iterations, else at the cap (80); the trace says which, and says so when
//! the deviance never reached the noise level. The output is `v`.
//! Every default above was chosen on the tuning images of the benchmark
//! (BENCHMARKS.md, "Held-out reconstruction benchmark") and judged on the
//! held-out ones.
//!
//! One iteration costs `2 K + 2` FFTs of the grid (K forward transforms of
//! `z_k - a_k`, one of `v - b`, one inverse for `o`, K inverse for `H_k o`)
//! plus one denoiser call: about one likelihood gradient of Algorithm 1,
//! against tens of gradients per L-BFGS o-update. The 2 K per-bin transforms
//! run in single precision (the prox, the duals, `o` and `v` in double):
//! on the tuning images every PSNR, SSIM, deviance and stopping iteration
//! came out the same to four decimals, about 4 % faster (BENCHMARKS.md).

use std::time::Instant;

use ndarray::parallel::prelude::*;
use ndarray::{Array2, Array3, Axis};
use rustfft::num_complex::{Complex32, Complex64};

use super::data::{Data, flat_level};
use super::discrepancy::ExpectedDeviance;
use super::error::ReconstructError;
use super::rl_sum::rl_steps;
use super::run::{Estimate, Reconstructor, Run, WorkShape, grid_note};
use super::trace::TraceRow;
use crate::denoise::{Denoiser, denoise_scaled, denoise_scaled_grid_average};
use crate::fft2::Fft2;
use crate::forward::ForwardModel;
use crate::poisson::deviance::m_log_m;

/// Parameters of the exact-splitting solver. The command line's split
/// flags are these fields (their docs are the flags' help; one
/// `--max-iters` caps both solvers).
#[derive(Debug, Clone, Copy)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
#[cfg_attr(
    feature = "cli",
    command(next_help_heading = "Split solver (--solver split)")
)]
pub struct SplitOptions {
    /// Data penalty rho, relative to the Poisson curvature at the flat
    /// object's counts.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = SplitOptions::default().rho))]
    pub rho: f64,
    /// Prior penalty gamma, relative to the data's weight at frequency 0.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = SplitOptions::default().gamma))]
    pub gamma: f64,
    /// The prior's first sigma, relative to the flat object's level.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = SplitOptions::default().sigma0))]
    pub sigma0: f64,
    /// Sigma shrinks by this factor per iteration, down to its floor.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = SplitOptions::default().sigma_decay))]
    pub sigma_decay: f64,
    /// The prior's last sigma: `sigma_floor o_flat n^-sigma_power` with
    /// `n = o_flat M` the photons per pixel of the flat object (M the total
    /// kernel mass), so it falls as the light grows; never above the first
    /// sigma.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = SplitOptions::default().sigma_floor))]
    pub sigma_floor: f64,
    /// How fast the last sigma falls with the light (0.5: as the relative
    /// Poisson noise); see --sigma-floor.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = SplitOptions::default().sigma_power))]
    pub sigma_power: f64,
    /// Deviance target: the deviance may lie this many noise standard
    /// deviations above its expectation under Poisson noise.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = SplitOptions::default().target_z))]
    pub target_z: f64,
    /// Iterations at a sigma that meets the target before stopping.
    #[cfg_attr(feature = "cli", arg(long = "split-patience", id = "split_patience", value_name = "SPLIT_PATIENCE", default_value_t = SplitOptions::default().patience))]
    pub patience: usize,
    /// Iteration cap.
    #[cfg_attr(feature = "cli", arg(skip = SplitOptions::default().max_iters))]
    pub max_iters: usize,
    /// Richardson-Lucy iterations on the time-summed stack that give the
    /// starting object (0: the flat object).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = SplitOptions::default().warm_start))]
    pub warm_start: usize,
    /// The learned prior on its fixed 2x2 grid, or averaged over its four
    /// positions, so that the grid leaves no pattern in the blur's null
    /// space (4 denoiser calls per iteration instead of 1, 3x the time;
    /// +0.3 dB on average, BENCHMARKS.md). Applies to a denoiser that
    /// unshuffles its input onto a grid (FFDNet).
    #[cfg_attr(feature = "cli", arg(long = "prior-grid", value_name = "PRIOR_GRID", action = clap::ArgAction::Set, default_value = "fixed", value_parser = clap::builder::TypedValueParser::map(clap::builder::PossibleValuesParser::new(["fixed", "average"]), |grid: String| grid == "average")))]
    pub average_prior_grid: bool,
}

impl Default for SplitOptions {
    fn default() -> Self {
        Self {
            rho: 1.0,
            gamma: 0.03,
            sigma0: 0.5,
            sigma_decay: 0.85,
            sigma_floor: 3.2,
            sigma_power: 0.25,
            target_z: 1.0,
            patience: 15,
            max_iters: 80,
            warm_start: 0,
            average_prior_grid: false,
        }
    }
}

/// Share of the total kernel mass below which a bin is left out when it
/// holds no count or a modelled background explains its counts (its data
/// term moves the answer by less than this).
pub const NEGLIGIBLE_BIN: f64 = 1e-4;

/// Share of the total kernel mass below which a bin is left out even with
/// counts and no background: its light is beyond what double precision
/// resolves against the other bins (its Poisson weight `1/mass` would
/// overflow). Its counts cannot come from the model; the output says how
/// many there were.
pub const UNRESOLVED_BIN: f64 = 1e-12;

/// Per-bin state of the data split, on the sensor window except `q`.
struct BinState {
    counts: Vec<f64>,
    /// `m log m` of each count, for the deviance check.
    m_log_m: Vec<f64>,
    /// `rho_k`.
    rho: f64,
    z: Vec<f64>,
    a: Vec<f64>,
    /// The grid image the o-update needs: `z_k - a_k` on the window and
    /// `H_k o` outside it (where `z_k` is free). The inverse transform of
    /// `H_k o` is written here, the z-update reads the window and puts
    /// `z_k - a_k` back, so no grid image is copied. Single precision and
    /// in units of the flat object's level (so that no count scale can
    /// overflow it), as `spec` and `kernel`: their round-off (about 1e-7 of
    /// each bin's largest value) is far below the Poisson noise, and the
    /// transforms ran about 4 % faster; the prox, the duals and the
    /// o-update stay in double precision.
    q: Vec<f32>,
    /// Reused spectrum buffer.
    spec: Vec<Complex32>,
    /// The bin's kernel spectrum.
    kernel: Vec<Complex32>,
}

/// The starting object on the grid: `iterations` Richardson-Lucy steps on
/// the time-summed stack on the sensor window and the flat level `flat`
/// beyond it, or the flat object for none. (Beyond the window RL divides
/// by the little light the sensor sees of those pixels, and a start taken
/// from there made the split diverge at 0.1x the light.)
fn warm_start(
    model: &ForwardModel,
    counts: &Array3<f64>,
    bins: &[usize],
    iterations: usize,
    flat: f64,
    run: &mut Run<'_>,
) -> Array2<f64> {
    let flat_start = || Array2::from_elem(model.grid_shape(), flat);
    if iterations == 0 {
        return flat_start();
    }
    let start = Instant::now();
    let mut rl = run.sub_run("rl-sum", false);
    let start_steps = rl_steps(model, counts, bins, iterations, &mut rl);
    match start_steps {
        Some(o) if o.iter().all(|x| x.is_finite()) => {
            run.note(format!(
                "start: {iterations} Richardson-Lucy iterations on the time-summed stack on the sensor window, the flat level beyond it ({:.2} s)",
                start.elapsed().as_secs_f64()
            ));
            model.embed(o.view(), flat)
        }
        _ => {
            run.note(
                "start: the flat object (Richardson-Lucy on the time-summed stack gave no finite start)",
            );
            flat_start()
        }
    }
}

/// A double-precision spectrum value in single precision.
#[inline]
fn single(x: Complex64) -> Complex32 {
    Complex32::new(x.re as f32, x.im as f32)
}

/// Minimiser of `z - m log z + rho/2 (z - t)^2` over `z >= 0`: the positive
/// root of `rho z^2 + (1 - rho t) z - m = 0`, written so that neither branch
/// cancels digits.
///
/// Both branches are computed and one is selected, so that loops over it
/// vectorise; for `m = 0` and `b < 0` the second branch is exactly 0.
#[inline]
pub fn poisson_prox(m: f64, t: f64, rho: f64) -> f64 {
    let b = rho * t - 1.0;
    let root = (b * b + 4.0 * rho * m).sqrt();
    let upper = (b + root) / (2.0 * rho);
    // root - b >= 2 |b| > 0 when b < 0; max keeps b >= 0 (unused) finite.
    let lower = 2.0 * m / (root - b).max(f64::MIN_POSITIVE);
    if b >= 0.0 { upper } else { lower }
}

/// The exact-splitting PnP-ADMM with `denoiser` as its prior.
pub struct Split<'a> {
    /// The prior.
    pub denoiser: &'a dyn Denoiser,
    /// Its settings.
    pub opts: SplitOptions,
}

impl Reconstructor for Split<'_> {
    fn name(&self, bins: usize) -> &'static str {
        if bins == 1 { "pnp-slice" } else { "pnp" }
    }

    fn reconstruct(
        &self,
        data: &Data<'_>,
        run: &mut Run<'_>,
    ) -> Result<Estimate, ReconstructError> {
        pnp_split(data, self.denoiser, &self.opts, run)
    }

    /// Per bin: its counts, their `m log m`, the split variables `z` and
    /// the multipliers on the sensor (f64), its image on the grid (f32),
    /// its spectrum and kernel (complex f32). Shared: the object, the
    /// prior's iterate and their copies on the grid, their spectra, the
    /// threads' scratch; and the prior's own.
    fn working_bytes(&self, shape: &WorkShape) -> u64 {
        pnp_working_bytes(shape, self.denoiser, 0)
    }
}

/// A PnP solver's working memory (see [`Split`]'s), with `grid_extra`
/// more bytes per grid pixel, and its prior's own.
pub(super) fn pnp_working_bytes(
    shape: &WorkShape,
    denoiser: &dyn Denoiser,
    grid_extra: u64,
) -> u64 {
    let (gh, gw) = shape.grid;
    shape
        .bytes([32, 4, 16], [0, 128 + grid_extra, 96])
        .saturating_add(denoiser.working_bytes(gh, gw))
}

/// Runs the exact-splitting PnP-ADMM on `data`.
fn pnp_split(
    data: &Data<'_>,
    denoiser: &dyn Denoiser,
    opts: &SplitOptions,
    run: &mut Run<'_>,
) -> Result<Estimate, ReconstructError> {
    let (model, counts, bins) = (data.model, data.counts, data.bins);
    let (h, w) = model.sensor_shape();
    let (gh, gw) = model.grid_shape();
    let n = gh * gw;
    let fft = model.fft();
    run.set_prior(denoiser.name());
    run.note(grid_note(model));
    let total: f64 = counts.sum();
    let total_mass: f64 = bins.iter().map(|&k| model.mass(k)).sum();
    if total == 0.0 {
        return Ok(run.no_photons((h, w)));
    }
    // Bins whose kernels carry a negligible share of the light (the first
    // picoseconds, or IRF-spread tails) cannot change the answer when they
    // hold no count or a background explains their counts: left out.
    let bg = model.background();
    // The counts of the bins used: the flat object explains them (the
    // left-out bins' background counts are not its light).
    let (mut used, mut used_counts, mut unexplained) = (Vec::new(), 0.0, 0.0);
    for (i, &k) in bins.iter().enumerate() {
        let share = model.mass(k) / total_mass;
        let held: f64 = counts.index_axis(Axis(0), i).sum();
        if share >= NEGLIGIBLE_BIN || (bg == 0.0 && held > 0.0 && share >= UNRESOLVED_BIN) {
            used.push((i, k));
            used_counts += held;
        } else if bg == 0.0 {
            unexplained += held;
        }
    }
    if used.len() < bins.len() {
        let why = if bg > 0.0 {
            "without a count or whose counts the background explains"
        } else {
            "without a count"
        };
        run.note(format!(
            "left out {} bin(s) {why}, whose kernels carry less than {NEGLIGIBLE_BIN:e} of the light each",
            bins.len() - used.len()
        ));
    }
    if unexplained > 0.0 {
        run.note(format!(
            "left out {unexplained} counts in bins whose kernels carry less than {UNRESOLVED_BIN:e} of the light: no light of the model reaches them (a background not modelled, or a time window the physics does not match)"
        ));
    }
    run.note(format!(
        "solver: exact splitting (P4IP), {} FFTs and one denoiser call per iteration",
        2 * used.len() + 2
    ));
    // Background counts per pixel and bin: the data are Poisson(H o + bg).
    run.note_background(model);
    let flat = flat_level(used_counts, bg, used.len(), total_mass, h * w);
    // Precision of the data split per frequency, without rho:
    // sum_k |K_k|^2 / (mass_k o_flat).
    let mut kernel_power = vec![0.0f64; fft.spectrum_len()];
    for &(_, k) in &used {
        let scale = 1.0 / (model.mass(k) * flat);
        kernel_power
            .iter_mut()
            .zip(model.spectrum(k))
            .for_each(|(p, s)| *p += s.norm_sqr() * scale);
    }
    let gamma_unit = total_mass / flat;
    let average_grid = opts.average_prior_grid && denoiser.unshuffles();
    if average_grid {
        run.note(
            "the prior is averaged over its 2x2 grid's four positions (4 denoiser calls per iteration)",
        );
    }
    let o0 = warm_start(model, counts, bins, opts.warm_start, flat, run);
    let o0_spec = fft.forward(o0.as_slice().expect("standard layout"));
    let fft32 = Fft2::<f32>::new(gh, gw);
    // The per-bin single-precision images hold values / unit.
    let unit = if flat.is_finite() && flat > 0.0 {
        flat
    } else {
        1.0
    };
    let mut states: Vec<BinState> = used
        .iter()
        .map(|&(i, k)| {
            let m = counts.index_axis(Axis(0), i);
            let ho = fft.inverse(
                o0_spec
                    .iter()
                    .zip(model.spectrum(k))
                    .map(|(a, b)| a * b)
                    .collect(),
            );
            BinState {
                counts: m.iter().copied().collect(),
                m_log_m: m.iter().map(|&c| m_log_m(c)).collect(),
                rho: opts.rho / (model.mass(k) * flat),
                z: model.crop_vec(&ho),
                a: vec![0.0; h * w],
                q: ho.iter().map(|&x| (x / unit) as f32).collect(),
                spec: vec![Complex32::default(); fft.spectrum_len()],
                kernel: model.spectrum(k).iter().map(|&x| single(x)).collect(),
            }
        })
        .collect();
    let mut v = o0;
    let mut b = vec![0.0f64; n];
    let (mut vb, mut o) = (vec![0.0f64; n], vec![0.0f64; n]);
    let mut ob = Array2::<f64>::zeros((gh, gw));
    let mut o_spec = vec![Complex64::default(); fft.spectrum_len()];
    let mut o_spec32 = vec![Complex32::default(); fft.spectrum_len()];
    let gamma = opts.gamma * gamma_unit;
    // The prior starts at sigma0 o_flat and never rises above it; it
    // anneals down to the floor that the photon noise sets.
    let mut sigma = opts.sigma0 * flat;
    let photons_per_pixel = flat * total_mass;
    let sigma_floor =
        (opts.sigma_floor * flat * photons_per_pixel.powf(-opts.sigma_power)).min(sigma);
    let mut held = 0usize;
    let mut stopped = format!("iteration cap {}", opts.max_iters);
    let mut last_z = f64::INFINITY;
    let deviance = ExpectedDeviance::shared();
    let mut row0 = run.row(0);
    run.score(&mut row0, model.crop(v.view()).view());
    run.push(row0);
    let (oy, ox) = model.sensor_offset();
    for it in 1..=opts.max_iters {
        // o-update: exact, in the Fourier domain.
        states.par_iter_mut().for_each(|s| {
            fft32.forward_into(&s.q, &mut s.spec);
            let rho = (s.rho * unit) as f32;
            for (x, k) in s.spec.iter_mut().zip(&s.kernel) {
                *x = *x * k.conj() * rho;
            }
        });
        // The grid and spectrum buffers below are reused across iterations.
        vb.iter_mut()
            .zip(v.iter().zip(&b))
            .for_each(|(x, (vj, bj))| *x = vj - bj);
        fft.forward_into(&vb, &mut o_spec);
        o_spec.iter_mut().for_each(|x| *x *= gamma);
        for s in &states {
            o_spec
                .iter_mut()
                .zip(&s.spec)
                .for_each(|(a, x)| *a += Complex64::new(x.re.into(), x.im.into()));
        }
        o_spec
            .iter_mut()
            .zip(&kernel_power)
            .for_each(|(x, p)| *x /= opts.rho * p + gamma);
        // The z-update's copy of o's spectrum, in the per-bin images'
        // precision and units, made once for all bins; the inverse
        // transform then uses o_spec as its scratch.
        o_spec32
            .iter_mut()
            .zip(&o_spec)
            .for_each(|(x, &a)| *x = single(a / unit));
        fft.inverse_into(&mut o_spec, &mut o);
        // z-update and data duals, per bin.
        // The deviance check (a logarithm and a table lookup per pixel and
        // bin) only matters once sigma has reached its floor, where it
        // decides when to stop; before that it is left out.
        let at_floor = sigma <= sigma_floor;
        let sums: Vec<(f64, f64, f64)> = states
            .par_iter_mut()
            .map(|s| {
                for (x, (a, k)) in s.spec.iter_mut().zip(o_spec32.iter().zip(&s.kernel)) {
                    *x = a * k;
                }
                fft32.inverse_into(&mut s.spec, &mut s.q);
                let (mut d, mut e, mut var) = (0.0, 0.0, 0.0);
                for r in 0..h {
                    // H_k o on this window row; replaced by z_k - a_k.
                    let q = &mut s.q[(oy + r) * gw + ox..(oy + r) * gw + ox + w];
                    let span = r * w..(r + 1) * w;
                    let m = &s.counts[span.clone()];
                    if at_floor {
                        let mlm = &s.m_log_m[span.clone()];
                        for ((&mj, &lj), &yj) in m.iter().zip(mlm).zip(q.iter()) {
                            let (dj, f, g) = deviance.point_with(mj, lj, f64::from(yj) * unit + bg);
                            d += dj;
                            e += f;
                            var += g;
                        }
                    }
                    // Branch-free, so that it vectorises.
                    for (((qj, &mj), zj), aj) in q
                        .iter_mut()
                        .zip(m)
                        .zip(&mut s.z[span.clone()])
                        .zip(&mut s.a[span])
                    {
                        let y = f64::from(*qj) * unit;
                        // With y' = z + bg the term is the plain Poisson
                        // prox at t + bg.
                        let z = poisson_prox(mj, y + *aj + bg, s.rho) - bg;
                        *aj += y - z;
                        *zj = z;
                        *qj = ((z - *aj) / unit) as f32;
                    }
                }
                (d, e, var)
            })
            .collect();
        // Summed in bin order, so that runs are reproducible.
        let (dev, expected, variance) = sums
            .iter()
            .fold((0.0, 0.0, 0.0), |x, y| (x.0 + y.0, x.1 + y.1, x.2 + y.2));
        // v-update: the prior at the noise level of its input, and v >= 0.
        ob.iter_mut()
            .zip(o.iter().zip(&b))
            .for_each(|(x, (oj, bj))| *x = oj + bj);
        let mut v_new = if average_grid {
            denoise_scaled_grid_average(denoiser, ob.view(), sigma)
        } else {
            denoise_scaled(denoiser, ob.view(), sigma).image
        };
        v_new.mapv_inplace(|x| x.max(0.0));
        let (mut primal, mut dual) = (0.0, 0.0);
        for (((bj, &oj), &vn), &vo) in b.iter_mut().zip(&o).zip(&v_new).zip(&v) {
            *bj += oj - vn;
            primal += (oj - vn) * (oj - vn);
            dual += (vn - vo) * (vn - vo);
        }
        v = v_new;
        if v.iter().any(|x| !x.is_finite()) {
            return Err(run.non_finite(it));
        }
        let mut row = TraceRow {
            primal_residual: Some((primal / n as f64).sqrt()),
            dual_residual: Some(gamma * (dual / n as f64).sqrt()),
            sigma: Some(sigma),
            lambda: Some(gamma),
            deviance: at_floor.then_some(dev),
            expected_deviance: at_floor.then_some(expected),
            deviance_sd: at_floor.then_some(variance.sqrt()),
            ..run.row(it)
        };
        if run.scores() {
            run.score(&mut row, model.crop(v.view()).view());
        }
        run.push(row);
        // The prior weakens to its floor; then the run stops once the data
        // step's estimate explains the counts as well as Poisson noise
        // allows for `patience` iterations.
        if sigma > sigma_floor {
            sigma = (sigma * opts.sigma_decay).max(sigma_floor);
            continue;
        }
        last_z = (dev - expected) / variance.sqrt().max(f64::MIN_POSITIVE);
        if last_z > opts.target_z {
            held = 0;
        } else {
            held += 1;
            if held >= opts.patience {
                stopped = format!(
                    "the deviance met the noise level (at most {} standard deviations above its expectation) for {} iterations at sigma {:.4}",
                    opts.target_z, opts.patience, sigma
                );
                break;
            }
        }
    }
    run.note(format!("stopped: {stopped}"));
    if last_z.is_infinite() {
        run.note(format!(
            "sigma had not reached its floor {sigma_floor:.4} at the iteration cap; the deviance was not checked"
        ));
    } else if last_z > opts.target_z {
        run.note(format!(
            "the deviance did not reach the noise level: {last_z:.1} noise standard deviations above its expectation at the last iteration (the model or the physics may not match the data, or more iterations are needed)"
        ));
    }
    let iteration = run.rows().len() - 1;
    run.note(format!("output: iteration {iteration}"));
    Ok(Estimate {
        image: model.crop(v.view()),
        iteration,
    })
}
