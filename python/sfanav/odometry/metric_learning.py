"""Unsupervised metric learning (thesis 5.3.1): :class:`MetricLearner` learns
the map from slow features to metric (x, y) from odometry distances along
straight lines, without ground truth. Solvers: the thesis's momentum gradient
descent (``"gd"``), L-BFGS-B on all parameters (``"lbfgs"``) and variable
projection (``"varpro"``, the default). The result is defined up to a
rigid motion (and a mirror image without a signed angle term); align it to
ground truth for evaluation only (:func:`sfanav.localization.align`). The
cost, its gradient and the solver comparison: docs/odometry.md."""

from __future__ import annotations

import os
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .._checks import NotFittedError, as_matrix, check_int, check_nonneg_float
from .._threads import one_blas_thread
from ..sfa.modelfile import register_loader, save_model
from ..sfa.node import expand, expanded_dim
from .lines import Lines, segment_lines
from .metric_cost import (
    ANGLE_TERMS,
    SOLVERS,
    LineProblem,
    VarPro,
    noise_dict,
    odometry_variances,
)
from .metric_solvers import solve


def _check_fixed(mapping: Any, name: str, width: int) -> dict[int, Any]:
    if mapping is None:
        return {}
    if not isinstance(mapping, Mapping):
        raise TypeError(f"{name} must be a mapping from line index to value, got {type(mapping).__name__}")
    out: dict[int, Any] = {}
    for k, v in mapping.items():
        n = check_int(k, f"{name} key", minimum=0)
        arr = np.asarray(v, dtype=np.float64)
        if arr.shape != (() if width == 1 else (width,)) or not np.all(np.isfinite(arr)):
            want = "a finite number (radians)" if width == 1 else "a finite (x, y) pair (metres)"
            raise ValueError(f"{name}[{n}] must be {want}, got {v!r}")
        out[n] = float(arr) if width == 1 else arr.copy()
    return out


