"""Navigation along slow-feature gradients (thesis chapter 7): cost, the
plane-fit gradient, the descents, A*, velocity-region helpers and a
closed-loop smoke test in a tiny simulated world."""

import numpy as np
import pytest

import sfanav
from sfanav import navigation as nav
from sfanav.sim import World
from sfanav.sim.robot import OdometryNoise, Robot

# --------------------------------------------------------------------- cost


def test_cost_is_euclidean_over_n_outputs_and_weighted():
    t = np.array([1.0, -2.0, 0.5])
    c = nav.SlowFeatureCost(t, n=2)
    f = np.array([[4.0, 2.0, 100.0], [1.0, -2.0, -7.0]])
    np.testing.assert_allclose(c(f), [5.0, 0.0])
    w = nav.beta_weights([0.01, 0.02, 0.04])
    np.testing.assert_allclose(w, [100, 50, 25])
    np.testing.assert_allclose(nav.beta_weights([0.01, 0.02, 0.04], relative=True), [1, 0.5, 0.25])
    cw = nav.SlowFeatureCost(t, n=3, weights=[1.0, 0.5, 0.25])
    np.testing.assert_allclose(cw(f[0]), np.sqrt(3**2 + (0.5 * 4) ** 2 + (0.25 * 99.5) ** 2))
    with pytest.raises(ValueError, match="n must be"):
        nav.SlowFeatureCost(t, n=4)
    with pytest.raises(ValueError, match="weights"):
        nav.SlowFeatureCost(t, n=3, weights=[1.0])
    with pytest.raises(ValueError, match="beta"):
        nav.beta_weights([0.1, 0.0])


# --------------------------------------------------------------------- gradient


def _two_stops(base, heading, step, sep=0.7):
    """Camera positions of a robot at ``base`` facing ``heading`` before and
    after driving ``step`` m forward (left camera first)."""
    u = np.array([np.cos(heading), np.sin(heading)])
    left = np.array([-u[1], u[0]])
    p0 = np.array([base + sep / 2 * left, base - sep / 2 * left])
    return p0, p0 + step * u


@pytest.mark.parametrize("weighting", ["area", "unit"])
def test_plane_gradient_is_exact_for_planes(weighting):
    rng = np.random.default_rng(0)
    for _ in range(50):
        a = rng.normal(size=2) * rng.uniform(0.01, 5)
        plane = lambda P: P @ a + 3.0  # noqa: E731
        P = rng.uniform(-3, 3, (4, 2))
        g = nav.plane_gradient(P, plane(P), weighting=weighting)
        np.testing.assert_allclose(g, a, rtol=1e-9, atol=1e-12)
    # the thesis's configuration: two stops of a two-camera robot
    p0, p1 = _two_stops(np.array([2.0, -1.0]), 0.7, 0.3)
    P = np.vstack([p0, p1])
    np.testing.assert_allclose(nav.plane_gradient(P, plane(P), weighting=weighting), a, rtol=1e-9)


def test_plane_gradient_degenerate_points():
    P = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [3.0, 3.0]])
    assert nav.plane_gradient(P, np.arange(4.0)) is None
    with pytest.raises(ValueError):
        nav.plane_gradient(P[:2], np.arange(2.0))


def _angle(g, true):
    return np.degrees(np.arccos(np.clip(g @ true / np.linalg.norm(g) / np.linalg.norm(true), -1, 1)))


def test_plane_gradient_direction_on_quadratics():
    """On quadratic bowls the (area-weighted) plane of two stops has exactly
    the gradient at the centroid of the four camera positions, and points
    within a few degrees of the gradient at the robot's new position (steps
    of 0.3 m, cameras 0.7 m apart, 2-8 m from the minimum)."""
    rng = np.random.default_rng(1)
    bowls = [np.diag([1.0, 2.0]), np.array([[1.5, 0.4], [0.4, 0.7]]), np.diag([0.3, 0.3])]
    worst, worst_centroid = 0.0, 0.0
    for A in bowls:
        f = lambda P: 0.5 * np.einsum("ni,ij,nj->n", P, A, P)  # noqa: E731
        for _ in range(40):
            r = rng.uniform(2, 8)
            base = r * np.array([np.cos(a := rng.uniform(0, 2 * np.pi)), np.sin(a)])
            p0, p1 = _two_stops(base, rng.uniform(-np.pi, np.pi), 0.3)
            P = np.vstack([p0, p1])
            g = nav.plane_gradient(P, f(P))
            worst = max(worst, _angle(g, A @ p1.mean(axis=0)))
            worst_centroid = max(worst_centroid, _angle(g, A @ P.mean(axis=0)))
    assert worst_centroid < 1e-3
    assert worst < 7.0


def test_plane_gradient_estimator_starts_with_the_difference_quotient():
    a = np.array([0.3, -0.2])
    plane = lambda P: P @ a  # noqa: E731
    est = nav.PlaneGradient()
    p0, p1 = _two_stops(np.zeros(2), 0.0, 0.4)  # heading +x: cameras at (0, +-0.35)
    g0 = est.update(p0, plane(p0))
    assert est.last_method == "difference"
    np.testing.assert_allclose(g0, [0.0, -0.2])  # the component along the baseline only
    np.testing.assert_allclose(nav.difference_quotient(p0[0], p0[1], *plane(p0)), g0)
    g1 = est.update(p1, plane(p1))
    assert est.last_method == "plane"
    np.testing.assert_allclose(g1, a, atol=1e-12)
    # not moving at all leaves only two distinct points: back to the difference quotient
    est.update(p1, plane(p1))
    assert est.last_method == "difference"
    est.reset()
    est.update(p1, plane(p1))
    assert est.last_method == "difference"


