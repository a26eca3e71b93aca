//! The discretised ST-PSF: one kernel image per time bin.
//!
//! Each kernel pixel holds the expected photon count that a unit object
//! pixel at offset (0, 0) sends into the sensor pixel at offset (dx, dy)
//! during the bin. By default the kernel is integrated over each pixel's area
//! (exactly, with erf, because the ST-PSF factorises into Gaussians in x and y)
//! and over the bin's duration (adaptive Gauss-Kronrod in `v = sqrt(t)`, which
//! removes the `t^(-1/2)` singularity at `t = 0` when `z0 = 0`). Point
//! sampling at pixel and bin centres is offered for comparison; it is wrong
//! where the kernel is narrower than a pixel (early bins).
//!
//! With an instrument response ([`crate::irf`]) the time integral runs over
//! every arrival time that can be recorded in the bin, weighted by the
//! probability that it is: the ST-PSF convolved in time with the IRF, then
//! integrated over the bin, in one quadrature. With a measured table the
//! arrivals are cut into cells on which the chance of being recorded is
//! linear, and each bin sums two integrals per cell (`ArrivalCells`).
//!
//! Work that cannot change the answer is left out: each bin is evaluated only
//! within `SUPPORT_SIGMAS` lateral standard deviations of its centre, and
//! quadrature nodes whose weight underflows to zero are skipped.

use ndarray::{Array2, Array3, ArrayView2, azip, s};
use serde::{Deserialize, Serialize};

use crate::diffusion::{Diffusion, gaussian_interval_fraction};
use crate::error::ParamError;
use crate::irf::{InstrumentResponse, Irf, IrfTable};
use crate::params::{MediumModel, Setup};
use crate::quadrature::adaptive_nodes;

/// Lateral support radius in standard deviations: the per-axis tail beyond it
/// is below 1e-16 of the mass, under f64 resolution of the kernel sum.
pub const SUPPORT_SIGMAS: f64 = 8.5;
/// Relative tolerance of the time quadrature on its probes.
pub const TIME_RTOL: f64 = 1e-9;
/// Cap on adaptive panels per bin (15 nodes each).
pub const MAX_TIME_PANELS: usize = 400;

/// How the ST-PSF is discretised.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Sampling {
    /// Integrated over pixel area and bin duration (correct; the default).
    #[default]
    Integrated,
    /// Evaluated at pixel centre and bin centre, times area and duration.
    Point,
}

impl Sampling {
    /// Name used on the command line and in metadata.
    pub fn name(self) -> &'static str {
        match self {
            Sampling::Integrated => "integrated",
            Sampling::Point => "point",
        }
    }
}

/// What was computed for one time bin of the setup.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BinInfo {
    /// Index of the bin in the setup's binning.
    pub index: usize,
    /// Bin start (ps).
    pub start_ps: f64,
    /// Bin end (ps).
    pub end_ps: f64,
    /// Expected photons of the bin's kernel (its sum) after normalisation.
    pub photons: f64,
    /// Whether the bin carries at least `min_bin_photons` and is kept.
    pub kept: bool,
    /// Lateral standard deviation at the bin centre (pixels): diffusion's,
    /// or measured from the kernel's light under Monte Carlo transport.
    pub sigma_px: f64,
    /// Largest kernel value (photons per pixel).
    pub peak: f64,
    /// Half-width of the evaluated support (pixels).
    pub support_radius_px: usize,
    /// Time quadrature nodes used (after skipping zero weights).
    pub time_nodes: usize,
    /// The relative standard error of the bin's light, for kernels made
    /// by Monte Carlo transport.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub relative_error: Option<f64>,
}

