//! The `report`: every method on simulated scenes, against the truth.
//!
//! Per scene: a table of PSNR / SSIM / wall time per method, the paper's
//! Fig. 4 analogue (PSNR per time bin of scaled counts, RL and PnP on that bin, with
//! the full-stack results as lines) and error-against-run-time curves.
//!
//! Beside it, what the other jobs write and print: the held-out benchmarks
//! ([`bench`], [`hidden_bench`]), hidden-object volumes ([`hidden`]), the
//! instrument's description ([`instrument`]) and the calibrations' files
//! ([`calibration`]).

pub mod bench;
pub mod calibration;
pub mod hidden;
pub mod hidden_bench;
pub mod instrument;

use crate::named::{Named, named};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::denoise::Denoiser;
use crate::formats::png::write_png;
use crate::forward::Boundary;
use crate::physics::{Sampling, Setup};
use crate::plot::{self, Series};
use crate::reconstruct::method::{Method, MethodOptions, RlStop, Solver, run_method};
use crate::reconstruct::problem::Problem;
use crate::reconstruct::trace::Trace;
use crate::reconstruct::{ReconstructError, Reconstruction};
use crate::scene::Scene;
use crate::simulate::{SimulateError, Simulation, simulate};

/// One method's result on one scene.
#[derive(Debug, Clone, Serialize)]
pub struct MethodScore {
    /// Scene name.
    pub scene: String,
    /// Method label (e.g. `pnp`, `rl (best bin 96 ps)`).
    pub method: String,
    /// Prior, for PnP.
    pub prior: Option<String>,
    /// PSNR of the output (dB).
    pub psnr: f64,
    /// SSIM of the output.
    pub ssim: f64,
    /// Wall time (s).
    pub wall_s: f64,
    /// Iterations run.
    pub iterations: usize,
    /// Best PSNR over the iterations, chosen with the truth (dB).
    pub oracle_psnr: f64,
    /// Iteration of that best PSNR.
    pub oracle_iteration: usize,
}

/// Scores of the single-bin methods on one bin.
#[derive(Debug, Clone, Serialize)]
pub struct BinScore {
    /// Bin start (ps).
    pub start_ps: f64,
    /// Counts / kernel mass (no deblurring).
    pub scaled_counts_psnr: f64,
    /// Richardson-Lucy, output of the last iteration.
    pub rl_psnr: f64,
    /// Richardson-Lucy, best iteration by truth.
    pub rl_oracle_psnr: f64,
    /// PnP-ADMM on the bin.
    pub pnp_psnr: f64,
}

/// Everything measured on one scene.
pub struct SceneReport {
    /// Scene name.
    pub scene: String,
    /// Whole-stack methods and the best single-bin results.
    pub scores: Vec<MethodScore>,
    /// Per-bin scores (Fig. 4).
    pub bins: Vec<BinScore>,
    /// Traces of the whole-stack methods and the best bins.
    pub traces: Vec<Trace>,
}