# --------------------------------------------------------------------- descents


def _bowl_navigator(descent, scale=0.13, **kw):
    """A point robot whose 'slow features' are smooth functions of position
    (monotonic half waves with slopes up to 0.18 per metre, like unit-variance
    SFA outputs over 20 m)."""
    sim = nav.PointSimulator((18.0, 22.0), Robot.two_cameras(0.7))
    feats = nav.CoordinateFeatures(lambda X: np.column_stack([np.sin(scale * X[:, 0]), np.sin(scale * X[:, 1])]) * 1.4)
    return nav.Navigator(sim, feats, descent, **kw)


@pytest.mark.parametrize("descent", [nav.ThesisDescent(1.0, 0.5), nav.RobustDescent()], ids=lambda d: d.name)
def test_descents_reach_the_minimum_of_a_bowl(descent):
    navi = _bowl_navigator(descent)
    for start, target in [((-7.0, -9.0), (6.0, 8.0)), ((7.5, 2.0), (-7.0, -3.0)), ((0.0, 9.0), (1.0, -9.0))]:
        r = navi.run(start, target, heading=0.3)
        assert r.success and r.reason == "reached", (start, target, r.reason)
        assert np.hypot(*(r.path[-1] - np.array(target))) <= 0.5
        assert r.direct / r.travelled > 0.6
        assert len(r.costs) == r.iterations and r.images >= 2 * r.iterations
    # the robust descent takes near-straight paths
    if isinstance(descent, nav.RobustDescent):
        assert r.direct / r.travelled > 0.9


def test_thesis_descent_is_momentum_gradient_descent():
    d = nav.ThesisDescent(eta=2.0, gamma=0.5)
    info = nav.StepInfo()
    np.testing.assert_allclose(d.step(np.array([1.0, 0.0]), 1.0, np.zeros(2), info), [-2.0, 0.0])
    np.testing.assert_allclose(d.step(np.array([0.0, 1.0]), 1.0, np.zeros(2), info), [-1.0, -2.0])
    d.reset()
    np.testing.assert_allclose(d.step(np.array([0.0, 1.0]), 1.0, np.zeros(2), info), [0.0, -2.0])
    with pytest.raises(ValueError):
        nav.ThesisDescent(gamma=1.0)


def test_flat_region_stalls_the_thesis_rule_but_not_the_robust_descent():
    """A cost with a tiny slope (a plateau) far from the target: the thesis
    rule creeps, the normalised steps of the robust descent cross it."""
    feats = lambda X: np.column_stack([np.tanh(0.15 * X[:, 0]) ** 3, np.tanh(0.15 * X[:, 1]) ** 3])  # noqa: E731
    out = {}
    for d in (nav.ThesisDescent(1.0, 0.5), nav.RobustDescent()):
        sim = nav.PointSimulator((18.0, 22.0), Robot.two_cameras(0.7))
        navi = nav.Navigator(sim, nav.CoordinateFeatures(feats), d, max_iterations=150)
        out[d.name] = navi.run((-7.0, -9.0), (0.5, 0.5))
    assert not out["thesis rule"].success
    assert out["robust descent"].success


def test_stuck_detector_ends_runs_when_asked():
    sim = nav.PointSimulator((18.0, 22.0), Robot.two_cameras(0.7))
    flat = nav.CoordinateFeatures(lambda X: np.zeros((len(X), 2)) + 1e-9 * X)
    navi = nav.Navigator(sim, flat, nav.ThesisDescent(), stuck_window=10, stop_when_stuck=True)
    r = navi.run((0.0, 0.0), (5.0, 5.0))
    assert r.reason == "stuck" and not r.success and r.iterations <= 12


def test_obstacles_are_physical_for_the_point_robot():
    world = World.generate(3, area=(8.0, 8.0), n_objects=4, obstacles=({"kind": "box", "x": 0.0, "y": 0.0,
                                                                        "length": 6.0, "width": 0.4},))
    sim = nav.PointSimulator(robot=Robot.two_cameras(0.7), world=world)
    # a cost pulling straight through the wall
    navi = nav.Navigator(sim, nav.CoordinateFeatures(lambda X: 0.2 * X), nav.ThesisDescent(), max_iterations=40)
    r = navi.run((0.0, -2.5), (0.0, 2.5))
    assert world.free(r.path[:, 0], r.path[:, 1], 0.35 - 1e-9).all()
    assert r.blocked > 0


# --------------------------------------------------------------------- A*


def _dijkstra(G, s, g, W=None):
    import heapq

    R, C = G.shape
    dist = {s: 0.0}
    heap = [(0.0, s)]
    while heap:
        d, p = heapq.heappop(heap)
        if p == g:
            return d
        if d > dist[p]:
            continue
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                q = (p[0] + dr, p[1] + dc)
                if (dr, dc) == (0, 0) or not (0 <= q[0] < R and 0 <= q[1] < C) or not G[q]:
                    continue
                if dr and dc and not (G[p[0] + dr, p[1]] and G[p[0], p[1] + dc]):
                    continue
                L = np.hypot(dr, dc) * (1 if W is None else 0.5 * (W[p] + W[q]))
                if d + L < dist.get(q, np.inf):
                    dist[q] = d + L
                    heapq.heappush(heap, (d + L, q))
    return np.inf


