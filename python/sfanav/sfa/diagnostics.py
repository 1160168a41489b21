"""Diagnostics of slow features (thesis 5.1.3): delta values of signals, eta
values of the outputs under simulated rotation (how much of an output's
variance is orientation, how much position), and their plot."""

from __future__ import annotations

from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from .._checks import as_matrix, as_real_array, check_finite
from .._plotting import figure, save_figure


class EtaValues(NamedTuple):
    """``eta_p`` and ``eta_phi`` per output, each of shape (n,)."""

    eta_p: np.ndarray
    eta_phi: np.ndarray


def as_rotated_outputs(outputs: Any, name: str = "outputs") -> np.ndarray:
    a = as_real_array(outputs, name).astype(np.float64, copy=False)
    if a.ndim != 3:
        raise ValueError(
            f"{name} must have shape (n_positions, n_orientations, n_outputs), e.g. from "
            f"Network.transform(images, rotations=True); got shape {a.shape}"
        )
    if a.shape[0] < 2 or a.shape[2] < 1:
        raise ValueError(f"{name} needs at least 2 positions and 1 output, got shape {a.shape}")
    check_finite(a, name)
    return a


def eta_values(outputs: Any, *, normalize: bool = False) -> EtaValues:
    """Sensitivity of each output to position and to orientation (thesis 3.5,
    after Franzius et al. 2007).

    With ``s(p, phi)`` the output at position ``p`` and (relative) orientation
    ``phi``:

    * mean positional variance ``eta_p = < var_p( s(p, phi) ) >_phi``: the
      variance over positions at each fixed orientation, averaged over
      orientations;
    * mean orientation variance ``eta_phi = < var_phi( s(p, phi) ) >_p``: the
      variance over orientations at each fixed position, averaged over
      positions.

    Variances are population variances (divided by the count), as the SFA
    unit-variance constraint. For outputs of unit variance (the network's
    outputs on its own training views, all rotations included) the ideal
    position code has ``eta_p = 1`` and ``eta_phi = 0``. The two need not sum
    to 1.

    Parameters
    ----------
    outputs : array of shape (P, K, n)
        ``n`` outputs at ``P`` positions under ``K`` orientations, e.g.
        ``Network.transform(images, rotations=True)`` (the simulated
        rotations are the orientations).
    normalize : bool, default False
        Divide both by each output's total variance over all (p, phi): the
        thesis's values for outputs whose variance is not 1 (e.g. on a test
        run). Not part of the thesis's definition; False gives it exactly.

    Returns
    -------
    EtaValues
        ``(eta_p, eta_phi)``, each of shape (n,).
    """
    s = as_rotated_outputs(outputs)
    eta_p = s.var(axis=0).mean(axis=0)
    eta_phi = s.var(axis=1).mean(axis=0)
    if normalize:
        total = s.reshape(-1, s.shape[2]).var(axis=0)
        if np.any(total <= 0):
            raise ValueError(f"output(s) {np.flatnonzero(total <= 0).tolist()} are constant: cannot normalize")
        eta_p, eta_phi = eta_p / total, eta_phi / total
    return EtaValues(eta_p, eta_phi)


def delta_values(signals: Any) -> np.ndarray:
    """Delta value of each column of a time series (T, n): the mean squared
    difference of consecutive samples (unit time step, as :class:`sfanav.SFA`).
    Not normalised: equal to SFA's Delta for unit-variance signals. See
    :func:`beta_values` for ``sqrt(Delta) / (2 pi)``."""
    s = as_matrix(signals, "signals", min_rows=2)
    return (np.diff(s, axis=0) ** 2).mean(axis=0)


def orientation_angles(n_orientations: int, *, step: int | None = None, width: int | None = None) -> np.ndarray:
    """Relative orientation (degrees) of each of ``K`` simulated rotations.

    Rotation ``k`` shifts the panorama by ``k * step`` px of ``width``, i.e.
    ``360 * k * step / width`` degrees; without ``step``/``width``, rotations are
    taken as evenly spaced (``360 k / K``)."""
    k = np.arange(int(n_orientations))
    if step is None or width is None:
        return 360.0 * k / n_orientations
    return 360.0 * k * step / width


def plot_eta(eta_p: Any, eta_phi: Any, path: Any, *, title: str | None = None, dpi: int = 120) -> Path:
    """Bar chart of ``eta_p`` and ``eta_phi`` per output (thesis 5.1, Fig. 5.8a)."""
    p = np.asarray(eta_p, dtype=float).ravel()
    f = np.asarray(eta_phi, dtype=float).ravel()
    if p.shape != f.shape:
        raise ValueError(f"eta_p and eta_phi must have the same length, got {p.shape} and {f.shape}")
    idx = np.arange(1, len(p) + 1)
    fig = figure(max(4.0, 0.5 * len(p) + 2), 3.2)
    ax = fig.subplots()
    ax.bar(idx - 0.2, p, 0.4, label=r"$\eta_p$ (position)")
    ax.bar(idx + 0.2, f, 0.4, label=r"$\eta_\varphi$ (orientation)")
    ax.set_xticks(idx, [f"s{i}" for i in idx])
    ax.set_ylabel("mean variance")
    ax.legend(fontsize="small")
    ax.set_title(title or "position vs orientation sensitivity")
    return save_figure(fig, path, dpi)
