"""What a trained network expects and how any input is made to match it.

* :class:`Preprocessing`: panorama size (width = 360 degrees), gray or RGB,
  per-image normalisation; stored in a localizer's model file.
* :class:`Preprocessor`: applies it to batches of images: panoramas of the
  right size pass as they are, omnidirectional (mirror) images are unwarped
  (for training, optionally with a random centre offset per image: the
  thesis's centre jitter), other panoramas resized; then gray conversion and
  normalisation."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from .._checks import check_nonneg_float
from .._progress import Log, stderr_log

if TYPE_CHECKING:  # annotations only: data/ sits below the network and the localizer
    from ..localization.localizer import Localizer
    from ..sfa.network import Network


MAX_SIDE = 32767  # px: OpenCV's remap and resize maps are indexed by 16-bit integers


@dataclass(frozen=True)
class Preprocessing:
    """The images a trained network expects.

    Attributes
    ----------
    width, height : int
        Panorama size in pixels; ``width`` is the full 360 degrees (the
        rotation period), which may be wider than the network's input
        window.
    gray : bool
        One channel (ITU-R 601 luma) instead of RGB.
    normalize : bool
        Each image shifted and scaled to zero mean and unit variance
        (thesis 5.2.1), float32.
    """

    width: int
    height: int
    gray: bool
    normalize: bool = False

    def __post_init__(self) -> None:
        for name in ("width", "height"):
            v = getattr(self, name)
            if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)):
                raise TypeError(f"panorama {name} must be an integer, got {v!r}")
            if not 1 <= v <= MAX_SIDE:
                raise ValueError(f"panorama {name} must be 1..{MAX_SIDE} px, got {v}")
        for name in ("gray", "normalize"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise TypeError(f"{name} must be a bool, got {getattr(self, name)!r}")

    @classmethod
    def for_network(cls, network: Network, *, window: float = 1.0, normalize: bool = False) -> "Preprocessing":
        """The input of ``network`` when trained with a ``window`` (fraction of
        the panorama it sees): width = network input width / window."""
        h, v, c = network.input_shape
        width = int(round(v / window))
        if round(window * width) != v:  # pragma: no cover - rounding corner
            width += 1
        return cls(width, h, c == 1, normalize)

    def to_dict(self) -> dict[str, Any]:
        return {"width": self.width, "height": self.height, "gray": self.gray, "normalize": self.normalize}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "Preprocessing":
        try:
            return cls(d["width"], d["height"], d["gray"], d.get("normalize", False))
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"invalid preprocessing record {d!r}: {exc}") from None

    @classmethod
    def of_model(cls, loc: Localizer) -> "Preprocessing":
        """What a saved localizer expects: its stored record, or (models
        saved from Python) the network's input as it is."""
        rec = (loc.info or {}).get("preprocessing")
        if rec:
            return cls.from_dict(rec)
        if loc.network is None:
            raise ValueError("this model has no network: it localizes from features, not images")
        net = loc.network
        period = net.period_
        h, v, c = net.input_shape
        return cls(int(period or v), h, c == 1, False)

    @property
    def size(self) -> tuple[int, int]:
        return (self.width, self.height)

    def describe(self) -> str:
        return f"{self.width}x{self.height} {'gray' if self.gray else 'RGB'}{', normalized' if self.normalize else ''}"


def _to_gray(batch: np.ndarray) -> np.ndarray:
    if batch.ndim == 3:
        return batch
    import cv2

    return np.stack([cv2.cvtColor(np.ascontiguousarray(b), cv2.COLOR_RGB2GRAY) for b in batch])


def _normalize(batch: np.ndarray) -> np.ndarray:
    a = batch.astype(np.float32)
    flat = a.reshape(len(a), -1)
    mean = flat.mean(axis=1, dtype=np.float64)
    std = flat.std(axis=1, dtype=np.float64)
    std[std == 0] = 1.0
    return ((flat - mean[:, None]) / std[:, None]).astype(np.float32).reshape(a.shape)


def _parse_mirror(mirror: Any) -> tuple[float, float, float, float] | None:
    if mirror is None:
        return None
    if isinstance(mirror, str):
        parts = mirror.replace(" ", "").split(",")
    else:
        parts = list(mirror)
    try:
        vals = tuple(float(p) for p in parts)
    except (TypeError, ValueError):
        raise ValueError(f"mirror must be CX,CY,INNER,OUTER (pixels), got {mirror!r}") from None
    if len(vals) != 4 or not all(np.isfinite(vals)) or not 0 <= vals[2] < vals[3]:
        raise ValueError(f"mirror must be CX,CY,INNER,OUTER with 0 <= INNER < OUTER (pixels), got {mirror!r}")
    return vals  # type: ignore[return-value]


