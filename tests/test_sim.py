"""The garden simulator: worlds, rendering geometry, robot, odometry, trajectories."""

import json

import numpy as np
import pytest

from sfanav import sim
from sfanav.sim import (
    Lighting,
    OdometryNoise,
    OmniCamera,
    PanoramicCamera,
    Primitive,
    Renderer,
    Robot,
    Texture,
    World,
    WorldObject,
    simulate_odometry,
    trajectories as T,
)


def posts(*specs, area=(4.0, 4.0)):
    """A world with flat-coloured vertical cylinders: specs of (x, y, radius, (r, g, b))."""
    tex, objs = {}, []
    for i, (x, y, r, color) in enumerate(specs):
        tex[f"t{i}"] = Texture("noise", color, 0.0, 0, (1.0, 1.0))
        objs.append(WorldObject("post", x, y, r, [Primitive("cylinder", x, y, 0.0, 3.0, f"t{i}", radius=r)]))
    return World(area, 3.0, 20.0, objs, tex)


@pytest.fixture(scope="module")
def garden():
    return World.generate(seed=5, area=(6.0, 6.0), n_objects=14, depth=6.0, markers=(136,),
                          obstacles=({"kind": "box", "x": 1.5, "y": 1.5, "length": 0.8, "width": 0.5},))


@pytest.fixture(scope="module")
def renderer(garden):
    return Renderer(garden)


@pytest.fixture(scope="module")
def empty_renderer():
    return Renderer(posts())


# ------------------------------------------------------------------ worlds


def test_world_is_deterministic_by_seed(garden):
    again = World.generate(seed=5, area=(6.0, 6.0), n_objects=14, depth=6.0, markers=(136,),
                           obstacles=({"kind": "box", "x": 1.5, "y": 1.5, "length": 0.8, "width": 0.5},))
    assert json.dumps(again.to_dict()) == json.dumps(garden.to_dict())
    other = World.generate(seed=6, area=(6.0, 6.0), n_objects=14, depth=6.0)
    assert [o.x for o in other.objects] != [o.x for o in garden.objects[: len(other.objects)]]


def test_objects_stand_beyond_the_free_area_without_overlap(garden):
    objs = [o for o in garden.objects if not o.obstacle]
    assert len(objs) == 15 and {o.kind for o in objs} >= {"marker"}
    for o in objs:
        assert np.hypot(o.x, o.y) - o.radius >= garden.free_radius - 1e-9
        assert np.hypot(o.x, o.y) + o.radius <= garden.outer_radius + 1e-9
    for i, a in enumerate(objs):
        for b in objs[i + 1 :]:
            assert np.hypot(a.x - b.x, a.y - b.y) >= a.radius + b.radius
    assert garden.free_radius >= 0.5 * np.hypot(*garden.area)
    assert [o.kind for o in garden.obstacles] == ["box"]
    assert garden.collides(1.5, 1.5) and not garden.collides(-1.5, -1.5)
    assert 136 in garden.markers


def test_world_json_round_trip(garden, renderer, tmp_path):
    path = tmp_path / "w.json"
    garden.save(path)
    loaded = World.load(path)
    assert loaded.to_dict() == garden.to_dict()
    cam = PanoramicCamera(120, 16)
    np.testing.assert_array_equal(Renderer(loaded).render(cam, (0.3, -0.4, 1.0)),
                                  renderer.render(cam, (0.3, -0.4, 1.0)))


def test_world_errors(tmp_path):
    with pytest.raises(ValueError, match="area"):
        World.generate(area=(0, 5))
    with pytest.raises(ValueError, match="unknown object types.*'ufo'"):
        World.generate(weights={"ufo": 1.0})
    with pytest.raises(ValueError, match="unknown obstacle kind 'pond'"):
        World.generate(n_objects=0, obstacles=({"kind": "pond"},))
    with pytest.raises(ValueError, match="v-wall: unknown keys"):
        World.generate(n_objects=0, obstacles=({"kind": "v-wall", "length": 3},))
    with pytest.raises(ValueError, match="unknown texture kind"):
        Texture("velvet")
    with pytest.raises(ValueError, match="marker id 5000 is outside"):
        Renderer(World.generate(n_objects=0, markers=(5000,)))
    with pytest.raises(FileNotFoundError, match="no world file"):
        World.load(tmp_path / "missing.json")
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(ValueError, match="not valid JSON"):
        World.load(tmp_path / "bad.json")
    (tmp_path / "other.json").write_text('{"format": "something"}')
    with pytest.raises(ValueError, match="not an sfanav world"):
        World.load(tmp_path / "other.json")
    with pytest.raises(ValueError, match="texture 'nope'"):
        World((4, 4), 3, 20, [WorldObject("post", 5, 0, 1, [Primitive("cylinder", 5, 0, 0, 1, "nope", radius=1)])], {})


