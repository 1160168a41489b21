//! The SFA node: optional linear SFA reduction, polynomial expansion, SFA.
//!
//! A node is a short pipeline of *stages*. Each stage expands its input to a
//! degree (1 = no expansion), then applies SFA to a number of outputs:
//!
//! * `reduce_to = None`: one stage, `expand(degree)` then SFA to
//!   `n_components` (linear SFA for degree 1, polynomial SFA otherwise);
//! * `reduce_to = Some(k)`: the thesis's network node (section 3.4.2): linear
//!   SFA to `k`, expansion of those `k` signals to `degree`, SFA to
//!   `n_components`.
//!
//! Stages train one after another, each on a full pass over the data
//! ([`SfaNode::partial_fit`] feeds the stage in training,
//! [`SfaNode::finish_stage`] solves it and opens the next). Expansions are
//! formed block by block and never materialised for the whole data set.
//! If the reduction stage finds fewer than `k` directions above the
//! tolerance it keeps those it has and reports the rank deficit; the final
//! stage fails instead ([`SfaError::RankDeficient`]).

use crate::error::{Result, SfaError};
use crate::expansion::{expanded_dim, Expansion};
use crate::solve::{self, DEFAULT_TOL};
use crate::stats::{Accumulator, AccumulatorState, GraphPart};
use crate::view::{Sample, View};
use faer::linalg::matmul::matmul;
use faer::{Accum, MatRef, Par};
use rayon::prelude::*;

mod batch;

