//! The held-out reconstruction benchmark (`scatterscope bench-recon`).
//!
//! Images come from a directory written by `scripts/bench_images.py`: grey
//! PNGs larger than the sensor (the object extends past the sensor on every
//! side) and a `manifest.csv` naming each image's source, category and
//! split (`tuning` or `held-out`). Built-in scenes listed without a file are
//! rendered on the sensor's field, dark outside it.
//!
//! Simulation is independent of the reconstruction's model: the object's
//! whole grid is convolved (periodically, on a grid wider than the sensor by
//! more than the kernels' full support, so nothing wraps into the sensor)
//! with kernels at their full support, and only the sensor window is kept.
//! Reconstruction then sees a sensor with edges and models it with its own
//! padded grid and truncated margin.

use crate::named::{Named, named};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use ndarray::{Array2, Array3, ArrayView2, s};
use serde::Serialize;

use crate::denoise::Denoiser;
use crate::denoise::prior::{PriorError, PriorSpec};
use crate::forward::{Boundary, ForwardModel, poisson_counts};
use crate::metrics;
use crate::physics::{KernelStack, Sampling, Setup};
use crate::reconstruct::method::{Method, MethodOptions, RlStop, Solver, run_method};
use crate::reconstruct::problem::Problem;
use crate::reconstruct::trace::Trace;
use crate::scene::Scene;

use super::ReportError;
use crate::plot::{Series, chart};

/// Label of Richardson-Lucy's best iteration chosen with the truth.
pub const RL_BEST: &str = "rl-sum (best iteration by truth)";

/// Label of Richardson-Lucy with its iteration count chosen by
/// cross-validation on thinned halves of the counts (no truth).
pub const RL_CV: &str = "rl-sum (cross-validated stop)";

/// Label of whole-stack Richardson-Lucy with its cross-validated stop.
pub const RL_STACK_CV: &str = "rl-stack (cross-validated stop)";
/// Label of the default method's rows.
pub const AUTO: &str = "auto (the default)";
/// The learned reconstruction's label.
pub const LEARNED: &str = "learned";

/// Label of Richardson-Lucy's output after a fixed count of `iterations`.
pub fn rl_fixed_label(iterations: usize) -> String {
    format!("rl-sum ({iterations} iterations)")
}

/// Label of Richardson-Lucy's default output under `opts`: its stop.
pub fn rl_default_label(opts: &MethodOptions) -> String {
    match opts.rl_stop {
        RlStop::CrossValidated { .. } => RL_CV.into(),
        RlStop::After(iterations) => rl_fixed_label(iterations),
    }
}

/// One image of the benchmark.
#[derive(Debug, Clone)]
pub struct BenchImage {
    /// Short name.
    pub name: String,
    /// The PNG, or `None` for a built-in scene of that name.
    pub file: Option<PathBuf>,
    /// Where the image comes from (package or generator).
    pub source: String,
    /// Kind of scene (natural photo, medical, sparse, ...).
    pub category: String,
    /// `tuning` or `held-out`.
    pub split: String,
}

/// Reads `dir/manifest.csv` (columns name, file, source, category, split,
/// licence; the file empty for built-in scenes).
pub fn read_manifest(dir: &Path) -> Result<Vec<BenchImage>, ReportError> {
    let path = dir.join("manifest.csv");
    let bytes = crate::files::read_bounded(&path, 16 << 20, "benchmark manifest")
        .map_err(|e| ReportError::Input(e.to_string()))?;
    let text = String::from_utf8_lossy(&bytes);
    let bad = |line: usize, why: String| {
        ReportError::Input(format!("{}: line {line}: {why}", path.display()))
    };
    let mut lines = text.lines().enumerate();
    let header = lines.next().map(|(_, h)| h).unwrap_or_default();
    if !header.starts_with("name,file,source,category,split") {
        return Err(bad(
            1,
            format!("header `{header}` is not name,file,source,category,split,licence"),
        ));
    }
    let mut images = Vec::new();
    for (i, line) in lines.filter(|(_, l)| !l.trim().is_empty()) {
        let fields: Vec<&str> = line.splitn(6, ',').collect();
        if fields.len() < 5 {
            return Err(bad(
                i + 1,
                format!("{} fields, need at least 5", fields.len()),
            ));
        }
        let split = fields[4].to_string();
        if split != "tuning" && split != "held-out" {
            return Err(bad(
                i + 1,
                format!("split `{split}` is neither tuning nor held-out"),
            ));
        }
        images.push(BenchImage {
            name: fields[0].to_string(),
            file: (!fields[1].is_empty()).then(|| dir.join(fields[1])),
            source: fields[2].to_string(),
            category: fields[3].to_string(),
            split,
        });
    }
    Ok(images)
}

/// The images of `split` (`tuning`, `held-out` or `all`), only those named
/// in `only` when it is not empty.
pub fn select(
    images: Vec<BenchImage>,
    split: &str,
    only: &[String],
) -> Result<Vec<BenchImage>, ReportError> {
    if !["tuning", "held-out", "all"].contains(&split) {
        return Err(ReportError::Input(format!(
            "split `{split}` is not tuning, held-out or all"
        )));
    }
    Ok(images
        .into_iter()
        .filter(|i| split == "all" || i.split == split)
        .filter(|i| only.is_empty() || only.contains(&i.name))
        .collect())
}

/// `base` with its light budget multiplied by `level` (> 0).
pub fn level_setup(base: &Setup, level: f64) -> Result<Setup, ReportError> {
    if !(level > 0.0 && level.is_finite()) {
        return Err(ReportError::Input(format!(
            "light level {level} must be a positive number"
        )));
    }
    let mut setup = base.clone();
    setup.total_photons *= level;
    Ok(setup)
}

/// A simulated measurement of one image at one light level.
pub struct BenchCase {
    /// The object on the sensor's field (what a reconstruction should return).
    pub truth: Array2<f64>,
    /// Counts and the reconstruction's model (sensor with edges).
    pub problem: Problem,
}