# ------------------------------------------------------------------ geometry


@pytest.mark.parametrize("heading", [0.0, 0.7, -2.5, 3.1])
def test_known_object_appears_at_its_azimuth(empty_renderer, heading):
    x, y, r = 5.0, 3.0, 0.3
    world = posts((x, y, r, (1.0, 0.0, 0.0)))
    cam = PanoramicCamera(720, 40, (-20, 20))
    light = Lighting(shadows=False)
    img = Renderer(world).render(cam, (0.0, 0.0, heading), lighting=light).astype(int)
    bg = empty_renderer.render(cam, (0.0, 0.0, heading), lighting=light).astype(int)
    cols = np.nonzero(np.abs(img - bg).sum(axis=2)[20] > 30)[0]
    expected = cam.column_of_bearing(np.arctan2(y, x) - heading)
    if cols.max() - cols.min() > 360:  # straddles the seam
        cols = np.where(cols < 360, cols + 720, cols)
    centre = (cols.min() + cols.max()) / 2 % 720
    assert abs(centre - expected) <= 1.0
    width = 2 * np.arcsin(r / np.hypot(x, y)) * 720 / (2 * np.pi)  # angular size: parallax from true geometry
    assert abs(len(cols) - width) <= 1.5


def test_parallax_moves_near_objects_more_than_far_ones():
    world = posts((3.0, 2.0, 0.2, (1.0, 0.0, 0.0)), (12.0, 8.0, 0.6, (0.0, 0.0, 1.0)))  # same bearing
    cam = PanoramicCamera(720, 40, (-20, 20))
    ren = Renderer(world)

    def columns(img, channel):
        other = [c for c in range(3) if c != channel]
        return np.nonzero((img[20, :, channel] > 150) & (img[20, :, other].max(axis=0) < 60))[0]

    a = ren.render(cam, (0.0, 0.0, 0.0))
    assert len(columns(a, 0)) and not len(columns(a, 2))  # the near post hides the far one
    b = ren.render(cam, (0.0, -1.0, 0.0))  # one metre sideways
    for (x, y), ch in (((3.0, 2.0), 0), ((12.0, 8.0), 2)):
        expected = cam.column_of_bearing(np.arctan2(y + 1.0, x))
        assert abs(columns(b, ch).mean() - expected) <= 1.0
    near_shift = cam.column_of_bearing(np.arctan2(2.0, 3.0)) - columns(b, 0).mean()
    far_shift = cam.column_of_bearing(np.arctan2(8.0, 12.0)) - columns(b, 2).mean()
    assert abs(near_shift) > 3 * abs(far_shift) > 0


def test_occlusion_nearest_hit_wins():
    world = posts((3.0, 0.0, 0.3, (1.0, 0.0, 0.0)), (8.0, 0.0, 1.0, (0.0, 0.0, 1.0)))
    cam = PanoramicCamera(360, 30, (-20, 20))
    img = Renderer(world).render(cam, (0.0, 0.0, 0.0))
    mid = int(round(cam.column_of_bearing(0.0)))
    assert img[15, mid, 0] > 150 and img[15, mid, 2] < 60  # red post in front
    side = int(round(cam.column_of_bearing(np.radians(6.5))))  # red spans +-5.7 deg, blue +-7.2 deg
    assert img[15, side, 2] > 150  # blue post visible beside it


@pytest.mark.parametrize("k", [1, 37, -150])
def test_heading_change_is_a_circular_shift(renderer, k):
    cam = PanoramicCamera(300, 30)
    a = renderer.render(cam, (0.4, -0.3, 0.9))
    b = renderer.render(cam, (0.4, -0.3, 0.9 + 2 * np.pi * k / 300))
    same = (np.roll(a, k, axis=1) == b).all(axis=2).mean()
    assert same >= 0.995