/// Runs every method on `scene` simulated with `setup`, writing images,
/// traces and plots into `dir`; Richardson-Lucy runs `rl_iters`
/// iterations. `slice_step` picks every n-th bin for the
/// single-bin methods. `comparison` adds whole-stack PnP with a second
/// prior (labelled `pnp (NAME prior)`, never counted as a baseline).
/// `progress` receives a line per finished method.
#[allow(clippy::too_many_arguments)]
pub fn run_scene(
    scene: &Scene,
    setup: &Setup,
    boundary: Boundary,
    seed: u64,
    denoiser: &dyn Denoiser,
    comparison: Option<(&str, &dyn Denoiser)>,
    opts: &MethodOptions,
    rl_iters: usize,
    slice_step: usize,
    dir: &Path,
    mut progress: impl FnMut(&str),
) -> Result<SceneReport, ReportError> {
    let Simulation {
        truth,
        kernels,
        model,
        counts,
        ..
    } = simulate(setup, scene, Sampling::Integrated, boundary, seed)?;
    let problem = Problem {
        model,
        // Whole counts: exact in f32 and back.
        counts: counts.data.mapv(f64::from),
        bin_starts_ps: kernels.kept_bins().map(|b| b.start_ps).collect(),
        setup: setup.clone(),
        left_out: Vec::new(),
    };
    std::fs::create_dir_all(dir).map_err(|e| ReportError::Io(dir.display().to_string(), e))?;
    let name = scene.name();
    write_png(truth.view(), Some(1.0), &dir.join("truth.png"))?;
    // The baselines are ranked by their best iteration chosen with the
    // truth, so Richardson-Lucy runs its fixed count here.
    let opts = &MethodOptions {
        rl_stop: RlStop::After(rl_iters),
        ..*opts
    };
    let run_with = |method: Method,
                    bin: Option<usize>,
                    denoiser: &dyn Denoiser|
     -> Result<Reconstruction, ReportError> {
        Ok(run_method(
            &problem,
            method,
            bin,
            denoiser,
            opts,
            Some(truth.view()),
            |_| {},
        )?)
    };
    let run = |method: Method, bin: Option<usize>| run_with(method, bin, denoiser);
    let score = |label: String, r: &Reconstruction| {
        let last = r.trace.rows.last().expect("every method records a row");
        let best = r.trace.best_psnr().expect("truth is known");
        MethodScore {
            scene: name.clone(),
            method: label,
            prior: r.trace.prior.clone(),
            psnr: crate::metrics::psnr(r.image.view(), truth.view()),
            ssim: crate::metrics::ssim(r.image.view(), truth.view()),
            wall_s: r.trace.wall_s,
            iterations: last.iteration,
            oracle_psnr: best.psnr.unwrap_or(f64::NAN),
            oracle_iteration: best.iteration,
        }
    };
    let mut scores = Vec::new();
    let mut traces = Vec::new();
    let save = |r: &Reconstruction, file: &str| -> Result<(), ReportError> {
        let top = r.image.iter().fold(1.0f64, |m, &v| m.max(v));
        write_png(r.image.view(), Some(top), &dir.join(format!("{file}.png")))?;
        r.trace
            .write(dir, &format!("trace_{file}"))
            .map_err(|e| ReportError::Io(dir.display().to_string(), e))
    };
    for method in [Method::Pnp, Method::RlSum, Method::ScaledCounts] {
        let r = run(method, None)?;
        let label = if method == Method::ScaledCounts {
            "scaled-counts-sum"
        } else {
            method.name()
        };
        save(&r, label)?;
        progress(&format!("{name}: {label} done"));
        scores.push(score(label.into(), &r));
        traces.push(r.trace);
    }
    // The other solver on the same stack with the same prior: PSNR against
    // wall time of both lands in error_vs_time.png.
    let other = match opts.solver {
        Solver::Split => Solver::AdmmLbfgs,
        Solver::AdmmLbfgs => Solver::Split,
    };
    {
        let label = format!("pnp ({} solver)", other.name());
        let r = run_method(
            &problem,
            Method::Pnp,
            None,
            denoiser,
            &MethodOptions {
                solver: other,
                ..*opts
            },
            Some(truth.view()),
            |_| {},
        )?;
        let mut r = r;
        r.trace.method = label.clone();
        save(&r, &format!("pnp-{}", other.name()))?;
        progress(&format!("{name}: {label} done"));
        scores.push(score(label, &r));
        traces.push(r.trace);
    }
    if let Some((prior, d)) = comparison {
        let label = format!("pnp ({prior} prior)");
        let mut r = run_with(Method::Pnp, None, d)?;
        r.trace.method = label.clone();
        save(&r, &format!("pnp-{prior}"))?;
        progress(&format!("{name}: {label} done"));
        scores.push(score(label, &r));
        traces.push(r.trace);
    }
    let mut bins = Vec::new();
    let mut best_slices: [Option<(f64, MethodScore, Reconstruction)>; 2] = [None, None];
    for k in (0..problem.counts.shape()[0]).step_by(slice_step.max(1)) {
        let start = problem.bin_starts_ps[k];
        let scaled = run(Method::ScaledCounts, Some(k))?;
        let rl = run(Method::Rl, Some(k))?;
        let pnp = run(Method::PnpSlice, Some(k))?;
        let scaled_s = score(format!("scaled-counts (bin {start} ps)"), &scaled);
        let rl_s = score(format!("rl (bin {start} ps)"), &rl);
        let pnp_s = score(format!("pnp-slice (bin {start} ps)"), &pnp);
        bins.push(BinScore {
            start_ps: start,
            scaled_counts_psnr: scaled_s.psnr,
            rl_psnr: rl_s.psnr,
            rl_oracle_psnr: rl_s.oracle_psnr,
            pnp_psnr: pnp_s.psnr,
        });
        progress(&format!("{name}: bin {start} ps done"));
        for (slot, (s, r)) in best_slices.iter_mut().zip([(rl_s, rl), (pnp_s, pnp)]) {
            // RL is ranked by its best iteration, PnP by its output.
            let key = if r.trace.method == "rl" {
                s.oracle_psnr
            } else {
                s.psnr
            };
            if slot.as_ref().is_none_or(|(best, _, _)| key > *best) {
                *slot = Some((key, s, r));
            }
        }
    }
    for (file, (_, s, r)) in ["rl-best-bin", "pnp-slice-best-bin"]
        .iter()
        .zip(best_slices.into_iter().flatten())
    {
        save(&r, file)?;
        scores.push(s);
        traces.push(r.trace);
    }
    write_scene_files(dir, &name, &scores, &bins, &traces)?;
    Ok(SceneReport {
        scene: name,
        scores,
        bins,
        traces,
    })
}

