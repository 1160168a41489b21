//! The hierarchical receptive-field SFA network (thesis sections 3.3, 3.4.2).
//!
//! Layers of SFA nodes on regular grids: layer `l` sees a field of
//! `in_h x in_w x in_c` values (the image for layer 0, the outputs of layer
//! `l - 1` above it) and places receptive fields (RFs) of `rf_w x rf_h`
//! every `stride_w x stride_h`; each RF's values, flattened row by row, then
//! column, then channel, are one node input. The grid must tile its input
//! exactly. The last layer has a single RF over its whole input; its
//! outputs are the network's slow features.
//!
//! With weight sharing (the default) one node per layer is trained on the
//! RFs of every position and used at all of them; otherwise every position
//! has its own node.
//!
//! Training under simulated rotation lives in [`crate::rotation`],
//! [`crate::trainer`] and [`crate::training`].

use crate::error::{Result, SfaError};
use crate::expansion::expanded_dim;
use crate::node::{NodeConfig, NodeState, SfaNode};
use crate::pixel::Pixel;
use crate::view::View;
use rayon::prelude::*;

/// Largest expanded dimension the default reduction allows (thesis: <= 300
/// for numerical stability).
pub const DEFAULT_MAX_EXPANDED: usize = 300;

/// One layer as the user writes it.
#[derive(Clone, Debug, PartialEq)]
pub struct LayerSpec {
    /// RF width and height in units of the layer's input grid.
    pub rf: (usize, usize),
    /// Stride (width, height).
    pub stride: (usize, usize),
    /// Node outputs.
    pub n_out: usize,
    /// Linear SFA reduction before the expansion (None: the largest k whose
    /// expansion stays within [`DEFAULT_MAX_EXPANDED`], capped by the input
    /// dimension).
    pub reduce_to: Option<usize>,
    /// Expansion degree (2 = quadratic, 3 = cubic).
    pub degree: usize,
}

/// The whole network as the user writes it.
#[derive(Clone, Debug, PartialEq)]
pub struct NetworkSpec {
    /// Input height in pixels.
    pub height: usize,
    /// Input width in pixels (the width the network sees: the window).
    pub width: usize,
    /// 1 (gray) or 3 (RGB).
    pub channels: usize,
    pub layers: Vec<LayerSpec>,
    /// One node per layer (true) or one per RF position.
    pub weight_sharing: bool,
    /// Relative eigenvalue tolerance of every node.
    pub tol: f64,
    /// Mixed-precision statistics in every node (see [`NodeConfig`]).
    pub mixed_precision: bool,
}

/// A layer's resolved geometry.
#[derive(Clone, Debug, PartialEq)]
pub struct LayerGeometry {
    pub in_h: usize,
    pub in_w: usize,
    pub in_c: usize,
    pub rf_w: usize,
    pub rf_h: usize,
    pub stride_w: usize,
    pub stride_h: usize,
    /// RF grid: positions across and down.
    pub n_w: usize,
    pub n_h: usize,
    /// Node input dimension `rf_w * rf_h * in_c`.
    pub in_dim: usize,
    pub n_out: usize,
    /// Effective reduction `k`.
    pub reduce_to: usize,
    pub degree: usize,
}

impl LayerGeometry {
    /// Number of RF positions.
    pub fn n_positions(&self) -> usize {
        self.n_w * self.n_h
    }
    /// Gathers the RF at grid position (`row`, `col`) of a row-major
    /// `in_h x in_w x in_c` field into `out` (length `in_dim`).
    #[inline]
    pub fn gather(&self, field: &[f64], row: usize, col: usize, out: &mut [f64]) {
        let (r0, c0) = (row * self.stride_h, col * self.stride_w);
        let span = self.rf_w * self.in_c;
        for dr in 0..self.rf_h {
            let src = ((r0 + dr) * self.in_w + c0) * self.in_c;
            out[dr * span..(dr + 1) * span].copy_from_slice(&field[src..src + span]);
        }
    }
}

/// Checks a batch of `n` images of `size` values each: the length, and that
/// every value is finite (the error names the image, numbered from `first`).
pub(crate) fn check_images<P: Pixel>(images: &[P], n: usize, size: usize, first: usize) -> Result<()> {
    if images.len() != n * size {
        return Err(SfaError::ShapeMismatch {
            what: "image data length (n x height x width x channels)",
            expected: n * size,
            got: images.len(),
        });
    }
    if P::ALWAYS_FINITE {
        return Ok(());
    }
    if let Some(i) = images.iter().position(|v| !v.to_f64().is_finite()) {
        return Err(SfaError::InvalidArgument(format!("image {} contains NaN or infinity", first + i / size.max(1))));
    }
    Ok(())
}