def test_astar_is_optimal_on_small_grids():
    G = np.ones((5, 7), bool)
    path, cost = nav.astar(G, (0, 0), (4, 6))
    assert cost == pytest.approx(4 * np.sqrt(2) + 2)
    assert path[0] == (0, 0) and path[-1] == (4, 6) and len(path) == 7
    G[1:, 3] = False  # a wall with a gap at the top
    path, cost = nav.astar(G, (4, 0), (4, 6))
    assert all(G[p] for p in path)
    assert cost == pytest.approx(_dijkstra(G, (4, 0), (4, 6)))
    G[0, 3] = False
    assert nav.astar(G, (4, 0), (4, 6)) == ([], float("inf"))
    rng = np.random.default_rng(0)
    for _ in range(30):
        G = rng.random((9, 11)) > 0.3
        W = rng.uniform(1, 3, G.shape)
        s, g = (0, 0), (8, 10)
        G[s] = G[g] = True
        for weights in (None, W):
            _, cost = nav.astar(G, s, g, weights)
            assert cost == pytest.approx(_dijkstra(G, s, g, weights))
    _, c4 = nav.astar(np.ones((3, 3), bool), (0, 0), (2, 2), connectivity=4)
    assert c4 == 4


def test_shortest_path_around_an_obstacle():
    world = World.generate(3, area=(8.0, 8.0), n_objects=4, obstacles=({"kind": "box", "x": 0.0, "y": 0.0,
                                                                        "length": 6.0, "width": 0.4},))
    grid = nav.occupancy_grid(world.area, lambda x, y: world.free(x, y, 0.35), resolution=0.1, margin=0.35)
    P, L = nav.shortest_path(grid, (0.0, -2.0), (0.0, 2.0))
    Ps, Ls = nav.shortest_path(grid, (0.0, -2.0), (0.0, 2.0), smooth=True)
    # around the end of the wall inflated by 0.35 m (corners at (3.35, +-0.55)): two legs and the end face
    assert Ls == pytest.approx(2 * np.hypot(3.35, 1.45) + 1.1, rel=0.03)
    assert Ls <= L <= Ls * 1.09
    assert world.free(P[:, 0], P[:, 1], 0.3).all()
    assert nav.path_length(Ps) == pytest.approx(Ls)


# --------------------------------------------------------------------- velocity regions


def test_halfplane_optimum_obeys_snells_law():
    s, t = np.array([-6.0, -5.0]), np.array([7.0, 6.0])
    P, T = nav.halfplane_optimal(s, t, x0=0.0, speed_left=1.0, speed_right=3.0)
    m = P[1]
    assert m[0] == 0.0
    sin1 = abs(m[1] - s[1]) / np.hypot(*(m - s))
    sin2 = abs(t[1] - m[1]) / np.hypot(*(t - m))
    assert sin1 / 1.0 == pytest.approx(sin2 / 3.0, rel=1e-6)
    regions = sfanav.sim.VelocityRegions.half_plane(0.0, "left", 3.0)
    assert nav.travel_time(P, regions) == pytest.approx(T, rel=1e-3)
    # better than the straight line and than crossing at the start's or target's height
    assert T < nav.travel_time(np.array([s, t]), regions)
    for y in (s[1], t[1], 0.0):
        assert T <= nav.travel_time(np.array([s, [0.0, y], t]), regions) + 1e-9


def test_travel_time_and_weighted_astar_avoid_a_slow_disc():
    regions = sfanav.sim.VelocityRegions.disc(3.0, factor=3.0)
    assert nav.travel_time(np.array([[-5.0, 0.0], [5.0, 0.0]]), regions) == pytest.approx(4 / 3 + 6.0, rel=1e-3)
    grid = nav.occupancy_grid((12.0, 12.0), None, resolution=0.1, margin=0.0)
    X, Y = grid.centres()
    W = np.where(X**2 + Y**2 < 9.0, 3.0, 1.0)
    P, cost = nav.shortest_path(grid, (-5.0, 0.0), (5.0, 0.0), weights=W)
    t_opt = nav.travel_time(P, regions)
    assert t_opt < nav.travel_time(np.array([[-5.0, 0.0], [5.0, 0.0]]), regions)
    assert np.hypot(P[:, 0], P[:, 1]).min() > 2.0  # goes (almost) around the disc


def test_coordinate_sfa_learns_position_codes():
    from sfanav.sim import trajectories as T

    tr = T.random_lines((10.0, 10.0), 3000, 0.2, margin=0.3, rng=0)
    for kw in ({"expansion": "rbf", "spacing": 1.5}, {"expansion": "poly", "degree": 5}):
        _check_coordinate_sfa(tr, kw)


def _check_coordinate_sfa(tr, kw):
    model = nav.fit_coordinate_sfa(tr.poses[:, :2], (10.0, 10.0), n_components=4, **kw)
    F = model(tr.poses[:, :2])
    assert F.shape == (3000, 4)
    # the slowest two are (mixtures of) half waves along x and y: together they encode position
    A = np.column_stack([F[:, :2], np.ones(len(F))])
    coef, *_ = np.linalg.lstsq(A, tr.poses[:, :2], rcond=None)
    assert np.sqrt(np.mean((A @ coef - tr.poses[:, :2]) ** 2)) < 1.0
    assert np.all(np.diff(model.sfa.beta_values_) >= 0)