fn write_scene_files(
    dir: &Path,
    name: &str,
    scores: &[MethodScore],
    bins: &[BinScore],
    traces: &[Trace],
) -> Result<(), ReportError> {
    let mut csv =
        String::from("start_ps,scaled_counts_psnr,rl_psnr,rl_oracle_psnr,pnp_slice_psnr\n");
    for b in bins {
        writeln!(
            csv,
            "{},{:.4},{:.4},{:.4},{:.4}",
            b.start_ps, b.scaled_counts_psnr, b.rl_psnr, b.rl_oracle_psnr, b.pnp_psnr
        )
        .expect("String");
    }
    let path = dir.join("per_bin.csv");
    crate::files::write_atomic(&path, csv)
        .map_err(|e| ReportError::Io(path.display().to_string(), e))?;
    let per_bin = |f: fn(&BinScore) -> f64, label: &str| Series {
        label: label.into(),
        points: bins.iter().map(|b| (b.start_ps, f(b))).collect(),
    };
    let (x0, x1) = (
        bins.first().map_or(0.0, |b| b.start_ps),
        bins.last().map_or(1.0, |b| b.start_ps),
    );
    let full = |label: &str| {
        scores.iter().find(|s| s.method == label).map(|s| Series {
            label: format!("{label} (all bins)"),
            points: vec![(x0, s.psnr), (x1, s.psnr)],
        })
    };
    let lines: Vec<Series> = ["scaled-counts-sum", "rl-sum", "pnp"]
        .iter()
        .filter_map(|l| full(l))
        .collect();
    plot::chart(
        &dir.join("fig4_psnr_per_bin.png"),
        &format!("{name}: PSNR per time bin (points: that bin only; lines: all bins)"),
        "bin start (ps)",
        "PSNR (dB)",
        &[
            per_bin(|b| b.scaled_counts_psnr, "scaled counts"),
            per_bin(|b| b.rl_oracle_psnr, "RL (best iteration)"),
            per_bin(|b| b.pnp_psnr, "PnP-ADMM"),
        ],
        &lines,
        false,
    )
    .map_err(ReportError::Plot)?;
    let curves: Vec<Series> = traces
        .iter()
        .filter(|t| t.rows.len() > 1)
        .map(|t| Series {
            label: t.method.clone(),
            points: t
                .rows
                .iter()
                .filter(|r| r.wall_s > 0.0)
                .filter_map(|r| r.psnr.map(|p| (r.wall_s, p)))
                .collect(),
        })
        .collect();
    plot::chart(
        &dir.join("error_vs_time.png"),
        &format!("{name}: PSNR against wall time"),
        "wall time (s)",
        "PSNR (dB)",
        &[],
        &curves,
        true,
    )
    .map_err(ReportError::Plot)
}

