//! # sfa-core
//!
//! Slow Feature Analysis (SFA) numerics for `sfanav`, in pure Rust:
//!
//! * [`expansion`]: polynomial expansion of degree 1..=d in a documented order;
//! * [`stats`]: streaming, mergeable, weighted mean / covariance /
//!   derivative-covariance accumulation;
//! * [`solve`]: the generalized symmetric eigenproblem by whitening with a
//!   relative tolerance and reported rank deficit;
//! * [`node`]: the SFA node (linear or polynomial, with the thesis's optional
//!   linear reduction stage) and beta values.
//!
//! Nothing here depends on Python; the `sfanav-py` crate binds it.

pub mod error;
pub mod expansion;
pub mod network;
pub mod node;
mod periodic;
pub mod rotation;
pub mod solve;
pub mod stats;
pub mod view;

pub use error::{Result, SfaError};
pub use expansion::{expand, expanded_dim, Expansion};
pub use node::{beta_values, NodeConfig, NodeState, SfaNode, SolutionState, StageState};
pub use solve::{solve, solve_up_to, GeneralizedEigen, DEFAULT_TOL};
pub use stats::{Accumulator, AccumulatorState};
pub use view::{Sample, View};
pub use network::{LayerGeometry, LayerSpec, Network, NetworkSpec};
pub use rotation::{LayerTrainer, Path, Rotation};