/// Simulates `image` through `setup` as `how` says: the object on a
/// square grid of side `object_px` (>= the sensor), the sensor seeing its
/// centre.
pub fn simulate_case(
    image: &BenchImage,
    setup: &Setup,
    object_px: usize,
    seed: u64,
    how: &CaseSimulation,
) -> Result<BenchCase, ReportError> {
    let (h, w) = (setup.sensor.height_px, setup.sensor.width_px);
    if object_px < h.max(w) {
        return Err(ReportError::Input(format!(
            "object grid {object_px} px is smaller than the {w} x {h} sensor"
        )));
    }
    let (oy, ox) = ((object_px - h) / 2, (object_px - w) / 2);
    let object = match &image.file {
        Some(path) => Scene::File(path.clone()).render(object_px, object_px)?,
        None => {
            let mut full = Array2::zeros((object_px, object_px));
            full.slice_mut(s![oy..oy + h, ox..ox + w])
                .assign(&Scene::parse(&image.name).render(h, w)?);
            full
        }
    };
    simulate_object(object, setup, seed, how)
}

/// How a simulated case discretises the ST-PSF. The benchmark simulates
/// with [`Discretisation::Integrated`], the reconstruction's own model; the
/// learned reconstruction's trainer varies it, so that its network learns
/// the physics rather than one discretisation of it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Discretisation {
    /// Kernels integrated over pixel area and bin duration.
    #[default]
    Integrated,
    /// Kernels evaluated at pixel and bin centres.
    Point,
    /// The object on a grid of half the pitch (each object pixel split
    /// into 2 x 2), kernels at that grid's points and bin centres, each
    /// sensor pixel the sum of 2 x 2 fine pixels whose blocks start
    /// `offset` fine pixels (each 0 or 1) from the object's: the sensor's
    /// grid half a pixel off the object's.
    HalfPitch {
        /// Rows and columns, 0 or 1.
        offset: (usize, usize),
    },
}

/// What a simulated case adds to the reconstruction's model.
#[derive(Debug, Clone, Default)]
pub struct CaseSimulation {
    /// Background over the mean expected count per pixel and bin.
    pub background_share: f64,
    /// How the simulation discretises the ST-PSF.
    pub discretisation: Discretisation,
    /// The medium the light really crossed, when it differs from the
    /// setup's (a slab whose parameters the reconstruction knows only
    /// roughly); `None`: the setup's.
    pub true_medium: Option<crate::physics::Medium>,
}

/// Simulates `object`, a square grid at least as large as `setup`'s
/// sensor, which sees its centre, as the benchmark does: the kernels of
/// the grid at the sensor's pitch (periodic there, the object reaching
/// past the kernels' support), the sensor's window, plus
/// `how.background_share` times its mean expected count per pixel and bin,
/// Poisson-sampled with `seed`; the problem is the sensor-edged model
/// `reconstruct` builds from `setup`, with that background. Also what the
/// learned reconstruction's trainer simulates, with other discretisations
/// and media (`how`).
pub fn simulate_object(
    object: Array2<f64>,
    setup: &Setup,
    seed: u64,
    how: &CaseSimulation,
) -> Result<BenchCase, ReportError> {
    let (h, w) = (setup.sensor.height_px, setup.sensor.width_px);
    let object_px = object.nrows();
    if object.ncols() != object_px || object_px < h.max(w) {
        return Err(ReportError::Input(format!(
            "the object is {} x {}: it must be a square grid at least the {w} x {h} sensor",
            object.nrows(),
            object.ncols()
        )));
    }
    let background_share = how.background_share;
    if !(background_share.is_finite() && background_share >= 0.0) {
        return Err(ReportError::Input(format!(
            "background share {background_share}: give a finite number >= 0"
        )));
    }
    let kernels = KernelStack::build(setup, Sampling::Integrated)?;
    let (window, truth) = expected_window(object, setup, &kernels, how)?;
    let background = background_share * window.mean().unwrap_or(0.0);
    let counts = poisson_counts(&window.mapv(|v| v + background), seed);
    let problem = Problem {
        model: ForwardModel::new(&kernels, Boundary::Sensor).with_background(background),
        counts,
        bin_starts_ps: kernels.kept_bins().map(|b| b.start_ps).collect(),
        setup: setup.clone(),
        left_out: Vec::new(),
    };
    Ok(BenchCase { truth, problem })
}