def test_views_carry_position(renderer):
    cam = PanoramicCamera(200, 20, rgb=False)
    a = renderer.render(cam, (0.0, 0.0, 0.0)).astype(float)
    b = renderer.render(cam, (0.05, 0.0, 0.0)).astype(float)
    c = renderer.render(cam, (2.0, 0.0, 0.0)).astype(float)
    assert a.shape == (20, 200) and a.dtype == np.float64
    assert np.abs(a - b).mean() < np.abs(a - c).mean()
    assert np.abs(a - c).mean() > 5


def test_rendering_is_deterministic(garden, renderer):
    cam = PanoramicCamera(100, 12)
    np.testing.assert_array_equal(renderer.render(cam, (1, 1, 1)), Renderer(garden).render(cam, (1, 1, 1)))


def test_omni_image_unwarps_to_the_panorama(renderer):
    omni = OmniCamera(320, elevation_deg=(-50, 15))
    img = renderer.render(omni, (0.2, 0.1, 0.5))
    assert img.shape == (320, 320, 3) and img.dtype == np.uint8
    c = 159.5
    assert (img[0, 0] == 0).all() and (img[160, 160] == 0).all()  # outside the mirror, blind centre
    assert img[int(c - omni.outer_radius * 0.9), 160].sum() > 0
    pano_cam = PanoramicCamera(400, 40, (-45, 10))
    unwarped = omni.unwarp(img, 400, 40, (-45, 10)).astype(float)
    pano = renderer.render(pano_cam, (0.2, 0.1, 0.5)).astype(float)
    corr = np.corrcoef(unwarped.ravel(), pano.ravel())[0, 1]
    assert corr > 0.9
    e = np.radians([-40.0, 0.0, 10.0])
    np.testing.assert_allclose(omni.elevation_of_radius(omni.radius_of_elevation(e)), e, atol=1e-12)
    eq = OmniCamera(100, (-60, 20), mirror="equiangular")
    np.testing.assert_allclose(eq.elevation_of_radius([eq.inner_radius, eq.outer_radius]), np.radians([-60, 20]))


def test_omni_forward_is_up():
    world = posts((6.0, 0.0, 0.6, (1.0, 0.0, 0.0)))
    omni = OmniCamera(200, (-50, 20))
    img = Renderer(world).render(omni, (0.0, 0.0, 0.0)).astype(int)
    red = (img[..., 0] > 150) & (img[..., 1] < 80)
    ys, xs = np.nonzero(red)
    assert len(ys) and ys.mean() < 100 and abs(xs.mean() - 99.5) < 3  # ahead = up, centred
    img2 = Renderer(world).render(omni, (0.0, 0.0, -np.pi / 2)).astype(int)  # object now on the left
    ys, xs = np.nonzero((img2[..., 0] > 150) & (img2[..., 1] < 80))
    assert xs.mean() < 100 and abs(ys.mean() - 99.5) < 3


def test_lighting_intensity_tint_and_sun(renderer):
    cam = PanoramicCamera(120, 16)
    dim = renderer.render(cam, (0, 0, 0), lighting=Lighting(intensity=0.5)).astype(float)
    bright = renderer.render(cam, (0, 0, 0), lighting=Lighting(intensity=1.0)).astype(float)
    assert 0.45 < dim.mean() / bright.mean() < 0.55
    red = renderer.render(cam, (0, 0, 0), lighting=Lighting(tint=(0.5, 1, 1))).astype(float)
    assert red[..., 0].mean() < 0.6 * bright[..., 0].mean() and abs(red[..., 1].mean() - bright[..., 1].mean()) < 1
    # a post lit from the east is brighter on its east side
    world = posts((0.0, 6.0, 1.0, (0.8, 0.8, 0.8)))
    ren = Renderer(world)
    cam = PanoramicCamera(720, 30, (-10, 10))
    img = ren.render(cam, (0.0, 0.0, np.pi / 2), lighting=Lighting(sun_azimuth_deg=0.0)).astype(float)
    half = np.arcsin(1.0 / 6.0)  # the post's angular half-width
    left = img[15, int(cam.column_of_bearing(half - 0.03)), 0]  # robot faces +y: west limb on the left
    right = img[15, int(cam.column_of_bearing(-half + 0.03)), 0]
    assert right > left + 40
    with pytest.raises(ValueError, match="intensity"):
        Lighting(intensity=-1)
    with pytest.raises(ValueError, match="sun_elevation_deg"):
        Lighting(sun_elevation_deg=0)