fn default_reduce(in_dim: usize, degree: usize) -> Result<usize> {
    let mut k = 1;
    while k < in_dim && expanded_dim(k + 1, degree)? <= DEFAULT_MAX_EXPANDED {
        k += 1;
    }
    Ok(k)
}

impl NetworkSpec {
    /// Bytes the network needs to exist and to transform one image (its
    /// nodes, the image as f64, every layer's patches and output field),
    /// None if the figure overflows.
    pub fn model_bytes(&self, geom: &[LayerGeometry]) -> Option<usize> {
        use crate::memory::{bytes_of, total};
        let node = std::mem::size_of::<SfaNode>();
        let mut parts = vec![bytes_of(8, &[self.height, self.width, self.channels])];
        for g in geom {
            let nodes = if self.weight_sharing { 1 } else { g.n_positions() };
            parts.push(bytes_of(node, &[nodes]));
            parts.push(bytes_of(8, &[g.n_positions(), g.in_dim]));
            parts.push(bytes_of(8, &[g.n_positions(), g.n_out]));
        }
        total(&parts)
    }

    /// Bytes of the statistics that training layer `l` of `geom` holds at
    /// once (both stages of every node trained on it), None on overflow.
    pub fn training_bytes(&self, geom: &[LayerGeometry], l: usize) -> Option<usize> {
        use crate::memory::{bytes_of, total};
        let g = &geom[l];
        let ed = expanded_dim(g.reduce_to, g.degree).ok()?;
        let nodes = if self.weight_sharing { 1 } else { g.n_positions() };
        let per_node = total(&[bytes_of(16, &[g.in_dim, g.in_dim]), bytes_of(16, &[ed, ed])])?;
        per_node.checked_mul(nodes)
    }

    /// Checks the spec and resolves every layer's geometry; errors name the
    /// layer (1-based) and the reason.
    pub fn geometry(&self) -> Result<Vec<LayerGeometry>> {
        let bad = |m: String| Err(SfaError::InvalidArgument(m));
        if self.height == 0 || self.width == 0 {
            return bad(format!("image size {}x{} is empty", self.width, self.height));
        }
        if self.channels != 1 && self.channels != 3 {
            return bad(format!("channels must be 1 (gray) or 3 (RGB), got {}", self.channels));
        }
        if self.layers.is_empty() {
            return bad("a network needs at least one layer".into());
        }
        if !(self.tol.is_finite() && (0.0..1.0).contains(&self.tol)) {
            return bad(format!("tol must be in [0, 1), got {}", self.tol));
        }
        let (mut h, mut w, mut c) = (self.height, self.width, self.channels);
        let mut out = Vec::new();
        for (i, l) in self.layers.iter().enumerate() {
            let name = format!("layer {}", i + 1);
            let (rw, rh) = l.rf;
            let (sw, sh) = l.stride;
            if rw == 0 || rh == 0 || sw == 0 || sh == 0 || l.n_out == 0 {
                return bad(format!("{name}: RF size, stride and output dim must be positive"));
            }
            if rw > w || rh > h {
                return bad(format!("{name}: RF {rw}x{rh} is larger than its {w}x{h} input"));
            }
            if (w - rw) % sw != 0 || (h - rh) % sh != 0 {
                return bad(format!(
                    "{name}: RFs of {rw}x{rh} with stride {sw}x{sh} do not tile the {w}x{h} input \
                     ((width - rf) and (height - rf) must be multiples of the stride)"
                ));
            }
            if l.degree == 0 || l.degree > 3 {
                return bad(format!("{name}: degree must be 1, 2 or 3, got {}", l.degree));
            }
            let (n_w, n_h) = ((w - rw) / sw + 1, (h - rh) / sh + 1);
            let Some(in_dim) = rw.checked_mul(rh).and_then(|v| v.checked_mul(c)) else {
                return bad(format!("{name}: a {rw}x{rh} RF of {c} channels has too many values"));
            };
            if n_w.checked_mul(n_h).is_none() {
                return bad(format!("{name}: a {n_w}x{n_h} grid has too many positions"));
            }
            let k = match l.reduce_to {
                Some(0) => return bad(format!("{name}: reduce_to must be at least 1")),
                Some(k) if k > in_dim => {
                    return bad(format!("{name}: reduce_to {k} exceeds the node input dim {in_dim}"))
                }
                Some(k) => k,
                None => default_reduce(in_dim, l.degree)?,
            };
            let ed = expanded_dim(k, l.degree)?;
            if l.n_out > ed {
                return bad(format!(
                    "{name}: output dim {} exceeds the expanded dim {ed} of {k} reduced signals",
                    l.n_out
                ));
            }
            let last = i + 1 == self.layers.len();
            if last && (n_w, n_h) != (1, 1) {
                return bad(format!(
                    "{name}: the top layer must be a single RF over its whole {w}x{h} input, \
                     got a {n_w}x{n_h} grid"
                ));
            }
            out.push(LayerGeometry {
                in_h: h,
                in_w: w,
                in_c: c,
                rf_w: rw,
                rf_h: rh,
                stride_w: sw,
                stride_h: sh,
                n_w,
                n_h,
                in_dim,
                n_out: l.n_out,
                reduce_to: k,
                degree: l.degree,
            });
            h = n_h;
            w = n_w;
            c = l.n_out;
        }
        Ok(out)
    }
}