/// The expected counts of `object` on the sensor's window in the bins the
/// model `kernels` keeps, simulated as `how` says, and the truth there (the
/// object over each sensor pixel's area).
fn expected_window(
    object: Array2<f64>,
    setup: &Setup,
    kernels: &KernelStack,
    how: &CaseSimulation,
) -> Result<(Array3<f64>, Array2<f64>), ReportError> {
    let (h, w) = (setup.sensor.height_px, setup.sensor.width_px);
    let object_px = object.nrows();
    let (oy, ox) = ((object_px - h) / 2, (object_px - w) / 2);
    let (factor, sampling, offset) = match how.discretisation {
        Discretisation::Integrated => (1, Sampling::Integrated, (0, 0)),
        Discretisation::Point => (1, Sampling::Point, (0, 0)),
        Discretisation::HalfPitch { offset } => {
            if offset.0 > 1 || offset.1 > 1 {
                return Err(ReportError::Input(format!(
                    "half-pitch offset {offset:?}: each must be 0 or 1"
                )));
            }
            (2, Sampling::Point, offset)
        }
    };
    // The simulation's grid: the object's, `factor` times finer, every bin
    // kept (the model's are picked from them by index).
    let side = object_px * factor;
    let mut wide = setup.clone();
    if let Some(medium) = &how.true_medium {
        wide.medium = *medium;
    }
    wide.sensor.height_px = side;
    wide.sensor.width_px = side;
    wide.sensor.fov_cm = setup.sensor.fov_cm * object_px as f64 / w as f64;
    wide.total_photons = setup.total_photons / (factor * factor) as f64;
    wide.min_bin_photons = 0.0;
    crate::memory::check_setup(&wide, crate::memory::SIMULATE_BYTES, "a benchmark case")
        .map_err(|e| ReportError::Input(e.to_string()))?;
    let sim_kernels = KernelStack::build(&wide, sampling)?;
    // Per bin the model keeps: the simulation's kernel of it, or none
    // where the simulated medium puts no light in it (light as it travels
    // arrives no earlier than it can cross the slab; the model's medium
    // may say otherwise): those bins' counts are zero.
    let lit: Vec<Option<usize>> = kernels
        .kept_bins()
        .map(|b| sim_kernels.position_of_bin(b.index))
        .collect();
    if lit.iter().all(Option::is_none) {
        return Err(ReportError::Input(
            "no bin the model keeps carries light in the simulation's medium".into(),
        ));
    }
    let bins: Vec<usize> = lit.iter().flatten().copied().collect();
    let reach = bins
        .iter()
        .map(|&k| sim_kernels.kept_bins().nth(k))
        .map(|b| b.map_or(0, |b| b.support_radius_px))
        .max()
        .unwrap_or(0);
    let room = (oy.min(ox) * factor).saturating_sub(offset.0.max(offset.1));
    if reach > room {
        return Err(ReportError::Input(format!(
            "object grid {object_px} px leaves {} px around the sensor, less than the kernels' support {} px",
            oy.min(ox),
            reach.div_ceil(factor)
        )));
    }
    let fine = if factor == 1 {
        object
    } else {
        Array2::from_shape_fn((side, side), |(r, c)| object[(r / factor, c / factor)])
    };
    let sim = ForwardModel::with_bins(&sim_kernels, &bins, Boundary::Periodic);
    let expected = sim.expected(fine.view()).counts;
    // Each sensor pixel sums its factor x factor block of the fine grid.
    let (fy, fx) = (oy * factor + offset.0, ox * factor + offset.1);
    let block = |r: usize, c: usize, k: Option<usize>| -> f64 {
        let mut sum = 0.0;
        for dy in 0..factor {
            for dx in 0..factor {
                let (y, x) = (fy + r * factor + dy, fx + c * factor + dx);
                sum += match k {
                    Some(k) => expected[(k, y, x)],
                    None => fine[(y, x)],
                };
            }
        }
        sum
    };
    let mut at = 0;
    let rows: Vec<Option<usize>> = lit
        .iter()
        .map(|l| {
            l.map(|_| {
                at += 1;
                at - 1
            })
        })
        .collect();
    let window = Array3::from_shape_fn((lit.len(), h, w), |(k, r, c)| {
        rows[k].map_or(0.0, |j| block(r, c, Some(j)))
    });
    let cells = (factor * factor) as f64;
    let truth = Array2::from_shape_fn((h, w), |(r, c)| block(r, c, None) / cells);
    Ok((window, truth))
}

/// One method's result on one case.
#[derive(Debug, Clone, Serialize)]
pub struct BenchRow {
    /// Image name.
    pub image: String,
    /// `tuning` or `held-out`.
    pub split: String,
    /// Scene category.
    pub category: String,
    /// Light level relative to the setup's budget.
    pub level: f64,
    /// Method label (`pnp split ffdnet`, `rl-sum`, ...).
    pub method: String,
    /// PSNR of the output (dB).
    pub psnr: f64,
    /// SSIM of the output.
    pub ssim: f64,
    /// Wall time (s).
    pub wall_s: f64,
    /// Iterations run.
    pub iterations: usize,
    /// The iteration returned as the output (the last unless a stopping
    /// rule chose an earlier one).
    pub output_iteration: usize,
    /// Best PSNR over the iterations, chosen with the truth (dB).
    pub best_psnr: f64,
    /// Iteration of that best PSNR.
    pub best_iteration: usize,
    /// Output deviance minus its expectation under Poisson noise, in noise
    /// standard deviations (PnP only).
    pub deviance_z: Option<f64>,
    /// What `auto` chose (its rows only).
    pub chose: Option<String>,
    /// Photons in the case's stack (every bin the model keeps).
    pub photons: f64,
}

/// A PnP configuration of the benchmark.
pub struct PnpEntry<'a> {
    /// Label used in the rows.
    pub label: String,
    /// Method (`Pnp` or `PnpSum`).
    pub method: Method,
    /// Solver.
    pub solver: Solver,
    /// Prior.
    pub denoiser: &'a dyn Denoiser,
}

/// The PnP runs of the benchmark: every solver with every named prior on
/// the whole stack, and with `time_summed` the first solver and prior on
/// the time-summed stack. The first entry is the headline.
pub fn pnp_entries<'a>(
    solvers: &[Solver],
    priors: &'a [(String, Box<dyn Denoiser>)],
    time_summed: bool,
) -> Vec<PnpEntry<'a>> {
    let mut entries = Vec::new();
    for &solver in solvers {
        for (name, d) in priors {
            entries.push(PnpEntry {
                label: format!("pnp {} {name}", solver.name()),
                method: Method::Pnp,
                solver,
                denoiser: d.as_ref(),
            });
        }
    }
    if time_summed && let (Some(&solver), Some((name, d))) = (solvers.first(), priors.first()) {
        entries.push(PnpEntry {
            label: format!("pnp-sum {} {name}", solver.name()),
            method: Method::PnpSum,
            solver,
            denoiser: d.as_ref(),
        });
    }
    entries
}

/// The methods a benchmark run may run (RL's best iteration, the
/// reference, always runs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BenchMethod {
    /// Every PnP entry.
    Pnp,
    /// Richardson-Lucy on the time-summed stack, cross-validated stop.
    RlSum,
    /// Richardson-Lucy on the whole stack, cross-validated stop.
    RlStack,
    /// The default, `auto`, with the headline prior.
    Auto,
    /// The learned reconstruction (its embedded network).
    Learned,
}

named!(BenchMethod {
    Pnp => "pnp",
    RlSum => "rl-sum",
    RlStack => "rl-stack",
    Auto => "auto",
    Learned => "learned",
});