# --------------------------------------------------------------------- trials, closed loop, plots


def test_sample_trials_respects_distance_and_regions():
    S, T = nav.sample_trials(20, (18.0, 22.0), min_distance=15.0, rng=0)
    assert S.shape == T.shape == (20, 2)
    assert (np.hypot(*(S - T).T) >= 15.0).all()
    S, T = nav.sample_trials(5, (18.0, 22.0), target=(0.0, 1.0), start_region=lambda x, y: y < -3, min_distance=2.0,
                             rng=1)
    assert (T == [0.0, 1.0]).all() and (S[:, 1] < -3).all()


@pytest.fixture(scope="module")
def tiny_world():
    """A 5 x 5 m garden with a short wall and a small network trained on 300
    frames of 60 x 8 gray panoramas."""
    from sfanav.sim import trajectories as T
    from sfanav.sim.cameras import PanoramicCamera
    from sfanav.sim.robot import Simulator

    world = World.generate(5, area=(5.0, 5.0), n_objects=10, depth=5.0,
                           obstacles=({"kind": "box", "x": 0.0, "y": 0.0, "length": 2.0, "width": 0.3},))
    cam = PanoramicCamera(60, 8, rgb=False)
    sim = Simulator(world, cam, Robot.two_cameras(0.7, noise=OdometryNoise.none()), seed=0)
    tr = T.random_lines(world.area, 300, 0.2, margin=0.35, world=world, rng=0)
    imgs = np.stack([sim.renderer.render(cam, p) for p in tr.poses])
    net = sfanav.Network({"input": {"width": 60, "height": 8, "channels": 1},
                          "layers": [{"rf": [10, 8], "stride": [5, 8], "out": 6}, {"rf": "full", "out": 4}]})
    net.fit(imgs, rotation=sfanav.Rotation(10), progress=False)
    return world, cam, sim, net


@pytest.mark.parametrize("descent", [nav.ThesisDescent(), nav.RobustDescent()], ids=lambda d: d.name)
def test_navigation_smoke_in_a_tiny_world(tiny_world, descent):
    world, cam, sim, net = tiny_world
    feats = nav.ImageFeatures(net, sim.renderer, cam)
    navi = nav.Navigator(sim, feats, descent, max_iterations=15)
    S, T = nav.sample_trials(2, world.area, free=lambda x, y: world.free(x, y, 0.4), min_distance=2.5, rng=3)
    summary = nav.evaluate_trials(navi, S, T)
    assert 0.0 <= summary.success_rate <= 1.0
    assert len(summary.results) == 2 and sum(summary.reasons.values()) == 2
    for r in summary.results:
        assert world.free(r.path[:, 0], r.path[:, 1], 0.35 - 1e-9).all()  # never inside the wall
        assert r.travelled == pytest.approx(nav.path_length(r.path), rel=1e-6, abs=1e-9)
        assert np.isfinite(r.costs).all() and r.images >= 2 * r.iterations
        assert r.success == (np.hypot(*(r.path[-1] - r.target)) <= 0.5)
    ok = np.array([r.success for r in summary.results])
    assert np.isnan(summary.efficiencies[~ok]).all()
    assert np.isfinite(summary.efficiencies[ok]).all()


def test_plots_write_pngs(tmp_path):
    xs, ys = np.linspace(-2, 2, 9), np.linspace(-3, 3, 13)
    X, Y = np.meshgrid(xs, ys)
    F = np.stack([X, Y, X * Y, X**2], axis=-1)
    F[0, 0] = np.nan
    p = nav.plot_cost_surface(xs, ys, F, [0.0, 0.0, 0.0, 0.0], tmp_path / "c.png", ns=(2, 4),
                              weights=[1, 1, 0.5, 0.25], target=(0, 0))
    assert p.exists() and p.stat().st_size > 1000
    navi = _bowl_navigator(nav.RobustDescent())
    rs = [navi.run((-3.0, -3.0), (3.0, 4.0)), navi.run((3.0, -3.0), (-3.0, 4.0))]
    q = nav.plot_trajectories(rs, tmp_path / "t.png", area=(18.0, 22.0), optimal=[np.array([r.start, r.target])
                                                                                   for r in rs])
    assert q.exists() and q.stat().st_size > 1000
    with pytest.raises(ValueError, match="png"):
        nav.plot_trajectories(rs, tmp_path / "t.jpg", area=(18.0, 22.0))


def test_robust_descent_follows_a_wall_out_of_a_local_minimum():
    """Straight-line cost to a target behind a wall: the thesis rule presses
    against the wall (a local minimum of the cost on the free space); the
    robust descent follows the wall round its end and arrives."""
    world = World.generate(3, area=(12.0, 12.0), n_objects=4, obstacles=({"kind": "box", "x": 0.0, "y": 0.0,
                                                                         "length": 6.0, "width": 0.3},))
    feats = nav.CoordinateFeatures(lambda X: 0.2 * X)
    out = {}
    for d in (nav.ThesisDescent(1.0, 0.5), nav.RobustDescent()):
        sim = nav.PointSimulator(robot=Robot.two_cameras(0.7), world=world)
        out[d.name] = nav.Navigator(sim, feats, d, max_iterations=150).run((0.5, -3.0), (-0.5, 3.0))
    assert not out["thesis rule"].success
    r = out["robust descent"]
    assert r.success and r.follows >= 1
    assert world.free(r.path[:, 0], r.path[:, 1], 0.35 - 1e-9).all()
    assert r.direct / r.travelled > 0.4