/// A Monte Carlo kernel on the sensor (centred at `(h / 2, w / 2)`) cut
/// to the square that holds all its light: light travels no farther
/// sideways than its path allows, so late bins reach farther than early
/// ones. Kept whole when its light reaches the sensor's edge.
fn lit_support(values: Array2<f64>, (h, w): (usize, usize)) -> LocalKernel {
    let (cy, cx) = (h / 2, w / 2);
    let reach = values
        .indexed_iter()
        .filter(|&(_, &v)| v > 0.0)
        .map(|((y, x), _)| y.abs_diff(cy).max(x.abs_diff(cx)))
        .max()
        .unwrap_or(0);
    let whole = reach > (h - 1 - cy).min(w - 1 - cx).min(cy).min(cx);
    if whole {
        return LocalKernel {
            values,
            log_scale: 0.0,
            radius: (cy, cx),
            nodes: 0,
        };
    }
    LocalKernel {
        values: values
            .slice(s![cy - reach..=cy + reach, cx - reach..=cx + reach])
            .to_owned(),
        log_scale: 0.0,
        radius: (reach, reach),
        nodes: 0,
    }
}

/// A kernel's lateral standard deviation along one axis (pixels), from
/// its light: the root mean square distance from its centre over the
/// square root of 2 (a Gaussian's sigma, for kernels that are not).
fn measured_sigma_px(local: &LocalKernel) -> f64 {
    let (ry, rx) = local.radius;
    let (mut mass, mut second) = (0.0, 0.0);
    for ((y, x), &v) in local.values.indexed_iter() {
        let (dy, dx) = (y as f64 - ry as f64, x as f64 - rx as f64);
        mass += v;
        second += v * (dy * dy + dx * dx);
    }
    if mass > 0.0 {
        (second / (2.0 * mass)).sqrt()
    } else {
        0.0
    }
}

/// The ST-PSF kernels of all kept bins, normalised to the setup's light budget.
#[derive(Debug, Clone)]
pub struct KernelStack {
    /// The setup the kernels were built for.
    pub setup: Setup,
    /// How they were discretised.
    pub sampling: Sampling,
    /// Derived diffusion constants.
    pub diffusion: Diffusion,
    /// Kept kernels, K x H x W, centred: offset (0, 0) sits at (H/2, W/2).
    pub kernels: Array3<f64>,
    /// One entry per bin of the setup, kept or not.
    pub bins: Vec<BinInfo>,
    /// For kernels made by Monte Carlo transport: what the run cache did.
    pub transport_cache: Option<crate::transport_cache::CacheUse>,
}

/// A bin's kernel on its support, scaled by `exp(-log_scale)`.
struct LocalKernel {
    values: Array2<f64>,
    log_scale: f64,
    radius: (usize, usize),
    nodes: usize,
}

