"""Experiment logic of thesis 5.3 (odometry integration) on arrays: given
the features, odometry and ground truth of a training and a test run,
:func:`experiment_5_3_1` (unsupervised metric learning vs a supervised
regression) and :func:`experiment_5_3_2` (EKF fusion) compute the rows that
``sfanav experiment`` prints beside the thesis's figures. Ground truth is
used for evaluation only (and, as in the thesis, for the EKF's noise grid
search; a ground-truth-free choice is reported beside it)."""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .._checks import as_matrix, check_same_length
from .._threads import one_blas_thread
from ..localization.error_metrics import align, med
from ..localization.quadratic import QuadraticRegression
from ..odometry.dead_reckoning import as_poses
from ..odometry.ekf import OdometryEKF, grid_search

THESIS_FILTER = {"reinit_after": None, "gap_factor": None, "jump_factor": None}
"""The thesis's EKF (5.3.2): the filter without sfanav's divergence recovery."""
from ..odometry.lines import Lines, segment_lines
from ..odometry.metric_learning import MetricLearner
from ..odometry.plots import plot_fusion, plot_metric_lines
from . import ExperimentResult

#: The thesis's figures (section 5.3, ``docs/thesis-figures.md``).
THESIS: dict[str, dict[str, Any]] = {
    "5.3.1-sim": {
        "lines": 10, "points on lines": 862, "iterations": 1000,
        "train MED supervised (m)": 0.13, "train MED unsupervised (m)": 0.17,
        "test MED supervised (m)": 0.39, "test MED unsupervised (m)": 0.36,
        "unsupervised/supervised test MED ratio": round(0.36 / 0.39, 3),
    },
    "5.3.1-real": {
        "lines": 18, "points on lines": 1346, "iterations": 900,
        "train MED supervised (m)": 0.12, "train MED unsupervised (m)": 0.17,
        "test MED supervised (m)": 0.14, "test MED unsupervised (m)": 0.14,
        "unsupervised/supervised test MED ratio": 1.0,
    },
    "5.3.2": {
        "SFA MED (m)": 0.14, "odometry MED (m)": 0.31, "EKF MED (m)": 0.11,
        "EKF improvement over SFA alone (%)": 21.0,
    },
}