# --------------------------------------------------------------------- metric space (beyond the thesis)


def _wall_world():
    return World.generate(3, area=(12.0, 12.0), n_objects=4, obstacles=({"kind": "box", "x": 0.0, "y": 0.0,
                                                                         "length": 6.0, "width": 0.3},))


def _exploration(world, n=6000, seed=0):
    """Random lines bouncing off the wall and the border (an exploration run)."""
    from sfanav.sim import trajectories as T

    return T.random_lines(world.area, n, 0.2, margin=0.35, world=world, rng=seed).poses[:, :2]


def test_geodesic_field_goes_around_a_wall():
    """Places on the two sides of a wall: the run's geodesic distance is the
    way round the wall's end, not the straight line; the waypoint from one
    side heads for an end of the wall; unreachable places still get a
    finite cost; bad input is refused."""
    world = _wall_world()
    run = _exploration(world)
    field = nav.GeodesicField(run)
    a, b = np.array([0.0, -1.5]), np.array([0.0, 1.5])
    straight = 3.0
    around = 2 * np.hypot(3.0, 1.5)  # via an end of the 6 m wall
    g = float(field(a, b))
    assert g > 1.8 * straight and abs(g - around) < 0.3 * around, g
    # symmetric, and zero at the target
    assert abs(float(field(b, a)) - g) < 0.5 and float(field(b, b)) < 0.2
    # the open side: nearly the straight distance
    c, d = np.array([-4.5, -4.0]), np.array([-4.5, 4.0])
    assert abs(float(field(c, d)) - 8.0) < 1.2
    w = field.waypoint(a, b, lookahead=1.5)
    assert abs(w[0]) > 0.8 and world.free(w[0], w[1], 0.3)  # sideways towards an end, in free space
    assert field.visible(c, d) and not field.visible(a, b)
    # a wall is a jump of the geodesic distance along the segment; open ground is not, even across coverage gaps
    assert field.crosses_wall(a, b, b) and not field.crosses_wall(c, d, d)
    assert not field.crosses_wall(a, a + [0.0, -0.8], b)  # along one side of the wall
    wj = field.waypoint(a, b, lookahead=1.5, jump=3.0)
    assert abs(wj[0]) > 0.8 and world.free(wj[0], wj[1], 0.3)
    sparse = nav.GeodesicField(run[::4])  # every 4th frame: gaps wider than visible()'s clearance
    far = [(np.array([-4.5, -4.0 + i]), np.array([-4.5, 4.0 - i])) for i in range(3)]
    assert not any(sparse.visible(p, q) for p, q in far)  # the gaps look blocked to visible() ...
    assert not any(sparse.crosses_wall(p, q, q) for p, q in far)  # ... but are no wall
    with pytest.raises(ValueError, match="jump"):
        field.crosses_wall(a, b, b, jump=0.0)
    with pytest.raises(ValueError, match="jump"):
        nav.MetricDescent(jump=-1.0)
    # opt-in: heads straight over open ground that the sparse run covers with gaps
    rng = np.random.default_rng(2)
    feats = nav.CoordinateFeatures(lambda X: X + 0.1 * rng.standard_normal(X.shape))
    sim = nav.PointSimulator(robot=Robot.two_cameras(0.7, noise=OdometryNoise()), world=world)
    r = nav.Navigator(sim, feats, nav.MetricDescent(field=sparse, jump=3.0), max_iterations=150).run(c, d)
    assert r.success and r.direct / r.travelled > 0.85, (r.reason, r.direct / r.travelled)
    # a separate island of the run: finite, larger than everything reachable
    island = np.vstack([run, [[20.0, 20.0], [20.1, 20.0]]])
    f2 = nav.GeodesicField(island)
    assert np.isfinite(f2.distances_from(a)).all()
    far_cost = float(f2(np.array([20.05, 20.0]), a))
    assert np.isfinite(far_cost) and far_cost > float(f2(run[::50], a).max())
    cost = field.cost(b, 2)
    np.testing.assert_allclose(cost(np.array([a, b])), [g, float(field(b, b))])
    with pytest.raises(ValueError, match="positions must be"):
        nav.GeodesicField(np.zeros((1, 2)))
    with pytest.raises(ValueError, match="NaN"):
        nav.GeodesicField(np.array([[0.0, 0.0], [np.nan, 1.0]]))
    with pytest.raises(ValueError, match="radius must be"):
        nav.GeodesicField(run, radius=0.0)
    with pytest.raises(ValueError, match="at least 1.5 x the cell size"):
        nav.GeodesicField(run, radius=0.1, thin=0.1)
    with pytest.raises(ValueError, match="too large"):
        nav.GeodesicField(np.array([[0.0, 0.0], [500.0, 500.0]]), temporal=False)
    with pytest.raises(ValueError, match="n_outputs must be 2"):
        field.cost(b, 3)