thread_local! {
    /// Expanded rows of one block in [`Stage::apply`], reused across calls.
    static APPLY_SCRATCH: std::cell::RefCell<Vec<f64>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// Hyper-parameters of a node.
#[derive(Clone, Debug, PartialEq)]
pub struct NodeConfig {
    /// Number of outputs (slowest first).
    pub n_components: usize,
    /// Degree of the polynomial expansion before the final SFA (1 = linear).
    pub degree: usize,
    /// Dimension of the linear SFA reduction before the expansion.
    pub reduce_to: Option<usize>,
    /// Relative tolerance below which covariance directions are dropped.
    pub tol: f64,
    /// Form outer products in f32 per cache-sized block, summed in f64
    /// ([`Accumulator::set_mixed_precision`]); the tolerance is then at least
    /// [`MIXED_TOL_FLOOR`].
    pub mixed_precision: bool,
}

/// Smallest relative tolerance used with mixed-precision statistics: their
/// moments carry a relative error of about 1e-6, so directions with less
/// variance than that are not resolved.
pub const MIXED_TOL_FLOOR: f64 = 1e-6;

impl NodeConfig {
    /// Linear SFA with `n_components` outputs.
    pub fn linear(n_components: usize) -> Self {
        NodeConfig { n_components, degree: 1, reduce_to: None, tol: DEFAULT_TOL, mixed_precision: false }
    }

    fn validate(&self) -> Result<()> {
        if self.n_components == 0 {
            return Err(SfaError::InvalidArgument("n_components must be at least 1".into()));
        }
        expanded_dim(1, self.degree)?; // checks the degree
        if self.reduce_to == Some(0) {
            return Err(SfaError::InvalidArgument("reduce_to must be at least 1".into()));
        }
        if !(self.tol.is_finite() && self.tol >= 0.0 && self.tol < 1.0) {
            return Err(SfaError::InvalidArgument(format!("tol must be in [0, 1), got {}", self.tol)));
        }
        Ok(())
    }
}

/// A solved stage: `y = (expand(x) - mean) @ projection`.
#[derive(Clone, Debug, PartialEq)]
pub struct SolutionState {
    /// Mean of the expanded stage input (length `expanded_dim`).
    pub mean: Vec<f64>,
    /// Row-major `expanded_dim x n_out` projection.
    pub projection: Vec<f64>,
    /// Number of outputs actually produced.
    pub n_out: usize,
    /// Delta values of the outputs, ascending.
    pub delta: Vec<f64>,
    /// Number of covariance directions kept.
    pub rank: usize,
    /// Dropped covariance eigenvalues (the rank deficit is their count).
    pub dropped: Vec<f64>,
}

/// Plain-data state of one stage.
#[derive(Clone, Debug, PartialEq)]
pub struct StageState {
    pub degree: usize,
    /// Requested number of outputs.
    pub n_out: usize,
    /// Dimension of the stage input before expansion.
    pub input_dim: usize,
    pub solution: Option<SolutionState>,
    pub stats: Option<AccumulatorState>,
}

/// Plain-data state of a node (see [`SfaNode::state`]).
#[derive(Clone, Debug, PartialEq)]
pub struct NodeState {
    pub config: NodeConfig,
    /// Number of input features (0 before the first data).
    pub n_features: usize,
    /// Index of the stage currently being trained.
    pub training_stage: usize,
    pub stages: Vec<StageState>,
}

#[derive(Clone, Debug)]
struct Stage {
    degree: usize,
    n_out: usize,
    input_dim: usize,
    expansion: Option<Expansion>,
    acc: Option<Accumulator>,
    solution: Option<SolutionState>,
    /// `mean P` of the solution (empty without one), subtracted by `apply`.
    bias: Vec<f64>,
}

impl Stage {
    /// A stage in training (with empty statistics).
    fn new(input_dim: usize, degree: usize, n_out: usize, mixed: bool) -> Result<Self> {
        let mut stage = Stage::plan(input_dim, degree, n_out)?;
        let mut a = Accumulator::new(stage.expanded_dim())?;
        a.set_mixed_precision(mixed);
        stage.acc = Some(a);
        Ok(stage)
    }

    /// A stage with neither statistics nor a solution (for restoring).
    fn plan(input_dim: usize, degree: usize, n_out: usize) -> Result<Self> {
        let expansion = if degree > 1 { Some(Expansion::new(input_dim, degree)?) } else { None };
        Ok(Stage { degree, n_out, input_dim, expansion, acc: None, solution: None, bias: Vec::new() })
    }

    /// Sets (or clears) the solution and the bias `mean P` that `apply`
    /// subtracts, computed once here rather than on every call.
    fn set_solution(&mut self, solution: Option<SolutionState>) {
        self.bias = match &solution {
            Some(sol) => {
                let (ed, m) = (sol.mean.len(), sol.n_out);
                (0..m).map(|j| (0..ed).map(|i| sol.mean[i] * sol.projection[i * m + j]).sum()).collect()
            }
            None => Vec::new(),
        };
        self.solution = solution;
    }

    fn expanded_dim(&self) -> usize {
        self.expansion.as_ref().map_or(self.input_dim, |e| e.out_dim())
    }

    /// The statistics in training; an error for a stage saved without them.
    fn acc_mut(&mut self) -> Result<&mut Accumulator> {
        self.acc.as_mut().ok_or_else(|| {
            SfaError::NotFitted("the model was saved without training statistics; it cannot be trained further".into())
        })
    }

    /// The stage's expansion of `n` finite input rows (borrowed when the
    /// stage does not expand); fails when a product overflows to infinity.
    fn expand_rows<'a>(&self, input: &'a [f64], n: usize) -> Result<std::borrow::Cow<'a, [f64]>> {
        let Some(ex) = &self.expansion else {
            return Ok(std::borrow::Cow::Borrowed(input));
        };
        let mut out = crate::memory::filled(n.saturating_mul(ex.out_dim()), 0.0, || {
            format!("the expansion of {n} rows to {} terms", ex.out_dim())
        })?;
        ex.expand_block(input, &mut out);
        if out.iter().any(|v| !v.is_finite()) {
            return Err(overflow(self.degree, input));
        }
        Ok(std::borrow::Cow::Owned(out))
    }

    /// Sequential forward pass of `n` rows (row-major, `input_dim` wide):
    /// `(expand(x) - mean) P`, computed as `expand(x) P - mean P` block by
    /// block, so the expanded rows only ever exist for one cache-sized
    /// block (in a per-thread scratch buffer) and are not centred in a
    /// separate pass.
    fn apply(&self, input: &[f64], n: usize) -> Vec<f64> {
        const BLOCK: usize = 128;
        let sol = self.solution.as_ref().expect("stage solved");
        let ed = self.expanded_dim();
        let m = sol.n_out;
        let rhs = MatRef::from_row_major_slice(&sol.projection, ed, m);
        let bias = &self.bias;
        let mut out = vec![0.0; n * m];
        match &self.expansion {
            None => {
                let lhs = MatRef::from_row_major_slice(&input[..n * ed], n, ed);
                let dst = faer::MatMut::from_row_major_slice_mut(&mut out, n, m);
                matmul(dst, Accum::Replace, lhs, rhs, 1.0, Par::Seq);
            }
            Some(ex) => APPLY_SCRATCH.with(|scratch| {
                let mut buf = scratch.borrow_mut();
                buf.resize(BLOCK * ed, 0.0);
                let d = self.input_dim;
                for (ob, ib) in out.chunks_mut(BLOCK * m).zip(input[..n * d].chunks(BLOCK * d)) {
                    let nb = ob.len() / m;
                    for (e, x) in buf.chunks_mut(ed).zip(ib.chunks(d)) {
                        ex.expand_row(x, e);
                    }
                    let lhs = MatRef::from_row_major_slice(&buf[..nb * ed], nb, ed);
                    let dst = faer::MatMut::from_row_major_slice_mut(ob, nb, m);
                    matmul(dst, Accum::Replace, lhs, rhs, 1.0, Par::Seq);
                }
            }),
        }
        for row in out.chunks_mut(m.max(1)) {
            row.iter_mut().zip(bias).for_each(|(v, b)| *v -= b);
        }
        out
    }

    fn solve(&mut self, tol: f64, strict: bool) -> Result<()> {
        let acc = self
            .acc
            .as_ref()
            .ok_or_else(|| SfaError::NotFitted("this stage has no training statistics (they were not saved)".into()))?;
        let c = acc.covariance()?;
        let cd = acc.derivative_covariance()?;
        let tol = if acc.is_mixed_precision() { tol.max(MIXED_TOL_FLOOR) } else { tol };
        let ed = self.expanded_dim();
        if strict && self.n_out > ed {
            return Err(SfaError::InvalidArgument(format!(
                "n_components ({}) exceeds the dimension of the (expanded) input ({ed})",
                self.n_out
            )));
        }
        let g = if strict {
            solve::solve(cd.as_ref(), c.as_ref(), self.n_out, tol)?
        } else {
            solve::solve_up_to(cd.as_ref(), c.as_ref(), self.n_out.min(ed), tol)?
        };
        let n_out = g.values.len();
        let projection =
            (0..ed).flat_map(|i| (0..n_out).map(move |j| (i, j))).map(|(i, j)| g.vectors[(i, j)]).collect();
        let solution = SolutionState {
            mean: acc.mean()?,
            projection,
            n_out,
            delta: g.values.clone(),
            rank: g.rank,
            dropped: g.dropped.clone(),
        };
        self.set_solution(Some(solution));
        Ok(())
    }
}