/// Markdown table of all scenes with the margins of full-stack PnP over the
/// best baseline (baselines at their best iteration chosen with the truth).
pub fn summary_markdown(reports: &[SceneReport]) -> String {
    let mut md = String::from(
        "| scene | method | prior | PSNR (dB) | SSIM | wall (s) | iterations | best PSNR by truth (dB) @ iteration |\n|---|---|---|---|---|---|---|---|\n",
    );
    for r in reports {
        for s in &r.scores {
            writeln!(
                md,
                "| {} | {} | {} | {:.2} | {:.4} | {:.2} | {} | {:.2} @ {} |",
                s.scene,
                s.method,
                s.prior.as_deref().unwrap_or(""),
                s.psnr,
                s.ssim,
                s.wall_s,
                s.iterations,
                s.oracle_psnr,
                s.oracle_iteration
            )
            .expect("String");
        }
    }
    md.push_str("\n| scene | PnP (data-driven stop) | best baseline (best iteration) | margin (dB) | PnP best by truth | stop rule loss (dB) |\n|---|---|---|---|---|---|\n");
    for r in reports {
        let Some(pnp) = r.scores.iter().find(|s| s.method == "pnp") else {
            continue;
        };
        let best = r
            .scores
            .iter()
            .filter(|s| s.method != "pnp" && !s.method.starts_with("pnp ("))
            .max_by(|a, b| {
                a.oracle_psnr
                    .max(a.psnr)
                    .total_cmp(&b.oracle_psnr.max(b.psnr))
            });
        if let Some(b) = best {
            let base = b.oracle_psnr.max(b.psnr);
            writeln!(
                md,
                "| {} | {:.2} | {} {:.2} | {:+.2} | {:.2} @ {} | {:.2} |",
                r.scene,
                pnp.psnr,
                b.method,
                base,
                pnp.psnr - base,
                pnp.oracle_psnr,
                pnp.oracle_iteration,
                pnp.oracle_psnr - pnp.psnr
            )
            .expect("String");
        }
    }
    md
}

/// CSV of every method's scores on every scene.
pub fn summary_csv(reports: &[SceneReport]) -> String {
    let mut csv = String::from(
        "scene,method,prior,psnr,ssim,wall_s,iterations,oracle_psnr,oracle_iteration\n",
    );
    for s in reports.iter().flat_map(|r| &r.scores) {
        writeln!(
            csv,
            "{},{},{},{:.4},{:.5},{:.4},{},{:.4},{}",
            s.scene,
            s.method,
            csv_field(s.prior.as_deref().unwrap_or_default()),
            s.psnr,
            s.ssim,
            s.wall_s,
            s.iterations,
            s.oracle_psnr,
            s.oracle_iteration
        )
        .expect("String");
    }
    csv
}

