"""Navigation trials (thesis 7.1.2): :func:`sample_trials` draws start/target
pairs, :func:`evaluate_trials` runs them and reports success rate and
efficiency (optimal / travelled path length) as a :class:`TrialSummary`."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .cost import as_vector2
from .navigator import NavigationResult, Navigator


def sample_trials(
    n: int,
    area: Sequence[float],
    *,
    free: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
    min_distance: float = 15.0,
    margin: float = 0.35,
    target: Any = None,
    start_region: Callable[[float, float], bool] | None = None,
    target_region: Callable[[float, float], bool] | None = None,
    rng: Any = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Random start and target positions (thesis 7.1.2): uniform in the area
    (``margin`` m from the border), where ``free(x, y)`` holds, at least
    ``min_distance`` apart; ``target`` fixes the target; ``start_region`` /
    ``target_region`` restrict the draws. Returns (starts (n, 2), targets (n, 2))."""
    rng = np.random.default_rng(rng)
    w, h = (float(a) for a in area)
    hx, hy = w / 2 - margin, h / 2 - margin
    if hx <= 0 or hy <= 0:
        raise ValueError(f"margin {margin} leaves no room in area {area}")

    def draw(region: Callable[[float, float], bool] | None) -> np.ndarray:
        for _ in range(100000):
            x, y = rng.uniform(-hx, hx), rng.uniform(-hy, hy)
            if (free is None or bool(free(np.array(x), np.array(y)))) and (region is None or region(x, y)):
                return np.array([x, y])
        raise ValueError("found no free position in the region")

    starts, targets = [], []
    for _ in range(int(n)):
        for _ in range(100000):
            tg = as_vector2(target, "target") if target is not None else draw(target_region)
            st = draw(start_region)
            if np.hypot(*(st - tg)) >= min_distance:
                break
        else:
            raise ValueError(f"found no start and target {min_distance} m apart")
        starts.append(st)
        targets.append(tg)
    return np.array(starts), np.array(targets)


@dataclass
class TrialSummary:
    """Outcome of :func:`evaluate_trials`.

    ``success_rate``: fraction of runs that reached the target;
    ``efficiency``: mean over successful runs of optimal / travelled length
    (the thesis's measure; NaN without successes); ``efficiencies``: per
    run (NaN for failures); ``results``: the :class:`NavigationResult` s;
    ``optimal``: the optimal lengths used."""

    success_rate: float
    efficiency: float
    efficiencies: np.ndarray
    results: list[NavigationResult]
    optimal: np.ndarray
    mean_iterations: float = 0.0
    reasons: dict[str, int] = field(default_factory=dict)


def evaluate_trials(
    navigator: Navigator,
    starts: Any,
    targets: Any,
    *,
    optimal_lengths: Any = None,
    headings: Any = None,
    progress: bool = False,
    desc: str = "trials",
) -> TrialSummary:
    """Runs ``navigator`` from each start to its target.

    ``optimal_lengths`` (per trial) defaults to the direct distance; with
    obstacles pass :func:`shortest_path` lengths (thesis: A* on a 0.1 grid).
    ``headings`` default to random ones from a fixed seed."""
    S = np.asarray(starts, float).reshape(-1, 2)
    T = np.asarray(targets, float).reshape(-1, 2)
    if S.shape != T.shape:
        raise ValueError("starts and targets must have the same length")
    n = len(S)
    opt = np.hypot(*(T - S).T) if optimal_lengths is None else np.asarray(optimal_lengths, float).reshape(n)
    if headings is None:
        headings = np.random.default_rng(12345).uniform(-np.pi, np.pi, n)
    headings = np.asarray(headings, float).reshape(n)
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=n, desc=desc, unit="run", leave=False)
    results = []
    cache: dict[tuple[float, float], np.ndarray] = {}
    for i in range(n):
        key = (float(T[i, 0]), float(T[i, 1]))
        if key not in cache:
            cache[key] = navigator.target_features(T[i])
        results.append(navigator.run(S[i], T[i], heading=float(headings[i]), target_features=cache[key]))
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    ok = np.array([r.success for r in results])
    eff = np.array([opt[i] / r.travelled if r.success and r.travelled > 0 else (1.0 if r.success else np.nan)
                    for i, r in enumerate(results)])
    reasons: dict[str, int] = {}
    for r in results:
        reasons[r.reason] = reasons.get(r.reason, 0) + 1
    return TrialSummary(
        success_rate=float(ok.mean()) if n else float("nan"),
        efficiency=float(np.nanmean(eff[ok])) if ok.any() else float("nan"),
        efficiencies=eff,
        results=results,
        optimal=opt,
        mean_iterations=float(np.mean([r.iterations for r in results])) if n else 0.0,
        reasons=reasons,
    )