class MetricLearner:
    """Unsupervised metric learning (thesis 5.3.1): learns ``W`` mapping the
    quadratically expanded slowest SFA outputs (with a bias) to metric
    (x, y), from odometry distances along straight lines. No ground truth.

    Parameters
    ----------
    n_outputs : int, default 8
        Number of slowest outputs used (thesis: 8).
    degree : int, default 2
        Degree of the expansion (:func:`sfanav.expand`); 8 outputs at degree 2
        give 44 monomials + 1 bias = 45 dims.
    solver : {"varpro", "gd", "lbfgs"}, default "varpro"
        ``"gd"``: the thesis's momentum gradient descent; ``"lbfgs"``: L-BFGS-B
        on all parameters; ``"varpro"``: L-BFGS-B on the line orientations with
        origins and W eliminated (fastest; docs/odometry.md compares them).
    angle_term : {"auto", "cos", "signed", None}, default "auto"
        None: cost (5.1). ``"cos"``: cost (5.5), the thesis's term on the
        cosine of the measured heading change between consecutive lines
        (against shear on grid-like trajectories). ``"signed"``: a term on the
        signed heading change, ``lambda (1 - cos(alpha_{n+1} - alpha_n -
        phi_n))`` (the von Mises likelihood; also excludes the mirror image).
        ``"auto"``: if the lines carry measured relative angles ``"signed"``
        with ``angle_weight="noise"`` and ``"cos"`` otherwise, else None.
    angle_weight : float or "noise", default 1.0
        Weight of the angle term (thesis: 1). ``"noise"`` (beyond the thesis):
        the maximum-likelihood weight ``sigma_f^2 / var(phi_n)`` per pair of
        lines, from the odometry noise model (:func:`odometry_variances`) and
        the residual variance ``sigma_f^2`` of the map (``feature_noise``).
    transit_weight : float or "noise", default 0.0
        Beyond the thesis: weight of the transit term, which ties the origin of
        line n+1 to the origin of line n plus the odometry's displacement
        between them (``Lines.transits``), ``1/2 sum_n w_n ||o_{n+1} - o_n -
        R(alpha_n) q_n||^2``. Without it every line's origin is free, and on
        grid-like runs of parallel lanes the map can bend (docs/odometry.md).
        ``"noise"``: ``w_n = sigma_f^2 / var(t_n)`` from the noise model. 0: off
        (the thesis's costs).
    odometry_noise : mapping or sfanav.sim.OdometryNoise, optional
        The odometry's random noise for the ``"noise"`` weights:
        ``distance_sigma`` (m/sqrt(m)), ``heading_sigma`` (rad/sqrt(m)),
        ``turn_sigma`` (rad/sqrt(rad)); default :data:`DEFAULT_ODOMETRY_NOISE`.
    feature_noise : float or None, default None
        ``sigma_f``, the standard deviation (metres, per coordinate) of the
        line residuals for the ``"noise"`` weights. None: estimated by maximum
        likelihood, alternating fits and ``sigma_f^2 = sum ||r||^2 / (2 M -
        n_parameters)`` from the residuals (starting from the residuals of the
        regression onto the odometry's line positions) until it changes by
        less than 0.1 %.
    heading_drift : float, "estimate" or None, default None
        Beyond the thesis: a systematic heading drift of the odometry in
        rad/m (positive: the odometry believes the robot turned left), whose
        share ``drift * p_n`` of each measured heading change is removed,
        ``p_n`` the odometry path between the two lines' mean headings
        (``S_n/2 + l_n + S_{n+1}/2``, needs the transits). ``"estimate"``:
        the drift is a further unknown of the fit (maximum likelihood; solver
        ``"varpro"`` and the signed angle term only). A random-walk noise
        model does not cover drift, and the likelihood trusts the heading
        changes (docs/odometry.md). None: no correction.
    ridge : float, default 0.0
        L2 penalty ``ridge / 2 * ||W||^2`` on the weights of the expanded
        features (not the bias); beyond the thesis. It shrinks the map
        towards a constant, which the distances resist; off by default
        (docs/odometry.md).
    init : {"random", "odometry"} or mapping, default "random"
        ``"random"`` (thesis, simulator): alpha uniform in [0, 2 pi), origins
        uniform in +-``origin_range``, W uniform in +-``weight_range``.
        ``"odometry"`` (thesis, real robot): alpha and origins from the
        odometry headings and line starts, W by least squares from the
        features to the odometry positions of the line samples. A mapping with
        ``"alpha"`` (L,), ``"origins"`` (L, 2), ``"weights"`` (K, 2) warm-starts
        (``"varpro"`` uses ``"alpha"`` only).
    learning_rate : float or None, default None
        beta of (5.7), solver ``"gd"`` only. None: the thesis's 1e-5, or 0.3
        with ``precondition``. The cost is a sum over samples, so a good
        (unpreconditioned) learning rate shrinks as they grow.
    momentum : float, default 0.95
        gamma of (5.7), solver ``"gd"`` only.
    precondition : bool, default False
        Solver ``"gd"`` only, beyond the thesis: scale the gradient by the
        inverse of each block's curvature, ``(Phi^T Phi)^+`` for W,
        ``1 / sum_m d_{n,m}^2`` for alpha_n and ``1 / M_n`` for o_n (block
        Jacobi). The expanded features are strongly correlated, which makes
        plain gradient descent crawl along W's flat directions.
    max_iter : int, default 5000
        Iteration limit (per start).
    tol : float, default 1e-7
        Stop when the relative decrease of the cost over an iteration,
        ``(C_{t-1} - C_t) / C_{t-1}``, falls below ``tol`` (for ``"gd"``: in
        absolute value; for the L-BFGS solvers this is scipy's ``ftol``).
    n_init : int, default 1
        Starts from independent random initialisations (``init="random"``);
        the lowest final cost wins.
    fix_alpha : mapping int -> float, optional
        Line orientations (radians) held fixed, e.g. ``{0: 0.0}``.
    fix_origin : mapping int -> (x, y), optional
        Line origins (metres) held fixed, e.g. ``{0: (0.0, 0.0)}``.
    origin_range : float or (float, float), optional
        Half-width in metres of the random origins per axis; default half the
        longest line (thesis: 8 and 9 m on a 16 x 18 m area).
    weight_range : float, default 1.0
        Half-width of the random weights (thesis: 1).
    snapshot_iterations : sequence of int, default ()
        Iterations at which the parameters are recorded in ``snapshots_``
        (e.g. (0, 500, 1000) for :func:`plot_metric_lines`, fig. 5.19).
    segmentation : mapping, optional
        Keyword arguments for :func:`sfanav.odometry.segment_lines` when
        :meth:`fit` is given odometry poses.
    random_state : int, Generator or None
        Seed of the random initialisation.

    Attributes
    ----------
    weights_ : ndarray (K, 2)
        W; row 0 multiplies the bias 1, rows 1.. the expanded features.
    coef_, intercept_ : ndarray (K - 1, 2), (2,)
        The same split into the expanded features' weights and the bias.
    alpha_ : ndarray (L,)
        Line orientations, radians.
    origins_ : ndarray (L, 2)
        Line origins, metres.
    lines_ : Lines
        The lines fitted on.
    cost_ : float
        Final cost (5.1 or 5.5), evaluated on all parameters.
    cost_history_ : ndarray
        Cost at iteration 0 (initialisation), 1, 2, ... of the winning start.
    n_iter_ : int
        Iterations of the winning start.
    n_iter_total_ : int
        Iterations over all starts.
    fit_time_ : float
        Wall time of :meth:`fit` in seconds.
    converged_ : bool
        True if the winning start stopped on ``tol`` rather than ``max_iter``.
    start_costs_ : ndarray (n_init,)
        Final cost of each start.
    snapshots_ : dict int -> dict
        ``{iteration: {"alpha", "origins", "weights"}}`` of the winning start,
        at ``snapshot_iterations`` (those reached) and at the last iteration.
    angle_term_ : str or None
        The angle term used.
    angle_weights_ : ndarray (L - 1,)
        Weight of the angle term per pair of lines (0 without an angle term).
    transit_weights_ : ndarray (L - 1,)
        Weight of the transit term per pair of lines (0: off).
    feature_noise_ : float or None
        ``sigma_f`` (metres) the ``"noise"`` weights used (estimated or given);
        None without them.
    noise_iterations_ : int
        Fits of the ``sigma_f`` alternation (1 without it).
    heading_drift_ : float
        The heading drift (rad/m) removed from the heading changes (given,
        estimated, or 0).
    learning_rate_ : float
        The learning rate used (solver ``"gd"``).
    n_features_in_ : int
        Feature columns seen in fit.
    """

    def __init__(
        self,
        n_outputs: int = 8,
        degree: int = 2,
        *,
        solver: str = "varpro",
        angle_term: str | None = "auto",
        angle_weight: float | str = 1.0,
        transit_weight: float | str = 0.0,
        odometry_noise: Any = None,
        feature_noise: float | None = None,
        heading_drift: float | str | None = None,
        ridge: float = 0.0,
        init: str | Mapping[str, Any] = "random",
        learning_rate: float | None = None,
        momentum: float = 0.95,
        precondition: bool = False,
        max_iter: int = 5000,
        tol: float = 1e-7,
        n_init: int = 1,
        fix_alpha: Mapping[int, float] | None = None,
        fix_origin: Mapping[int, Any] | None = None,
        origin_range: float | tuple[float, float] | None = None,
        weight_range: float = 1.0,
        snapshot_iterations: Sequence[int] = (),
        segmentation: Mapping[str, Any] | None = None,
        random_state: int | np.random.Generator | None = None,
    ) -> None:
        self.n_outputs = n_outputs
        self.degree = degree
        self.solver = solver
        self.angle_term = angle_term
        self.angle_weight = angle_weight
        self.transit_weight = transit_weight
        self.odometry_noise = odometry_noise
        self.feature_noise = feature_noise
        self.heading_drift = heading_drift
        self.ridge = ridge
        self.init = init
        self.learning_rate = learning_rate
        self.momentum = momentum
        self.precondition = precondition
        self.max_iter = max_iter
        self.tol = tol
        self.n_init = n_init
        self.fix_alpha = fix_alpha
        self.fix_origin = fix_origin
        self.origin_range = origin_range
        self.weight_range = weight_range
        self.snapshot_iterations = snapshot_iterations
        self.segmentation = segmentation
        self.random_state = random_state

    _PARAMS = (
        "n_outputs", "degree", "solver", "angle_term", "angle_weight", "transit_weight", "odometry_noise",
        "feature_noise", "heading_drift", "ridge", "init", "learning_rate", "momentum", "precondition",
        "max_iter", "tol", "n_init", "fix_alpha", "fix_origin", "origin_range", "weight_range",
        "snapshot_iterations", "segmentation", "random_state",
    )

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self._PARAMS}

    def set_params(self, **params: Any) -> "MetricLearner":
        for k, v in params.items():
            if k not in self._PARAMS:
                raise ValueError(f"unknown parameter {k!r} for MetricLearner")
            setattr(self, k, v)
        return self

    def __repr__(self) -> str:
        state = "fitted" if hasattr(self, "weights_") else "not fitted"
        return (
            f"MetricLearner(n_outputs={self.n_outputs!r}, degree={self.degree!r}, solver={self.solver!r}, "
            f"angle_term={self.angle_term!r}, init={self.init if isinstance(self.init, str) else 'given'!r}) "
            f"<{state}>"
        )

    # ------------------------------------------------------------ design
    def _design(self, features: Any, n: int, degree: int, name: str = "features") -> np.ndarray:
        F = as_matrix(features, name)
        if F.shape[1] < n:
            raise ValueError(f"{name} has {F.shape[1]} columns, but the learner uses the first {n}")
        E = expand(np.ascontiguousarray(F[:, :n]), degree)
        return np.hstack([np.ones((len(E), 1)), E])

    def _lines(self, odometry: Any, n_samples: int) -> Lines:
        if isinstance(odometry, Lines):
            lines = odometry
        else:
            P = np.asarray(odometry) if not isinstance(odometry, np.ndarray) else odometry
            if P.ndim == 2 and P.shape[1] == 3:
                lines = segment_lines(P, **dict(self.segmentation or {}))
            else:
                raise ValueError(
                    "odometry must be poses of shape (N, 3) (x [m], y [m], heading [rad]) or a "
                    f"sfanav.odometry.Lines, got shape {getattr(P, 'shape', None)}"
                )
        if len(lines.labels) != n_samples:
            raise ValueError(
                f"features have {n_samples} rows but the odometry/lines have {len(lines.labels)}; they must match"
            )
        if lines.n_lines == 0:
            raise ValueError("no line found: every sample is labelled -1")
        return lines

    # ------------------------------------------------------------ fit
    def fit(self, features: Any, odometry: Any, *, progress: bool = True) -> "MetricLearner":
        """Learns the metric map.

        Parameters
        ----------
        features : array (N, m >= n_outputs)
            Slow features of the run, slowest first.
        odometry : array (N, 3) or Lines
            Odometry poses ``(x [m], y [m], heading [rad])`` of the same
            samples, split into lines with :func:`sfanav.odometry.segment_lines`
            (``segmentation`` keywords), or lines given directly
            (:func:`sfanav.odometry.lines_from_labels`).
        progress : bool, default True
            A tqdm progress bar over the iterations.

        Returns
        -------
        self
        """
        n = check_int(self.n_outputs, "n_outputs")
        degree = check_int(self.degree, "degree")
        if self.solver not in SOLVERS:
            raise ValueError(f"solver must be one of {SOLVERS}, got {self.solver!r}")
        if self.angle_term not in ANGLE_TERMS:
            raise ValueError(f"angle_term must be one of {ANGLE_TERMS}, got {self.angle_term!r}")
        lam_noise = isinstance(self.angle_weight, str)
        if lam_noise and self.angle_weight != "noise":
            raise ValueError(f"angle_weight must be a number >= 0 or 'noise', got {self.angle_weight!r}")
        lam = 0.0 if lam_noise else check_nonneg_float(self.angle_weight, "angle_weight")
        wt_noise = isinstance(self.transit_weight, str)
        if wt_noise and self.transit_weight != "noise":
            raise ValueError(f"transit_weight must be a number >= 0 or 'noise', got {self.transit_weight!r}")
        wt = 0.0 if wt_noise else check_nonneg_float(self.transit_weight, "transit_weight")
        sigma_f = None if self.feature_noise is None else check_nonneg_float(self.feature_noise, "feature_noise")
        if sigma_f is not None and sigma_f == 0:
            raise ValueError("feature_noise must be > 0 (metres), or None to estimate it")
        noise = noise_dict(self.odometry_noise) if (lam_noise or wt_noise) else None
        hd = self.heading_drift
        if isinstance(hd, str):
            if hd != "estimate":
                raise ValueError(f"heading_drift must be a number (rad/m), 'estimate' or None, got {hd!r}")
            if self.solver != "varpro":
                raise ValueError(f"heading_drift='estimate' needs solver='varpro', got solver={self.solver!r}")
        elif hd is not None:
            hd = float(hd)
            if not np.isfinite(hd):
                raise ValueError(f"heading_drift must be finite (rad/m), got {self.heading_drift!r}")
        lr_default = 0.3 if self.precondition else 1e-5
        lr = lr_default if self.learning_rate is None else check_nonneg_float(self.learning_rate, "learning_rate")
        mom = check_nonneg_float(self.momentum, "momentum")
        if mom > 1:
            raise ValueError(f"momentum must be in [0, 1], got {mom}")
        max_iter = check_int(self.max_iter, "max_iter")
        tol = check_nonneg_float(self.tol, "tol")
        n_init = check_int(self.n_init, "n_init")
        F = as_matrix(features, "features")
        if F.shape[1] < n:
            raise ValueError(f"n_outputs={n}, but features have only {F.shape[1]} columns")
        lines = self._lines(odometry, len(F))
        on = lines.mask
        L = lines.n_lines
        Phi = self._design(F[on], n, degree)
        lab, d = lines.labels[on], lines.distances[on]
        K = Phi.shape[1]
        n_params = 3 * L + 2 * K
        if len(lab) < 2 or 2 * len(lab) < n_params - 3:
            raise ValueError(
                f"too few points on lines: {len(lab)} samples on {L} lines give {2 * len(lab)} equations for "
                f"{n_params} parameters ({L} orientations, {2 * L} origin coordinates, {2 * K} weights); "
                "drive more or longer lines, or use fewer outputs"
            )
        angle_term = self.angle_term
        if angle_term == "auto":
            has = lines.relative_angles is not None and L > 1
            angle_term = ("signed" if lam_noise else "cos") if has else None
        if angle_term is not None and lines.relative_angles is None:
            raise ValueError(
                f"angle_term={angle_term!r} needs the measured relative angles between lines, but the lines have "
                "none: pass relative_angles to lines_from_labels, or use angle_term=None (cost 5.1)"
            )
        fix_a = _check_fixed(self.fix_alpha, "fix_alpha", 1)
        fix_o = _check_fixed(self.fix_origin, "fix_origin", 2)
        for name, fx in (("fix_alpha", fix_a), ("fix_origin", fix_o)):
            bad = [k for k in fx if k >= L]
            if bad:
                raise ValueError(f"{name} names line(s) {bad}, but only {L} lines were found (0..{L - 1})")
        ridge = check_nonneg_float(self.ridge, "ridge")
        transits = None
        if wt_noise or wt > 0:
            if L < 2:
                wt_noise, wt = False, 0.0
            elif lines.origins is None or lines.headings is None:
                raise ValueError(
                    "transit_weight needs the odometry origins and headings of the lines (their transits): fit on "
                    "odometry poses, or use segment_lines / lines_from_odometry"
                )
            else:
                transits = lines.transits()
        drift_path, drift0 = None, 0.0
        if hd is not None and angle_term is not None and L > 1:
            if lines.transit_lengths is None:
                raise ValueError("heading_drift needs the transits between lines (their path lengths): use "
                                 "segment_lines or lines_from_odometry")
            if hd == "estimate" and angle_term != "signed":
                raise ValueError(f"heading_drift='estimate' needs angle_term='signed', got {angle_term!r}")
            S = lines.path_lengths()
            drift_path = S[:-1] / 2 + lines.transit_lengths + S[1:] / 2
            drift0 = 0.0 if hd == "estimate" else hd
        var_a = var_t = None
        if (lam_noise and angle_term is not None) or wt_noise:
            var_a, var_t = odometry_variances(lines, noise)
        use_noise = (lam_noise and angle_term is not None) or wt_noise
        rng = np.random.default_rng(self.random_state)
        snaps_at = sorted({check_int(int(i), "snapshot_iterations", minimum=0) for i in self.snapshot_iterations})

        def problem(s2, drift):
            la = s2 / var_a if (lam_noise and var_a is not None) else lam
            w = s2 / var_t if (wt_noise and var_t is not None) else wt
            return LineProblem(Phi, lab, d, lines.relative_angles, angle_term, la, fix_a, fix_o, ridge, transits, w,
                            drift_path, drift)

        t0 = time.perf_counter()
        best = None
        costs, total = [], 0
        n_rounds = 0
        s2 = None
        with one_blas_thread():
            if use_noise:
                if sigma_f is not None:
                    s2 = sigma_f**2
                else:
                    s2 = self._initial_residual_variance(Phi, lab, d, lines, n_params)
            pb = problem(s2, drift0)
            inits = self._inits(pb, lines, rng, n_init)
            while True:
                n_rounds += 1
                vp = VarPro(pb) if self.solver == "varpro" else None  # one factorisation for all starts
                best, costs = None, []
                for a0, O0, W0 in inits:
                    pb.drift = drift0
                    res = solve(pb, vp, a0, O0, W0, solver=self.solver, precondition=self.precondition,
                                heading_drift=self.heading_drift, lr=lr, mom=mom, max_iter=max_iter, tol=tol,
                                snaps_at=snaps_at, progress=progress)
                    costs.append(res["cost"])
                    total += res["n_iter"]
                    if best is None or res["cost"] < best["cost"]:
                        best = res
                if not use_noise or sigma_f is not None or n_rounds >= self._MAX_NOISE_ROUNDS:
                    break
                R = pb.residuals(best["alpha"], best["origins"], best["weights"])
                s2_new = max(float(np.einsum("ij,ij->", R, R)) / max(2 * len(lab) - n_params, 1), 1e-12)
                if abs(s2_new - s2) <= 1e-3 * s2:
                    break
                s2 = s2_new
                drift0 = best["drift"]
                pb = problem(s2, drift0)
                inits = [(best["alpha"], best["origins"], best["weights"])]
        self.fit_time_ = time.perf_counter() - t0
        assert best is not None
        self.angle_weights_ = pb.lam.copy() if pb.has_angle else np.zeros(max(L - 1, 0))
        self.transit_weights_ = pb.wt.copy()
        self.feature_noise_ = None if s2 is None else float(np.sqrt(s2))
        self.noise_iterations_ = n_rounds
        pb.drift = best["drift"]
        self.heading_drift_ = float(best["drift"]) if drift_path is not None else 0.0
        self.alpha_ = best["alpha"]
        self.origins_ = best["origins"]
        self.weights_ = best["weights"]
        self.cost_ = float(best["cost"])
        self.cost_history_ = np.asarray(best["history"], dtype=np.float64)
        self.n_iter_ = int(best["n_iter"])
        self.n_iter_total_ = int(total)
        self.converged_ = bool(best["converged"])
        self.snapshots_ = best["snapshots"]
        self.start_costs_ = np.asarray(costs)
        self.lines_ = lines
        self.angle_term_ = angle_term
        self.learning_rate_ = lr
        self.n_outputs_ = n
        self.degree_ = degree
        self.n_features_in_ = F.shape[1]
        return self

    _MAX_NOISE_ROUNDS = 30

    @staticmethod
    def _initial_residual_variance(Phi, lab, d, lines: Lines, n_params: int) -> float:
        """Residual variance per coordinate (m^2) of the regression of the
        features onto the odometry's line positions: the starting sigma_f^2."""
        if lines.headings is None or lines.origins is None:
            raise ValueError("estimating feature_noise needs the odometry origins and headings of the lines; "
                             "give feature_noise")
        a, O = lines.headings, lines.origins
        target = O[lab] + d[:, None] * np.c_[np.cos(a), np.sin(a)][lab]
        W = np.linalg.lstsq(Phi, target, rcond=None)[0]
        R = target - Phi @ W
        return max(float(np.einsum("ij,ij->", R, R)) / max(2 * len(lab) - n_params, 1), 1e-12)

    def _inits(self, pb: LineProblem, lines: Lines, rng: np.random.Generator, n_init: int):
        L, K = pb.L, pb.K
        init = self.init
        if isinstance(init, Mapping):
            a0 = np.asarray(init.get("alpha"), dtype=np.float64)
            if a0.shape != (L,):
                raise ValueError(f"init['alpha'] must have shape ({L},) for {L} lines, got {a0.shape}")
            O0 = np.asarray(init.get("origins", np.zeros((L, 2))), dtype=np.float64)
            W0 = np.asarray(init.get("weights", np.zeros((K, 2))), dtype=np.float64)
            if O0.shape != (L, 2) or W0.shape != (K, 2):
                raise ValueError(
                    f"init['origins'] and init['weights'] must have shapes ({L}, 2) and ({K}, 2), "
                    f"got {O0.shape} and {W0.shape}"
                )
            a0, O0 = pb.apply_fixed(a0, O0)
            return [(a0, O0, W0)]
        if init == "odometry":
            if lines.headings is None or lines.origins is None:
                raise ValueError(
                    "init='odometry' needs the odometry headings and line origins: fit on odometry poses, or "
                    "pass headings and origins to lines_from_labels"
                )
            a0, O0 = pb.apply_fixed(lines.headings.copy(), lines.origins.copy())
            target = O0[pb.lab] + pb.d[:, None] * np.c_[np.cos(a0), np.sin(a0)][pb.lab]
            W0 = np.linalg.lstsq(pb.Phi, target, rcond=None)[0]
            return [(a0, O0, W0)]
        if init != "random":
            raise ValueError(f"init must be 'random', 'odometry' or a mapping of arrays, got {init!r}")
        if self.origin_range is None:
            half = 0.5 * float(lines.lengths().max())
            ox = oy = max(half, 1e-6)
        else:
            rr = np.broadcast_to(np.asarray(self.origin_range, dtype=np.float64), (2,))
            if not np.all(np.isfinite(rr)) or np.any(rr < 0):
                raise ValueError(f"origin_range must be finite and >= 0, got {self.origin_range!r}")
            ox, oy = float(rr[0]), float(rr[1])
        wr = check_nonneg_float(self.weight_range, "weight_range")
        out = []
        for _ in range(n_init):
            a0 = rng.uniform(0, 2 * np.pi, L)
            O0 = np.c_[rng.uniform(-ox, ox, L), rng.uniform(-oy, oy, L)]
            W0 = rng.uniform(-wr, wr, (K, 2))
            a0, O0 = pb.apply_fixed(a0, O0)
            out.append((a0, O0, W0))
        return out

    # ------------------------------------------------------------ inference
    def _check_fitted(self) -> None:
        if not hasattr(self, "weights_"):
            raise NotFittedError("this MetricLearner is not fitted yet; call fit first")

    @property
    def coef_(self) -> np.ndarray:
        self._check_fitted()
        return self.weights_[1:]

    @property
    def intercept_(self) -> np.ndarray:
        self._check_fitted()
        return self.weights_[0]

    def transform(self, features: Any) -> np.ndarray:
        """Metric positions (N, 2) in metres (in the learned frame, see the
        module docstring) of features (N, m >= n_outputs_)."""
        self._check_fitted()
        F = as_matrix(features, "features")
        if F.shape[1] != self.n_features_in_:
            raise ValueError(
                f"features have {F.shape[1]} columns, but this MetricLearner was fitted with {self.n_features_in_}"
            )
        return self._design(F, self.n_outputs_, self.degree_) @ self.weights_

    predict = transform

    def fit_transform(self, features: Any, odometry: Any, **kw: Any) -> np.ndarray:
        """:meth:`fit`, then :meth:`transform` of the same features."""
        return self.fit(features, odometry, **kw).transform(features)

    def line_points(self, snapshot: int | None = None) -> np.ndarray:
        """Line-model positions ``o_n + d u(alpha_n)`` (N, 2) in metres of the
        training samples (NaN rows off the lines), with the final parameters
        or those of ``snapshots_[snapshot]``."""
        self._check_fitted()
        a, O, _ = self._snapshot(snapshot)
        lab, d = self.lines_.labels, self.lines_.distances
        out = np.full((len(lab), 2), np.nan)
        on = lab >= 0
        out[on] = O[lab[on]] + d[on, None] * np.c_[np.cos(a), np.sin(a)][lab[on]]
        return out

    def _snapshot(self, snapshot: int | None):
        if snapshot is None:
            return self.alpha_, self.origins_, self.weights_
        if snapshot not in self.snapshots_:
            raise ValueError(f"no snapshot at iteration {snapshot}; recorded: {sorted(self.snapshots_)}")
        s = self.snapshots_[snapshot]
        return s["alpha"], s["origins"], s["weights"]

    def transform_snapshot(self, features: Any, snapshot: int) -> np.ndarray:
        """As :meth:`transform`, with W of ``snapshots_[snapshot]``."""
        self._check_fitted()
        _, _, W = self._snapshot(snapshot)
        F = as_matrix(features, "features")
        return self._design(F, self.n_outputs_, self.degree_) @ W

    # ------------------------------------------------------------ persistence
    def save(self, path: str | os.PathLike) -> Path:
        """Saves the fitted learner as a model file (kind ``"MetricLearner"``,
        pickle-free); read back with :func:`sfanav.load`. ``init`` given as
        arrays and ``random_state`` generators are not stored."""
        self._check_fitted()
        lines = self.lines_
        params = {k: getattr(self, k) for k in self._PARAMS}
        params["init"] = self.init if isinstance(self.init, str) else "random"
        params["random_state"] = self.random_state if isinstance(self.random_state, (int, np.integer)) else None
        params["fix_alpha"] = [[int(k), float(v)] for k, v in (self.fix_alpha or {}).items()]
        params["fix_origin"] = [[int(k), [float(x) for x in v]] for k, v in (self.fix_origin or {}).items()]
        params["snapshot_iterations"] = [int(i) for i in self.snapshot_iterations]
        params["segmentation"] = dict(self.segmentation or {})
        params["odometry_noise"] = None if self.odometry_noise is None else noise_dict(self.odometry_noise)
        if params["origin_range"] is not None:
            params["origin_range"] = np.broadcast_to(np.asarray(params["origin_range"], float), (2,)).tolist()
        state = {
            "params": params,
            "weights": self.weights_,
            "alpha": self.alpha_,
            "origins": self.origins_,
            "cost": self.cost_,
            "cost_history": self.cost_history_,
            "n_iter": self.n_iter_,
            "n_iter_total": self.n_iter_total_,
            "fit_time": self.fit_time_,
            "converged": self.converged_,
            "start_costs": self.start_costs_,
            "angle_term": self.angle_term_,
            "angle_weights": self.angle_weights_,
            "transit_weights": self.transit_weights_,
            "feature_noise": -1.0 if self.feature_noise_ is None else self.feature_noise_,
            "noise_iterations": self.noise_iterations_,
            "heading_drift": self.heading_drift_,
            "learning_rate": self.learning_rate_,
            "n_outputs": self.n_outputs_,
            "degree": self.degree_,
            "n_features_in": self.n_features_in_,
            "lines": {
                "labels": lines.labels,
                "distances": np.nan_to_num(lines.distances, nan=0.0),
                "relative_angles": lines.relative_angles,
                "headings": lines.headings,
                "origins": lines.origins,
                "transit_lengths": lines.transit_lengths,
                "transit_turns": lines.transit_turns,
            },
        }
        return save_model(path, "MetricLearner", state)

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> "MetricLearner":
        try:
            p = dict(state["params"])
            p["fix_alpha"] = {int(k): float(v) for k, v in p["fix_alpha"]} or None
            p["fix_origin"] = {int(k): tuple(v) for k, v in p["fix_origin"]} or None
            p["snapshot_iterations"] = tuple(p["snapshot_iterations"])
            if p["origin_range"] is not None:
                p["origin_range"] = tuple(p["origin_range"])
            m = cls(**p)
            m.weights_ = np.asarray(state["weights"], dtype=np.float64)
            m.alpha_ = np.asarray(state["alpha"], dtype=np.float64)
            m.origins_ = np.asarray(state["origins"], dtype=np.float64)
            m.cost_ = float(state["cost"])
            m.cost_history_ = np.asarray(state["cost_history"], dtype=np.float64)
            m.n_iter_ = int(state["n_iter"])
            m.n_iter_total_ = int(state["n_iter_total"])
            m.fit_time_ = float(state["fit_time"])
            m.converged_ = bool(state["converged"])
            m.start_costs_ = np.asarray(state["start_costs"], dtype=np.float64)
            m.angle_term_ = state["angle_term"]
            L1 = max(len(np.asarray(state["alpha"])) - 1, 0)
            m.angle_weights_ = np.asarray(state.get("angle_weights", np.zeros(L1)), dtype=np.float64)
            m.transit_weights_ = np.asarray(state.get("transit_weights", np.zeros(L1)), dtype=np.float64)
            fn = float(state.get("feature_noise", -1.0))
            m.feature_noise_ = None if fn < 0 else fn
            m.noise_iterations_ = int(state.get("noise_iterations", 1))
            m.heading_drift_ = float(state.get("heading_drift", 0.0))
            m.learning_rate_ = float(state["learning_rate"])
            m.n_outputs_ = int(state["n_outputs"])
            m.degree_ = int(state["degree"])
            m.n_features_in_ = int(state["n_features_in"])
            ls = state["lines"]
            lab = np.asarray(ls["labels"])
            dist = np.where(lab >= 0, np.asarray(ls["distances"], dtype=np.float64), np.nan)
            m.lines_ = Lines(lab, dist, ls["relative_angles"], ls["headings"], ls["origins"],
                             ls.get("transit_lengths"), ls.get("transit_turns"))
        except (KeyError, TypeError) as exc:
            raise ValueError(f"invalid MetricLearner state: {exc}") from None
        want = expanded_dim(m.n_outputs_, m.degree_) + 1
        if m.weights_.shape != (want, 2) or m.alpha_.shape != (m.lines_.n_lines,):
            raise ValueError(
                f"invalid MetricLearner state: weights of shape {m.weights_.shape} (want ({want}, 2)) or "
                f"{m.alpha_.shape[0]} orientations for {m.lines_.n_lines} lines"
            )
        m.snapshots_ = {m.n_iter_: {"alpha": m.alpha_, "origins": m.origins_, "weights": m.weights_}}
        return m


register_loader("MetricLearner", MetricLearner.from_state)
