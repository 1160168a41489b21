"""The product's training recipe applied to one run: images (and odometry,
and ground truth where the run has it) in, a trained
:class:`sfanav.Localizer` with its filter noise out.

:func:`train_localizer` is what ``sfanav train`` does, and the one place
the demo, the garden suites and the experiments train the sfanav default
(or the thesis's configuration, through ``recipe``): the network under
simulated rotation, the readout fitted to ground truth or, without it, to
the positions learned from the run's images and odometry (pose graph),
trained again with loop-closure feedback where the network's code changes
between visits of one place (a light or objects changing through the run),
and the EKF noise for fusing odometry, chosen on the training run's held-out
estimates. What each step does and why: docs/localization.md,
docs/odometry.md, docs/robustness.md.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ._progress import Log, quiet_log
from .localization.recipe import CAMERA_ELEVATION, Recipe, default_network, recipe_for, supervision_for
from .localization.training import fit_localizer
from .loopclosure.factory import make_detector
from .loopclosure.revisits import FEEDBACK_RATIO, FEEDBACK_RATIO_LEARNED, MIN_REVISITS, revisit_change
from .odometry.fusion import noise_for_localizer
from .odometry.self_supervision import fit_localizer_from_odometry
from .sfa.network import Network, Rotation

METRIC_MAPS = ("pose-graph", "metric-learning")
"""How positions are learned without ground truth (``sfanav train --metric-map``)."""
CLOSURES = ("relative-pose", "min-warping", "auto", "heading")
"""What the pose graph's loop closures measure (``train_localizer(closures=)``, ``sfanav train --closures``):
the whole relative pose on GTSAM (the closures of one place counted as one) by the warping method; the same
by min-warping (a landmark distance per image column: the better map on a mower's serpentine of lanes,
docs/relative-pose.md "Min-warping"); ``auto`` (the default since 2026-12-07): both, keeping the map its own
closures fit better (no ground truth; docs/relative-pose.md "Choosing the method without ground truth"); or
the relative heading only. docs/odometry.md, "Correlated bearing errors", has the measurements behind the
relative pose."""
CLOSURE_METHOD = {"relative-pose": "warping", "min-warping": "min-warping", "auto": "auto"}
"""The pose graph's ``closure_method`` (:data:`sfanav.odometry.pose_graph.CLOSURE_METHODS`) of each relative-pose
choice of :data:`CLOSURES`."""
DEFAULT_CLOSURES = "auto"
"""The closures of ``closures=None`` with the pose graph."""
ROTATION_STEP = 5
"""The simulated rotation's step in pixels (the thesis's)."""
FEEDBACK = ("auto", "none")
"""Loop-closure feedback of ``train_localizer(feedback=)`` when no closures are given: ``auto`` (the default since
2026-12-07) trains once, measures how much the network's code changes between two visits of one place
(:func:`sfanav.loopclosure.revisits.revisit_change` on the training positions, ground truth or learned) and, above
:data:`sfanav.loopclosure.revisits.FEEDBACK_RATIO` (ground truth) or ``FEEDBACK_RATIO_LEARNED`` (learned positions,
which read it lower), trains again with the closures a bag of visual words finds
(thesis 6.2.1); ``none`` never does. docs/loop-closures.md, "When feedback is used"."""
FEEDBACK_DETECTOR = "bow"
"""The closures of ``feedback="auto"``: found from the images alone and robust to light (docs/loop-closures.md)."""
FIRST_MAP_MAX_RATIO = 4.0
"""Without ground truth, the feedback's second training keeps the map the first network's features learned while
their revisit ratio (on that map) stays below this: the feedback makes the passes of one place alike in the code,
and a pose graph that pairs places by that code places them less precisely. Above it the first network's code
changes so much between visits (a light dominating it) that its own map is the worse one, and the map is learned
again from the second network's features (docs/loop-closures.md, "The map of a run trained with feedback")."""