impl KernelStack {
    /// Builds the kernel stack for `setup`.
    pub fn build(setup: &Setup, sampling: Sampling) -> Result<Self, ParamError> {
        setup.validate()?;
        let diffusion = Diffusion::new(&setup.medium)?;
        if let (Some(irf), Sampling::Point) = (&setup.irf, sampling) {
            let (field, value) = match irf {
                InstrumentResponse::Parametric(p) => ("irf_fwhm_ps", p.fwhm_ps),
                InstrumentResponse::Measured(t) => ("irf_table_weights", t.weights().len() as f64),
            };
            return Err(ParamError::new(
                field,
                value,
                "point sampling does not model an instrument response; use integrated sampling",
            ));
        }
        let (h, w) = (setup.sensor.height_px, setup.sensor.width_px);
        let mut relative_errors = vec![None; setup.bins.count];
        let mut transport_cache = None;
        let locals: Vec<Option<LocalKernel>> = if setup.medium.model == MediumModel::MonteCarlo {
            if sampling == Sampling::Point {
                return Err(ParamError::new(
                    "sampling",
                    "point",
                    "the Monte Carlo medium records each bin's light whole: use integrated sampling",
                ));
            }
            let mc = crate::transport::setup_kernels(
                setup,
                crate::transport::SETUP_PACKETS,
                crate::transport::SETUP_SEED,
            )?;
            for (e, r) in relative_errors.iter_mut().zip(&mc.relative_errors) {
                *e = Some(*r);
            }
            transport_cache = Some(mc.cache);
            mc.kernels
                .into_iter()
                .map(|k| k.map(|values| lit_support(values, (h, w))))
                .collect()
        } else {
            match &setup.irf {
                Some(InstrumentResponse::Measured(table)) => {
                    measured_bins(&diffusion, setup, table)
                }
                irf => {
                    let irf = irf.as_ref().and_then(InstrumentResponse::parametric);
                    (0..setup.bins.count)
                        .map(|k| {
                            let (ta, tb) = setup.bins.edges_ps(k);
                            match sampling {
                                Sampling::Integrated => {
                                    integrated_bin(&diffusion, setup, irf, ta, tb)
                                }
                                Sampling::Point => point_bin(&diffusion, setup, ta, tb),
                            }
                        })
                        .collect()
                }
            }
        };
        let log_masses: Vec<f64> = locals
            .iter()
            .map(|l| match l {
                Some(l) => l.log_scale + l.values.sum().ln(),
                None => f64::NEG_INFINITY,
            })
            .collect();
        let log_total = log_sum_exp(&log_masses);
        if !log_total.is_finite() {
            return Err(ParamError::new(
                "bins",
                format!(
                    "{} x {} ps from {} ps",
                    setup.bins.count, setup.bins.width_ps, setup.bins.start_ps
                ),
                if setup.medium.model == MediumModel::MonteCarlo {
                    format!(
                        "Monte Carlo transport records no light in these bins: the first light crosses the slab at n d / c = {:.1} ps (give bins from there, --t-start)",
                        setup.medium.first_light_ps()
                    )
                } else {
                    format!(
                        "the ST-PSF carries no photons before {} ps (light reaches the sensor around {:.1} ps)",
                        setup.bins.end_ps(),
                        diffusion.peak_time_ps()
                    )
                },
            ));
        }
        let log_budget = setup.total_photons.ln() - log_total;
        let pitch = setup.sensor.pixel_pitch_cm();
        let mut bins = Vec::with_capacity(setup.bins.count);
        let mut kept_kernels = Vec::new();
        for (k, (local, log_mass)) in locals.into_iter().zip(&log_masses).enumerate() {
            let (start_ps, end_ps) = setup.bins.edges_ps(k);
            let photons = (log_mass + log_budget).exp();
            let kept = photons > 0.0 && photons >= setup.min_bin_photons;
            let mut info = BinInfo {
                index: k,
                start_ps,
                end_ps,
                photons,
                kept,
                // Transport's is measured from the kernel's light below
                // (0 where a bin has none).
                sigma_px: if setup.medium.model == MediumModel::MonteCarlo {
                    0.0
                } else {
                    diffusion.lateral_sigma_cm(0.5 * (start_ps + end_ps)) / pitch
                },
                peak: 0.0,
                support_radius_px: 0,
                time_nodes: 0,
                relative_error: relative_errors[k].filter(|e| e.is_finite()),
            };
            if let Some(local) = local {
                if setup.medium.model == MediumModel::MonteCarlo {
                    info.sigma_px = measured_sigma_px(&local);
                }
                let factor = (local.log_scale + log_budget).exp();
                info.peak = local.values.iter().fold(0.0f64, |m, &v| m.max(v)) * factor;
                info.support_radius_px = local.radius.0.max(local.radius.1);
                info.time_nodes = local.nodes;
                if kept {
                    let mut full = Array2::<f64>::zeros((h, w));
                    let (ry, rx) = local.radius;
                    let (cy, cx) = (h / 2, w / 2);
                    let ly = local.values.nrows();
                    let lx = local.values.ncols();
                    full.slice_mut(s![cy - ry..cy - ry + ly, cx - rx..cx - rx + lx])
                        .zip_mut_with(&local.values, |d, &v| *d = v * factor);
                    kept_kernels.push(full);
                }
            }
            bins.push(info);
        }
        let mut kernels = Array3::<f64>::zeros((kept_kernels.len(), h, w));
        for (i, kern) in kept_kernels.into_iter().enumerate() {
            kernels.slice_mut(s![i, .., ..]).assign(&kern);
        }
        Ok(Self {
            setup: setup.clone(),
            sampling,
            diffusion,
            kernels,
            bins,
            transport_cache,
        })
    }

    /// Bins that were kept, in stack order.
    pub fn kept_bins(&self) -> impl Iterator<Item = &BinInfo> {
        self.bins.iter().filter(|b| b.kept)
    }

