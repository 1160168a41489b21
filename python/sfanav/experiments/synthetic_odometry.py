"""Synthetic odometry problems for tests and the solver comparison: a smooth
8-dim "slow feature" code of position (:func:`synthetic_features`), runs of
straight lines (:func:`make_line_problem`, :func:`make_odometry_run`), and
:func:`compare_solvers` of metric learning on one problem."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .._checks import as_matrix
from ..localization.error_metrics import align, med
from ..odometry.dead_reckoning import dead_reckon
from ..odometry.lines import Lines, lines_from_labels, segment_lines
from ..odometry.metric_learning import MetricLearner


def compare_solvers(
    features: Any,
    lines: Lines,
    xy: Any = None,
    *,
    solvers: Sequence[str] = ("varpro", "lbfgs", "gd"),
    learner_params: Mapping[str, Any] | None = None,
    solver_params: Mapping[str, Mapping[str, Any]] | None = None,
    warmup: bool = True,
) -> list[dict[str, Any]]:
    """Fits the same problem with each solver from the same seed.

    Parameters
    ----------
    features : array (N, m)
    lines : Lines
    xy : array (N, 2), optional
        Ground truth: adds the aligned MED on the line samples.
    learner_params : mapping, optional
        Common :class:`MetricLearner` parameters (default ``random_state=0``).
    solver_params : mapping solver -> mapping, optional
        Per-solver parameters (e.g. ``{"gd": {"max_iter": 20000}}``).
    warmup : bool, default True
        One untimed fit first (imports, BLAS start-up).

    Returns
    -------
    list of dict
        ``solver``, ``cost``, ``n_iter``, ``time_s``, ``converged`` and, with
        ground truth, ``med`` (metres).
    """
    base = {"random_state": 0, **dict(learner_params or {})}
    per = dict(solver_params or {})
    if warmup:
        MetricLearner(**{**base, "solver": "varpro", "max_iter": 5}).fit(features, lines, progress=False)
    Y = None if xy is None else as_matrix(xy, "xy", n_cols=2)
    out = []
    for s in solvers:
        m = MetricLearner(**{**base, **dict(per.get(s, {})), "solver": s}).fit(features, lines, progress=False)
        row = {"solver": s, "cost": m.cost_, "n_iter": m.n_iter_, "time_s": m.fit_time_, "converged": m.converged_}
        if Y is not None:
            on = lines.mask
            P = m.transform(np.asarray(features)[on])
            row["med"] = med(align(P, Y[on], allow_reflection=True).apply(P), Y[on])
        out.append(row)
    return out


def synthetic_features(xy: Any, *, area: tuple[float, float] = (16.0, 18.0), n_outputs: int = 8,
                       noise: float = 0.0, random_state: int | np.random.Generator | None = 0) -> np.ndarray:
    """A smooth 8-dim "slow feature" code of position (N, 2) metres inside
    ``[0, area_x] x [0, area_y]``: x, y, cosines of one and two periods and
    two products, each scaled to unit variance over the area, mixed by a
    fixed random rotation (seed 12345), plus Gaussian noise of std
    ``noise``. Their quadratic expansion contains x and y linearly, so a
    metric map exists (exactly, without noise)."""
    P = as_matrix(xy, "xy", n_cols=2)
    if not 1 <= n_outputs <= 8:
        raise ValueError(f"n_outputs must be in 1..8, got {n_outputs}")
    x = 2 * P[:, 0] / area[0] - 1
    y = 2 * P[:, 1] / area[1] - 1
    pi = np.pi
    g = np.c_[
        x * np.sqrt(3), y * np.sqrt(3), np.cos(pi * x) * np.sqrt(2), np.cos(pi * y) * np.sqrt(2),
        2 * np.cos(pi * x) * np.cos(pi * y), np.sin(pi * x) * np.cos(pi * y / 2) * 1.6,
        np.cos(2 * pi * x) * np.sqrt(2), 2 * np.sin(pi * x) * np.sin(pi * y),
    ][:, :n_outputs]
    M = np.linalg.qr(np.random.default_rng(12345).normal(size=(8, 8)))[0][:n_outputs, :n_outputs]
    out = g @ M
    if noise:
        out = out + noise * np.random.default_rng(random_state).normal(size=out.shape)
    return out


def make_line_problem(*, n_lines: int = 10, area: tuple[float, float] = (16.0, 18.0), step: float = 0.2,
                      min_length: float = 8.0, noise: float = 0.02, random_state: int | None = 0) -> dict[str, Any]:
    """Synthetic thesis 5.3.1-sim data: ``n_lines`` straight lines of random
    orientation, start and end inside the area, at least ``min_length``
    metres (and at least 70 % of the way to the border), sampled every
    ``step`` metres.

    Returns
    -------
    dict
        ``features`` (N, 8), ``xy`` (N, 2) metres, ``lines`` (Lines with
        the true heading differences as relative angles), ``alpha`` (L,)
        true orientations in radians.
    """
    rng = np.random.default_rng(random_state)
    pts, lab, dist, heads = [], [], [], []
    tries = 0
    while len(heads) < n_lines:
        tries += 1
        if tries > 10000:
            raise ValueError(f"cannot fit lines of {min_length} m into an area of {area} m")
        p0 = rng.uniform([0.0, 0.0], area)
        a = rng.uniform(0, 2 * np.pi)
        u = np.array([np.cos(a), np.sin(a)])
        ts = [t for i in range(2) if abs(u[i]) > 1e-9 for t in ((0 - p0[i]) / u[i], (area[i] - p0[i]) / u[i])]
        tmax = min(t for t in ts if t > 0)
        if tmax < min_length:
            continue
        d = np.arange(0.0, rng.uniform(max(min_length, 0.7 * tmax), tmax), step)
        pts.append(p0 + d[:, None] * u)
        lab.append(np.full(len(d), len(heads)))
        dist.append(d)
        heads.append(a)
    xy = np.vstack(pts)
    alpha = np.array(heads)
    lines = lines_from_labels(np.concatenate(lab), np.concatenate(dist), np.angle(np.exp(1j * np.diff(alpha))))
    feats = synthetic_features(xy, area=area, noise=noise, random_state=rng)
    return {"features": feats, "xy": xy, "lines": lines, "alpha": alpha}


def make_odometry_run(*, n_legs: int = 12, area: tuple[float, float] = (5.0, 5.0), speed: float = 0.04,
                      turn_steps: int = 8, feature_noise: float = 0.02, distance_noise: float = 0.02,
                      heading_noise: float = 0.01, heading_bias: float = 0.002,
                      random_state: int | None = 0) -> dict[str, Any]:
    """Synthetic thesis 5.3.1-real / 5.3.2 run: a robot drives straight legs
    of random length and turns on the spot by about +-90 or 180 degrees
    (a grid-like pattern), starting in the centre facing +x.

    ``distance_noise`` is the relative error of each step's distance,
    ``heading_noise`` the std of each step's heading change (radians) and
    ``heading_bias`` a constant heading error per moving step (radians):
    the odometry drifts.

    Returns
    -------
    dict
        ``poses`` (N, 3) true poses, ``odometry`` (N, 3) noisy odometry poses
        from (0, 0, 0), ``features`` (N, 8), ``xy`` (N, 2).
    """
    rng = np.random.default_rng(random_state)
    start = np.array([area[0] / 2, area[1] / 2, 0.0])
    steps: list[tuple[float, float]] = []
    pose = start.copy()
    margin = 0.3
    for _ in range(n_legs):
        turn = float(rng.choice([-np.pi / 2, np.pi / 2, np.pi]) + rng.normal(0, 0.05))
        steps += [(0.0, turn / turn_steps)] * turn_steps
        th = pose[2] + turn
        u = np.array([np.cos(th), np.sin(th)])
        ts = [t for i in range(2) if abs(u[i]) > 1e-9
              for t in ((margin - pose[i]) / u[i], (area[i] - margin - pose[i]) / u[i])]
        tmax = min([t for t in ts if t > 0], default=0.0)
        length = rng.uniform(0.5, 1.0) * tmax
        n = max(int(length / speed), 2)
        steps += [(length / n, 0.0)] * n
        pose = dead_reckon(np.array(steps), start)[-1]
    U = np.array(steps)
    poses = dead_reckon(U, start)
    Un = U.copy()
    Un[:, 0] *= 1 + distance_noise * rng.normal(size=len(U))
    Un[:, 1] += heading_noise * rng.normal(size=len(U)) + heading_bias * (np.abs(U[:, 0]) > 0)
    odometry = dead_reckon(Un, (0.0, 0.0, 0.0))
    feats = synthetic_features(poses[:, :2], area=area, noise=feature_noise, random_state=rng)
    return {"poses": poses, "odometry": odometry, "features": feats, "xy": poses[:, :2].copy()}


def print_solver_comparison(max_iter: int = 20000) -> list[dict[str, Any]]:
    """The solver comparison of ``docs/odometry.md`` on two synthetic problems
    (seed 0): the 5.3.1-sim setting (random lines, random initialisation,
    cost 5.1) and the 5.3.1-real setting (lines from drifting odometry,
    initialisation from odometry, cost 5.5). Prints and returns the rows
    (with a ``problem`` key)::

        python -c "from sfanav.experiments.thesis_5_3 import print_solver_comparison as p; p()"
    """
    solvers = ("varpro", "lbfgs", "gd", "gd-precond")
    per = {"gd": {"max_iter": max_iter}, "lbfgs": {"max_iter": max_iter},
           "gd-precond": {"max_iter": max_iter, "precondition": True}}
    out = []
    sim = make_line_problem(random_state=0)
    real = make_odometry_run(n_legs=18, random_state=0)
    problems = [
        ("5.3.1-sim (random init, cost 5.1)", sim["features"], sim["lines"], sim["xy"],
         {"angle_term": None, "init": "random"}),
        ("5.3.1-real (odometry init, cost 5.5)", real["features"], segment_lines(real["odometry"]), real["xy"],
         {"angle_term": "cos", "init": "odometry"}),
    ]
    for name, F, lines, xy, common in problems:
        print(f"{name}: {lines.n_lines} lines, {lines.n_points} points, 8 outputs -> 45 dims")
        for s in solvers:
            params = dict(per.get(s, {}))
            (row,) = compare_solvers(F, lines, xy, solvers=("gd" if s.startswith("gd") else s,),
                                     learner_params={"random_state": 0, **common},
                                     solver_params={"gd" if s.startswith("gd") else s: params}, warmup=not out)
            row["solver"] = s
            row["problem"] = name
            out.append(row)
            print(f"  {s:>10}: cost {row['cost']:.4f}, {row['n_iter']} iterations, {row['time_s']:.3f} s, "
                  f"converged {row['converged']}, aligned MED {row['med']:.3f} m")
    return out
