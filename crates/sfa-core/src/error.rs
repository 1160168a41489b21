//! Errors of the SFA core. Every fallible public function returns
//! [`SfaError`]; nothing in the public API panics on bad input.

use std::fmt;

/// What went wrong, with enough context to name the problem to a user.
#[derive(Debug, Clone, PartialEq)]
pub enum SfaError {
    /// An argument is outside its domain (a degree of 0, a negative weight, ...).
    InvalidArgument(String),
    /// Shapes disagree (feature count, weight count, ...).
    ShapeMismatch { what: &'static str, expected: usize, got: usize },
    /// The input holds NaN or an infinity.
    NonFinite { what: &'static str, row: usize, col: usize },
    /// Not enough data to form the requested statistic.
    TooFewSamples { what: &'static str, needed: usize, got: usize },
    /// After dropping directions whose variance is below the tolerance, fewer
    /// directions remain than outputs were requested.
    RankDeficient { rank: usize, requested: usize, dim: usize, tol: f64 },
    /// The model has not been trained (far enough) for this call.
    NotFitted(String),
    /// A saved state is internally inconsistent.
    InvalidState(String),
    /// A linear-algebra routine failed to converge.
    Numerical(String),
    /// A caller's callback (an image source, a progress report) failed;
    /// the caller holds the reason.
    Interrupted(String),
    /// A request needs more memory than the limit ([`crate::memory`]);
    /// `bytes` is None when the size does not even fit a `usize`.
    TooLarge { what: String, bytes: Option<usize>, limit: usize },
}

impl fmt::Display for SfaError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SfaError::InvalidArgument(m) => write!(f, "{m}"),
            SfaError::ShapeMismatch { what, expected, got } => {
                write!(f, "{what}: expected {expected}, got {got}")
            }
            SfaError::NonFinite { what, row, col } => {
                write!(f, "{what} contains NaN or infinity (first at row {row}, column {col})")
            }
            SfaError::TooFewSamples { what, needed, got } => {
                write!(f, "{what}: needs at least {needed}, got {got}")
            }
            SfaError::RankDeficient { rank, requested, dim, tol } => write!(
                f,
                "singular problem: the input covariance has only {rank} of {dim} directions \
                 with variance above {tol:e} x the largest, fewer than the {requested} \
                 requested outputs (the data are degenerate, e.g. constant or linearly \
                 dependent features; reduce n_components or add data)"
            ),
            SfaError::NotFitted(m) => write!(f, "not fitted: {m}"),
            SfaError::InvalidState(m) => write!(f, "invalid model state: {m}"),
            SfaError::Numerical(m) => write!(f, "numerical failure: {m}"),
            SfaError::Interrupted(m) => write!(f, "interrupted: {m}"),
            SfaError::TooLarge { what, bytes, limit } => {
                let need = bytes.map_or_else(|| "over 18 EB".to_string(), crate::memory::human);
                write!(
                    f,
                    "{what} needs {need} of memory; the limit is {} \
                     (physical memory or the address-space limit; see sfanav.set_memory_limit)",
                    crate::memory::human(*limit)
                )
            }
        }
    }
}

impl std::error::Error for SfaError {}

/// Result alias of the core.
pub type Result<T> = std::result::Result<T, SfaError>;
