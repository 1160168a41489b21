"""The cost of unsupervised metric learning (thesis 5.3.1) and its gradient:
:func:`metric_cost`, the line problem it is evaluated on, variable
projection (orientations only; origins and map eliminated in closed form),
and the odometry noise model behind the maximum-likelihood weights
(:func:`odometry_variances`). The cost and its derivation: docs/odometry.md."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from .._checks import check_nonneg_float
from .lines import Lines

SOLVERS = ("gd", "lbfgs", "varpro")


ANGLE_TERMS = ("auto", "cos", "signed", None)


def metric_cost(
    alpha: Any,
    origins: Any,
    weights: Any,
    design: Any,
    labels: Any,
    distances: Any,
    relative_angles: Any = None,
    *,
    angle_term: str | None = "cos",
    angle_weight: Any = 1.0,
    ridge: float = 0.0,
    transits: Any = None,
    transit_weight: Any = 0.0,
) -> tuple[float, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Cost (thesis 5.1, or 5.5 with the angle term) and its gradient.

    Parameters
    ----------
    alpha : array (L,)
        Line orientations, radians.
    origins : array (L, 2)
        Line origins, metres.
    weights : array (K, 2)
        W: expanded features (with the bias column) to metres.
    design : array (M, K)
        Expanded features of the M samples on lines (bias column included).
    labels : int array (M,)
        Line of each sample, 0..L-1.
    distances : array (M,)
        Distance along the line from its origin, metres.
    relative_angles : array (L - 1,), optional
        Measured heading change from line n to n+1, radians. Needed by the
        angle term; ignored without it.
    angle_term : {"cos", "signed", None}
        ``"cos"``: the thesis's (5.5); ``"signed"``: ``1 - cos`` of the
        difference of signed turns; None: cost (5.1).
    angle_weight : float or array (L - 1,)
        Weight lambda of the angle term (thesis: 1), or one per pair of
        consecutive lines.
    ridge : float
        Adds ``ridge / 2 * ||W[1:]||^2`` (not the bias row; beyond the thesis).
    transits : array (L - 1, 2), optional
        Odometry displacement ``q_n`` from the origin of line n to that of
        line n+1 in line n's frame (metres; :meth:`sfanav.odometry.Lines.transits`).
        Beyond the thesis: adds, with ``t_n = o_{n+1} - o_n - q_{n,x} u(alpha_n)
        - q_{n,y} u'(alpha_n)``, the term ``1/2 sum_n w_n ||t_n||^2``.
    transit_weight : float or array (L - 1,)
        Weight ``w_n`` of the transit term (0: off).

    Returns
    -------
    cost : float
    (grad_alpha, grad_origins, grad_weights) : arrays of shapes (L,), (L, 2), (K, 2)
    """
    a = np.asarray(alpha, dtype=np.float64)
    O = np.asarray(origins, dtype=np.float64)
    W = np.asarray(weights, dtype=np.float64)
    Phi = np.asarray(design, dtype=np.float64)
    lab = np.asarray(labels)
    d = np.asarray(distances, dtype=np.float64)
    ca, sa = np.cos(a), np.sin(a)
    R = O[lab] + d[:, None] * np.c_[ca, sa][lab] - Phi @ W
    cost = 0.5 * float(np.einsum("ij,ij->", R, R))
    L = len(a)
    g_a = np.bincount(lab, weights=d * (-sa[lab] * R[:, 0] + ca[lab] * R[:, 1]), minlength=L)
    g_o = np.c_[np.bincount(lab, weights=R[:, 0], minlength=L), np.bincount(lab, weights=R[:, 1], minlength=L)]
    g_W = -Phi.T @ R
    if ridge:
        cost += 0.5 * ridge * float(np.einsum("ij,ij->", W[1:], W[1:]))
        g_W[1:] += ridge * W[1:]
    if angle_term is not None and relative_angles is not None and L > 1:
        if angle_term not in ("cos", "signed"):
            raise ValueError(f"angle_term must be 'cos', 'signed' or None, got {angle_term!r}")
        c_ang, g_ang = _angle_cost(a, np.asarray(relative_angles, dtype=np.float64), angle_term,
                                   np.broadcast_to(np.asarray(angle_weight, dtype=np.float64), (L - 1,)))
        cost += c_ang
        g_a += g_ang
    if transits is not None and L > 1:
        w = np.broadcast_to(np.asarray(transit_weight, dtype=np.float64), (L - 1,))
        if np.any(w):
            q = np.asarray(transits, dtype=np.float64)
            T = O[1:] - O[:-1] - q[:, :1] * np.c_[ca, sa][:-1] - q[:, 1:] * np.c_[-sa, ca][:-1]
            cost += 0.5 * float(np.sum(w * np.einsum("ij,ij->i", T, T)))
            wT = w[:, None] * T
            g_o[1:] += wT
            g_o[:-1] -= wT
            # dt_n / d alpha_n = -q_x u'(alpha_n) + q_y u(alpha_n)
            dT = -q[:, :1] * np.c_[-sa, ca][:-1] + q[:, 1:] * np.c_[ca, sa][:-1]
            g_a[:-1] += np.einsum("ij,ij->i", wT, dT)
    return cost, (g_a, g_o, g_W)


