//! Many sample graphs at once: [`Accumulator::add_graphs`].
//!
//! Training feeds one graph per image (its patches as weighted samples,
//! the pairs between views as edges). Accumulating a whole batch of images
//! in one call forms the moments of all their rows with one set of
//! per-thread partial sums, instead of one set per image: the `d x d`
//! partial sums are allocated, zeroed and added up once per batch, and the
//! rows of every image are streamed through the same cache-sized blocks.
//! A row map (a node stage's polynomial expansion) may be applied block by
//! block, so the expanded rows are never materialised.

use super::Accumulator;
use crate::error::{Result, SfaError};
use crate::moments::{check_weights, first_non_finite, parallel_moments, Kind, Moments};
use crate::view::{Sample, View};

/// One graph of a batch: every row of `x` is a sample with weight
/// `weights[i]` (default 1; 0 makes the row a pair end only) and every
/// edge `[a, b]` a derivative pair `x[b] - x[a]` (rows of this graph) with
/// weight `edge_weights[e]` (default 1).
pub struct GraphPart<'a, T> {
    pub x: View<'a, T>,
    pub weights: Option<&'a [f64]>,
    pub edges: &'a [[usize; 2]],
    pub edge_weights: Option<&'a [f64]>,
}

/// A map applied to every row before it enters the statistics: input
/// width and `f(input_row, output_row)` (output width = the accumulator's
/// dimension). Its outputs are checked to be finite.
pub type RowMap<'a> = (usize, &'a (dyn Fn(&[f64], &mut [f64]) + Sync));

/// Index of the part holding global item `i`, given the prefix offsets
/// (`offsets[0] = 0`, `offsets[p + 1] - offsets[p]` items in part `p`).
fn part_of(offsets: &[usize], i: usize) -> usize {
    offsets.partition_point(|&o| o <= i) - 1
}

fn prefix(counts: impl Iterator<Item = usize>) -> Vec<usize> {
    let mut v = vec![0];
    for c in counts {
        v.push(v.last().unwrap() + c);
    }
    v
}

impl Accumulator {
    /// Adds the graphs `parts` (see [`GraphPart`]) as if each were given to
    /// [`add_graph`](Self::add_graph) in order, with `map` (if any) applied
    /// to every row first. Everything is checked and gathered before
    /// anything is added, so on error the statistics are unchanged. A
    /// non-finite mapped row is reported as `NonFinite` with the row index
    /// within its part.
    pub fn add_graphs<T: Sample>(&mut self, parts: &[GraphPart<'_, T>], map: Option<RowMap<'_>>) -> Result<()> {
        let d = self.dim;
        let in_d = map.map_or(d, |m| m.0);
        for p in parts {
            if p.x.ncols() != in_d {
                return Err(SfaError::ShapeMismatch { what: "number of features", expected: in_d, got: p.x.ncols() });
            }
            check_weights(p.weights, p.x.nrows(), "sample weights")?;
            check_weights(p.edge_weights, p.edges.len(), "pair weights")?;
            if let Some(e) = p.edges.iter().find(|e| e[0] >= p.x.nrows() || e[1] >= p.x.nrows()) {
                return Err(SfaError::InvalidArgument(format!(
                    "pair ({}, {}) refers to a sample outside 0..{}",
                    e[0],
                    e[1],
                    p.x.nrows()
                )));
            }
        }
        let parts: Vec<&GraphPart<'_, T>> = parts.iter().filter(|p| p.x.nrows() > 0).collect();
        if parts.is_empty() {
            return Ok(());
        }
        // One row, mapped (if there is a map) into `out`; `buf` is scratch.
        let row = |p: &GraphPart<'_, T>, i: usize, buf: &mut [f64], out: &mut [f64]| match map {
            Some((_, f)) => {
                p.x.row_into(i, None, buf);
                f(buf, out);
            }
            None => p.x.row_into(i, None, out),
        };
        let had_shift = self.shift.is_some();
        if !had_shift {
            let mut s = vec![0.0; d];
            row(parts[0], 0, &mut vec![0.0; in_d], &mut s);
            if let Some(col) = s.iter().position(|v| !v.is_finite()) {
                return Err(SfaError::NonFinite { what: "samples", row: 0, col });
            }
            self.first = Some(s.clone());
            self.shift = Some(s);
        }
        let no_samples = parts.iter().all(|p| p.weights.is_some_and(|w| w.iter().all(|&v| v == 0.0)));
        let gathered = (|| -> Result<(Moments, Option<Moments>)> {
            let ms = if no_samples {
                // Pair ends only: no sample products (rows are still checked).
                for p in &parts {
                    p.x.check_finite("samples")?;
                }
                Moments::empty(d)
            } else {
                self.batch_sample_moments(&parts, in_d, &row)?
            };
            let n_edges: usize = parts.iter().map(|p| p.edges.len()).sum();
            let mp = if n_edges == 0 { None } else { Some(self.batch_pair_moments(&parts, in_d, &row)?) };
            Ok((ms, mp))
        })();
        match gathered {
            Ok((ms, mp)) => {
                self.absorb(&ms);
                for p in &parts {
                    self.n_samples += p.x.nrows() as u64;
                    self.weight_sum += p.weights.map_or(p.x.nrows() as f64, |w| w.iter().sum());
                }
                if let Some(mp) = mp {
                    self.absorb(&mp);
                    for p in &parts {
                        self.pair_weight_sum += p.edge_weights.map_or(p.edges.len() as f64, |w| w.iter().sum());
                    }
                }
                Ok(())
            }
            Err(e) => {
                if !had_shift {
                    self.shift = None;
                    self.first = None;
                }
                Err(e)
            }
        }
    }