def test_sun_intensity_lights_the_sunlit_parts_only(renderer):
    """The direct light scales, the sky does not: no gain undoes it (thesis 6.2.1's lamp)."""
    cam = PanoramicCamera(120, 16)
    weak, normal, strong = (renderer.render(cam, (0.5, 0.5, 0), lighting=Lighting(sun_intensity=s)).astype(float)
                            for s in (0.1, 1.0, 2.0))
    above, below = cam.elevations > 0, cam.elevations < 0
    assert above.any() and below.any()
    assert (weak <= strong).all()
    # the sky keeps its light (objects in front of it do not)
    assert (weak[above] == strong[above]).all(axis=-1).mean() > 0.5
    assert weak[below].mean() < normal[below].mean() < strong[below].mean()
    assert np.array_equal(normal, renderer.render(cam, (0.5, 0.5, 0), lighting=Lighting()))

    def normalised(img):
        g = img.mean(axis=-1)
        return (g - g.mean()) / g.std()

    # per-image normalisation undoes a change of intensity (up to rounding), not one of the sun's strength
    dim = renderer.render(cam, (0.5, 0.5, 0), lighting=Lighting(intensity=0.6)).astype(float)
    gain_change = np.abs(normalised(dim) - normalised(normal)).mean()
    sun_change = np.abs(normalised(weak) - normalised(strong)).mean()
    assert sun_change > 5 * gain_change
    for bad in (-0.5, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="sun_intensity"):
            Lighting(sun_intensity=bad)
    assert "sun_intensity" not in Lighting().to_dict()  # datasets of the default light are written as before
    assert Lighting.from_dict(Lighting(sun_intensity=0.3).to_dict()) == Lighting(sun_intensity=0.3)

def test_ground_shadows(garden):
    ren = Renderer(garden)
    sm = ren._shadow_map(Lighting(sun_elevation_deg=30))
    assert 0 < (sm > 0.5).mean() < 0.2
    assert ren._shadow_map(Lighting(shadows=False)).max() == 0



def test_uniform_lawn_has_one_colour_and_the_same_objects():
    kw = dict(seed=3, area=(6.0, 6.0), n_objects=8, depth=6.0)
    patchy, uniform = World.generate(**kw), World.generate(**kw, lawn="uniform")
    assert uniform.to_dict()["objects"] == patchy.to_dict()["objects"]
    # the colour map under the area: several metres-scale shades on the patchy lawn, one on the uniform
    for world, spread in ((patchy, (0.02, None)), (uniform, (None, 1e-4))):
        ren = Renderer(world)
        n, res, o = ren._gmap_n, ren._gmap_res, ren._gmap_origin
        i = ((np.linspace(-3, 3, 31) - o) / res).astype(int)
        col = ren._gmap[np.ix_(i, i)].reshape(-1, 3)
        sd = float(col.std(axis=0).max())
        lo, hi = spread
        assert (lo is None or sd > lo) and (hi is None or sd < hi), (world.ground, sd)
    assert World.from_dict(uniform.to_dict()).ground == uniform.ground
    with pytest.raises(ValueError, match="lawn must be one of 'patchy', 'uniform', got 'striped'"):
        World.generate(n_objects=0, lawn="striped")

def test_dynamic_object_moves_and_circles_back():
    world = posts((0.0, 15.0, 0.1, (0.2, 0.2, 0.2)))
    world.add_dynamic({"orbit": 5.0, "period": 40.0})
    ren = Renderer(world)
    cam = PanoramicCamera(180, 20)
    a = ren.render(cam, (0, 0, 0), time=0.0)
    b = ren.render(cam, (0, 0, 0), time=10.0)
    c = ren.render(cam, (0, 0, 0), time=40.0)
    assert np.abs(a.astype(int) - b).mean() > 1
    np.testing.assert_array_equal(a, c)
    # at t = 0 it stands at bearing 0 (east), a quarter period later at bearing +90 deg
    diff0 = np.abs(a.astype(int) - b).sum(axis=2).max(axis=0)
    assert diff0[int(cam.column_of_bearing(0.0))] > 0 and diff0[int(cam.column_of_bearing(np.pi / 2))] > 0


