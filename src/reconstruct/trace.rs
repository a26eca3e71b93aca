//! Per-iteration traces of every method, written as CSV and JSON.

use std::fmt::Write as _;
use std::path::Path;

use serde::Serialize;

/// One iteration of one method. Fields a method does not have are `None`.
#[derive(Debug, Clone, Default, Serialize)]
pub struct TraceRow {
    /// Iteration number (1-based; 0 is the starting point).
    pub iteration: usize,
    /// Wall time since the method started (s).
    pub wall_s: f64,
    /// Negative log-likelihood (plus any penalty) of the iterate.
    pub objective: Option<f64>,
    /// ADMM primal residual ||o - v|| / sqrt(N).
    pub primal_residual: Option<f64>,
    /// ADMM dual residual lambda ||v - v_prev|| / sqrt(N).
    pub dual_residual: Option<f64>,
    /// Denoiser noise level sigma = sqrt(beta / lambda).
    pub sigma: Option<f64>,
    /// ADMM penalty lambda.
    pub lambda: Option<f64>,
    /// Poisson deviance of the output iterate against the counts.
    pub deviance: Option<f64>,
    /// Deviance expected from Poisson noise alone at that iterate.
    pub expected_deviance: Option<f64>,
    /// Standard deviation of the deviance under Poisson noise at that iterate.
    pub deviance_sd: Option<f64>,
    /// Inner optimiser iterations (L-BFGS) in this iteration.
    pub inner_iterations: Option<u64>,
    /// PSNR against the truth (dB), when known.
    pub psnr: Option<f64>,
    /// SSIM against the truth, when known.
    pub ssim: Option<f64>,
}

/// A method's trace plus what it said about itself.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Trace {
    /// Method name (`pnp`, `rl-sum`, ...).
    pub method: String,
    /// Prior used, for methods that have one.
    pub prior: Option<String>,
    /// Notes: stopping reason, work left out, FFTs per gradient, clamping.
    pub notes: Vec<String>,
    /// Wall time of the whole run (s), set when it finishes: what the
    /// caller waited, including work after the last row.
    pub wall_s: f64,
    /// One row per iteration.
    pub rows: Vec<TraceRow>,
}

impl Trace {
    /// A new empty trace for `method`.
    pub fn new(method: &str) -> Self {
        Self {
            method: method.into(),
            ..Default::default()
        }
    }

    /// The CSV text: a header line and one line per row.
    pub fn to_csv(&self) -> String {
        let mut s = String::from(
            "method,iteration,wall_s,objective,primal_residual,dual_residual,sigma,lambda,deviance,expected_deviance,deviance_sd,inner_iterations,psnr,ssim\n",
        );
        let f = |v: Option<f64>| v.map_or(String::new(), |x| format!("{x:.9e}"));
        for r in &self.rows {
            writeln!(
                s,
                "{},{},{:.6},{},{},{},{},{},{},{},{},{},{},{}",
                self.method,
                r.iteration,
                r.wall_s,
                f(r.objective),
                f(r.primal_residual),
                f(r.dual_residual),
                f(r.sigma),
                f(r.lambda),
                f(r.deviance),
                f(r.expected_deviance),
                f(r.deviance_sd),
                r.inner_iterations.map_or(String::new(), |v| v.to_string()),
                f(r.psnr),
                f(r.ssim)
            )
            .expect("writing to a String");
        }
        s
    }

    /// Writes `STEM.csv` and `STEM.json` into `dir`.
    pub fn write(&self, dir: &Path, stem: &str) -> std::io::Result<()> {
        crate::files::write_atomic(dir.join(format!("{stem}.csv")), self.to_csv())?;
        let json = serde_json::to_string_pretty(self).expect("trace serialises");
        crate::files::write_atomic(dir.join(format!("{stem}.json")), json)
    }

    /// The row with the highest PSNR, when the truth was known.
    pub fn best_psnr(&self) -> Option<&TraceRow> {
        self.rows
            .iter()
            .filter(|r| r.psnr.is_some())
            .max_by(|a, b| a.psnr.partial_cmp(&b.psnr).expect("PSNR is not NaN"))
    }

    /// The iteration returned as the output, as the method's notes name it
    /// (`output: iteration N`); `None` when they name none.
    pub fn output_iteration(&self) -> Option<usize> {
        self.notes
            .iter()
            .find_map(|n| n.strip_prefix("output: iteration "))
            .and_then(|n| n.parse().ok())
    }
}
