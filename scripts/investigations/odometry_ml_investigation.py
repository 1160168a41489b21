"""The investigation behind the maximum-likelihood metric learning of
``docs/odometry.md`` (issue 8, thesis 5.3.1), on the slow features that
``sfanav experiment 5.3.1-real`` / ``5.3.1-sim`` cached:

* ``real``: variants of the cost on the 5.3.1-real training lines (MED
  against the training run's ground truth; the test walk is not used);
* ``noise``: the training run's odometry redrawn with the simulator's noise
  scaled by k (two draws each): odometry initialisation, the thesis's cost
  5.5 and the ML cost with the default and a matched noise model, train /
  test MED;
* ``sim``: the ML cost against the thesis's cost 5.1 on the 5.3.1-sim lines,
  learner seeds 0-4;
* ``drift``: systematic heading drift on the synthetic ``make_odometry_run``
  (no cached features needed) and the drift estimated on 5.3.1-real.

    PYTHONPATH=python python3 scripts/investigations/odometry_ml_investigation.py \\
        --real RESULTS/data/thesis-5.2-indoor-II-seed0-features.npz \\
        --sim RESULTS/data/thesis-5.3.1-sim-seed0-features.npz [--parts real noise sim drift]

Seconds per part (one BLAS thread).
"""

from __future__ import annotations

import argparse
from dataclasses import asdict

import numpy as np
from threadpoolctl import threadpool_limits

from sfanav.experiments.thesis_5_3 import experiment_5_3_1
from sfanav.odometry import DEFAULT_ODOMETRY_NOISE, MetricLearner
from sfanav.localization import align, med
from sfanav.odometry import lines_from_odometry, segment_lines
from sfanav.localization import QuadraticRegression
from sfanav.sim import OdometryNoise, simulate_odometry


def _aligned(m: MetricLearner, F: np.ndarray, xy: np.ndarray, on: np.ndarray, F_test=None, xy_test=None):
    al = align(m.transform(F[on]), xy[on], allow_reflection=True)
    train = med(al.apply(m.transform(F[on])), xy[on])
    return train if F_test is None else (train, med(al.apply(m.transform(F_test)), xy_test))


def part_real(path: str) -> None:
    z = np.load(path)
    F, xy, odo = z["train/features"], z["train/poses"][:, :2], z["train/odometry"]
    lines = segment_lines(odo)
    on = lines.mask
    print(f"5.3.1-real training lines: {lines.n_lines} lines, {lines.n_points} points")
    print(f"  supervised regression on the line samples: train MED {QuadraticRegression(8).fit(F[on], xy[on]).score(F[on], xy[on]):.3f} m")
    variants = {
        "thesis cost 5.5 (cos term, lambda 1)": dict(angle_term="cos"),
        "signed angle term, lambda 1": dict(angle_term="signed"),
        "signed angle term, noise-model weights": dict(angle_term="signed", angle_weight="noise"),
        "transit term only, noise-model weights": dict(angle_term=None, transit_weight="noise"),
        "signed angle + transit, noise-model weights (default)": dict(angle_weight="noise", transit_weight="noise"),
        "cos angle + transit, noise-model weights": dict(angle_term="cos", angle_weight="noise", transit_weight="noise"),
    }
    for s in (0.1, 0.3, 3.0, 10.0):
        variants[f"default, noise model x{s:g}"] = dict(
            angle_weight="noise", transit_weight="noise",
            odometry_noise={k: v * s for k, v in DEFAULT_ODOMETRY_NOISE.items()})
    for name, kw in variants.items():
        m = MetricLearner(init="odometry", **kw).fit(F, lines, progress=False)
        sf = "-" if m.feature_noise_ is None else f"{m.feature_noise_:.3f}"
        print(f"  {name:55s} cost {m.cost_:8.2f}  sigma_f {sf:>5}  train MED {_aligned(m, F, xy, on):.3f} m")