def test_aruco_marker_is_detectable():
    cv2 = pytest.importorskip("cv2")
    world = World.generate(seed=1, area=(2.0, 2.0), n_objects=0, markers=(136,), marker_size=0.8)
    mx, my = world.markers[136]
    ren = Renderer(world)
    cam = PanoramicCamera(2400, 400, (-15, 25))
    img = ren.render(cam, (0.0, 0.0, float(np.arctan2(my, mx))), lighting=Lighting(shadows=False))
    gray = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
    det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_ARUCO_ORIGINAL))
    corners, ids, _ = det.detectMarkers(gray)
    assert ids is not None and 136 in ids.ravel()
    c = corners[list(ids.ravel()).index(136)][0].mean(axis=0)
    assert abs(c[0] - cam.column_of_bearing(0.0)) < 10  # straight ahead


def test_camera_errors(renderer):
    with pytest.raises(ValueError, match="width"):
        PanoramicCamera(0, 10)
    with pytest.raises(ValueError, match="elevation_deg"):
        PanoramicCamera(100, 10, (20, -20))
    with pytest.raises(ValueError, match="unknown mirror"):
        OmniCamera(100, mirror="conic")
    with pytest.raises(ValueError, match="pose"):
        renderer.render(PanoramicCamera(50, 5), (0, 0))
    with pytest.raises(ValueError, match="finite"):
        renderer.render(PanoramicCamera(50, 5), (0, np.nan, 0))
    with pytest.raises(TypeError, match="camera"):
        renderer.render("cam", (0, 0, 0))
    with pytest.raises(TypeError, match="World"):
        Renderer({"area": 1})
    with pytest.raises(ValueError, match="omni image must be 100 x 100"):
        OmniCamera(100).unwarp(np.zeros((50, 50, 3), np.uint8))


# ------------------------------------------------------------------ robot and odometry


def test_unicycle_step_is_exact():
    pose = np.array([1.0, -2.0, 0.3])
    v, w, dt = 0.5, 0.8, 2.0
    p = pose.copy()
    n = 20000
    for _ in range(n):  # fine Euler integration
        p = p + dt / n * np.array([v * np.cos(p[2]), v * np.sin(p[2]), w])
    np.testing.assert_allclose(sim.unicycle_step(pose, v, w, dt), p, atol=1e-4)
    np.testing.assert_allclose(sim.unicycle_step(pose, v, 0.0, dt), [1 + np.cos(0.3), -2 + np.sin(0.3), 0.3])


def test_perfect_odometry_reproduces_the_path():
    for tr in (T.grid((6, 6), spacing=1.5, turn="arc"), T.grid((6, 6), spacing=1.5),
               T.random_lines((6, 6), 300, rng=1), T.line_segments((8, 8), 3, 4.0, rng=2)):
        odo = simulate_odometry(tr.poses, OdometryNoise.none(), rng=0)
        np.testing.assert_allclose(odo[:, :2], tr.poses[:, :2], atol=1e-9)
        np.testing.assert_allclose(sim.wrap_angle(odo[:, 2] - tr.poses[:, 2]), 0, atol=1e-9)


def test_odometry_drift_statistics():
    noise = OdometryNoise(distance_sigma=0.02, scale_error=0.01, heading_sigma=0.01, turn_sigma=0.0,
                          heading_drift=0.004, slip_rate=0.0)
    L, n = 20.0, 100
    line = np.column_stack([np.linspace(0, L, n + 1), np.zeros(n + 1), np.zeros(n + 1)])
    rng = np.random.default_rng(0)
    runs = np.array([simulate_odometry(line, noise, rng) for _ in range(600)])
    heading_err = runs[:, -1, 2]
    assert abs(heading_err.mean() - noise.heading_drift * L) < 0.15 * noise.heading_sigma * np.sqrt(L) + 0.002
    assert abs(heading_err.std() / (noise.heading_sigma * np.sqrt(L)) - 1) < 0.1
    dist = np.hypot(runs[:, -1, 0], runs[:, -1, 1])
    assert abs(dist.mean() - L * (1 + noise.scale_error)) < 0.02
    assert abs(dist.std() / (noise.distance_sigma * np.sqrt(L)) - 1) < 0.12
    # dead reckoning drifts: the position error grows with distance travelled
    err = np.hypot(runs[:, :, 0] - line[:, 0], runs[:, :, 1] - line[:, 1]).mean(axis=0)
    assert err[25] < err[50] < err[100]
    # slips add distance: rate x length x mean extra distance
    slip = OdometryNoise(0, 0, 0, 0, 0, slip_rate=0.5, slip_distance=0.04, slip_heading_sigma=0)
    extra = np.array([simulate_odometry(line, slip, rng)[-1, 0] - L for _ in range(400)])
    assert abs(extra.mean() - 0.5 * L * 0.04) < 0.05