def test_geodesic_field_is_nearly_straight_in_open_ground():
    """In open ground the geodesic distance is the straight distance: the
    grid of covered space gives it within a few per cent (the run's own
    frames joined by their neighbours zig-zag 10-25 % longer), it changes
    smoothly between places 0.1 m apart, never undercuts the straight
    distance, and still goes round the wall; neighbours must be a positive
    integer."""
    world = _wall_world()
    run = _exploration(world)
    field = nav.GeodesicField(run)
    assert field.neighbours == 8
    rng = np.random.default_rng(3)
    t = np.array([-4.5, 4.5])
    P = np.column_stack([rng.uniform(-5.5, -3.5, 300), rng.uniform(-5.5, 3.5, 300)])  # open strip left of the wall
    straight = np.hypot(*(P - t).T)
    ratio = field(P, t) / straight
    assert np.median(ratio) < 1.06 and np.percentile(ratio, 90) < 1.15, (np.median(ratio), np.percentile(ratio, 90))
    assert ratio.min() > 0.97
    line = np.column_stack([np.full(60, -4.5), np.linspace(-5.0, 1.0, 60)])  # 0.1 m apart
    assert np.abs(np.diff(field(line, t))).max() < 0.16
    a, b = np.array([0.0, -1.5]), np.array([0.0, 1.5])
    assert float(field(a, b)) > 1.8 * 3.0
    for bad in (0, -2, 1.5, True):
        with pytest.raises(ValueError, match="neighbours"):
            nav.GeodesicField(run, neighbours=bad)


def test_run_graph_features_are_the_ideal_slow_features():
    """Exactly zero mean, unit variance and decorrelated over the run's
    frames (SFA's constraints); in an open rectangle the slowest is a
    monotone code of the long axis (a half cosine: flat at the borders);
    behind a wall places a short step apart across it differ far more than
    the same step in the open; bad input is refused."""
    from sfanav.sim import trajectories as T

    open_world = World.generate(3, area=(12.0, 4.0), n_objects=4)
    run = T.random_lines(open_world.area, 3000, 0.2, margin=0.35, world=open_world, rng=0).poses[:, :2]
    g = nav.RunGraphFeatures(run, 3)
    F = g.run_features_
    np.testing.assert_allclose(F.mean(axis=0), 0.0, atol=1e-9)
    np.testing.assert_allclose(np.cov(F.T, bias=True), np.eye(3), atol=1e-8)
    assert g.delta_values_[0] < g.delta_values_[1] < g.delta_values_[2]
    np.testing.assert_allclose(g.beta_values_, np.sqrt(g.delta_values_) / (2 * np.pi))
    xs = np.linspace(-5.5, 5.5, 23)
    s1 = g(np.column_stack([xs, np.zeros_like(xs)]))[:, 0]
    assert abs(np.corrcoef(s1, xs)[0, 1]) > 0.95
    assert np.all(np.diff(s1) * np.sign(s1[-1] - s1[0]) > -0.02)  # monotone up to interpolation
    mid, edge = abs(s1[12] - s1[10]), abs(s1[-1] - s1[-3])
    assert edge < 0.5 * mid  # the half cosine flattens at the border
    world = _wall_world()
    wr = nav.RunGraphFeatures(_exploration(world), 2)
    a, b = np.array([[0.0, -0.6]]), np.array([[0.0, 0.6]])  # across the 6 m wall
    c, d = np.array([[-4.5, -0.6]]), np.array([[-4.5, 0.6]])  # the same step in the open
    assert np.linalg.norm(wr(a) - wr(b)) > 3 * np.linalg.norm(wr(c) - wr(d))
    with pytest.raises(ValueError, match="n_components"):
        nav.RunGraphFeatures(run, 0)
    with pytest.raises(ValueError, match="sigma"):
        nav.RunGraphFeatures(run, 2, sigma=-1.0)
    with pytest.raises(ValueError, match="positions must be"):
        nav.RunGraphFeatures(run[:1], 2)
    with pytest.raises(ValueError, match="too few"):
        nav.RunGraphFeatures(run[:3], 2)
    with pytest.raises(ValueError, match="poses"):
        g(np.zeros(3))


def test_map_tracker_fuses_estimates_with_odometry():
    """Odometry in a rotated, shifted frame and noisy estimates with a few
    far-off ones: the fused positions are far closer to the truth than the
    estimates, barely moved by the outliers; until the cameras spread the
    estimates pass through; reset forgets; bad input is refused."""
    rng = np.random.default_rng(4)
    a = 0.7
    rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    tr = nav.MapTracker(window=20)
    errs_raw, errs_fused = [], []
    for k in range(40):
        true = np.array([[0.3 * k, 0.35], [0.3 * k, -0.35]])  # two cameras driving along x
        odo = (true - [1.0, 2.0]) @ rot  # the odometry frame: rotated and shifted
        est = true + 0.25 * rng.standard_normal((2, 2))
        if k % 7 == 3:
            est[0] += [3.0, -2.5]  # a far-off estimate (near a wall)
        F = np.column_stack([est, np.full(2, 5.0)])  # a third output passes through
        out = tr.update(odo, F)
        assert out.shape == F.shape and (out[:, 2] == 5.0).all()
        if k >= 10:
            errs_raw.append(np.hypot(*(est - true).T))
            errs_fused.append(np.hypot(*(out[:, :2] - true).T))
    assert np.mean(errs_fused) < 0.35 * np.mean(errs_raw), (np.mean(errs_fused), np.mean(errs_raw))
    assert np.max(errs_fused) < 0.4
    tr.reset()  # forgets: one stop of two cameras 0.7 m apart spreads less than 1 m, so it passes through
    wide = nav.MapTracker(min_spread=1.0)
    F = np.array([[1.0, 2.0], [1.5, 2.0]])
    odo = np.array([[0.0, 0.35], [0.0, -0.35]])
    np.testing.assert_array_equal(wide.update(odo, F), F)
    assert not np.array_equal(tr.update(odo, F), F)  # 0.7 m >= 0.5 m: fitted (rigid: 0.7 m apart)
    wide.reset()
    np.testing.assert_array_equal(wide.update(odo + 5.0, F), F)
    for kw in ({"window": 1}, {"window": 2.5}, {"huber": 0.0}, {"min_spread": -1.0}, {"iterations": 0}):
        with pytest.raises(ValueError):
            nav.MapTracker(**kw)
    with pytest.raises(ValueError, match="features must be"):
        tr.update(np.zeros((2, 2)), np.zeros((3, 2)))
    with pytest.raises(ValueError, match="NaN"):
        tr.update(np.zeros((2, 2)), np.array([[np.nan, 0.0], [0.0, 0.0]]))


