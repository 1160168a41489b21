"""Analysis of learned slow-feature representations (thesis 3.5, 5.1).

* :func:`eta_values`: mean positional variance ``eta_p`` and mean orientation
  variance ``eta_phi`` of each output.
* :func:`delta_values`, :func:`beta_values`: slowness of output signals.
* Plots (PNG, matplotlib's Agg renderer, no display needed): spatial firing
  maps (:func:`plot_firing_maps`), estimated vs true trajectories
  (:func:`plot_trajectory`), error against the number of outputs
  (:func:`plot_error_vs_n`), eta values (:func:`plot_eta`). Each takes
  arrays and an output path and returns the path.
* :func:`write_report`: a Markdown report embedding PNGs and a metrics table.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from ._checks import as_matrix, as_real_array, check_finite, check_same_length
from .sfa import beta_values

__all__ = [
    "EtaValues",
    "beta_values",
    "delta_values",
    "eta_values",
    "orientation_angles",
    "plot_error_vs_n",
    "plot_eta",
    "plot_firing_maps",
    "plot_trajectory",
    "write_report",
]


class EtaValues(NamedTuple):
    """``eta_p`` and ``eta_phi`` per output, each of shape (n,)."""

    eta_p: np.ndarray
    eta_phi: np.ndarray


def _as_rotated_outputs(outputs: Any, name: str = "outputs") -> np.ndarray:
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
    s = _as_rotated_outputs(outputs)
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


# --------------------------------------------------------------------- plotting


def _figure(width: float, height: float):
    from matplotlib.figure import Figure  # Agg canvas; no pyplot, no display

    return Figure(figsize=(width, height), layout="constrained")


def _save(fig: Any, path: Any, dpi: int) -> Path:
    path = Path(path)
    if path.suffix.lower() != ".png":
        raise ValueError(f"plots are written as PNG: give a path ending in .png, got {path}")
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi, format="png")
    return path


def plot_firing_maps(
    outputs: Any,
    xy: Any,
    path: Any,
    *,
    which: Sequence[int] = (0, 1, 2, 3),
    orientations: Sequence[float] = (0, 90, 180, 270),
    angles: Any = None,
    bins: int | None = None,
    cmap: str = "viridis",
    title: str | None = None,
    dpi: int = 120,
) -> Path:
    """Spatial firing maps (thesis Fig. 3.3c, 5.2a, 5.5a): each output's value
    colour-coded over position, one column per orientation.

    Parameters
    ----------
    outputs : array (N, K, n) or (N, n)
        Outputs under ``K`` simulated rotations (``Network.transform(images,
        rotations=True)``), or at one orientation only.
    xy : array (N, 2)
        Positions, metres.
    path : str or Path
        Output PNG.
    which : sequence of int
        Output indices to plot (0 = slowest); rows of the figure.
    orientations : sequence of float
        Relative orientations in degrees (columns); each picks the nearest
        rotation. Ignored for (N, n) outputs.
    angles : array (K,), optional
        Degrees of each rotation (see :func:`orientation_angles`); default evenly spaced.
    bins : int, optional
        Average into a ``bins x bins`` grid (for dense walks); default: one
        square marker per sample.
    """
    a = as_real_array(outputs, "outputs").astype(np.float64, copy=False)
    if a.ndim == 2:
        a = a[:, None, :]
        orientations, angles = (0.0,), np.zeros(1)
    a = _as_rotated_outputs(a)
    P = as_matrix(xy, "xy", n_cols=2)
    check_same_length(a, P, "outputs", "xy")
    K, n = a.shape[1], a.shape[2]
    which = [int(j) for j in which]
    if not which or min(which) < 0 or max(which) >= n:
        raise ValueError(f"which must list output indices in 0..{n - 1}, got {which}")
    ang = orientation_angles(K) if angles is None else np.asarray(angles, dtype=float)
    if ang.shape != (K,):
        raise ValueError(f"angles must have shape ({K},), got {ang.shape}")
    cols = []
    for o in orientations:
        diff = np.abs((ang - float(o) + 180.0) % 360.0 - 180.0)
        cols.append(int(np.argmin(diff)))
    fig = _figure(2.4 * len(cols) + 0.8, 2.2 * len(which) + (0.4 if title else 0))
    axes = fig.subplots(len(which), len(cols), squeeze=False, sharex=True, sharey=True)
    x0, x1, y0, y1 = P[:, 0].min(), P[:, 0].max(), P[:, 1].min(), P[:, 1].max()
    pad = 0.02 * max(x1 - x0, y1 - y0)
    x0, x1, y0, y1 = x0 - pad, x1 + pad, y0 - pad, y1 + pad
    marker = float(np.clip((150.0 / np.sqrt(len(P))) ** 2, 2.0, 200.0))  # points^2: tiles a ~2 inch panel
    for r, j in enumerate(which):
        vals = a[:, cols, j]
        vmin, vmax = float(vals.min()), float(vals.max())
        im = None
        for c, k in enumerate(cols):
            ax = axes[r, c]
            v = a[:, k, j]
            if bins:
                sums, xe, ye = np.histogram2d(P[:, 0], P[:, 1], bins=bins, weights=v)
                cnt, _, _ = np.histogram2d(P[:, 0], P[:, 1], bins=[xe, ye])
                with np.errstate(invalid="ignore"):
                    grid = np.where(cnt > 0, sums / np.maximum(cnt, 1), np.nan)
                im = ax.pcolormesh(xe, ye, grid.T, cmap=cmap, vmin=vmin, vmax=vmax)
            else:
                im = ax.scatter(P[:, 0], P[:, 1], c=v, s=marker, marker="s", cmap=cmap, vmin=vmin, vmax=vmax, linewidths=0)
            ax.set_aspect("equal")
            if x1 > x0:
                ax.set_xlim(x0, x1)
            if y1 > y0:
                ax.set_ylim(y0, y1)
            if r == 0:
                ax.set_title(f"{ang[k]:.0f}\N{DEGREE SIGN}")
            if c == 0:
                ax.set_ylabel(f"s{j + 1}  y [m]")
            if r == len(which) - 1:
                ax.set_xlabel("x [m]")
        fig.colorbar(im, ax=list(axes[r]), shrink=0.9)
    if title:
        fig.suptitle(title)
    return _save(fig, path, dpi)


def plot_trajectory(
    xy_true: Any,
    xy_pred: Any,
    path: Any,
    *,
    title: str | None = None,
    connect: bool = True,
    error_lines: bool = False,
    dpi: int = 120,
) -> Path:
    """Ground truth and estimated positions (thesis Fig. 5.2b, 5.5b), equal
    axes in metres. ``connect`` draws the ground truth as a line (a walk);
    ``error_lines`` joins each estimate to its true position."""
    T = as_matrix(xy_true, "xy_true", n_cols=2)
    E = as_real_array(xy_pred, "xy_pred").astype(np.float64, copy=False)
    if E.shape != T.shape:
        raise ValueError(f"xy_pred must have the shape of xy_true {T.shape}, got {E.shape}")
    ok = np.isfinite(E).all(axis=1)  # random-split predictions may hold NaN rows
    fig = _figure(5.5, 5.0)
    ax = fig.subplots()
    if error_lines:
        from matplotlib.collections import LineCollection

        segs = np.stack([T[ok], E[ok]], axis=1)
        ax.add_collection(LineCollection(segs, colors="0.7", linewidths=0.5))
    if connect:
        ax.plot(T[:, 0], T[:, 1], "-", color="tab:blue", lw=1.0, label="ground truth")
    else:
        ax.plot(T[:, 0], T[:, 1], ".", color="tab:blue", ms=3, label="ground truth")
    ax.plot(E[ok, 0], E[ok, 1], ".", color="tab:red", ms=3, label="estimate")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(loc="best", fontsize="small")
    if title:
        ax.set_title(title)
    return _save(fig, path, dpi)


def plot_error_vs_n(
    ns: Any,
    train_error: Any,
    test_error: Any,
    path: Any,
    *,
    best_n: int | None = None,
    protocol: str | None = None,
    title: str | None = None,
    unit: str = "m",
    dpi: int = 120,
) -> Path:
    """Training and test error against the number of slow outputs used
    (thesis Fig. 5.3, 5.6). ``train_error`` may be None."""
    ns_a = np.asarray(ns, dtype=float).ravel()
    te = np.asarray(test_error, dtype=float).ravel()
    if te.shape != ns_a.shape:
        raise ValueError(f"test_error must have one value per n ({len(ns_a)}), got {te.shape}")
    fig = _figure(5.0, 3.5)
    ax = fig.subplots()
    if train_error is not None:
        tr = np.asarray(train_error, dtype=float).ravel()
        if tr.shape != ns_a.shape:
            raise ValueError(f"train_error must have one value per n ({len(ns_a)}), got {tr.shape}")
        ax.plot(ns_a, tr, "o-", label="training error")
    ax.plot(ns_a, te, "s-", label="test error")
    if best_n is not None:
        ax.axvline(best_n, color="0.5", ls="--", lw=0.8, label=f"best n = {best_n}")
    ax.set_xlabel("number of slow outputs n")
    ax.set_ylabel(f"MED [{unit}]")
    ax.set_xticks(ns_a)
    ax.legend(fontsize="small")
    ax.set_title(title or (f"error vs n ({protocol})" if protocol else "error vs n"))
    return _save(fig, path, dpi)


def plot_eta(eta_p: Any, eta_phi: Any, path: Any, *, title: str | None = None, dpi: int = 120) -> Path:
    """Bar chart of ``eta_p`` and ``eta_phi`` per output (thesis 5.1, Fig. 5.8a)."""
    p = np.asarray(eta_p, dtype=float).ravel()
    f = np.asarray(eta_phi, dtype=float).ravel()
    if p.shape != f.shape:
        raise ValueError(f"eta_p and eta_phi must have the same length, got {p.shape} and {f.shape}")
    idx = np.arange(1, len(p) + 1)
    fig = _figure(max(4.0, 0.5 * len(p) + 2), 3.2)
    ax = fig.subplots()
    ax.bar(idx - 0.2, p, 0.4, label=r"$\eta_p$ (position)")
    ax.bar(idx + 0.2, f, 0.4, label=r"$\eta_\varphi$ (orientation)")
    ax.set_xticks(idx, [f"s{i}" for i in idx])
    ax.set_ylabel("mean variance")
    ax.legend(fontsize="small")
    ax.set_title(title or "position vs orientation sensitivity")
    return _save(fig, path, dpi)


# --------------------------------------------------------------------- report


def _fmt(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, (bool, np.bool_)):
        return str(bool(v))
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        v = float(v)
        if not np.isfinite(v):
            return str(v)
        if v != 0 and (abs(v) >= 1e5 or abs(v) < 1e-3):
            return f"{v:.3e}"
        return f"{v:.3f}" if abs(v) < 100 else f"{v:.1f}"
    return str(v).replace("|", "\\|").replace("\n", " ")


def _row(value: Any) -> dict[str, Any]:
    if hasattr(value, "metrics") and hasattr(value, "protocol"):  # a RegressionResult
        return {"protocol": value.protocol, **value.metrics}
    if isinstance(value, Mapping):
        return dict(value)
    raise TypeError(f"a metrics row must be a dict or a RegressionResult, got {type(value).__name__}")


def write_report(
    path: Any,
    *,
    title: str = "sfanav localization report",
    metrics: Mapping[str, Any] | None = None,
    columns: Sequence[str] | None = None,
    figures: Sequence[tuple[str, Any]] | Mapping[str, Any] = (),
    text: str | Sequence[str] | None = None,
) -> Path:
    """Writes a Markdown report: title, text paragraphs, a metrics table and
    the figures (embedded by paths relative to the report).

    Parameters
    ----------
    path : str or Path
        The ``.md`` file to write.
    metrics : mapping of row name -> dict or RegressionResult, optional
        One table row per entry (e.g. ``{"SFA, test run": result, "perfect
        memory": {...}}``); a RegressionResult contributes its protocol and
        test metrics.
    columns : sequence of str, optional
        Columns to show, in order; default all keys in order of appearance.
    figures : sequence of (caption, png path) or mapping caption -> path
    text : str or sequence of str, optional
        Paragraphs placed after the title.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    lines = [f"# {title}", ""]
    if text:
        for para in [text] if isinstance(text, str) else text:
            lines += [str(para), ""]
    if metrics:
        rows = {str(k): _row(v) for k, v in metrics.items()}
        if columns is None:
            columns = []
            for r in rows.values():
                columns += [c for c in r if c not in columns]
        columns = list(columns)
        lines += ["| | " + " | ".join(columns) + " |", "|---" * (len(columns) + 1) + "|"]
        for name, r in rows.items():
            lines.append(f"| {_fmt(name)} | " + " | ".join(_fmt(r.get(c)) for c in columns) + " |")
        lines.append("")
    items = list(figures.items()) if isinstance(figures, Mapping) else list(figures)
    for caption, fig_path in items:
        rel = Path(os.path.relpath(Path(fig_path).resolve(), path.parent.resolve())).as_posix()
        lines += [f"![{_fmt(caption)}]({rel})", "", f"*{_fmt(caption)}*", ""]
    path.write_text("\n".join(lines))
    return path
