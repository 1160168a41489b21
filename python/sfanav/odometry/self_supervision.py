"""Positions without ground truth: the metric map of a training run learned
from its own images, slow features and odometry, in the odometry's frame, as
targets for a readout.

:func:`learn_positions` makes the map one of two ways:

* ``"pose-graph"`` (the default when the panoramas are given):
  :func:`~sfanav.odometry.fit_pose_graph` corrects the odometry's heading
  drift with loop closures (places passed twice, found by the slow features,
  their relative heading read off the panoramas) and integrates the
  odometry's distances along the corrected headings;
* ``"metric-learning"`` (thesis 5.3.1): the run's odometry split into
  straight lines (:func:`~sfanav.odometry.segment_lines`), a
  :class:`MetricLearner` (the maximum-likelihood cost with the signed angle
  and transit terms when the lines carry them, the thesis's cost otherwise)
  maps every frame's features to a position, moved into the odometry frame
  by the rigid transform (no scale: odometry is in metres) that best fits
  the first line's samples to their odometry positions.

Nothing here reads ground truth.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._checks import as_matrix, check_int, check_n_outputs, check_same_length
from ..localization.error_metrics import Alignment, align
from ..localization.training import fit_localizer
from .dead_reckoning import as_poses
from .lines import Lines, segment_lines
from .metric_learning import MetricLearner
from .pose_graph import PoseGraph, fit_pose_graph

MIN_LINES = 3
"""Fewest straight lines with which a run can fix a metric map (metric learning)."""

MIN_LOOP_CLOSURES = 10
"""Fewest kept loop closures below which the pose graph warns."""


class OdometryMapWarning(UserWarning):
    """The run's odometry barely constrains the metric map (few lines, or
    lines of nearly one direction): positions learned from it are unreliable."""


METHODS = ("pose-graph", "metric-learning")
"""The ways :func:`learn_positions` can make a metric map."""


@dataclass
class LearnedPositions:
    """The learned positions of a training run and how they were made.

    Attributes
    ----------
    positions : ndarray (N, 2)
        Every frame's position in metres, in the odometry frame (the frame of
        the run's odometry, whose origin is its first pose's).
    method : str
        ``"pose-graph"`` or ``"metric-learning"``.
    lines : Lines
        The straight lines of the odometry (the metric learner's input;
        reported for both methods).
    graph : PoseGraph or None
        The solved pose graph (method ``"pose-graph"``).
    learner : MetricLearner or None
        The fitted metric map, features -> positions before ``alignment``
        (method ``"metric-learning"``).
    alignment : Alignment or None
        The rigid transform from the learner's frame (mirrored first where the
        learner's cost leaves the handedness open) to the odometry frame,
        fitted on the first line (method ``"metric-learning"``).
    warnings : list of str
        What makes the map unreliable, if anything (also warned).
    """

    positions: np.ndarray
    method: str
    lines: Lines
    graph: PoseGraph | None = None
    learner: MetricLearner | None = None
    alignment: Alignment | None = None
    warnings: list[str] = field(default_factory=list)

    def info(self) -> dict[str, Any]:
        """A JSON-able summary for a model file's ``info``."""
        out: dict[str, Any] = {
            "supervision": "odometry",
            "frame": "odometry (the training run's odometry frame)",
            "metric map": self.method,
            "lines": int(self.lines.n_lines),
            "points on lines": int(self.lines.n_points),
        }
        if self.graph is not None:
            out.update(self.graph.info())
        if self.learner is not None and self.alignment is not None:
            out.update({"metric cost": float(self.learner.cost_), "angle term": self.learner.angle_term_,
                        "transit term": bool(np.any(self.learner.transit_weights_)),
                        "rms to odometry on the first line (m)": float(self.alignment.rmse)})
        out["warnings"] = list(self.warnings)
        return out


def _direction_spread(lines: Lines, odometry: np.ndarray) -> float:
    """How far the lines' directions are from all being parallel: 0 when
    every line has one direction (up to sign), 1 for directions spread
    evenly (the resultant length of the doubled angles)."""
    angles = []
    for k in range(lines.n_lines):
        idx = np.flatnonzero(lines.labels == k)
        d = odometry[idx[-1], :2] - odometry[idx[0], :2]
        angles.append(np.arctan2(d[1], d[0]))
    a = 2 * np.asarray(angles)
    return float(1.0 - np.hypot(np.cos(a).mean(), np.sin(a).mean()))


def check_timestamps(timestamps: Any, n: int) -> np.ndarray:
    """Finite, strictly increasing timestamps (seconds) of ``n`` frames in
    temporal order, as float64; ValueError naming the first offending frame."""
    t = np.asarray(timestamps, dtype=np.float64).ravel()
    if len(t) != n:
        raise ValueError(f"timestamps has {len(t)} entries but the run has {n} frames; they must match")
    bad = np.flatnonzero(~np.isfinite(t))
    if len(bad):
        raise ValueError(f"timestamps must be finite; frame {bad[0]} has {t[bad[0]]}")
    back = np.flatnonzero(np.diff(t) <= 0)
    if len(back):
        k = int(back[0])
        # full precision (17 significant digits): two Unix times 1 us apart print apart
        raise ValueError(f"timestamps must increase (frames in temporal order): frame {k + 1} at {t[k + 1]:.17g} s "
                         f"does not come after frame {k} at {t[k]:.17g} s")
    return t