/// Runs the `methods` on one case: every PnP entry, Richardson-Lucy on
/// the time-summed stack and on the whole stack with their stop chosen by
/// cross-validation (as `opts.rl_stop` sets it when it is `cv`, else
/// with its default search), `auto`; and always RL on the time-summed
/// stack for `rl_best_iters` iterations (its output at `rl_fixed_iters`
/// is RL's fixed-count row, the best iteration by truth its oracle).
/// `on_trace` gets each PnP, cross-validated RL and `auto` trace (PSNR
/// against wall time) with its label.
#[allow(clippy::too_many_arguments)]
pub fn run_case(
    image: &BenchImage,
    level: f64,
    case: &BenchCase,
    entries: &[PnpEntry],
    methods: &[BenchMethod],
    opts: &MethodOptions,
    rl_best_iters: usize,
    rl_fixed_iters: usize,
    mut on_trace: impl FnMut(&str, &Trace),
) -> Result<Vec<BenchRow>, ReportError> {
    let truth = case.truth.view();
    let photons = case.problem.counts.sum();
    let row = |method: String, image_out: ArrayView2<f64>, trace: &Trace| {
        let last = trace.rows.last().expect("every method records a row");
        let best = trace.best_psnr().expect("truth is known");
        let output_iteration = trace.output_iteration().unwrap_or(last.iteration);
        let out_row = trace.rows.iter().find(|r| r.iteration == output_iteration);
        BenchRow {
            image: image.name.clone(),
            split: image.split.clone(),
            category: image.category.clone(),
            level,
            method,
            psnr: metrics::psnr(image_out, truth),
            ssim: metrics::ssim(image_out, truth),
            wall_s: trace.wall_s,
            iterations: last.iteration,
            output_iteration,
            best_psnr: best.psnr.unwrap_or(f64::NAN),
            best_iteration: best.iteration,
            deviance_z: out_row
                .and_then(|r| Some((r.deviance? - r.expected_deviance?) / r.deviance_sd?)),
            chose: None,
            photons,
        }
    };
    let mut rows = Vec::new();
    let runs = |m: BenchMethod| methods.contains(&m);
    for e in entries.iter().filter(|_| runs(BenchMethod::Pnp)) {
        let mut o = *opts;
        o.solver = e.solver;
        let r = run_method(
            &case.problem,
            e.method,
            None,
            e.denoiser,
            &o,
            Some(truth),
            |_| {},
        )?;
        on_trace(&e.label, &r.trace);
        rows.push(row(e.label.clone(), r.image.view(), &r.trace));
    }
    let run_rl = |method: Method, o: &MethodOptions| {
        run_method(
            &case.problem,
            method,
            None,
            &crate::denoise::NoPrior,
            o,
            Some(truth),
            |_| {},
        )
    };
    let cross_validated = MethodOptions {
        rl_stop: match opts.rl_stop {
            cv @ RlStop::CrossValidated { .. } => cv,
            RlStop::After(_) => RlStop::CROSS_VALIDATED,
        },
        ..*opts
    };
    for (wanted, method, label) in [
        (BenchMethod::RlSum, Method::RlSum, RL_CV),
        (BenchMethod::RlStack, Method::RlStack, RL_STACK_CV),
    ] {
        if !runs(wanted) {
            continue;
        }
        let r = run_rl(method, &cross_validated)?;
        on_trace(label, &r.trace);
        rows.push(row(label.into(), r.image.view(), &r.trace));
    }
    if runs(BenchMethod::Learned) {
        let r = run_rl(Method::Learned, &cross_validated)?;
        on_trace(LEARNED, &r.trace);
        rows.push(row(LEARNED.into(), r.image.view(), &r.trace));
    }
    // The default, with the headline prior.
    if let Some(e) = entries.first().filter(|_| runs(BenchMethod::Auto)) {
        let r = run_method(
            &case.problem,
            Method::Auto,
            None,
            e.denoiser,
            &cross_validated,
            Some(truth),
            |_| {},
        )?;
        on_trace(AUTO, &r.trace);
        let mut auto = row(AUTO.into(), r.image.view(), &r.trace);
        auto.chose = crate::reconstruct::auto::chosen(&r.trace).map(str::to_string);
        rows.push(auto);
    }
    let rl = run_rl(
        Method::RlSum,
        &MethodOptions {
            rl_stop: RlStop::After(rl_best_iters.max(rl_fixed_iters)),
            ..*opts
        },
    )?;
    let mut best = row(RL_BEST.into(), rl.image.view(), &rl.trace);
    // RL's rows start at iteration 1.
    let best_row = rl
        .trace
        .rows
        .iter()
        .find(|r| r.iteration == best.best_iteration)
        .expect("the best row is a row");
    best.psnr = best.best_psnr;
    best.ssim = best_row.ssim.unwrap_or(f64::NAN);
    best.iterations = best.best_iteration;
    best.output_iteration = best.best_iteration;
    best.wall_s = best_row.wall_s;
    let at_default = rl
        .trace
        .rows
        .iter()
        .find(|r| r.iteration == rl_fixed_iters)
        .expect("RL ran at least its default iterations");
    let mut default = best.clone();
    default.method = rl_fixed_label(rl_fixed_iters);
    default.psnr = at_default.psnr.unwrap_or(f64::NAN);
    default.ssim = at_default.ssim.unwrap_or(f64::NAN);
    default.wall_s = at_default.wall_s;
    default.iterations = rl_fixed_iters;
    default.output_iteration = rl_fixed_iters;
    rows.push(default);
    rows.push(best);
    Ok(rows)
}

/// CSV of all rows.
pub fn rows_csv(rows: &[BenchRow]) -> String {
    let mut csv = String::from(
        "image,split,category,level,method,psnr,ssim,wall_s,iterations,output_iteration,best_psnr,best_iteration,deviance_z,chose,photons\n",
    );
    for r in rows {
        writeln!(
            csv,
            "{},{},\"{}\",{},\"{}\",{:.4},{:.5},{:.3},{},{},{:.4},{},{},{},{}",
            r.image,
            r.split,
            r.category,
            r.level,
            r.method,
            r.psnr,
            r.ssim,
            r.wall_s,
            r.iterations,
            r.output_iteration,
            r.best_psnr,
            r.best_iteration,
            r.deviance_z.map_or(String::new(), |z| format!("{z:.2}")),
            r.chose.as_deref().unwrap_or(""),
            r.photons
        )
        .expect("String");
    }
    csv
}

