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
//!   linear reduction stage) and beta values;
//! * [`network`]: the hierarchical receptive-field network;
//! * [`rotation`], [`trainer`], [`training`]: training under simulated
//!   rotation, one layer at a time ([`LayerTrainer`]) and the whole loop
//!   ([`fit`]) over images of any [`Pixel`] type from a [`BatchSource`];
//! * [`closures`]: loop closures for feedback training ([`LoopClosures`]);
//! * [`warping`]: the warping method's scores for the relative poses of loop
//!   closures ([`warp_scores`], [`min_warp_scores`], [`warp_and_min_warp_scores`]).
//!
//! Nothing here depends on Python; the `sfanav-py` crate binds it.

pub mod closures;
pub mod error;
pub mod expansion;
mod fields;
pub mod memory;
mod moments;
pub mod network;
pub mod node;
mod periodic;
pub mod pixel;
pub mod rotation;
pub mod solve;
pub mod stats;
pub mod trainer;
pub mod training;
pub mod view;
pub mod warping;

pub use closures::LoopClosures;
pub use error::{Result, SfaError};
pub use expansion::{expand, expanded_dim, Expansion};
pub use network::{LayerGeometry, LayerSpec, Network, NetworkSpec};
pub use node::{beta_values, NodeConfig, NodeState, SfaNode, SolutionState, StageState};
pub use pixel::{Batch, Pixel, Pixels};
pub use rotation::{transform_rotations, Rotation, TrainingPath};
pub use solve::{solve, solve_up_to, GeneralizedEigen, DEFAULT_TOL};
pub use stats::{Accumulator, AccumulatorState};
pub use trainer::LayerTrainer;
pub use training::{
    fit, BatchSource, CacheDecision, CachePolicy, FitOptions, FitReport, InMemory, Progress, ProgressEvent,
    SpatialPairs,
};
pub use view::{Sample, View};
pub use warping::{min_warp_scores, warp_and_min_warp_scores, warp_scores};