def learn_positions(features: Any, odometry: Any, *, images: Any = None, method: str = "auto", n_outputs: int = 8,
                    learner: MetricLearner | None = None, segmentation: Mapping[str, Any] | None = None,
                    odometry_noise: Any = None, pose_graph: Mapping[str, Any] | None = None,
                    timestamps: Any = None, random_state: int | None = 0,
                    progress: bool = False, gyro: Any = None) -> LearnedPositions:
    """Learns the positions of a training run's frames from its slow
    features, odometry and (for the pose graph) panoramas, without ground
    truth.

    Parameters
    ----------
    features : array (N, m)
        Slow features of the run's frames in temporal order (slowest first,
        m >= ``n_outputs``), e.g. a :class:`~sfanav.Localizer`'s features.
    odometry : array (N, 3)
        The odometry poses of the same frames: x, y in metres, heading in
        radians (finite).
    images : array (N, H, W[, C]), optional
        The run's 360-degree panoramas (the pose graph's compass).
    method : {"auto", "pose-graph", "metric-learning"}, default "auto"
        ``"auto"``: the pose graph when ``images`` are given, metric
        learning otherwise.
    n_outputs : int, default 8
        Slowest features the map uses (place pairs or the metric map).
    learner : MetricLearner, optional
        Overrides the default metric learner (it is fitted here).
    segmentation : mapping, optional
        Keywords for :func:`~sfanav.odometry.segment_lines`.
    odometry_noise : mapping or sfanav.sim.OdometryNoise, optional
        The odometry's random-walk noise model (weights of both methods).
    pose_graph : mapping, optional
        Keywords for :func:`~sfanav.odometry.fit_pose_graph`.
    timestamps : array (N,), optional
        The frames' times (s), checked to increase (the frames must be in
        temporal order).
    gyro : array (N,), optional
        A yaw gyro's integrated heading (rad, :attr:`sfanav.Dataset.gyro`):
        fused with the odometry's turns (:func:`sfanav.odometry.gyro.fuse_gyro`)
        by the pose graph, and before the metric learner reads the odometry.

    Returns
    -------
    LearnedPositions

    Raises
    ------
    ValueError
        Non-finite or mismatched inputs, timestamps that do not increase, a
        run without motion, an unknown
        method, the pose graph without images, or (metric learning) fewer
        than two straight lines. With fewer than :data:`MIN_LINES` lines or
        lines of nearly one direction (metric learning), or few loop closures
        (pose graph), an :class:`OdometryMapWarning` is issued and recorded.

    Examples
    --------
    >>> lp = learn_positions(loc.features(images), odometry, images=images)  # doctest: +SKIP
    >>> loc.fit_features(loc.features(images), lp.positions)  # doctest: +SKIP
    """
    F = as_matrix(features, "features")
    P = as_poses(odometry, "odometry")
    check_same_length(F, P, "features", "odometry")
    n_outputs = check_n_outputs(check_int(n_outputs, "n_outputs"), F.shape[1], what="the features have", unit="columns")
    if timestamps is not None:
        check_timestamps(timestamps, len(P))
    if method not in ("auto",) + METHODS:
        raise ValueError(f"method must be 'auto', 'pose-graph' or 'metric-learning', got {method!r}")
    if method == "auto":
        method = "pose-graph" if images is not None else "metric-learning"
    if method == "pose-graph" and images is None:
        raise ValueError("method='pose-graph' needs the run's panoramas (images=...)")
    steps = np.hypot(*np.diff(P[:, :2], axis=0).T)
    if not np.any(steps > 0):
        raise ValueError("the odometry does not move: positions cannot be learned from it")
    lines = segment_lines(P, **dict(segmentation or {}))
    notes = []
    if method == "pose-graph":
        kw = dict(pose_graph or {})
        if gyro is not None:
            kw["gyro"] = gyro
        graph = fit_pose_graph(images, F, P, odometry_noise=odometry_noise, n_outputs=n_outputs, **kw)
        if graph.n_inliers < MIN_LOOP_CLOSURES:
            notes.append(f"only {graph.n_inliers} loop closures: the run barely passes a place twice, so the "
                         "odometry's heading drift is not corrected")
        for n in notes:
            warnings.warn(n, OdometryMapWarning, stacklevel=2)
        return LearnedPositions(graph.poses[:, :2].copy(), method, lines, graph=graph, warnings=notes)
    if gyro is not None:  # the metric learner reads the odometry with the gyro's turns
        from .gyro import fuse_gyro

        P = fuse_gyro(P, gyro, odometry_noise=odometry_noise).odometry
        lines = segment_lines(P, **dict(segmentation or {}))
    if lines.n_lines < 2:
        raise ValueError(f"the odometry has {lines.n_lines} straight line segment(s); learning a metric map needs "
                         "at least 2 (drive straight lanes in several directions)")
    if lines.n_lines < MIN_LINES:
        notes.append(f"only {lines.n_lines} straight line segments: the metric map is barely constrained")
    spread = _direction_spread(lines, P)
    if spread < 0.05:
        notes.append(f"the {lines.n_lines} straight lines are nearly parallel (direction spread {spread:.3f}): "
                     "the metric map is not fixed across them")
    for n in notes:
        warnings.warn(n, OdometryMapWarning, stacklevel=2)
    if learner is None:
        has_transits = lines.transit_lengths is not None and lines.origins is not None
        if has_transits:
            learner = MetricLearner(n_outputs, angle_term="signed", angle_weight="noise", transit_weight="noise",
                                    odometry_noise=odometry_noise, init="odometry", random_state=random_state)
        else:
            learner = MetricLearner(n_outputs, angle_term="cos", init="odometry", random_state=random_state)
    learner.fit(F, lines, progress=progress)
    raw = learner.transform(F)
    # Handedness from all lines (the unsigned angle terms leave the mirror image open), then the frame from the
    # first line alone: the odometry has not drifted yet there, so the map lands in the frame of its first pose.
    on = lines.mask
    if learner.angle_term_ != "signed":
        whole = align(raw[on], P[on, :2], allow_reflection=True)
        if np.linalg.det(whole.rotation) < 0:
            raw = raw * np.array([1.0, -1.0])
    first = lines.labels == 0
    al = align(raw[first], P[first, :2])
    return LearnedPositions(al.apply(raw), method, lines, learner=learner, alignment=al, warnings=notes)