/// The error for finite input whose degree-`degree` expansion (or
/// projection) overflows to infinity.
fn overflow(degree: usize, input: &[f64]) -> SfaError {
    let big = input.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    SfaError::InvalidArgument(format!(
        "the input is finite but too large: its degree-{degree} expansion overflows to infinity \
         (largest magnitude {big:e}); scale the input down"
    ))
}

/// An SFA node. See the module documentation.
#[derive(Clone, Debug)]
pub struct SfaNode {
    config: NodeConfig,
    n_features: Option<usize>,
    stages: Vec<Stage>,
    training_stage: usize,
}

/// Rows per training block.
const TRAIN_BLOCK: usize = 8192;
/// Rows per parallel task in forward passes.
const TASK_ROWS: usize = 256;

impl SfaNode {
    /// A new, untrained node.
    pub fn new(config: NodeConfig) -> Result<Self> {
        config.validate()?;
        Ok(SfaNode { config, n_features: None, stages: Vec::new(), training_stage: 0 })
    }

    /// The node's hyper-parameters.
    pub fn config(&self) -> &NodeConfig {
        &self.config
    }

    /// Number of input features, once known.
    pub fn n_features(&self) -> Option<usize> {
        self.n_features
    }

    /// Number of stages (training passes) the node needs: 1, or 2 with a
    /// reduction.
    pub fn n_stages(&self) -> usize {
        if self.config.reduce_to.is_some() {
            2
        } else {
            1
        }
    }

