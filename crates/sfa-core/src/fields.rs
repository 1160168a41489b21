//! Per-image periodic fields and training graphs under simulated rotation
//! (the machinery of [`crate::rotation`] and [`crate::trainer`]): which
//! column offsets a layer sees, a layer's field of one image, the patches
//! and weighted pairs one image contributes to a layer's statistics on the
//! fast and the naive path.

use crate::error::{Result, SfaError};
use crate::network::{LayerGeometry, Network};
use crate::periodic;
use crate::pixel::Pixel;
use crate::rotation::Rotation;
use crate::view::View;

/// One image's training graph for a layer: patch rows, their sample weights,
/// weighted pairs inside the image, and which rows start and end the image's
/// per-position series (for the pairs between consecutive images). Row
/// indices count from the image's first own row.
pub(crate) struct ImageGraph {
    /// `lead + n` rows: the first `lead` are reserved for the previous
    /// image's last views (filled by the trainer, so the image's rows are
    /// never copied to prepend them); the image's own rows follow.
    pub(crate) rows: Vec<f64>,
    pub(crate) lead: usize,
    pub(crate) n: usize,
    /// Row width, and the node stage the rows enter at (0: raw patches; 1:
    /// outputs of the node's linear first stage, formed by
    /// [`periodic::first_stage_outputs`]).
    pub(crate) width: usize,
    pub(crate) from_stage: usize,
    pub(crate) weights: Vec<f64>,
    pub(crate) edges: Vec<[usize; 2]>,
    pub(crate) edge_weights: Vec<f64>,
    /// Per series (RF row x RF position): row of the first view.
    pub(crate) first: Vec<usize>,
    /// Per series: row of the last view.
    pub(crate) last: Vec<usize>,
    /// Per series, a second first row (the interleaved sequence of a loop
    /// closure starts with the partner's view; [`interleaved_graph`]):
    /// the pair from the previous image's last view goes to `first` with
    /// weight factor `1 - alt_weight` and to `alt_first` with `alt_weight`.
    /// Empty for a plain image.
    pub(crate) alt_first: Vec<usize>,
    pub(crate) alt_weight: f64,
    /// Statistics formed without rows (first layer, lag products; see
    /// `periodic.rs`), combined with other images' by the trainer; the
    /// rows are then only the first and last views, as weight-0 pair ends.
    pub(crate) moments: Option<periodic::LatticeImage>,
}

/// Distinct offsets `(k * step + j * t) mod period` for `k < views`,
/// `j < positions`, sorted, with an index map (usize::MAX where absent).
pub(crate) fn offset_set(rot: &Rotation, t: usize, positions: usize) -> (Vec<usize>, Vec<usize>) {
    let w = rot.period;
    let mut present = vec![false; w];
    for k in 0..rot.n_views() {
        for j in 0..positions {
            present[(k * rot.step + j * t) % w] = true;
        }
    }
    let offs: Vec<usize> = (0..w).filter(|&o| present[o]).collect();
    let mut idx = vec![usize::MAX; w];
    for (i, &o) in offs.iter().enumerate() {
        idx[o] = i;
    }
    (offs, idx)
}

/// Column strides `T_l` (product of strides up to and including `l`).
pub(crate) fn cum_strides(geom: &[LayerGeometry]) -> Vec<usize> {
    let mut t = 1;
    geom.iter()
        .map(|g| {
            t *= g.stride_w;
            t
        })
        .collect()
}

/// A layer's periodic output field of one image: `n_h x |offsets| x n_out`.
pub(crate) struct Field {
    pub(crate) data: FieldData,
    pub(crate) idx: Vec<usize>,
    pub(crate) n_off: usize,
    pub(crate) depth: usize,
}

/// Field values: f64, or f32 when cached for a mixed-precision network.
pub(crate) enum FieldData {
    F64(Vec<f64>),
    F32(Vec<f32>),
}

impl Field {
    /// The `depth` values at (row, offset index), written into `out`.
    #[inline]
    pub(crate) fn read(&self, row: usize, i: usize, out: &mut [f64]) {
        let at = (row * self.n_off + i) * self.depth;
        match &self.data {
            FieldData::F64(v) => out.copy_from_slice(&v[at..at + self.depth]),
            FieldData::F32(v) => {
                for (o, x) in out.iter_mut().zip(&v[at..at + self.depth]) {
                    *o = *x as f64;
                }
            }
        }
    }

    pub(crate) fn compact(self, f32_storage: bool) -> Field {
        match (self.data, f32_storage) {
            (FieldData::F64(v), true) => {
                Field { data: FieldData::F32(v.into_iter().map(|x| x as f32).collect()), ..self }
            }
            (data, _) => Field { data, ..self },
        }
    }

