"""Training a localizer from a run: :func:`fit_localizer` trains the network
on the run's images (simulated rotation), then the readout on the slow
features and the run's positions, and returns a :class:`sfanav.Localizer`
that carries how it was made."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from .._checks import check_n_outputs
from ..data.preprocessing import Preprocessing
from ..sfa.network import Network, Rotation
from .localizer import Localizer
from .recipe import CAMERA_ELEVATION, default_network, recipe_for


def fit_localizer(
    network: Network,
    images: np.ndarray,
    xy: np.ndarray | Callable[[np.ndarray], np.ndarray],
    *,
    rotation: Rotation | None = None,
    n_outputs: int | None = None,
    readout: str | dict[str, Any] = "auto",
    rows: Any = None,
    prep: Preprocessing | None = None,
    progress: bool = True,
    info: dict[str, Any] | None = None,
    rotation_pooling: int | str | None = "auto",
    signature: str | None = None,
    loop_closures: Any = None,
    closure_weights: Any = None,
    network_images: np.ndarray | None = None,
    network_fit: dict[str, Any] | None = None,
) -> Localizer:
    """Trains ``network`` on ``images`` (the training run, in temporal order)
    under simulated rotation and fits the readout of its slowest outputs to
    ``xy`` (N, 2) metres: ground truth, or a function that learns the
    positions from the trained network's features (N, m) -> (N, 2), as
    :func:`sfanav.odometry.fit_localizer_from_odometry` passes (no ground
    truth).

    ``readout``, ``n_outputs``: as :class:`Localizer` (default ``"auto"``:
    the sfanav default's GP, or kernel ridge / kNN by blocked CV, on this
    run; ``readout="quadratic", n_outputs=8`` is the thesis's). ``rows``: an
    :class:`sfanav.data.ImageRows` applied to the images before the
    network, in training and (stored in the localizer) at every query.
    ``rotation_pooling``: as :class:`Localizer` (``"auto"``: 8 rotations
    unless the readout is the thesis's quadratic one). ``signature``: as
    :class:`Localizer` (``"fourier"``: the readout also reads the Fourier
    signature of the images as given, before ``rows``).
    ``loop_closures``, ``closure_weights``: loop-closure feedback in the
    network's training, as :meth:`sfanav.Network.fit` (indices into
    ``images``; closures found with :mod:`sfanav.loopclosure`). The
    returned localizer's ``info`` records preprocessing, rotation, training
    time (seconds: network) and readout selection time.

    ``network_images``: the images the network is trained on, when they
    differ from ``images`` (the same run, same shape and order), e.g. the run
    unwarped with centre jitter (:class:`sfanav.data.Preprocessor`): the
    network then learns to ignore the jitter, and the readout (and the
    signature) is fitted on ``images`` as the queries will look. Default:
    ``images``.

    ``network_fit``: more keyword arguments of the network's
    :meth:`~sfanav.Network.fit`, e.g. ``{"client": dask_client, "breaks":
    [...]}`` to train it on a Dask cluster (docs/distributed.md).

    Examples
    --------
    >>> X, xy = load_run(train, prep, mirror=m)                        # doctest: +SKIP
    >>> Xj, _ = load_run(train, prep, mirror=m, jitter=5.0, seed=0)    # doctest: +SKIP
    >>> loc = fit_localizer(net, X, xy, network_images=Xj)             # doctest: +SKIP
    """
    rotation = rotation or Rotation()
    raw = images
    if network_images is not None:
        shape = getattr(network_images, "shape", None)
        if shape != getattr(images, "shape", None):
            raise ValueError(f"network_images must have the shape of images {getattr(images, 'shape', None)}, "
                             f"got {shape}")
    if rows is not None and not rows.identity:
        images = rows(images)
        network_images = None if network_images is None else rows(network_images)
    else:
        rows = None
    t0 = time.perf_counter()
    network.fit(images if network_images is None else network_images, rotation, progress=progress,
                loop_closures=loop_closures, closure_weights=closure_weights, **(network_fit or {}))
    fit_s = time.perf_counter() - t0
    check_n_outputs(n_outputs, network.n_outputs_)
    loc = Localizer(network, n_outputs=n_outputs, readout=readout, rows=rows, rotation_pooling=rotation_pooling,
                    signature=signature)
    t1 = time.perf_counter()
    F = loc.transform_rows(images)
    G = loc.signatures(raw) if signature is not None else None
    loc.fit_features(F, xy(F) if callable(xy) else xy, signatures=G)
    readout_s = time.perf_counter() - t1
    loc.info = dict(info or {})
    if prep is not None:
        loc.info["preprocessing"] = prep.to_dict()
    loc.info.update({"rotation": {"step": rotation.step, "window": rotation.window},
                     "n_train_images": int(len(images)), "fit_seconds": round(fit_s, 2),
                     "readout_seconds": round(readout_s, 2), "readout": loc.describe_readout(),
                     "loop_closures": int(getattr(network, "n_loop_closures_", 0)),
                     "rotation_pooling": int(loc.rotation_pooling_)})
    if loc.selection_ is not None:
        loc.info["readout_rule"] = loc.selection_.rule
    return loc


def train_default(images: Any, xy: Any, *, camera_elevation: Sequence[float] = CAMERA_ELEVATION,
                  network: Network | None = None, rotation: Rotation | None = None, progress: bool = False,
                  info: dict[str, Any] | None = None, loop_closures: Any = None, closure_weights: Any = None) -> Any:
    """Trains the sfanav default on a training run: ``images`` (N, 40, 350, 3)
    uint8 or float in temporal order, ``xy`` (N, 2) metres. Returns a fitted
    :class:`sfanav.Localizer` (network, rows and readout; ``save`` it as one
    model file). ``network`` replaces the default network (e.g. for other
    image sizes). ``loop_closures``, ``closure_weights``: feedback training,
    as :meth:`sfanav.Network.fit`."""
    from .training import (
        fit_localizer,  # training imports the localizer, which imports this module
    )

    recipe = recipe_for()
    net = network if network is not None else default_network()
    return fit_localizer(net, np.asarray(images), np.asarray(xy, float), rotation=rotation or Rotation(5, 1.0),
                         readout=recipe.readout, rows=recipe.image_rows(camera_elevation), progress=progress,
                         signature=recipe.signature, loop_closures=loop_closures, closure_weights=closure_weights,
                         info={**recipe.info(), **(info or {})})
