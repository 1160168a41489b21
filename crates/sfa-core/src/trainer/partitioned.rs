//! Partitioned training of one layer: a pass split into partitions whose
//! statistics are accumulated apart (other threads, processes or machines)
//! and merged before the pass ends, with the same result as one trainer.

use super::*;

impl LayerTrainer {
    /// Starts a trainer at pass `pass` of `layer` on a network whose
    /// earlier stages of that layer are solved (by [`end_pass`](Self::end_pass)
    /// of earlier passes, possibly in another process): the entry point of
    /// partitioned (distributed) training. Each partition of the images is
    /// fed to its own trainer on its own copy of the network; the
    /// partitions' [`statistics`](Self::statistics) are merged into one
    /// trainer ([`merge_statistics`](Self::merge_statistics)) that ends the
    /// pass. The partition boundaries leave the result unchanged when each
    /// partition but the first is [`prime`](Self::prime)d with the image
    /// before it and every trainer gets the pass's
    /// [`set_reference_image`](Self::set_reference_image). No field cache.
    /// Loop closures: each partition's trainer gets the closures of its own
    /// images ([`set_loop_closures`](Self::set_loop_closures), indices
    /// counted within the partition). Spatial pairs may go to trainers of
    /// their own that are fed pairs only
    /// ([`feed_pairs_shifted`](Self::feed_pairs_shifted)).
    pub fn resume(net: &Network, layer: usize, pass: usize, rot: Rotation, path: TrainingPath) -> Result<Self> {
        let mut tr = LayerTrainer::new(net, layer, rot, path)?;
        let n_passes = tr.n_passes(net);
        if pass >= n_passes {
            return Err(SfaError::InvalidArgument(format!(
                "layer {} trains in {n_passes} passes, there is no pass {}",
                layer + 1,
                pass + 1
            )));
        }
        if net.n_trained() > layer {
            return Err(SfaError::InvalidArgument(format!("layer {} is already trained", layer + 1)));
        }
        for node in net.nodes(layer) {
            let stage = if node.n_features().is_some() { node.training_stage() } else { 0 };
            if stage != pass {
                return Err(SfaError::InvalidArgument(format!(
                    "layer {} of this network is at pass {}, not {}",
                    layer + 1,
                    stage + 1,
                    pass + 1
                )));
            }
        }
        tr.pass = pass;
        Ok(tr)
    }

    /// The pass in progress (0-based).
    pub fn pass(&self) -> usize {
        self.pass
    }

    /// The layer this trainer trains (0-based).
    pub fn layer(&self) -> usize {
        self.layer
    }

    /// Images fed (or merged) in the pass in progress.
    pub fn images_seen(&self) -> usize {
        self.images_seen
    }

    /// Spatial pairs added in the pass in progress (those with weight > 0
    /// between two different images, or an image and itself rolled).
    pub fn pairs_fed(&self) -> usize {
        self.pairs_fed
    }

    /// Sets the reference point of the first layer's lag-product statistics
    /// for this pass from `image` (one image, `height x period x
    /// channels`), which must be the first image of the whole pass; every
    /// partition's trainer gets the same one, so that the partitions'
    /// statistics are those of one run. A no-op where no lag products are
    /// formed; call before the first [`feed`](Self::feed).
    pub fn set_reference_image<P: Pixel>(&mut self, net: &Network, image: &[P]) -> Result<()> {
        let (h, _, c) = net.input_shape();
        let size = h * self.rot.period * c;
        check_images(image, 1, size, 0)?;
        if self.images_seen > 0 {
            return Err(SfaError::InvalidArgument("set the reference image before the first image of the pass".into()));
        }
        if self.uses_reference(net) {
            self.reference = Some(channel_means(image, c));
        }
        Ok(())
    }

    pub(super) fn uses_reference(&self, net: &Network) -> bool {
        self.layer == 0 && self.path == TrainingPath::Fast && self.lag_products && net.nodes(0)[0].trains_on_raw_input()
    }