    /// Bins that were dropped for carrying too few photons.
    pub fn dropped_bins(&self) -> impl Iterator<Item = &BinInfo> {
        self.bins.iter().filter(|b| !b.kept)
    }

    /// The kernel of the `i`-th kept bin (centred layout).
    pub fn kernel(&self, i: usize) -> ArrayView2<'_, f64> {
        self.kernels.slice(s![i, .., ..])
    }

    /// Position in the kernel stack of the setup's bin `index`, if kept.
    pub fn position_of_bin(&self, index: usize) -> Option<usize> {
        self.kept_bins().position(|b| b.index == index)
    }

    /// Number of kept bins.
    pub fn len(&self) -> usize {
        self.kernels.shape()[0]
    }

    /// Whether no bin was kept.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Support radii (rows, columns) for a bin ending at `tb_ps`.
fn support_radius(d: &Diffusion, setup: &Setup, tb_ps: f64) -> (usize, usize) {
    let sigma_px = d.lateral_sigma_cm(tb_ps) / setup.sensor.pixel_pitch_cm();
    let r = (SUPPORT_SIGMAS * sigma_px).ceil().min(1e9) as usize + 1;
    let (h, w) = (setup.sensor.height_px, setup.sensor.width_px);
    // Offsets run from -(n/2) to (n-1)/2 on an n-pixel periodic grid.
    let clamp = |n: usize| r.min((n - 1) / 2).min(n / 2);
    (clamp(h), clamp(w))
}

/// Sum of `weight * outer(fy, fx)` over the nodes, on a (2ry+1) x (2rx+1) grid,
/// where the grid may be cut on the positive side for even image sizes.
fn separable_sum(radius: (usize, usize), nodes: &[(f64, Vec<f64>, Vec<f64>)]) -> Array2<f64> {
    let (ry, rx) = radius;
    let mut out = Array2::<f64>::zeros((2 * ry + 1, 2 * rx + 1));
    for (weight, fy, fx) in nodes {
        for (row, &vy) in out.rows_mut().into_iter().zip(fy) {
            let a = weight * vy;
            if a == 0.0 {
                continue;
            }
            for (o, &vx) in row.into_iter().zip(fx) {
                *o += a * vx;
            }
        }
    }
    out
}

/// The time integral of one bin `[ta, tb)`: every arrival time that can be
/// recorded in it, the scale that keeps the integrand near 1, and the
/// quadrature's breakpoints, in `v = sqrt(t)`.
struct BinTime<'a> {
    d: &'a Diffusion,
    irf: Option<&'a Irf>,
    ta: f64,
    tb: f64,
    /// Latest arrival time that can be recorded in the bin (ps).
    hi: f64,
    log_scale: f64,
    breaks: Vec<f64>,
}

impl<'a> BinTime<'a> {
    fn new(d: &'a Diffusion, irf: Option<&'a Irf>, ta: f64, tb: f64) -> Option<Self> {
        // Arrival times that can be recorded in [ta, tb): the bin itself, or
        // with an IRF the bin shifted back by every delay the IRF allows.
        let (lo, hi) = match irf {
            None => (ta, tb),
            Some(irf) => {
                let (early, late) = irf.support_ps();
                (ta - late, tb - early)
            }
        };
        let lo = lo.max(0.0);
        if hi <= lo {
            return None;
        }
        let four_dc = 4.0 * d.dc_cm2_per_ps();
        // Upper bound of ln(T(t) * dt/dv) on the range, so scaled values
        // stay <= ~1 (the IRF's weight is at most 1).
        let log_scale = if d.z0_cm == 0.0 && lo == 0.0 {
            (2.0 * d.c_cm_per_ps).ln() - 0.5 * (std::f64::consts::PI * four_dc).ln()
        } else {
            d.log_temporal_density(d.peak_time_ps().clamp(lo, hi)) + (2.0 * hi.sqrt()).ln()
        };
        // Breakpoints in v = sqrt(t): halve t from the end down to the start
        // (features of T scale with t), ending in a panel from 0 when the
        // range starts at 0.
        let (va, vb) = (lo.sqrt(), hi.sqrt());
        let mut breaks = vec![vb];
        let mut v = vb;
        while v / std::f64::consts::SQRT_2 > va && breaks.len() < 60 {
            v /= std::f64::consts::SQRT_2;
            breaks.push(v);
        }
        breaks.push(va);
        // With an IRF the weight turns on and off over about one IRF sigma
        // at each bin edge (and decays with the tail before ta): break
        // there too.
        if let Some(irf) = irf {
            let s = irf.sigma_ps();
            let edges = [ta, tb]
                .into_iter()
                .flat_map(|edge| (-4..=4).map(move |k| edge + k as f64 * s));
            let tail = (1..=8).map(|k| ta - k as f64 * irf.tail_ps);
            breaks.extend(
                edges
                    .chain(tail)
                    .filter(|&t| t > lo && t < hi)
                    .map(f64::sqrt),
            );
        }
        breaks.sort_by(f64::total_cmp);
        breaks.dedup();
        Some(Self {
            d,
            irf,
            ta,
            tb,
            hi,
            log_scale,
            breaks,
        })
    }

