//! Why a reconstruction cannot run.

/// Why a reconstruction cannot run.
#[derive(Debug, thiserror::Error)]
pub enum ReconstructError {
    /// A count is NaN, infinite or negative.
    #[error(
        "counts: bin {bin}, row {row}, column {col} is {value}; counts must be finite and >= 0"
    )]
    InvalidCount {
        /// Bin index in the stack.
        bin: usize,
        /// Row.
        row: usize,
        /// Column.
        col: usize,
        /// The offending value.
        value: f64,
    },
    /// Counts that cannot be thinned into halves.
    #[error(transparent)]
    Counts(#[from] crate::poisson::thinning::CountError),
    /// More memory than the budget.
    #[error(transparent)]
    Memory(#[from] crate::memory::MemoryError),
    /// A method's setting is out of range.
    #[error("{name} = {value} must be {want}")]
    Setting {
        /// The setting.
        name: &'static str,
        /// Its value.
        value: f64,
        /// What it must be.
        want: &'static str,
    },
    /// Stack and kernels do not fit together.
    #[error("{0}")]
    Shape(String),
    /// The optimiser reported an error.
    #[error("L-BFGS o-update: {0}")]
    Optimiser(String),
    /// A non-finite value appeared in the estimate.
    #[error("{method}: the estimate became non-finite at iteration {iteration}")]
    NonFinite {
        /// Method name.
        method: String,
        /// Iteration at which it happened.
        iteration: usize,
    },
}
