"""Navigation experiments of thesis chapter 7 on the built-in simulator.

* ``7.1-open``: open field (7.1.2), n = 2 outputs, 50 trials with start and
  target >= 15 m apart; success rate and efficiency (direct / travelled).
* ``7.1-obstacle``: the v-shaped wall (7.1.2); target fixed inside the V,
  starts in the lower half on the other side; efficiency against A* on a
  0.1 m grid.
* ``7.2.1``: n = 2..8 outputs, raw and weighted by 1/beta (open field).
* ``7.2.2``: SFA on the coordinates of a random trajectory with a 3x speed
  difference (half-plane split; slow central disc); paths against the
  time-optimal ones.

Each runs the thesis's descent rule (:class:`~sfanav.navigation.ThesisDescent`,
eta 1.0, gamma 0.5) and sfanav's :class:`~sfanav.navigation.RobustDescent` on
the same trials and reports one row per descent and metric; ``7.1-*`` also
run the metric-space arms (:func:`metric_arms`: the cameras localized by the
sfanav default, :class:`~sfanav.navigation.MetricDescent` without and with
the exploration run's :class:`~sfanav.navigation.GeodesicField`). ``quick=True``
shrinks everything to a smoke test (a 6 x 6 m garden, 120 x 16 gray
panoramas, a two-layer network, a few trials).

Networks are trained on the preset's training run (the robot's centre
poses of the preset's random-lines trajectory, rendered as 600 x 60 RGB
panoramas) with the thesis-5.2 network in mixed precision (for speed) and
cached under ``out/cache`` (``7.2.1`` reuses ``7.1-open``'s network when run
into the same directory).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from .. import navigation as nav
from . import ExperimentResult, register
from .navigation_scenes import (
    DEFAULT_NET_WEIGHTED_N,
    ETA,
    GAMMA,
    MAX_ITERATIONS,
    QUICK_ITERATIONS,
    SUCCESS_RADIUS,
    Scene,
    coordinate_model,
    free_space,
    grid_features,
    homing_navigator,
    image_trials,
    metric_localizer,
    navigator,
    no_ground_truth_localizer,
    position_code_error,
    scene,
    scene_network,
    trial_rng,
)

# The thesis's figures (chapter 7, thesis-figures.md).
THESIS = {
    "open": {"success": 0.98, "efficiency": 0.94},
    "obstacle": {"success": 0.88, "efficiency": 0.76},
    "7.2.1": {("raw", 2): (0.98, 0.94), ("raw", 8): (0.16, None), ("weighted", 3): (0.98, 0.92),
              ("weighted", 8): (0.86, 0.86)},
}




def _descents() -> list[Any]:
    return [nav.ThesisDescent(ETA, GAMMA), nav.RobustDescent()]




def _summary_rows(label: str, s: nav.TrialSummary, thesis: dict[str, Any] | None, extra: str = "") -> list[dict[str, Any]]:
    th = thesis or {}
    rows = [
        {"metric": f"success{extra} ({label})", "thesis": th.get("success"), "sfanav": s.success_rate},
        {"metric": f"efficiency{extra} ({label})", "thesis": th.get("efficiency"), "sfanav": s.efficiency},
    ]
    return rows


def _reasons(s: nav.TrialSummary) -> str:
    return ", ".join(f"{k} {v}" for k, v in sorted(s.reasons.items()))


def pick_trials(results: list[nav.NavigationResult], k: int) -> list[int]:
    """Indices of up to k runs to plot: failures first, then successes."""
    fail = [i for i, r in enumerate(results) if not r.success]
    ok = [i for i, r in enumerate(results) if r.success]
    sel = fail[: k // 2] + ok
    return sorted(sel[:k])



def _plot_trials(s: nav.TrialSummary, path: Path, sc: Scene, opt_paths: list[Any] | None, title: str) -> str:
    """Up to 8 of a summary's trials (failures first), with their shortest
    paths if given, each titled by its outcome and efficiency; the PNG's
    path."""
    sel = pick_trials(s.results, 8)
    return str(nav.plot_trajectories(
        [s.results[i] for i in sel], path, world=sc.world,
        optimal=None if opt_paths is None else [opt_paths[i] for i in sel],
        titles=[("reached" if s.results[i].success else s.results[i].reason)
                + (f" e={s.efficiencies[i]:.2f}" if s.results[i].success else "") for i in sel],
        title=title))


def metric_arms(sc: Scene, out: Path, seed: int, starts: np.ndarray, targets: np.ndarray,
                optimal: np.ndarray | None, *, progress: bool = False,
                localizer: tuple[Any, Any] | None = None, field: Any = None,
                no_ground_truth: tuple[Any, Any] | None = None) -> tuple[list[dict[str, Any]], list[str], list[str]]:
    """Navigation in the learned metric space on the same trials: the thesis
    rule (eta 1, gamma 0.5) on the distance between estimated positions and
    on the exploration run's geodesic distance, both divided by the run's
    spread (:class:`ScaledCost`: the slow features' unit-variance scale the
    rule was set for), on single-image estimates and on positions fused
    with odometry (:class:`MapTracker`), and :class:`MetricDescent` without
    and with the run's :class:`GeodesicField`. ``localizer``: (localizer, camera) from
    :func:`metric_localizer` if the caller has it; ``field``: the run's
    GeodesicField if the caller built it; ``no_ground_truth``: (localizer,
    field) of :func:`no_ground_truth_localizer`, run as one more arm
    (metric descent + its geodesic field, its own estimates). Returns
    (rows, plots, notes)."""
    loc, cam = localizer if localizer is not None else metric_localizer(sc, out, seed, progress=progress)
    feats = nav.MetricFeatures(loc, sc.simulator.renderer, cam)
    run_xy = sc.trajectory.poses[:, :2]
    field = nav.GeodesicField(run_xy) if field is None else field
    spread = nav.run_spread(run_xy)  # metres per slow-feature unit: the thesis rule's eta and gamma apply
    arms = [("thesis rule, metric cost", nav.ThesisDescent(ETA, GAMMA), nav.ScaledCost(spread), None),
            ("thesis rule, geodesic metric cost", nav.ThesisDescent(ETA, GAMMA), nav.ScaledCost(spread, field.cost),
             None),
            ("thesis rule, metric cost, tracked positions", nav.ThesisDescent(ETA, GAMMA), nav.ScaledCost(spread),
             nav.MapTracker()),
            ("thesis rule, geodesic metric cost, tracked positions", nav.ThesisDescent(ETA, GAMMA),
             nav.ScaledCost(spread, field.cost), nav.MapTracker()),
            ("metric descent", nav.MetricDescent(), None, None),
            ("metric descent + geodesic field", nav.MetricDescent(field=field), None, None)]
    rows: list[dict[str, Any]] = []
    plots: list[str] = []
    notes: list[str] = []
    arms = [(name, d, cost, tracker, feats) for name, d, cost, tracker in arms]
    if no_ground_truth is not None:
        free, free_field = no_ground_truth
        arms.append(("metric descent + geodesic field, no ground truth", nav.MetricDescent(field=free_field), None,
                     None, nav.MetricFeatures(free, sc.simulator.renderer, cam)))
    for name, d, cost, tracker, feats in arms:
        navi = nav.Navigator(sc.fresh_noise(), feats, d, n_outputs=2, success_radius=SUCCESS_RADIUS,
                             max_iterations=QUICK_ITERATIONS if sc.quick else MAX_ITERATIONS, cost=cost,
                             tracker=tracker)
        s = nav.evaluate_trials(navi, starts, targets, optimal_lengths=optimal, progress=progress, desc=name)
        rows += _summary_rows(name, s, None)
        rows.append({"metric": f"mean stops ({name})", "thesis": None, "sfanav": s.mean_iterations})
        notes.append(f"{name}: {_reasons(s)}")
        tag = name.replace(" ", "-").replace("+", "plus").replace(",", "")
        plots.append(_plot_trials(s, out / f"7.1-{sc.name.split('-')[-1]}-trajectories-{tag}.png", sc, None,
                                  f"7.1: {name}"))
    return rows, plots, notes


def trials_71(sc: Scene, kind: str, seed: int, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray | None,
                                                                np.ndarray | None, list[Any]]:
    """The trials of ``7.1-<kind>`` from trial stream ``seed`` (the
    experiment's is its seed; other streams give other trials; the first k
    of n are the trials drawn with n = k). Open field: start and target
    uniform in the free area, >= 15 m apart (3.5 m in the quick scene).
    Obstacle: the target fixed inside the V, starts in the lower half
    outside it, >= 4 m away (2 m quick), with the A* length (8-connected,
    0.1 m grid, obstacles inflated by the robot radius), the any-angle
    length and the any-angle path of each. Returns (starts (n, 2), targets
    (n, 2), A* lengths (n,) or None, any-angle lengths (n,) or None, paths:
    a list of n arrays or None)."""
    rng = trial_rng(seed, 71, 0 if kind == "open" else 1)
    free = free_space(sc)
    w, h = sc.area
    if kind == "open":
        starts, targets = nav.sample_trials(n, sc.area, free=free, min_distance=3.5 if sc.quick else 15.0,
                                            margin=0.4, rng=rng)
        return starts, targets, None, None, [None] * n
    apex_y = -0.15 * h
    arm = 0.3 * min(w, h)
    target = np.array([0.0, apex_y + 0.45 * arm])  # inside the V, on the side it opens to

    def below(x: float, y: float) -> bool:  # lower half, outside the V's cup
        return y < 0 and y < apex_y + abs(x) - 0.3

    starts, targets = nav.sample_trials(n, sc.area, free=free, min_distance=2.0 if sc.quick else 4.0,
                                        margin=0.4, target=target, start_region=below, rng=rng)
    grid = nav.occupancy_grid(sc.area, lambda x, y: sc.world.free(x, y, sc.robot.size / 2), resolution=0.1,
                              margin=sc.robot.size / 2)
    optimal, geo, paths = [], [], []
    for s_, t_ in zip(starts, targets):
        optimal.append(nav.shortest_path(grid, s_, t_)[1])
        Ps, Ls = nav.shortest_path(grid, s_, t_, smooth=True)
        geo.append(Ls)
        paths.append(Ps)
    return starts, targets, np.array(optimal), np.array(geo), paths


def _run_71(kind: str, out: Path, *, quick: bool, seed: int, progress: bool) -> ExperimentResult:
    sc = scene(kind, seed, quick=quick)
    net = scene_network(sc, out, seed, progress=progress)
    n_trials = 3 if quick else 50
    starts, targets, optimal, geo, opt_paths = trials_71(sc, kind, seed, n_trials)
    rows: list[dict[str, Any]] = []
    plots: list[str] = []
    notes_runs = []
    summaries = {}
    n_img = n_trials if quick else image_trials(n_trials)
    for d in _descents():
        navi = navigator(sc, net, d)
        s = nav.evaluate_trials(navi, starts[:n_img], targets[:n_img],
                                optimal_lengths=None if optimal is None else optimal[:n_img], progress=progress,
                                desc=d.name)
        summaries[d.name] = s
        rows += _summary_rows(d.name, s, THESIS[kind] if d.name == "thesis rule" else None)
        if geo is not None:
            ok = np.array([r.success for r in s.results])
            eff_geo = np.array([geo[i] / r.travelled for i, r in enumerate(s.results) if r.success and r.travelled > 0])
            rows.append({"metric": f"efficiency vs any-angle shortest path ({d.name})", "thesis": None,
                         "sfanav": float(eff_geo.mean()) if ok.any() else float("nan")})
        rows.append({"metric": f"mean stops ({d.name})", "thesis": None, "sfanav": s.mean_iterations})
        notes_runs.append(f"{d.name}: {_reasons(s)}" + (f", escapes {sum(r.escapes for r in s.results)}"
                                                        if d.name == "robust descent" else ""))
        tag = d.name.replace(" ", "-")
        plots.append(_plot_trials(s, out / f"7.1-{kind}-trajectories-{tag}.png", sc, opt_paths,
                                  f"7.1 {kind}: {d.name}"))
    # the peer: homing by perfect memory (robust descent of the rotational image difference to the target's view)
    label = "robust descent, perfect memory homing (rotational image difference)"
    s = nav.evaluate_trials(homing_navigator(sc), starts[:n_img], targets[:n_img],
                            optimal_lengths=None if optimal is None else optimal[:n_img], progress=progress,
                            desc=label)
    rows += _summary_rows(label, s, None)
    rows.append({"metric": f"mean stops ({label})", "thesis": None, "sfanav": s.mean_iterations})
    notes_runs.append(f"{label}: {_reasons(s)}")
    plots.append(_plot_trials(s, out / f"7.1-{kind}-trajectories-perfect-memory-homing.png", sc, opt_paths,
                              f"7.1 {kind}: {label}"))
    # the sfanav default network's slow features (horizon band, wider layers: the metric arms' localizer's
    # network, unpooled), n = 2 raw (the thesis's setting) and n = 8 weighted by beta_1 / beta_i (7.2.1's remedy)
    loc, dcam = metric_localizer(sc, out, seed, progress=progress)
    dnet = loc.network
    n_w = min(DEFAULT_NET_WEIGHTED_N, dnet.n_outputs_)
    dw = nav.beta_weights(np.asarray(dnet.beta_values_, float)[:n_w], relative=True)
    for n, wts, tag in ((2, None, "n = 2"), (n_w, dw, f"n = {n_w} weighted")):
        for d in _descents():
            label = f"{d.name}, sfanav default network, {tag}"
            navi = nav.Navigator(sc.fresh_noise(), nav.ImageFeatures(dnet, sc.simulator.renderer, dcam, rows=loc.network_input),
                                 d, n_outputs=n, weights=wts, success_radius=SUCCESS_RADIUS,
                                 max_iterations=QUICK_ITERATIONS if quick else MAX_ITERATIONS)
            s = nav.evaluate_trials(navi, starts[:n_img], targets[:n_img],
                                    optimal_lengths=None if optimal is None else optimal[:n_img], progress=progress,
                                    desc=label)
            rows += _summary_rows(label, s, None)
            rows.append({"metric": f"mean stops ({label})", "thesis": None, "sfanav": s.mean_iterations})
            notes_runs.append(f"{label}: {_reasons(s)}")
            if d.name == "thesis rule":
                plots.append(_plot_trials(s, out / f"7.1-{kind}-trajectories-default-network-n{n}.png", sc,
                                          opt_paths, f"7.1 {kind}: {label}"))
    # the same trials with slow features of the coordinates (the ideal case of the image network)
    model = coordinate_model(sc)
    for d in _descents():
        psim = nav.PointSimulator(robot=sc.robot, world=sc.world)
        navi = nav.Navigator(psim, nav.CoordinateFeatures(model), d, n_outputs=2, success_radius=SUCCESS_RADIUS,
                             max_iterations=QUICK_ITERATIONS if quick else MAX_ITERATIONS)
        s = nav.evaluate_trials(navi, starts, targets, optimal_lengths=optimal, progress=progress,
                                desc=f"{d.name}, coordinate SFA")
        rows += _summary_rows(f"{d.name}, coordinate SFA", s, None)
        notes_runs.append(f"{d.name} with coordinate SFA: {_reasons(s)}")
        if d.name == "robust descent":
            sel = pick_trials(s.results, 8)
            plots.append(str(nav.plot_trajectories(
                [s.results[i] for i in sel], out / f"7.1-{kind}-trajectories-coordinate-sfa.png", world=sc.world,
                optimal=[opt_paths[i] for i in sel], title=f"7.1 {kind}: robust descent on coordinate SFA")))
    # the thesis rule on ideal features of the exploration run itself (a point robot at true positions): the
    # slowest functions of the run with no limit on the function class (graph SFA: Laplacian eigenmaps of the
    # run's places, which flow around the obstacle), and the run's geodesic distance (what SFA's slowness
    # stands for around obstacles) on the unit-variance scale of slow features
    run_xy = sc.trajectory.poses[:, :2]
    field = nav.GeodesicField(run_xy)
    ideal = [("thesis rule, graph SFA of the run (ideal slow features, n = 2)",
              nav.CoordinateFeatures(nav.RunGraphFeatures(run_xy, 2)), None),
             ("thesis rule, geodesic cost of the run (true positions)", nav.CoordinateFeatures(lambda X: X),
              nav.ScaledCost(nav.run_spread(run_xy), field.cost))]
    for label, feats, cost in ideal:
        psim = nav.PointSimulator(robot=sc.robot, world=sc.world)
        navi = nav.Navigator(psim, feats, nav.ThesisDescent(ETA, GAMMA), n_outputs=2, success_radius=SUCCESS_RADIUS,
                             max_iterations=QUICK_ITERATIONS if quick else MAX_ITERATIONS, cost=cost)
        s = nav.evaluate_trials(navi, starts, targets, optimal_lengths=optimal, progress=progress, desc=label)
        rows += _summary_rows(label, s, None)
        notes_runs.append(f"{label}: {_reasons(s)}")
    # beyond the thesis: the same trials in the learned metric space (images -> slow features -> positions)
    free, free_xy, free_info = no_ground_truth_localizer(sc, out, seed, loc, dcam, progress=progress)
    mrows, mplots, mnotes = metric_arms(sc, out, seed, starts, targets, optimal, progress=progress,
                                        localizer=(loc, dcam), field=field,
                                        no_ground_truth=(free, nav.GeodesicField(free_xy)))
    for k, v in free_info.items():
        if isinstance(v, (int, float)) and v is not None:
            rows.append({"metric": f"{k} (no ground truth)", "thesis": None, "sfanav": float(v)})
    rows += mrows
    plots += mplots
    notes_runs += mnotes
    xs, ys, F = grid_features(sc, net, 0.75 if quick else 0.5, progress)
    for n in (2, 8):
        rows.append({"metric": f"position code: RMS of x, y from s1-s{n} (m)", "thesis": None,
                     "sfanav": position_code_error(xs, ys, F, n)})
    dxs, dys, DF = grid_features(sc, dnet, 0.75 if quick else 0.5, progress, camera=dcam, rows=loc.network_input)
    for n in (2, n_w):
        rows.append({"metric": f"position code: RMS of x, y from s1-s{n} (m), sfanav default network", "thesis": None,
                     "sfanav": position_code_error(dxs, dys, DF, n)})
    dtf = nav.ImageFeatures(dnet, sc.simulator.renderer, dcam, rows=loc.network_input)(
        np.array([[targets[0][0], targets[0][1], 0.0]]))[0]
    plots.append(str(nav.plot_cost_surface(dxs, dys, DF, dtf, out / f"7.1-{kind}-cost-surface-default-network.png",
                                           ns=(2, n_w), weights=np.concatenate([dw, np.ones(DF.shape[-1] - n_w)]),
                                           n_firing=4, target=targets[0], world=sc.world,
                                           title=f"7.1 {kind}: sfanav default network, s1-s4, cost n = 2 and "
                                                 f"{n_w} (weighted)")))
    tf = navigator(sc, net, None).target_features(targets[0])
    plots.append(str(nav.plot_cost_surface(xs, ys, F, tf, out / f"7.1-{kind}-cost-surface.png", ns=(2,), n_firing=4,
                                           target=targets[0], world=sc.world,
                                           title=f"7.1 {kind}: firing maps s1-s4, cost to the first trial's target")))
    notes = (
        f"{'QUICK smoke version: ' if quick else ''}scene {sc.name} (seed {seed}), {len(sc.trajectory)} training frames, "
        f"network {'two-layer 120x16 gray' if quick else 'thesis-5.2 (600x60 RGB), precision mixed'}, rotation step {10 if quick else 5} px; "
        f"{n_trials} trials ({n_img} of them with the image network), two cameras 0.7 m apart, n = 2 outputs, success radius {SUCCESS_RADIUS} m, "
        f"at most {QUICK_ITERATIONS if quick else MAX_ITERATIONS} stops; thesis rule eta {ETA}, gamma {GAMMA}; robust descent "
        "defaults (see docs/navigation.md). "
        + ("Start-target >= %.1f m apart, efficiency = direct distance / travelled. " % (3.5 if quick else 15.0)
           if kind == "open" else
           f"Target fixed inside the V at ({targets[0][0]:.2f}, {targets[0][1]:.2f}); starts in the lower half outside "
           "the V; efficiency = A* length (8-connected, 0.1 m grid, obstacles inflated by the robot radius) / "
           "travelled; the any-angle row uses the line-of-sight-shortened A* path. ")
        + "Rows 'graph SFA of the run' and 'geodesic cost of the run': the thesis rule on ideal features of the "
        "training run itself, a point robot at true positions: its slowest functions with no limit on the function "
        "class (Laplacian eigenmaps of the run's places, nav.RunGraphFeatures, n = 2) and its geodesic distance "
        "(nav.GeodesicField) divided by the run's spread. Every closed-loop arm starts from the same odometry noise "
        "stream. "
        + "Rows 'coordinate SFA': the same trials with slow features of the coordinates (degree-7 monomials of the "
        "training trajectory's positions, the image network's ideal case), a point robot with exact odometry. "
        "'position code' rows: RMS error of x, y fitted as a quadratic function of the image network's first 2 / 8 "
        "outputs on a 0.5 m grid (how well the representation codes position). "
        "Rows 'sfanav default network': the same trials (as many as the image network's) on the raw slow features "
        "of the network of the metric arms' localizer (" + ("the quick two-layer network" if quick else
        "the sfanav default: horizon band, wider layers, 350x40 renders, unpooled") + f"), n = 2 raw and n = {n_w} "
        "weighted by beta_1/beta_i (7.2.1's remedy), thesis rule eta 1 and robust descent; position-code rows "
        "likewise on its outputs. "
        "Rows 'metric cost' / 'metric descent' (beyond the thesis): the same trials with the cameras localized by "
        + ("a GP readout of the quick network" if quick else
           "the sfanav default (horizon band, 12 outputs, 350x40 RGB renders of the training run, GP readout, "
           "8 rotations pooled)")
        + "; the cost is the distance between the cameras' and the target image's estimated positions (or the "
        "training run's geodesic distance between them; 'tracked positions': the cameras' estimates fused with "
        "odometry by a robust rigid fit over the last 20 stops, nav.MapTracker), divided by the run's spread (RMS std of its positions, "
        f"{nav.run_spread(sc.trajectory.poses[:, :2]):.2f} m) for the thesis rule, which then runs with the thesis's eta and gamma on unit-variance 'ideal' "
        "x / y features; MetricDescent heads for the target through a rigid odometry-to-map fit, with the geodesic field over the "
        "training run's positions (ground truth here) when the run's path is > 1.2x the straight line. "
        "Row '..., no ground truth': the same network with its readout fitted to the training run's positions "
        "learned from its images and simulated odometry (pose graph), the geodesic field over those learned "
        "positions, targets as images (their estimates); success measured in the world. "
        + "Outcomes: " + "; ".join(notes_runs) + "."
    )
    return ExperimentResult(f"7.1-{kind}", rows, plots, notes)


@register("7.1-open", "Navigation in an open field (thesis 7.1.2): thesis rule vs robust descent vs metric descent")
def exp_71_open(out: Path, *, quick: bool = False, seed: int = 0, progress: bool = True) -> ExperimentResult:
    return _run_71("open", Path(out), quick=quick, seed=seed, progress=progress)


@register("7.1-obstacle", "Navigation around the v-shaped obstacle (thesis 7.1.2): thesis rule vs robust descent "
          "vs metric descent")
def exp_71_obstacle(out: Path, *, quick: bool = False, seed: int = 0, progress: bool = True) -> ExperimentResult:
    return _run_71("obstacle", Path(out), quick=quick, seed=seed, progress=progress)


N_TRIALS_721_IMAGES = 20  # image-based runs per setting (28 settings; the thesis: 50)


@register("7.2.1", "More slow-feature outputs, raw vs weighted by 1/beta (thesis 7.2.1)")
def exp_721(out: Path, *, quick: bool = False, seed: int = 0, progress: bool = True) -> ExperimentResult:
    out = Path(out)
    sc = scene("open", seed, quick=quick)
    net = scene_network(sc, out, seed, progress=progress)
    beta = np.asarray(net.beta_values_, float)
    wrel = nav.beta_weights(beta, relative=True)
    model = coordinate_model(sc)
    cbeta = np.asarray(model.sfa.beta_values_, float)
    cw = nav.beta_weights(cbeta, relative=True)
    n_trials = 1 if quick else 50
    n_img = 1 if quick else image_trials(N_TRIALS_721_IMAGES)
    ns = list(range(2, 9))
    rng = trial_rng(seed, 721)
    starts, targets = nav.sample_trials(n_trials, sc.area, free=free_space(sc), min_distance=3.5 if quick else 15.0,
                                        margin=0.4, rng=rng)
    rows: list[dict[str, Any]] = []
    outcome = []
    for arm in ("images", "coordinate SFA"):
        for n in ns:
            for mode in ("raw", "weighted"):
                for d in _descents():
                    if arm == "images":
                        navi = navigator(sc, net, d, n=n, weights=wrel if mode == "weighted" else None)
                        S, T = starts[:n_img], targets[:n_img]
                        label = d.name
                    else:
                        psim = nav.PointSimulator(robot=sc.robot, world=sc.world)
                        navi = nav.Navigator(psim, nav.CoordinateFeatures(model), d, n_outputs=n,
                                             weights=cw if mode == "weighted" else None,
                                             success_radius=SUCCESS_RADIUS, max_iterations=MAX_ITERATIONS)
                        S, T = starts, targets
                        label = f"{d.name}, coordinate SFA"
                    if quick:
                        navi.max_iterations = 25
                    s = nav.evaluate_trials(navi, S, T, progress=progress, desc=f"n={n} {mode} {label}")
                    th = THESIS["7.2.1"].get((mode, n), (None, None)) if label == "thesis rule" else (None, None)
                    rows.append({"metric": f"n={n} {mode}: success ({label})", "thesis": th[0], "sfanav": s.success_rate})
                    rows.append({"metric": f"n={n} {mode}: efficiency ({label})", "thesis": th[1],
                                 "sfanav": s.efficiency})
                    outcome.append((n, mode, label, s.success_rate, s.efficiency))
    plots = []
    xs, ys, F = grid_features(sc, net, 0.75 if quick else 0.5, progress)
    tf = navigator(sc, net, None).target_features(targets[0])
    plots.append(str(nav.plot_cost_surface(xs, ys, F, tf, out / "7.2.1-cost-surfaces.png", ns=ns, weights=wrel,
                                           n_firing=8, target=targets[0],
                                           title="7.2.1: firing maps s1-s8; cost n = 2..8 raw and 1/beta-weighted")))
    X, Y = np.meshgrid(xs, ys)
    FC = model(np.column_stack([X.ravel(), Y.ravel()])).reshape(X.shape + (8,))
    FC[~np.asarray(sc.world.free(X, Y, 0.0))] = np.nan
    plots.append(str(nav.plot_cost_surface(xs, ys, FC, model(targets[:1])[0], out / "7.2.1-cost-surfaces-coordinate-sfa.png",
                                           ns=ns, weights=cw, n_firing=8, target=targets[0],
                                           title="7.2.1, coordinate SFA: s1-s8; cost n = 2..8 raw and 1/beta-weighted")))
    plots.append(str(_plot_721([o for o in outcome if "coordinate" not in o[2]], out / "7.2.1-success-vs-n.png")))
    plots.append(str(_plot_721([(n, m, d.replace(", coordinate SFA", ""), sr, ef) for n, m, d, sr, ef in outcome
                                if "coordinate" in d], out / "7.2.1-success-vs-n-coordinate-sfa.png")))
    notes = (
        f"{'QUICK smoke version: ' if quick else ''}open-field scene {sc.name} (seed {seed}) and its network; "
        f"{n_img} trials per n, descent and weighting with images (the thesis: 50; 28 settings of up to 400 stops "
        f"of rendering and SFA each), {n_trials} with coordinate SFA (degree-7 monomials of the training "
        f"trajectory's positions, the image network's ideal case); start-target >= {3.5 if quick else 15.0} m. "
        f"beta of the network's outputs: {', '.join(f'{b:.3g}' for b in beta)}; of the coordinate SFA: "
        f"{', '.join(f'{b:.3g}' for b in cbeta)}. Weighted outputs use weights beta_1 / beta_i "
        f"(1/beta scaled so the slowest output keeps weight 1) with eta = {ETA}, which equals the thesis's 1/beta "
        f"weights with eta = beta_1 = {beta[0]:.3g} (thesis: 0.0015); raw outputs eta = {ETA}; gamma {GAMMA}. "
        "The thesis gives numbers only for raw n = 2 and 8 and weighted n = 3 and 8 (fig. 7.8)."
    )
    return ExperimentResult("7.2.1", rows, plots, notes)


def _plot_721(outcome: list[tuple[int, str, str, float, float]], path: Path) -> Path:
    from .._plotting import figure, save_figure

    fig = figure(8.0, 3.2)
    axes = fig.subplots(1, 2)
    for (mode, dname), style in {("raw", "thesis rule"): "o-", ("weighted", "thesis rule"): "s-",
                                 ("raw", "robust descent"): "o--", ("weighted", "robust descent"): "s--"}.items():
        pts = [(n, sr, ef) for n, m, d, sr, ef in outcome if m == mode and d == dname]
        if not pts:
            continue
        a = np.array(pts, float)
        axes[0].plot(a[:, 0], a[:, 1], style, label=f"{mode}, {dname}")
        axes[1].plot(a[:, 0], a[:, 2], style, label=f"{mode}, {dname}")
    axes[0].plot([2, 8, 3, 8], [0.98, 0.16, 0.98, 0.86], "k*", ms=9, label="thesis")
    axes[1].plot([2, 3, 8], [0.94, 0.92, 0.86], "k*", ms=9)
    axes[0].set_ylabel("success rate")
    axes[1].set_ylabel("efficiency")
    for ax in axes:
        ax.set_xlabel("number of SFA outputs n")
        ax.set_ylim(0, 1.05)
    axes[0].legend(fontsize="x-small")
    return save_figure(fig, path, 110)


def _coordinate_scene(kind: str, seed: int, quick: bool) -> tuple[Any, Any, Any]:
    """(world, trajectory, velocity regions) of a 7.2.2 preset (quick: 1500 frames)."""
    from ..sim import presets as P
    from ..sim import recording as R
    from ..sim import trajectories as T
    from ..sim.world import World

    name = f"thesis-7.2.2-{kind}"
    p = P.get(name)
    s_world, s_runs, s_traj, _ = R.random_streams(seed)
    world = World.generate(int(s_world.integers(2**31)), **p.world)
    regions = T.VelocityRegions.half_plane(0.0, "left", 3.0) if kind == "halfplane" else T.VelocityRegions.disc(5.0, factor=3.0)
    if quick:
        traj = T.random_lines(world.area, 1500, 0.2, margin=0.35, world=world, rng=s_traj, speed=regions)
    else:
        traj = p.runs(s_runs)[0].trajectory(world, s_traj)
    return world, traj, regions


@register("7.2.2", "Velocity regions: SFA on coordinates, paths vs time-optimal ones (thesis 7.2.2)")
def exp_722(out: Path, *, quick: bool = False, seed: int = 0, progress: bool = True) -> ExperimentResult:
    from ..sim.robot import Robot

    out = Path(out)
    rows: list[dict[str, Any]] = []
    plots: list[str] = []
    notes = []
    n_trials = 2 if quick else 20
    for kind in ("halfplane", "disc"):
        world, traj, regions = _coordinate_scene(kind, seed, quick)
        area = world.area
        model = nav.fit_coordinate_sfa(traj.poses[:, :2], area, n_components=8, expansion="rbf", spacing=1.5)
        beta = model.sfa.beta_values_
        w = nav.beta_weights(beta, relative=True)
        rng = trial_rng(seed, 722, 0 if kind == "halfplane" else 1)
        hw, hh = area[0] / 2 - 0.5, area[1] / 2 - 0.5
        if kind == "halfplane":
            starts, targets = nav.sample_trials(n_trials, area, min_distance=8.0, margin=0.5,
                                                start_region=lambda x, y: x < -1.0, target_region=lambda x, y: x > 1.0,
                                                rng=rng)
        else:
            th = rng.uniform(-np.pi, np.pi, n_trials)
            r0, r1 = rng.uniform(7.0, 8.5, n_trials), rng.uniform(7.0, 8.5, n_trials)
            th1 = th + np.pi + rng.uniform(-0.25, 0.25, n_trials)
            starts = np.clip(np.column_stack([r0 * np.cos(th), r0 * np.sin(th)]), [-hw, -hh], [hw, hh])
            targets = np.clip(np.column_stack([r1 * np.cos(th1), r1 * np.sin(th1)]), [-hw, -hh], [hw, hh])
        # time-optimal references
        opt_paths, opt_times = [], []
        if kind == "disc":
            grid = nav.occupancy_grid(area, None, resolution=0.1, margin=0.35)
            GX, GY = grid.centres()
            slow = (GX ** 2 + GY ** 2) < 25.0
            wgrid = np.where(slow, 3.0, 1.0)
        for s_, t_ in zip(starts, targets):
            if kind == "halfplane":
                P, T_ = nav.halfplane_optimal(s_, t_, x0=0.0, speed_left=1.0, speed_right=3.0)
            else:
                P, cost = nav.shortest_path(grid, s_, t_, weights=wgrid)
                T_ = nav.travel_time(P, regions)
            opt_paths.append(P)
            opt_times.append(T_)
        direct_times = [nav.travel_time(np.array([s_, t_]), regions) for s_, t_ in zip(starts, targets)]
        gd = nav.RobustDescent(gauss_newton=False)
        gd.name = "robust descent, gradient steps"
        for d in _descents() + [gd]:
            sim = nav.PointSimulator(area, Robot.two_cameras(0.7))
            navi = nav.Navigator(sim, nav.CoordinateFeatures(model), d, n_outputs=8, weights=w,
                                 success_radius=SUCCESS_RADIUS, max_iterations=MAX_ITERATIONS)
            s = nav.evaluate_trials(navi, starts, targets, progress=progress, desc=f"{kind} {d.name}")
            teff = [opt_times[i] / nav.travel_time(r.path, regions) for i, r in enumerate(s.results) if r.success]
            rows.append({"metric": f"{kind}: success ({d.name})", "thesis": None, "sfanav": s.success_rate})
            rows.append({"metric": f"{kind}: time efficiency, optimal / path time ({d.name})", "thesis": None,
                         "sfanav": float(np.mean(teff)) if teff else float("nan")})
            if kind == "halfplane":
                err = []
                for i, r in enumerate(s.results):
                    P = r.path
                    k = np.nonzero(np.diff(np.sign(P[:, 0])) != 0)[0]
                    if r.success and len(k):
                        a, b = P[k[0]], P[k[0] + 1]
                        y = a[1] + (b[1] - a[1]) * (0 - a[0]) / (b[0] - a[0])
                        err.append(abs(y - opt_paths[i][1][1]))
                rows.append({"metric": f"{kind}: transition point error m ({d.name})", "thesis": None,
                             "sfanav": float(np.mean(err)) if err else float("nan")})
            tag = d.name.replace(" ", "-")
            k = min(4, len(s.results))
            plots.append(str(nav.plot_trajectories(
                s.results[:k], out / f"7.2.2-{kind}-trajectories-{tag}.png", area=area, optimal=opt_paths[:k],
                regions=lambda X, Y: np.vectorize(lambda x, y: 3.0 - regions(x, y))(X, Y) / 2,
                title=f"7.2.2 {kind}: {d.name} (grey: slow region; dashed: time-optimal)")))
            notes.append(f"{kind} {d.name}: {_reasons(s)}")
        rows.append({"metric": f"{kind}: time efficiency of the direct path", "thesis": None,
                     "sfanav": float(np.mean(np.array(opt_times) / np.array(direct_times)))})
        xs = np.linspace(-area[0] / 2 + 0.25, area[0] / 2 - 0.25, 72)
        ys = np.linspace(-area[1] / 2 + 0.25, area[1] / 2 - 0.25, 88)
        GX, GY = np.meshgrid(xs, ys)
        F = model(np.column_stack([GX.ravel(), GY.ravel()])).reshape(GX.shape + (8,))
        tf = model(targets[:1])[0]
        plots.append(str(nav.plot_cost_surface(xs, ys, F, tf, out / f"7.2.2-{kind}-maps.png", ns=(8,), weights=w,
                                               n_firing=4, target=targets[0],
                                               title=f"7.2.2 {kind}: s1-s4, cost (8 outputs) raw and 1/beta")))
    header = (
        f"{'QUICK smoke version: ' if quick else ''}Linear SFA (8 outputs) on Gaussian bumps (1.5 m grid and "
        f"width) of the coordinates along the preset's random-lines trajectory ({'1500' if quick else '5000'} frames, 3x farther per "
        "step in the fast region); navigation with the 8 outputs weighted by beta_1/beta_i, a point robot with two "
        f"virtual sensors 0.7 m apart; {n_trials} trials per scene (half-plane: start x < -1, target x > 1, >= 8 m "
        "apart; disc: start and target 7-8.5 m from the centre on opposite sides). Optimal: Snell transition point "
        "(half-plane), A* on a 0.1 m grid with cost 3 per metre in the slow disc (disc). The thesis reports no "
        "numbers here, only that the paths are close to the time-optimal ones. 'robust descent, gradient steps': the robust "
        "descent without its Gauss-Newton steps (it follows the cost's gradient like the thesis rule). "
    )
    return ExperimentResult("7.2.2", rows, plots, header + "Outcomes: " + "; ".join(notes) + ".")
