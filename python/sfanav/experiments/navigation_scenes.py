"""The scenes, networks and localizers of the navigation experiments
(thesis chapter 7, :mod:`sfanav.experiments.navigation`): the simulated
gardens and their trials' random streams, the trained networks (cached
under ``out/cache``), the navigators and descents' constants, features on
a grid of positions, and the localizers of the metric-space arms (with and
without ground truth)."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .. import navigation as nav

ETA, GAMMA = 1.0, 0.5  # thesis 7.1.2


SUCCESS_RADIUS, MAX_ITERATIONS = 0.5, 400


QUICK_ITERATIONS = 40


DEFAULT_NET_WEIGHTED_N = 8  # outputs of the sfanav default network in its weighted arms (7.2.1's remedy)


IMAGE_TRIALS_ENV = "SFANAV_NAV_IMAGE_TRIALS"


def image_trials(default: int) -> int:
    """Trials run with the image network (each up to 400 stops of rendering
    and SFA on two cameras): ``default``, or the first N of the trials when
    the environment variable ``SFANAV_NAV_IMAGE_TRIALS`` is set to N (for
    runs on a slow machine; the coordinate-SFA arm always runs all)."""
    v = os.environ.get(IMAGE_TRIALS_ENV)
    if v is None or v == "":
        return default
    try:
        k = int(v)
    except ValueError:
        raise ValueError(f"{IMAGE_TRIALS_ENV} must be a positive integer, got {v!r}") from None
    if k < 1:
        raise ValueError(f"{IMAGE_TRIALS_ENV} must be a positive integer, got {v!r}")
    return min(k, default)


@dataclass
class Scene:
    """A navigation scene: world, camera, robot and the training trajectory."""

    name: str
    world: Any
    camera: Any
    robot: Any
    trajectory: Any
    quick: bool
    _sim: Any = field(default=None, init=False, repr=False, compare=False)  # built on first use

    @property
    def simulator(self) -> Any:
        """The scene's closed-loop simulator (built once: its renderer takes
        a few seconds); its ``renderer`` also renders training images."""
        if self._sim is None:
            from ..sim.robot import Simulator

            self._sim = Simulator(self.world, self.camera, self.robot, seed=0)
        return self._sim

    def fresh_noise(self) -> Any:
        """The scene's simulator with its odometry noise stream restarted
        (seed 0), so that every arm of an experiment drives with the same
        noise whatever ran before it (common random numbers)."""
        sim = self.simulator
        sim.rng = np.random.default_rng(0)
        return sim

    @property
    def area(self) -> tuple[float, float]:
        return tuple(float(a) for a in self.world.area)  # type: ignore[return-value]


def trial_rng(seed: int, *tags: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([int(seed), *tags]))


def scene(kind: str, seed: int = 0, *, quick: bool = False, lawn: str | None = None) -> Scene:
    """The scene of ``7.1-open`` (``kind="open"``) or ``7.1-obstacle``
    (``"obstacle"``): the preset ``thesis-7.1-<kind>`` with its own
    training trajectory, or with ``quick`` a 6 x 6 m garden with 120 x 16
    gray panoramas and a 400-frame random-lines run. ``lawn`` overrides the
    preset's lawn (``"uniform"``; ``"patchy"``: the scenes before
    2026-11-24, see :meth:`sfanav.sim.World.generate`)."""
    from ..sim import presets as P
    from ..sim import recording as R
    from ..sim import trajectories as T
    from ..sim.cameras import PanoramicCamera
    from ..sim.robot import OdometryNoise, Robot
    from ..sim.world import World

    if kind not in ("open", "obstacle"):
        raise ValueError(f"kind must be 'open' or 'obstacle', got {kind!r}")
    if quick:
        r = trial_rng(seed, 7, 1 if kind == "open" else 2)
        world = World.generate(int(r.integers(2**31)), area=(6.0, 6.0), n_objects=14, depth=6.0,
                               obstacles=("v-wall",) if kind == "obstacle" else (), lawn=lawn or "uniform")
        traj = T.random_lines(world.area, 400, 0.2, margin=0.35, world=world, rng=r)
        cam = PanoramicCamera(120, 16, rgb=False)
        robot = Robot.two_cameras(0.7, noise=OdometryNoise())
        return Scene(f"quick-{kind}", world, cam, robot, traj, True)
    name = f"thesis-7.1-{kind}"
    p = P.get(name)
    s_world, s_runs, s_traj, _ = R.random_streams(seed)
    world = World.generate(int(s_world.integers(2**31)), **{**p.world, **({"lawn": lawn} if lawn else {})})
    traj = p.runs(s_runs)[0].trajectory(world, s_traj)
    return Scene(name, world, p.camera(), p.robot(), traj, False)


def cache_name(sc: Scene, what: str, seed: int, *parts: Any) -> str:
    """``<what>-seed<seed>-<key>.sfanav``: ``key`` hashes the world, the
    training trajectory and ``parts`` (the network's configuration), so a
    cached network of another scene version is never reused."""
    import hashlib
    import json

    h = hashlib.sha1(json.dumps(sc.world.to_dict(), sort_keys=True, default=str).encode())
    h.update(np.ascontiguousarray(sc.trajectory.poses, np.float64).tobytes())
    h.update(json.dumps(parts, sort_keys=True, default=str).encode())
    return f"{what}-seed{seed}-{h.hexdigest()[:10]}.sfanav"


def network_config(quick: bool) -> dict[str, Any]:
    """The network: thesis Table 5.2 (600 x 60 RGB) in mixed precision, or a
    two-layer network for 120 x 16 gray panoramas (quick)."""
    from ..sfa.config import preset_config

    if quick:
        return {
            "input": {"width": 120, "height": 16, "channels": 1},
            "network": {"weight_sharing": True},
            "layers": [{"rf": [10, 8], "stride": [5, 4], "out": 6}, {"rf": "full", "out": 8}],
        }
    cfg = preset_config("thesis-5.2")
    cfg.setdefault("network", {})["precision"] = "mixed"
    return cfg


def scene_network(sc: Scene, out: Path, seed: int, *, progress: bool = False) -> Any:
    """Trains (or loads from ``out/cache``) the network of a scene on the
    images of its training trajectory (robot centre poses, in time order),
    with simulated rotation in steps of 5 px over the whole panorama."""
    from ..sfa.modelfile import load
    from ..sfa.network import Network, Rotation

    cache = Path(out) / "cache" / cache_name(sc, sc.name, seed, network_config(sc.quick), "rotation 5/10 px")
    if cache.exists():
        return load(cache)
    renderer = sc.simulator.renderer
    poses = sc.trajectory.poses
    it = poses
    if progress:
        from tqdm.auto import tqdm

        it = tqdm(poses, desc=f"render {sc.name}", unit="img", leave=False)
    imgs = np.stack([renderer.render(sc.camera, p) for p in it])
    net = Network(network_config(sc.quick))
    net.fit(imgs, rotation=Rotation(10 if sc.quick else 5), progress=progress)
    cache.parent.mkdir(parents=True, exist_ok=True)
    net.save(cache)
    return net


def navigator(sc: Scene, net: Any, descent: Any, *, n: int = 2, weights: Any = None) -> nav.Navigator:
    """A navigator in the scene's simulator."""
    sim = sc.fresh_noise()
    feats = nav.ImageFeatures(net, sim.renderer, sc.camera)
    return nav.Navigator(sim, feats, descent, n_outputs=n, weights=weights, success_radius=SUCCESS_RADIUS,
                         max_iterations=QUICK_ITERATIONS if sc.quick else MAX_ITERATIONS)


def homing_navigator(sc: Scene) -> nav.Navigator:
    """The peer in the scene's simulator: homing by perfect memory (the
    robust descent of the rotational image difference to the target's
    panorama, :mod:`sfanav.navigation.homing`)."""
    sim = sc.fresh_noise()
    feats = nav.PanoramaFeatures(sim.renderer, sc.camera)
    return nav.Navigator(sim, feats, nav.RobustDescent(), n_outputs=1, success_radius=SUCCESS_RADIUS,
                         max_iterations=QUICK_ITERATIONS if sc.quick else MAX_ITERATIONS,
                         cost=nav.image_difference_cost(feats.width))


def free_space(sc: Scene, extra: float = 0.05):
    r = sc.robot.size / 2 + extra
    return lambda x, y: sc.world.free(x, y, r)


def grid_features(sc: Scene, net: Any, spacing: float, progress: bool, *, camera: Any = None,
                   rows: Any = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """SFA outputs on a grid over the area (NaN where the robot cannot stand),
    rendered with ``camera`` (default: the scene's), ``rows`` applied."""
    camera = sc.camera if camera is None else camera
    w, h = sc.area
    xs = np.arange(-w / 2 + spacing / 2, w / 2, spacing)
    ys = np.arange(-h / 2 + spacing / 2, h / 2, spacing)
    X, Y = np.meshgrid(xs, ys)
    ok = np.asarray(sc.world.free(X, Y, 0.0))
    renderer = sc.simulator.renderer
    F = np.full(X.shape + (net.n_outputs_,), np.nan)
    idx = np.argwhere(ok)
    it = range(0, len(idx), 64)
    if progress:
        from tqdm.auto import tqdm

        it = tqdm(it, desc="cost surface", unit="batch", leave=False)
    for k in it:
        chunk = idx[k : k + 64]
        imgs = np.stack([renderer.render(camera, (X[i, j], Y[i, j], 0.0)) for i, j in chunk])
        F[chunk[:, 0], chunk[:, 1]] = net.transform(imgs if rows is None else rows(imgs))
    return xs, ys, F


def position_code_error(xs: np.ndarray, ys: np.ndarray, F: np.ndarray, n: int) -> float:
    """RMS error (m) of x, y fitted as a quadratic function of the first
    ``n`` outputs over a grid (a measure of how well they code position)."""
    X, Y = np.meshgrid(xs, ys)
    ok = np.isfinite(F[..., 0])
    g = F[ok][:, :n]
    P = np.column_stack([X[ok], Y[ok]])
    A = np.column_stack([g] + [g[:, i : i + 1] * g[:, i:] for i in range(n)] + [np.ones(len(g))])
    coef, *_ = np.linalg.lstsq(A, P, rcond=None)
    return float(np.sqrt(np.mean(np.sum((A @ coef - P) ** 2, axis=1))))


def coordinate_model(sc: Scene) -> Any:
    """SFA on the coordinates of the scene's training trajectory (monomials
    up to degree 7): the representation the image network ideally learns
    (thesis 7.2.2, after [42]); a reference for the descents."""
    return nav.fit_coordinate_sfa(sc.trajectory.poses[:, :2], sc.area, n_components=8, expansion="poly", degree=7)


def metric_localizer(sc: Scene, out: Path, seed: int, *, progress: bool = False) -> tuple[Any, Any]:
    """The localizer of the metric-space arms (beyond the thesis): the sfanav
    default network (horizon band, 12 outputs, 350 x 40 RGB panoramas at the
    robot's centre along the scene's training run) with a GP readout of its
    outputs to the run's positions, rotation pooled (the default's); with
    ``quick`` the scene's camera and the two-layer network. Cached as a model
    file under ``out/cache``. Returns (localizer, camera)."""
    from ..localization.localizer import Localizer
    from ..localization.recipe import CAMERA_ELEVATION, default_network, default_rows
    from ..sfa.modelfile import load
    from ..sfa.network import Network, Rotation
    from ..sim.cameras import PanoramicCamera

    cam = sc.camera if sc.quick else PanoramicCamera(350, 40)
    cache = Path(out) / "cache" / cache_name(sc, f"metric-{sc.name}", seed, "sfanav default + gp, pooled", cam.to_dict())
    if cache.exists():
        loc = load(cache)
        if isinstance(loc, Localizer):
            return loc, cam
    rows = None if sc.quick else default_rows(CAMERA_ELEVATION)
    poses = sc.trajectory.poses
    imgs = training_images(sc, cam, progress=progress)
    net = Network(network_config(True)) if sc.quick else default_network()
    net.fit(imgs if rows is None else rows(imgs), rotation=Rotation(10 if sc.quick else 5), progress=progress)
    loc = Localizer(net, readout={"kind": "gp", "n_outputs": net.n_outputs_}, rows=rows).fit(imgs, poses[:, :2])
    cache.parent.mkdir(parents=True, exist_ok=True)
    loc.save(cache)
    return loc, cam


def training_images(sc: Scene, cam: Any, *, progress: bool = False) -> np.ndarray:
    """The scene's training run rendered with ``cam`` at the robot's centre."""
    it = sc.trajectory.poses
    if progress:
        from tqdm.auto import tqdm

        it = tqdm(it, desc=f"render {sc.name} ({cam.width}x{cam.height})", unit="img", leave=False)
    renderer = sc.simulator.renderer
    return np.stack([renderer.render(cam, p) for p in it])


def exploration_odometry(sc: Scene, seed: int) -> np.ndarray:
    """The odometry (N, 3) of the scene's training run: the scene robot's
    noise model along the true poses (stream ``seed``), starting at the true
    first pose."""
    from ..sim.robot import simulate_odometry

    return simulate_odometry(sc.trajectory.poses, sc.robot.noise, trial_rng(seed, 7, 9))


def no_ground_truth_localizer(sc: Scene, out: Path, seed: int, loc: Any, cam: Any, *,
                              progress: bool = False) -> tuple[Any, np.ndarray, dict[str, Any]]:
    """The metric arms' localizer with its readout fitted without ground
    truth: the same network (trained on images only), the training run's
    positions learned from its images and simulated odometry
    (:func:`exploration_odometry`) by the pose graph. Returns (localizer,
    the learned positions (N, 2) for the geodesic field, a summary); cached
    under ``out/cache``."""
    import json
    import os
    import warnings

    from ..localization.error_metrics import align
    from ..localization.localizer import Localizer
    from ..odometry.self_supervision import OdometryMapWarning, learn_positions
    from ..sfa.modelfile import load

    cache = Path(out) / "cache" / cache_name(sc, f"metric-{sc.name}-no-ground-truth", seed, cam.to_dict(),
                                              "pose graph, 2 refinement rounds, offset sigma estimated")
    side = cache.with_suffix(".positions.npy")
    if cache.exists() and side.exists():
        free = load(cache)
        if isinstance(free, Localizer):
            return free, np.load(side), dict(free.info.get("no ground truth", {}))
    imgs = training_images(sc, cam, progress=progress)
    odo = exploration_odometry(sc, seed)
    F = loc.features(imgs)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OdometryMapWarning)
        lp = learn_positions(F, odo, images=imgs)
    free = loc.sibling(signature=None).fit_features(F, lp.positions)
    truth = sc.trajectory.poses[:, :2]  # evaluation only
    summary = {"loop closures kept": lp.graph.n_inliers if lp.graph is not None else None,
               "training positions median error (m)": float(np.median(np.hypot(*(
                   align(lp.positions, truth).apply(lp.positions) - truth).T))),
               "odometry median error (m)": float(np.median(np.hypot(*(
                   align(odo[:, :2], truth).apply(odo[:, :2]) - truth).T))),
               "warnings": "; ".join(lp.warnings) or "-"}
    free.info.update(lp.info())
    free.info["no ground truth"] = json.loads(json.dumps(summary))
    cache.parent.mkdir(parents=True, exist_ok=True)
    free.save(cache)
    tmp = side.with_name(side.name + ".part.npy")
    np.save(tmp, lp.positions)
    os.replace(tmp, side)
    return free, lp.positions, summary
