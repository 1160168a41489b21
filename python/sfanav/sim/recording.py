"""Recording a preset: its world, its runs driven and rendered, written as
one sfanav dataset.

``simulate(name, out, seed)`` generates a preset's world (:mod:`.presets`
holds the catalogue), drives its runs and writes one sfanav dataset (see
:mod:`sfanav.data.dataset`) with a ``run`` column (``train``, ``test``,
...), the world as ``world.json`` and the whole recipe in
``metadata.json``. ``sfanav simulate --preset NAME --out DIR`` is the same
from the command line. A preset seed splits into independent random
streams (:func:`random_streams` and the further ``*_stream`` functions), so
that adding a draw to one part leaves the others' datasets unchanged.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from . import trajectories as T
from .cameras import OmniCamera, PanoramicCamera
from .changes import changed_gardens
from .conditions import Lighting
from .presets import LightFn, get
from .render import Renderer
from .robot import Robot
from .terrain import HeightField
from .world import World
from ..data.schema import GYRO_COLUMN


def random_streams(seed: int) -> list[np.random.Generator]:
    """The four independent random streams of a preset seed (world, runs,
    trajectories, odometry noise), as every preset draws them."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    return [np.random.default_rng(s) for s in np.random.SeedSequence(int(seed)).spawn(4)]


def jitter_stream(seed: int) -> np.random.Generator:
    """The random stream of a preset seed's pose jitter: the seed's fifth
    child sequence, independent of the four of :func:`random_streams`."""
    return np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(4,)))


def gyro_stream(seed: int) -> np.random.Generator:
    """The random stream of a preset seed's gyro noise: the seed's seventh
    child sequence, independent of the others."""
    return np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(6,)))


def terrain_stream(seed: int) -> np.random.Generator:
    """The random stream of a preset seed's uneven ground: the seed's sixth
    child sequence, independent of the others."""
    return np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(5,)))


def preset_terrain(preset: str, seed: int = 0) -> HeightField | None:
    """The ground-height field that ``simulate(preset, ..., seed)`` drives
    on, or None for a preset on flat ground."""
    p = get(preset)
    return None if p.terrain is None else p.terrain.field(terrain_stream(seed))


def preset_world(preset: str, seed: int = 0) -> World:
    """The world that ``simulate(preset, ..., seed)`` uses (without the
    dynamic object, whose period depends on the run)."""
    p = get(preset)
    return World.generate(int(random_streams(seed)[0].integers(2**31)), **p.world)


