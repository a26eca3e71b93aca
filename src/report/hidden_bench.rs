//! The hidden-object benchmark (`scatterscope bench-hidden`): every
//! confocal scan of a folder, at full counts and binomially thinned, through
//! the reconstruction methods; the front projection's correlation with the
//! published method's at full counts, the object's depth and the wall time
//! (median of repeated runs) per row, and the letter-U depth series.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use super::ReportError;
use crate::confocal::auto::AutoBlur;
use crate::confocal::poisson::PoissonEm;
use crate::confocal::published::Published;
use crate::confocal::published::authors_settings;
use crate::confocal::volume::{HiddenVolume, Projection, correlation};
use crate::confocal::{
    ConfocalScan, PoissonOptions, PublishedOptions, SlabOptics, VolumeReconstructor,
};
use crate::formats::detect::Format;
use crate::units::CM_PER_M;

/// Label of the published method.
pub const PUBLISHED: &str = "published (Wiener + f-k)";

/// Label of the default method.
pub const AUTO: &str = "auto (published + blur chosen on halves)";

/// Label of the Poisson method.
pub const POISSON: &str = "poisson (EM + f-k)";

/// Settings of the benchmark.
pub struct HiddenBenchConfig {
    /// Folder of `.mat` scans named as the published ones (`letter_s`,
    /// `letter_u_NN` for NN cm, ...).
    pub dir: PathBuf,
    /// Bin width of the scans (ps).
    pub bin_width_ps: f64,
    /// Fractions of the counts kept (1 = the scan itself).
    pub fractions: Vec<f64>,
    /// Seed of the thinning.
    pub seed: u64,
    /// Runs per row whose median is the time.
    pub repeats: usize,
    /// Also run the Poisson method with these settings (once per row;
    /// its depth is the benchmark's).
    pub poisson: Option<PoissonOptions>,
    /// Blur baselines: the published volume blurred by a 3-D Gaussian of
    /// these (across, depth) standard deviations in voxels, a row each.
    pub blurs: Vec<(f64, f64)>,
}

/// The blur baseline chosen on the 12 shared scans (σ in voxels across,
/// in depth): the pair of a fixed grid with the best mean front-projection
/// correlation at 10 % and 1 % of the counts (thinning seed 1); see
/// docs/journal/2026-11-26-twenty-third-session.md.
pub const BLUR_BASELINE: (f64, f64) = (1.5, 3.0);

/// Label of the published method followed by a blur.
pub fn blur_label((across, depth): (f64, f64)) -> String {
    format!("published + blur {across}x{depth}")
}

/// One scan at one count fraction through one method.
#[derive(Debug, Clone)]
pub struct HiddenBenchRow {
    /// Scan name (file stem).
    pub scan: String,
    /// Fraction of the counts kept.
    pub fraction: f64,
    /// Counts in the (thinned) scan.
    pub counts: f64,
    /// Method label.
    pub method: String,
    /// Front projection's correlation with the published method's at full
    /// counts.
    pub correlation: f64,
    /// Object depth by the median rule (cm).
    pub depth_cm: Option<f64>,
    /// Depth of the brightest voxel (cm).
    pub brightest_cm: f64,
    /// Median wall time of the reconstruction (s).
    pub wall_s: f64,
    /// For an iterative method: the iteration its stop chose, and the
    /// iterations it searched.
    pub stop: Option<(usize, usize)>,
    /// For the default method: the blur it chose (across, depth voxels).
    pub blur: Option<(f64, f64)>,
}

impl HiddenBenchRow {
    /// The row as one printed line.
    pub fn line(&self) -> String {
        format!(
            "{:<14} {:>5}% {:<26} corr {:.3}  depth {:>6}  {:.3} s{}",
            self.scan,
            self.fraction * 100.0,
            self.method,
            self.correlation,
            self.depth_cm.map_or("-".into(), |d| format!("{d:.1}")),
            self.wall_s,
            self.blur
                .map_or(String::new(), |b| format!("  blur {:.2}x{:.2}", b.0, b.1))
        )
    }
}