/// Rows read back from [`rows_csv`]'s text (for `--resume`); errors name
/// the line and field.
pub fn rows_from_csv(text: &str) -> Result<Vec<BenchRow>, ReportError> {
    let mut rows = Vec::new();
    for (i, line) in text.lines().enumerate().skip(1) {
        if line.trim().is_empty() {
            continue;
        }
        let bad = |field: &str, value: &str| {
            ReportError::Input(format!(
                "rows.csv line {}: field {field} = {value:?} is not readable",
                i + 1
            ))
        };
        let mut fields = Vec::new();
        let (mut cur, mut quoted) = (String::new(), false);
        for ch in line.chars() {
            match ch {
                '"' => quoted = !quoted,
                ',' if !quoted => fields.push(std::mem::take(&mut cur)),
                _ => cur.push(ch),
            }
        }
        fields.push(cur);
        if fields.len() != 15 {
            return Err(ReportError::Input(format!(
                "rows.csv line {}: {} fields, 15 expected",
                i + 1,
                fields.len()
            )));
        }
        let num = |k: usize, name: &str| -> Result<f64, ReportError> {
            fields[k].parse::<f64>().map_err(|_| bad(name, &fields[k]))
        };
        let int = |k: usize, name: &str| -> Result<usize, ReportError> {
            fields[k]
                .parse::<usize>()
                .map_err(|_| bad(name, &fields[k]))
        };
        rows.push(BenchRow {
            image: fields[0].clone(),
            split: fields[1].clone(),
            category: fields[2].clone(),
            level: num(3, "level")?,
            method: fields[4].clone(),
            psnr: num(5, "psnr")?,
            ssim: num(6, "ssim")?,
            wall_s: num(7, "wall_s")?,
            iterations: int(8, "iterations")?,
            output_iteration: int(9, "output_iteration")?,
            best_psnr: num(10, "best_psnr")?,
            best_iteration: int(11, "best_iteration")?,
            deviance_z: if fields[12].is_empty() {
                None
            } else {
                Some(num(12, "deviance_z")?)
            },
            chose: (!fields[13].is_empty()).then(|| fields[13].clone()),
            photons: num(14, "photons")?,
        });
    }
    Ok(rows)
}

/// One method at one light level against RL-sum's best iteration chosen
/// with the truth, over the images that have both rows.
#[derive(Debug, Clone, PartialEq)]
pub struct Verdict {
    /// The method's label.
    pub method: String,
    /// The light level (x the preset's photon budget).
    pub level: f64,
    /// Images compared.
    pub images: usize,
    /// Mean PSNR margin over RL's best (dB).
    pub mean_margin: f64,
    /// Worst PSNR margin over RL's best (dB).
    pub worst_margin: f64,
    /// Worst PSNR margin over RL-sum's cross-validated output (dB).
    pub worst_vs_rl_cv: f64,
    /// Median wall time (s).
    pub median_s: f64,
}

/// Each method's [`Verdict`] per light level, in the order the rows name
/// them.
pub fn verdict(rows: &[BenchRow]) -> Vec<Verdict> {
    let find = |label: &str, r: &BenchRow| {
        rows.iter()
            .find(|b| b.method == label && b.image == r.image && b.level == r.level)
            .map(|b| r.psnr - b.psnr)
    };
    let mut out: Vec<Verdict> = Vec::new();
    let mut keys: Vec<(&str, f64)> = Vec::new();
    for r in rows.iter().filter(|r| r.method != RL_BEST) {
        if !keys.iter().any(|&(m, l)| m == r.method && l == r.level) {
            keys.push((&r.method, r.level));
        }
    }
    for (method, level) in keys {
        let (mut margins, mut vs_cv, mut times) = (Vec::new(), Vec::new(), Vec::new());
        for r in rows
            .iter()
            .filter(|r| r.method == method && r.level == level)
        {
            if let Some(m) = find(RL_BEST, r) {
                margins.push(m);
                vs_cv.extend(find(RL_CV, r));
                times.push(r.wall_s);
            }
        }
        if margins.is_empty() {
            continue;
        }
        times.sort_by(f64::total_cmp);
        let n = margins.len();
        out.push(Verdict {
            method: method.to_string(),
            level,
            images: n,
            mean_margin: margins.iter().sum::<f64>() / n as f64,
            worst_margin: margins.iter().copied().fold(f64::INFINITY, f64::min),
            worst_vs_rl_cv: vs_cv.iter().copied().fold(f64::INFINITY, f64::min),
            median_s: if n % 2 == 1 {
                times[n / 2]
            } else {
                0.5 * (times[n / 2 - 1] + times[n / 2])
            },
        });
    }
    out
}

/// The verdict as a Markdown table.
pub fn verdict_markdown(rows: &[BenchRow]) -> String {
    let mut md = String::from(
        "| method | level | images | mean margin over RL best | worst margin | worst vs RL-CV | median time |\n|---|---|---|---|---|---|---|\n",
    );
    for v in verdict(rows) {
        writeln!(
            md,
            "| {} | {}x | {} | {:+.2} dB | {:+.2} dB | {:+.2} dB | {:.2} s |",
            v.method,
            v.level,
            v.images,
            v.mean_margin,
            v.worst_margin,
            v.worst_vs_rl_cv,
            v.median_s
        )
        .expect("String");
    }
    md
}