def part_noise(path: str) -> None:
    z = np.load(path)
    F, P, Fte, xyte = z["train/features"], z["train/poses"], z["test/features"], z["test/poses"][:, :2]
    xy = P[:, :2]
    base = asdict(OdometryNoise())
    print("5.3.1-real, training odometry redrawn with the noise scaled by k: train / test MED (m)")
    for k in (0.0, 1.0, 3.0, 10.0):
        for draw in (1, 2):
            odo = simulate_odometry(P, OdometryNoise(**{a: v * k for a, v in base.items()}), 100 + draw)
            lines = segment_lines(odo)
            on = lines.mask
            row = {
                "odometry init": MetricLearner(init="odometry", angle_term="cos", solver="gd", max_iter=1),
                "thesis 5.5": MetricLearner(init="odometry", angle_term="cos"),
                "ML default": MetricLearner(init="odometry", angle_weight="noise", transit_weight="noise"),
            }
            if k > 0:
                row["ML matched"] = MetricLearner(init="odometry", angle_weight="noise", transit_weight="noise",
                                                  odometry_noise={a: v * k for a, v in DEFAULT_ODOMETRY_NOISE.items()})
            cells = []
            for name, m in row.items():
                tr, te = _aligned(m.fit(F, lines, progress=False), F, xy, on, Fte, xyte)
                cells.append(f"{name} {tr:.3f} / {te:.3f}")
            odo_med = med(odo[:, :2] - odo[0, :2] + P[0, :2], xy)
            print(f"  k={k:g} draw {draw}: {lines.n_lines} lines, odometry MED {odo_med:.3f} | " + " | ".join(cells))


def part_sim(path: str) -> None:
    z = np.load(path)
    lines = lines_from_odometry(z["lines/segment"], z["lines/odometry"])
    print("5.3.1-sim, ML cost (default learner), learner seeds 0-4")
    for seed in range(5):
        r = experiment_5_3_1(z["lines/features"], lines, z["lines/poses"][:, :2], z["test/features"],
                             z["test/poses"][:, :2], variant="sim", random_state=seed)
        print(f"  seed {seed}: cost {r.row('final cost'):.2f}, train MED {r.row('train MED unsupervised (m)'):.3f} m, "
              f"ratio {r.row('unsupervised/supervised test MED ratio'):.3f}; thesis cost 5.1: train MED "
              f"{r.row('thesis cost 5.1 at its minimum: train MED unsupervised (m)'):.3f} m")


def part_drift(path: str) -> None:
    from sfanav.experiments.synthetic_odometry import make_odometry_run

    print("synthetic make_odometry_run, training-line MED (m) [heading_drift_ used]")
    for bias in (0.002, 0.0002, 0.0):
        for seed in (0, 1):
            run = make_odometry_run(n_legs=14, random_state=seed, heading_bias=bias)
            lines = segment_lines(run["odometry"])
            F, xy, on = run["features"], run["xy"], lines.mask
            variants = {"thesis 5.5": dict(angle_term="cos"), "ML": dict(angle_weight="noise", transit_weight="noise"),
                        "ML drift estimated": dict(angle_weight="noise", transit_weight="noise", heading_drift="estimate"),
                        "ML drift known": dict(angle_weight="noise", transit_weight="noise", heading_drift=bias / 0.04)}
            cells = []
            for name, kw in variants.items():
                m = MetricLearner(init="odometry", **kw).fit(F, lines, progress=False)
                cells.append(f"{name} {_aligned(m, F, xy, on):.3f} [{m.heading_drift_:.4f}]")
            print(f"  drift {bias / 0.04:.3f} rad/m, seed {seed}: " + " | ".join(cells))
    if path is not None:
        z = np.load(path)
        F, xy = z["train/features"], z["train/poses"][:, :2]
        lines = segment_lines(z["train/odometry"])
        m = MetricLearner(init="odometry", angle_weight="noise", transit_weight="noise",
                          heading_drift="estimate").fit(F, lines, progress=False)
        print(f"  5.3.1-real: estimated drift {m.heading_drift_:.4f} rad/m, train MED "
              f"{_aligned(m, F, xy, lines.mask):.3f} m")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--real", help="cached features of 5.3.1-real (thesis-5.2-indoor-II-seed0-features.npz)")
    ap.add_argument("--sim", help="cached features of 5.3.1-sim (thesis-5.3.1-sim-seed0-features.npz)")
    ap.add_argument("--parts", nargs="+", default=["real", "noise", "sim", "drift"],
                    choices=["real", "noise", "sim", "drift"])
    args = ap.parse_args()
    with threadpool_limits(limits=1, user_api="blas"):
        for part in args.parts:
            path = args.sim if part == "sim" else args.real
            if path is None and part != "drift":
                ap.error(f"part {part!r} needs --{'sim' if part == 'sim' else 'real'}")
            {"real": part_real, "noise": part_noise, "sim": part_sim, "drift": part_drift}[part](path)


if __name__ == "__main__":
    main()