    /// Index of the stage that [`partial_fit`](Self::partial_fit) feeds.
    pub fn training_stage(&self) -> usize {
        self.training_stage
    }

    /// Forgets all training.
    pub fn reset(&mut self) {
        self.n_features = None;
        self.stages.clear();
        self.training_stage = 0;
    }

    fn init(&mut self, d: usize) -> Result<()> {
        if d == 0 {
            return Err(SfaError::InvalidArgument("input has no features".into()));
        }
        let c = &self.config;
        let stage = match c.reduce_to {
            Some(k) => {
                if k > d {
                    return Err(SfaError::InvalidArgument(format!(
                        "reduce_to ({k}) exceeds the number of input features ({d})"
                    )));
                }
                Stage::new(d, 1, k, c.mixed_precision)?
            }
            None => {
                let ed = expanded_dim(d, c.degree)?;
                crate::memory::check(
                    || format!("SFA on the degree-{} expansion of {d} features ({ed} terms)", c.degree),
                    crate::memory::bytes_of(16, &[ed, ed]),
                )?;
                if c.n_components > ed {
                    return Err(SfaError::InvalidArgument(format!(
                        "n_components ({}) exceeds the dimension of the {}input ({ed})",
                        c.n_components,
                        if c.degree > 1 { "expanded " } else { "" }
                    )));
                }
                Stage::new(d, c.degree, c.n_components, c.mixed_precision)?
            }
        };
        self.n_features = Some(d);
        self.stages = vec![stage];
        self.training_stage = 0;
        Ok(())
    }

    fn check_width<T: Sample>(&self, x: &View<'_, T>) -> Result<()> {
        if let Some(d) = self.n_features {
            if x.ncols() != d {
                return Err(SfaError::ShapeMismatch {
                    what: "number of features (the model was trained on a different width)",
                    expected: d,
                    got: x.ncols(),
                });
            }
        }
        Ok(())
    }

    /// Sets the node up on the first data and returns the stage in training.
    fn begin_training<T: Sample>(&mut self, x: &View<'_, T>) -> Result<usize> {
        if self.n_features.is_none() {
            self.init(x.ncols())?;
        }
        self.check_width(x)?;
        let s = self.training_stage;
        self.stages[s].acc_mut()?;
        Ok(s)
    }

    /// Feeds a chunk of a time series to the stage in training (see
    /// [`Accumulator::update`] for the sequence semantics).
    pub fn partial_fit<T: Sample>(&mut self, x: View<'_, T>, new_sequence: bool) -> Result<()> {
        let s = self.begin_training(&x)?;
        // Invalidate the stage being trained.
        self.stages[s].set_solution(None);
        if s == 0 && self.stages[0].expansion.is_none() {
            // Zero-copy path: the accumulator reads the caller's array.
            return self.stages[0].acc.as_mut().expect("acc").update(x, new_sequence);
        }
        let n = x.nrows();
        if n == 0 {
            return Ok(());
        }
        x.check_finite("input")?;
        let mut start = 0;
        while start < n {
            let end = (start + TRAIN_BLOCK).min(n);
            let input = self.forward_block(x.rows(start, end), 0, s)?;
            let stage = &self.stages[s];
            let nb = end - start;
            let ed = stage.expanded_dim();
            let data = stage.expand_rows(&input, nb)?;
            let v = View::from_slice(&data, nb, ed)?;
            let first = start == 0 && new_sequence;
            self.stages[s].acc.as_mut().expect("acc").update(v, first)?;
            start = end;
        }
        Ok(())
    }