    pub(crate) fn bytes(&self) -> usize {
        match &self.data {
            FieldData::F64(v) => v.len() * 8,
            FieldData::F32(v) => v.len() * 4,
        }
    }
}

/// Gathers layer `l`'s periodic patches (rows `0..n_h`, offsets `offs`) of one
/// image, reading the image (l = 0) or the field below.
pub(crate) fn periodic_patches(
    g: &LayerGeometry,
    dilation: usize,
    period: usize,
    image: &[f64],
    below: Option<&Field>,
    offs: &[usize],
    lead: usize,
) -> Vec<f64> {
    let mut all = vec![0.0; (lead + g.n_h * offs.len()) * g.in_dim];
    let out = &mut all[lead * g.in_dim..];
    let c = g.in_c;
    for r in 0..g.n_h {
        for (oi, &o) in offs.iter().enumerate() {
            let p = &mut out[(r * offs.len() + oi) * g.in_dim..(r * offs.len() + oi + 1) * g.in_dim];
            let mut w = 0;
            for dr in 0..g.rf_h {
                let src_row = r * g.stride_h + dr;
                for m in 0..g.rf_w {
                    let col = (o + m * dilation) % period;
                    match below {
                        None => p[w..w + c]
                            .copy_from_slice(&image[(src_row * period + col) * c..(src_row * period + col + 1) * c]),
                        Some(f) => {
                            let i = f.idx[col];
                            debug_assert!(i != usize::MAX, "offset {col} missing below");
                            f.read(src_row, i, &mut p[w..w + c]);
                        }
                    }
                    w += c;
                }
            }
        }
    }
    all
}

/// Layer `l`'s periodic field of one image, from the image (l = 0) or the
/// field of layer `l - 1`.
pub(crate) fn layer_field(
    net: &Network,
    rot: &Rotation,
    l: usize,
    image: &[f64],
    below: Option<&Field>,
) -> Result<Field> {
    let geom = net.geometry();
    let t = cum_strides(geom);
    let g = &geom[l];
    let (offs, idx) = offset_set(rot, t[l], g.n_w);
    let dilation = if l == 0 { 1 } else { t[l - 1] };
    let n = g.n_h * offs.len();
    let node = &net.nodes(l)[0];
    let data = match (l, node.linear_first_stage()) {
        (0, Some(first)) => {
            let y = periodic::first_stage_outputs(g, image, rot.period, &offs, first);
            node.transform_from(1, View::from_slice(&y, n, first.2)?)?
        }
        _ => {
            let patches = periodic_patches(g, dilation, rot.period, image, below, &offs, 0);
            net.apply_nodes(l, &patches, n, |_| 0)?
        }
    };
    Ok(Field { data: FieldData::F64(data), idx, n_off: offs.len(), depth: g.n_out })
}

/// Periodic fields of layers `0..upto` of one image (weight sharing only).
pub(crate) fn periodic_fields(net: &Network, rot: &Rotation, image: &[f64], upto: usize) -> Result<Vec<Field>> {
    let mut fields: Vec<Field> = Vec::with_capacity(upto);
    for l in 0..upto {
        let f = layer_field(net, rot, l, image, fields.last())?;
        fields.push(f);
    }
    Ok(fields)
}

