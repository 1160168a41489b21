"""A live view of localization with Rerun (PyPI ``rerun-sdk``): the images,
the single-image estimates, the fused track with its covariance ellipses,
the learned map and the ground truth, to a recording file (``.rrd``) or a
running viewer.

:class:`RerunView` takes what :class:`~sfanav.odometry.streaming.StreamingLocalizer`
emits (:class:`~sfanav.odometry.streaming.LiveEstimate`), so ``sfanav
localize --rerun`` and the ROS node log the same entities. The streaming
core does not import Rerun. Entities (2D, metres, map frame):

* ``world/map``: the positions the model's readout was fitted to (static);
* ``world/estimate``: the single-image estimate of each image;
* ``world/fused``: the fused position, and ``world/fused/ellipse``: its
  2-sigma covariance ellipse (a closed line strip);
* ``world/truth``: the ground truth where known;
* ``camera/image``: the image.

Timelines: ``stamp`` (the image's stamp, nanoseconds since the Unix epoch,
when known) and ``frame`` (the image's index). Reading one back:
``docs/live.md``.

Layout: every recording carries a default layout (:func:`default_blueprint`):
the camera image above, the map below with the tracks so far (estimates,
fused, truth up to the time cursor) and the present ellipse. A viewer opens
it as it is; the user can rearrange it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

ELLIPSE_SIGMA = 2.0
"""The covariance ellipses are drawn at this many standard deviations."""
ELLIPSE_POINTS = 33
"""Points of an ellipse's closed line strip."""


def require_rerun() -> Any:
    """``rerun``; ImportError saying what to install when it is missing."""
    try:
        import rerun
    except ImportError:
        raise ImportError('the live view needs Rerun: pip install "sfanav[rerun]" (or rerun-sdk)') from None
    return rerun


def covariance_ellipse(center: Any, cov: Any, *, sigma: float = ELLIPSE_SIGMA, n: int = ELLIPSE_POINTS) -> np.ndarray:
    """The ``sigma``-standard-deviation ellipse of a 2D covariance (2, 2)
    about ``center`` (2,), as a closed polyline (n, 2): its first and last
    points are equal. Every point ``p`` has ``(p - c)^T C^-1 (p - c) =
    sigma^2``. ValueError for a covariance that is not symmetric positive
    semi-definite."""
    C = np.asarray(cov, float)
    if C.shape != (2, 2) or not np.allclose(C, C.T, atol=1e-12 * max(1.0, float(np.abs(C).max()))):
        raise ValueError(f"a 2D covariance must be a symmetric (2, 2) matrix, got {C.tolist()}")
    w, V = np.linalg.eigh(0.5 * (C + C.T))
    if w.min() < -1e-12 * max(1.0, float(w.max())):
        raise ValueError(f"a covariance must be positive semi-definite, got eigenvalues {w.tolist()}")
    a = np.linspace(0.0, 2 * np.pi, n)
    a[-1] = 0.0
    unit = np.c_[np.cos(a), np.sin(a)]
    return np.asarray(center, float) + sigma * (unit * np.sqrt(np.clip(w, 0, None))) @ V.T


TIMELINES = ("stamp", "frame")
"""The timelines every view logs to (``stamp`` only when stamps are times)."""


def default_blueprint(*, panels: bool = True) -> Any:
    """The layout a recording opens with: ``camera`` (the image) above
    ``world`` (the map, the estimates, fused positions and truth from the
    start up to the time cursor, and the present covariance ellipse only),
    following the newest image on the ``frame`` timeline. ``panels=False``
    collapses the viewer's side and time panels (for pictures).

    Returns a ``rerun.blueprint.Blueprint``. Raises ImportError (with the
    install line) without ``rerun-sdk``.
    """
    require_rerun()
    import rerun.blueprint as rrb

    B = rrb.TimeRangeBoundary
    past = [rrb.VisibleTimeRange(t, start=B.infinite(), end=B.cursor_relative()) for t in TIMELINES]
    now = [rrb.VisibleTimeRange(t, start=B.cursor_relative(), end=B.cursor_relative()) for t in TIMELINES]
    world = rrb.Spatial2DView(
        origin="world", name="map and tracks", time_ranges=past,
        overrides={"world/fused/ellipse": [rrb.VisibleTimeRanges(now)]})
    camera = rrb.Spatial2DView(origin="camera", name="camera")
    time = rrb.TimePanel(timeline="frame", play_state="following", state=None if panels else "collapsed")
    return rrb.Blueprint(rrb.Vertical(camera, world, row_shares=[1, 4]), time, collapse_panels=not panels)


