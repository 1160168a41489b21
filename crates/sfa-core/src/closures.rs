//! Loop closures for feedback training (thesis 6.2.1): images of the
//! training run that show a place seen before, each with its earlier
//! partner aligned to its orientation. Training interleaves the simulated
//! rotation of such an image with its partner's (`A'_0, C_0, A'_1, C_1,
//! ...`), so that every rotation step also carries the change of
//! condition between the two visits; a weight in `[0, 1]` mixes the
//! interleaved sequence with the plain one (1: the thesis; lower weights
//! for less certain matches).

use std::collections::HashMap;

use crate::error::{Result, SfaError};

/// Loop closures of one training run: for image `current[i]` (an index into
/// the training images, in the order they are fed), its partner image
/// (already aligned, `height x period x channels`, row-major, as `f64`)
/// and the closure's weight in `[0, 1]`. At most one closure per image.
#[derive(Clone, Debug, PartialEq)]
pub struct LoopClosures {
    current: Vec<usize>,
    weights: Vec<f64>,
    images: Vec<f64>,
    size: usize,
    slot: HashMap<usize, usize>,
}

impl LoopClosures {
    /// `images` holds `current.len()` partner images of equal size, in the
    /// order of `current`. Errors: lengths that disagree, an image named
    /// twice, a weight outside `[0, 1]`, a non-finite pixel value.
    pub fn new(current: Vec<usize>, weights: Vec<f64>, images: Vec<f64>) -> Result<Self> {
        let m = current.len();
        if weights.len() != m {
            return Err(SfaError::ShapeMismatch { what: "loop-closure weights", expected: m, got: weights.len() });
        }
        if m == 0 {
            if !images.is_empty() {
                return Err(SfaError::InvalidArgument("partner images given without loop closures".into()));
            }
            return Ok(LoopClosures { current, weights, images, size: 0, slot: HashMap::new() });
        }
        if images.is_empty() || images.len() % m != 0 {
            return Err(SfaError::InvalidArgument(format!(
                "{} partner pixel values do not split into {m} images",
                images.len()
            )));
        }
        if let Some((i, w)) = weights.iter().enumerate().find(|(_, w)| !(w.is_finite() && (0.0..=1.0).contains(*w))) {
            return Err(SfaError::InvalidArgument(format!("loop closure {i}: the weight must be in [0, 1], got {w}")));
        }
        if let Some(at) = images.iter().position(|v| !v.is_finite()) {
            let size = images.len() / m;
            return Err(SfaError::InvalidArgument(format!(
                "loop closure {}: the partner image holds a non-finite value",
                at / size
            )));
        }
        let mut slot = HashMap::with_capacity(m);
        for (i, &c) in current.iter().enumerate() {
            if slot.insert(c, i).is_some() {
                return Err(SfaError::InvalidArgument(format!(
                    "image {c} has more than one loop closure; keep one per image"
                )));
            }
        }
        let size = images.len() / m;
        Ok(LoopClosures { current, weights, images, size, slot })
    }

    /// Number of closures.
    pub fn len(&self) -> usize {
        self.current.len()
    }

    /// True when there are none.
    pub fn is_empty(&self) -> bool {
        self.current.is_empty()
    }

    /// Values per partner image (`height x period x channels`).
    pub fn image_size(&self) -> usize {
        self.size
    }

    /// The largest image index a closure names (None when empty).
    pub fn max_current(&self) -> Option<usize> {
        self.current.iter().copied().max()
    }

    /// Bytes the partner images take.
    pub fn bytes(&self) -> usize {
        self.images.len() * std::mem::size_of::<f64>()
    }

    /// The aligned partner of training image `image` and the closure's
    /// weight, if it has one.
    pub fn partner(&self, image: usize) -> Option<(&[f64], f64)> {
        self.slot.get(&image).map(|&i| (&self.images[i * self.size..(i + 1) * self.size], self.weights[i]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn partners_are_found_by_image_index() {
        let lc = LoopClosures::new(vec![5, 2], vec![1.0, 0.5], vec![1.0, 2.0, 3.0, 4.0]).unwrap();
        assert_eq!(lc.len(), 2);
        assert_eq!(lc.image_size(), 2);
        assert_eq!(lc.partner(2), Some((&[3.0, 4.0][..], 0.5)));
        assert_eq!(lc.partner(5), Some((&[1.0, 2.0][..], 1.0)));
        assert_eq!(lc.partner(3), None);
        assert_eq!(lc.max_current(), Some(5));
    }

    #[test]
    fn bad_closures_are_errors() {
        assert!(LoopClosures::new(vec![1], vec![1.0, 1.0], vec![0.0]).is_err());
        assert!(LoopClosures::new(vec![1, 1], vec![1.0, 1.0], vec![0.0, 0.0]).is_err());
        assert!(LoopClosures::new(vec![1], vec![1.5], vec![0.0]).is_err());
        assert!(LoopClosures::new(vec![1], vec![f64::NAN], vec![0.0]).is_err());
        assert!(LoopClosures::new(vec![1], vec![1.0], vec![f64::INFINITY]).is_err());
        assert!(LoopClosures::new(vec![1, 2], vec![1.0, 1.0], vec![0.0, 0.0, 0.0]).is_err());
        assert!(LoopClosures::new(vec![], vec![], vec![]).unwrap().is_empty());
    }
}