/// A blur baseline as given, `ACROSSxDEPTH` (Gaussian sigma in voxels), or
/// `none` (no baseline).
pub fn parse_blur(text: &str) -> Result<Option<(f64, f64)>, String> {
    if text == "none" {
        return Ok(None);
    }
    let bad = || {
        format!("blur {text:?}: give ACROSSxDEPTH, Gaussian sigma in voxels (e.g. 1.5x3), or none")
    };
    let (a, d) = text.split_once('x').ok_or_else(bad)?;
    let (a, d): (f64, f64) = (a.parse().map_err(|_| bad())?, d.parse().map_err(|_| bad())?);
    if !(a.is_finite() && d.is_finite() && a >= 0.0 && d >= 0.0) {
        return Err(bad());
    }
    Ok(Some((a, d)))
}

/// Writes `out/rows.csv` and `out/summary.md` (each whole or not at all);
/// the files written.
pub fn write_results(
    out: &Path,
    rows: &[HiddenBenchRow],
    summary: &str,
) -> Result<[PathBuf; 2], ReportError> {
    let io = |path: &Path, e| ReportError::Io(path.display().to_string(), e);
    std::fs::create_dir_all(out).map_err(|e| io(out, e))?;
    let files = [out.join("rows.csv"), out.join("summary.md")];
    crate::files::write_atomic(&files[0], rows_csv(rows)).map_err(|e| io(&files[0], e))?;
    crate::files::write_atomic(&files[1], summary).map_err(|e| io(&files[1], e))?;
    Ok(files)
}

/// Runs `f` `repeats` times; its last result and the median time (s).
fn timed<T>(
    repeats: usize,
    mut f: impl FnMut() -> Result<T, ReportError>,
) -> Result<(T, f64), ReportError> {
    let mut times = Vec::new();
    let mut last = None;
    for _ in 0..repeats.max(1) {
        let start = Instant::now();
        last = Some(f()?);
        times.push(start.elapsed().as_secs_f64());
    }
    times.sort_by(f64::total_cmp);
    Ok((last.expect("at least one run"), times[times.len() / 2]))
}

/// The scans of `dir` the benchmark knows settings for, by name.
pub fn scans_in(dir: &Path) -> Result<Vec<(String, PathBuf)>, ReportError> {
    let entries =
        std::fs::read_dir(dir).map_err(|e| ReportError::Io(dir.display().to_string(), e))?;
    let mut scans: Vec<(String, PathBuf)> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| Format::of_file(p) == Format::Mat)
        .filter_map(|p| {
            let stem = p.file_stem()?.to_str()?.to_string();
            authors_settings(&stem).map(|_| (stem, p))
        })
        .collect();
    scans.sort();
    if scans.is_empty() {
        return Err(ReportError::Input(format!(
            "{}: no scan named as the published ones (letter_s.mat, letter_u_50.mat, ...)",
            dir.display()
        )));
    }
    Ok(scans)
}