def simulate(preset: str, out: str | os.PathLike, seed: int = 0, *, max_frames: int | None = None,
             camera: PanoramicCamera | OmniCamera | None = None, overwrite: bool = False,
             progress: bool = True, flat: bool = False) -> Any:
    """Generates a preset's dataset.

    Parameters
    ----------
    preset : str
        A name from ``PRESETS`` (``describe()`` lists them).
    out : path
        Directory of the dataset (must not exist or be empty, unless ``overwrite``).
    seed : int
        Seeds the world, the trajectories, the lighting conditions, the
        odometry noise, the pose jitter, the uneven ground and the changed
        gardens: same seed, same dataset (the gyro noise of a robot with a
        gyro too).
    max_frames : int, optional
        Keep only the first frames of every run (quick looks, tests).
    camera : PanoramicCamera or OmniCamera, optional
        Replaces the preset's camera.
    progress : bool
        A progress bar (tqdm).
    flat : bool
        Drive a preset with uneven ground on flat ground instead (a control:
        the same world, runs and images as far as the ground allows).

    Returns
    -------
    sfanav.Dataset
        A preset with uneven ground (``Preset.terrain``) adds the columns
        ``roll_deg``, ``pitch_deg`` and ``camera_dz_m`` (the robot's
        attitude per frame, :class:`~sfanav.sim.terrain.Attitude`) and
        records the ground's recipe in the metadata (``terrain``). A
        preset whose robot has a gyro (``mower-survey``) adds the column
        ``gyro_heading`` (:attr:`~sfanav.Dataset.gyro`). Runs that see a
        changed garden (``RunSpec.changes``) name it in
        ``metadata["runs"][run]["garden"]``; ``metadata["gardens"][name]``
        holds its world file (``world-<name>.json``), the changes' spec and
        one record per object changed (:meth:`GardenChanges.apply`).
    """
    from ..data.dataset import Dataset
    from ..data.writer import DatasetWriter

    p = get(preset)
    if max_frames is not None and (isinstance(max_frames, bool) or not isinstance(max_frames, (int, np.integer))
                                   or max_frames < 1):
        raise ValueError(f"max_frames must be a positive integer, got {max_frames!r}")
    if not isinstance(flat, (bool, np.bool_)):
        raise TypeError(f"flat must be a bool, got {flat!r}")
    s_world, s_runs, s_traj, s_odo = random_streams(seed)
    world = World.generate(int(s_world.integers(2**31)), **p.world)
    cam = camera or p.camera()
    robot = p.robot()
    runs = p.runs(s_runs)
    gardens = changed_gardens(world, runs, seed)  # each from its own stream: other draws are unchanged
    worlds = [world if r.changes is None else gardens[r.changes.name][0] for r in runs]
    full = [r.trajectory(wd, s_traj) for r, wd in zip(runs, worlds)]  # jitter draws over the whole run, then it is cut
    trajs = [tr if max_frames is None else tr[: int(max_frames)] for tr in full]
    s_jit = jitter_stream(seed)
    if p.dynamic:
        world.add_dynamic({"period": float(max(trajs[0].times[-1], 1e-3)), "radius": 0.6, "height": 2.5},
                          seed=int(s_world.integers(2**31)))
    renderers = {id(wd): Renderer(wd) for wd in {id(wd): wd for wd in worlds}.values()}
    heights = None if flat else preset_terrain(preset, seed)
    total = sum(len(t) * len(r.conditions) * len(robot.cameras) for t, r in zip(trajs, runs))
    attitude_cols = set(ATTITUDE_COLUMNS) if heights is not None else set()
    gyro_cols = {GYRO_COLUMN} if robot.gyro is not None else set()
    extra_cols = sorted({k for t in trajs for k in t.extra} | attitude_cols | gyro_cols)
    s_gyro = gyro_stream(seed)
    meta = {
        "source": "sfanav.sim",
        "preset": p.name,
        "thesis_section": p.section,
        "description": p.description,
        "seed": int(seed),
        "max_frames": max_frames,
        "camera": cam.to_dict(),
        "robot": robot.to_dict(),
        "world": "world.json",
        "runs": {},
    }
    if gardens:
        meta["gardens"] = {name: {"world": f"world-{name}.json", "changes": spec.to_dict(), "objects": records}
                           for name, (_, records, spec) in gardens.items()}
    if heights is not None:
        meta["terrain"] = heights.ground.to_dict()
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=total, desc=f"simulate {p.name}", unit="img")
    frame = 0
    with DatasetWriter(out, meta, overwrite=overwrite, extra_columns=extra_cols) as w:
        for r, tr, whole, wd in zip(runs, trajs, full, worlds):
            info: dict[str, Any] = {"frames": len(tr), "conditions": {}}
            if r.changes is not None:
                info["garden"] = r.changes.name
            if r.jitter is not None:
                info["jitter"] = {"lateral_m": r.jitter[0], "heading_deg": r.jitter[1]}
            for cond, light in r.conditions.items():
                info["conditions"][cond] = light.to_dict() if isinstance(light, Lighting) else {
                    "changing": True, "start": light(0.0).to_dict(), "end": light(1.0).to_dict()}
                drive = tr if r.jitter is None else T.jitter(whole, *r.jitter, rng=s_jit)[: len(tr)]
                frame = _record(w, renderers[id(wd)], robot, cam, drive, run=r.name, condition=cond, lighting=light,
                                frame0=frame, rng=s_odo, bar=bar, heights=heights, gyro_rng=s_gyro)
            meta["runs"][r.name] = info
        w.metadata.update(meta)
        world.save(Path(out) / "world.json")
        for name, (changed, _, _) in gardens.items():
            changed.save(Path(out) / f"world-{name}.json")
    if bar is not None:
        bar.close()
    return Dataset(out)


ATTITUDE_COLUMNS = ("roll_deg", "pitch_deg", "camera_dz_m")
"""The per-frame columns of a dataset simulated on uneven ground."""


def _record(w: Any, renderer: Renderer, robot: Robot, cam: Any, tr: T.Trajectory, *, run: str, condition: str,
            lighting: Lighting | LightFn, frame0: int, rng: np.random.Generator, bar: Any,
            heights: HeightField | None = None, gyro_rng: np.random.Generator | None = None) -> int:
    cam_poses = robot.camera_poses(tr.poses)
    odo = robot.camera_poses(robot.odometry(tr.poses, rng))
    gyro = robot.gyro_headings(tr.poses, tr.times, gyro_rng) if robot.gyro is not None else None
    n = len(tr)
    attitudes = heights.attitudes(tr.poses) if heights is not None else None  # the robot's, shared by its cameras
    for k in range(n):
        light = lighting if isinstance(lighting, Lighting) else lighting(k / max(n - 1, 1))
        extra = {c: v[k].item() for c, v in tr.extra.items()}
        if gyro is not None:
            extra[GYRO_COLUMN] = float(gyro[k])
        att = None
        if attitudes is not None:
            att = attitudes[k]
            extra.update(roll_deg=att.roll_deg, pitch_deg=att.pitch_deg, camera_dz_m=att.height_m)
        for name in robot.cameras:
            img = renderer.render(cam, cam_poses[name][k], float(tr.times[k]), light, attitude=att)
            w.add(img, frame=frame0 + k, timestamp=float(tr.times[k]), pose=cam_poses[name][k],
                  odometry=odo[name][k], camera=name, condition=condition, run=run, **extra)
            if bar is not None:
                bar.update(1)
    return frame0 + n