    /// True when the stage in training reads the raw input linearly (no
    /// expansion): its statistics are then those of the input itself, and
    /// may be formed by the caller ([`merge_statistics`](Self::merge_statistics)).
    pub fn trains_on_raw_input(&self) -> bool {
        match self.stages.get(self.training_stage) {
            Some(st) => self.training_stage == 0 && st.expansion.is_none(),
            // Not initialised yet: stage 0 is linear iff it is a reduction
            // or a degree-1 node.
            None => self.config.reduce_to.is_some() || self.config.degree == 1,
        }
    }

    /// Adds statistics of raw `dim`-wide input gathered elsewhere (e.g. by
    /// a structured algorithm) to the stage in training, which must read the
    /// raw input linearly ([`trains_on_raw_input`](Self::trains_on_raw_input)).
    pub fn merge_statistics(&mut self, stats: &Accumulator) -> Result<()> {
        if self.n_features.is_none() {
            self.init(stats.dim())?;
        }
        if !self.trains_on_raw_input() {
            return Err(SfaError::InvalidArgument(
                "the stage in training expands its input; it cannot take raw-input statistics".into(),
            ));
        }
        if Some(stats.dim()) != self.n_features {
            return Err(SfaError::ShapeMismatch {
                what: "dimension of the merged statistics",
                expected: self.n_features.unwrap_or(0),
                got: stats.dim(),
            });
        }
        let stage = &mut self.stages[0];
        stage.acc_mut()?.merge(stats)?;
        stage.set_solution(None);
        Ok(())
    }

    /// Adds statistics gathered elsewhere for the stage in training (e.g.
    /// by a copy of this node fed another part of the data, exported with
    /// [`statistics`](Self::statistics)): `stats` must have the dimension of
    /// that stage's (expanded) input. `n_features` sets the node up if it
    /// has not seen data yet (and must match it otherwise).
    pub fn merge_stage_statistics(&mut self, n_features: usize, stats: &Accumulator) -> Result<()> {
        if self.n_features.is_none() {
            self.init(n_features)?;
        }
        if self.n_features != Some(n_features) {
            return Err(SfaError::ShapeMismatch {
                what: "number of input features of the merged statistics",
                expected: self.n_features.unwrap_or(0),
                got: n_features,
            });
        }
        let stage = &mut self.stages[self.training_stage];
        if stats.dim() != stage.expanded_dim() {
            return Err(SfaError::ShapeMismatch {
                what: "dimension of the merged statistics (the stage in training)",
                expected: stage.expanded_dim(),
                got: stats.dim(),
            });
        }
        stage.acc_mut()?.merge(stats)?;
        stage.set_solution(None);
        Ok(())
    }

    /// Feeds a *graph* of samples to the stage in training: every row of `x`
    /// is a sample with weight `sample_weights[i]` (default 1; 0 makes a row
    /// usable as a pair end only), and every edge `[a, b]` is a derivative
    /// pair `x[b] - x[a]` with weight `edge_weights[e]` (default 1). The
    /// sequence API ([`partial_fit`](Self::partial_fit)) is the special case
    /// of a path graph. The stage's expansion is applied block by block;
    /// [`partial_fit_graphs`](Self::partial_fit_graphs) takes many graphs at
    /// once.
    pub fn partial_fit_graph<T: Sample>(
        &mut self,
        x: View<'_, T>,
        sample_weights: Option<&[f64]>,
        edges: &[[usize; 2]],
        edge_weights: Option<&[f64]>,
    ) -> Result<()> {
        // checked and gathered before anything is added: a failure leaves the statistics as they were
        self.partial_fit_graphs(0, &[GraphPart { x, weights: sample_weights, edges, edge_weights }])
    }

    /// [`partial_fit_graph`](Self::partial_fit_graph) for rows that already
    /// went through the solved stages `0..from` (`from >= 1`; the rows are
    /// stage `from`'s input, e.g. a first stage evaluated by the caller in
    /// a structured way).
    pub fn partial_fit_graph_from<T: Sample>(
        &mut self,
        from: usize,
        y: View<'_, T>,
        sample_weights: Option<&[f64]>,
        edges: &[[usize; 2]],
        edge_weights: Option<&[f64]>,
    ) -> Result<()> {
        if from == 0 {
            return Err(SfaError::InvalidArgument(format!(
                "rows after stage 0 cannot train stage {} (need 1 <= from <= stage in training)",
                self.training_stage
            )));
        }
        self.partial_fit_graphs(from, &[GraphPart { x: y, weights: sample_weights, edges, edge_weights }])
    }

