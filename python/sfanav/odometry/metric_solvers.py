"""The solvers of the unsupervised metric learning's line fit
(:class:`~sfanav.odometry.MetricLearner`): the thesis's momentum gradient
descent with a block-Jacobi preconditioner, L-BFGS-B on all parameters, and
variable projection over the headings (origins and weights solved in closed
form by :class:`~sfanav.odometry.metric_cost.VarPro`). The cost and its
gradient: :mod:`sfanav.odometry.metric_cost`; the comparison of the solvers:
docs/odometry.md."""

from __future__ import annotations

from typing import Any

import numpy as np

from .._progress import progress_bar
from .metric_cost import LineProblem, VarPro

__all__ = ["preconditioner", "solve"]


def preconditioner(pb: LineProblem) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Block-Jacobi: inverse curvature of alpha_n, o_n and W (pseudo-inverse)."""
    h_a = np.bincount(pb.lab, weights=pb.d**2, minlength=pb.L)
    h_o = np.bincount(pb.lab, minlength=pb.L).astype(np.float64)
    if pb.has_angle:
        adj = np.zeros(pb.L)
        adj[:-1] = pb.lam
        adj[1:] = np.maximum(adj[1:], pb.lam)
        h_a = h_a + 2.0 * adj
    if pb.transits is not None:
        h_a[:-1] += pb.wt * np.einsum("ij,ij->i", pb.transits, pb.transits)
        h_o[:-1] += pb.wt
        h_o[1:] += pb.wt
    H = pb.Phi.T @ pb.Phi
    if pb.ridge:
        H[1:, 1:] += pb.ridge * np.eye(pb.K - 1)
    ev, U = np.linalg.eigh(H)
    keep = ev > ev[-1] * 1e-10
    Hinv = (U[:, keep] / ev[keep]) @ U[:, keep].T
    return 1.0 / np.maximum(h_a, 1e-12), (1.0 / h_o)[:, None], Hinv

def solve(pb: LineProblem, vp: VarPro | None, a0: np.ndarray, O0: np.ndarray, W0: np.ndarray, *, solver: str,
          precondition: bool, heading_drift: Any, lr: float, mom: float, max_iter: int, tol: float,
          snaps_at: Any, progress: bool) -> dict[str, Any]:
    """One start of the line-fit from ``(a0, O0, W0)`` (headings, origins,
    readout weights) with ``solver`` ("gd": the thesis's momentum gradient
    descent with learning rate ``lr`` and momentum ``mom``, block-Jacobi
    preconditioned if ``precondition``; "lbfgs": L-BFGS-B on all free
    parameters; "varpro": L-BFGS-B on the headings with origins and weights
    solved by ``vp``, and the heading drift too when ``heading_drift`` is
    "estimate"). Stops after ``max_iter`` iterations or a relative cost
    change below ``tol``; keeps snapshots of the parameters at the
    iterations in ``snaps_at``. Returns the parameters, cost, history,
    drift, iteration count, convergence flag and snapshots."""
    snaps: dict[int, dict[str, np.ndarray]] = {}

    def snap(it, a, O, W):
        snaps[it] = {"alpha": a.copy(), "origins": O.copy(), "weights": W.copy()}

    if solver == "gd":
        theta = pb.pack(a0, O0, W0)
        free = pb.free
        precond = preconditioner(pb) if precondition else None
        v = np.zeros_like(theta)
        c, g = pb.cost(*pb.unpack(theta))
        hist = [c]
        if 0 in snaps_at:
            snap(0, *pb.unpack(theta))
        bar = progress_bar(progress, max_iter, "metric learning (gd)")
        converged, it = False, 0
        try:
            for it in range(1, max_iter + 1):
                if precond is not None:
                    g = (g[0] * precond[0], g[1] * precond[1], precond[2] @ g[2])
                grad = np.concatenate([g[0], g[1].ravel(), g[2].ravel()])
                v = mom * v + lr * np.where(free, grad, 0.0)  # (5.7)
                theta = theta - v  # (5.8)
                c_new, g = pb.cost(*pb.unpack(theta))
                hist.append(c_new)
                if it in snaps_at:
                    snap(it, *pb.unpack(theta))
                if bar is not None:
                    bar.update(1)
                    if it % 50 == 0:
                        bar.set_postfix(cost=f"{c_new:.4g}")
                if not np.isfinite(c_new):
                    raise FloatingPointError(
                        f"gradient descent diverged at iteration {it} (cost {c_new}); "
                        f"lower learning_rate (now {lr:g})"
                    )
                if abs(c - c_new) <= tol * abs(c):
                    converged = True
                    break
                c = c_new
        finally:
            if bar is not None:
                bar.close()
        a, O, W = pb.unpack(theta)
        a, O, W = a.copy(), O.copy(), W.copy()
        n_iter = it
    else:
        from scipy.optimize import minimize

        hist: list[float] = []
        bar = progress_bar(progress, max_iter, f"metric learning ({solver})")
        if solver == "lbfgs":
            free = pb.free
            base = pb.pack(a0, O0, W0)

            def full(x):
                th = base.copy()
                th[free] = x
                return th

            def fun(x):
                c, g = pb.cost(*pb.unpack(full(x)))
                return c, np.concatenate([g[0], g[1].ravel(), g[2].ravel()])[free]

            def params(x):
                a, O, W = pb.unpack(full(x))
                return a.copy(), O.copy(), W.copy()

            x0 = base[free]
        else:
            freea = pb.free_a
            abase = a0.copy()

            def full_a(x):
                a = abase.copy()
                a[freea] = x
                return a

            est = pb.drift_path is not None and heading_drift == "estimate" and pb.has_angle
            n_a = int(freea.sum())

            def fun(x):
                if est:
                    pb.drift = float(x[n_a])
                a = full_a(x[:n_a])
                c, g = vp.cost(a)
                if est:
                    return c, np.r_[g[freea], vp.drift_gradient(a)]
                return c, g[freea]

            def params(x):
                if est:
                    pb.drift = float(x[n_a])
                a = full_a(x[:n_a])
                O, W = vp.linear(a)
                return a, O, W

            x0 = np.r_[a0[freea], pb.drift] if est else a0[freea]
        hist.append(float(pb.cost(*params(x0))[0]))
        if 0 in snaps_at:
            snap(0, *params(x0))
        counter = [0]

        def callback(intermediate_result):
            counter[0] += 1
            x = intermediate_result.x
            if counter[0] in snaps_at:
                snap(counter[0], *params(x))
            hist.append(float(intermediate_result.fun) if solver == "lbfgs" else float(pb.cost(*params(x))[0]))
            if bar is not None:
                bar.update(1)

        try:
            if len(x0):
                res = minimize(fun, x0, jac=True, method="L-BFGS-B", callback=callback,
                               options={"maxiter": max_iter, "ftol": tol, "gtol": 1e-12, "maxcor": 20})
                x_opt, n_iter = res.x, int(res.nit)
                converged = bool(res.success) and n_iter < max_iter
            else:
                x_opt, n_iter, converged = x0, 0, True
        finally:
            if bar is not None:
                bar.close()
        a, O, W = params(x_opt)
    cost = float(pb.cost(a, O, W)[0])
    snap(n_iter, a, O, W)
    return {"alpha": a, "origins": O, "weights": W, "cost": cost, "history": hist, "drift": pb.drift,
            "n_iter": n_iter, "converged": converged, "snapshots": snaps}