def test_navigator_with_a_tracker_reaches_a_target_on_noisy_positions():
    """The thesis rule on noisy position estimates, fused with odometry by
    a MapTracker, drives nearly straight to the target."""
    rng = np.random.default_rng(5)
    feats = nav.CoordinateFeatures(lambda X: X + 0.3 * rng.standard_normal(X.shape))
    sim = nav.PointSimulator((12.0, 12.0), Robot.two_cameras(0.7))
    cost = nav.ScaledCost(2.0)
    plain = nav.Navigator(sim, feats, nav.ThesisDescent(), cost=cost, max_iterations=200)
    fused = nav.Navigator(sim, feats, nav.ThesisDescent(), cost=cost, max_iterations=200, tracker=nav.MapTracker())
    s_plain = nav.evaluate_trials(plain, [(-4.0, -4.0), (4.0, -4.0)], [(4.0, 4.0), (-4.0, 3.0)])
    s_fused = nav.evaluate_trials(fused, [(-4.0, -4.0), (4.0, -4.0)], [(4.0, 4.0), (-4.0, 3.0)])
    assert s_fused.success_rate == 1.0 and s_fused.efficiency > 0.9, s_fused.efficiency
    assert s_fused.efficiency > s_plain.efficiency or s_plain.success_rate < 1.0


def test_metric_descent_aligns_odometry_to_the_map():
    """The rigid fit recovers a known rotation and translation exactly."""
    rng = np.random.default_rng(0)
    P = rng.uniform(-3, 3, (12, 2))
    a = 0.7
    R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    Q = P @ R.T + [1.5, -2.0]
    rot, t = nav.MetricDescent.align(P, Q)
    np.testing.assert_allclose(rot, R, atol=1e-12)
    np.testing.assert_allclose(t, [1.5, -2.0], atol=1e-12)
    with pytest.raises(ValueError, match="detour"):
        nav.MetricDescent(detour=0.5)
    with pytest.raises(ValueError, match="window"):
        nav.MetricDescent(window=1)


def test_metric_descent_reaches_targets_in_the_open_and_behind_a_wall():
    """Features = position estimates with noise (what MetricFeatures gives),
    odometry with its default noise: the metric descent drives nearly
    straight in the open, and with the run's geodesic field round the wall
    to a target behind it, where the straight-line metric descent fails."""
    world = _wall_world()
    field = nav.GeodesicField(_exploration(world))
    rng = np.random.default_rng(1)
    feats = nav.CoordinateFeatures(lambda X: X + 0.1 * rng.standard_normal(X.shape))
    robot = Robot.two_cameras(0.7, noise=OdometryNoise())

    def run(descent, start, target):
        sim = nav.PointSimulator(robot=robot, world=world)
        return nav.Navigator(sim, feats, descent, max_iterations=150).run(start, target)

    r = run(nav.MetricDescent(), (-4.5, -4.5), (-4.0, 4.5))
    assert r.success and r.direct / r.travelled > 0.85, (r.reason, r.direct / r.travelled)
    behind = ((0.5, -2.0), (-0.5, 2.0))
    plain = run(nav.MetricDescent(), *behind)
    geo = run(nav.MetricDescent(field=field), *behind)
    assert geo.success and geo.direct / geo.travelled > 0.4, (geo.reason, geo.direct / geo.travelled)
    assert geo.travelled < plain.travelled or not plain.success
    assert world.free(geo.path[:, 0], geo.path[:, 1], 0.35 - 1e-9).all()