    /// `T(t) W(t) dt/dv / exp(log_scale)` at `v = sqrt(t)`, `W` the chance
    /// that an arrival at `t` is recorded in the bin.
    fn weight(&self, v: f64) -> f64 {
        let t = v * v;
        let recorded = self
            .irf
            .map_or(1.0, |irf| irf.bin_weight(self.ta, self.tb, t));
        if recorded == 0.0 {
            return 0.0;
        }
        (self.d.log_temporal_density(t) - self.log_scale).exp() * 2.0 * v * recorded
    }
}

/// Share of the light in each bin of `setup` over the whole sensor plane
/// (no pixels, no sensor edges): the time profile that `calibrate` fits.
/// Sums to 1 over the bins; an error when no bin has light. Under the
/// Monte Carlo medium, by transport
/// ([`crate::transport::setup_profile`], [`crate::transport::PROFILE_PACKETS`]
/// packets from the kernels' seed).
pub fn bin_profile(setup: &Setup) -> Result<Vec<f64>, ParamError> {
    setup.validate()?;
    if setup.medium.model == MediumModel::MonteCarlo {
        return crate::transport::setup_profile(
            setup,
            crate::transport::PROFILE_PACKETS,
            crate::transport::SETUP_SEED,
        );
    }
    let d = Diffusion::new(&setup.medium)?;
    let logs: Vec<f64> = match &setup.irf {
        Some(InstrumentResponse::Measured(table)) => {
            let cells = ArrivalCells::new(&d, setup, table);
            let mut sums = vec![0.0; setup.bins.count];
            for cell in cells.cells() {
                let r = adaptive_nodes(&cell.time.breaks, TIME_RTOL, MAX_TIME_PANELS, |v| {
                    let wgt = cell.time.weight(v);
                    let beta = cell.beta(v);
                    [wgt * (1.0 - beta), wgt * beta]
                });
                let scale = (cell.time.log_scale - cells.log_scale).exp();
                for (k, sum) in sums.iter_mut().enumerate() {
                    let (a, b) = cells.shares(k, cell.index);
                    *sum += scale * (a * r.integral[0] + b * r.integral[1]);
                }
            }
            sums.iter().map(|v| cells.log_scale + v.ln()).collect()
        }
        irf => {
            let irf = irf.as_ref().and_then(InstrumentResponse::parametric);
            (0..setup.bins.count)
                .map(|k| {
                    let (ta, tb) = setup.bins.edges_ps(k);
                    BinTime::new(&d, irf, ta, tb).map_or(f64::NEG_INFINITY, |bt| {
                        let r = adaptive_nodes(&bt.breaks, TIME_RTOL, MAX_TIME_PANELS, |v| {
                            [bt.weight(v)]
                        });
                        bt.log_scale + r.integral[0].ln()
                    })
                })
                .collect()
        }
    };
    let total = log_sum_exp(&logs);
    if !total.is_finite() {
        return Err(ParamError::new(
            "bins",
            setup.bins.end_ps(),
            "the ST-PSF carries no photons in these bins",
        ));
    }
    Ok(logs.iter().map(|l| (l - total).exp()).collect())
}