/// The fast graph of one image for `layer`; `below` is the field of layer
/// `layer - 1` (computed from the image when None). Also returns that field.
/// `reference`: per-channel reference point for the first layer's
/// lag-product statistics (None: always one row per patch).
pub(crate) fn fast_graph(
    net: &Network,
    rot: &Rotation,
    image: &[f64],
    layer: usize,
    below: Option<&Field>,
    reference: Option<&[f64]>,
) -> Result<(ImageGraph, Option<Field>)> {
    let geom = net.geometry();
    let g = &geom[layer];
    let t = cum_strides(geom);
    let computed = match (below, layer) {
        (None, l) if l > 0 => periodic_fields(net, rot, image, layer)?.pop(),
        _ => None,
    };
    let below = below.or(computed.as_ref());
    let (offs, idx) = offset_set(rot, t[layer], g.n_w);
    let dilation = if layer == 0 { 1 } else { t[layer - 1] };
    let (w, k_views, s) = (rot.period, rot.n_views(), rot.step);
    let no = offs.len();
    let mut mult = vec![0.0; no];
    let mut pmult = vec![0.0; no];
    for k in 0..k_views {
        for j in 0..g.n_w {
            let i = idx[(k * s + j * t[layer]) % w];
            mult[i] += 1.0;
            if k + 1 < k_views {
                pmult[i] += 1.0;
            }
        }
    }
    let lead = g.n_positions();
    let first_offset = |j: usize| (j * t[layer]) % w;
    let last_offset = |j: usize| ((k_views - 1) * s + j * t[layer]) % w;
    if let (0, Some(reference)) = (layer, reference) {
        let per_column = |m: &[f64]| {
            let mut v = vec![0.0; w];
            offs.iter().zip(m).for_each(|(&o, &x)| v[o] = x);
            v
        };
        if let Some(plan) = periodic::plan(g, &per_column(&mult), &per_column(&pmult)) {
            let moments = periodic::lattice_image(g, &plan, image, w, s, reference, net.spec().mixed_precision);
            // Rows: per RF row, the first views then the last views.
            let ends: Vec<usize> = (0..g.n_w).map(first_offset).chain((0..g.n_w).map(last_offset)).collect();
            let rows = periodic_patches(g, 1, w, image, None, &ends, lead);
            let n = g.n_h * ends.len();
            let series = |r: usize, j: usize, end: usize| r * 2 * g.n_w + end * g.n_w + j;
            let (mut first, mut last) = (Vec::new(), Vec::new());
            for r in 0..g.n_h {
                for j in 0..g.n_w {
                    first.push(series(r, j, 0));
                    last.push(series(r, j, 1));
                }
            }
            let graph = ImageGraph {
                rows,
                lead,
                n,
                width: g.in_dim,
                from_stage: 0,
                weights: vec![0.0; n],
                edges: Vec::new(),
                edge_weights: Vec::new(),
                first,
                last,
                alt_first: Vec::new(),
                alt_weight: 0.0,
                moments: Some(moments),
            };
            return Ok((graph, computed));
        }
    }
    // The first layer's second pass: rows enter after the node's solved
    // linear first stage, evaluated without gathering patches.
    let first = if layer == 0 { net.nodes(0)[0].linear_first_stage() } else { None };
    let (rows, width, from_stage) = match first {
        Some(first) => {
            let mut rows = vec![0.0; lead * first.2];
            rows.extend(periodic::first_stage_outputs(g, image, w, &offs, first));
            (rows, first.2, 1)
        }
        None => (periodic_patches(g, dilation, rot.period, image, below, &offs, lead), g.in_dim, 0),
    };
    let n = g.n_h * no;
    let mut weights = Vec::with_capacity(n);
    let (mut edges, mut edge_weights) = (Vec::new(), Vec::new());
    for r in 0..g.n_h {
        weights.extend_from_slice(&mult);
        for (oi, &o) in offs.iter().enumerate() {
            if pmult[oi] > 0.0 {
                edges.push([r * no + oi, r * no + idx[(o + s) % w]]);
                edge_weights.push(pmult[oi]);
            }
        }
    }
    let (mut first, mut last) = (Vec::new(), Vec::new());
    for r in 0..g.n_h {
        for j in 0..g.n_w {
            first.push(r * no + idx[first_offset(j)]);
            last.push(r * no + idx[last_offset(j)]);
        }
    }
    let graph = ImageGraph {
        rows,
        lead,
        n,
        width,
        from_stage,
        weights,
        edges,
        edge_weights,
        first,
        last,
        alt_first: Vec::new(),
        alt_weight: 0.0,
        moments: None,
    };
    Ok((graph, computed))
}

/// Checks spatial pairs `(a, b, w)` against `n` images.
pub(crate) fn check_pairs(pairs: &[(usize, usize, f64)], n: usize) -> Result<()> {
    for (e, &(a, b, w)) in pairs.iter().enumerate() {
        if a >= n || b >= n {
            return Err(SfaError::InvalidArgument(format!("pair {e} ({a}, {b}) names an image beyond the {n} given")));
        }
        if !(w.is_finite() && w >= 0.0) {
            return Err(SfaError::InvalidArgument(format!(
                "pair {e}: weights must be finite and non-negative, got {w}"
            )));
        }
    }
    Ok(())
}

/// View `k` of a `h x period x c` image through a window of `v` columns.
pub(crate) fn view<P: Pixel>(image: &[P], h: usize, period: usize, c: usize, v: usize, shift: usize) -> Vec<f64> {
    let mut out = vec![0.0; h * v * c];
    for r in 0..h {
        for col in 0..v {
            let src = (r * period + (shift + col) % period) * c;
            for (o, x) in out[(r * v + col) * c..(r * v + col + 1) * c].iter_mut().zip(&image[src..src + c]) {
                *o = x.to_f64();
            }
        }
    }
    out
}