def _angle_cost(a: np.ndarray, phi: np.ndarray, angle_term: str, lam: np.ndarray) -> tuple[float, np.ndarray]:
    """The angle term and its gradient in alpha, with one weight per pair."""
    grad = np.zeros_like(a)
    if angle_term == "cos":
        delta = a[:-1] - a[1:]
        e = np.cos(delta) - np.cos(phi)
        cost = 0.5 * float(np.sum(lam * e * e))
        g = lam * e * np.sin(delta)
        grad[:-1] -= g
        grad[1:] += g
    else:
        delta = a[1:] - a[:-1] - phi
        cost = float(np.sum(lam * (1.0 - np.cos(delta))))
        g = lam * np.sin(delta)
        grad[1:] += g
        grad[:-1] -= g
    return cost, grad


class LineProblem:
    """The data of one fit: design, labels, distances, angles, transits, weights, fixed parameters."""

    def __init__(self, Phi, lab, d, phi, angle_term, lam, fix_alpha, fix_origin, ridge=0.0, transits=None,
                 transit_weight=0.0, drift_path=None, drift=0.0):
        self.Phi, self.lab, self.d, self.phi0, self.ridge = Phi, lab, d, phi, ridge
        # heading drift (rad/m) times the odometry path between the lines' mean headings: the drift's
        # share of the measured heading changes, removed from them
        self.drift_path, self.drift = drift_path, float(drift)
        self.angle_term = angle_term
        self.L, self.K = int(lab.max()) + 1, Phi.shape[1]
        self.lam = np.broadcast_to(np.asarray(lam, dtype=np.float64), (max(self.L - 1, 0),)).copy()
        wt = np.broadcast_to(np.asarray(transit_weight, dtype=np.float64), (max(self.L - 1, 0),)).copy()
        self.transits = transits if (transits is not None and np.any(wt)) else None
        self.wt = wt if self.transits is not None else np.zeros(max(self.L - 1, 0))
        self.fix_alpha, self.fix_origin = fix_alpha, fix_origin
        free_a = np.ones(self.L, bool)
        free_a[list(fix_alpha)] = False
        free_o = np.ones(self.L, bool)
        free_o[list(fix_origin)] = False
        self.free_a, self.free_o = free_a, free_o
        # free-parameter mask over the packed vector [alpha (L), origins (L*2), W (K*2)]
        self.free = np.concatenate([free_a, np.repeat(free_o, 2), np.ones(2 * self.K, bool)])

    @property
    def phi(self):
        if self.phi0 is None or self.drift_path is None or not self.drift:
            return self.phi0
        return self.phi0 - self.drift * self.drift_path

    @property
    def has_angle(self) -> bool:
        return self.angle_term is not None and self.phi is not None and self.L > 1

    def cost(self, a, O, W):
        return metric_cost(a, O, W, self.Phi, self.lab, self.d, self.phi,
                           angle_term=self.angle_term, angle_weight=self.lam, ridge=self.ridge,
                           transits=self.transits, transit_weight=self.wt)

    def residuals(self, a, O, W):
        """Residuals (M, 2) of the line samples, metres."""
        return O[self.lab] + self.d[:, None] * np.c_[np.cos(a), np.sin(a)][self.lab] - self.Phi @ W

    def pack(self, a, O, W):
        return np.concatenate([a, O.ravel(), W.ravel()])

    def unpack(self, theta):
        L, K = self.L, self.K
        return theta[:L], theta[L : 3 * L].reshape(L, 2), theta[3 * L :].reshape(K, 2)

    def apply_fixed(self, a, O):
        a, O = a.copy(), O.copy()
        for n, v in self.fix_alpha.items():
            a[n] = v
        for n, v in self.fix_origin.items():
            O[n] = v
        return a, O


