"""Robust descent wall-following variants behind the v-wall with coordinate SFA (trial seed 7, 20 trials):
    PYTHONPATH=python python3 scripts/nav_wall_follow_tune.py "" "follow_step=0.7,leave_drop=0.0" ..."""
import sys, time, numpy as np
sys.path.insert(0, __import__("os").path.join(__import__("os").path.dirname(__file__), "..", "python"))
from sfanav import navigation as nav
from sfanav.experiments import navigation as EN
sc = EN.scene("obstacle", 0); w, h = sc.area
model = EN.coordinate_model(sc)
rng = EN._rng(7, 71, 1)
apex_y = -0.15 * h; arm = 0.3 * min(w, h); target = np.array([0.0, apex_y + 0.45 * arm])
S, T = nav.sample_trials(20, sc.area, free=EN._free(sc), min_distance=4.0, margin=0.4, target=target,
                         start_region=lambda x, y: y < 0 and y < apex_y + abs(x) - 0.3, rng=rng)
g = nav.occupancy_grid(sc.area, lambda x, y: sc.world.free(x, y, sc.robot.size / 2), resolution=0.1, margin=sc.robot.size / 2)
opt = np.array([nav.shortest_path(g, s, t)[1] for s, t in zip(S, T)])
for a in sys.argv[1:]:
    kw = eval("dict(" + a + ")")
    navi = nav.Navigator(nav.PointSimulator(robot=sc.robot, world=sc.world), nav.CoordinateFeatures(model),
                         nav.RobustDescent(**kw), n_outputs=2)
    t = time.time(); s = nav.evaluate_trials(navi, S, T, optimal_lengths=opt)
    print(repr(a), f"{s.success_rate:.2f} {s.efficiency:.3f}", s.reasons, f"{time.time()-t:.0f}s", flush=True)