fn integrated_bin(
    d: &Diffusion,
    setup: &Setup,
    irf: Option<&Irf>,
    ta: f64,
    tb: f64,
) -> Option<LocalKernel> {
    let bt = BinTime::new(d, irf, ta, tb)?;
    let pitch = setup.sensor.pixel_pitch_cm();
    let four_dc = 4.0 * d.dc_cm2_per_ps();
    let radius = support_radius(d, setup, bt.hi);
    let cell = |i: i64, s: f64| {
        gaussian_interval_fraction((i as f64 - 0.5) * pitch, (i as f64 + 0.5) * pitch, s)
    };
    // Probes: total mass, the centre pixel (narrowest feature) and a pixel at
    // one end-of-range sigma (where the lateral profile turns on latest).
    let probe_offset = ((d.lateral_sigma_cm(bt.hi) / pitch).round() as i64).max(1);
    let adapted = adaptive_nodes(&bt.breaks, TIME_RTOL, MAX_TIME_PANELS, |v| {
        let wgt = bt.weight(v);
        if wgt == 0.0 {
            return [0.0; 3];
        }
        let s = (four_dc * v * v).sqrt();
        let c0 = cell(0, s);
        [wgt, wgt * c0 * c0, wgt * c0 * cell(probe_offset, s)]
    });
    let (ry, rx) = radius;
    let nodes: Vec<_> = adapted
        .nodes
        .iter()
        .filter_map(|n| {
            let weight = n.w * bt.weight(n.x);
            (weight > 0.0).then(|| {
                let s = (four_dc * n.x * n.x).sqrt();
                let fy = (-(ry as i64)..=ry as i64).map(|i| cell(i, s)).collect();
                let fx = (-(rx as i64)..=rx as i64).map(|i| cell(i, s)).collect();
                (weight, fy, fx)
            })
        })
        .collect();
    if nodes.is_empty() {
        return None;
    }
    Some(LocalKernel {
        values: separable_sum(radius, &nodes),
        log_scale: bt.log_scale,
        radius,
        nodes: nodes.len(),
    })
}

/// Kinks of the recording chances closer than this (ps) are merged into
/// one cell edge (they come from the same lattice, apart by round-off).
pub const KINK_MERGE_PS: f64 = 1e-6;

/// The arrival-time cells of a measured response `table` for the setup's
/// bins. The chance that an arrival at `s` is recorded in bin `[ta, tb)`,
/// `F(tb - s) - F(ta - s)` with `F` the table's piecewise-linear
/// distribution, bends only where `ta - s` or `tb - s` crosses one of the
/// table's bin edges: with those arrival times as the cells' edges, the
/// chance is linear inside every cell, and each bin's kernel is an exact
/// sum over cells of two integrals (the ST-PSF weighted by the position in
/// the cell and by its complement). No resampling of the table: a
/// reference binned on the stack's lattice gives one cell per bin width, a
/// narrow or offset one short cells where its edges fall.
struct ArrivalCells<'a> {
    d: &'a Diffusion,
    table: &'a IrfTable,
    /// The setup's bin edges (ps).
    bin_edges: Vec<f64>,
    /// Cell edges (ps), increasing, from the earliest arrival that can be
    /// recorded (not before 0) to the latest.
    edges: Vec<f64>,
    /// Largest of the cells' log scales: the common scale of the sums.
    log_scale: f64,
}

/// One arrival cell's quadrature.
struct Cell<'a> {
    index: usize,
    /// Start of the cell (ps) and its length.
    u0: f64,
    length: f64,
    time: BinTime<'a>,
}

impl Cell<'_> {
    /// Position of `t = v^2` in the cell, 0 at its start and 1 at its end.
    fn beta(&self, v: f64) -> f64 {
        ((v * v - self.u0) / self.length).clamp(0.0, 1.0)
    }
}