    /// Width of stage `from`'s input: the raw width for 0, else the outputs
    /// of the solved stage `from - 1`.
    fn stage_input_width(&self, from: usize) -> Result<usize> {
        if from == 0 {
            return self.n_features.ok_or_else(|| SfaError::NotFitted("the node has not seen data".into()));
        }
        Ok(self
            .stages
            .get(from - 1)
            .and_then(|st| st.solution.as_ref())
            .ok_or_else(|| SfaError::NotFitted("an earlier stage is not solved".into()))?
            .n_out)
    }

    /// The solved linear first stage as `(mean, projection, k)`: outputs
    /// `(x - mean) P` with `P` row-major `n_features x k`. None when stage 0
    /// expands its input or is not solved, or is the node's only stage.
    pub fn linear_first_stage(&self) -> Option<(&[f64], &[f64], usize)> {
        let st = self.stages.first()?;
        if st.expansion.is_some() || self.stages.len() < 2 {
            return None;
        }
        st.solution.as_ref().map(|sol| (&sol.mean[..], &sol.projection[..], sol.n_out))
    }

    /// [`transform`](Self::transform) of rows that already went through the
    /// solved stages `0..from`.
    pub fn transform_from<T: Sample>(&self, from: usize, y: View<'_, T>) -> Result<Vec<T>> {
        let sol = self.final_solution()?;
        let width = self.stage_input_width(from)?;
        if y.ncols() != width {
            return Err(SfaError::ShapeMismatch { what: "width of the stage input", expected: width, got: y.ncols() });
        }
        y.check_finite("stage input")?;
        let out = self.forward_block(y, from, self.stages.len())?;
        debug_assert_eq!(out.len(), y.nrows() * sol.n_out);
        Ok(out.into_iter().map(T::from_f64).collect())
    }

    /// Rows of `x` (stage `from`'s input) pushed through stages
    /// `from..upto` (all solved), in parallel; row-major output of the
    /// width stage `upto` takes as input.
    fn forward_block<T: Sample>(&self, x: View<'_, T>, from: usize, upto: usize) -> Result<Vec<f64>> {
        let n = x.nrows();
        let d = x.ncols();
        let width = if upto == from {
            d
        } else {
            self.stages[upto - 1]
                .solution
                .as_ref()
                .ok_or_else(|| SfaError::NotFitted("an earlier stage is not solved".into()))?
                .n_out
        };
        let mut out = vec![0.0; n * width];
        out.par_chunks_mut(TASK_ROWS * width).enumerate().for_each(|(c, o)| {
            let r0 = c * TASK_ROWS;
            let nr = o.len() / width.max(1);
            let mut cur = vec![0.0; nr * d];
            for (k, row) in cur.chunks_mut(d).enumerate() {
                x.row_into(r0 + k, None, row);
            }
            for st in &self.stages[from..upto] {
                cur = st.apply(&cur, nr);
            }
            o.copy_from_slice(&cur);
        });
        Ok(out)
    }

    /// Solves the stage in training; if it is not the last, opens the next
    /// stage for the next pass over the data.
    pub fn finish_stage(&mut self) -> Result<()> {
        let s = self.training_stage;
        if self.stages.is_empty() {
            return Err(SfaError::NotFitted("no training data was given".into()));
        }
        let last = s + 1 == self.n_stages();
        let tol = self.config.tol;
        self.stages[s].solve(tol, last)?;
        if !last {
            let k = self.stages[s].solution.as_ref().expect("solved").n_out;
            let c = &self.config;
            let ed = expanded_dim(k, c.degree)?;
            if c.n_components > ed {
                return Err(SfaError::InvalidArgument(format!(
                    "n_components ({}) exceeds the expanded dimension ({ed}) of the {k} reduced signals",
                    c.n_components
                )));
            }
            self.stages.push(Stage::new(k, c.degree, c.n_components, c.mixed_precision)?);
            self.training_stage += 1;
        }
        Ok(())
    }