def fit_localizer_from_odometry(network: Any, images: Any, odometry: Any, *, n_metric_outputs: int = 8,
                                method: str = "auto", pose_graph: Mapping[str, Any] | None = None,
                                learner: MetricLearner | None = None, segmentation: Mapping[str, Any] | None = None,
                                odometry_noise: Any = None, timestamps: Any = None, gyro: Any = None,
                                info: dict[str, Any] | None = None, learned: LearnedPositions | None = None,
                                **fit_kwargs: Any) -> Any:
    """Trains a :class:`~sfanav.Localizer` on a run's images and odometry
    alone: the network on the images (simulated rotation), the metric map on
    the network's features, the odometry and (the default pose graph) the
    images (:func:`learn_positions`, ``method``), then the readout on the
    learned positions. Its estimates are metres in the
    training run's odometry frame.

    ``images`` (N, H, W[, C]) and ``odometry`` (N, 3) are the frames of the
    run in temporal order; ``fit_kwargs`` go to
    :func:`sfanav.localization.fit_localizer` (rotation, readout, n_outputs,
    rows, prep, progress, rotation_pooling). The localizer's ``info`` records
    ``"supervision": "odometry"``, the frame and the map's lines;
    ``timestamps`` (N,), if given, are checked to increase before anything
    is trained; ``gyro`` (N,), a yaw gyro's integrated heading (rad), is
    passed to :func:`learn_positions`;
    ``learned_positions_`` holds the :class:`LearnedPositions`. Raises as
    :func:`learn_positions`.

    ``learned``: a map learned before on the same run (another localizer's
    ``learned_positions_``, e.g. the first training's when the recipe trains
    again with loop-closure feedback): the readout is fitted to its
    positions and no map is learned from this network's features. A
    ValueError if it holds another number of frames.
    """
    P = as_poses(odometry, "odometry")
    if len(P) != len(images):
        raise ValueError(f"images has {len(images)} frames but odometry has {len(P)} poses; they must match")
    if timestamps is not None:
        check_timestamps(timestamps, len(P))  # before the network's training, not after it
    if gyro is not None:
        from .gyro import as_gyro

        gyro = as_gyro(gyro, len(P))  # before the network's training too
    if learned is not None:
        if not isinstance(learned, LearnedPositions):
            raise TypeError(f"learned must be a LearnedPositions, got {type(learned).__name__}")
        if len(learned.positions) != len(P):
            raise ValueError(f"learned holds {len(learned.positions)} positions but the run has {len(P)} frames")
        loc = fit_localizer(network, images, learned.positions, info=info, **fit_kwargs)
        loc.info.update(learned.info())
        loc.learned_positions_ = learned
        return loc
    learned_now: list[LearnedPositions] = []

    def positions(features: np.ndarray) -> np.ndarray:
        learned_now.append(learn_positions(features, P, images=images, method=method, pose_graph=pose_graph,
                                       n_outputs=n_metric_outputs, learner=learner,
                                       segmentation=segmentation, odometry_noise=odometry_noise,
                                       progress=bool(fit_kwargs.get("progress", False)), gyro=gyro))
        return learned_now[-1].positions

    loc = fit_localizer(network, images, positions, info=info, **fit_kwargs)
    loc.info.update(learned_now[-1].info())
    loc.learned_positions_ = learned_now[-1]
    return loc