def describe_closures(info: Mapping[str, Any]) -> str:
    """The pose graph's loop closures of a model trained without ground
    truth, in words, from its ``info``: how many were kept, what they
    measure and (``closures="auto"``) which warping method the misfit
    chose.

    >>> print(describe_closures({"loop closures": 10, "loop closures kept": 9, "closures": "auto",
    ...                          "closure method": "min-warping",
    ...                          "closure misfit by method": {"warping": 0.2, "min-warping": 0.1}}))
    9 of 10 loop closures kept, relative poses by min-warping (closures' misfit 0.1 against 0.2 by the warping)
    """
    out = f"{info.get('loop closures kept', 0)} of {info.get('loop closures', 0)} loop closures kept"
    method, misfits = info.get("closure method"), info.get("closure misfit by method") or {}
    if method is None:
        return out + (", relative headings only" if info.get("closures") == "heading" else "")
    out += f", relative poses by {'the ' if method == 'warping' else ''}{method}"
    other = next((m for m in misfits if m != method), None)
    if other is not None and misfits.get(method) is not None and misfits.get(other) is not None:
        out += (f" (closures' misfit {misfits[method]:.3g} against {misfits[other]:.3g} by "
                f"{'the ' if other == 'warping' else ''}{other})")
    return out


def _all_finite(a: Any, n_cols: int) -> bool:
    if a is None:
        return False
    A = np.asarray(a, dtype=float)
    return A.ndim == 2 and A.shape[1] >= n_cols and bool(np.isfinite(A[:, :n_cols]).all())


def _image_height(images: Any) -> int:
    """Rows of the training images (N, H, W[, C]) without copying them."""
    shape = getattr(images, "shape", None)
    if shape is None:
        shape = (len(images), *np.shape(images[0])) if len(images) else (0,)
    if len(shape) < 3:
        raise ValueError(f"images must be (N, H, W[, C]), got shape {tuple(shape)}")
    return int(shape[1])