def _single_blas_thread(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Runs ``fn`` with one BLAS thread: its matrices are small, and BLAS
    threads cost more than they give there (see ``sfanav.odometry.metric_learning``)."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        with one_blas_thread():
            return fn(*args, **kwargs)

    return wrapper


def _rows(name: str, values: Mapping[str, Any]) -> list[dict[str, Any]]:
    thesis = THESIS.get(name, {})
    return [{"metric": k, "thesis": thesis.get(k), "sfanav": v} for k, v in values.items()]


def _as_lines(odometry: Any, n: int, segmentation: Mapping[str, Any] | None) -> Lines:
    if isinstance(odometry, Lines):
        lines = odometry
    else:
        lines = segment_lines(as_poses(odometry, "odometry_train"), **dict(segmentation or {}))
    if len(lines.labels) != n:
        raise ValueError(f"features_train has {n} rows but the odometry/lines have {len(lines.labels)}; they must match")
    return lines


@_single_blas_thread
def experiment_5_3_1(
    features_train: Any,
    odometry_train: Any,
    xy_train: Any,
    features_test: Any,
    xy_test: Any,
    *,
    variant: str = "real",
    learner: MetricLearner | None = None,
    n_outputs: int = 8,
    segmentation: Mapping[str, Any] | None = None,
    odometry_noise: Any = None,
    out_dir: Any = None,
    random_state: int | None = 0,
    progress: bool = False,
) -> ExperimentResult:
    """Thesis 5.3.1: unsupervised metric learning against a supervised
    quadratic regression on the same training samples.

    The default learner (beyond the thesis) is the maximum-likelihood cost
    with the odometry between the lines: the signed angle term and the
    transit term, weighted by the odometry noise model and the map's residual
    variance (``MetricLearner(angle_weight="noise", transit_weight="noise")``,
    docs/odometry.md). It needs lines that carry their transits
    (:func:`sfanav.odometry.segment_lines`,
    :func:`sfanav.odometry.lines_from_odometry`); for lines without them it
    falls back to the thesis's cost of the variant. The thesis's cost at its
    minimum is reported beside it (rows ``thesis cost ...``).

    Parameters
    ----------
    features_train : array (N, m)
        Slow features of the training run (slowest first).
    odometry_train : array (N, 3) or Lines
        Odometry poses of the training run (x, y in metres, heading in
        radians), split into lines with :func:`sfanav.odometry.segment_lines`;
        or the lines themselves (simulator: lines driven on purpose).
    xy_train : array (N, 2)
        Ground truth of the training run, metres (evaluation and the
        supervised reference only).
    features_test, xy_test : arrays (T, m), (T, 2)
        The separate test run.
    variant : {"real", "sim"}
        Initialisation of the thesis's two runs: ``"sim"``: random (best of 5
        starts; thesis cost 5.1); ``"real"``: from odometry (thesis cost 5.5).
    learner : MetricLearner, optional
        Overrides the default learner (fitted here).
    n_outputs : int, default 8
        Slowest outputs used by both models.
    segmentation : mapping, optional
        Keywords for :func:`sfanav.odometry.segment_lines`.
    odometry_noise : mapping or sfanav.sim.OdometryNoise, optional
        The odometry's noise model for the default learner's weights
        (default :data:`sfanav.odometry.DEFAULT_ODOMETRY_NOISE`).
    out_dir : path, optional
        Writes fig. 5.19 (``metric_lines.png``) and the test trajectories
        (``metric_test.png``) there.

    Returns
    -------
    ExperimentResult
        Rows ``lines``, ``points on lines``, ``iterations``, ``fit time (s)``,
        ``train MED supervised (m)``, ``train MED unsupervised (m)``,
        ``test MED supervised (m)``, ``test MED unsupervised (m)``,
        ``unsupervised/supervised test MED ratio``; target "unsupervised within
        1.3x of supervised test MED". ``details["test_estimates"]`` holds the
        unsupervised test estimates aligned to ground truth (input for
        :func:`experiment_5_3_2`).
    """
    if variant not in ("real", "sim"):
        raise ValueError(f"variant must be 'real' or 'sim', got {variant!r}")
    name = f"5.3.1-{variant}"
    Ftr = as_matrix(features_train, "features_train")
    Ytr = as_matrix(xy_train, "xy_train", n_cols=2)
    check_same_length(Ftr, Ytr, "features_train", "xy_train")
    Fte = as_matrix(features_test, "features_test")
    Yte = as_matrix(xy_test, "xy_test", n_cols=2)
    check_same_length(Fte, Yte, "features_test", "xy_test")
    lines = _as_lines(odometry_train, len(Ftr), segmentation)
    init = {"init": "odometry"} if variant == "real" else {"init": "random", "n_init": 5}
    thesis_learner = MetricLearner(n_outputs, angle_term="cos" if variant == "real" else None,
                                   snapshot_iterations=(0,), random_state=random_state, **init)
    has_transits = lines.transit_lengths is not None and lines.origins is not None and lines.n_lines > 1
    if learner is None:
        if has_transits:
            learner = MetricLearner(n_outputs, angle_term="signed", angle_weight="noise", transit_weight="noise",
                                    odometry_noise=odometry_noise, snapshot_iterations=(0,),
                                    random_state=random_state, **init)
        else:
            learner = thesis_learner
    learner.fit(Ftr, lines, progress=progress)
    on = lines.mask
    F_on, Y_on = Ftr[on], Ytr[on]
    sup = QuadraticRegression(learner.n_outputs_, degree=learner.degree_).fit(F_on, Y_on)
    P_on = learner.transform(F_on)
    al = align(P_on, Y_on, allow_reflection=True)
    test_est = al.apply(learner.transform(Fte))
    train_sup, test_sup = sup.score(F_on, Y_on), sup.score(Fte, Yte)
    train_uns, test_uns = med(al.apply(P_on), Y_on), med(test_est, Yte)
    ratio = test_uns / test_sup if test_sup > 0 else float("inf")
    if learner.transit_weights_.any():
        cost_name = "ML: (5.1) + signed angle + transit terms, weights from the odometry noise model"
    elif learner.angle_term_ is not None:
        cost_name = f"(5.5), angle term {learner.angle_term_!r}"
    else:
        cost_name = "(5.1)"
    values = {
        "lines": lines.n_lines,
        "points on lines": lines.n_points,
        "cost": cost_name,
        "solver": learner.solver,
        "iterations": learner.n_iter_total_,
        "fit time (s)": learner.fit_time_,
        "final cost": learner.cost_,
        "train MED supervised (m)": train_sup,
        "train MED unsupervised (m)": train_uns,
        "test MED supervised (m)": test_sup,
        "test MED unsupervised (m)": test_uns,
        "unsupervised/supervised test MED ratio": ratio,
        "alignment mirrored": bool(np.linalg.det(al.rotation) < 0),
    }
    if learner.feature_noise_ is not None:
        values["map residual sigma_f, ML estimate (m)"] = learner.feature_noise_
        values["fits of the sigma_f estimation"] = learner.noise_iterations_
        values["median angle / transit weight"] = (
            f"{float(np.median(learner.angle_weights_)):.3g} / {float(np.median(learner.transit_weights_)):.3g}")
    thesis_fit = None
    if learner.transit_weights_.any() or learner.feature_noise_ is not None:
        # the thesis's cost (5.5 real / 5.1 sim) at its minimum, same initialisation
        thesis_fit = thesis_learner.fit(Ftr, lines, progress=False)
        P_th = thesis_fit.transform(F_on)
        al_th = align(P_th, Y_on, allow_reflection=True)
        th_test = med(al_th.apply(thesis_fit.transform(Fte)), Yte)
        label = "5.5" if variant == "real" else "5.1"
        values[f"thesis cost {label} at its minimum: train MED unsupervised (m)"] = med(al_th.apply(P_th), Y_on)
        values[f"thesis cost {label} at its minimum: test MED unsupervised (m)"] = th_test
        values[f"thesis cost {label} at its minimum: unsupervised/supervised test MED ratio"] = (
            th_test / test_sup if test_sup > 0 else float("inf"))
    if lines.relative_angles is not None and learner.angle_term_ != "signed":
        # beyond the thesis: the signed heading change between lines (also excludes the mirror image)
        alt = MetricLearner(**{**learner.get_params(), "angle_term": "signed", "snapshot_iterations": ()})
        alt.fit(Ftr, lines, progress=False)
        P_alt = alt.transform(F_on)
        al_alt = align(P_alt, Y_on, allow_reflection=True)
        values["test MED unsupervised, signed angle term (m)"] = med(al_alt.apply(alt.transform(Fte)), Yte)
    res = ExperimentResult(
        name, _rows(name, values),
        targets={"unsupervised test MED within 1.3x of supervised": bool(ratio <= 1.3),
                 **({"unsupervised (thesis cost at its minimum) test MED within 1.3x of supervised":
                     bool(th_test <= 1.3 * test_sup)} if thesis_fit is not None else {})},
        details={"learner": learner, "thesis_learner": thesis_fit, "supervised": sup, "alignment": al, "lines": lines,
                 "test_estimates": test_est, "test_estimates_supervised": sup.predict(Fte)},
    )
    if out_dir is not None:
        from ..localization.plots import plot_trajectory

        out = Path(out_dir)
        res.figures["unsupervised metric learning (fig. 5.19)"] = plot_metric_lines(
            learner, Ftr, out / "metric_lines.png", title=f"{name}: line estimates (dotted) vs W^T s (solid)")
        res.figures["unsupervised estimates on the test run, aligned"] = plot_trajectory(
            Yte, test_est, out / "metric_test.png", title=f"{name}: test MED {test_uns:.3f} m")
    return res


@_single_blas_thread
def experiment_5_3_2(
    sfa_test: Any,
    odometry_test: Any,
    truth_test: Any,
    *,
    start_pose: Any = None,
    sfa_train: Any = None,
    odometry_train: Any = None,
    truth_train: Any = None,
    grid: Mapping[str, Sequence[float]] | None = None,
    gate_probability: float = 0.999,
    out_dir: Any = None,
    progress: bool = False,
) -> ExperimentResult:
    """Thesis 5.3.2: EKF fusion of SFA estimates (measurements) and odometry
    (CTRV prediction) from a known start pose.

    Parameters
    ----------
    sfa_test : array (T, 2)
        SFA position estimates of the test run in the ground truth's frame,
        metres (e.g. ``experiment_5_3_1(...).details["test_estimates"]``:
        unsupervised, aligned with the training run's alignment).
    odometry_test : array (T, 3)
        Odometry poses of the test run (own frame; only increments are used).
    truth_test : array (T, 3) or (T, 2)
        Ground-truth poses (x, y [m], heading [rad]) or positions. The start
        pose is its first pose, or ``start_pose`` for positions only.
    sfa_train, odometry_train, truth_train : arrays, optional
        The same for the training run: the noise is then also tuned there
        (row ``EKF MED, noise tuned on the training run (m)``).
    grid : mapping, optional
        Candidate ``distance_noise``, ``heading_noise``, ``measurement_noise``
        for :func:`sfanav.odometry.grid_search`.
    gate_probability : float, default 0.999
        For the gated run (row ``EKF MED with Mahalanobis gating (m)``).
    out_dir : path, optional
        Writes fig. 5.24 (``fusion.png``) there.

    Returns
    -------
    ExperimentResult
        The headline EKF row uses the noise chosen by grid search against
        the test run's ground truth (the thesis's protocol); the rows below
        it show the ground-truth-free (innovation likelihood) choice and,
        with training data, the noise tuned on the training run.
    """
    Z = as_matrix(sfa_test, "sfa_test", n_cols=2)
    odo = as_poses(odometry_test, "odometry_test")
    T = as_matrix(truth_test, "truth_test")
    check_same_length(Z, odo, "sfa_test", "odometry_test")
    check_same_length(Z, T, "sfa_test", "truth_test")
    if T.shape[1] == 3:
        s0 = T[0] if start_pose is None else np.asarray(start_pose, dtype=np.float64)
    elif T.shape[1] == 2:
        if start_pose is None:
            raise ValueError("truth_test holds positions only: pass start_pose (x [m], y [m], heading [rad])")
        s0 = np.asarray(start_pose, dtype=np.float64)
    else:
        raise ValueError(f"truth_test must have shape (T, 3) or (T, 2), got {T.shape}")
    train_given = [a is not None for a in (sfa_train, odometry_train, truth_train)]
    if any(train_given) and not all(train_given):
        raise ValueError("give all of sfa_train, odometry_train and truth_train, or none")
    xy = T[:, :2]
    g = dict(grid or {})
    # the thesis's filter: no divergence recovery (sfanav.odometry.recovery), which the thesis did not have
    g["ekf_params"] = {**THESIS_FILTER, **dict(g.get("ekf_params") or {})}
    odo_xy = OdometryEKF.dead_reckoning(odo, s0)[:, :2]
    gs = grid_search(odo, Z, s0, xy, criterion="med", progress=progress, **g)
    ekf_xy = gs.best_poses[:, :2]
    gs_nll = grid_search(odo, Z, s0, None, criterion="nll", progress=progress, **g)
    sfa_med, odo_med, ekf_med = med(Z, xy), med(odo_xy, xy), med(ekf_xy, xy)
    gated = OdometryEKF(**gs.best_params, **g["ekf_params"], gate_probability=gate_probability)
    gated_xy = gated.run(odo, Z, s0)[:, :2]
    improvement = 100.0 * (sfa_med - ekf_med) / sfa_med if sfa_med > 0 else float("nan")
    bp = gs.best_params
    values: dict[str, Any] = {
        "SFA MED (m)": sfa_med,
        "odometry MED (m)": odo_med,
        "EKF MED (m)": ekf_med,
        "EKF improvement over SFA alone (%)": improvement,
        "EKF noise (distance m, heading rad, measurement m)":
            f"{bp['distance_noise']:g}, {bp['heading_noise']:g}, {bp['measurement_noise']:g}",
        "EKF MED, noise by innovation likelihood, no ground truth (m)": med(gs_nll.best_poses[:, :2], xy),
    }
    details: dict[str, Any] = {"grid_search": gs, "grid_search_nll": gs_nll, "ekf_poses": gs.best_poses,
                               "odometry_xy": odo_xy, "gated": gated}
    if all(train_given):
        Ttr = as_matrix(truth_train, "truth_train")
        if Ttr.shape[1] != 3:
            raise ValueError(f"truth_train must be poses of shape (N, 3), got {Ttr.shape}")
        gs_tr = grid_search(odometry_train, sfa_train, Ttr[0], Ttr[:, :2], criterion="med", progress=progress, **g)
        tuned = OdometryEKF(**gs_tr.best_params, **g["ekf_params"]).run(odo, Z, s0)
        values["EKF MED, noise tuned on the training run (m)"] = med(tuned[:, :2], xy)
        details["grid_search_train"] = gs_tr
    values["EKF MED with Mahalanobis gating (m)"] = med(gated_xy, xy)
    values["gated SFA measurements"] = gated.n_gated_
    res = ExperimentResult(
        "5.3.2", _rows("5.3.2", values),
        targets={
            "EKF at least 20 % better than SFA alone": bool(improvement >= 20.0),
            "EKF better than odometry alone": bool(ekf_med < odo_med),
        },
        details=details,
    )
    if out_dir is not None:
        res.figures["SFA vs odometry vs EKF (fig. 5.24)"] = plot_fusion(
            xy, Z, odo_xy, ekf_xy, Path(out_dir) / "fusion.png", title="5.3.2: fusion of SFA estimates and odometry")
    return res
