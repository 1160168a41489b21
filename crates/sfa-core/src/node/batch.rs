//! Many sample graphs at once for the stage in training:
//! [`SfaNode::partial_fit_graphs`].

use super::{overflow, SfaNode};
use crate::error::{Result, SfaError};
use crate::stats::GraphPart;
use crate::view::{Sample, View};

impl SfaNode {
    /// Feeds a batch of sample graphs (e.g. one per image) to the stage in
    /// training, as [`partial_fit_graph`](Self::partial_fit_graph) (for
    /// `from = 0`) or [`partial_fit_graph_from`](Self::partial_fit_graph_from)
    /// (`from >= 1`) would one after the other, but with one accumulation
    /// for all of them: the stage's expansion is applied block by block
    /// and the expanded rows are never stored. The rows of every part are
    /// stage `from`'s input. On error nothing is added.
    pub fn partial_fit_graphs<T: Sample>(&mut self, from: usize, parts: &[GraphPart<'_, T>]) -> Result<()> {
        let Some(first) = parts.first() else {
            return Ok(());
        };
        let s = if from == 0 {
            self.begin_training(&first.x)?
        } else {
            if self.n_features.is_none() {
                return Err(SfaError::NotFitted("the node has not seen raw input yet".into()));
            }
            let s = self.training_stage;
            if from > s {
                return Err(SfaError::InvalidArgument(format!(
                    "rows after stage {from} cannot train stage {s} (need from <= stage in training)"
                )));
            }
            s
        };
        self.stages[s].acc_mut()?; // a stage saved without statistics cannot train
        let width = self.stage_input_width(from)?;
        for p in parts {
            if p.x.ncols() != width {
                return Err(SfaError::ShapeMismatch {
                    what: "width of the stage input",
                    expected: width,
                    got: p.x.ncols(),
                });
            }
            p.x.check_finite(if from == 0 { "input" } else { "stage input" })?;
        }
        if parts.iter().all(|p| p.x.nrows() == 0) {
            return Ok(());
        }
        self.stages[s].solution = None;
        // Rows pushed through the solved stages between `from` and `s`.
        let forwarded: Vec<Vec<f64>> = if from < s {
            parts.iter().map(|p| self.forward_block(p.x, from, s)).collect::<Result<_>>()?
        } else {
            Vec::new()
        };
        let super::Stage { expansion, acc, degree, .. } = &mut self.stages[s];
        let acc = acc.as_mut().expect("acc");
        let expand = |x: &[f64], out: &mut [f64]| expansion.as_ref().expect("expansion").expand_row(x, out);
        let map = expansion.as_ref().map(|e| (e.dim(), &expand as &(dyn Fn(&[f64], &mut [f64]) + Sync)));
        let result = if forwarded.is_empty() {
            acc.add_graphs(parts, map)
        } else {
            let views: Vec<View<'_, f64>> = forwarded
                .iter()
                .zip(parts)
                .map(|(f, p)| View::from_slice(f, p.x.nrows(), f.len() / p.x.nrows().max(1)))
                .collect::<Result<_>>()?;
            let fparts: Vec<GraphPart<'_, f64>> = views
                .into_iter()
                .zip(parts)
                .map(|(x, p)| GraphPart { x, weights: p.weights, edges: p.edges, edge_weights: p.edge_weights })
                .collect();
            acc.add_graphs(&fparts, map)
        };
        match result {
            // finite input whose expansion is not finite: an overflow
            Err(SfaError::NonFinite { .. }) if expansion.is_some() => {
                let big = if forwarded.is_empty() {
                    parts.iter().map(|p| max_abs(&p.x)).fold(0.0, f64::max)
                } else {
                    forwarded.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()))
                };
                Err(overflow(*degree, &[big]))
            }
            r => r,
        }
    }
}

fn max_abs<T: Sample>(x: &View<'_, T>) -> f64 {
    (0..x.nrows()).flat_map(|i| (0..x.ncols()).map(move |j| x.get(i, j).to_f64().abs())).fold(0.0, f64::max)
}
