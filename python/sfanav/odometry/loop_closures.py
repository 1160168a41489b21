"""Loop-closure feedback training (thesis 6.2.1), image-based.

SFA learns what changes slowly in the *order* the training images come.
Where the training run passes a place twice (the crossings of a grid), the
thesis re-inserted the earlier image of that place, aligned to the current
orientation, right after the current one in the training sequence: a
feedback signal that the two must give similar outputs, i.e. more pairs of
images of the same place at different times (thesis 6.2.1). The thesis
found the loop closures from ground truth and, for real runs, with a visual
bag of words; here they come from the images and (optionally) odometry:

1. every training panorama's Fourier signature (row-wise azimuthal DFT
   magnitudes: rotation invariant; Menegatti et al. 2004);
2. for each image, the nearest earlier image by signature distance among
   those at least ``min_gap`` frames earlier (another pass) and, with
   odometry, within ``max_odometry_distance`` metres by odometry (a loose
   gate: odometry drifts);
3. accepted if that distance is at most ``accept`` times the image's
   distance to its own temporal neighbours ``neighbor_lag`` frames away (a
   match must look at least about as alike as a nearby frame);
4. the earlier image is aligned to the current orientation by the column
   shift that maximises the circular cross-correlation of the two.

:func:`interleave` builds a plain training sequence: each image, followed
by its aligned loop-closure partner if it has one. The thesis's feedback
(the partner woven into the simulated rotation) is
``Network.fit(..., loop_closures=...)``; the detectors live in
:mod:`sfanav.loopclosure`.
"""

from __future__ import annotations

from ..loopclosure.closures import LoopClosures, interleave, panorama_rows
from ..loopclosure.detectors import find_loop_closures

__all__ = ["LoopClosures", "find_loop_closures", "interleave", "panorama_rows"]