/// Writes each method's mean PSNR margin over RL's best against its median
/// wall time, one point per light level (time on a log axis), as a PNG;
/// the legend gives every level's numbers.
pub fn write_time_figure(rows: &[BenchRow], path: &Path) -> Result<(), ReportError> {
    let mut series: Vec<Series> = Vec::new();
    let mut labels: Vec<(String, Vec<String>)> = Vec::new();
    for v in verdict(rows) {
        let text = format!("{}x {:+.2} dB {:.1} s", v.level, v.mean_margin, v.median_s);
        let point = (v.median_s.max(1e-3), v.mean_margin);
        match series
            .iter_mut()
            .zip(labels.iter_mut())
            .find(|(s, _)| s.label == v.method)
        {
            Some((s, (_, l))) => {
                s.points.push(point);
                l.push(text);
            }
            None => {
                series.push(Series {
                    label: v.method.clone(),
                    points: vec![point],
                });
                labels.push((v.method, vec![text]));
            }
        }
    }
    for (s, (_, l)) in series.iter_mut().zip(&labels) {
        s.label = format!("{}: {}", s.label, l.join(", "));
    }
    // The split the rows are from (the benchmark runs one at a time).
    let mut splits: Vec<&str> = rows.iter().map(|r| r.split.as_str()).collect();
    splits.sort_unstable();
    splits.dedup();
    let title = format!(
        "{}: mean PSNR margin against median run time, one point per light level",
        splits.join(" and ")
    );
    chart(
        path,
        &title,
        "median wall time (s)",
        "mean PSNR minus RL's best iteration chosen with the truth (dB)",
        &series,
        &[],
        true,
    )
    .map_err(ReportError::Plot)
}

/// Markdown summary: per split and level, each method's mean PSNR and time,
/// and the margins of `headline` over RL-sum's best iteration and over
/// RL-sum's default output, the rows labelled `rl_default` (mean, worst).
pub fn summary_markdown(rows: &[BenchRow], headline: &str, rl_default: &str) -> String {
    let mut md = String::new();
    let mut groups: Vec<(String, f64)> = Vec::new();
    for r in rows {
        if !groups.iter().any(|(s, l)| *s == r.split && *l == r.level) {
            groups.push((r.split.clone(), r.level));
        }
    }
    for (split, level) in groups {
        let sel: Vec<&BenchRow> = rows
            .iter()
            .filter(|r| r.split == split && r.level == level)
            .collect();
        let mut methods: Vec<&str> = Vec::new();
        for r in &sel {
            if !methods.contains(&r.method.as_str()) {
                methods.push(&r.method);
            }
        }
        let images: Vec<&str> = {
            let mut v: Vec<&str> = Vec::new();
            for r in &sel {
                if !v.contains(&r.image.as_str()) {
                    v.push(&r.image);
                }
            }
            v
        };
        writeln!(
            md,
            "\n### {split}, light level {level}x ({} images)\n",
            images.len()
        )
        .expect("String");
        md.push_str("| method | mean PSNR (dB) | mean SSIM | median time (s) | max time (s) |\n|---|---|---|---|---|\n");
        for m in &methods {
            let of: Vec<&&BenchRow> = sel.iter().filter(|r| r.method == *m).collect();
            let mean =
                |f: fn(&BenchRow) -> f64| of.iter().map(|r| f(r)).sum::<f64>() / of.len() as f64;
            let mut times: Vec<f64> = of.iter().map(|r| r.wall_s).collect();
            times.sort_by(f64::total_cmp);
            writeln!(
                md,
                "| {m} | {:.2} | {:.4} | {:.2} | {:.2} |",
                mean(|r| r.psnr),
                mean(|r| r.ssim),
                times[times.len() / 2],
                times.last().copied().unwrap_or(0.0)
            )
            .expect("String");
        }
        let find = |img: &str, m: &str| sel.iter().find(|r| r.image == img && r.method == m);
        let mut margins = Vec::new();
        md.push_str(&format!(
            "\n| image | {headline} (dB) | rl-sum best (dB) | margin | {rl_default} (dB) | margin | deviance z | time (s) |\n|---|---|---|---|---|---|---|---|\n"
        ));
        for img in &images {
            let (Some(p), Some(b), Some(d)) = (
                find(img, headline),
                find(img, RL_BEST),
                find(img, rl_default),
            ) else {
                continue;
            };
            margins.push((p.psnr - b.psnr, p.psnr - d.psnr, p.wall_s));
            writeln!(
                md,
                "| {img} | {:.2} | {:.2} | {:+.2} | {:.2} | {:+.2} | {} | {:.2} |",
                p.psnr,
                b.psnr,
                p.psnr - b.psnr,
                d.psnr,
                p.psnr - d.psnr,
                p.deviance_z.map_or("-".into(), |z| format!("{z:.1}")),
                p.wall_s
            )
            .expect("String");
        }
        if !margins.is_empty() {
            let n = margins.len() as f64;
            let mean_best = margins.iter().map(|m| m.0).sum::<f64>() / n;
            let worst_best = margins.iter().map(|m| m.0).fold(f64::INFINITY, f64::min);
            let worst_default = margins.iter().map(|m| m.1).fold(f64::INFINITY, f64::min);
            let mean_default = margins.iter().map(|m| m.1).sum::<f64>() / n;
            let mut times: Vec<f64> = margins.iter().map(|m| m.2).collect();
            times.sort_by(f64::total_cmp);
            let median = times[times.len() / 2];
            writeln!(
                md,
                "\n{headline}: margin over RL-sum's best iteration mean {mean_best:+.2} dB, worst {worst_best:+.2} dB; over RL-sum's default output ({rl_default}) mean {mean_default:+.2} dB, worst {worst_default:+.2} dB; time median {median:.2} s, max {:.2} s ({:.2}x the median)",
                times.last().copied().unwrap_or(0.0),
                times.last().copied().unwrap_or(0.0) / median
            )
            .expect("String");
        }
    }
    md
}

