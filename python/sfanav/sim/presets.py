"""Scene presets: the thesis's simulator experiments (and sfanav's own
scenes) as recipes: world, camera, robot, runs, lighting.

:data:`PRESETS` is the catalogue (:func:`describe` lists it, :func:`get`
looks a name up); :func:`sfanav.sim.recording.simulate` turns a preset and
a seed into a dataset.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Callable, Sequence

import numpy as np

from . import surveys as S
from . import trajectories as T
from .cameras import OmniCamera, PanoramicCamera
from .changes import GardenChanges
from .conditions import SEASONS, Lighting, Season, season_of_year
from .robot import GyroNoise, OdometryNoise, Robot
from .terrain import UnevenGround
from .world import World

LightFn = Callable[[float], Lighting]  # progress in [0, 1] -> lighting


@dataclass
class RunSpec:
    """One run of a preset: a trajectory under one or more conditions.

    ``trajectory(world, rng)`` builds the trajectory; ``conditions`` maps a
    condition name to a Lighting, or to a function of the run's progress
    (0 .. 1) for light that changes during the run. With several conditions
    the same trajectory is driven once per condition.

    ``jitter = (lateral m, heading deg)`` makes every condition's drive
    deviate from the trajectory by its own smooth random sideways offset and
    heading error of at most these (:func:`~sfanav.sim.trajectories.jitter`,
    drawn from the preset seed's jitter stream); the dataset's poses and
    odometry are those of the jittered drive. None (default): every
    condition drives the exact trajectory.

    ``changes``: the run sees a changed garden, objects moved, removed or
    added (:class:`~sfanav.sim.changes.GardenChanges`; runs with changes of
    the same name see the same garden). None (default): the generated world.
    """

    name: str
    trajectory: Callable[[World, np.random.Generator], T.Trajectory]
    conditions: dict[str, Lighting | LightFn] = field(default_factory=lambda: {"default": Lighting()})
    jitter: tuple[float, float] | None = None
    changes: GardenChanges | None = None

    def __post_init__(self) -> None:
        if self.changes is not None and not isinstance(self.changes, GardenChanges):
            raise TypeError(f"run {self.name!r}: changes must be a GardenChanges or None, got "
                            f"{type(self.changes).__name__}")
        if self.jitter is not None:
            try:
                lat, head = (float(v) for v in self.jitter)
            except (TypeError, ValueError):
                lat = head = float("nan")
            if not (np.isfinite(lat) and np.isfinite(head) and lat >= 0 and head >= 0):
                raise ValueError(f"run {self.name!r}: jitter must be (lateral m, heading deg), two numbers >= 0, "
                                 f"got {self.jitter!r}")
            self.jitter = (lat, head)


@dataclass
class Preset:
    name: str
    section: str
    description: str
    world: dict[str, Any]
    camera: Callable[[], PanoramicCamera | OmniCamera]
    runs: Callable[[np.random.Generator], list[RunSpec]]
    robot: Callable[[], Robot] = Robot
    dynamic: bool = False  # a cylinder circling the area once during the first run
    terrain: UnevenGround | None = None  # uneven ground: the camera tilts and bobs (default flat)


def _garden(area: tuple[float, float], n_objects: int = 30, **kw: Any) -> dict[str, Any]:
    return {"area": area, "n_objects": n_objects, **kw}


def _ramp(lo: float, hi: float) -> LightFn:
    return lambda s: Lighting(intensity=lo + (hi - lo) * s)


def _sun_ramp(lo: float, hi: float) -> LightFn:
    return lambda s: Lighting(sun_intensity=lo + (hi - lo) * s)


def _random_conditions(rng: np.random.Generator, n: int,
                       seasons: Sequence[Season] | None = None) -> dict[str, Lighting]:
    """Thesis 6.2.2: lamp energy in [3, 8], its y in [-10, 10], red channel in
    [0.5, 1]; here intensity = energy / 5, the sun azimuth towards a lamp at
    (10, y), red tint as drawn, sun elevation in [25, 60] degrees. With
    ``seasons`` (one per condition) condition ``i`` is in ``seasons[i]``,
    named ``c{i}-{season}``, its sun elevation drawn in the season's range."""
    out = {}
    for i in range(n):
        season = seasons[i] if seasons is not None else None
        energy = rng.uniform(3, 8)
        ly = rng.uniform(-10, 10)
        red = rng.uniform(0.5, 1.0)
        lo, hi = season.sun_elevation_deg if season is not None else (25, 60)
        name = f"c{i}" if season is None else f"c{i}-{season.name}"
        out[name] = Lighting(intensity=float(energy / 5), tint=(float(red), 1.0, 1.0),
                             sun_azimuth_deg=float(np.degrees(np.arctan2(ly, 10.0))),
                             sun_elevation_deg=float(rng.uniform(lo, hi)), season=season)
    return out


def _year_of_conditions(rng: np.random.Generator, n: int) -> dict[str, Lighting]:
    """``n`` recordings spread evenly over a year from the start of spring,
    recording ``i`` at ``i / n`` of the year in the season of that quarter
    (10: 3 spring, 2 summer, 3 autumn, 2 winter), with random light as
    :func:`_random_conditions`."""
    order = list(SEASONS.values())
    return _random_conditions(rng, n, [order[(4 * i) // n] for i in range(n)])


#: a border-wire mower's deviation from one drive of its loop to the next:
#: (largest sideways offset m, largest heading error deg)
LOOP_JITTER = (0.05, 2.0)


PRESETS: dict[str, Preset] = {}


def _add(p: Preset) -> None:
    PRESETS[p.name] = p


_add(Preset(
    "demo", "-",
    "small 8x8 m garden: a grid exploration (~480 frames) and a 150-frame test walk, 600x60 panoramas; quick to make",
    _garden((8.0, 8.0), 22, depth=8.0),
    lambda: PanoramicCamera(600, 60),
    lambda rng: [RunSpec("train", lambda w, r: T.grid(w.area, spacing=1.5, step=0.25)),
                 RunSpec("test", lambda w, r: T.random_walk(w.area, 150, rng=r, world=w))],
))


_add(Preset(
    "thesis-5.1.1-grid", "5.1.1",
    "30x30 m garden seen on regular grids walked as serpentines: 624 training (26x24) and 196 test (14x14) "
    "350x40 RGB panoramas",
    _garden((30.0, 30.0), 40, depth=12.0),
    lambda: PanoramicCamera(350, 40),
    lambda rng: [RunSpec("train", lambda w, r: T.grid_points(w.area, 26, 24, margin=0.5)),
                 RunSpec("test", lambda w, r: T.grid_points(w.area, 14, 14, margin=2.0))],
))


_add(Preset(
    "thesis-5.1.2-outdoor", "5.1.2",
    "5x7 m area (the thesis's outdoor experiment) in a garden: a grid exploration with crossings and large-radius "
    "turns, 2 cm per frame (~5900 frames), and a 2800-frame test walk, 600x60 RGB panoramas",
    _garden((5.0, 7.0), 30, depth=8.0),
    lambda: PanoramicCamera(600, 60),
    lambda rng: [RunSpec("train", lambda w, r: T.grid(w.area, spacing=0.5, step=0.0204, turn="arc", margin=0.3)),
                 RunSpec("test", lambda w, r: T.random_walk(w.area, 2800, 0.04, margin=0.3, rng=r, world=w))],
))


_INDOOR_WEIGHTS = {"house": 0.25, "shed": 0.2, "fence": 0.15, "hedge": 0.15, "bush": 0.1, "tree": 0.1, "rock": 0.05}


_add(Preset(
    "thesis-5.2-indoor-I", "5.2.2",
    "indoor-style 4x4 m area closely walled by sheds, houses, fences and hedges: grid exploration with crossings "
    "and large-radius turns, 3 cm per frame (~1700 frames), an 800-frame test walk; 409x40 gray panoramas",
    _garden((4.0, 4.0), 24, margin=0.5, depth=4.0, weights=_INDOOR_WEIGHTS),
    lambda: PanoramicCamera(409, 40, rgb=False),
    lambda rng: [RunSpec("train", lambda w, r: T.grid(w.area, spacing=0.5, step=0.03, turn="arc", margin=0.3)),
                 RunSpec("test", lambda w, r: T.random_walk(w.area, 800, 0.04, margin=0.3, rng=r, world=w))],
))


_add(Preset(
    "thesis-5.2-indoor-II", "5.2.2",
    "as thesis-5.2-indoor-I, but turns on the spot and denser lanes (more crossings, ~2600 frames); an 800-frame "
    "test walk; 409x40 gray panoramas",
    _garden((4.0, 4.0), 24, margin=0.5, depth=4.0, weights=_INDOOR_WEIGHTS),
    lambda: PanoramicCamera(409, 40, rgb=False),
    lambda rng: [RunSpec("train", lambda w, r: T.grid(w.area, spacing=0.4, step=0.03, turn="spot", margin=0.3)),
                 RunSpec("test", lambda w, r: T.random_walk(w.area, 800, 0.04, margin=0.3, rng=r, world=w))],
))


_add(Preset(
    "thesis-5.2.3-outdoor", "5.2.3",
    "5x7 m patch of uneven grass (the thesis's outdoor comparison with SLAM) in a garden, seen by a 400x400 "
    "omnidirectional camera (spherical mirror, elevation -30..+20 deg): bumps and swell under the four wheels tilt "
    "the robot (roll and pitch about 2 deg rms, up to ~7 deg) and move the camera up and down (about 2 cm rms); "
    "a grid exploration with crossings and large-radius turns, 5 cm per frame (~2400 frames), and a 1000-frame "
    "test walk",
    _garden((5.0, 7.0), 30, depth=8.0),
    lambda: OmniCamera(400, elevation_deg=(-30.0, 20.0)),
    lambda rng: [RunSpec("train", lambda w, r: T.grid(w.area, spacing=0.5, step=0.05, turn="arc", margin=0.3)),
                 RunSpec("test", lambda w, r: T.random_walk(w.area, 1000, 0.04, margin=0.3, rng=r, world=w))],
    terrain=UnevenGround(),
))


def _garden_runs(lines: bool) -> Callable[[np.random.Generator], list[RunSpec]]:
    def runs(rng: np.random.Generator) -> list[RunSpec]:
        out = [RunSpec("train", lambda w, r: T.grid(w.area, spacing=1.6, step=0.26)),
               RunSpec("test", lambda w, r: T.random_walk(w.area, 1090, rng=r, world=w))]
        if lines:
            out.append(RunSpec("lines", lambda w, r: T.line_segments(w.area, 10, 8.0, 0.2, rng=r, world=w)))
        return out
    return runs


_add(Preset(
    "thesis-5.3-garden", "5.3, 5.4",
    "16x18 m garden with ArUco markers 136 and 144: grid exploration with crossings (~1780 frames), a 1090-frame "
    "test walk and 10 straight lines >= 8 m sampled every 0.2 m (metric learning), 600x60 RGB panoramas",
    _garden((16.0, 18.0), 30, markers=(136, 144)),
    lambda: PanoramicCamera(600, 60),
    _garden_runs(lines=True),
))


# Thesis 5.3.1 simulator experiment: the 5.3 garden's world, training grid and
# test walk, but the 10 lines are whole chords of the area through a random
# point in a random direction (>= 8 m), which gives the thesis's point count
# (862 on 10 lines; about 800 here) -- the `lines` run of thesis-5.3-garden
# joins two random points (about 520 points on lines). Every frame has noisy
# odometry; the experiment takes the distances along the lines from it.
_add(Preset(
    "thesis-5.3.1-sim", "5.3.1",
    "the 16x18 m garden of thesis-5.3-garden: grid exploration (~1780 frames), a 1090-frame test walk, and 10 "
    "straight lines >= 8 m running through the area (whole chords, ~800 points every 0.2 m, joined by "
    "turn-drive-turn transits) for unsupervised metric learning, 600x60 RGB panoramas",
    _garden((16.0, 18.0), 30, markers=(136, 144)),
    lambda: PanoramicCamera(600, 60),
    lambda rng: [RunSpec("train", lambda w, r: T.grid(w.area, spacing=1.6, step=0.26)),
                 RunSpec("test", lambda w, r: T.random_walk(w.area, 1090, rng=r, world=w)),
                 RunSpec("lines", lambda w, r: T.line_segments(w.area, 10, 8.0, 0.2, rng=r, world=w, through=True))],
))


# Thesis 5.4: the 16x18 m garden with ArUco markers 136 and 144, seen by an
# omnidirectional camera whose markers the detector can read: 1000x1000 px,
# an equiangular mirror (elevation linear in radius) over -30..25 deg and
# 2 m marker boards (the 500 px spherical-mirror camera of 6.2.1 finds the
# 0.8 m boards in a few per cent of the frames; docs/landmarks.md).
LANDMARK_MARKERS = (136, 144)
LANDMARK_MARKER_SIZE = 2.0
LANDMARK_ELEVATION = (-30.0, 25.0)
# thesis 5.4.1: marker 136 unseen where x < 0 and y < 0, marker 144 where x > 0 and y > 0 (25 % of the area each)
LANDMARK_OCCLUSIONS = ({"marker_id": 136, "x_range": (None, 0.0), "y_range": (None, 0.0)},
                       {"marker_id": 144, "x_range": (0.0, None), "y_range": (0.0, None)})


def _landmark_runs(rng: np.random.Generator) -> list[RunSpec]:
    return [RunSpec("train", lambda w, r: T.grid(w.area, spacing=1.6, step=0.26)),
            RunSpec("test", lambda w, r: T.random_walk(w.area, 1190, rng=r, world=w))]


_add(Preset(
    "thesis-5.4-landmarks", "5.4",
    "the 16x18 m garden with 2 m ArUco marker boards 136 and 144: grid exploration (~1780 frames), a 1190-frame "
    "test walk, 1000x1000 omnidirectional images (equiangular mirror, elevation -30..25 deg)",
    _garden((16.0, 18.0), 30, markers=LANDMARK_MARKERS, marker_size=LANDMARK_MARKER_SIZE),
    lambda: OmniCamera(1000, LANDMARK_ELEVATION, mirror="equiangular"),
    _landmark_runs,
))


_add(Preset(
    "thesis-5.4-occlusion", "5.4",
    "as thesis-5.4-landmarks, but marker 136 is covered where x < 0 and y < 0 and marker 144 where x > 0 and "
    "y > 0 (25 % of the area each)",
    _garden((16.0, 18.0), 30, markers=LANDMARK_MARKERS, marker_size=LANDMARK_MARKER_SIZE,
            occlusions=LANDMARK_OCCLUSIONS),
    lambda: OmniCamera(1000, LANDMARK_ELEVATION, mirror="equiangular"),
    _landmark_runs,
))


_add(Preset(
    "thesis-6.2.1-static", "6.2.1",
    "the 16x18 m garden seen by a 500x500 omnidirectional camera (unwarp to 600x55): grid exploration "
    "(~1780 frames), 1090-frame test walk",
    _garden((16.0, 18.0), 30, markers=(136, 144)),
    lambda: OmniCamera(500),
    _garden_runs(lines=False),
))


def _light_621(name: str, description: str, condition: str, light: LightFn) -> Preset:
    """A 6.2.1 scene whose training run is driven under ``light`` (the
    condition ``condition``), its test run lit normally."""
    return Preset(name, "6.2.1", description, _garden((16.0, 18.0), 30, markers=(136, 144)),
                  lambda: OmniCamera(500),
                  lambda rng: [RunSpec("train", lambda w, r: T.grid(w.area, spacing=1.6, step=0.26),
                                       {condition: light}),
                               RunSpec("test", lambda w, r: T.random_walk(w.area, 1090, rng=r, world=w))])


_add(_light_621(
    "thesis-6.2.1-light",
    "as thesis-6.2.1-static, but the direct sunlight rises from 0.1 to 2.0 of its normal strength through the "
    "training run while the sky light stays, like the thesis's lamp turned up in a scene whose sky does not change "
    "(condition 'sun-ramp'); the test run is lit normally",
    "sun-ramp", _sun_ramp(0.1, 2.0)))


_add(_light_621(
    "thesis-6.2.1-gain",
    "as thesis-6.2.1-static, but the light intensity of the whole scene, sky included, rises from 0.4 to 1.4 "
    "through the training run (condition 'light-ramp': a global gain, which per-image normalisation undoes); "
    "the test run is lit normally",
    "light-ramp", _ramp(0.4, 1.4)))


_add(Preset(
    "thesis-6.2.1-dynamic", "6.2.1",
    "as thesis-6.2.1-static, plus a textured cylinder circling the area once during the training run",
    _garden((16.0, 18.0), 30, markers=(136, 144)),
    lambda: OmniCamera(500),
    _garden_runs(lines=False),
    dynamic=True,
))


#: garden-changes: the garden after run A (run B and the test walk see it): 4 objects moved around the garden,
#: 3 removed, 5 new ones beyond the area's border (sim.changes)
GARDEN_CHANGES = GardenChanges("after", move=4, remove=3, add=("car", "trailer", "shed", "furniture", "parasol"))


_add(Preset(
    "garden-changes", "-",
    "the 16x18 m garden of thesis-6.2.1-static (same seed, same world) whose objects change between runs: run A, "
    "the grid exploration with crossings (~1780 frames); then 4 garden objects moved around the garden, 3 removed, "
    "a car, a trailer, a shed, garden furniture and a parasol added beyond the area's border (garden 'after', "
    "world-after.json); run B, a second exploration in the changed garden (crossing grid, 2 m lanes, ~1040 frames) "
    "and the 1090-frame test walk there; 350x40 RGB panoramas",
    _garden((16.0, 18.0), 30, markers=(136, 144)),
    lambda: PanoramicCamera(350, 40),
    lambda rng: [RunSpec("A", lambda w, r: T.grid(w.area, spacing=1.6, step=0.26)),
                 RunSpec("B", lambda w, r: S.crossing(w.area, 2.0, 0.26), changes=GARDEN_CHANGES),
                 RunSpec("test", lambda w, r: T.random_walk(w.area, 1090, rng=r, world=w), changes=GARDEN_CHANGES)],
))


_add(Preset(
    "thesis-6.2.2-conditions", "6.2.2",
    "15x15 m garden, a border-wire loop of 279 frames driven under 10 random lighting conditions "
    "(intensity, sun direction, red tint), each drive off the loop by its own smooth <= 5 cm and <= 2 deg; "
    "600x60 RGB panoramas",
    _garden((15.0, 15.0), 30),
    lambda: PanoramicCamera(600, 60),
    lambda rng: [RunSpec("loop", lambda w, r: T.border_loop(w.area, 279, rng=r), _random_conditions(rng, 10),
                         jitter=LOOP_JITTER)],
))


_add(Preset(
    "thesis-6.2.2-seasons", "6.2.2",
    "the 15x15 m garden and 279-frame border-wire loop of thesis-6.2.2-conditions, driven 10 times spread over a "
    "year from spring (c0-spring .. c9-winter: 3 spring, 2 summer, 3 autumn, 2 winter): seasonal lawn, foliage "
    "and sky colours, thinning crowns, the sun as high as in the season, random light as in "
    "thesis-6.2.2-conditions; each drive off the loop by its own smooth <= 5 cm and <= 2 deg; "
    "600x60 RGB panoramas",
    _garden((15.0, 15.0), 30),
    lambda: PanoramicCamera(600, 60),
    lambda rng: [RunSpec("loop", lambda w, r: T.border_loop(w.area, 279, rng=r), _year_of_conditions(rng, 10),
                         jitter=LOOP_JITTER)],
))


def _weather(rng: np.random.Generator, season: Season, fraction: float | None = None) -> Lighting:
    """One day's light in ``season``: intensity 0.75..1.25, a random sun
    azimuth, the sun elevation drawn in the season's range."""
    lo, hi = season.sun_elevation_deg
    return Lighting(intensity=float(rng.uniform(0.75, 1.25)), sun_azimuth_deg=float(rng.uniform(0, 360)),
                    sun_elevation_deg=float(rng.uniform(lo, hi)), season=season)


def _year_lapse(rng: np.random.Generator, n: int = 512) -> LightFn:
    """A time-lapse over a year from the start of spring: at progress ``s``
    the season of :func:`season_of_year` (``s``) under that day's weather
    (:func:`_weather`; ``n`` days drawn once, the nearest one is used)."""
    days = [_weather(rng, season_of_year(i / n), i / n) for i in range(n)]
    return lambda s: days[min(int(round(float(s) * (n - 1))), n - 1)]


#: thesis 6.1: the camera pose of the year time-lapse in an area centred at the origin (x, y m, heading rad)
LAPSE_POSE = (0.0, -2.0, np.pi / 2)


#: thesis 6.1: the texture seed of each named season in thesis-6.1-seasons' route (Season.texture_seed): the
#: leaves and the grass have a different fine pattern in every season; other presets keep the plain seasons
SEASONS_61_TEXTURE_SEEDS = {"spring": 1, "summer": 2, "autumn": 3, "winter": 4}


def _seasons_61(rng: np.random.Generator) -> list[RunSpec]:
    seasons = {name: _weather(rng, replace(s, texture_seed=SEASONS_61_TEXTURE_SEEDS[name]))
               for name, s in SEASONS.items()}
    lapse = _year_lapse(rng)
    return [RunSpec("route", lambda w, r: T.border_loop(w.area, 160, rng=r), seasons),
            RunSpec("year", lambda w, r: T.Trajectory(np.tile(LAPSE_POSE, (101, 1)), np.arange(101) * 86400.0 * 3.6),
                    {"year": lapse})]


#: thesis 6.1, "some objects that come and go": what stands on the lawn of thesis-6.1-seasons in which
#: season (sim.transient; x, y m in the 15x15 m area, clear of the loop 1 m inside the border and of the
#: year's camera at LAPSE_POSE). The tarp covers the furniture's place in autumn and winter.
SEASONS_61_TRANSIENT = (
    {"kind": "furniture", "seasons": ["spring", "summer"], "x": 3.0, "y": 3.0},
    {"kind": "parasol", "seasons": ["summer"], "x": 3.0, "y": 3.0},
    {"kind": "tarp", "seasons": ["autumn", "winter"], "x": 3.0, "y": 3.0},
    {"kind": "paddling_pool", "seasons": ["summer"], "x": -3.0, "y": 2.5},
    {"kind": "toys", "seasons": ["spring", "summer"], "x": -1.0, "y": 4.3},
    {"kind": "wheelbarrow", "seasons": ["spring"], "x": -4.0, "y": -3.5},
    {"kind": "leaf_pile", "seasons": ["autumn"], "x": -3.5, "y": -0.8},
    {"kind": "leaf_pile", "seasons": ["autumn"], "x": 2.8, "y": -4.2},
    {"kind": "snowman", "seasons": ["winter"], "x": 1.5, "y": 1.0},
    {"kind": "snow_patch", "seasons": ["winter"], "x": -1.8, "y": -4.2},
    {"kind": "snow_patch", "seasons": ["winter"], "x": 4.3, "y": -0.5},
)


_add(Preset(
    "thesis-6.1-seasons", "6.1",
    "15x15 m garden for local visual features over the seasons: a 160-frame border-wire loop ('route') driven "
    "exactly once in each season (conditions spring, summer, autumn, winter: lawn, foliage and sky colours, "
    "thinning crowns, another fine pattern of leaves and grass, the season's sun height and shadows, a random "
    "day's light, and objects on the lawn that "
    "come and go: garden furniture in spring and summer, a parasol and a paddling pool in summer, toys, a "
    "wheelbarrow in spring, leaf piles in autumn, a tarp in autumn and winter, a snowman and snow patches in "
    "winter), and a fixed camera recording 101 frames over one year from the start of spring ('year', "
    "condition 'year': the season blends continuously, the light changes from frame to frame, the objects "
    "change with the quarter); 1200x120 RGB panoramas",
    _garden((15.0, 15.0), 30, transient=SEASONS_61_TRANSIENT),
    lambda: PanoramicCamera(1200, 120),
    _seasons_61,
))


_add(Preset(
    "thesis-7.1-open", "7.1.2",
    "18x22 m open field on a uniformly coloured lawn (the thesis's textured ground plane), two cameras on the "
    "robot's left and right (0.7 m apart), 5000 frames along random straight lines at 0.2 m per step, 600x60 RGB "
    "panoramas per camera",
    _garden((18.0, 22.0), 36, lawn="uniform"),
    lambda: PanoramicCamera(600, 60),
    lambda rng: [RunSpec("train", lambda w, r: T.random_lines(w.area, 5000, 0.2, margin=0.35, world=w, rng=r))],
    robot=lambda: Robot.two_cameras(0.7),
))


_add(Preset(
    "thesis-7.1-obstacle", "7.1.2",
    "as thesis-7.1-open with a v-shaped wall in the area; the random lines bounce off it",
    _garden((18.0, 22.0), 36, obstacles=("v-wall",), lawn="uniform"),
    lambda: PanoramicCamera(600, 60),
    lambda rng: [RunSpec("train", lambda w, r: T.random_lines(w.area, 5000, 0.2, margin=0.35, world=w, rng=r))],
    robot=lambda: Robot.two_cameras(0.7),
))


_add(Preset(
    "thesis-7.2.2-halfplane", "7.2.2",
    "18x22 m field, random lines (5000 frames) moving 3x farther per step in the right half (x > 0) than in the "
    "left; column speed_factor; 600x60 panoramas",
    _garden((18.0, 22.0), 36),
    lambda: PanoramicCamera(600, 60),
    lambda rng: [RunSpec("train", lambda w, r: T.random_lines(
        w.area, 5000, 0.2, margin=0.35, world=w, rng=r, speed=T.VelocityRegions.half_plane(0.0, "left", 3.0)))],
))


_add(Preset(
    "thesis-7.2.2-disc", "7.2.2",
    "18x22 m field, random lines (5000 frames), 3x slower inside a central disc of radius 5 m; column "
    "speed_factor; 600x60 panoramas",
    _garden((18.0, 22.0), 36),
    lambda: PanoramicCamera(600, 60),
    lambda rng: [RunSpec("train", lambda w, r: T.random_lines(
        w.area, 5000, 0.2, margin=0.35, world=w, rng=r, speed=T.VelocityRegions.disc(5.0, factor=3.0)))],
))


GARDEN_INNER = {"tree": 3, "bush": 4, "pole": 4, "shed": 1}


GARDEN_PATCHES = {"patio": 1, "path": 1, "bed": 3}


def _realistic_runs(rng: np.random.Generator) -> list[RunSpec]:
    # grid-like exploration with crossings and large-radius turns, led around the objects in the area;
    # a random test walk that keeps clear of them
    return [RunSpec("train", lambda w, r: T.detour(T.grid(w.area, spacing=1.0, step=0.25, turn="arc", margin=0.5), w)),
            RunSpec("test", lambda w, r: T.random_walk(w.area, 400, 0.2, margin=0.45, rng=r, world=w))]


_add(Preset(
    "realistic-garden", "- (docs/gardens.md)",
    "12x12 m lawn with objects INSIDE the area (3 small trees, 4 bushes, 4 poles, a shed against the border) and "
    "ground patches (a patio, a gravel path, 3 flower beds), 30 garden objects around; a grid exploration with "
    "crossings and large-radius turns led around the objects (~1200 frames), a 400-frame random test walk; "
    "350x40 RGB panoramas",
    _garden((12.0, 12.0), 30, depth=10.0, inner=GARDEN_INNER, patches=GARDEN_PATCHES),
    lambda: PanoramicCamera(350, 40),
    _realistic_runs,
))


_add(Preset(
    "realistic-garden-control", "- (docs/gardens.md)",
    "the thesis-like control of realistic-garden: the same 12x12 m garden and outer objects (same seed), but "
    "nothing inside the area and a plain lawn; the same grid exploration (~1130 frames) and a 400-frame random "
    "test walk; 350x40 RGB panoramas",
    _garden((12.0, 12.0), 30, depth=10.0),
    lambda: PanoramicCamera(350, 40),
    _realistic_runs,
))


# The gardens suite (docs/gardens.md, `sfanav experiment gardens-suite`): clearly different
# layouts, each with two training runs (a serpentine grid along x; the same with crossing lanes
# along y) and two test runs (a grid of points between and beyond the training lanes, at random
# headings; a random walk). 350x40 RGB panoramas.
SUITE_DENSE_TREES = {"tree": 0.45, "conifer": 0.3, "bush": 0.2, "rock": 0.05}


def _suite_test_grid(w: World, r: np.random.Generator, spacing: float) -> T.Trajectory:
    """Points on a grid offset from the training lanes (between them and
    beyond the outermost ones), clear of obstacles, at random headings."""
    ax, ay = w.area
    g = T.grid_points(w.area, max(2, int(round(ax / spacing)) + 1), max(2, int(round(ay / spacing)) + 1),
                      margin=0.4)
    keep = w.free(g.poses[:, 0], g.poses[:, 1], 0.3)
    pts = g.poses[keep].copy()
    pts[:, 2] = r.uniform(-np.pi, np.pi, len(pts))
    return T.Trajectory(pts, np.arange(len(pts), dtype=float))


def _suite_runs(spacing: float = 1.0, light: Lighting | None = None,
                walk: int = 300) -> Callable[[np.random.Generator], list[RunSpec]]:
    cond: dict[str, Lighting | LightFn] = {"default": light or Lighting()}

    def runs(rng: np.random.Generator) -> list[RunSpec]:
        def lanes(crossings: bool) -> Callable[[World, np.random.Generator], T.Trajectory]:
            return lambda w, r: T.detour(T.grid(w.area, spacing=spacing, step=0.25, turn="arc", margin=0.5,
                                                crossings=crossings), w)

        return [RunSpec("train-grid", lanes(False), cond), RunSpec("train-cross", lanes(True), cond),
                RunSpec("test-grid", lambda w, r: _suite_test_grid(w, r, spacing), cond),
                RunSpec("test-walk", lambda w, r: T.random_walk(w.area, walk, 0.2, margin=0.45, rng=r, world=w),
                        cond)]

    return runs


SUITE_GARDENS: dict[str, tuple[str, dict[str, Any], Callable[[np.random.Generator], list[RunSpec]]]] = {
    "inner": ("10x10 m lawn with objects inside (trees, bushes, poles, a shed) and ground patches",
              _garden((10.0, 10.0), 30, depth=10.0, inner=GARDEN_INNER, patches=GARDEN_PATCHES), _suite_runs()),
    "inner-uniform": ("the inner layout on a uniform lawn, no ground patches",
                      _garden((10.0, 10.0), 30, depth=10.0, inner=GARDEN_INNER, lawn="uniform"), _suite_runs()),
    "control": ("thesis-like control: nothing inside the 10x10 m area, patchy lawn",
                _garden((10.0, 10.0), 30, depth=10.0), _suite_runs()),
    "control-uniform": ("thesis-like control on a uniform lawn (the thesis's Blender garden)",
                        _garden((10.0, 10.0), 30, depth=10.0, lawn="uniform"), _suite_runs()),
    "dense-trees": ("60 trees, conifers and bushes close around the area (0.2 m margin, 4 m deep)",
                    _garden((10.0, 10.0), 60, margin=0.2, depth=4.0, weights=SUITE_DENSE_TREES), _suite_runs()),
    "open-lawn": ("an open lawn: 8 objects, 6-26 m beyond the area, uniform lawn",
                  _garden((10.0, 10.0), 8, margin=6.0, depth=20.0, lawn="uniform"), _suite_runs()),
    "textured-ground": ("strong ground texture: 2 patios, 3 paths, 8 flower beds on a patchy lawn",
                        _garden((10.0, 10.0), 30, depth=10.0, patches={"patio": 2, "path": 3, "bed": 8}),
                        _suite_runs()),
    "dusk": ("the inner layout at dusk: overcast sky, dim orange light from a low sun",
             _garden((10.0, 10.0), 30, depth=10.0, inner=GARDEN_INNER, patches=GARDEN_PATCHES, cloud_cover=0.95),
             _suite_runs(light=Lighting(intensity=0.55, tint=(1.0, 0.82, 0.66), sun_elevation_deg=8.0))),
    "low-sun": ("the control layout under a clear sky and a low sun: long shadows",
                _garden((10.0, 10.0), 30, depth=10.0, cloud_cover=0.05),
                _suite_runs(light=Lighting(intensity=1.2, sun_azimuth_deg=30.0, sun_elevation_deg=12.0))),
    "large-inner": ("a 16x16 m lawn with objects inside, lanes 1.5 m apart",
                    _garden((16.0, 16.0), 40, depth=12.0, inner={"tree": 5, "bush": 6, "pole": 5, "shed": 1},
                            patches=GARDEN_PATCHES), _suite_runs(spacing=1.5, walk=400)),
    "small-dense": ("a 6x6 m yard with bushes and poles inside, 40 objects close around",
                    _garden((6.0, 6.0), 40, margin=0.4, depth=5.0, inner={"bush": 3, "pole": 2},
                            patches={"bed": 2}), _suite_runs(spacing=0.75, walk=200)),
    "inner-sparse": ("a few objects inside (2 trees, 2 poles), 20 objects around, patchy lawn",
                     _garden((10.0, 10.0), 20, depth=14.0, inner={"tree": 2, "pole": 2}), _suite_runs()),
}

for _name, (_desc, _world, _runs) in SUITE_GARDENS.items():
    _add(Preset(f"suite-{_name}", "- (docs/gardens.md, gardens suite)", f"{_desc}; grid and crossing training "
                "runs, a test grid between and beyond the lanes and a test walk; 350x40 RGB panoramas",
                _world, lambda: PanoramicCamera(350, 40), _runs))


# A 30x30 m garden surveyed as robot mowers drive it, with a mower's odometry and a gyro.
#: the mower's wheel odometry: 2 % distance noise, 0.5 deg heading noise per frame (plus 1 % of
#: the frame's turn), 0.1 deg/m systematic heading drift, no wheel slip
MOWER_ODOMETRY = OdometryNoise.mower(distance_fraction=0.02, heading_deg=0.5, drift_deg_per_m=0.1,
                                     turn_fraction=0.01)
#: 24 lanes across the 29 m inside the 0.5 m margin of a 30 m garden
MOWER_LANE_SPACING = 29.0 / 23.0
#: frames along the path (m)
MOWER_FRAME_SPACING = 1.2


def _mower_runs(rng: np.random.Generator) -> list[RunSpec]:
    ls, sp = MOWER_LANE_SPACING, MOWER_FRAME_SPACING

    def pattern(name: str, lanes: float = ls, heading: str = "travel") -> RunSpec:
        label = name if heading == "travel" else f"{name}-random-heading"
        return RunSpec(label, lambda w, r: S.survey(name, w.area, lanes, sp, n_frames=600, heading=heading,
                                                    world=w if name == "random" else None, rng=r))

    def test_grid(w: World, r: np.random.Generator) -> T.Trajectory:
        g = T.grid_points(w.area, 14, 14, margin=2.0)
        P = g.poses.copy()
        P[:, 2] = r.uniform(-np.pi, np.pi, len(P))
        return T.Trajectory(P, g.times)

    # the crossing's lanes are twice as far apart (12 + 12 lanes), so that every run is ~600 frames
    return [pattern("serpentine"), pattern("perimeter-serpentine"), pattern("spiral"), pattern("crossing", 2 * ls),
            pattern("random"), pattern("serpentine", heading="random"),
            RunSpec("test-walk", lambda w, r: T.random_walk(w.area, 300, 0.5, margin=0.5, rng=r, world=w)),
            RunSpec("test-grid", test_grid)]


_add(Preset(
    "mower-survey", "- (docs/simulator.md)",
    "30x30 m garden (40 objects) surveyed as robot mowers drive it, the robot facing where it drives, frames "
    "1.2 m apart along the path: serpentine (24 lanes, 594 frames), perimeter lap then serpentine, inward "
    "spiral, crossing grid (12 + 12 lanes), random bounce (600), the serpentine with panoramas at random "
    "headings; test walk (300, 0.5 m) and 14x14 test grid at random headings; mower odometry (2 % distance, "
    "0.5 deg per frame, 0.1 deg/m drift) and a gyro column gyro_heading; 350x40 RGB panoramas",
    _garden((30.0, 30.0), 40, depth=12.0),
    lambda: PanoramicCamera(350, 40),
    _mower_runs,
    robot=lambda: Robot(noise=MOWER_ODOMETRY, gyro=GyroNoise()),
))


def describe() -> str:
    """One line per preset: name, thesis section, description."""
    width = max(len(n) for n in PRESETS)
    return "\n".join(f"{n:<{width}}  [{p.section}] {p.description}" for n, p in PRESETS.items())


def get(name: str) -> Preset:
    if name not in PRESETS:
        raise ValueError(f"unknown preset {name!r}; available: {', '.join(PRESETS)}")
    return PRESETS[name]