    fn batch_sample_moments<T: Sample, R>(&self, parts: &[&GraphPart<'_, T>], in_d: usize, row: &R) -> Result<Moments>
    where
        R: Fn(&GraphPart<'_, T>, usize, &mut [f64], &mut [f64]) + Sync,
    {
        let d = self.dim;
        let shift = self.shift.as_deref().expect("shift set");
        let offsets = prefix(parts.iter().map(|p| p.x.nrows()));
        let n = *offsets.last().unwrap();
        parallel_moments(n, d, Kind::Samples, self.mixed, "samples", |s, e, cb, _db, sum, _sum_d| {
            let mut buf = vec![0.0; in_d];
            let mut p = part_of(&offsets, s);
            let mut k = 0;
            for i in s..e {
                while i >= offsets[p + 1] {
                    p += 1;
                }
                let (part, local) = (parts[p], i - offsets[p]);
                let w = part.weights.map_or(1.0, |w| w[local]);
                let out = &mut cb[k * d..(k + 1) * d];
                row(part, local, &mut buf, out);
                if let Some(j) = first_non_finite(out) {
                    return Err((local, j));
                }
                if w == 0.0 {
                    continue;
                }
                let sw = w.sqrt();
                for ((a, v), c) in sum.iter_mut().zip(out.iter_mut()).zip(shift) {
                    *v -= c;
                    *a += w * *v;
                    *v *= sw;
                }
                k += 1;
            }
            Ok((k, 0))
        })
    }

    fn batch_pair_moments<T: Sample, R>(&self, parts: &[&GraphPart<'_, T>], in_d: usize, row: &R) -> Result<Moments>
    where
        R: Fn(&GraphPart<'_, T>, usize, &mut [f64], &mut [f64]) + Sync,
    {
        let d = self.dim;
        let offsets = prefix(parts.iter().map(|p| p.edges.len()));
        let n = *offsets.last().unwrap();
        parallel_moments(n, d, Kind::Pairs, self.mixed, "pairs", |s, e, _cb, db, _sum, sum_d| {
            let (mut buf, mut tmp) = (vec![0.0; in_d], vec![0.0; d]);
            let mut p = part_of(&offsets, s);
            for (k, i) in (s..e).enumerate() {
                while i >= offsets[p + 1] {
                    p += 1;
                }
                let (part, local) = (parts[p], i - offsets[p]);
                let [a, b] = part.edges[local];
                let out = &mut db[k * d..(k + 1) * d];
                row(part, b, &mut buf, out);
                row(part, a, &mut buf, &mut tmp);
                out.iter_mut().zip(&tmp).for_each(|(r, t)| *r -= t);
                if let Some(j) = first_non_finite(out) {
                    return Err((b, j));
                }
                let w = part.edge_weights.map_or(1.0, |w| w[local]);
                let sw = w.sqrt();
                for (acc, v) in sum_d.iter_mut().zip(out.iter_mut()) {
                    *acc += w * *v;
                    *v *= sw;
                }
            }
            Ok((0, e - s))
        })
    }
}

impl Accumulator {
    /// [`add_samples`](Self::add_samples) of several row blocks at once,
    /// each with the same `weights` (one per row). Checked and gathered
    /// before anything is added.
    pub fn add_samples_batch<T: Sample>(&mut self, blocks: &[View<'_, T>], weights: &[f64]) -> Result<()> {
        let parts: Vec<GraphPart<'_, T>> =
            blocks.iter().map(|&x| GraphPart { x, weights: Some(weights), edges: &[], edge_weights: None }).collect();
        self.add_graphs(&parts, None)
    }

    /// [`add_differences`](Self::add_differences) of several blocks of
    /// derivative rows at once, each with the same `weights` (one per
    /// row). Checked and gathered before anything is added.
    pub fn add_differences_batch<T: Sample>(&mut self, blocks: &[View<'_, T>], weights: &[f64]) -> Result<()> {
        let d = self.dim;
        for x in blocks {
            if x.ncols() != d {
                return Err(SfaError::ShapeMismatch { what: "number of features", expected: d, got: x.ncols() });
            }
            check_weights(Some(weights), x.nrows(), "difference weights")?;
        }
        let offsets = prefix(blocks.iter().map(|x| x.nrows()));
        let n = *offsets.last().unwrap();
        if n == 0 {
            return Ok(());
        }
        let m = parallel_moments(n, d, Kind::Pairs, self.mixed, "pairs", |s, e, _cb, db, _sum, sum_d| {
            let mut p = part_of(&offsets, s);
            for (k, i) in (s..e).enumerate() {
                while i >= offsets[p + 1] {
                    p += 1;
                }
                let local = i - offsets[p];
                let out = &mut db[k * d..(k + 1) * d];
                blocks[p].row_into(local, None, out);
                if let Some(j) = first_non_finite(out) {
                    return Err((local, j));
                }
                let w = weights[local];
                let sw = w.sqrt();
                for (acc, v) in sum_d.iter_mut().zip(out.iter_mut()) {
                    *acc += w * *v;
                    *v *= sw;
                }
            }
            Ok((0, e - s))
        })?;
        self.absorb(&m);
        self.pair_weight_sum += blocks.len() as f64 * weights.iter().sum::<f64>();
        Ok(())
    }
}