class VarPro:
    """The cost as a function of the line orientations alone: for fixed
    alpha, origins and W solve a linear least-squares problem (see the
    module docstring and docs/odometry.md).

    All residuals are linear in the origins and W and in ``z = (cos alpha,
    sin alpha)``: stacked per coordinate, ``r_x = A theta_x + M_x z + f_x``
    and ``r_y = A theta_y + M_y z + f_y`` with the same A (sample rows
    ``[E, -Phi]``, transit rows ``sqrt(w_n) (e_{n+1} - e_n)`` on the
    origins, ridge rows on W). With ``P = I - A A^+`` the cost is
    ``1/2 z^T G z + h^T z + kappa`` + angle term, ``G = sum (P M)^T (P M)``,
    ``h = sum (P M)^T P f``."""

    def __init__(self, pb: LineProblem):
        self.pb = pb
        L, m0, K = pb.L, len(pb.lab), pb.K
        nf = int(pb.free_o.sum())
        col = -np.ones(L, dtype=np.int64)
        col[pb.free_o] = np.arange(nf)
        blocks_A, blocks_Mx, blocks_My, blocks_fx, blocks_fy = [], [], [], [], []
        # samples: o_n + d u(alpha_n) - W^T s
        E = np.zeros((m0, nf + K))
        fr = col[pb.lab] >= 0
        E[np.flatnonzero(fr), col[pb.lab[fr]]] = 1.0
        E[:, nf:] = -pb.Phi
        blocks_A.append(E)
        Dm = np.zeros((m0, L))
        Dm[np.arange(m0), pb.lab] = pb.d
        Z = np.zeros((m0, L))
        blocks_Mx.append(np.hstack([Dm, Z]))
        blocks_My.append(np.hstack([Z, Dm]))
        fx, fy = np.zeros(m0), np.zeros(m0)
        for n, (ox, oy) in pb.fix_origin.items():
            fx[pb.lab == n] = ox
            fy[pb.lab == n] = oy
        blocks_fx.append(fx)
        blocks_fy.append(fy)
        if pb.transits is not None:
            # sqrt(w) (o_{n+1} - o_n - q_x u(alpha_n) - q_y u'(alpha_n)), u' = (-sin, cos)
            sw = np.sqrt(pb.wt)
            q = pb.transits
            T = np.zeros((L - 1, nf + K))
            tfx, tfy = np.zeros(L - 1), np.zeros(L - 1)
            for n in range(L - 1):
                for m, sign in ((n + 1, 1.0), (n, -1.0)):
                    if col[m] >= 0:
                        T[n, col[m]] += sign * sw[n]
                    else:
                        tfx[n] += sign * sw[n] * pb.fix_origin[m][0]
                        tfy[n] += sign * sw[n] * pb.fix_origin[m][1]
            Cx, Sx = np.zeros((L - 1, L)), np.zeros((L - 1, L))
            Cy, Sy = np.zeros((L - 1, L)), np.zeros((L - 1, L))
            idx = np.arange(L - 1)
            Cx[idx, idx] = -sw * q[:, 0]
            Sx[idx, idx] = sw * q[:, 1]
            Cy[idx, idx] = -sw * q[:, 1]
            Sy[idx, idx] = -sw * q[:, 0]
            blocks_A.append(T)
            blocks_Mx.append(np.hstack([Cx, Sx]))
            blocks_My.append(np.hstack([Cy, Sy]))
            blocks_fx.append(tfx)
            blocks_fy.append(tfy)
        if pb.ridge:
            # ridge on W[1:] as extra residual rows sqrt(ridge) * W[1:] (with M = f = 0 there)
            J = np.zeros((K - 1, nf + K))
            J[:, nf + 1 :] = np.sqrt(pb.ridge) * np.eye(K - 1)
            blocks_A.append(J)
            blocks_Mx.append(np.zeros((K - 1, 2 * L)))
            blocks_My.append(np.zeros((K - 1, 2 * L)))
            blocks_fx.append(np.zeros(K - 1))
            blocks_fy.append(np.zeros(K - 1))
        self.A = np.vstack(blocks_A)
        self.Mx, self.My = np.vstack(blocks_Mx), np.vstack(blocks_My)
        self.fx, self.fy = np.concatenate(blocks_fx), np.concatenate(blocks_fy)
        self.nf = nf
        U, S, Vt = np.linalg.svd(self.A, full_matrices=False)
        rank = int((S > S[0] * max(self.A.shape) * np.finfo(float).eps).sum())
        self.U, self.S, self.Vt, self.rank = U[:, :rank], S[:rank], Vt[:rank], rank
        Q = self.U
        G = np.zeros((2 * L, 2 * L))
        h = np.zeros(2 * L)
        kappa = 0.0
        for Mm, f in ((self.Mx, self.fx), (self.My, self.fy)):
            PM = Mm - Q @ (Q.T @ Mm)
            Pf = f - Q @ (Q.T @ f)
            G += PM.T @ PM
            h += PM.T @ Pf
            kappa += 0.5 * float(Pf @ Pf)
        self.G, self.h, self.kappa = G, h, kappa

    def cost(self, a):
        pb = self.pb
        L = pb.L
        c, s = np.cos(a), np.sin(a)
        z = np.concatenate([c, s])
        gz = self.G @ z + self.h
        cost = 0.5 * float(z @ (gz + self.h)) + self.kappa
        grad = -s * gz[:L] + c * gz[L:]
        if pb.has_angle:
            c_ang, g_ang = _angle_cost(a, pb.phi, pb.angle_term, pb.lam)
            cost += c_ang
            grad = grad + g_ang
        return cost, grad

    def drift_gradient(self, a):
        """d cost / d drift (signed angle term: phi_n = phi0_n - drift p_n)."""
        pb = self.pb
        delta = a[1:] - a[:-1] - pb.phi
        return float(np.sum(pb.lam * np.sin(delta) * pb.drift_path))

    def linear(self, a):
        """Origins (L, 2) and W (K, 2) minimising the cost for orientations ``a``."""
        pb = self.pb
        z = np.concatenate([np.cos(a), np.sin(a)])
        B = np.c_[self.Mx @ z + self.fx, self.My @ z + self.fy]
        theta = -(self.Vt.T @ ((self.U.T @ B) / self.S[:, None]))  # minimum-norm least squares
        nf = self.nf
        O = np.zeros((pb.L, 2))
        O[pb.free_o] = theta[:nf]
        for n, v in pb.fix_origin.items():
            O[n] = v
        return O, theta[nf:]