/// Everything one run of the benchmark needs. The command line's
/// benchmark flags are these fields (their docs are the flags' help); the
/// physics, the methods' settings and the priors' weights and gain come
/// from the physics and reconstruction flags.
#[derive(Debug, Clone)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct BenchConfig {
    /// Directory with manifest.csv and the images.
    pub images: PathBuf,
    /// Which images: tuning, held-out or all.
    #[cfg_attr(feature = "cli", arg(long, default_value = "held-out"))]
    pub split: String,
    /// Only these images (by manifest name; default all of the split).
    #[cfg_attr(feature = "cli", arg(long = "image", value_name = "NAME"))]
    pub only: Vec<String>,
    /// Light levels relative to the physics' budget.
    #[cfg_attr(
        feature = "cli",
        arg(long, value_delimiter = ',', default_value = "0.1,1,10")
    )]
    pub levels: Vec<f64>,
    /// PnP solvers to run on the whole stack.
    #[cfg_attr(feature = "cli", arg(long, value_parser = crate::named::choice::<Solver>(), value_delimiter = ',', default_value = "split,admm-lbfgs"))]
    pub solvers: Vec<Solver>,
    /// Priors to run with each solver (the first is the headline prior).
    #[cfg_attr(feature = "cli", arg(long, value_name = "PRIORS", value_delimiter = ',', default_value = "ffdnet,tv", value_parser = clap::builder::TypedValueParser::map(crate::named::choice::<crate::denoise::prior::PriorKind>(), |kind| PriorSpec { kind, ..PriorSpec::default() })))]
    pub priors: Vec<PriorSpec>,
    /// Also run PnP on the time-summed stack (`false`: the flag
    /// `--no-sum`).
    #[cfg_attr(feature = "cli", arg(long = "no-sum", action = clap::ArgAction::SetFalse, help = "Skip PnP on the time-summed stack"))]
    pub time_summed: bool,
    /// Methods to run (RL's best iteration, the reference, always runs).
    #[cfg_attr(feature = "cli", arg(long, value_parser = crate::named::choice::<BenchMethod>(), value_delimiter = ',', default_value = "pnp,rl-sum,rl-stack,auto"))]
    pub methods: Vec<BenchMethod>,
    /// Richardson-Lucy iterations searched for its best iteration.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 1000))]
    pub rl_best_iters: usize,
    /// Iterations of Richardson-Lucy's fixed-count row.
    #[cfg_attr(feature = "cli", arg(skip = RlStop::DEFAULT_ITERS))]
    pub rl_fixed_iters: usize,
    /// Side of the simulated object grid (pixels); the sensor sees its
    /// centre.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 384))]
    pub object_px: usize,
    /// The physics at level 1.
    #[cfg_attr(feature = "cli", arg(skip = crate::physics::Preset::Paper.setup()))]
    pub setup: Setup,
    /// The medium model the light is simulated with, when it is not the
    /// one the methods reconstruct with (`--medium`): e.g. stacks of light
    /// as it travels (`monte-carlo`) reconstructed with diffusion's
    /// kernels.
    #[cfg_attr(feature = "cli", arg(long, value_name = "MODEL", value_parser = crate::config::parse_medium_model))]
    pub simulate_medium: Option<crate::physics::MediumModel>,
    /// The methods' settings.
    #[cfg_attr(feature = "cli", arg(skip))]
    pub opts: MethodOptions,
    /// Seed of the Poisson sampler.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 0))]
    pub seed: u64,
    /// Output directory: rows.csv, summary.md, traces/ (CSV and JSON, the
    /// notes in the JSON).
    #[cfg_attr(feature = "cli", arg(long, default_value = "out/bench-recon"))]
    pub out: PathBuf,
    /// Keep the cases (image and level) OUT/rows.csv already holds and run
    /// only the others (an interrupted run goes on; the summary covers
    /// both).
    #[cfg_attr(feature = "cli", arg(long))]
    pub resume: bool,
}

impl BenchRow {
    /// The row as one printed line.
    pub fn line(&self) -> String {
        format!(
            "{:<18} {:>5}x {:<36} {:>6.2} dB (best {:>6.2} @ {:>4}) {:>7.2} s{}",
            self.image,
            self.level,
            self.method,
            self.psnr,
            self.best_psnr,
            self.best_iteration,
            self.wall_s,
            self.deviance_z
                .map_or(String::new(), |z| format!("  deviance z {z:.1}"))
        )
    }
}

/// Runs the benchmark: every selected image at every level through every
/// method, the rows shown to `on_row` as they come and written to
/// `rows.csv` after each case, the PnP traces to `traces/`; returns the
/// rows and the summary (also written to `summary.md`).
pub fn run_benchmark(
    cfg: &BenchConfig,
    mut on_row: impl FnMut(&BenchRow),
) -> Result<(Vec<BenchRow>, String), ReportError> {
    cfg.opts.validate()?;
    let images = select(read_manifest(&cfg.images)?, &cfg.split, &cfg.only)?;
    if images.is_empty() {
        return Err(ReportError::Input(format!(
            "no image of {} matches",
            cfg.images.display()
        )));
    }
    let setups = cfg
        .levels
        .iter()
        .map(|&level| Ok((level, level_setup(&cfg.setup, level)?)))
        .collect::<Result<Vec<_>, ReportError>>()?;
    let priors = build_priors(cfg)?;
    let entries = pnp_entries(&cfg.solvers, &priors, cfg.time_summed);
    let Some(headline) = entries.first().map(|e| e.label.clone()) else {
        return Err(ReportError::Input("no solver or prior given".into()));
    };
    let traces = cfg.out.join("traces");
    std::fs::create_dir_all(&traces)
        .map_err(|e| ReportError::Io(traces.display().to_string(), e))?;
    let rows_path = cfg.out.join("rows.csv");
    let mut rows = Vec::new();
    if cfg.resume && rows_path.exists() {
        let text = std::fs::read_to_string(&rows_path)
            .map_err(|e| ReportError::Io(rows_path.display().to_string(), e))?;
        rows = rows_from_csv(&text)?;
    }
    let kept = rows.len();
    for image in &images {
        for &(level, ref setup) in &setups {
            if rows[..kept]
                .iter()
                .any(|r| r.image == image.name && r.level == level)
            {
                continue;
            }
            let how = CaseSimulation {
                true_medium: cfg.simulate_medium.map(|model| crate::physics::Medium {
                    model,
                    ..setup.medium
                }),
                ..CaseSimulation::default()
            };
            let case = simulate_case(image, setup, cfg.object_px, cfg.seed, &how)?;
            let mut trace_error = None;
            let new = run_case(
                image,
                level,
                &case,
                &entries,
                &cfg.methods,
                &cfg.opts,
                cfg.rl_best_iters,
                cfg.rl_fixed_iters,
                |label, trace| {
                    let stem = format!("{}_{level}_{}", image.name, label.replace(' ', "_"));
                    if let Err(e) = trace.write(&traces, &stem) {
                        let file = traces.join(format!("{stem}.{{csv,json}}"));
                        trace_error.get_or_insert(ReportError::Io(file.display().to_string(), e));
                    }
                },
            )?;
            if let Some(e) = trace_error {
                return Err(e);
            }
            new.iter().for_each(&mut on_row);
            rows.extend(new);
            crate::files::write_atomic(&rows_path, rows_csv(&rows))
                .map_err(|e| ReportError::Io(rows_path.display().to_string(), e))?;
        }
    }
    let md = write_summary(&rows, &headline, cfg)?;
    Ok((rows, md))
}