def train_localizer(images: Any, *, xy: Any = None, odometry: Any = None, timestamps: Any = None, gyro: Any = None,
                    supervision: str = "auto", closures: str | None = None, network: Network | None = None,
                    recipe: Recipe | None = None,
                    camera_elevation: Sequence[float] | None = None, rotation: Rotation | None = None,
                    prep: Any = None, metric_map: str = "pose-graph", loop_closures: Any = None,
                    closure_weights: Any = None, network_images: Any = None,
                    network_fit: Mapping[str, Any] | None = None, readout_memory: int | None = None,
                    readout_memory_images: bool = False, filter_noise: bool = True,
                    info: Mapping[str, Any] | None = None, groups: Any = None, feedback: str | None = None,
                    seed: int = 0, progress: bool = False, log: Log = quiet_log) -> Any:
    """Trains a localizer on one run as ``sfanav train`` does.

    Parameters
    ----------
    images : array (N, H, W[, C])
        The run's panoramas in temporal order, in the network's input format
        (:func:`sfanav.data.load_run`).
    xy : array (N, 2) or None
        Ground-truth positions (metres), if the run has them for every frame.
    odometry : array (N, 3) or None
        Wheel odometry (x m, y m, heading rad) of every frame, if the run has it.
    timestamps : array (N,) or None
        Frame times (s), strictly increasing; checked before any training
        when positions are learned from the odometry.
    gyro : array (N,) or None
        A yaw gyro's integrated heading (rad), fused with the odometry's turns.
    supervision : "auto", "ground-truth" or "odometry"
        What the readout is fitted to; ``"auto"``: ground truth where the run
        has it, else positions learned from its images and odometry
        (:func:`sfanav.localization.recipe.supervision_for`).
    closures : "relative-pose", "min-warping", "auto", "heading" or None
        Without ground truth, what the pose graph's loop closures measure
        (:data:`CLOSURES`; GTSAM solves the relative-pose graph). None: the
        pose graph's default (:data:`DEFAULT_CLOSURES`), nothing with the
        metric learner.
    network : Network or None
        The unfitted network (default: the sfanav default's).
    recipe : Recipe or None
        Readout, rows, pooling, signature and robustness
        (:func:`sfanav.localization.recipe.recipe_for`; default: the sfanav
        default's).
    camera_elevation : (float, float) or None
        Elevations (degrees) of the panoramas' lowest and highest rows, for
        the horizon band and the photometric low-pass's rows (2.5 degrees of
        elevation: :func:`sfanav.data.photometric.lowpass_for`; default: the
        simulator's, -30..20).
    rotation : Rotation or None
        The simulated rotation (default: a 5 px step, the whole panorama).
    prep : Preprocessing or None
        Recorded in the model so that ``localize`` prepares images alike.
    metric_map : "pose-graph" or "metric-learning"
        How positions are learned without ground truth.
    loop_closures, closure_weights, network_images, network_fit
        Feedback training, jittered network images and distributed fitting,
        as :func:`sfanav.localization.fit_localizer`.
    readout_memory : int or None
        Keep what :meth:`sfanav.Localizer.partial_fit` needs to add later runs:
        the network's statistics and at most this many training views
        (docs/updates.md); without ground truth the memory holds the learned
        positions (the model's odometry frame).
    readout_memory_images : bool
        The readout memory keeps the views' images too (about H x W x C
        bytes each), for updates that train every layer again
        (``UpdatePolicy(resolve="all")``, ``sfanav update --resolve all``).
    filter_noise : bool
        With odometry for every frame, choose and store the EKF noise in
        ``info["ekf_noise"]`` (:func:`sfanav.odometry.noise_for_localizer`);
        a run on which it cannot be chosen is logged, not an error.
    info : mapping or None
        Extra entries for the model's ``info``.
    groups : array (N,) or None
        The recording (or condition) each image comes from, when ``images``
        are several recordings of the same places: the default readout is
        then chosen by holding out one recording at a time
        (:func:`sfanav.localization.select_auto_readout`).
    feedback : "auto", "none" or None
        None: ``"auto"`` with the sfanav default's recipe, ``"none"`` with
        any other (the thesis's configuration trains as the thesis did).
        Without ``loop_closures``: whether the recipe may train again with
        loop-closure feedback when the trained network's code changes
        between visits of one place more than their positions explain
        (:data:`FEEDBACK`; a light or objects changing through the run).
        The measurement is in ``info["revisit change"]``, the closures used
        in ``info["feedback"]``; without ground truth the second training's
        readout keeps the positions the first one learned while the ratio is
        below :data:`FIRST_MAP_MAX_RATIO`. Not with ``groups`` (several recordings
        train in their own order) or ``metric_map="metric-learning"``.
    seed : int
        Seed of the robustness's corrupted copies.
    log : callable
        Receives one line per notable event (default: quiet).

    Returns
    -------
    Localizer
        Fitted; ``info["supervision"]`` says what its readout was fitted to
        (estimates of an ``"odometry"`` model are metres in the training
        run's odometry frame).

    Raises
    ------
    ValueError
        When the run lacks what the supervision needs, shapes disagree, the
        horizon band does not fit the camera, or the times do not increase.

    Example
    -------
    >>> from sfanav.data import Dataset, Preprocessing, load_run      # doctest: +SKIP
    >>> run = Dataset("garden").select(run="train")                    # doctest: +SKIP
    >>> X, _ = load_run(run, Preprocessing(350, 40, False))            # doctest: +SKIP
    >>> loc = train_localizer(X, odometry=run.odometry)                # doctest: +SKIP
    >>> loc.save("garden.sfa")                                         # doctest: +SKIP
    """
    if metric_map not in METRIC_MAPS:
        raise ValueError(f"metric_map must be one of {METRIC_MAPS}, got {metric_map!r}")
    if closures is not None and closures not in CLOSURES:
        raise ValueError(f"closures must be one of {CLOSURES} or None, got {closures!r}")
    if closures is not None and metric_map != "pose-graph":
        raise ValueError(f"closures={closures!r} needs metric_map='pose-graph', got {metric_map!r}")
    if closures is None and metric_map == "pose-graph":
        closures = DEFAULT_CLOSURES
    if feedback is not None and feedback not in FEEDBACK:
        raise ValueError(f"feedback must be one of {FEEDBACK} or None, got {feedback!r}")
    recipe = recipe if recipe is not None else recipe_for()
    if feedback is None:
        feedback = "auto" if recipe.name == "sfanav default" else "none"
    net = network if network is not None else default_network()
    has_odometry = _all_finite(odometry, 3)
    supervision = supervision_for(supervision, has_ground_truth=_all_finite(xy, 2), has_odometry=has_odometry)
    height = _image_height(images)
    try:
        fit_kw = recipe.fit_kwargs(CAMERA_ELEVATION if camera_elevation is None else camera_elevation, height)
    except ValueError as exc:
        raise ValueError(f"horizon band: {exc}") from None
    fit_kw.update(rotation=rotation or Rotation(step=ROTATION_STEP), prep=prep, progress=progress,
                  closure_weights=closure_weights, network_images=network_images,
                  network_fit=dict(network_fit or {}), info={**dict(info or {}), **recipe.info()},
                  seed=seed, **({"readout_memory_images": True} if readout_memory_images else {}),
                  **({"groups": groups} if groups is not None else {}))
    graph = None
    if supervision == "odometry" and closures in CLOSURE_METHOD:
        graph = {"solver": "gtsam", "pair_closures": "relative-pose", "closure_method": CLOSURE_METHOD[closures]}
        from .odometry.pose_graph_gtsam import require_gtsam

        require_gtsam()  # a clear error before any training

    def fit(network: Network, found: Any, learned: Any = None) -> Any:
        if supervision == "odometry":
            loc = fit_localizer_from_odometry(network, images, odometry, method=metric_map, timestamps=timestamps,
                                              gyro=gyro, readout_memory=readout_memory, pose_graph=graph,
                                              loop_closures=found, learned=learned, **fit_kw)
            loc.info["gyro"] = gyro is not None
            if closures is not None:
                loc.info["closures"] = closures
        else:
            loc = fit_localizer(network, images, np.asarray(xy, float)[:, :2], readout_memory=readout_memory,
                                loop_closures=found, **fit_kw)
            loc.info["supervision"] = "ground-truth"
        return loc

    loc = fit(net, loop_closures)
    F = None
    if feedback == "auto" and loop_closures is None and groups is None and metric_map == "pose-graph":
        F = loc.features(images)
        change = revisit_change(F, loc.training_positions_)
        threshold = FEEDBACK_RATIO if supervision == "ground-truth" else FEEDBACK_RATIO_LEARNED
        measured = {**change.to_dict(), "threshold": threshold}
        loc.info["revisit change"] = measured
        if not change.needs_feedback(threshold):
            log(f"revisits: the network's code changes {change.ratio:.2f}x what the positions explain over "
                f"{change.n_revisits} revisits (feedback above {threshold:g}): no feedback needed"
                if np.isfinite(change.ratio) else
                f"revisits: {change.n_revisits} found, too few (under {MIN_REVISITS}) or no moving frames to "
                "measure the change: no feedback")
        else:
            found = make_detector(FEEDBACK_DETECTOR).detect(images)
            said = (f"the network's code changes between visits of one place {change.ratio:.1f}x what their "
                    f"positions explain (above {threshold:g})")
            if len(found) < MIN_REVISITS:
                log(f"{said}, but only {len(found)} loop closures ({FEEDBACK_DETECTOR}) were found (fewer than "
                    f"{MIN_REVISITS}): no feedback")
            else:
                # without ground truth: the first map, unless the first code changed too much to learn it
                keep = supervision == "odometry" and change.ratio < FIRST_MAP_MAX_RATIO
                first_map = loc.learned_positions_ if keep else None
                kept = (", keeping the positions the first training learned" if keep else
                        f", learning the positions again (the code changed {FIRST_MAP_MAX_RATIO:g}x or more)"
                        if supervision == "odometry" else "")
                log(f"{said}: training again with {len(found)} loop closures ({FEEDBACK_DETECTOR}) as feedback{kept}")
                loc = fit(Network(net.config), found, first_map)
                loc.info["revisit change"] = measured
                loc.info["feedback"] = {"closures": FEEDBACK_DETECTOR, "count": int(len(found)),
                                        "map": ("the first training's" if first_map is not None
                                                else "learned again" if supervision == "odometry" else
                                                "ground truth")}
                F = None
    if filter_noise and has_odometry:
        try:
            F = loc.features(images) if F is None else F
            feats = loc.readout_features(F, loc.signatures(images) if loc.n_signature_ else None)
            loc.info["ekf_noise"] = noise_for_localizer(loc, feats, loc.training_positions_, odometry)
        except ValueError as exc:
            log(f"no EKF noise stored (fusing odometry will not be available): {exc}")
    return loc