/// A CSV field, quoted when it holds a comma, quote or line break.
fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// Why a report could not be produced.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// Invalid physics.
    #[error(transparent)]
    Param(#[from] crate::physics::ParamError),
    /// A scene could not be rendered.
    #[error(transparent)]
    Scene(#[from] crate::scene::ImageError),
    /// A scene could not be simulated.
    #[error(transparent)]
    Simulate(#[from] SimulateError),
    /// A reconstruction failed.
    #[error(transparent)]
    Reconstruct(#[from] ReconstructError),
    /// A stack does not fit its physics.
    #[error(transparent)]
    Problem(#[from] crate::reconstruct::problem::ProblemError),
    /// An image could not be written.
    #[error(transparent)]
    Stack(#[from] crate::stack::StackError),
    /// A file could not be written.
    #[error("{0}: {1}")]
    Io(String, std::io::Error),
    /// A plot could not be drawn.
    #[error("plot: {0}")]
    Plot(String),
    /// An input file is unusable (names the file, line and value).
    #[error("{0}")]
    Input(String),
}

/// The instrument the report's scenes are measured with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Instrument {
    /// No instrument response and no background.
    #[default]
    Ideal,
    /// Also with an instrument response and a background, and what
    /// ignoring either costs.
    Realistic,
}

named!(Instrument {
    Ideal => "ideal",
    Realistic => "realistic",
});

/// The report's own settings (`scatterscope report`'s flags are these
/// fields, their docs the flags' help).
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct ReportSettings {
    /// The sensor's edges, simulated and modelled: sensor or periodic.
    #[cfg_attr(feature = "cli", arg(long, value_parser = crate::named::choice::<Boundary>(), default_value = ReportSettings::default().boundary.name()))]
    pub boundary: Boundary,
    /// Seed of the Poisson sampler.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = ReportSettings::default().seed))]
    pub seed: u64,
    /// Instrument: ideal, or realistic (also with an IRF and a background,
    /// and what ignoring either costs).
    #[cfg_attr(feature = "cli", arg(long, value_parser = crate::named::choice::<Instrument>(), default_value = ReportSettings::default().instrument.name()))]
    pub instrument: Instrument,
    /// Realistic instrument: background, a share of the mean expected count.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = ReportSettings::default().background_share))]
    pub background_share: f64,
    /// Run the single-bin methods on every n-th bin only.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = ReportSettings::default().slice_step))]
    pub slice_step: usize,
}

impl Default for ReportSettings {
    /// The sensor's edges, seed 0, the ideal instrument (a realistic one
    /// with a background of 5 % of the mean expected count), every bin.
    fn default() -> Self {
        Self {
            boundary: Boundary::default(),
            seed: 0,
            instrument: Instrument::default(),
            background_share: 0.05,
            slice_step: 1,
        }
    }
}

impl ReportSettings {
    /// The realistic instrument's background share, `None` for the ideal
    /// instrument.
    pub fn realistic_background(&self) -> Option<f64> {
        (self.instrument == Instrument::Realistic).then_some(self.background_share)
    }
}

/// Everything one `report` needs.
pub struct ReportConfig<'a> {
    /// The scenes (built-in or image files).
    pub scenes: Vec<Scene>,
    /// The physics they are measured with.
    pub setup: Setup,
    /// Edges, seed, instrument and bin step.
    pub settings: ReportSettings,
    /// The headline prior.
    pub denoiser: &'a dyn Denoiser,
    /// A second prior shown beside it (TV when the headline is not TV).
    pub comparison: Option<(&'a str, &'a dyn Denoiser)>,
    /// The methods' settings.
    pub opts: MethodOptions,
    /// Richardson-Lucy's iterations: the baselines run a fixed count, to
    /// be ranked by their best iteration chosen with the truth.
    pub rl_iters: usize,
    /// Output directory: one folder per scene, `summary.{md,csv}`.
    pub out: PathBuf,
}

/// The folder of `scene`'s outputs: its name, or a file's stem.
pub fn scene_dir(scene: &Scene) -> String {
    match scene {
        Scene::File(p) => p
            .file_stem()
            .map_or("file".into(), |s| s.to_string_lossy().into_owned()),
        other => other.name(),
    }
}

/// Runs the report: every scene through every method (and with the
/// realistic instrument when asked), `progress` told what is running;
/// writes the per-scene folders and `summary.{md,csv}` and returns the
/// Markdown summary.
pub fn run_report(
    cfg: &ReportConfig<'_>,
    mut progress: impl FnMut(&str),
) -> Result<String, ReportError> {
    let io = |path: &Path| {
        let name = path.display().to_string();
        move |e| ReportError::Io(name, e)
    };
    std::fs::create_dir_all(&cfg.out).map_err(io(&cfg.out))?;
    let mut reports = Vec::new();
    for scene in &cfg.scenes {
        let dir = cfg.out.join(scene_dir(scene));
        progress(&format!("{}: simulating", scene.name()));
        reports.push(run_scene(
            scene,
            &cfg.setup,
            cfg.settings.boundary,
            cfg.settings.seed,
            cfg.denoiser,
            cfg.comparison,
            &cfg.opts,
            cfg.rl_iters,
            cfg.settings.slice_step,
            &dir,
            &mut progress,
        )?);
        progress(&format!(
            "{}: done, files in {}",
            scene.name(),
            dir.display()
        ));
    }
    let mut md = summary_markdown(&reports);
    if let Some(share) = cfg.settings.realistic_background() {
        let (mut backgrounds, mut rows) = (Vec::new(), Vec::new());
        for scene in &cfg.scenes {
            progress(&format!("{}: realistic instrument", scene.name()));
            let (b, r) = instrument::instrument_costs(
                scene,
                &cfg.setup,
                share,
                cfg.settings.boundary,
                cfg.settings.seed,
                cfg.denoiser,
                &cfg.opts,
            )?;
            backgrounds.push((scene.name(), b));
            rows.extend(r);
        }
        md.push('\n');
        md.push_str(&instrument::instrument_markdown(
            &instrument::realistic(&cfg.setup),
            &backgrounds,
            &rows,
        ));
    }
    let md_path = cfg.out.join("summary.md");
    crate::files::write_atomic(&md_path, &md).map_err(io(&md_path))?;
    let csv_path = cfg.out.join("summary.csv");
    crate::files::write_atomic(&csv_path, summary_csv(&reports)).map_err(io(&csv_path))?;
    Ok(md)
}