/// A prior built, with its name.
type NamedPrior = (String, Box<dyn Denoiser>);

/// The configured priors built, each with its name.
fn build_priors(cfg: &BenchConfig) -> Result<Vec<NamedPrior>, ReportError> {
    cfg.priors
        .iter()
        .map(|p| Ok((p.kind.name().to_string(), p.build()?)))
        .collect::<Result<_, PriorError>>()
        .map_err(|e| ReportError::Input(e.to_string()))
}

/// The summary of `rows` (table, verdict, figure) written into `cfg.out`.
fn write_summary(
    rows: &[BenchRow],
    headline: &str,
    cfg: &BenchConfig,
) -> Result<String, ReportError> {
    let model = cfg.setup.medium.model;
    let mut md = format!(
        "Light simulated with the {} medium, reconstructed with the {} medium.\n",
        cfg.simulate_medium.unwrap_or(model).name(),
        model.name()
    );
    md.push_str(&summary_markdown(
        rows,
        headline,
        &rl_default_label(&cfg.opts),
    ));
    md.push_str("\n### Every method against RL's best iteration chosen with the truth\n\n");
    md.push_str(&verdict_markdown(rows));
    write_time_figure(rows, &cfg.out.join("psnr_vs_time.png"))?;
    let md_path = cfg.out.join("summary.md");
    crate::files::write_atomic(&md_path, &md)
        .map_err(|e| ReportError::Io(md_path.display().to_string(), e))?;
    Ok(md)
}

/// The benchmark as a batch: one job per selected image, each running
/// `bench-recon IMAGES --image NAME ARGS...` (`args`: the run's other
/// flags); [`merge_benchmark`] gathers their rows into the one summary.
pub fn batch_jobs(
    cfg: &BenchConfig,
    args: &[String],
) -> Result<Vec<crate::batch::JobSpec>, ReportError> {
    let images = select(read_manifest(&cfg.images)?, &cfg.split, &cfg.only)?;
    let dir = std::path::absolute(&cfg.images).unwrap_or_else(|_| cfg.images.clone());
    Ok(images
        .iter()
        .map(|image| crate::batch::JobSpec {
            name: image.name.clone(),
            command: "bench-recon".into(),
            input: Some(dir.display().to_string()),
            args: ["--image".to_string(), image.name.clone()]
                .into_iter()
                .chain(args.iter().cloned())
                .collect(),
            timeout: None,
        })
        .collect())
}

/// The rows the jobs of [`batch_jobs`] wrote (`cfg.out/NAME/rows.csv`, in
/// the selection's order) and their summary, written into `cfg.out` as a
/// single run writes it. An image without rows is an error naming it.
pub fn merge_benchmark(cfg: &BenchConfig) -> Result<(Vec<BenchRow>, String), ReportError> {
    let images = select(read_manifest(&cfg.images)?, &cfg.split, &cfg.only)?;
    let mut rows = Vec::new();
    for image in &images {
        let path = cfg.out.join(&image.name).join("rows.csv");
        let text = std::fs::read_to_string(&path).map_err(|e| {
            ReportError::Io(
                format!(
                    "{} (has the batch job of {} finished?)",
                    path.display(),
                    image.name
                ),
                e,
            )
        })?;
        rows.extend(rows_from_csv(&text)?);
    }
    let priors = build_priors(cfg)?;
    let entries = pnp_entries(&cfg.solvers, &priors, cfg.time_summed);
    let headline = entries
        .first()
        .map(|e| e.label.clone())
        .ok_or_else(|| ReportError::Input("no solver or prior given".into()))?;
    crate::files::write_atomic(cfg.out.join("rows.csv"), rows_csv(&rows))
        .map_err(|e| ReportError::Io(cfg.out.join("rows.csv").display().to_string(), e))?;
    let md = write_summary(&rows, &headline, cfg)?;
    Ok((rows, md))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(method: &str, chose: Option<&str>, z: Option<f64>) -> BenchRow {
        BenchRow {
            image: "camera".into(),
            split: "held-out".into(),
            category: "natural photo".into(),
            level: 0.1,
            method: method.into(),
            psnr: 21.2785,
            ssim: 0.54844,
            wall_s: 2.419,
            iterations: 80,
            output_iteration: 80,
            best_psnr: 21.2785,
            best_iteration: 80,
            deviance_z: z,
            chose: chose.map(str::to_string),
            photons: 1_234_567.0,
        }
    }

    /// What `rows_csv` writes, `rows_from_csv` reads back to the same text.
    #[test]
    fn rows_round_trip_through_csv() {
        let rows = vec![
            row("pnp split ffdnet", None, Some(43.99)),
            row(AUTO, Some("rl-stack"), None),
        ];
        let text = rows_csv(&rows);
        let back = rows_from_csv(&text).unwrap();
        assert_eq!(back.len(), 2);
        assert_eq!(back[1].chose.as_deref(), Some("rl-stack"));
        assert_eq!(back[0].deviance_z, Some(43.99));
        assert_eq!(rows_csv(&back), text);
    }

    #[test]
    fn an_unreadable_row_names_its_line_and_field() {
        let mut text = rows_csv(&[row("rl-sum", None, None)]);
        text = text.replace(",21.2785,", ",twenty,");
        let e = rows_from_csv(&text).unwrap_err().to_string();
        assert!(
            e.contains("line 2") && e.contains("psnr") && e.contains("twenty"),
            "{e}"
        );
    }
}