def test_default_odometry_drifts_like_fig_5_24():
    tr = T.grid((8, 8), spacing=1.0)
    err = [np.hypot(*(simulate_odometry(tr.poses, rng=s)[:, :2] - tr.poses[:, :2]).T).mean() for s in range(10)]
    assert 0.05 < np.median(err) < 2.0  # decimetres over a ~100 m run, not centimetres nor metres


def test_two_camera_mounts():
    robot = Robot.two_cameras(0.7)
    poses = np.array([[1.0, 2.0, np.pi / 2], [0.0, 0.0, 0.0]])
    cams = robot.camera_poses(poses)
    np.testing.assert_allclose(cams["left"][0], [1.0 - 0.35, 2.0, np.pi / 2], atol=1e-12)
    np.testing.assert_allclose(cams["right"][1], [0.0, -0.35, 0.0], atol=1e-12)
    with pytest.raises(ValueError, match="offset"):
        Robot(cameras={"c": (1,)})
    with pytest.raises(ValueError, match="at least one camera"):
        Robot(cameras={})
    with pytest.raises(ValueError, match="shape"):
        robot.camera_poses(np.zeros((3, 2)))
    with pytest.raises(ValueError, match="row 1"):
        simulate_odometry([[0, 0, 0], [np.nan, 0, 0]])
    with pytest.raises(ValueError, match="heading_sigma"):
        OdometryNoise(heading_sigma=-1)


def test_closed_loop_simulator(garden):
    s = sim.Simulator(garden, PanoramicCamera(60, 8), Robot.two_cameras(0.5), seed=3)
    obs = s.observe()
    assert set(obs) == {"left", "right"} and obs["left"].shape == (8, 60, 3)
    assert s.step(0.4, 0.0, 1.0)
    np.testing.assert_allclose(s.pose, [0.4, 0.0, 0.0])
    assert np.hypot(*(s.odometry_pose[:2] - s.pose[:2])) < 0.05
    s.reset((1.5, 0.8, np.pi / 2))
    assert not s.step(1.0, 0.0, 1.0)  # would hit the box obstacle
    np.testing.assert_allclose(s.pose, [1.5, 0.8, np.pi / 2])
    s.reset((1.5, 0.5, np.pi / 2))
    assert garden.free(1.5, 2.5, 0.25)
    assert not s.step(2.0, 0.0, 1.0)  # would end clear beyond the box, but passes through it
    s.reset((1.5, 0.5, -np.pi / 2))
    assert s.step(0.5, 0.0, 1.0)  # driving away is fine
    np.testing.assert_allclose(s.pose, [1.5, 0.0, -np.pi / 2], atol=1e-12)


# ------------------------------------------------------------------ trajectories


def test_grid_exploration_covers_the_area_with_crossings():
    for turn in ("spot", "arc"):
        tr = T.grid((8, 6), spacing=1.0, step=0.2, turn=turn)
        P = tr.poses
        assert (np.abs(P[:, 0]) <= 3.5 + 1e-9).all() and (np.abs(P[:, 1]) <= 2.5 + 1e-9).all()
        steps = np.hypot(*np.diff(P[:, :2], axis=0).T)
        assert steps.max() <= 0.2 + 1e-6 and np.all(np.diff(tr.times) > 0)
        horiz = np.isclose(np.abs(np.cos(P[:, 2])), 1, atol=1e-6)
        vert = np.isclose(np.abs(np.sin(P[:, 2])), 1, atol=1e-6)
        assert horiz.sum() > 150 and vert.sum() > 150  # lanes both ways: crossings
    spot = T.grid((8, 6), spacing=1.0, turn="spot")
    still = np.hypot(*np.diff(spot.poses[:, :2], axis=0).T) < 1e-9
    assert still.sum() > 20  # turns on the spot