/// A network: spec, geometry and (trained or untrained) nodes.
#[derive(Clone, Debug)]
pub struct Network {
    spec: NetworkSpec,
    geom: Vec<LayerGeometry>,
    /// Per layer: one node (shared) or one per position (row-major grid).
    nodes: Vec<Vec<SfaNode>>,
    /// Number of layers trained so far (bottom up).
    trained: usize,
}

impl Network {
    /// Builds an untrained network; fails with a message naming the layer if
    /// the spec is inconsistent.
    pub fn new(spec: NetworkSpec) -> Result<Self> {
        let geom = spec.geometry()?;
        crate::memory::check(
            || {
                let n: usize = geom
                    .iter()
                    .map(|g| if spec.weight_sharing { 1 } else { g.n_positions() })
                    .fold(0, usize::saturating_add);
                format!(
                    "a network on {}x{}x{} images with {n} node{}",
                    spec.width,
                    spec.height,
                    spec.channels,
                    if n == 1 { "" } else { "s" }
                )
            },
            spec.model_bytes(&geom),
        )?;
        let nodes = geom
            .iter()
            .map(|g| {
                let count = if spec.weight_sharing { 1 } else { g.n_positions() };
                (0..count)
                    .map(|_| {
                        SfaNode::new(NodeConfig {
                            n_components: g.n_out,
                            degree: g.degree,
                            reduce_to: Some(g.reduce_to),
                            tol: spec.tol,
                            mixed_precision: spec.mixed_precision,
                        })
                    })
                    .collect::<Result<Vec<_>>>()
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Network { spec, geom, nodes, trained: 0 })
    }

    pub fn spec(&self) -> &NetworkSpec {
        &self.spec
    }
    pub fn geometry(&self) -> &[LayerGeometry] {
        &self.geom
    }
    pub fn n_layers(&self) -> usize {
        self.geom.len()
    }
    pub fn n_trained(&self) -> usize {
        self.trained
    }
    pub fn is_trained(&self) -> bool {
        self.trained == self.geom.len()
    }
    /// Number of outputs of the top node.
    pub fn n_outputs(&self) -> usize {
        self.geom.last().map_or(0, |g| g.n_out)
    }
    /// Input size (height, width, channels).
    pub fn input_shape(&self) -> (usize, usize, usize) {
        (self.spec.height, self.spec.width, self.spec.channels)
    }
    /// Nodes of a layer.
    pub fn nodes(&self, layer: usize) -> &[SfaNode] {
        &self.nodes[layer]
    }
    pub(crate) fn nodes_mut(&mut self, layer: usize) -> &mut Vec<SfaNode> {
        &mut self.nodes[layer]
    }
    pub(crate) fn set_trained(&mut self, n: usize) {
        self.trained = n;
    }

    /// Applies layer `l` (trained) to one field; returns the output field
    /// (`n_h x n_w x n_out`, row-major).
    pub fn apply_layer(&self, l: usize, field: &[f64]) -> Result<Vec<f64>> {
        let g = &self.geom[l];
        let np = g.n_positions();
        let mut patches = vec![0.0; np * g.in_dim];
        for r in 0..g.n_h {
            for c in 0..g.n_w {
                let p = r * g.n_w + c;
                g.gather(field, r, c, &mut patches[p * g.in_dim..(p + 1) * g.in_dim]);
            }
        }
        self.apply_nodes(l, &patches, np, |p| p)
    }

    /// Applies layer `l`'s node(s) to `n` row-major patches; `position(i)`
    /// gives patch `i`'s grid position (used without weight sharing).
    pub(crate) fn apply_nodes(
        &self,
        l: usize,
        patches: &[f64],
        n: usize,
        position: impl Fn(usize) -> usize,
    ) -> Result<Vec<f64>> {
        let g = &self.geom[l];
        let nodes = &self.nodes[l];
        if nodes.len() == 1 {
            return nodes[0].transform(View::from_slice(patches, n, g.in_dim)?);
        }
        let mut out = vec![0.0; n * g.n_out];
        for i in 0..n {
            let y = nodes[position(i)].transform(View::from_slice(
                &patches[i * g.in_dim..(i + 1) * g.in_dim],
                1,
                g.in_dim,
            )?)?;
            out[i * g.n_out..(i + 1) * g.n_out].copy_from_slice(&y);
        }
        Ok(out)
    }

    /// Runs layers `0..upto` on one image (`height x width x channels`,
    /// row-major) and returns the field layer `upto` sees.
    pub fn field_below<P: Pixel>(&self, image: &[P], upto: usize) -> Result<Vec<f64>> {
        let mut f: Vec<f64> = image.iter().map(|v| v.to_f64()).collect();
        for l in 0..upto {
            f = self.apply_layer(l, &f)?;
        }
        Ok(f)
    }

    /// Slow features of a batch of images (`n x height x width x channels`,
    /// row-major, `u8`, `f32` or `f64` pixels): `n x n_outputs`, in parallel
    /// over images (each converted to `f64` on its own).
    pub fn transform<P: Pixel>(&self, images: &[P], n: usize) -> Result<Vec<f64>> {
        if !self.is_trained() {
            return Err(SfaError::NotFitted(format!(
                "only {} of {} layers are trained",
                self.trained,
                self.geom.len()
            )));
        }
        let (h, w, c) = self.input_shape();
        let size = h * w * c;
        check_images(images, n, size, 0)?;
        let m = self.n_outputs();
        let outs: Vec<Result<Vec<f64>>> =
            images.par_chunks(size).map(|img| self.field_below(img, self.geom.len())).collect();
        let mut y = Vec::with_capacity(n * m);
        for o in outs {
            y.extend(o?);
        }
        Ok(y)
    }

    /// Node states, per layer (for saving).
    pub fn node_states(&self, with_statistics: bool) -> Vec<Vec<NodeState>> {
        self.nodes.iter().map(|ns| ns.iter().map(|n| n.state(with_statistics)).collect()).collect()
    }

    /// Rebuilds a network from its spec, node states and trained-layer count.
    pub fn from_states(spec: NetworkSpec, states: &[Vec<NodeState>], trained: usize) -> Result<Self> {
        let mut net = Network::new(spec)?;
        if states.len() != net.geom.len() || trained > net.geom.len() {
            return Err(SfaError::InvalidState("layer count disagrees with the spec".into()));
        }
        for (l, st) in states.iter().enumerate() {
            if st.len() != net.nodes[l].len() {
                return Err(SfaError::InvalidState(format!(
                    "layer {} has {} nodes, expected {}",
                    l + 1,
                    st.len(),
                    net.nodes[l].len()
                )));
            }
            let g = &net.geom[l];
            let want = NodeConfig {
                n_components: g.n_out,
                degree: g.degree,
                reduce_to: Some(g.reduce_to),
                tol: net.spec.tol,
                mixed_precision: net.spec.mixed_precision,
            };
            // The configurations and widths first: nothing of a node is
            // rebuilt before its state fits the layer.
            for s in st {
                if s.config != want || (s.n_features != 0 && s.n_features != g.in_dim) {
                    return Err(SfaError::InvalidState(format!(
                        "layer {} node disagrees with the spec (config {:?}, {} inputs; the layer has {:?}, {} inputs)",
                        l + 1,
                        s.config,
                        s.n_features,
                        want,
                        g.in_dim
                    )));
                }
            }
            let nodes = st.iter().map(SfaNode::from_state).collect::<Result<Vec<_>>>()?;
            for n in &nodes {
                if l < trained && !n.is_solved() {
                    return Err(SfaError::InvalidState(format!(
                        "layer {} is marked trained but a node is not solved",
                        l + 1
                    )));
                }
            }
            net.nodes[l] = nodes;
        }
        net.trained = trained;
        Ok(net)
    }
}