impl<'a> ArrivalCells<'a> {
    fn new(d: &'a Diffusion, setup: &Setup, table: &'a IrfTable) -> Self {
        let bin_edges: Vec<f64> = (0..=setup.bins.count)
            .map(|k| setup.bins.start_ps + k as f64 * setup.bins.width_ps)
            .collect();
        let table_edges: Vec<f64> = (0..=table.weights().len())
            .map(|j| table.start_ps() + j as f64 * table.bin_ps())
            .collect();
        let (first_delay, last_delay) = table.support_ps();
        let lo = (bin_edges[0] - last_delay).max(0.0);
        let hi = bin_edges[bin_edges.len() - 1] - first_delay;
        let mut edges: Vec<f64> = bin_edges
            .iter()
            .flat_map(|b| table_edges.iter().map(move |e| b - e))
            .filter(|&t| t > lo && t < hi)
            .chain([lo, hi])
            .collect();
        edges.sort_by(f64::total_cmp);
        edges.dedup_by(|b, a| *b - *a < KINK_MERGE_PS);
        if hi <= lo {
            edges.clear();
        }
        let mut cells = Self {
            d,
            table,
            bin_edges,
            edges,
            log_scale: f64::NEG_INFINITY,
        };
        cells.log_scale = cells
            .cells()
            .map(|c| c.time.log_scale)
            .fold(f64::NEG_INFINITY, f64::max);
        cells
    }

    /// The cells, in time order.
    fn cells(&self) -> impl Iterator<Item = Cell<'a>> + '_ {
        self.edges.windows(2).enumerate().filter_map(move |(c, w)| {
            let time = BinTime::new(self.d, None, w[0], w[1])?;
            Some(Cell {
                index: c,
                u0: w[0],
                length: w[1] - w[0],
                time,
            })
        })
    }

    /// The chances that arrivals at cell `c`'s start and end are recorded
    /// in bin `k`; in between the chance is linear.
    fn shares(&self, k: usize, c: usize) -> (f64, f64) {
        let (ta, tb) = (self.bin_edges[k], self.bin_edges[k + 1]);
        let chance = |s: f64| self.table.bin_weight(ta, tb, s);
        (chance(self.edges[c]), chance(self.edges[c + 1]))
    }

    /// Latest arrival that bin `k` records (ps).
    fn latest_for(&self, k: usize) -> f64 {
        self.bin_edges[k + 1] - self.table.support_ps().0
    }
}