def test_grid_points_serpentine():
    tr = T.grid_points((30, 30), 26, 24, margin=0.5)
    assert len(tr) == 624
    assert len(T.grid_points((30, 30), 14, 14)) == 196
    np.testing.assert_allclose(tr.poses[25, :2], [14.5, -14.5])
    np.testing.assert_allclose(tr.poses[26, 0], 14.5)


def test_random_lines_bounce_at_constant_speed(garden):
    tr = T.random_lines(garden.area, 800, 0.2, margin=0.3, world=garden, rng=4)
    steps = np.hypot(*np.diff(tr.poses[:, :2], axis=0).T)
    np.testing.assert_allclose(steps, 0.2, atol=1e-9)
    assert garden.free(tr.poses[:, 0], tr.poses[:, 1], 0.3).all()
    turns = np.abs(sim.wrap_angle(np.diff(tr.poses[:, 2]))) > 1e-9
    assert 5 < turns.sum() < 400  # straight lines between bounces
    again = T.random_lines(garden.area, 800, 0.2, margin=0.3, world=garden, rng=4)
    np.testing.assert_array_equal(again.poses, tr.poses)


def test_velocity_regions():
    vr = T.VelocityRegions.half_plane(0.0, "left", 3.0)
    tr = T.random_lines((10, 10), 2000, 0.1, speed=vr, rng=1)
    steps = np.hypot(*np.diff(tr.poses[:, :2], axis=0).T)
    f = tr.extra["speed_factor"][:-1]
    np.testing.assert_allclose(steps[f == 1], 0.1)
    np.testing.assert_allclose(steps[f == 3], 0.3)
    assert (f[tr.poses[:-1, 0] < 0] == 1).all() and (f[tr.poses[:-1, 0] > 0] == 3).all()
    disc = T.VelocityRegions.disc(2.0, factor=3.0)
    assert disc(0.5, 0.5) == 1.0 and disc(3.0, 0.0) == 3.0


def test_border_loop_is_closed():
    tr = T.border_loop((15, 15), 279, rng=2)
    assert len(tr) == 279
    steps = np.hypot(*np.diff(np.vstack([tr.poses[:, :2], tr.poses[:1, :2]]), axis=0).T)
    assert steps.max() / steps.min() < 1.05  # evenly spaced, and the last frame leads back to the first
    assert (np.abs(tr.poses[:, :2]) < 7.5).all()
    assert np.abs(np.unwrap(tr.poses[:, 2])[-1] - tr.poses[0, 2]) == pytest.approx(2 * np.pi, abs=0.3)


def test_line_segments_for_metric_learning():
    tr = T.line_segments((16, 18), 10, 8.0, 0.2, rng=3)
    seg = tr.extra["segment"]
    assert set(seg) == set(range(-1, 10))
    for k in range(10):
        P = tr.poses[seg == k]
        length = np.hypot(*(P[-1, :2] - P[0, :2]))
        assert length >= 8.0 - 1e-9
        d = np.hypot(*np.diff(P[:, :2], axis=0).T)
        np.testing.assert_allclose(d, d[0])
        assert abs(d[0] - 0.2) < 0.01
        np.testing.assert_allclose(P[:, 2], P[0, 2])  # straight
        np.testing.assert_allclose(np.cumsum(d)[-1], length)
    assert (tr.extra["segment"] >= 0).sum() == len(T.line_segments((16, 18), 10, 8.0, 0.2, rng=3, transit=False))


def test_random_walk_stays_inside():
    tr = T.random_walk((6, 6), 500, 0.2, margin=0.5, rng=1)
    assert (np.abs(tr.poses[:, :2]) <= 2.5 + 1e-9).all()
    np.testing.assert_allclose(np.hypot(*np.diff(tr.poses[:, :2], axis=0).T), 0.2)


def test_trajectory_errors():
    with pytest.raises(ValueError, match="area"):
        T.grid((-1, 5))
    with pytest.raises(ValueError, match="turn"):
        T.grid((5, 5), turn="skid")
    with pytest.raises(ValueError, match="n_frames"):
        T.random_lines((5, 5), 0)
    with pytest.raises(ValueError, match="min_length"):
        T.line_segments((4, 4), 2, 10.0)
    with pytest.raises(ValueError, match="slow_side"):
        T.VelocityRegions.half_plane(slow_side="up")
    with pytest.raises(ValueError, match="times"):
        T.Trajectory(np.zeros((3, 3)), np.zeros(2))