/// Runs the benchmark, showing each row to `on_row`; returns the rows and
/// the Markdown summary.
pub fn run_hidden_bench(
    cfg: &HiddenBenchConfig,
    mut on_row: impl FnMut(&HiddenBenchRow),
) -> Result<(Vec<HiddenBenchRow>, String), ReportError> {
    let mut rows = Vec::new();
    for (name, path) in scans_in(&cfg.dir)? {
        let (side, snr) = authors_settings(&name).expect("scans_in keeps known names");
        let scan = ConfocalScan::read_mat(&path, "meas", cfg.bin_width_ps, side)
            .map_err(|e| ReportError::Input(e.to_string()))?;
        let opts = PublishedOptions {
            snr,
            ..PublishedOptions::default()
        };
        let run = |method: &dyn VolumeReconstructor, s: &ConfocalScan| {
            method
                .reconstruct(s, &SlabOptics::PUBLISHED_FOAM)
                .map_err(|e| ReportError::Input(e.to_string()))
        };
        let published = |s: &ConfocalScan| run(&Published(opts), s).map(|r| r.volume);
        let reference = published(&scan)?.projection(Projection::Front);
        for &fraction in &cfg.fractions {
            let thinned = if fraction < 1.0 {
                scan.thinned(fraction, cfg.seed)
                    .map_err(|e| ReportError::Input(e.to_string()))?
            } else {
                scan.clone()
            };
            let (volume, wall_s) = timed(cfg.repeats, || published(&thinned))?;
            let row = row_of(
                &name, fraction, &thinned, PUBLISHED, &volume, &reference, wall_s,
            );
            on_row(&row);
            rows.push(row);
            for &blur in &cfg.blurs {
                let started = Instant::now();
                let blurred = volume.blurred(blur.0, blur.1);
                let label = blur_label(blur);
                let blur_s = started.elapsed().as_secs_f64();
                let row = row_of(
                    &name,
                    fraction,
                    &thinned,
                    &label,
                    &blurred,
                    &reference,
                    wall_s + blur_s,
                );
                on_row(&row);
                rows.push(row);
            }
            let (auto, wall_s) = timed(cfg.repeats, || run(&AutoBlur(opts), &thinned))?;
            let mut row = row_of(
                &name,
                fraction,
                &thinned,
                AUTO,
                &auto.volume,
                &reference,
                wall_s,
            );
            row.blur = auto.choice.map(|c| c.blur);
            on_row(&row);
            rows.push(row);
            if let Some(poisson) = &cfg.poisson {
                let (result, wall_s) = timed(1, || run(&PoissonEm(*poisson), &thinned))?;
                let mut row = row_of(
                    &name,
                    fraction,
                    &thinned,
                    POISSON,
                    &result.volume,
                    &reference,
                    wall_s,
                );
                let trace = result.trace.unwrap_or_default();
                let chosen = trace
                    .iter()
                    .min_by(|a, b| a.held_out_deviance.total_cmp(&b.held_out_deviance))
                    .map_or(0, |t| t.iteration);
                row.stop = Some((chosen, trace.len().saturating_sub(1)));
                on_row(&row);
                rows.push(row);
            }
        }
    }
    let md = summary_markdown(&rows, cfg);
    Ok((rows, md))
}

fn row_of(
    name: &str,
    fraction: f64,
    scan: &ConfocalScan,
    method: &str,
    volume: &HiddenVolume,
    reference: &ndarray::Array2<f64>,
    wall_s: f64,
) -> HiddenBenchRow {
    HiddenBenchRow {
        scan: name.to_string(),
        fraction,
        counts: scan.total(),
        method: method.to_string(),
        correlation: correlation(&volume.projection(Projection::Front), reference),
        depth_cm: volume.object_depth().map(|d| d * CM_PER_M),
        brightest_cm: volume.brightest_depth() * CM_PER_M,
        wall_s,
        stop: None,
        blur: None,
    }
}

/// The letter-U series of `rows` for `method` at full counts: (true
/// distance cm, estimate cm, brightest voxel cm) per scan.
pub fn letter_u_series(rows: &[HiddenBenchRow], method: &str) -> Vec<(f64, f64, f64)> {
    rows.iter()
        .filter(|r| r.method == method && r.fraction == 1.0)
        .filter_map(|r| {
            let cm: f64 = r.scan.strip_prefix("letter_u_")?.parse().ok()?;
            Some((cm, r.depth_cm?, r.brightest_cm))
        })
        .collect()
}

/// RMS of `estimate - truth` after subtracting their mean (one fitted
/// offset), and that offset.
pub fn rms_after_offset(pairs: &[(f64, f64)]) -> Option<(f64, f64)> {
    if pairs.is_empty() {
        return None;
    }
    let n = pairs.len() as f64;
    let offset = pairs.iter().map(|(t, e)| e - t).sum::<f64>() / n;
    let rms = (pairs
        .iter()
        .map(|(t, e)| (e - t - offset).powi(2))
        .sum::<f64>()
        / n)
        .sqrt();
    Some((rms, offset))
}

