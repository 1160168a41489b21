"""Synthetic runs on which the fused track can lose the robot, and the
measurement of ``docs/odometry.md`` ("Divergence and recovery"): single
images vs the fused track with and without recovery.

:func:`make_filter_case` makes one run (truth, noisy wheel odometry, noisy
single-image estimates with a few outliers, frame times) of a kind in
:data:`CASES`; :func:`compare_recovery` fuses it both ways over several
seeds. No images are needed::

    PYTHONPATH=python python3 -c "from sfanav.experiments.filter_cases import print_recovery_table as p; p()"
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ..odometry.dead_reckoning import dead_reckon, increments, wrap_angle
from ..odometry.fusion import fuse

CASES = ("clean", "sharp_turns", "dropped", "slip", "kidnap", "raster", "serpentine")
"""``clean``: a smooth random drive; ``sharp_turns``: sparse frames with a
turn of 60-120 degrees in one frame every 6-10 frames; ``dropped``: blocks
of 5-12 frames missing (the odometry spans the gaps, the stamps show them);
``slip``: two slip events where the wheels spin for 3 frames while the
robot stands (the odometry drives on); ``kidnap``: the robot carried 20 m
with the odometry showing nothing; ``raster``: a raster survey, every row
driven in the same direction, each row end a 28 m jump back (in the
odometry too, as a wheel-odometry simulator records it) and a heading drift
of 0.1 deg/m; ``serpentine``: a mower's lanes driven back and forth, at
each lane end a quarter turn on the spot, one frame's step to the next
lane, another quarter turn (the displacement of those frames is off the
arc a turn-rate model assumes), and the same heading drift."""


def _drive(n: int, step: float, rng: np.random.Generator, area: float, sharp: bool) -> np.ndarray:
    """Increments (n - 1, 2) of a drive inside [0, area]^2 from its centre."""
    pose = np.array([area / 2, area / 2, rng.uniform(-np.pi, np.pi)])
    steps = []
    next_turn = rng.integers(6, 11)
    for i in range(n - 1):
        turn = 0.08 * rng.normal()
        if sharp and i == next_turn:
            turn = rng.choice([-1, 1]) * np.deg2rad(rng.uniform(60, 120))
            next_turn = i + rng.integers(6, 11)
        ahead = pose[:2] + 3 * step * np.array([np.cos(pose[2] + turn), np.sin(pose[2] + turn)])
        if np.any(ahead < 1) or np.any(ahead > area - 1):  # steer toward the centre
            to_c = np.arctan2(area / 2 - pose[1], area / 2 - pose[0])
            turn = float(np.clip(wrap_angle(to_c - pose[2]), -np.pi / 2, np.pi / 2))
        steps.append((step, turn))
        pose = dead_reckon(np.array([steps[-1]]), pose)[-1]
    return np.array(steps)


def make_filter_case(kind: str, *, random_state: int = 0, n_frames: int = 240, step: float = 1.2,
                     area: float = 30.0, estimate_noise: float = 0.3, outlier_rate: float = 0.02,
                     distance_noise: float = 0.02, heading_noise: float = float(np.deg2rad(0.5))) -> dict[str, Any]:
    """One synthetic run of the kind ``kind`` (see :data:`CASES`).

    Parameters
    ----------
    n_frames : int
        Frames of the run (``raster``: rows of 24 frames, ``serpentine``
        of 20, as many as fit;
        ``dropped``: before dropping).
    step : float
        Metres between frames.
    estimate_noise : float
        Standard deviation (metres, each axis) of the single-image estimates;
        a fraction ``outlier_rate`` of them is 2-5 m off in a random direction.
    distance_noise, heading_noise : float
        Odometry noise per frame: relative distance error and heading
        error (radians).

    Returns
    -------
    dict
        ``poses`` (N, 3) truth, ``odometry`` (N, 3) (from (0, 0, 0)),
        ``estimates`` (N, 2), ``stamps`` (N,) seconds (one per nominal
        frame), ``noise`` (the filter's noise for these settings, as
        :func:`sfanav.odometry.fuse` takes it), ``events`` (frames where the
        robot was kidnapped or slipped; for ``raster`` and ``serpentine``
        the row starts).
    Raises ValueError on an unknown kind.
    """
    if kind not in CASES:
        raise ValueError(f"kind must be one of {', '.join(CASES)}, got {kind!r}")
    rng = np.random.default_rng(random_state)
    drift = 0.0
    events: list[int] = []
    if kind == "raster":
        per_row = 24
        rows = max(2, n_frames // per_row)
        xs = 1.0 + step * np.arange(per_row)
        truth = np.array([(x, 1.0 + step * r, 0.0) for r in range(rows) for x in xs])
        events = [r * per_row for r in range(1, rows)]
        U_true = increments(truth, direction=True)
        U_odo = U_true.copy()
        drift = np.deg2rad(0.1)  # rad per metre
    elif kind == "serpentine":
        per_row = 20
        rows = max(2, n_frames // per_row)
        xs = 1.0 + step * np.arange(per_row)
        truth = np.array([(x, 1.0 + step * r, 0.0 if r % 2 == 0 else np.pi)
                          for r in range(rows) for x in (xs if r % 2 == 0 else xs[::-1])])
        turns = np.arange(1, rows) * per_row  # each lane's first frame: reached by a quarter turn and a step
        truth[turns, 2] = np.pi / 2
        U_true = increments(truth, direction=True)
        U_odo = U_true.copy()
        drift = np.deg2rad(0.1)
        events = [int(t) for t in turns]
    else:
        U_true = np.c_[_drive(n_frames, step, rng, area, sharp=kind == "sharp_turns"), np.zeros(n_frames - 1)]
        U_odo = U_true.copy()
        if kind == "kidnap":
            k = n_frames // 2  # step k (frame k to k + 1): carried, the odometry shows nothing
            U_odo[k] = 0.0
            events = [k + 1]
        if kind == "slip":
            for k in (n_frames // 3, 2 * n_frames // 3):
                U_true[k : k + 3, 0] = 0.0  # the robot stands, the wheels spin
                events.append(k + 1)
    Un = U_odo.copy()
    Un[:, 0] *= 1 + distance_noise * rng.normal(size=len(Un))
    Un[:, 1] += heading_noise * rng.normal(size=len(Un)) + drift * np.abs(U_odo[:, 0])
    odometry = dead_reckon(Un, (0.0, 0.0, 0.0))
    start = ((area / 2, area / 2, float(rng.uniform(-np.pi, np.pi))) if kind not in ("raster", "serpentine")
             else (1.0, 1.0, 0.0))
    if kind == "kidnap":
        k = events[0] - 1
        before = dead_reckon(U_true[:k], start)  # frames 0..k
        p = before[-1]
        away = np.array([area / 2, area / 2]) - p[:2]  # carried 20 m toward the centre and beyond: it stays inside
        nrm = np.hypot(*away)
        away = 20.0 * (away / nrm if nrm > 1e-9 else np.array([1.0, 0.0]))
        landing = np.array([p[0] + away[0], p[1] + away[1], p[2]])
        poses = np.vstack([before, dead_reckon(U_true[k + 1 :], landing)])  # frames k + 1 .. N - 1
    else:
        poses = dead_reckon(U_true, start)
    stamps = np.arange(len(poses), dtype=float)
    if kind == "dropped":
        keep = np.ones(len(poses), bool)
        for k in rng.choice(np.arange(20, len(poses) - 20, 25), 4, replace=False):
            keep[k : k + rng.integers(5, 13)] = False
        poses, odometry, stamps = poses[keep], odometry[keep], stamps[keep]
    Z = poses[:, :2] + estimate_noise * rng.normal(size=(len(poses), 2))
    bad = rng.random(len(Z)) < outlier_rate
    ang = rng.uniform(0, 2 * np.pi, bad.sum())
    Z[bad] += rng.uniform(2, 5, bad.sum())[:, None] * np.c_[np.cos(ang), np.sin(ang)]
    noise = {"distance_noise": distance_noise * step,
             "heading_noise": float(np.hypot(heading_noise, drift * step)), "measurement_noise": estimate_noise,
             "turn_noise": 0.0}
    return {"poses": poses, "odometry": odometry, "estimates": Z, "stamps": stamps, "noise": noise,
            "events": events, "kind": kind}


def _err(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.hypot(*(a[:, :2] - b[:, :2]).T)


def compare_recovery(cases: Sequence[str] = CASES, seeds: Sequence[int] = (0, 1, 2, 3, 4),
                     **case_params: Any) -> list[dict[str, Any]]:
    """Mean position error (metres) of the single-image estimates, the fused
    track (:func:`sfanav.odometry.fuse`, start pose from the estimates,
    stamps given) and the fused track without recovery, per case, averaged
    over ``seeds``; with ``reinit`` the mean number of re-initialisations
    and ``worst_ratio`` the largest fused / single ratio over the seeds."""
    rows = []
    for kind in cases:
        single, fused, plain, reinit, ratio = [], [], [], [], []
        for seed in seeds:
            c = make_filter_case(kind, random_state=seed, **case_params)
            T = c["poses"]
            f, ekf = fuse(c["odometry"], c["estimates"], c["noise"], stamps=c["stamps"], return_filter=True)
            p = fuse(c["odometry"], c["estimates"], c["noise"], stamps=c["stamps"], recovery=False)
            single.append(_err(c["estimates"], T).mean())
            fused.append(_err(f, T).mean())
            plain.append(_err(p, T).mean())
            reinit.append(ekf.n_reinitializations_)
            ratio.append(fused[-1] / single[-1])
        rows.append({"case": kind, "single": float(np.mean(single)), "fused": float(np.mean(fused)),
                     "fused_no_recovery": float(np.mean(plain)), "reinit": float(np.mean(reinit)),
                     "worst_ratio": float(np.max(ratio))})
    return rows


def print_recovery_table(seeds: Sequence[int] = (0, 1, 2, 3, 4)) -> list[dict[str, Any]]:
    """Prints :func:`compare_recovery` as the Markdown table of the docs."""
    rows = compare_recovery(seeds=seeds)
    print("| case | single images (m) | fused (m) | fused / single (worst seed) | fused without recovery (m) "
          "| re-initialisations per run |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['case']} | {r['single']:.3f} | {r['fused']:.3f} | {r['fused'] / r['single']:.2f} "
              f"({r['worst_ratio']:.2f}) | {r['fused_no_recovery']:.3f} | {r['reinit']:.1f} |")
    return rows