    /// Solves the last stage if it has new data (a no-op when solved).
    pub fn ensure_solved(&mut self) -> Result<()> {
        if self.stages.is_empty() {
            return Err(SfaError::NotFitted("no training data was given".into()));
        }
        if self.training_stage + 1 < self.n_stages() {
            return Err(SfaError::NotFitted(format!(
                "stage {} of {} is still in training; call finish_stage after each full pass",
                self.training_stage + 1,
                self.n_stages()
            )));
        }
        let s = self.training_stage;
        if self.stages[s].solution.is_none() {
            self.stages[s].solve(self.config.tol, true)?;
        }
        Ok(())
    }

    /// True when every stage is solved and the node can transform.
    pub fn is_solved(&self) -> bool {
        self.stages.len() == self.n_stages() && self.stages.iter().all(|s| s.solution.is_some())
    }

    fn final_solution(&self) -> Result<&SolutionState> {
        if !self.is_solved() {
            return Err(SfaError::NotFitted("call fit (or partial_fit) first".into()));
        }
        Ok(self.stages.last().and_then(|s| s.solution.as_ref()).expect("solved"))
    }

    /// Number of outputs.
    pub fn n_outputs(&self) -> usize {
        self.config.n_components
    }

    /// Applies the trained node: `n x n_components`, row-major, same sample
    /// type as the input.
    pub fn transform<T: Sample>(&self, x: View<'_, T>) -> Result<Vec<T>> {
        let sol = self.final_solution()?;
        let d = self.n_features.expect("fitted");
        if x.ncols() != d {
            return Err(SfaError::ShapeMismatch {
                what: "number of features (the model was trained on a different width)",
                expected: d,
                got: x.ncols(),
            });
        }
        x.check_finite("input")?;
        let m = sol.n_out;
        let y = self.forward_block(x, 0, self.stages.len())?;
        debug_assert_eq!(y.len(), x.nrows() * m);
        let y: Vec<T> = y.into_iter().map(T::from_f64).collect();
        if y.iter().any(|v| !v.to_f64().is_finite()) {
            return Err(SfaError::InvalidArgument(
                "the input is finite but too large: the node's outputs overflow to infinity \
                 (in the expansion or in the output precision); scale the input down"
                    .into(),
            ));
        }
        Ok(y)
    }

    /// Delta values of the outputs (ascending).
    pub fn delta_values(&self) -> Result<&[f64]> {
        Ok(&self.final_solution()?.delta)
    }

    /// Total rank deficit over the stages (dropped covariance directions).
    pub fn rank_deficits(&self) -> Vec<usize> {
        self.stages.iter().map(|s| s.solution.as_ref().map_or(0, |x| x.dropped.len())).collect()
    }

    /// Effective output count of each solved stage.
    pub fn stage_outputs(&self) -> Vec<usize> {
        self.stages.iter().map(|s| s.solution.as_ref().map_or(0, |x| x.n_out)).collect()
    }

    /// The training statistics of the stage in training.
    pub fn statistics(&self) -> Option<&Accumulator> {
        self.stages.get(self.training_stage).and_then(|s| s.acc.as_ref())
    }

    /// Plain-data state; `with_statistics` keeps the training statistics so
    /// training can continue after a round trip.
    pub fn state(&self, with_statistics: bool) -> NodeState {
        NodeState {
            config: self.config.clone(),
            n_features: self.n_features.unwrap_or(0),
            training_stage: self.training_stage,
            stages: self
                .stages
                .iter()
                .map(|s| StageState {
                    degree: s.degree,
                    n_out: s.n_out,
                    input_dim: s.input_dim,
                    solution: s.solution.clone(),
                    stats: if with_statistics { s.acc.as_ref().map(|a| a.state()) } else { None },
                })
                .collect(),
        }
    }