/// Every bin's kernel under the measured response `table`: for each
/// arrival cell the ST-PSF integrated over the cell twice (weighted by the
/// position in the cell and by its complement), then added into each bin
/// with the chances at the cell's two ends ([`ArrivalCells`]).
fn measured_bins(d: &Diffusion, setup: &Setup, table: &IrfTable) -> Vec<Option<LocalKernel>> {
    let cells = ArrivalCells::new(d, setup, table);
    // Every cell that bin k takes ends by its latest arrival: the bin's
    // support covers theirs.
    let radii: Vec<(usize, usize)> = (0..setup.bins.count)
        .map(|k| support_radius(d, setup, cells.latest_for(k)))
        .collect();
    let mut sums: Vec<Array2<f64>> = radii
        .iter()
        .map(|&(ry, rx)| Array2::zeros((2 * ry + 1, 2 * rx + 1)))
        .collect();
    let mut nodes_used = vec![0usize; setup.bins.count];
    let pitch = setup.sensor.pixel_pitch_cm();
    let four_dc = 4.0 * d.dc_cm2_per_ps();
    let cell_px = |i: i64, s: f64| {
        gaussian_interval_fraction((i as f64 - 0.5) * pitch, (i as f64 + 0.5) * pitch, s)
    };
    for cell in cells.cells() {
        let chances: Vec<(usize, f64, f64)> = (0..setup.bins.count)
            .map(|k| {
                let (a, b) = cells.shares(k, cell.index);
                (k, a, b)
            })
            .filter(|&(_, a, b)| a > 0.0 || b > 0.0)
            .collect();
        if chances.is_empty() {
            continue;
        }
        let bt = &cell.time;
        let radius = support_radius(d, setup, bt.hi);
        let probe_offset = ((d.lateral_sigma_cm(bt.hi) / pitch).round() as i64).max(1);
        let adapted = adaptive_nodes(&bt.breaks, TIME_RTOL, MAX_TIME_PANELS, |v| {
            let wgt = bt.weight(v);
            if wgt == 0.0 {
                return [0.0; 4];
            }
            let beta = cell.beta(v);
            let s = (four_dc * v * v).sqrt();
            let c0 = cell_px(0, s);
            [
                wgt * (1.0 - beta),
                wgt * beta,
                wgt * c0 * c0,
                wgt * c0 * cell_px(probe_offset, s),
            ]
        });
        let scale = (bt.log_scale - cells.log_scale).exp();
        if scale == 0.0 {
            continue;
        }
        let (ry, rx) = radius;
        let mut early = Vec::new();
        let mut late = Vec::new();
        for n in &adapted.nodes {
            let weight = n.w * bt.weight(n.x) * scale;
            if weight > 0.0 {
                let s = (four_dc * n.x * n.x).sqrt();
                let fy: Vec<f64> = (-(ry as i64)..=ry as i64).map(|i| cell_px(i, s)).collect();
                let fx: Vec<f64> = (-(rx as i64)..=rx as i64).map(|i| cell_px(i, s)).collect();
                let beta = cell.beta(n.x);
                early.push((weight * (1.0 - beta), fy.clone(), fx.clone()));
                late.push((weight * beta, fy, fx));
            }
        }
        if early.is_empty() {
            continue;
        }
        let a_img = separable_sum(radius, &early);
        let b_img = separable_sum(radius, &late);
        for (k, a, b) in chances {
            let (by, bx) = radii[k];
            // The cell's support lies inside the bin's (see `radii`) but
            // where round-off gives a cell beyond the bin's latest arrival a
            // share of ~1e-16: the central overlap is added.
            let (cy, cx) = (ry.min(by), rx.min(bx));
            let dst_rows = by - cy..by + cy + 1;
            let dst_cols = bx - cx..bx + cx + 1;
            let src_rows = ry - cy..ry + cy + 1;
            let src_cols = rx - cx..rx + cx + 1;
            let mut dst = sums[k].slice_mut(s![dst_rows, dst_cols]);
            let src = s![src_rows, src_cols];
            azip!((d in &mut dst, &x in &a_img.slice(src), &y in &b_img.slice(src)) *d += a * x + b * y);
            nodes_used[k] += early.len();
        }
    }
    sums.into_iter()
        .zip(radii)
        .zip(nodes_used)
        .map(|((values, radius), nodes)| {
            (values.iter().any(|&v| v > 0.0)).then_some(LocalKernel {
                values,
                log_scale: cells.log_scale,
                radius,
                nodes,
            })
        })
        .collect()
}

fn point_bin(d: &Diffusion, setup: &Setup, ta: f64, tb: f64) -> Option<LocalKernel> {
    let t = 0.5 * (ta + tb);
    let log_t = d.log_temporal_density(t);
    if log_t == f64::NEG_INFINITY {
        return None;
    }
    let pitch = setup.sensor.pixel_pitch_cm();
    let four_dct = 4.0 * d.dc_cm2_per_ps() * t;
    // h(0, 0, t) * pixel area * bin width, in the log domain.
    let log_scale =
        log_t - (std::f64::consts::PI * four_dct).ln() + 2.0 * pitch.ln() + (tb - ta).ln();
    let radius = support_radius(d, setup, tb);
    let gauss = |r: usize| {
        (-(r as i64)..=r as i64)
            .map(|i| (-(i as f64 * pitch).powi(2) / four_dct).exp())
            .collect::<Vec<_>>()
    };
    let nodes = vec![(1.0, gauss(radius.0), gauss(radius.1))];
    Some(LocalKernel {
        values: separable_sum(radius, &nodes),
        log_scale,
        radius,
        nodes: 1,
    })
}

/// ln(sum(exp(x))) without overflow; `-inf` for an empty or all `-inf` input.
fn log_sum_exp(xs: &[f64]) -> f64 {
    let m = xs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if m == f64::NEG_INFINITY || !m.is_finite() {
        return m;
    }
    m + xs.iter().map(|x| (x - m).exp()).sum::<f64>().ln()
}