def test_scaled_cost_puts_metric_costs_on_the_slow_feature_scale():
    """ScaledCost divides any cost by the run's spread; run_spread of a
    uniform square of side 2a is a / sqrt(3); with the scale, the thesis's
    rule (eta 1, gamma 0.5) on noisy position estimates reaches targets
    nearly straight."""
    rng = np.random.default_rng(0)
    sq = rng.uniform(-3.0, 3.0, (200000, 2))
    assert abs(nav.run_spread(sq) - 3.0 / np.sqrt(3.0)) < 0.01
    t, F = np.array([1.0, 2.0]), rng.normal(size=(5, 2))
    np.testing.assert_allclose(nav.ScaledCost(2.5)(t, 2)(F), nav.SlowFeatureCost(t, 2)(F) / 2.5)
    world = _wall_world()
    field = nav.GeodesicField(_exploration(world))
    np.testing.assert_allclose(nav.ScaledCost(4.0, field.cost)(t, 2)(F), field.cost(t, 2)(F) / 4.0)
    for bad, exc in ((0.0, ValueError), (-1.0, ValueError), (float("nan"), ValueError), ("1", TypeError)):
        with pytest.raises(exc, match="scale"):
            nav.ScaledCost(bad)
    with pytest.raises(ValueError, match="positions must be"):
        nav.run_spread(np.zeros(3))
    with pytest.raises(ValueError, match="spread"):
        nav.run_spread(np.ones((4, 2)))
    # closed loop in an open 12 x 12 m world: features = noisy positions (metres)
    open_world = World.generate(3, area=(12.0, 12.0), n_objects=4)
    feats = nav.CoordinateFeatures(lambda X: X + 0.1 * rng.standard_normal(X.shape))
    robot = Robot.two_cameras(0.7, noise=OdometryNoise())
    cost = nav.ScaledCost(nav.run_spread(_exploration(open_world)))
    effs = []
    for start, target in (((-4.5, -4.5), (-4.0, 4.5)), ((-4.5, 4.0), (3.0, -4.0)), ((4.0, -4.5), (-4.5, 3.0))):
        sim = nav.PointSimulator(robot=robot, world=open_world)
        r = nav.Navigator(sim, feats, nav.ThesisDescent(1.0, 0.5), max_iterations=150, cost=cost).run(start, target)
        assert r.success, r.reason
        effs.append(r.direct / r.travelled)
    assert np.mean(effs) > 0.8, effs


def test_metric_features_localize_rendered_views(tiny_world):
    """MetricFeatures: a fitted Localizer's position estimates of rendered
    camera poses; refused unfitted."""
    from sfanav.sim import trajectories as T

    world, cam, sim, net = tiny_world
    poses = T.random_lines(world.area, 60, 0.3, margin=0.35, world=world, rng=1).poses
    images = np.stack([sim.renderer.render(cam, p) for p in poses])
    loc = sfanav.Localizer(net, readout={"kind": "gp", "n_outputs": 4}).fit(images, poses[:, :2])
    f = nav.MetricFeatures(loc, sim.renderer, cam)
    est = f(poses[:3])
    assert est.shape == (3, 2) and f.images == 3
    np.testing.assert_allclose(est, loc.predict(images[:3]), atol=1e-9)
    with pytest.raises(ValueError, match="fitted"):
        nav.MetricFeatures(sfanav.Localizer(net), sim.renderer, cam)


def test_image_features_apply_rows_before_the_network(tiny_world):
    world, cam, sim, net = tiny_world

    class Crop:  # an ImageRows stand-in: keeps rows 2..5 of 8 and repeats them back to 8
        identity = False
        calls = 0

        def __call__(self, imgs):
            Crop.calls += 1
            a = np.asarray(imgs)
            return np.concatenate([a[:, 2:6], a[:, 2:6]], axis=1)

    poses = np.array([[0.5, -1.0, 0.3], [1.0, 1.5, -2.0]])
    plain = nav.ImageFeatures(net, sim.renderer, cam)(poses)
    cropped = nav.ImageFeatures(net, sim.renderer, cam, rows=Crop())(poses)
    imgs = np.stack([sim.renderer.render(cam, p) for p in poses])
    np.testing.assert_allclose(cropped, net.transform(Crop()(imgs)))
    assert Crop.calls == 2 and not np.allclose(plain, cropped)


# --------------------------------------------------------------------- the peer: perfect memory homing

def test_rotational_image_difference_is_the_best_roll():
    """The FFT form equals the minimum over every roll of the RMS difference;
    a rolled copy of the target costs 0 (rotation invariance)."""
    rng = np.random.default_rng(0)
    T = rng.uniform(0, 255, (6, 24))
    Q = rng.uniform(0, 255, (4, 6, 24))
    Q[1] = np.roll(T, 7, axis=1)
    brute = [min(np.sqrt(((q - np.roll(T, d, axis=1)) ** 2).mean()) for d in range(24)) for q in Q]
    got = nav.rotational_image_difference(Q, T)
    np.testing.assert_allclose(got, brute, rtol=1e-9, atol=1e-4)  # grey levels; the FFT form cancels sums of squares
    assert got[1] == pytest.approx(0.0, abs=1e-4)
    cost = nav.image_difference_cost(24)(T.ravel(), 1, None)
    np.testing.assert_allclose(cost(Q.reshape(4, -1)), got)
    assert cost.residuals(Q.reshape(4, -1)).shape == (4, 1)
    with pytest.raises(ValueError, match="24-column rows"):
        nav.RotationalImageDifferenceCost(np.zeros(25), 24)
    with pytest.raises(ValueError, match="features have 10 values"):
        cost(np.zeros((1, 10)))


def test_perfect_memory_homing_reaches_targets_in_the_open(tiny_world):
    """The peer in the closed loop: the robust descent of the rotational image
    difference to the target's panorama, from 1.5-2.5 m away in the tiny
    garden's open part."""
    world, cam, sim, _ = tiny_world
    feats = nav.PanoramaFeatures(sim.renderer, cam)
    navi = nav.Navigator(sim, feats, nav.RobustDescent(), n_outputs=1, max_iterations=25,
                         cost=nav.image_difference_cost(feats.width))
    S = np.array([[-1.8, 1.2], [1.6, -1.5]])
    T = np.array([[-0.2, 1.8], [1.7, 0.6]])
    summary = nav.evaluate_trials(navi, S, T)
    assert summary.success_rate == 1.0, summary.reasons
    for r in summary.results:
        assert r.costs[-1] < r.costs[0] and r.images >= 2 * r.iterations