    /// Continues the sequence from `image` (one image), the image before
    /// the next one fed, without adding its statistics: the derivative
    /// pairs between it and the next image are then counted by this
    /// trainer. For a partition whose first image continues the previous
    /// partition's last (that partition counts everything before). With
    /// loop closures the tail is the same whether or not that image has a
    /// closure (an interleaved sequence ends at the image's own last view).
    pub fn prime<P: Pixel>(&mut self, net: &Network, image: &[P]) -> Result<()> {
        let (h, _, c) = net.input_shape();
        let size = h * self.rot.period * c;
        check_images(image, 1, size, 0).map_err(|e| match e {
            SfaError::InvalidArgument(m) => SfaError::InvalidArgument(format!("the image before this partition: {m}")),
            e => e,
        })?;
        if self.cache.is_some() || self.caching {
            return Err(SfaError::InvalidArgument("prime works without the field cache".into()));
        }
        let (layer, rot) = (self.layer, self.rot);
        let gr = match self.path {
            TrainingPath::Fast => {
                fast_graph(net, &rot, &P::image_f64(image), layer, None, self.reference.as_deref())?.0
            }
            TrainingPath::Naive => naive_graph(net, &rot, image, layer)?,
        };
        let d = gr.width;
        let mut tail = vec![0.0; gr.last.len() * d];
        for (i, &r) in gr.last.iter().enumerate() {
            let src = (gr.lead + r) * d;
            tail[i * d..(i + 1) * d].copy_from_slice(&gr.rows[src..src + d]);
        }
        self.tail = Some(tail);
        self.by_tail = true;
        Ok(())
    }

    /// Ends the sequence: no derivative pair joins the last image fed and
    /// the next (separate recordings).
    pub fn break_sequence(&mut self) {
        self.tail = None;
        self.by_tail = true;
    }

    /// The statistics this trainer's images (and spatial pairs) added to
    /// the stage in training of each node of the layer (one per node; the
    /// statistics that the network held before are included, so feed a
    /// network fresh from the end of the previous pass).
    pub fn statistics(&self, net: &Network) -> Result<Vec<Accumulator>> {
        if self.images_seen == 0 && self.pairs_fed == 0 {
            return Err(SfaError::TooFewSamples { what: "training images in this partition", needed: 1, got: 0 });
        }
        net.nodes(self.layer)
            .iter()
            .map(|node| {
                node.statistics()
                    .cloned()
                    .ok_or_else(|| SfaError::NotFitted("the layer has no statistics in training".into()))
            })
            .collect()
    }

    /// Adds statistics of `n_images` images gathered by other trainers
    /// ([`statistics`](Self::statistics), merged in any order with
    /// [`Accumulator::merge`]) to the layer's nodes, one per node; then
    /// [`end_pass`](Self::end_pass) solves from them.
    pub fn merge_statistics(&mut self, net: &mut Network, stats: &[Accumulator], n_images: usize) -> Result<()> {
        let layer = self.layer;
        let d = net.geometry()[layer].in_dim;
        let nodes = net.nodes_mut(layer);
        if stats.len() != nodes.len() {
            return Err(SfaError::ShapeMismatch {
                what: "statistics per node of the layer",
                expected: nodes.len(),
                got: stats.len(),
            });
        }
        if let Some(node) = nodes.first() {
            let stage = if node.n_features().is_some() { node.training_stage() } else { 0 };
            if stage != self.pass {
                return Err(SfaError::InvalidArgument(format!(
                    "layer {} of this network is at pass {}, the trainer at {}",
                    layer + 1,
                    stage + 1,
                    self.pass + 1
                )));
            }
        }
        for (node, s) in nodes.iter_mut().zip(stats) {
            node.merge_stage_statistics(d, s)?;
        }
        self.images_seen += n_images;
        Ok(())
    }
}