/// The rows as CSV.
pub fn rows_csv(rows: &[HiddenBenchRow]) -> String {
    let mut csv = String::from(
        "scan,fraction,counts,method,correlation,depth_cm,brightest_cm,wall_s,stop,searched,blur_across,blur_depth\n",
    );
    for r in rows {
        writeln!(
            csv,
            "{},{},{:.0},\"{}\",{:.4},{},{:.2},{:.4},{},{},{},{}",
            r.scan,
            r.fraction,
            r.counts,
            r.method,
            r.correlation,
            r.depth_cm.map_or(String::new(), |d| format!("{d:.2}")),
            r.brightest_cm,
            r.wall_s,
            r.stop.map_or(String::new(), |s| s.0.to_string()),
            r.stop.map_or(String::new(), |s| s.1.to_string()),
            r.blur.map_or(String::new(), |b| format!("{:.3}", b.0)),
            r.blur.map_or(String::new(), |b| format!("{:.3}", b.1))
        )
        .expect("String");
    }
    csv
}

fn summary_markdown(rows: &[HiddenBenchRow], cfg: &HiddenBenchConfig) -> String {
    let mut md = format!(
        "Thinning seed {}; times are the median of {} runs.\n\n| scan | counts kept | counts | method | front-projection correlation with published at full counts | object depth (cm) | brightest voxel (cm) | time (s) |\n|---|---|---|---|---|---|---|---|\n",
        cfg.seed, cfg.repeats
    );
    for r in rows {
        writeln!(
            md,
            "| {} | {}% | {:.0} | {} | {:.3} | {} | {:.1} | {:.3} |",
            r.scan,
            r.fraction * 100.0,
            r.counts,
            r.method,
            r.correlation,
            r.depth_cm.map_or("-".into(), |d| format!("{d:.2}")),
            r.brightest_cm,
            r.wall_s
        )
        .expect("String");
    }
    if rows.iter().any(|r| r.scan.starts_with("letter_u_")) {
        md.push_str("\n### Letter U depth (full counts, one fitted offset)\n\n| method | depth rule | scans | offset (cm) | RMS error (cm) |\n|---|---|---|---|---|\n");
        let mut methods = vec![PUBLISHED.to_string()];
        methods.extend(cfg.blurs.iter().map(|&b| blur_label(b)));
        methods.push(AUTO.to_string());
        methods.push(POISSON.to_string());
        for method in &methods {
            depth_rows(&mut md, rows, method);
        }
    }
    md
}

/// The letter-U depth rows of `method` (both depth rules).
fn depth_rows(md: &mut String, rows: &[HiddenBenchRow], method: &str) {
    let series = letter_u_series(rows, method);
    let median: Vec<(f64, f64)> = series.iter().map(|&(t, e, _)| (t, e)).collect();
    let brightest: Vec<(f64, f64)> = series.iter().map(|&(t, _, b)| (t, b)).collect();
    for (rule, pairs) in [
        ("median over the object, sub-voxel", median),
        ("brightest voxel", brightest),
    ] {
        if let Some((rms, offset)) = rms_after_offset(&pairs) {
            writeln!(
                md,
                "| {method} | {rule} | {} | {offset:+.2} | {rms:.2} |",
                pairs.len()
            )
            .expect("String");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_offset_removes_a_constant_bias() {
        let pairs = [(50.0, 53.0), (52.0, 55.0), (54.0, 57.0)];
        let (rms, offset) = rms_after_offset(&pairs).unwrap();
        assert!((offset - 3.0).abs() < 1e-12 && rms < 1e-12);
        let (rms, _) = rms_after_offset(&[(50.0, 51.0), (52.0, 52.0)]).unwrap();
        assert!((rms - 0.5).abs() < 1e-12);
    }
}