class RerunView:
    """Logs localization to Rerun.

    Parameters
    ----------
    target : str or Path
        ``NAME.rrd``: a recording file (written as the view logs; complete
        after :meth:`close`); ``"viewer"``: a viewer spawned on this machine;
        ``rerun+http://HOST:PORT/proxy``: a running viewer.
    images : bool, default True
        Log the images too (the largest part of a recording).
    application_id : str, default "sfanav"

    Example
    -------
    >>> view = RerunView("run.rrd")                          # doctest: +SKIP
    >>> view.log_map(loc.training_positions_)                # doctest: +SKIP
    >>> for est in live.push_image(t_ns, image):            # doctest: +SKIP
    ...     view.log(est, frame=k, image=image)
    >>> view.close()                                         # doctest: +SKIP
    """

    def __init__(self, target: str | Path, *, images: bool = True, application_id: str = "sfanav") -> None:
        rr = require_rerun()
        self._rr = rr
        self.images = bool(images)
        self.rec = rr.RecordingStream(application_id)
        t = str(target)
        if t == "viewer":
            self.rec.spawn()
        elif t.startswith("rerun+http://") or t.startswith("rerun://"):
            self.rec.connect_grpc(t)
        elif Path(t).suffix.lower() == ".rrd":
            self.rec.save(t)
        else:
            raise ValueError(f"a Rerun target is NAME.rrd, 'viewer' or rerun+http://HOST:PORT/proxy, got {t!r}")
        self.rec.send_blueprint(default_blueprint())
        self.target = t
        self.n_logged_ = 0

    def _time(self, stamp_ns: int | None, frame: int | None) -> None:
        if frame is not None:
            self.rec.set_time("frame", sequence=int(frame))
        if stamp_ns is not None:
            self.rec.set_time("stamp", timestamp=np.datetime64(int(stamp_ns), "ns"))

    def log_map(self, positions: Any) -> None:
        """The learned map (N, 2), metres: static points."""
        P = np.asarray(positions, float).reshape(-1, 2)
        self.rec.log("world/map", self._rr.Points2D(P, radii=0.02, colors=[150, 150, 150]), static=True)

    def log_image(self, image: Any, *, stamp_ns: int | None = None, frame: int | None = None) -> None:
        """An image (H, W[, 3]) uint8 at ``stamp_ns`` / ``frame`` (nothing when ``images`` is False)."""
        if self.images:
            self._time(stamp_ns, frame)
            self.rec.log("camera/image", self._rr.Image(np.asarray(image)))

    def log_truth(self, xy: Any, *, stamp_ns: int | None = None, frame: int | None = None) -> None:
        """The true position (2,) of the image at ``stamp_ns`` / ``frame``."""
        self._time(stamp_ns, frame)
        self.rec.log("world/truth", self._rr.Points2D([np.asarray(xy, float)], radii=0.04, colors=[40, 180, 40]))

    def log(self, est: Any, *, frame: int | None = None, image: Any = None, stamp: bool = True) -> None:
        """One :class:`~sfanav.odometry.streaming.LiveEstimate` (or anything
        with ``stamp_ns``, ``estimate``, ``pose``, ``covariance``) and its image
        (H, W[, 3]) uint8. ``stamp``: put it on the ``stamp`` timeline too
        (False when the stamps are only an order, not times)."""
        rr = self._rr
        if image is not None:
            self.log_image(image, stamp_ns=est.stamp_ns if stamp else None, frame=frame)
        self._time(est.stamp_ns if stamp else None, frame)
        self.rec.log("world/estimate", rr.Points2D([np.asarray(est.estimate, float)], radii=0.04,
                                                   colors=[230, 120, 30]))
        if est.pose is not None:
            self.rec.log("world/fused", rr.Points2D([np.asarray(est.pose[:2], float)], radii=0.05,
                                                    colors=[40, 110, 230]))
            self.rec.log("world/fused/ellipse", rr.LineStrips2D(
                [covariance_ellipse(est.pose[:2], np.asarray(est.covariance)[:2, :2])], colors=[40, 110, 230]))
        self.n_logged_ += 1

    def close(self) -> None:
        """Flushes and ends the recording (a file is then complete)."""
        self.rec.flush()
        self.rec.disconnect()