    /// Restores a node from [`state`](Self::state), checking consistency.
    pub fn from_state(st: &NodeState) -> Result<Self> {
        let bad = |m: String| Err(SfaError::InvalidState(m));
        st.config.validate()?;
        let mut node = SfaNode::new(st.config.clone())?;
        if st.n_features == 0 {
            if !st.stages.is_empty() {
                return bad("stages present but no input width".into());
            }
            return Ok(node);
        }
        let n_stages = node.n_stages();
        if st.stages.is_empty() || st.stages.len() > n_stages {
            return bad(format!("{} stages for a node of {n_stages}", st.stages.len()));
        }
        if st.training_stage.checked_add(1) != Some(st.stages.len()) {
            return bad("training stage index disagrees with the stage count".into());
        }
        let mut input_dim = st.n_features;
        for (i, ss) in st.stages.iter().enumerate() {
            let last = i + 1 == n_stages;
            let want_degree = if last { st.config.degree } else { 1 };
            let want_out = if last { st.config.n_components } else { st.config.reduce_to.unwrap_or(0) };
            if ss.degree != want_degree || ss.n_out != want_out || ss.input_dim != input_dim {
                return bad(format!("stage {i} does not match the node's configuration"));
            }
            // Everything is checked against the stored arrays before anything
            // is allocated: the sizes below are bounded by data that exists.
            let ed = expanded_dim(input_dim, ss.degree)
                .map_err(|_| SfaError::InvalidState(format!("stage {i}: input dimension {input_dim} is too large")))?;
            if ss.stats.is_none() && ss.solution.is_none() {
                return bad(format!("stage {i} has neither statistics nor a solution"));
            }
            if let Some(a) = &ss.stats {
                if a.dim != ed {
                    return bad(format!("stage {i} statistics have dimension {}, expected {ed}", a.dim));
                }
                if a.mixed != st.config.mixed_precision {
                    return bad(format!("stage {i} statistics disagree with the node's precision"));
                }
            }
            if let Some(sol) = &ss.solution {
                if sol.mean.len() != ed {
                    return bad(format!(
                        "stage {i} solution has a mean of {} values for an input of dimension {ed}",
                        sol.mean.len()
                    ));
                }
            }
            let mut stage = Stage::plan(input_dim, ss.degree, ss.n_out)?;
            stage.acc = match &ss.stats {
                Some(a) => Some(Accumulator::from_state(a)?),
                None => None,
            };
            if let Some(sol) = &ss.solution {
                let ok = sol.mean.len() == ed
                    && sol.n_out >= 1
                    && sol.n_out <= ss.n_out
                    && (!last || sol.n_out == ss.n_out)
                    && ed.checked_mul(sol.n_out) == Some(sol.projection.len())
                    && sol.delta.len() == sol.n_out
                    && sol.rank.checked_add(sol.dropped.len()) == Some(ed)
                    && sol.n_out <= sol.rank
                    && sol
                        .mean
                        .iter()
                        .chain(&sol.projection)
                        .chain(&sol.delta)
                        .chain(&sol.dropped)
                        .all(|v| v.is_finite());
                if !ok {
                    return bad(format!("stage {i} solution has inconsistent shapes or values"));
                }
                input_dim = sol.n_out;
            } else if i + 1 < st.stages.len() {
                return bad(format!("stage {i} is not solved but a later stage exists"));
            }
            stage.set_solution(ss.solution.clone());
            node.stages.push(stage);
        }
        node.n_features = Some(st.n_features);
        node.training_stage = st.training_stage;
        Ok(node)
    }
}

/// Delta to beta: `beta = sqrt(Delta) / (2 pi)` (thesis section 7.2.1),
/// Delta clipped at 0 against rounding.
pub fn beta_values(delta: &[f64]) -> Vec<f64> {
    delta.iter().map(|d| d.max(0.0).sqrt() / (2.0 * std::f64::consts::PI)).collect()
}

/// A node is moved into worker threads (GIL-free calls, parallel layers).
const _: () = {
    const fn assert_send_sync<T: Send + Sync>() {}
    assert_send_sync::<SfaNode>();
};
