"""Training a localizer from a run: :func:`fit_localizer` trains the network
on the run's images (simulated rotation), then the readout on the slow
features and the run's positions, and returns a :class:`sfanav.Localizer`
that carries how it was made."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from .._checks import check_int, check_n_outputs
from ..data.camera_gamma import reference_spread
from ..data.corruptions import CorruptionModel
from ..data.preprocessing import Preprocessing
from ..loopclosure.partners import check_closures, closure_partners
from ..sfa.network import Network, Rotation
from .localizer import Localizer


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
    photometric: str | None = None,
    lowpass: Any = None,
    readout_augmentation: CorruptionModel | None = None,
    invariance: CorruptionModel | None = None,
    invariance_weight: float = 1.0,
    seed: int = 0,
    readout_memory: int | None = None,
    readout_memory_images: bool = False,
    groups: Any = None,
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

    ``photometric``: a photometric normalisation of every image before the
    rows, the network and the signature (``"log-contrast"`` or ``"lowpass-log-contrast"``, the sfanav
    default's: :mod:`sfanav.data.photometric`), stored in the localizer; ``lowpass``: the latter's widths
    in pixels, (rows, columns) (None: 2 px on both; :class:`Localizer`).

    ``readout_augmentation``: a :class:`~sfanav.data.corruptions.CorruptionModel`;
    the readout is then fitted on the run and on a copy of it with one
    corruption drawn per image (``seed``), at the same positions
    (:meth:`Localizer.fit_features` ``augmented``). ``invariance``: a
    corruption model for the network: each training image's simulated
    rotation is interleaved with that of a corrupted copy of it (of its
    loop-closure partner where it has one), weight ``invariance_weight``,
    so that the slow features ignore the corruption (:meth:`Network.fit`
    ``partners``; one machine only). Both need 8-bit images. What each
    costs and buys: docs/robustness.md.

    ``readout_memory``: keep at most this many evenly spaced training views
    for later updates (:func:`sfanav.localization.updates.remember`: the
    localizer can then take new runs with ``partial_fit``, and its model
    file keeps the network's training statistics). None: not updatable.
    ``readout_memory_images``: the memory keeps the views' images too, for
    updates that train every layer again (``UpdatePolicy(resolve="all")``).

    ``groups`` (N,): the recording each image comes from, when ``images``
    are several recordings of the same places (say in different light, in
    place-major order): the default readout is then chosen by holding out
    one recording at a time (:meth:`Localizer.fit_features`).

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
    if rows is not None and rows.identity:
        rows = None
    seed = check_int(seed, "seed", minimum=0)
    if groups is not None and np.shape(groups) != (len(images),):
        raise ValueError(f"groups must hold one label per training image ({len(images)}), got shape "
                         f"{np.shape(groups)}")
    for name, model in (("readout_augmentation", readout_augmentation), ("invariance", invariance)):
        if model is not None:
            if not isinstance(model, CorruptionModel):
                raise TypeError(f"{name} must be a sfanav.data.corruptions.CorruptionModel or None, "
                                f"got {type(model).__name__}")
            if np.asarray(images).dtype != np.uint8:
                raise ValueError(f"{name} corrupts the training images as a camera would: it needs 8-bit images "
                                 f"(uint8), got {np.asarray(images).dtype} (train without image normalisation)")
    # an unfitted localizer holds how images become the network's input (photometric, rows)
    loc = Localizer(network, n_outputs=n_outputs, readout=readout, rows=rows, rotation_pooling=rotation_pooling,
                    signature=signature, photometric=photometric, lowpass=lowpass)
    images = loc.network_input(raw)
    fit_kw = dict(loop_closures=loop_closures, closure_weights=closure_weights)
    if invariance is not None:
        fit_kw = {"partners": invariance_partners(raw if network_images is None else network_images, invariance,
                                                  loc.network_input, weight=invariance_weight, seed=seed,
                                                  loop_closures=loop_closures, closure_weights=closure_weights)}
    network_images = None if network_images is None else loc.network_input(network_images)
    t0 = time.perf_counter()
    network.fit(images if network_images is None else network_images, rotation, progress=progress,
                **fit_kw, **(network_fit or {}))
    fit_s = time.perf_counter() - t0
    check_n_outputs(n_outputs, network.n_outputs_)
    t1 = time.perf_counter()
    F = loc.transform_rows(images)
    G = loc.signatures(raw) if signature is not None else None
    Y = xy(F) if callable(xy) else xy
    if readout_augmentation is None:
        loc.fit_features(F, Y, signatures=G, groups=groups)
    else:
        loc.fit_features(F, Y, signatures=G, augmented=augmented_features(loc, raw, readout_augmentation, seed=seed),
                         groups=groups)
    readout_s = time.perf_counter() - t1
    if readout_memory is not None:
        from .updates import remember

        remember(loc, raw, Y, max_views=readout_memory, augmentation=readout_augmentation, seed=seed,
                 keep_images=readout_memory_images)
    loc.info = dict(info or {})
    if prep is not None:
        loc.info["preprocessing"] = prep.to_dict()
    loc.info.update({"rotation": {"step": rotation.step, "window": rotation.window},
                     "n_train_images": int(len(images)), "fit_seconds": round(fit_s, 2),
                     "readout_seconds": round(readout_s, 2), "readout": loc.describe_readout(),
                     # with invariance partners the closures' partners are among them (the network counts none)
                     "loop_closures": (int(getattr(network, "n_loop_closures_", 0)) if invariance is None
                                       or loop_closures is None else
                                       len(check_closures(loop_closures, len(raw), closure_weights)[1])),
                     **({"photometric": photometric, "camera_gamma": reference_spread(raw, Y)} if photometric else {}),
                     **({"lowpass": list(loc.photometric_lowpass())} if loc.photometric_lowpass() else {}),
                     **({"readout_augmentation": readout_augmentation.describe()} if readout_augmentation else {}),
                     **({"invariance": invariance.describe(), "invariance_weight": float(invariance_weight)}
                        if invariance else {}),
                     **({"robustness_seed": seed} if invariance or readout_augmentation else {}),
                     "rotation_pooling": int(loc.rotation_pooling_)})
    if loc.selection_ is not None:
        loc.info["readout_rule"] = loc.selection_.rule
    return loc


def augmented_features(loc: Localizer, images: np.ndarray, model: CorruptionModel, *,
                       seed: int = 0) -> tuple[np.ndarray, np.ndarray | None]:
    """``(features, signatures)`` of ``images`` (N, H, W[, C]) uint8, each
    with a corruption drawn from ``model`` (``seed + 1``: the draw
    :func:`fit_localizer` makes for ``readout_augmentation``), as ``loc``
    (network trained) sees them: what :meth:`Localizer.fit_features` takes
    as ``augmented``, e.g. to fit the same localizer's readout to other
    positions of its training run (signatures None if it reads none)."""
    altered = model.apply(images, seed=seed + 1)
    return loc.features(altered), (loc.signatures(altered) if loc.signature is not None else None)


def invariance_partners(images: np.ndarray, model: CorruptionModel, network_input: Callable[[Any], Any], *,
                        weight: float = 1.0, seed: int = 0, loop_closures: Any = None,
                        closure_weights: Any = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The invariance partners of a training run ``images`` (N, H, W[, C])
    uint8, as :meth:`sfanav.Network.fit` takes them (``partners``): every
    image's partner is a copy of it with a corruption drawn from ``model``
    (``seed``), or, where a loop closure names the image, a corrupted copy
    of its aligned loop-closure partner (the closure's weight times
    ``weight``); ``network_input`` makes the copies what the network sees
    (photometric normalisation, rows)."""
    n = len(images)
    w = float(weight)
    if not (np.isfinite(w) and 0 <= w <= 1):
        raise ValueError(f"invariance_weight must be in [0, 1], got {weight!r}")
    base = np.array(images, copy=True)
    weights = np.full(n, w)
    if loop_closures is not None:
        current, cw, aligned = closure_partners(images, loop_closures, closure_weights)
        base[current] = aligned
        weights[current] = np.asarray(cw) * w
    partners = network_input(model.apply(base, seed=seed))
    return np.arange(n), weights, np.ascontiguousarray(partners)

