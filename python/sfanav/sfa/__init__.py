"""Stage 1-2: images -> network -> slow features.

Slow Feature Analysis (thesis chapter 3) and the hierarchical
receptive-field network trained under simulated rotation (3.3-3.4, 5.1):

* :class:`SFA` (one node, scikit-learn style), :class:`Statistics` (the
  mergeable covariance / derivative-covariance accumulator), :func:`expand`;
* :class:`Network` with its presets (``sfanav/sfa/presets/*.toml``) and
  :class:`Rotation`; :func:`spatial_pairs` for graph-based training (:mod:`~sfanav.sfa.pairs`);
  loop-closure feedback (``Network.fit(loop_closures=...)``: the closures' partners from
  :mod:`sfanav.loopclosure.partners`, explicit partners checked in :mod:`~sfanav.sfa.feedback`);
* :mod:`~sfanav.sfa.diagnostics`: delta and eta values of the outputs;
* :mod:`~sfanav.sfa.modelfile`: versioned, checksummed, pickle-free model
  files and :func:`load`.

The numerics run in the Rust core (``sfanav._core``).
"""

from __future__ import annotations

from .diagnostics import (
    EtaValues,
    delta_values,
    eta_values,
    orientation_angles,
    plot_eta,
)
from .modelfile import FORMAT, VERSION, load, read_model, register_loader, save_model
from .config import PRESETS, resolve_config
from .network import DEFAULT_CACHE_LIMIT, Network, Rotation
from .pairs import spatial_pairs
from .node import SFA, NotFittedError, Statistics, beta_values, expand, expanded_dim

__all__ = ["DEFAULT_CACHE_LIMIT", "EtaValues", "FORMAT", "Network", "NotFittedError", "PRESETS", "Rotation", "SFA", "Statistics", "VERSION", "beta_values", "delta_values", "eta_values", "expand", "expanded_dim", "load", "orientation_angles", "plot_eta", "read_model", "register_loader", "resolve_config", "save_model", "spatial_pairs"]
