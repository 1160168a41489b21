"""The online peer of ``6.2.1-changes-online``: the published online SFA,
IncSFA (:class:`sfanav.sfa.incsfa.IncSFA`), in place of the exact top stage.

A model here keeps a fitted localizer's lower layers frozen (what the
``updated`` policy keeps) and replaces the network's top stage by an IncSFA
learning from that stage's inputs:

* the sequence: the top stage's inputs under the simulated rotations the
  network was trained with, image after image
  (:func:`sfanav.localization.updates.top_stage_training_inputs`), the
  sequence the exact stage's statistics are summed over;
* the expansion: the exact stage's (``sfanav._core.expand`` with
  :func:`sfanav.localization.updates.top_stage_degree`, quadratic for the
  sfanav default);
* the outputs: as many as the network's;
* one run at a time (:meth:`IncSFATopStage.partial_fit`), several passes
  over each run's sequence before the next, CIMCA's step decreasing from
  pass to pass (:data:`INCSFA_MCA_RATES`): at a constant step the features
  stop approaching the exact ones after the first pass (docs/updates.md,
  "The online peer: IncSFA").

The features of a view are the IncSFA's outputs of its top-stage inputs
averaged over the localizer's pooled rotations, as
:func:`sfanav.localization.updates.top_stage_features` averages the exact
stage's. The readout is refitted on those features of the readout memory's
views and the new run's (:meth:`IncSFATopStage.fit_readout`), the kind the
exact update's readout has (:func:`sfanav.localization.updates.readout_spec_for_update`),
so that the two differ only in the top stage.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from .. import _core
from ..localization.updates import (
    ReadoutMemory,
    readout_spec_for_update,
    top_stage_degree,
    top_stage_features,
    top_stage_inputs,
    top_stage_training_inputs,
    updatable_memory,
)
from ..sfa.incsfa import IncSFA

__all__ = ["INCSFA_MCA_RATES", "INCSFA_WHITENED", "IncSFATopStage", "canonical_correlations", "incsfa_update",
           "memory_views", "views_with_run"]

INCSFA_MCA_RATES = (0.5, 0.1, 0.02)
"""One pass over each run's top-stage sequence per value: IncSFA's
``mca_rate`` (CIMCA's step as a fraction of its stable bound) in that pass."""
INCSFA_WHITENED = 40
"""Principal directions of the expanded inputs IncSFA whitens (its ``n_whitened``)."""


def canonical_correlations(F: Any, G: Any) -> np.ndarray:
    """The canonical correlations (descending, min(m, n) values in [0, 1])
    between two feature sets of the same samples, F (N, m) and G (N, n):
    how much of one set's span the other reproduces, whatever the order,
    sign and mixing of its features."""
    A = np.asarray(F, dtype=np.float64)
    B = np.asarray(G, dtype=np.float64)
    if A.ndim != 2 or B.ndim != 2 or len(A) != len(B) or len(A) < 2:
        raise ValueError(f"F and G must be (N, m) and (N, n) with the same N >= 2, got {A.shape} and {B.shape}")

    def basis(X: np.ndarray) -> np.ndarray:
        U, s, _ = np.linalg.svd(X - X.mean(axis=0), full_matrices=False)
        return U[:, s > 1e-10 * max(float(s.max(initial=0.0)), 1e-300)]

    return np.clip(np.linalg.svd(basis(A).T @ basis(B), compute_uv=False), 0.0, 1.0)


class IncSFATopStage:
    """A localizer's network with its top stage replaced by an IncSFA.

    Parameters
    ----------
    localizer : Localizer
        Fitted (its network records its training rotation); its stages
        below the top one are used frozen, its readout's kind and settings
        are refitted on the IncSFA's features. Not modified.
    n_whitened : int, default :data:`INCSFA_WHITENED`
        IncSFA's ``n_whitened`` (at most the expanded input's dimension).
    mca_rates : sequence of float, default :data:`INCSFA_MCA_RATES`
        One pass over each run's sequence per value, IncSFA's ``mca_rate``
        in that pass (in (0, 1]).
    seed : int, default 0
        IncSFA's initial slow directions.

    Attributes
    ----------
    node_ : IncSFA
        The top stage: ``n_components`` the network's outputs, learning
        from the expanded top-stage inputs.
    degree_ : int
        The expansion's degree (the exact top stage's).
    readout_ : Localizer or None
        The readout fitted by :meth:`fit_readout` (on precomputed features).
    n_runs_, n_samples_ : int
        Runs learned from; sequence samples seen (each pass counted).
    """

    def __init__(self, localizer: Any, *, n_whitened: int = INCSFA_WHITENED,
                 mca_rates: Sequence[float] = INCSFA_MCA_RATES, seed: int = 0) -> None:
        net = localizer.trained_network()
        rates = tuple(float(r) for r in mca_rates)
        if not rates or not all(0.0 < r <= 1.0 for r in rates):
            raise ValueError(f"mca_rates must be one or more numbers in (0, 1], got {mca_rates!r}")
        self.localizer = localizer
        self.mca_rates = rates
        self.degree_ = top_stage_degree(net)
        self.node_ = IncSFA(n_components=int(net.n_outputs_), n_whitened=int(n_whitened), seed=seed)
        self.readout_: Any = None
        self.n_runs_ = 0

    @property
    def passes(self) -> int:
        """Passes over each run's sequence."""
        return len(self.mca_rates)

    @property
    def n_samples_(self) -> int:
        return int(self.node_.n_samples_)

    def expand(self, inputs: Any) -> np.ndarray:
        """Top-stage inputs (M, k) expanded as the exact stage expands them."""
        Z = np.ascontiguousarray(np.asarray(inputs, dtype=np.float64))
        return np.asarray(_core.expand(Z, self.degree_), dtype=np.float64)

    def partial_fit(self, images: Any, on_pass: Callable[[int], object] | None = None) -> "IncSFATopStage":
        """Learns from one run, images (N, H, W[, C]) as the localizer takes
        them: its top-stage sequence (N x V views), expanded, once per value
        of ``mca_rates`` (``on_pass(p)`` after pass p = 1, 2, ...). Returns
        ``self``."""
        Z = top_stage_training_inputs(self.localizer, images)
        E = self.expand(Z.reshape(-1, Z.shape[2]))
        for p, rate in enumerate(self.mca_rates, 1):
            self.node_.mca_rate = rate
            self.node_.partial_fit(E)
            if on_pass is not None:
                on_pass(p)
        self.n_runs_ += 1
        return self

    def features_of_inputs(self, inputs: Any) -> np.ndarray:
        """The features (N, J) of views from their top-stage inputs (N, K, k)
        under the localizer's K pooled rotations: the IncSFA's outputs
        averaged over the rotations."""
        Z = np.asarray(inputs, dtype=np.float64)
        n, K, k = Z.shape
        return self.node_.transform(self.expand(Z.reshape(n * K, k))).reshape(n, K, -1).mean(axis=1)

    def features(self, images: Any) -> np.ndarray:
        """The features (N, J) of images (N, H, W[, C]) as the localizer takes them."""
        return self.features_of_inputs(top_stage_inputs(self.localizer, images))

    def fit_readout(self, inputs: Any, positions: Any, signatures: Any = None, *,
                    kernel: str = "learn", like: Any = None) -> "IncSFATopStage":
        """Fits a readout on the IncSFA's features of views given by their
        top-stage inputs (N, K, k), at ``positions`` (N, 2), with their
        signatures (N, q) if the readout reads them: the kind and settings
        of ``like``'s fitted readout (a fitted Localizer; default the
        localizer this stage was made from), a Gaussian process's kernel
        learned again with ``kernel="learn"``, or kept. The experiments
        pass the exact update's localizer, so that peer and update read
        their features alike (an update may have chosen another kind over
        the runs). Returns ``self``."""
        old = self.localizer
        src = old if like is None else like
        self.readout_ = old.sibling(readout=readout_spec_for_update(src, kernel), n_outputs=src.n_outputs_ or None,
                                    rotation_pooling=old.rotation_pooling_)
        self.readout_.fit_features(self.features_of_inputs(inputs), positions, signatures=signatures)
        return self

    @property
    def regression_(self) -> Any:
        """The fitted readout's regression (what the experiments' MED reads)."""
        return None if self.readout_ is None else self.readout_.regression_

    def predict(self, images: Any) -> np.ndarray:
        """Positions (N, 2) metres of images (N, H, W[, C])."""
        if self.readout_ is None:
            raise ValueError("fit the readout (fit_readout) before predicting")
        a = np.asarray(images)
        G = self.localizer.signatures(a) if self.readout_.n_signature_ else None
        return self.readout_.predict_features(self.features(a), signatures=G)


def memory_views(mem: ReadoutMemory) -> ReadoutMemory:
    """The views of a readout memory without their images (what a readout
    refit reads: stage inputs, positions, signatures, runs)."""
    return ReadoutMemory(mem.inputs, mem.positions, mem.signatures, max_views=mem.max_views, n_seen=mem.n_seen,
                         runs=mem.runs)


def views_with_run(localizer: Any, views: ReadoutMemory, images: Any, xy: Any) -> ReadoutMemory:
    """``views`` extended by a new run's, images (N, H, W[, C]) at ``xy``
    (N, 2) m, their top-stage inputs under ``localizer``'s frozen lower
    layers: the views the exact update's readout sees (the memory extended
    and thinned alike, the run labelled as the next)."""
    a = np.asarray(images)
    new = ReadoutMemory(top_stage_inputs(localizer, a), xy, localizer.signatures(a) if localizer.n_signature_ else None,
                        max_views=len(a))
    new.max_views = views.max_views
    return views.extended(new)


def incsfa_update(stale: Any, run_a: tuple[Any, Any], run_b: tuple[Any, Any], *,
                  mca_rates: Sequence[float] = INCSFA_MCA_RATES, n_whitened: int = INCSFA_WHITENED,
                  kernel: str = "learn", seed: int = 0, like: Any = None,
                  log: Callable[[str], object] | None = None) -> tuple[IncSFATopStage, dict[str, Any]]:
    """The IncSFA arm of ``6.2.1-changes-online``: an :class:`IncSFATopStage`
    on the stale localizer (trained on run A, with a readout memory) learns
    from A's sequence (the analogue of the stale model's training), then
    from B's (the update); the readout is refitted on the IncSFA's features
    of the readout memory's views and B's (the memory extended as the
    ``updated`` arm extends it), of the kind of ``like``'s readout (the
    exact update's localizer; default the stale one's). ``run_a``,
    ``run_b``: (images, xy).

    Returns (model, info): ``info["seconds_a"]`` the passes over A,
    ``info["seconds_update"]`` the passes over B, the features and the
    readout fit; ``info["agreement_a"]`` the mean canonical correlation
    between the IncSFA's and the stale model's exact top-stage features of
    the memory's views after each pass over A; ``info["canonical_a"]`` those
    correlations after the last pass."""
    say = log or (lambda _msg: None)
    mem = updatable_memory(stale, "the IncSFA arm refits its readout on the map's views")
    if mem.augmented is not None:
        raise ValueError("the IncSFA arm does not refit readouts fitted on corrupted copies")
    model = IncSFATopStage(stale, n_whitened=n_whitened, mca_rates=mca_rates, seed=seed)
    exact_a = top_stage_features(stale.trained_network(), mem.inputs)
    agreement: list[float] = []
    spent = [0.0]  # the checks' time, not the IncSFA's

    def check(p: int) -> None:
        t = time.perf_counter()
        cc = canonical_correlations(model.features_of_inputs(mem.inputs), exact_a)
        agreement.append(float(cc.mean()))
        say(f"IncSFA top stage: pass {p} over A ({model.n_samples_} samples so far): mean canonical correlation "
            f"with the exact top stage on A's views {agreement[-1]:.3f} (largest {cc[0]:.3f})")
        spent[0] += time.perf_counter() - t

    t0 = time.perf_counter()
    model.partial_fit(run_a[0], on_pass=check)
    t_a = time.perf_counter() - t0 - spent[0]
    canonical_a = canonical_correlations(model.features_of_inputs(mem.inputs), exact_a)
    t0 = time.perf_counter()
    model.partial_fit(run_b[0])
    views = views_with_run(stale, memory_views(mem), *run_b)
    model.fit_readout(views.inputs, views.positions, views.signatures, kernel=kernel, like=like)
    t_update = time.perf_counter() - t0
    say(f"IncSFA top stage: {model.passes} pass(es) over A in {t_a:.1f} s, update with B ({model.passes} pass(es), "
        f"readout on {len(views)} views) in {t_update:.1f} s")
    return model, {"seconds_a": t_a, "seconds_update": t_update, "agreement_a": agreement,
                   "canonical_a": canonical_a.tolist(), "passes": model.passes,
                   "mca_rates": list(model.mca_rates), "n_whitened": n_whitened,
                   "degree": model.degree_, "readout_views": len(views), "kernel": kernel}