#: Random odometry noise assumed by ``angle_weight="noise"`` / ``transit_weight="noise"``
#: when none is given: the defaults of :class:`sfanav.sim.OdometryNoise` (a small
#: differential-drive robot; keys and units as there).
DEFAULT_ODOMETRY_NOISE = {"distance_sigma": 0.01, "heading_sigma": 0.004, "turn_sigma": 0.01}


def noise_dict(noise: Any) -> dict[str, float]:
    if noise is None:
        return dict(DEFAULT_ODOMETRY_NOISE)
    if hasattr(noise, "to_dict") and not isinstance(noise, Mapping):
        noise = noise.to_dict()
    if not isinstance(noise, Mapping):
        raise TypeError(
            "odometry_noise must be a mapping with distance_sigma (m/sqrt(m)), heading_sigma (rad/sqrt(m)) and "
            f"turn_sigma (rad/sqrt(rad)), or a sfanav.sim.OdometryNoise, got {type(noise).__name__}"
        )
    out = dict(DEFAULT_ODOMETRY_NOISE)
    for k in DEFAULT_ODOMETRY_NOISE:
        if k in noise:
            out[k] = check_nonneg_float(noise[k], f"odometry_noise[{k!r}]")
    return out


def odometry_variances(lines: Lines, noise: Any = None) -> tuple[np.ndarray, np.ndarray]:
    """Variances of the odometry's relative pose of consecutive lines under a
    random-walk noise model (beyond the thesis; the weights of
    ``MetricLearner(angle_weight="noise", transit_weight="noise")``).

    The odometry's heading error is a random walk with variance
    ``heading_sigma^2`` per metre driven and ``turn_sigma^2`` per radian
    turned, its distance error one with ``distance_sigma^2`` per metre (the
    random terms of :class:`sfanav.sim.OdometryNoise`). A line's heading is
    the mean over the line, and the mean of a random walk over a path of
    length S varies by S/3 of its end variance. Hence, with ``S_n`` the path
    length of line n, ``l_n`` and ``rho_n`` the path length and absolute turn
    of the transit to line n+1, and ``g_n`` the transit's displacement from
    the end of line n to the start of line n+1:

        var(phi_n) = heading_sigma^2 (S_n/3 + l_n + S_{n+1}/3) + turn_sigma^2 rho_n
        var(t_n)   = 1/2 [distance_sigma^2 (S_n/3 + l_n + S_{n+1}/3)
                          + |g_n|^2 (heading_sigma^2 (S_n/3 + l_n) + turn_sigma^2 rho_n)]

    ``var(t_n)`` is per coordinate: half the along-track plus cross-track
    variance of the transit (an isotropic approximation, which keeps the
    transit term linear in the origins).

    Parameters
    ----------
    lines : Lines
        With ``origins``, ``headings``, ``transit_lengths`` and ``transit_turns``
        (:func:`sfanav.odometry.segment_lines`, :func:`sfanav.odometry.lines_from_odometry`).
    noise : mapping or sfanav.sim.OdometryNoise, optional
        ``distance_sigma`` (m/sqrt(m)), ``heading_sigma`` (rad/sqrt(m)),
        ``turn_sigma`` (rad/sqrt(rad)); missing keys take
        :data:`DEFAULT_ODOMETRY_NOISE`.

    Returns
    -------
    var_angle : ndarray (L - 1,)
        rad^2.
    var_transit : ndarray (L - 1,)
        m^2 per coordinate.
    """
    if not isinstance(lines, Lines):
        raise TypeError(f"lines must be a sfanav.odometry.Lines, got {type(lines).__name__}")
    if lines.transit_lengths is None or lines.transit_turns is None or lines.origins is None or lines.headings is None:
        raise ValueError(
            "the odometry noise model needs the transits between lines (path length and turn) and the lines' "
            "odometry origins and headings: use segment_lines or lines_from_odometry"
        )
    nz = noise_dict(noise)
    sd2, sh2, st2 = nz["distance_sigma"] ** 2, nz["heading_sigma"] ** 2, nz["turn_sigma"] ** 2
    S = lines.path_lengths()
    ell, rho = lines.transit_lengths, lines.transit_turns
    seg = S[:-1] / 3 + ell + S[1:] / 3
    var_a = sh2 * seg + st2 * rho
    L = lines.n_lines
    last = np.array([lines.distances[np.flatnonzero(lines.labels == n)[-1]] for n in range(L - 1)])
    g = lines.transits() - np.c_[last, np.zeros(L - 1)]
    var_t = 0.5 * (sd2 * seg + np.einsum("ij,ij->i", g, g) * (sh2 * (S[:-1] / 3 + ell) + st2 * rho))
    tiny = 1e-12
    return np.maximum(var_a, tiny), np.maximum(var_t, tiny)