class Preprocessor:
    """Turns batches of images (uint8, (n, H, W[, 3]) RGB or (n, H, W) gray)
    into the network's input described by ``prep``.

    The first batch decides what is needed, and ``log`` says so once:

    * the panorama size already: used as it is;
    * an omnidirectional (mirror) image, recognised by its aspect ratio
      (width < 2 x height): unwarped with ``mirror = (cx, cy, inner, outer)``
      pixels, or with the mirror :func:`sfanav.estimate_mirror` finds in the
      first batch;
    * a panorama of another size: resized (area interpolation).

    Then RGB becomes gray if the network is gray, and each image is
    normalised if ``prep.normalize``.

    Parameters
    ----------
    prep : Preprocessing
        What the network expects.
    mirror : (cx, cy, inner, outer) or "CX,CY,INNER,OUTER", optional
        The mirror of omnidirectional images, pixels; default estimated.
    log : callable
        Where the one-line account of the conversion goes.
    jitter : float
        Centre jitter, pixels (thesis 5.2.1: 5): every omnidirectional image
        is unwarped about the mirror centre moved by a random offset drawn
        uniformly from ``[-jitter, jitter]`` in x and in y, so that a network
        trained on them learns to ignore where the horizon ring lies (a
        robot tilting on uneven ground moves it). A training augmentation:
        leave it 0 for images to localize. Panoramas are not unwarped and
        pass without jitter (the log says so). Must be smaller than the
        mirror ring's width.
    seed : int, optional
        Seeds the offsets: same seed and images, same panoramas.

    Raises
    ------
    TypeError, ValueError
        A ``jitter`` that is not a finite number >= 0, or (on the first
        batch) not smaller than the mirror ring's width; a malformed
        ``mirror``.

    Examples
    --------
    >>> prep = Preprocessing(409, 40, gray=True, normalize=True)
    >>> train = Preprocessor(prep, jitter=5.0, seed=0)     # doctest: +SKIP
    >>> X = train(omni_images)                             # doctest: +SKIP
    >>> test = Preprocessor(prep, mirror=train.mirror_used)  # no jitter  # doctest: +SKIP
    """

    def __init__(self, prep: Preprocessing, *, mirror: Any = None, log: Log = stderr_log, jitter: float = 0.0,
                 seed: int | None = None) -> None:
        self.prep = prep
        self.mirror = _parse_mirror(mirror)
        self.log = log
        self.jitter = check_nonneg_float(jitter, "jitter")
        if seed is not None and (isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer))
                                 or seed < 0):
            raise ValueError(f"seed must be a non-negative integer or None, got {seed!r}")
        self.seed = seed
        self.mode: str | None = None
        self._unwarper: Any = None
        self.message = ""
        self.mirror_used: tuple[float, float, float, float] | None = None

    def _decide(self, batch: np.ndarray) -> None:
        h, w = batch.shape[1], batch.shape[2]
        W, H = self.prep.size
        if (w, h) == (W, H):
            self.mode = "as-is"
            self._say_no_jitter(f"{w}x{h} panoramas")
            return
        if w < 2 * h:
            from .unwarp import Mirror, estimate_mirror

            if self.mirror is not None:
                cx, cy, r0, r1 = self.mirror
                m = Mirror((cx, cy), r0, r1)
                how = f"given mirror: center ({cx:.1f}, {cy:.1f}) px, radii {r0:.1f}..{r1:.1f} px"
            else:
                m = estimate_mirror(batch)
                self.mirror = (float(m.center[0]), float(m.center[1]), float(m.inner_radius), float(m.outer_radius))
                how = (f"estimated mirror center ({m.center[0]:.1f}, {m.center[1]:.1f}) px, radii "
                       f"{m.inner_radius:.1f}..{m.outer_radius:.1f} px; pass --mirror CX,CY,INNER,OUTER to set it")
            ring = m.outer_radius - m.inner_radius
            if self.jitter >= ring:
                raise ValueError(f"centre jitter {self.jitter:g} px is not smaller than the mirror ring's width "
                                 f"({ring:.1f} px, radii {m.inner_radius:.1f}..{m.outer_radius:.1f})")
            # clockwise: a mirror flips the scene; read so, the panorama follows sfanav's convention (a left turn
            # shifts the scene to larger columns, as sfanav.sim.PanoramicCamera), which the panorama compass, the
            # pose graph and homing assume (counter-clockwise gave mirrored panoramas whose compass read every turn
            # the wrong way: 6.2.1-static without ground truth 7.0 m, docs/experiments.md)
            self._unwarper = m.unwarper((W, H), jitter=self.jitter, random_state=self.seed, clockwise=True)
            if self.jitter:
                how += f"; centre jittered by up to +-{self.jitter:g} px per image (seed {self.seed})"
            self.mode = "unwarp"
            self.mirror_used = self.mirror
            self.message = f"unwarping {w}x{h} omnidirectional images to {W}x{H} panoramas: {how}"
        else:
            self.mode = "resize"
            self.message = f"resizing {w}x{h} images to {W}x{H}, the panorama size the model was trained on"
            self._say_no_jitter(f"{w}x{h} panoramas")
        self.log(self.message)

    def _say_no_jitter(self, what: str) -> None:
        if self.jitter:
            self.log(f"centre jitter ({self.jitter:g} px) applies to omnidirectional images only: the {what} "
                     "pass without it")

    def __call__(self, batch: np.ndarray) -> np.ndarray:
        a = np.asarray(batch)
        if a.ndim not in (3, 4):
            raise ValueError(f"images must be (n, H, W) or (n, H, W, 3), got shape {a.shape}")
        if self.mode is None:
            self._decide(a)
        if self.mode == "unwarp":
            a = self._unwarper.transform(a)
        elif self.mode == "resize":
            import cv2

            a = np.stack([cv2.resize(np.ascontiguousarray(b), self.prep.size, interpolation=cv2.INTER_AREA) for b in a])
        if a.shape[1:3] != (self.prep.height, self.prep.width):
            raise ValueError(f"images are {a.shape[2]}x{a.shape[1]} after conversion, expected "
                             f"{self.prep.width}x{self.prep.height}; do all images have one size?")
        if self.prep.gray:
            a = _to_gray(a)
        elif a.ndim == 3:
            raise ValueError("the model takes RGB images, but these are gray")
        if self.prep.normalize:
            a = _normalize(a)
        return a