pub(crate) fn naive_graph<P: Pixel>(net: &Network, rot: &Rotation, image: &[P], layer: usize) -> Result<ImageGraph> {
    let g = &net.geometry()[layer];
    let (h, v, c) = net.input_shape();
    let np = g.n_positions();
    let kv = rot.n_views();
    let lead = np;
    let mut rows = vec![0.0; (lead + kv * np) * g.in_dim];
    for k in 0..kv {
        let vw = view(image, h, rot.period, c, v, k * rot.step);
        let f = net.field_below(&vw, layer)?;
        for r in 0..g.n_h {
            for j in 0..g.n_w {
                let i = lead + k * np + r * g.n_w + j;
                g.gather(&f, r, j, &mut rows[i * g.in_dim..(i + 1) * g.in_dim]);
            }
        }
    }
    let mut edges = Vec::new();
    for k in 0..kv.saturating_sub(1) {
        for p in 0..np {
            edges.push([k * np + p, (k + 1) * np + p]);
        }
    }
    let ne = edges.len();
    Ok(ImageGraph {
        rows,
        lead,
        n: kv * np,
        width: g.in_dim,
        from_stage: 0,
        weights: vec![1.0; kv * np],
        edges,
        edge_weights: vec![1.0; ne],
        first: (0..np).collect(),
        last: (0..np).map(|p| (kv - 1) * np + p).collect(),
        alt_first: Vec::new(),
        alt_weight: 0.0,
        moments: None,
    })
}

/// The training graph of a loop closure (thesis 6.2.1): the current image's
/// simulated rotation interleaved with its aligned partner's, `A'_0, C_0,
/// A'_1, C_1, ...`, mixed with the plain rotation of the current image by
/// the closure's weight `w` in `[0, 1]`:
///
/// * samples: every view of `C` (weight 1) and of `A'` (weight `w`);
/// * pairs: `A'_k - C_k` (weight `w`), `C_k - A'_{k+1}` (weight `w`), and the
///   plain rotation pairs `C_k - C_{k+1}` (weight `1 - w`);
/// * the series starts at `A'_0` (weight `w`) and at `C_0` (`1 - w`) and ends
///   at `C_{K-1}`.
///
/// `w = 1` is the thesis's interleaved sequence, `w = 0` the plain image.
/// Both graphs must come from the same path (fast or naive) and layer, so
/// that rows correspond: the rotation successor of row `u` of `C` is read
/// off `gc`'s edges, and row `u` of `ga` is the same view (offset) of `A'`.
pub(crate) fn interleaved_graph(gc: ImageGraph, ga: ImageGraph, w: f64) -> Result<ImageGraph> {
    if gc.moments.is_some() || ga.moments.is_some() {
        return Err(SfaError::InvalidArgument("interleaved graphs need rows for every view (no lag products)".into()));
    }
    if (gc.n, gc.width, gc.from_stage, gc.lead) != (ga.n, ga.width, ga.from_stage, ga.lead) {
        return Err(SfaError::InvalidArgument("a loop closure's two graphs differ in shape".into()));
    }
    if !(w.is_finite() && (0.0..=1.0).contains(&w)) {
        return Err(SfaError::InvalidArgument(format!("a loop closure's weight must be in [0, 1], got {w}")));
    }
    let (n, d) = (gc.n, gc.width);
    let mut rows = gc.rows;
    rows.extend_from_slice(&ga.rows[ga.lead * d..]);
    let mut weights = gc.weights.clone();
    weights.extend(ga.weights.iter().map(|m| w * m));
    let mut edges = Vec::with_capacity(2 * gc.edges.len() + n);
    let mut edge_weights = Vec::with_capacity(2 * gc.edges.len() + n);
    for (&[u, v], &m) in gc.edges.iter().zip(&gc.edge_weights) {
        if w < 1.0 {
            edges.push([u, v]);
            edge_weights.push((1.0 - w) * m);
        }
        if w > 0.0 {
            edges.push([u, n + v]);
            edge_weights.push(w * m);
        }
    }
    if w > 0.0 {
        for (u, &m) in gc.weights.iter().enumerate() {
            if m > 0.0 {
                edges.push([n + u, u]);
                edge_weights.push(w * m);
            }
        }
    }
    let alt_first = gc.first.iter().map(|&f| n + f).collect();
    Ok(ImageGraph {
        rows,
        lead: gc.lead,
        n: 2 * n,
        width: d,
        from_stage: gc.from_stage,
        weights,
        edges,
        edge_weights,
        first: gc.first,
        last: gc.last,
        alt_first,
        alt_weight: w,
        moments: None,
    })
}

/// Bytes of one image's periodic field of layer `l` on the fast path (RF
/// rows x distinct column offsets x outputs x value size: 4 for a
/// mixed-precision network's cache, else 8).
pub(crate) fn field_bytes(net: &Network, rot: &Rotation, l: usize) -> usize {
    let g = &net.geometry()[l];
    let t = cum_strides(net.geometry())[l];
    let size = if net.spec().mixed_precision { 4 } else { 8 };
    g.n_h * offset_set(rot, t, g.n_w).0.len() * g.n_out * size
}
