"""The SLAM community's trajectory errors, as evo computes them (Grupp 2017,
PyPI ``evo``; Sturm et al. 2012 for the TUM RGB-D benchmark), for sfanav's
planar estimates, in plain numpy (evo is not needed at run time; the tests
check these numbers against evo's):

* :func:`ape`: absolute pose error, translation part, after the rigid
  alignment (rotation and translation, no scale: Umeyama 1991,
  :func:`sfanav.localization.align`) of the estimate to the reference, as
  ``evo_ape -a`` (``metrics.APE(PoseRelation.translation_part)`` after
  ``traj_est.align(traj_ref, correct_scale=False)``);
* :func:`rpe`: relative pose error, translation part, over consecutive pairs
  ``delta`` frames apart (default 1), as ``evo_rpe --delta 1 --delta_unit f``
  (with or without ``-a``: evo's alignment moves the rotations with the
  positions, which leaves every relative pose as it was);
* :func:`trajectory_errors`: both, as one flat dict.

Each returns plain floats: ``rmse``, ``mean``, ``median``, ``max`` (metres)
and ``n`` (number of errors). Unlike MED (no alignment: the estimates are in
the world frame), APE first moves the estimate by the rigid transform that
best fits it to the reference *on the same run*: it scores the shape of the
trajectory, not its placement in the world. See docs/localization.md.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._checks import as_matrix, as_real_array, check_finite, check_int, check_same_length
from . import error_metrics


def _stats(err: np.ndarray) -> dict[str, float]:
    return {"rmse": float(np.sqrt(np.mean(err**2))), "mean": float(err.mean()),
            "median": float(np.median(err)), "max": float(err.max()), "n": int(len(err))}


def _positions(estimate: Any, reference: Any) -> tuple[np.ndarray, np.ndarray]:
    p = as_matrix(estimate, "estimate", n_cols=2)
    t = as_matrix(reference, "reference", n_cols=2)
    check_same_length(p, t, "estimate", "reference")
    return p, t


def _heading(h: Any, n: int, name: str) -> np.ndarray:
    a = as_real_array(h, name).astype(np.float64, copy=False)
    if a.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},) (one heading per pose, radians), got {a.shape}")
    check_finite(a, name)
    return a


def _aligned(p: np.ndarray, t: np.ndarray, align: bool) -> tuple[np.ndarray, float]:
    if not align:
        return p, 0.0
    a = error_metrics.align(p, t, scale=False)
    return a.apply(p), float(np.arctan2(a.rotation[1, 0], a.rotation[0, 0]))


def ape(estimate: Any, reference: Any, *, align: bool = True) -> dict[str, float]:
    """Absolute pose error (translation part) of an estimated trajectory.

    Parameters
    ----------
    estimate, reference : array of shape (N, 2)
        Positions at the same N instants, metres (N >= 2 with ``align``).
    align : bool
        First move the estimate by the rigid transform (no scale) that best
        fits it to the reference (default True, as ``evo_ape -a``); False
        compares the positions as they are (then ``mean`` is the MED).

    Returns
    -------
    dict
        ``rmse``, ``mean``, ``median``, ``max`` of the Euclidean distances
        (metres) and ``n``. Headings do not change the translation part.

    Raises
    ------
    ValueError
        Shapes that differ, non-finite values, fewer than 2 poses or an
        estimate that is one point repeated (no alignment can be fitted).

    Example
    -------
    >>> ape([[0, 0], [1, 0], [2, 0]], [[0, 0], [0, 1], [0, 2]])["rmse"]  # a rotated copy  # doctest: +SKIP
    0.0
    """
    p, t = _positions(estimate, reference)
    q, _ = _aligned(p, t, align)
    return _stats(np.linalg.norm(q - t, axis=1))


def rpe(estimate: Any, reference: Any, *, estimate_heading: Any = None, reference_heading: Any = None,
        delta: int = 1) -> dict[str, float]:
    """Relative pose error (translation part) over pairs ``delta`` frames
    apart: for pairs ``(i, i + delta)``, ``i = 0, delta, 2 delta, ...`` (evo's
    consecutive pairs), the norm of the translation of
    ``(Q_i^-1 Q_j)^-1 (P_i^-1 P_j)``, Q the reference's and P the (aligned)
    estimate's poses, that is ``|R(h^P_i)^T (p_j - p_i) - R(h^Q_i)^T (q_j - q_i)|``.

    No rigid transform of the estimate (rotation and translation applied to
    its poses, headings included, as evo's alignment does) changes it, so
    there is no alignment. Without headings both trajectories have the
    identity rotation, as in the TUM files sfanav writes for single-image
    estimates: the error is then ``|(p_j - p_i) - (q_j - q_i)|``, each step
    in its own trajectory's frame. An estimate in a frame turned by ``a``
    against the reference (a model trained without ground truth, in its
    odometry frame) then has an error of ``2 sin(a / 2)`` times the step
    length even when perfect: give headings (a fused track has them) to
    compare such estimates. With headings (both or neither) it is the full
    SE(2) relative error.

    Parameters
    ----------
    estimate, reference : array of shape (N, 2)
        Positions, metres.
    estimate_heading, reference_heading : array of shape (N,), optional
        Headings, radians counter-clockwise from +x; give both or neither.
    delta : int
        Frames between the two poses of a pair (default 1); N > delta.

    Returns
    -------
    dict
        ``rmse``, ``mean``, ``median``, ``max`` (metres per ``delta`` frames)
        and ``n`` (number of pairs).

    Raises
    ------
    ValueError
        Shapes that differ, non-finite values, only one of the headings,
        ``delta`` < 1 or not below N.

    Example
    -------
    >>> rpe([[0, 0], [1, 0], [2, 0]], [[0, 0], [1, 0], [3, 0]])["max"]  # doctest: +SKIP
    1.0
    """
    p, t = _positions(estimate, reference)
    d = check_int(delta, "delta")
    if d >= len(p):
        raise ValueError(f"delta ({d} frames) must be below the number of poses ({len(p)})")
    if (estimate_heading is None) != (reference_heading is None):
        raise ValueError("give both estimate_heading and reference_heading, or neither (without headings both "
                         "trajectories have the identity rotation)")
    i = np.arange(0, len(p), d)
    i, j = i[:-1], i[1:]
    dp, dt = p[j] - p[i], t[j] - t[i]
    if estimate_heading is not None:
        he = _heading(estimate_heading, len(p), "estimate_heading")
        hr = _heading(reference_heading, len(p), "reference_heading")
        dp = _rotate(dp, -he[i])
        dt = _rotate(dt, -hr[i])
    return _stats(np.linalg.norm(dp - dt, axis=1))


def _rotate(v: np.ndarray, angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.column_stack([c * v[:, 0] - s * v[:, 1], s * v[:, 0] + c * v[:, 1]])


def trajectory_errors(estimate: Any, reference: Any, *, estimate_heading: Any = None,
                      reference_heading: Any = None, delta: int = 1, align: bool = True) -> dict[str, float]:
    """:func:`ape` and :func:`rpe` of one estimate as one flat dict:
    ``ape_rmse``, ``ape_mean``, ``ape_median``, ``ape_max``, ``rpe_rmse``,
    ``rpe_mean``, ``rpe_median``, ``rpe_max`` (metres) and ``n`` (poses).
    Arguments and errors as :func:`rpe`; ``align`` applies to the APE.

    Example
    -------
    >>> trajectory_errors(est_xy, true_xy)["ape_rmse"]  # doctest: +SKIP
    """
    a = ape(estimate, reference, align=align)
    r = rpe(estimate, reference, estimate_heading=estimate_heading, reference_heading=reference_heading,
            delta=delta)
    out: dict[str, float] = {f"ape_{k}": a[k] for k in ("rmse", "mean", "median", "max")}
    out.update({f"rpe_{k}": r[k] for k in ("rmse", "mean", "median", "max")})
    out["n"] = a["n"]
    return out
